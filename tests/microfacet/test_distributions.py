"""Beckmann and GGX slope distributions: normalisation, sampling, Smith G1, moments, scaling.

Reference values are computed independently (quadrature, Monte Carlo, textbook scalar
formulas), never copied from the code under test.
"""

import math

import numpy as np
import pytest

from brdffit.geometry import normal_to_slope, slope_to_normal
from brdffit.microfacet import (GGX, Beckmann, ScaledDistribution, g1_numerical,
                                sigma_numerical)
from brdffit.testing.chi2 import ChiSquareTest, check_sampling, pdf_integral

DISTS = [
    Beckmann(0.3), GGX(0.3),
    Beckmann(0.12, 0.45, 0.6), GGX(0.12, 0.45, -0.6),
    GGX(0.8, 0.25, 0.3), Beckmann(0.05, 0.08, -0.2),
]
IDS = [repr(d) for d in DISTS]


def _hemisphere_rule(n_t=96, n_p=128):
    """Gauss-Legendre in θ (mapped t = θ²... plain) × trapezoid in φ over the hemisphere."""
    x, w = np.polynomial.legendre.leggauss(n_t)
    # θ = (π/2) v², v in (0,1): clusters nodes near the pole for sharp lobes
    v = 0.5 * (x + 1.0)
    wv = 0.5 * w
    theta = 0.5 * np.pi * v * v
    wt = wv * np.pi * v * np.sin(theta)
    phi = (np.arange(n_p) + 0.5) * 2 * np.pi / n_p
    T, P = np.meshgrid(theta, phi, indexing="ij")
    W = wt[:, None] * (2 * np.pi / n_p)
    m = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    return m, np.broadcast_to(W, T.shape)


def _random_dirs(rng, n):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize("d", DISTS, ids=IDS)
def test_slope_pdf_and_ndf_are_normalised(d):
    # ∫ P ds = 1 in polar slope coordinates r = tan-mapped
    x, w = np.polynomial.legendre.leggauss(200)
    v = 0.5 * (x + 1) * (np.pi / 2)
    wv = 0.5 * w * (np.pi / 2)
    r = np.tan(v)
    jr = wv / np.cos(v) ** 2 * r
    psi = (np.arange(256) + 0.5) * 2 * np.pi / 256
    S = np.stack([r[:, None] * np.cos(psi), r[:, None] * np.sin(psi)], -1)
    total = np.sum(d.pdf(S) * jr[:, None]) * 2 * np.pi / 256
    assert total == pytest.approx(1.0, abs=2e-3)
    # ∫ D(m) cos θm dm = 1 (Dupuy Eq. 4)
    m, W = _hemisphere_rule(160, 256)
    assert np.sum(d.D(m) * m[..., 2] * W) == pytest.approx(1.0, abs=3e-3)


@pytest.mark.parametrize("d", DISTS, ids=IDS)
def test_ndf_matches_eq7(d):
    rng = np.random.default_rng(3)
    m = _random_dirs(rng, 500)
    ref = d.pdf(normal_to_slope(m)) / m[:, 2] ** 4
    np.testing.assert_allclose(d.D(m), ref, rtol=1e-10, atol=1e-300)
    assert np.all(d.D(m * [1, 1, -1]) == 0)


class _NormalSampler:
    """Slope sampling seen as a direction sampler: m ~ D(m) cos θm."""

    def __init__(self, d):
        self.d = d

    def sample(self, wi, u):
        m = slope_to_normal(self.d.sample(u))
        return m, self.pdf(wi, m)

    def pdf(self, wi, m):
        return self.d.D(m) * np.maximum(np.asarray(m)[..., 2], 0)


class _VisibleSampler(_NormalSampler):
    def sample(self, wi, u):
        m = self.d.sample_visible(wi, u)
        return m, self.pdf(wi, m)

    def pdf(self, wi, m):
        return self.d.pdf_visible(wi, m)


CHI2_DISTS = [Beckmann(0.3), GGX(0.3), Beckmann(0.15, 0.5, 0.6), GGX(0.15, 0.5, -0.6)]


@pytest.mark.parametrize("d", CHI2_DISTS, ids=[repr(d) for d in CHI2_DISTS])
def test_slope_sampling_chi2(d):
    r = ChiSquareTest(_NormalSampler(d), [0, 0, 1], sample_count=40_000, res_theta=16,
                      res_phi=32).run()
    print(repr(d), r)
    assert r.passed, str(r)


@pytest.mark.parametrize("d", CHI2_DISTS, ids=[repr(d) for d in CHI2_DISTS])
def test_visible_normal_sampling_chi2_and_normalisation(d):
    wis = [[0, 0, 1], [math.sin(1.0), 0, math.cos(1.0)],
           [math.sin(1.45) * math.cos(2.0), math.sin(1.45) * math.sin(2.0), math.cos(1.45)]]
    ok, res = check_sampling(_VisibleSampler(d), wis, sample_count=40_000, res_theta=16,
                             res_phi=32)
    for r in res:
        print(repr(d), r)
        assert abs(r.pdf_integral - 1.0) < 2e-3           # VNDF normalisation
    assert ok


def test_g1_closed_form_matches_numerical_integration():
    rng = np.random.default_rng(7)
    w = np.concatenate([_random_dirs(rng, 60),
                        [[0, 0, 1], [math.sin(1.5), 0, math.cos(1.5)],
                         [math.sin(1.56) * 0.6, math.sin(1.56) * 0.8, math.cos(1.56)]]])
    worst = 0.0
    for d in DISTS:
        g_closed = d.G1(w)
        g_num = g1_numerical(d, w)
        err = np.max(np.abs(g_num - g_closed) / g_closed)
        print(f"{d!r}: max relative error of G1 vs numerical Eq. 3 = {err:.3g}")
        worst = max(worst, err)
    print(f"max relative error of G1 over all distributions: {worst:.3g}")
    assert worst < 1e-6


def test_g1_textbook_isotropic_formulas():
    th = np.linspace(0.05, 1.55, 30)
    w = np.stack([np.sin(th), 0 * th, np.cos(th)], -1)
    a = 0.37
    lam_ggx = (-1 + np.sqrt(1 + a * a * np.tan(th) ** 2)) / 2
    np.testing.assert_allclose(GGX(a).Lambda(w), lam_ggx, rtol=1e-12)
    nu = 1 / (a * np.tan(th))
    lam_b = np.array([(math.erf(v) - 1) / 2 + math.exp(-v * v) / (2 * v * math.sqrt(math.pi))
                      for v in nu])
    np.testing.assert_allclose(Beckmann(a).Lambda(w), lam_b, rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("d", DISTS, ids=IDS)
def test_sigma_identities(d):
    rng = np.random.default_rng(11)
    w = _random_dirs(rng, 200)
    # σ(w) − σ(−w) = w_z (projected area of the microsurface = that of the mean plane)
    np.testing.assert_allclose(d.sigma(w) - d.sigma(-w), w[:, 2], atol=1e-12)
    # below-horizon closed form agrees with direct integration too
    wb = w * [1, 1, -1]
    np.testing.assert_allclose(sigma_numerical(d, wb), d.sigma(wb), rtol=1e-6, atol=1e-12)
    assert np.all(d.G1(wb) == 0)


def test_height_correlated_g2_bounds():
    rng = np.random.default_rng(5)
    wi, wo = _random_dirs(rng, 300), _random_dirs(rng, 300)
    d = GGX(0.5, 0.2, 0.4)
    g2 = d.G2(wi, wo)
    g1g1 = d.G1(wi) * d.G1(wo)
    assert np.all(g2 >= g1g1 - 1e-15) and np.all(g2 <= np.minimum(d.G1(wi), d.G1(wo)) + 1e-15)


@pytest.mark.parametrize("d", DISTS, ids=IDS)
def test_slope_moments_vs_monte_carlo(d):
    u = np.random.default_rng(2).random((200_000, 2))
    s = d.sample(u)
    m = d.slope_moments()
    n = len(s)
    for key, vals in (("E|x|", np.abs(s[:, 0])), ("E|y|", np.abs(s[:, 1]))):
        if isinstance(d, GGX):   # heavy tail: compare a robust quantity instead of the mean SE
            tol = 6 * np.std(np.minimum(vals, 50 * m[key])) / np.sqrt(n) + 0.01 * m[key]
        else:
            tol = 6 * np.std(vals) / np.sqrt(n)
        assert abs(vals.mean() - m[key]) < tol, key
    r2 = np.sum(s * s, -1)
    for key, vals in (("b1", s[:, 0] * s[:, 1] / r2), ("b2", s[:, 1] ** 2 / r2)):
        assert abs(vals.mean() - m[key]) < 6 * vals.std() / np.sqrt(n), key
    if isinstance(d, Beckmann):
        for key, vals in (("Exx", s[:, 0] ** 2), ("Eyy", s[:, 1] ** 2),
                          ("Exy", s[:, 0] * s[:, 1])):
            assert abs(vals.mean() - m[key]) < 6 * vals.std() / np.sqrt(n), key
        back = Beckmann.from_slope_moments(m)
    else:
        assert np.isinf(m["Exx"]) and np.isinf(m["Eyy"])
        back = GGX.from_slope_moments(m)
    np.testing.assert_allclose([back.alpha_x, back.alpha_y, back.rho],
                               [d.alpha_x, d.alpha_y, d.rho], rtol=1e-9, atol=1e-12)


def test_scale_matrix_convention():
    """Beckmann samples have covariance S/2 with S = [[αx², ραxαy], [ραxαy, αy²]]."""
    ax, ay, rho = 0.2, 0.5, 0.7
    s = Beckmann(ax, ay, rho).sample(np.random.default_rng(0).random((200_000, 2)))
    cov = np.cov(s.T)
    S = np.array([[ax * ax, rho * ax * ay], [rho * ax * ay, ay * ay]])
    np.testing.assert_allclose(cov, S / 2, rtol=0.02, atol=2e-4)


@pytest.mark.parametrize("d", [Beckmann(0.3), GGX(0.2, 0.4, 0.3)], ids=["beckmann", "ggx"])
def test_roughness_scaling_eq9(d):
    ax, ay = 0.6, 1.7
    ds = d.scaled(ax, ay)
    generic = ScaledDistribution(d, ax, ay)
    rng = np.random.default_rng(9)
    m = _random_dirs(rng, 300)
    sl = normal_to_slope(m)
    ref = d.pdf(sl / [ax, ay]) / (ax * ay) / m[:, 2] ** 4            # Dupuy Eq. 9
    np.testing.assert_allclose(ds.D(m), ref, rtol=1e-10, atol=1e-300)
    np.testing.assert_allclose(generic.D(m), ref, rtol=1e-10, atol=1e-300)
    # G1 roughness invariance (stretch): generic wrapper vs closed form of the scaled law
    w = _random_dirs(rng, 300)
    np.testing.assert_allclose(generic.G1(w), ds.G1(w), rtol=1e-10)
    np.testing.assert_allclose(generic.pdf_visible(w, m), ds.pdf_visible(w, m), rtol=1e-9)
    assert ds.scaled(1 / ax, 1 / ay).params() == pytest.approx(d.params())


def test_generic_scaled_method_of_the_base_class():
    from brdffit.microfacet.base import SlopeDistribution

    class Plain(SlopeDistribution):           # only pdf/sample/Lambda (unit isotropic GGX)
        def pdf(self, s):
            return GGX(1.0).pdf(s)

        def sample(self, u):
            return GGX(1.0).sample(u)

        def Lambda(self, w):
            return GGX(1.0).Lambda(w)

    d = Plain().scaled(0.3, 0.5)
    assert isinstance(d, ScaledDistribution)
    w = _random_dirs(np.random.default_rng(0), 50)
    np.testing.assert_allclose(d.G1(w), GGX(0.3, 0.5).G1(w), rtol=1e-12)
    np.testing.assert_allclose(d.D(w), GGX(0.3, 0.5).D(w), rtol=1e-12)


def test_scaled_visible_sampling_chi2():
    d = ScaledDistribution(GGX(0.5), 0.4, 1.2)
    ok, res = check_sampling(_VisibleSampler(d), [[0.5, 0.3, 0.81]], sample_count=30_000,
                             res_theta=16, res_phi=32)
    assert ok, [str(r) for r in res]


@pytest.mark.parametrize("cls", [GGX, Beckmann])
@pytest.mark.parametrize("args", [(0.0,), (-0.1,), (0.1, 0.0), (0.1, 0.2, 1.0),
                                  (0.1, 0.2, -1.5), (float("nan"),), ("abc",)])
def test_constructor_validation(cls, args):
    with pytest.raises(ValueError, match="alpha|rho|real|finite"):
        cls(*args)


def test_isotropy_flag_and_params():
    assert GGX(0.2).isotropic and not GGX(0.2, 0.3).isotropic
    assert not Beckmann(0.2, 0.2, 0.1).isotropic
    assert GGX(0.2, 0.3, 0.1).params() == {"alpha_x": 0.2, "alpha_y": 0.3, "rho": 0.1}
    assert pdf_integral(_NormalSampler(GGX(0.4)), [0, 0, 1]) == pytest.approx(1.0, abs=2e-3)


from hypothesis import given, settings, strategies as st  # noqa: E402


@settings(max_examples=40, deadline=None)
@given(ax=st.floats(0.02, 2.0), ay=st.floats(0.02, 2.0), rho=st.floats(-0.95, 0.95),
       theta=st.floats(0.0, 1.56), phi=st.floats(0.0, 6.28), beck=st.booleans())
def test_visible_normals_are_visible_and_g1_bounded(ax, ay, rho, theta, phi, beck):
    d = (Beckmann if beck else GGX)(ax, ay, rho)
    w = np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                  math.cos(theta)])
    u = np.random.default_rng(0).random((256, 2))
    m = d.sample_visible(w, u)
    assert np.all(np.isfinite(m))
    np.testing.assert_allclose(np.linalg.norm(m, axis=-1), 1.0, atol=1e-12)
    assert np.all(m[:, 2] >= 0) and np.all(m @ w >= -1e-12)
    g = d.G1(w)
    assert 0.0 < g <= 1.0
    assert d.sigma(w) - d.sigma(-w) == pytest.approx(w[2], abs=1e-12)


@pytest.mark.parametrize("alpha", [0.005, 0.05, 0.5])
def test_beckmann_lambda_cutoff_leaves_shadowing_unchanged(alpha):
    """Beckmann Λ is set to 0 from a = LAMBDA_ZERO_A on (skipping erfc/exp): there the
    closed form is below 2.3e-17, so Λ differs by < 1e-18 and G2 = 1/(1 + Λi + Λo) is
    bit-identical to the closed form everywhere."""
    from scipy import special

    from brdffit.microfacet import Beckmann
    from brdffit.microfacet.beckmann import LAMBDA_ZERO_A

    d = Beckmann(alpha)
    rng = np.random.default_rng(3)
    w = rng.normal(size=(50_000, 3))
    w[:, 2] = np.abs(w[:, 2])
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    a = w[:, 2] / np.sqrt(d._quad(w[:, 0], w[:, 1]))
    closed = 0.5 * (np.exp(-a * a) / (a * np.sqrt(np.pi)) - special.erfc(a))
    lam = d._lambda_upper(w[:, 0], w[:, 1], w[:, 2])
    assert np.any(a >= LAMBDA_ZERO_A) and np.any(a < LAMBDA_ZERO_A)
    np.testing.assert_array_equal(lam[a < LAMBDA_ZERO_A], closed[a < LAMBDA_ZERO_A])
    assert np.max(np.abs(lam - closed)) < 1e-18
    np.testing.assert_array_equal(1.0 / (1.0 + lam[:-1] + lam[1:]),
                                  1.0 / (1.0 + closed[:-1] + closed[1:]))


@pytest.mark.parametrize("cls", [GGX, Beckmann])
@pytest.mark.parametrize("alpha", [0.004, 0.2, 1.7])
def test_isotropic_shortcuts_equal_D_and_Lambda(cls, alpha):
    """``D_cos4(tan²θm)`` is ``D(m) cos⁴θm`` and ``Lambda_of_tan(tan θ)`` is ``Λ(w)`` for
    normals / directions of any azimuth of an isotropic distribution (the fits' fast path);
    an anisotropic distribution refuses both."""
    rng = np.random.default_rng(11)
    d = cls(alpha)
    w = _random_dirs(rng, 20_000)
    w = w[w[:, 2] > 1e-3]
    tan2 = (w[:, 0] ** 2 + w[:, 1] ** 2) / w[:, 2] ** 2
    np.testing.assert_allclose(d.D_cos4(tan2), d.D(w) * w[:, 2] ** 4, rtol=1e-11, atol=1e-300)
    np.testing.assert_allclose(d.Lambda_of_tan(np.sqrt(tan2)), d.Lambda(w), rtol=1e-12,
                               atol=1e-300)
    assert d.Lambda_of_tan(0.0) == 0.0
    for aniso in (cls(alpha, 2 * alpha), cls(alpha, alpha, 0.3)):
        with pytest.raises(ValueError, match="isotropic"):
            aniso.D_cos4(tan2)
        with pytest.raises(ValueError, match="isotropic"):
            aniso.Lambda_of_tan(tan2)
