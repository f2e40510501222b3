"""Shifted Gamma Distribution (Bagher, Soler, Holzschuch 2012 §4.2-4.5)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, special, stats

from brdffit.microfacet.sgd import SGD, g1_eq9, sgd_mu_lambda

CASES = [(0.01, 2.0), (0.002, 2.5), (0.05, 1.2), (0.3, 0.5), (0.5, -1.0), (0.1, 1.0)]


def _radial_integral(d, fn):
    """∫_0^∞ fn(x) π P(x) dx in u = ln x with scipy.quad (independent of the module)."""
    a = d.alpha
    f = lambda u: fn(np.exp(u)) * np.pi * d.pdf(np.array([np.sqrt(np.exp(u)), 0.0])) * np.exp(u)
    lo, hi = np.log(1e-16 * min(a, a * a)), np.log(a * 120.0 + 1.0)
    pts = np.log([a * a * 1e-3, a * a, a, 10 * a])
    val, _ = integrate.quad(f, lo, hi, points=sorted(p for p in pts if lo < p < hi), limit=400,
                            epsabs=0, epsrel=1e-12)
    return val


@pytest.mark.parametrize("alpha,p", CASES)
def test_normalisation_integral_of_D_cos_is_one(alpha, p):
    d = SGD(alpha, p)
    assert _radial_integral(d, lambda x: 1.0) == pytest.approx(1.0, abs=1e-9)
    # and directly on the hemisphere ∫ D(θ) cos θ dω (θ quadrature, graded near the peak)
    th = np.concatenate([[0.0], np.geomspace(1e-7, np.pi / 2 - 1e-9, 400001)])
    val = np.trapezoid(2 * np.pi * d.D_theta(th) * np.cos(th) * np.sin(th), th)
    assert val == pytest.approx(1.0, abs=2e-4)


def test_pdf_matches_paper_formula():
    # §4.2: P22(x) = α^{p−1}/Γ(1−p, α) · e^{−(α²+x)/α} / (α²+x)^p with mpmath's Γ(s, a)
    mpmath = pytest.importorskip("mpmath")
    a, p = 0.07, 1.8
    d = SGD(a, p)
    G = float(mpmath.gammainc(1 - p, a))
    x = np.array([0.0, 1e-4, 0.01, 0.3, 2.0])
    ref = a ** (p - 1) / G * np.exp(-(a * a + x) / a) / (a * a + x) ** p
    np.testing.assert_allclose(d.p22(x), ref, rtol=1e-12)
    np.testing.assert_allclose(d.pdf(np.stack([np.sqrt(x), 0 * x], -1)), ref / np.pi, rtol=1e-12)
    m = np.stack([np.sin(np.arctan(np.sqrt(x))), 0 * x, np.cos(np.arctan(np.sqrt(x)))], -1)
    np.testing.assert_allclose(d.D(m), ref / np.pi / m[:, 2] ** 4, rtol=1e-12)


@pytest.mark.parametrize("alpha,p", CASES[:4])
def test_radial_cdf_against_quadrature(alpha, p):
    d = SGD(alpha, p)
    for x in (alpha * alpha, alpha, 5 * alpha):
        direct = _radial_integral(d, lambda y, x=x: (y <= x).astype(float))
        assert d.cdf_tan2(x) == pytest.approx(direct, abs=1e-7)


@pytest.mark.parametrize("alpha,p", [(0.01, 2.0), (0.3, 0.5), (0.5, -1.0)])
def test_sampling_follows_pdf(alpha, p):
    d = SGD(alpha, p)
    rng = np.random.default_rng(7)
    s = d.sample(rng.random((40000, 2)))
    assert np.all(np.isfinite(s))
    # the radius against the radial CDF of §4.5 (KS), the azimuth uniform
    x = (s**2).sum(-1)
    assert stats.kstest(x, d.cdf_tan2).pvalue > 1e-3
    phi = np.mod(np.arctan2(s[:, 1], s[:, 0]), 2 * np.pi)
    assert stats.kstest(phi / (2 * np.pi), "uniform").pvalue > 1e-3
    # chi-square on a 2D histogram of slopes against the integrated pdf
    lim = np.quantile(np.abs(s), 0.98)
    edges = np.linspace(-lim, lim, 13)
    H, _, _ = np.histogram2d(s[:, 0], s[:, 1], bins=[edges, edges])
    c = 0.5 * (edges[1:] + edges[:-1])
    g, w = np.polynomial.legendre.leggauss(8)
    h = (edges[1] - edges[0]) / 2
    pts = (c[:, None] + h * g[None, :]).ravel()
    X, Y = np.meshgrid(pts, pts, indexing="ij")
    P = d.pdf(np.stack([X, Y], -1)).reshape(12, 8, 12, 8)
    E = np.einsum("iajb,a,b->ij", P, w, w) * h * h * len(s)
    keep = E > 20
    chi2 = np.sum((H[keep] - E[keep]) ** 2 / E[keep])
    assert stats.chi2.sf(chi2, keep.sum() - 1) > 1e-3


def test_inverse_cdf_table_accuracy():
    d = SGD(0.004, 2.2)
    u = np.linspace(1e-5, 1 - 1e-8, 2001)
    x = d.alpha * (d._invert_t(u) - d.alpha)
    assert np.max(np.abs(d.cdf_tan2(x) - u)) < 1e-7
    x2 = d.alpha * (d._invert_t(u, refine=True) - d.alpha)
    assert np.max(np.abs(d.cdf_tan2(x2) - u)) < 1e-11


def _mu_lambda_eq6_hyperu(alpha, p, mu):
    """Eq. 6 as printed: ∫_μ^∞ (r − μ) P2(r) dr with the §4.3 closed form of P2 (Tricomi U)."""
    G = float(special.gamma(1 - p) * special.gammaincc(1 - p, alpha)) if p < 1 else None
    if G is None:
        from brdffit.microfacet.gamma import upper_gamma
        G = float(upper_gamma(1 - p, alpha))
    P2 = lambda r: special.hyperu(p, p + 0.5, alpha + r * r / alpha) * np.exp(-alpha - r * r / alpha) \
        / (np.sqrt(np.pi * alpha) * G)
    s = np.sqrt(alpha)
    val, _ = integrate.quad(lambda r: (r - mu) * P2(r), mu, mu + 40 * s, points=[mu + alpha, mu + s],
                            limit=400, epsabs=0, epsrel=1e-11)
    return val


@pytest.mark.parametrize("alpha,p", [(0.01, 2.0), (0.3, 0.5), (0.2, -1.0)])
def test_lambda_quadrature_against_eq6_closed_form_marginal(alpha, p):
    d = SGD(alpha, p)
    mu = np.array([0.02, 0.1, 0.3, 0.6])
    ref = np.array([_mu_lambda_eq6_hyperu(alpha, p, m) for m in mu])
    keep = ref > 1e-200
    np.testing.assert_allclose(d.mu_lambda_exact(mu)[keep], ref[keep], rtol=1e-7)
    np.testing.assert_allclose(sgd_mu_lambda(mu, alpha, p)[keep], ref[keep], rtol=1e-7)


def test_direct_integrand_of_mu_lambda_agrees_with_the_small_z_series():
    """``small_z_series=False`` (the fits' G1) keeps ≈ 1e-13 relative accuracy over random
    (α, p, μ), μ = 0 and the μ² → 745 α end where the integrand peaks at small z."""
    rng = np.random.default_rng(7)
    for _ in range(150):
        alpha, p = 10 ** rng.uniform(-4, 0.45), rng.uniform(-2, 4)
        mu = np.concatenate([[0.0, np.sqrt(700 * alpha)], 10 ** rng.uniform(-6, 1.5, 60)])
        for h in (0.3, 0.2):
            series = sgd_mu_lambda(mu, alpha, p, h)
            direct = sgd_mu_lambda(mu, alpha, p, h, small_z_series=False)
            keep = series > 1e-290
            assert np.all(direct[~keep] < 1e-280)
            np.testing.assert_allclose(direct[keep], series[keep], rtol=5e-13)


def test_eq9_jacobian_matches_finite_differences():
    from brdffit.microfacet.sgd import _g1_eq9_jacobian

    theta = np.linspace(0.0, np.pi / 2, 257)
    for lam, w, k in ((0.05, 0.3, 3.0), (2.0, 0.8, 1.5), (0.3, 0.05, 8.0), (1e-3, 1.2, 0.7)):
        q = np.log([lam, w, k])

        def model(q):
            lam_, w_, k_ = np.exp(q)
            return g1_eq9(theta, lam_, np.log1p(1.0 / lam_) / w_**k_, k_)

        step = 1e-7
        fd = np.stack([(model(q + e * step) - model(q - e * step)) / (2 * step)
                       for e in np.eye(3)], axis=1)
        np.testing.assert_allclose(_g1_eq9_jacobian(theta, q), fd, atol=1e-6)


@pytest.mark.parametrize("alpha,p", [(0.01, 2.0), (0.05, 1.2), (0.4, 0.3)])
def test_g1_table_against_direct_integration_of_dupuy_eq3(alpha, p):
    # Independent check: σ(w) = ∫ <w,m>+ D(m) dm by the generic numerical integrator of
    # microfacet.shadowing (Dupuy 2015 Eq. 3), G1 = cos θ / σ.
    from brdffit.microfacet.shadowing import g1_numerical

    d = SGD(alpha, p)
    theta = np.array([0.3, 1.0, 1.3, 1.5, 1.55])
    w = np.stack([np.sin(theta), 0 * theta, np.cos(theta)], -1)
    ref = g1_numerical(d, w)
    got = d.G1(w)
    np.testing.assert_allclose(got, ref, atol=2e-6)
    np.testing.assert_allclose(d.G1_theta(theta), got, rtol=1e-12)
    # table (spline) vs exact quadrature over the whole range
    th, g = d.g1_table(257)
    assert np.max(np.abs(d.G1_theta(th) - g)) < 1e-7
    assert g[0] == pytest.approx(1.0) and g[-1] == 0.0 and np.all(np.diff(g) <= 1e-15)


def test_lambda_grazing_limit_is_first_moment():
    # Λ(μ) → E|x̃| / (2μ) as μ → 0 (E over the 1D marginal of |x̃|)
    d = SGD(0.03, 1.5)
    m = d.slope_moments()
    mu = 1e-6
    assert d.mu_lambda(mu) == pytest.approx(m["E|x|"] / 2, rel=1e-4)


def test_g1_approximation_eq9():
    d = SGD(0.01, 2.0)
    ap = d.g1_approximation()
    th, g = d.g1_table(512)
    approx = g1_eq9(th, ap["lambda"], ap["c"], ap["k"])
    assert np.sqrt(np.mean((approx - g) ** 2)) == pytest.approx(ap["rms"], rel=1e-9)
    assert ap["mse"] < 1e-5 and ap["max_abs"] < 0.02
    assert g1_eq9(np.pi / 2 - 1e-12, ap["lambda"], ap["c"], ap["k"]) < 1e-3
    assert ap["theta0"] == pytest.approx(
        np.pi / 2 - (np.log1p(1 / ap["lambda"]) / ap["c"]) ** (1 / ap["k"]), rel=1e-9)


@pytest.mark.parametrize("alpha,p", [(0.01, 2.0), (0.5, -1.0)])
def test_slope_moments(alpha, p):
    d = SGD(alpha, p)
    m = d.slope_moments()
    assert m["Exx"] == pytest.approx(d.second_moment_closed_form() / 2, rel=1e-9)
    # Monte Carlo cross-check through the sampler
    s = d.sample(np.random.default_rng(3).random((200000, 2)))
    assert np.mean(np.abs(s[:, 0])) == pytest.approx(m["E|x|"], rel=0.02)
    assert m["Exy"] == 0.0


def test_validation():
    for a, p in [(0.0, 1.0), (-0.1, 1.0), (np.nan, 1.0), (0.1, np.inf)]:
        with pytest.raises(ValueError):
            SGD(a, p)
    d = SGD(0.1, 1.5)
    assert d.params() == {"alpha": 0.1, "p": 1.5}
    assert d.D(np.array([0.0, 0.0, -1.0])) == 0.0
    assert d.G1(np.array([1.0, 0.0, 0.0])) == 0.0


# A mirror-like channel of the MERL chrome SGD fit: Eq. 9 wants k at its bound and c ~ 1e17,
# which the fit-file schema once refused (chrome, chrome-steel, tungsten-carbide had no SGD fit).
SHARP = (0.0026943, 1.34819)


def test_g1_approximation_of_a_mirror_like_sgd_is_saved_and_loaded(tmp_path):
    from brdffit.microfacet.sgd_model import PerChannelMicrofacetBRDF
    from brdffit.io.fitfile import load_fit, save_fit
    from brdffit.microfacet.sgd import EQ9_C_MAX

    d = SGD(*SHARP)
    ap = d.g1_approximation(n=256)
    assert 1e15 < ap["c"] <= EQ9_C_MAX and ap["max_abs"] < 1e-3
    model = PerChannelMicrofacetBRDF(
        [dict(distribution=d, rho_d=0.01, rho_s=0.5, F0=0.9, F1=0.0) for _ in range(3)],
        g1_approx=[ap] * 3, g1="approx")
    save_fit(model, tmp_path / "chrome.npz")
    back = load_fit(tmp_path / "chrome.npz")
    assert back.g1_approx[0]["c"] == ap["c"]


def test_g1_approximation_caps_c_and_stays_close(monkeypatch):
    """When every start wants c above the cap, k is capped so c stays representable."""
    import brdffit.microfacet.sgd as sgd_mod

    monkeypatch.setattr(sgd_mod, "EQ9_C_MAX", 1e8)
    d = SGD(*SHARP)
    ap = d.g1_approximation(n=256)
    assert np.isfinite(ap["c"]) and 0 < ap["c"] <= 1e8
    assert ap["max_abs"] < 0.05
