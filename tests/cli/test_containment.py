"""A renderer or worker that dies from a signal fails its scene or material only (issue 30).

The tests start ``brdffit`` as a user would, with a test-only ``sitecustomize``
(``tests/_crash_plugin``) that makes the child processes SIGSEGV at one point, as a fault in a
JIT-compiled kernel does. What must hold: one line naming the signal, the scene or stage and
the material; the other scenes and materials done and written; the index or summary with the
failure marked; exit status 3; never a ``BrokenProcessPool`` or a traceback.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from brdffit.evaluation.render import available

pytestmark = [pytest.mark.render,
              pytest.mark.skipif(not available(), reason="Mitsuba 3 LLVM back-end unavailable")]

PLUGIN = Path(__file__).resolve().parents[1] / "_crash_plugin"
SMALL = ["--spp", "4", "--batches", "2", "--resolution", "16"]


def _brdffit(args, crash: str, cwd: Path, timeout: float = 400) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(PLUGIN), *filter(None, [os.environ.get("PYTHONPATH")])]),
        "BRDFFIT_TEST_CRASH": crash}
    return subprocess.run([sys.executable, "-m", "brdffit", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def _clean(res: subprocess.CompletedProcess) -> None:
    for text in (res.stdout, res.stderr):
        assert "Traceback" not in text and "BrokenProcessPool" not in text, text


def test_compare_goes_on_after_the_renderer_crashes_in_one_scene(tmp_path):
    res = _brdffit(["compare", "synthetic:gold-ggx", "--models", "tabulated,ggx", *SMALL,
                    "--out", "cmp"], "render:knot-courtyard", tmp_path)
    _clean(res)
    assert res.returncode == 3, res.stderr
    line = "the renderer crashed (SIGSEGV) while rendering knot-courtyard for gold-ggx"
    assert f"gold-ggx: {line}\n" in res.stderr
    assert f"not rendered: knot-courtyard ({line})" in res.stdout
    result = json.loads((tmp_path / "cmp" / "gold-ggx" / "result.json").read_text())
    by_scene = {s["name"]: s for s in result["scenes"]}
    assert line in by_scene["knot-courtyard"]["error"]
    assert all("error" not in s for n, s in by_scene.items() if n != "knot-courtyard")
    for m in result["models"]:  # measured on the three sphere scenes, with a warning
        assert m["status"] == "ok" and len([s for s in m["scenes"] if "psnr" in s]) == 3
        assert any("knot-courtyard" in w for w in m["warnings"])
    assert (tmp_path / "cmp" / "index.html").is_file()
    assert result["timing"]["renders_isolated"] is True


def test_the_demo_goes_on_after_a_worker_crashes_and_indexes_the_failed_material(tmp_path):
    res = _brdffit(["demo", "--data", "synthetic:[gold-ggx,plastic-beckmann]", "--models",
                    "tabulated", "--spp", "4", "--resolution", "16", "--jobs", "2", "--out",
                    "demo"], "fit:plastic-beckmann", tmp_path)
    _clean(res)
    assert res.returncode == 3, res.stderr
    assert ("plastic-beckmann: FAILED: the worker of plastic-beckmann crashed (SIGSEGV) "
            "while fitting tabulated\n") in res.stdout
    assert "] gold-ggx (" in res.stdout and "report:" in res.stdout
    index = (tmp_path / "demo" / "index.html").read_text()
    assert "gold-ggx" in index and "plastic-beckmann" in index
    failed = json.loads((tmp_path / "demo" / "plastic-beckmann" / "result.json").read_text())
    assert failed["models"][0]["status"] == "failed" and "SIGSEGV" in failed["error"]
    assert (tmp_path / "demo" / "plastic-beckmann" / "index.html").is_file()


@pytest.mark.slow
def test_batch_render_records_the_crashed_scene_and_exits_3(tmp_path):
    res = _brdffit(["batch", "synthetic:[gold-ggx]", "--models", "ggx", "--render",
                    "--spp", "4", "--batches", "2", "--resolution", "16", "--workers", "1", "--quiet",
                    "--out", "runs"], "render:knot-courtyard", tmp_path)
    _clean(res)
    assert res.returncode == 3, res.stdout + res.stderr
    render = json.loads((tmp_path / "runs" / "renders" / "gold-ggx.json").read_text())
    assert render["status"] == "failed"
    assert "knot-courtyard: the renderer crashed (SIGSEGV)" in render["error"]
    fit = json.loads((tmp_path / "runs" / "records" / "gold-ggx" / "ggx.json").read_text())
    assert fit["status"] == "ok"
    assert (tmp_path / "runs" / "summary.csv").is_file()
    assert (tmp_path / "runs" / "report" / "index.html").is_file()


def test_brdfs_the_renderer_child_cannot_load_render_in_this_process(tmp_path, monkeypatch):
    """A BRDF class of the caller's ``__main__`` (a notebook, a script) cannot be sent to the
    renderer's child: the comparison renders in this process and says so."""
    import sys

    from brdffit.evaluation.compare import compare
    from brdffit.synthetic import synthetic

    ref = synthetic("gold-ggx")
    local = type("Local", (type(ref),), {"__module__": "__main__"})
    monkeypatch.setattr(sys.modules["__main__"], "Local", local, raising=False)
    ref.__class__ = local
    r = compare(ref, ["ggx"], tmp_path, spp=2, resolution=16, scenes="sphere-studio",
                brdf_metrics=(), write_exr=False)
    assert r["timing"]["renders_isolated"] is False and r["models"][0]["status"] == "ok"
    assert any("not isolated: the child process cannot load the call" in n for n in r["notes"])
