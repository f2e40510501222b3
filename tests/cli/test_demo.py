"""``brdffit demo``: what it fits and what it tells the user to do next."""

from __future__ import annotations

import json
import shlex

from brdffit.cli import main
from brdffit.cli.demo import DEMO_MODELS, NEXT_STEP


def test_the_demo_shows_the_engine_ready_model():
    assert "ggx-diffuse" in DEMO_MODELS.split(",")


def test_the_suggested_next_step_runs_and_writes_a_gltf_material(tmp_path, monkeypatch, capsys):
    """The commands the demo prints at its end must work as printed, from an empty folder."""
    monkeypatch.chdir(tmp_path)
    for step in NEXT_STEP:
        assert main(shlex.split(step)) == 0, capsys.readouterr().err
    doc = json.loads((tmp_path / "plastic.gltf").read_text())
    assert doc["asset"]["version"] == "2.0" and doc["materials"]


def test_the_demo_runs_materials_in_parallel_and_indexes_them_all(tmp_path, capsys):
    """Two materials in two worker processes: both compared, reported and in the index."""
    out = tmp_path / "demo"
    assert main(["demo", "--data", "synthetic:[gold-ggx,plastic-beckmann]", "--models",
                 "tabulated", "--spp", "4", "--resolution", "16", "--jobs", "2",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "(2 at a time)" in text and "[1/2]" in text and "[2/2]" in text
    index = (out / "index.html").read_text()
    for name in ("gold-ggx", "plastic-beckmann"):
        assert f"] {name} (" in text and (out / name / "index.html").is_file() and name in index
