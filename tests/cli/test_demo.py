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
