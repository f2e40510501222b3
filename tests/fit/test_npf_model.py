"""NPF models (Bagher, Snyder & Nowrouzezahrai 2016): evaluation, G-from-D, sampling, size,
save/load, and the compressive objective's weights."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import erf

from brdffit.losses.objective import (ObjectiveOptions, compressive_weight,
                                          merl_grid_geometry, prepare_objective,
                                          volume_form_weight, weighted_median)
from brdffit.geometry import half_diff_to_io
from brdffit.io.fitfile import load_fit, save_fit, table_bytes
from brdffit.microfacet.npf_model import (D_THETA_H, F_THETA_D, G_THETA, H_PHI_D,
                                          NPFBivariateBRDF, NPFMicrofacetBRDF, NPFNaiveBRDF,
                                          _smith_lambda, normalise_d, smith_g_from_d,
                                          smith_g_jacobian, smith_g_curvature)


def beckmann_d(alpha):
    t = np.tan(D_THETA_H)
    return np.exp(-(t / alpha) ** 2) / (np.pi * alpha**2 * np.cos(D_THETA_H) ** 4)


def example_factors(rng=None):
    al = np.array([0.2, 0.3, 0.45])
    D = np.stack([beckmann_d(a) for a in al], 1)
    D = D / D.max(0) + 1e-3
    F = 0.4 + 0.6 * (1 - np.cos(F_THETA_D))[:, None] ** 5 * np.array([1.0, 0.8, 0.6])
    G = (1 - 0.4 * (G_THETA / G_THETA[-1]) ** 2)[:, None] * np.array([1.0, 0.95, 0.9])
    return D, F, G


def make_models():
    D, F, G = example_factors()
    mf = NPFMicrofacetBRDF(D, F, G, [0.05, 0.08, 0.02], [0.6, 0.4, 0.9])
    H = 1 + 0.3 * np.cos(2 * H_PHI_D)[:, None] * np.array([1.0, 0.5, 0.2])
    nv = NPFNaiveBRDF(D, F, H, [0.05, 0.08, 0.02], [0.6, 0.4, 0.9])
    B = (D[:, None, :] * F[None, :, :]) * 0.5 + 0.03
    bv = NPFBivariateBRDF(B)
    return mf, nv, bv


# -- objective weights (Eq. 8-12) -------------------------------------------------------------
def test_volume_form_matches_jacobian_determinant():
    """Eq. 9 against a numerical Jacobian of the (θh, θd, φd) → (i, o) map (appendix)."""
    rng = np.random.default_rng(3)
    th, td, pd = rng.uniform(0.1, 1.4, 3)
    eps = 1e-6

    def T(x):
        wi, wo = half_diff_to_io(x[0], 0.0, x[1], x[2])
        return np.concatenate([wi, wo])

    x0 = np.array([th, td, pd])
    J = np.stack([(T(x0 + eps * e) - T(x0 - eps * e)) / (2 * eps) for e in np.eye(3)], 1)
    numeric = math.sqrt(np.linalg.det(J.T @ J))
    formula = math.sqrt(8 * math.sin(td) ** 2 * (math.cos(td) ** 2 + math.sin(td) ** 2
                                                  * math.cos(pd) ** 2))
    assert numeric == pytest.approx(formula, rel=1e-6)
    w = volume_form_weight()
    assert w.shape == (90, 90, 180) and np.all(w > 0)
    # integrates (sum of cell volumes) to the volume of the (i, o) domain it parameterises:
    # over θh ∈ [0, π/2], θd ∈ [0, π/2], φd ∈ [0, π): ∫ sqrt(det g) — compare with a fine rule
    tdf = (np.arange(2000) + 0.5) * (np.pi / 2 / 2000)
    pdf_ = (np.arange(2000) + 0.5) * (np.pi / 2000)
    inner = np.sqrt(8 * np.sin(tdf)[:, None] ** 2 * (np.cos(tdf)[:, None] ** 2 + np.sin(tdf)[:, None] ** 2
                                                     * np.cos(pdf_)[None] ** 2))
    total = inner.sum() * (np.pi / 2 / 2000) * (np.pi / 2000) * (np.pi / 2)
    assert w.sum() == pytest.approx(total, rel=2e-3)


def test_compressive_weight_properties():
    x = np.linspace(0, 20, 2001)
    w = compressive_weight(x, 1.0, p=1.4, alpha=math.log(2))
    assert w[0] == pytest.approx(1.0)
    assert np.all(np.diff(w) < 0)
    f = (1 - np.exp(-math.log(2) * x[1:])) / math.log(2)
    np.testing.assert_allclose(w[1:], (f / x[1:]) ** 1.4, rtol=1e-12)
    # the median maps to the centre of f's range: f(1) = 1/(2α)
    assert (1 - math.exp(-math.log(2))) / math.log(2) == pytest.approx(1 / (2 * math.log(2)))


def test_weighted_median():
    rng = np.random.default_rng(0)
    v = rng.random(101)
    assert weighted_median(v, np.ones(101)) == pytest.approx(np.median(v))
    w = np.zeros(101)
    w[17] = 1.0
    assert weighted_median(v, w) == v[17]


def test_objective_excludes_grazing_and_invalid_and_restricts():
    mf, _, _ = make_models()
    from brdffit.grid import tabulate_merl_grid

    values, valid = tabulate_merl_grid(mf)
    valid = valid.copy()
    valid[10, 20, 30] = False
    data = prepare_objective(values, valid)
    geo = merl_grid_geometry()
    inc = data.mask
    assert not inc[10, 20, 30]
    lim = math.cos(math.radians(89.0))
    assert np.all(geo["cos_i"][inc] >= lim - 1e-9) and np.all(geo["cos_o"][inc] >= lim - 1e-9)
    # samples just inside 89° are kept
    assert np.any(geo["cos_i"][inc] < math.cos(math.radians(88.0)))
    r = prepare_objective(values, valid, ObjectiveOptions(restrict_deg=80.0))
    assert r.n_samples < data.n_samples
    th = geo["theta_h"][r.mask]
    assert th.max() <= math.radians(80) + 1e-9
    nc = prepare_objective(values, valid, ObjectiveOptions(compressive=False))
    wvi = geo["w_volume"].ravel()[nc.index] * nc.cos_i * nc.cos_o
    np.testing.assert_allclose(nc.w[1], wvi)
    assert np.all(data.w <= nc.w * (1 + 1e-12))        # wC ≤ 1


# -- models ----------------------------------------------------------------------------------
def test_eval_matches_eq3_on_grid_and_eval_hd():
    mf, nv, bv = make_models()
    i, j, k = 37, 21, 50
    th, td, pd = D_THETA_H[i], F_THETA_D[j], H_PHI_D[k]
    ci = math.cos(th) * math.cos(td) - math.sin(th) * math.sin(td) * math.cos(pd)
    co = math.cos(th) * math.cos(td) + math.sin(th) * math.sin(td) * math.cos(pd)
    gi = np.array([np.interp(math.degrees(math.acos(ci)), np.arange(90), mf.G[:, c])
                   for c in range(3)])
    go = np.array([np.interp(math.degrees(math.acos(co)), np.arange(90), mf.G[:, c])
                   for c in range(3)])
    expect = mf.rho_d + mf.rho_s * mf.D[i] * mf.F[j] * gi * go / (ci * co)
    np.testing.assert_allclose(mf.eval_hd(th, td, pd), expect, rtol=1e-10)
    np.testing.assert_allclose(nv.eval_hd(th, td, pd),
                               nv.rho_d + nv.rho_s * nv.D[i] * nv.F[j] * nv.H[k], rtol=1e-10)
    np.testing.assert_allclose(bv.eval_hd(th, td, pd), bv.B[i, j], rtol=1e-10)
    wi, wo = half_diff_to_io(th, 0.7, td, pd)
    for m in (mf, nv, bv):
        np.testing.assert_allclose(m.eval(wi, wo), m.eval_hd(th, td, pd), rtol=1e-9)
        # reciprocity and the horizon
        np.testing.assert_allclose(m.eval(wo, wi), m.eval(wi, wo), rtol=1e-9)
        assert np.all(m.eval(wi, wo * np.array([1, 1, -1])) == 0)


def test_grazing_values_bounded():
    mf, _, _ = make_models()
    t = np.radians(np.linspace(85, 89.999, 50))
    wi = np.stack([np.sin(t), 0 * t, np.cos(t)], -1)
    wo = wi * np.array([-1, 1, 1])
    v = mf.eval(wi, wo)
    assert np.all(np.isfinite(v)) and v.max() < 1e4


def test_smith_g_from_d_matches_beckmann():
    """G-from-D (§4.3, 15-point quadrature) against the closed-form Beckmann Smith G1."""
    for alpha in (0.1, 0.3, 0.6):
        D = beckmann_d(alpha)
        dbar, _ = normalise_d(D)
        assert dbar == pytest.approx(1.0, rel=5e-3)           # Beckmann is normalised
        G = smith_g_from_d(D / D.max())                         # scale-free in D
        mu = 1 / np.tan(G_THETA[1:])
        a = mu / alpha
        lam = (erf(a) - 1) / 2 + np.exp(-a * a) / (2 * a * np.sqrt(np.pi))
        ref = np.concatenate([[1.0], 1 / (1 + lam)])
        np.testing.assert_allclose(G, ref, atol=1e-2)
        assert G[0] == 1.0 and np.all(np.diff(G) <= 1e-9)


def test_smith_g_from_d_is_the_quadrature_of_each_table():
    """The linear operator behind smith_g_from_d gives the quadrature's G for any table,
    including tables with zeros and identically zero ones (G = 1)."""
    rng = np.random.default_rng(3)
    D = rng.uniform(0.0, 2.0, (90, 4)) ** 3
    D[60:, 1] = 0.0
    D[:, 3] = 0.0
    dbar, dt = normalise_d(D)
    direct = np.ones_like(D)
    direct[1:] = 1.0 / (1.0 + np.maximum(_smith_lambda(dt), 0.0))
    np.testing.assert_allclose(smith_g_from_d(D), direct, rtol=1e-13, atol=0)
    assert np.all(smith_g_from_d(D)[:, 3] == 1.0)
    np.testing.assert_allclose(smith_g_from_d(D[:, 0]), direct[:, 0], rtol=1e-13)


def test_smith_g_jacobian_matches_central_differences():
    rng = np.random.default_rng(4)
    D = rng.uniform(0.05, 1.0, (3, 90))
    D[1, 50:] = 0.0                              # a zero tail: the one-sided derivative
    G, J = smith_g_jacobian(D)
    np.testing.assert_array_equal(G, smith_g_from_d(D.T).T)
    h = 1e-6
    for k in (0, 7, 45, 70, 89):
        up, down = D.copy(), D.copy()
        up[:, k] += h
        down[:, k] -= h
        down = np.maximum(down, 0.0)
        num = (smith_g_from_d(up.T).T - smith_g_from_d(down.T).T) / (up[:, k] - down[:, k])[:, None]
        np.testing.assert_allclose(J[:, :, k], num, rtol=1e-5, atol=1e-9)
    assert np.all(J[:, 0] == 0.0)                # G(0) = 1 whatever D
    # scale-free: D and 3 D give the same G, so J · D = 0 (Euler)
    np.testing.assert_allclose(np.einsum("cgk,ck->cg", J, D), 0.0, atol=1e-12)


def test_smith_g_curvature_matches_central_differences_of_the_jacobian():
    """Σ_k e_k ∂²G_k/∂D∂D (Newton's term through G = G(D)) against central differences of
    eᵀ ∂G/∂D, column by column; symmetric; zero for e = 0."""
    rng = np.random.default_rng(5)
    D = rng.uniform(0.05, 1.0, (3, 90))
    e = rng.normal(size=(3, 90))
    T = smith_g_curvature(D, e)
    np.testing.assert_allclose(T, np.swapaxes(T, 1, 2), rtol=1e-12, atol=1e-14)
    h = 1e-4                                # central differences: error O(h²) ≈ 1e-12 here
    scale = np.abs(T).max()
    assert scale > 1e-3                                          # not trivially zero
    for k in (0, 7, 45, 70, 89):
        up, down = D.copy(), D.copy()
        up[:, k] += h
        down[:, k] -= h
        num = (np.einsum("cg,cgi->ci", e, smith_g_jacobian(up)[1])
               - np.einsum("cg,cgi->ci", e, smith_g_jacobian(down)[1])) / (2 * h)
        np.testing.assert_allclose(T[:, :, k], num, rtol=1e-6, atol=1e-8 * scale)
    np.testing.assert_array_equal(smith_g_curvature(D, np.zeros((3, 90))), 0.0)
    # scale-free G: G(t D) = G(D), so the curvature along D itself is −(Jᵀe) (Euler, degree 0)
    Je = np.einsum("cg,cgi->ci", e, smith_g_jacobian(D)[1])
    np.testing.assert_allclose(np.einsum("cij,cj->ci", T, D), -Je, rtol=1e-9,
                               atol=1e-9 * np.abs(Je).max())


def test_sizes_and_save_load_identity(tmp_path):
    mf, nv, bv = make_models()
    assert table_bytes(mf) == 3264          # 3 · (3·90 + 2) · 4
    assert table_bytes(nv) == 4344          # 3 · (90 + 90 + 180 + 2) · 4
    assert table_bytes(bv) == 97200         # 90 · 90 · 3 · 4
    rng = np.random.default_rng(5)
    wi = rng.normal(size=(500, 3))
    wi[:, 2] = np.abs(wi[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo = rng.normal(size=(500, 3))
    wo[:, 2] = np.abs(wo[:, 2])
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    for m in (mf, nv, bv):
        m.fit_info = {"objective": 1.0}
        p = save_fit(m, tmp_path / f"{m.fit_kind}.npz")
        back = load_fit(p)
        assert type(back) is type(m) and back.fit_info["objective"] == 1.0
        _, arrays = m.to_state()
        _, arrays2 = back.to_state()
        for k in arrays:
            assert arrays2[k].dtype == np.float32
            np.testing.assert_array_equal(arrays[k], arrays2[k])
        np.testing.assert_allclose(back.eval(wi, wo), m.eval(wi, wo), rtol=2e-6, atol=1e-7)


CHI2 = dict(sample_count=40_000, res_theta=12, res_phi=24, ires=3)


@pytest.mark.parametrize("which,wi", [(0, [0.6, 0.0, 0.8]), (1, [0.0, 0.95, 0.3122499]),
                                      (2, [0.0, 0.0, 1.0])])
def test_sampling_chi2(which, wi):
    from brdffit.testing.chi2 import check_sampling

    m = make_models()[which]
    ok, res = check_sampling(m, [wi], **CHI2)
    assert ok, "\n".join(str(r) for r in res)
    for r in res:
        assert r.sample_pdf_mismatch < 1e-6


def test_sampling_chi2_detects_wrong_pdf():
    """The sampling test can fail: a pdf that disagrees with the sampler is rejected."""
    from brdffit.testing.chi2 import check_sampling

    m = make_models()[0]

    class Wrong(NPFMicrofacetBRDF):
        def pdf(self, wi, wo):
            return 1.3 * super().pdf(wi, wo) * (1 + 0.5 * np.asarray(wo)[..., 0])

    w = Wrong(m.D, m.F, m.G, m.rho_d, m.rho_s)
    ok, _ = check_sampling(w, [[0.6, 0.0, 0.8]], **CHI2)
    assert not ok


def test_compressive_objective_of_two_brdfs():
    from brdffit.losses.objective import compressive_objective, weighted_mean_relative_error

    mf, _, _ = make_models()
    same = compressive_objective(mf, mf)
    assert same["objective"] == 0.0
    brighter = NPFMicrofacetBRDF(mf.D, mf.F, mf.G, mf.rho_d * 1.1, mf.rho_s * 1.1)
    o = compressive_objective(brighter, mf)
    o_nc = compressive_objective(brighter, mf, ObjectiveOptions(compressive=False))
    assert o["objective"] > 0 and o["normalised"] == pytest.approx(0.01, rel=1e-9)
    assert o_nc["normalised"] == pytest.approx(0.01, rel=1e-9)
    rel = weighted_mean_relative_error(brighter, mf)
    assert rel["relative_error"] == pytest.approx(0.1, rel=0.02)
