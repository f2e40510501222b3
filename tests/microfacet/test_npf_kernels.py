"""The compiled per-sample evaluation of the NPF models (``microfacet/_npf_kernels.py``)
against their NumPy ``eval_hd``."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit._jit
from brdffit.microfacet import _npf_kernels
from tests.fit.test_npf_model import make_models


def _angles(n=20000, seed=4):
    """Angles in and beyond their ranges, with NaN and infinities."""
    rng = np.random.default_rng(seed)
    th = rng.uniform(-0.2, np.pi / 2 + 0.2, n)
    td = rng.uniform(-0.2, np.pi / 2 + 0.2, n)
    pd = rng.uniform(-7.0, 7.0, n)
    th[:5], td[5:10], pd[10:15], th[15:20] = np.nan, np.inf, -np.inf, np.pi / 2
    return th, td, pd


@pytest.mark.parametrize("which", [0, 1, 2], ids=["independent-g", "naive", "bivariate"])
def test_compiled_eval_hd_matches_numpy(which, monkeypatch):
    if _npf_kernels._numba is None:
        pytest.skip("numba not installed: only the NumPy path exists")
    model = make_models()[which]
    th, td, pd = _angles()
    monkeypatch.setattr(brdffit._jit, "COMPILE_AFTER", -1)      # compiled from the first call
    with np.errstate(all="ignore"):
        compiled = model.eval_hd(th, td, pd)
        kernel = (_npf_kernels.microfacet_hd, _npf_kernels.naive_hd,
                  _npf_kernels.bivariate_hd)[which]
        assert kernel._dispatcher is not None and kernel.signatures  # the compiled path ran
        monkeypatch.setattr(_npf_kernels, "_numba", None)       # the NumPy path
        reference = model.eval_hd(th, td, pd)
    assert compiled.shape == reference.shape == (th.size, 3)
    assert np.all(np.isfinite(compiled))
    assert np.all(compiled[:15] == 0) and np.all(reference[:15] == 0)   # non-finite angles
    np.testing.assert_allclose(compiled, reference, rtol=1e-13, atol=0)
    assert np.any(compiled > 0)


def test_compiled_eval_hd_broadcasts(monkeypatch):
    if _npf_kernels._numba is None:
        pytest.skip("numba not installed: only the NumPy path exists")
    monkeypatch.setattr(brdffit._jit, "COMPILE_AFTER", -1)
    model = make_models()[0]
    th = np.linspace(0, 1.4, 7)[:, None]
    out = model.eval_hd(th, np.linspace(0, 1.4, 5)[None, :], 0.3)
    monkeypatch.setattr(_npf_kernels, "_numba", None)
    assert out.shape == (7, 5, 3)
    np.testing.assert_allclose(out, model.eval_hd(th, np.linspace(0, 1.4, 5)[None, :], 0.3),
                               rtol=1e-13)


def test_numpy_eval_hd_of_nan_angles_is_zero(monkeypatch):
    monkeypatch.setattr(_npf_kernels, "_numba", None)
    for model in make_models():
        with np.errstate(all="ignore"):
            out = model.eval_hd(np.array([np.nan, 0.2]), np.array([0.1, np.nan]), 0.0)
        assert np.all(out == 0)
