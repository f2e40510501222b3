"""brdffit._blas: fits run with one BLAS thread; the CLI sets it before NumPy loads."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

threadpoolctl = pytest.importorskip("threadpoolctl")


def _blas_threads() -> list[int]:
    return [p["num_threads"] for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas"]


def test_registry_fitters_run_with_one_blas_thread(monkeypatch):
    from brdffit.fit import registry

    seen = []

    def spy(brdf, **options):
        seen.append(_blas_threads())
        return brdf

    entry = registry.register_fitter("spy", spy, description="test")
    try:
        assert entry.accepts("anything") and entry.fit.__wrapped__ is spy
        monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")      # not the CLI's environment
        entry.fit(object())
    finally:
        del registry.FITTERS["spy"]
    assert seen and seen[0] and all(n == 1 for n in seen[0]), seen   # a BLAS was found


@pytest.mark.parametrize("fitter", ["fit_tabulated", "fit_ggx_diffuse", "fit_sgd"])
def test_public_fitting_functions_run_with_one_blas_thread(fitter, monkeypatch):
    """Called directly from Python (not through the registry), as the README shows."""
    import brdffit
    from brdffit.synthetic import synthetic

    reference = synthetic("gold-ggx")
    seen = []

    class Spy(type(reference)):
        def eval(self, wi, wo):
            seen.append(_blas_threads())
            return super().eval(wi, wo)

    reference.__class__ = Spy
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")          # not the CLI's environment
    getattr(brdffit, fitter)(reference)
    assert seen and all(t and all(n == 1 for n in t) for t in seen), seen[:3]


def test_cli_environment_is_one_thread_unless_the_user_chose():
    code = ("import os, sys\n"
            "from brdffit._blas import single_thread_env, ENV_VARS\n"
            "done = single_thread_env()\n"
            "import numpy\n"
            "print(__import__('json').dumps([done, single_thread_env(), "
            "{v: os.environ.get(v) for v in ENV_VARS}]))")
    env = {k: v for k, v in os.environ.items() if not k.endswith("_THREADS")}
    env["MKL_NUM_THREADS"] = "4"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True, timeout=60).stdout
    done, again, values = json.loads(out)
    assert done is True and again is False                   # after NumPy: too late, no-op
    assert values["OPENBLAS_NUM_THREADS"] == "1" and values["MKL_NUM_THREADS"] == "4"
