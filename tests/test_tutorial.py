"""docs/tutorial.md runs as written: its Python block, and its command lines (fit and export)."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import shared_data_path

TUTORIAL = Path(__file__).resolve().parents[1] / "docs" / "tutorial.md"


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", TUTORIAL.read_text(encoding="utf-8"), re.S)


@pytest.mark.shared_data
def test_tutorial_python_block_runs(tmp_path, monkeypatch, capsys):
    shared_data_path("nbrdf", "merl_nbrdf.zip")
    (code,) = _blocks("python")
    monkeypatch.chdir(tmp_path)
    exec(compile(code, str(TUTORIAL), "exec"), {"__name__": "tutorial"})
    out = capsys.readouterr().out
    assert out.startswith("True ggx + Lambert")                # res.success, res.message
    assert re.search(r"glTF roughness 0\.\d+", out)
    gltf = json.loads((tmp_path / "gold.gltf").read_text())
    assert gltf["asset"]["version"] == "2.0" and (tmp_path / "gold-gd.npz").is_file()


@pytest.mark.shared_data
def test_tutorial_commands_run(tmp_path):
    """Every `brdffit` line of the sh blocks except the renders and the report (slow; they
    have their own tests), in order, in a fresh folder."""
    shared_data_path("nbrdf", "merl_nbrdf.zip")
    exe = Path(sys.executable).with_name("brdffit")
    lines = [ln.split("#")[0].strip() for b in _blocks("sh") for ln in b.splitlines()]
    cmds = [shlex.split(ln) for ln in lines if ln.startswith("brdffit ")]
    cmds = [c for c in cmds if c[1] not in ("render", "compare")]
    assert [c[1] for c in cmds] == ["info", "convert", "fit", "fit", "export", "export", "export"]
    for c in cmds:
        r = subprocess.run([str(exe), *c[1:]], cwd=tmp_path, capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 0, (c, r.stderr)
    for f in ("gold.binary", "gold-tab.npz", "gold-gd.npz", "gold.gltf", "gold.mtlx", "gold.xml",
              "gold.bsdf"):
        assert (tmp_path / f).is_file(), f
