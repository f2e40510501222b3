"""Fresnel terms: limits, agreement between exact forms, Schlick family, tabulation."""

import math

import numpy as np
import pytest

from brdffit.microfacet import (ConductorFresnel, DielectricFresnel, GeneralizedSchlickFresnel,
                                SchlickFresnel, TabulatedFresnel)
from brdffit.microfacet.fresnel import GOLD_ETA, GOLD_K


def _dielectric_polarised(eta, c):
    """Textbook s/p amplitudes with Snell's law (independent of the implementation)."""
    s = math.sqrt(1 - c * c)
    st = s / eta
    if st >= 1:
        return 1.0
    ct = math.sqrt(1 - st * st)
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return 0.5 * (rs * rs + rp * rp)


@pytest.mark.parametrize("eta", [1.2, 1.5, 2.4, 0.67])
def test_dielectric_matches_snell(eta):
    cs = np.linspace(0.001, 1.0, 50)
    ref = np.array([_dielectric_polarised(eta, c) for c in cs])
    np.testing.assert_allclose(DielectricFresnel(eta).eval(cs)[:, 1], ref, rtol=1e-10, atol=1e-12)


def test_limits_normal_and_grazing():
    cases = [
        (SchlickFresnel([0.04, 0.5, 0.9]), np.array([0.04, 0.5, 0.9])),
        (DielectricFresnel(1.5), np.full(3, ((1.5 - 1) / (1.5 + 1)) ** 2)),
        (ConductorFresnel(GOLD_ETA, GOLD_K),
         np.array([((n - 1) ** 2 + k * k) / ((n + 1) ** 2 + k * k) for n, k in zip(GOLD_ETA, GOLD_K)])),
        (GeneralizedSchlickFresnel(0.8, 0.1), np.full(3, 0.8 - 0.1)),
    ]
    for F, f0 in cases:
        np.testing.assert_allclose(F.eval(1.0), f0, rtol=1e-12, err_msg=repr(F))     # θd = 0
        np.testing.assert_allclose(F.eval(0.0), np.ones(3), atol=1e-12, err_msg=repr(F))  # 90°
        assert F.eval(np.ones((4, 5))).shape == (4, 5, 3)


def test_conductor_with_zero_k_is_dielectric():
    cs = np.linspace(0, 1, 101)
    np.testing.assert_allclose(ConductorFresnel(1.7, 0.0).eval(cs),
                               DielectricFresnel(1.7).eval(cs), atol=1e-12)


def test_conductor_matches_complex_amplitudes():
    cs = np.linspace(0.0, 1.0, 101)
    for n, k in [(0.2, 3.9), (1.5, 0.5), (1.66, 9.2), (0.5, 0.0)]:
        N = n + 1j * k
        nct = np.sqrt(N * N - (1 - cs**2))
        rs = (cs - nct) / (cs + nct)
        rp = (N * N * cs - nct) / (N * N * cs + nct)
        ref = 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)
        np.testing.assert_allclose(ConductorFresnel(n, k).eval(cs)[:, 0], ref, rtol=1e-9,
                                   atol=1e-12)


def test_conductor_is_high_and_monotone_for_gold():
    cs = np.linspace(0.02, 1, 200)
    F = ConductorFresnel(GOLD_ETA, GOLD_K).eval(cs)
    assert F[-1, 0] > F[-1, 2]                            # gold: red > blue at normal incidence
    assert np.all((F >= 0) & (F <= 1))


def test_schlick_family():
    cs = np.linspace(0, 1, 30)
    np.testing.assert_allclose(GeneralizedSchlickFresnel(0.3, 0.0).eval(cs),
                               SchlickFresnel(0.3).eval(cs), atol=1e-15)
    g = GeneralizedSchlickFresnel(0.3, 0.05).eval(cs)[:, 0]
    np.testing.assert_allclose(g, 0.3 + 0.7 * (1 - cs) ** 5 - 0.05 * cs, atol=1e-15)  # Eq. 11
    # Schlick approximates the exact dielectric (η = 1.5) to within ~0.035 absolute (known)
    ex = DielectricFresnel(1.5).eval(cs)[:, 0]
    sc = SchlickFresnel(0.04).eval(cs)[:, 0]
    assert np.max(np.abs(ex - sc)) < 0.04


def test_tabulated_interpolates_linearly_in_theta_d():
    td = np.linspace(0, np.pi / 2, 10)
    vals = np.stack([0.1 + 0.2 * td, 0.5 - 0.1 * td, np.full_like(td, 0.3)], -1)
    F = TabulatedFresnel(td, vals)
    q = np.random.default_rng(0).uniform(0, np.pi / 2, 100)
    out = F.eval(np.cos(q))
    np.testing.assert_allclose(out[:, 0], 0.1 + 0.2 * q, atol=1e-12)
    np.testing.assert_allclose(out[:, 1], 0.5 - 0.1 * q, atol=1e-12)
    params, arrays = F.to_state()
    G = TabulatedFresnel.from_state(params, arrays)
    np.testing.assert_array_equal(G.eval(np.cos(q)), out)


@pytest.mark.parametrize("make", [
    lambda: SchlickFresnel(1.5), lambda: SchlickFresnel([0.1, 0.2]),
    lambda: DielectricFresnel(-1.0), lambda: ConductorFresnel(1.0, -2.0),
    lambda: TabulatedFresnel([0.0, 0.5, 0.4], np.zeros((3, 3))),
    lambda: TabulatedFresnel([0.0, 0.5], np.zeros((3, 3))),
    lambda: GeneralizedSchlickFresnel(float("nan"), 0.0),
])
def test_validation(make):
    with pytest.raises(ValueError):
        make()


@pytest.mark.parametrize("fresnel", [
    SchlickFresnel([0.02, 0.5, 0.97]),
    GeneralizedSchlickFresnel([0.9, 0.3, 0.05], [0.2, -0.1, 0.0]),
    DielectricFresnel([1.3, 1.5, 0.8]), ConductorFresnel(GOLD_ETA, GOLD_K),
    TabulatedFresnel([0.0, 0.7, 1.5707963], [[0.1, 0.2, 0.3], [0.2, 0.3, 0.4], [1.0, 1.0, 1.0]]),
])
def test_eval_channel_is_the_channel_of_eval(fresnel):
    cos = np.random.default_rng(3).uniform(-0.2, 1.2, (7, 11))
    rgb = fresnel.eval(cos)
    for c in range(3):
        one = fresnel.eval_channel(c, cos)
        assert one.shape == cos.shape
        np.testing.assert_array_equal(one, rgb[..., c])
