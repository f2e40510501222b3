"""Upper incomplete gamma Γ(s, x) for all real s against mpmath (Bagher 2012 §4.2 needs s ≤ 0)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import special

from brdffit.microfacet.gamma import upper_gamma, upper_gamma_ratio

mpmath = pytest.importorskip("mpmath")


def _ref(s, x):
    with mpmath.workdps(30):
        return float(mpmath.gammainc(mpmath.mpf(float(s)), mpmath.mpf(float(x))))


def test_grid_against_mpmath():
    # s ∈ [−4, 2] incl. integers, near-integers (poles of Γ(s)) and near 0; x ∈ [1e-4, 50]
    S = np.concatenate([np.linspace(-4, 2, 25), [-3.0000001, -0.9999999, -1e-9, 1e-9, 0.4999]])
    X = np.concatenate([np.geomspace(1e-4, 50, 24), [1.9999999, 2.0000001]])
    s, x = np.meshgrid(S, X, indexing="ij")
    got = upper_gamma(s, x)
    ref = np.vectorize(_ref)(s, x)
    rel = np.abs(got - ref) / np.abs(ref)
    assert np.all(np.isfinite(got))
    assert rel.max() < 1e-10, (s.ravel()[rel.argmax()], x.ravel()[rel.argmax()], rel.max())


def test_scipy_returns_nan_where_we_do_not():
    # the reason this module exists: the regularised scipy function is undefined for s < 0
    assert np.isnan(special.gammaincc(-1.5, 0.3))
    assert np.isfinite(upper_gamma(-1.5, 0.3))


def test_recurrence_and_special_values():
    x = np.geomspace(1e-3, 30, 50)
    for s in (-2.7, -1.3, -0.4, 0.2):
        # Γ(s+1, x) = s Γ(s, x) + x^s e^{−x}
        lhs = upper_gamma(s + 1, x)
        rhs = s * upper_gamma(s, x) + x**s * np.exp(-x)
        np.testing.assert_allclose(lhs, rhs, rtol=1e-11)
    np.testing.assert_allclose(upper_gamma(0.0, x), special.exp1(x), rtol=1e-13)
    np.testing.assert_allclose(upper_gamma(1.0, x), np.exp(-x), rtol=1e-13)
    assert upper_gamma(-1.0, 0.0) == np.inf
    assert upper_gamma(2.5, 0.0) == pytest.approx(special.gamma(2.5))
    assert np.isnan(upper_gamma(1.0, -1.0))


def test_broadcast_and_ratio():
    s = np.array([-2.0, -0.5, 1.5])[:, None]
    x = np.array([0.1, 1.0, 5.0])[None, :]
    assert upper_gamma(s, x).shape == (3, 3)
    r = upper_gamma_ratio(-1.2, np.array([0.05, 1.0, 10.0]), 0.05)
    assert r[0] == pytest.approx(1.0) and np.all(np.diff(r) < 0) and r[-1] > 0


def test_scalar_path_matches_array_path():
    S = np.array([-3.7, -2.0, -1.0000001, -0.3, 0.0, 1e-9, 0.3, 1.7])
    X = np.array([1e-4, 0.05, 1.0, 2.0, 2.5, 40.0])
    arr = upper_gamma(S[:, None], X[None, :])
    sca = np.array([[float(upper_gamma(float(a), float(b))) for b in X] for a in S])
    np.testing.assert_allclose(sca, arr, rtol=1e-12)
