"""The full default scene suite, rendered again and again in one process, on the AVX2 target
(issue 30: the knot after the spheres crashed the renderer on AVX2 CPUs without AVX-512).

The renders run in this test's own child process *without* the renderer's isolation (a
crash there is the test's failure, exit status 139, not a recorded scene error) and with
Dr.Jit compiling for AVX2 only (``BRDFFIT_LLVM_TARGET=avx2``), where a stray gather index
faults. 128 px: the former NaN index crashed every run there (and debug mode reported 18
out-of-bounds gathers), at 32 and 64 px it did neither. A second run in Dr.Jit's debug mode
counts out-of-bounds accesses (must be 0).
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from brdffit.evaluation.render import available

pytestmark = [pytest.mark.render, pytest.mark.slow,
              pytest.mark.skipif(not available(), reason="Mitsuba 3 LLVM back-end unavailable")]

SCRIPT = r"""
import sys
from brdffit.evaluation.compare import DEFAULT_BATCHES, DEFAULT_SPP, compare, resolve_reference
from brdffit.evaluation.render.scenes import scene_suite
from brdffit.fit.registry import fit_model

out, repeats, resolution = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
reference = resolve_reference("synthetic:gold-ggx")
models = {m: fit_model(m, reference)[0] for m in ("tabulated", "ggx")}
for k in range(repeats):
    r = compare(reference, models, out, resolution=resolution, isolate_renders=False,
                save_fits=False, update_index=False, brdf_metrics=())
    assert r["scene"]["spp"] == DEFAULT_SPP and r["scene"]["batches"] == DEFAULT_BATCHES
    assert [s["name"] for s in r["scenes"]] == [s.name for s in scene_suite("paper")[0]]
    errors = [s.get("error") for s in r["scenes"] if s.get("error")]
    assert not errors, errors
    print("suite", k, [round(m["psnr"], 2) for m in r["models"]], flush=True)
"""


def _run(tmp_path, repeats: int, resolution: int, **env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path), str(repeats),
                           str(resolution)], env={**os.environ, **env}, capture_output=True,
                          text=True, timeout=600)


def test_the_default_suite_renders_three_times_in_one_process_on_avx2(tmp_path):
    res = _run(tmp_path, 3, 128, BRDFFIT_LLVM_TARGET="avx2", BRDFFIT_DRJIT_DEBUG="0")
    assert res.returncode == 0, (res.returncode, res.stderr[-2000:])
    assert res.stdout.count("suite ") == 3


def test_the_default_suite_reads_and_writes_nothing_out_of_bounds(tmp_path):
    res = _run(tmp_path, 1, 128, BRDFFIT_DRJIT_DEBUG="1")
    assert res.returncode == 0, res.stderr[-2000:]
    assert "out-of-bounds" not in res.stderr, res.stderr[-2000:]
