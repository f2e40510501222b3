"""Dr.Jit evaluators without rendering: sample/pdf/eval consistency, resampling error,
Eq. 9 roughness scaling, translation layer (needs Mitsuba's LLVM back-end)."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.evaluation.render import available

pytestmark = [pytest.mark.render,
              pytest.mark.skipif(not available(), reason="Mitsuba 3 LLVM back-end unavailable")]


def _models():
    from brdffit.microfacet import (Beckmann, ConductorFresnel, GGX, MicrofacetBRDF,
                                    SchlickFresnel, SumBRDF)

    return {
        "ggx+diffuse": MicrofacetBRDF(GGX(0.2), SchlickFresnel([0.9, 0.6, 0.3]),
                                      diffuse=[0.1, 0.1, 0.2]),
        "beckmann-aniso": MicrofacetBRDF(Beckmann(0.35, 0.12),
                                         ConductorFresnel([0.2, 0.9, 1.1], [3.9, 2.4, 2.2])),
        "ggx-rho": MicrofacetBRDF(GGX(0.3, 0.08, 0.5), None, diffuse=0.05),
        "beckmann-rho": MicrofacetBRDF(Beckmann(0.25, 0.1, -0.4), SchlickFresnel(0.5)),
        "sum": SumBRDF([MicrofacetBRDF(GGX(0.06), None), MicrofacetBRDF(GGX(0.4), None, diffuse=0.3)]),
    }


def _npf():
    from brdffit.microfacet.npf_model import D_THETA_H, F_THETA_D, G_THETA, NPFMicrofacetBRDF

    D = np.exp(-(np.tan(D_THETA_H) / 0.2) ** 2)[:, None] * np.array([1.0, 0.9, 0.8])
    F = (0.5 + 0.5 * (1 - np.cos(F_THETA_D)) ** 5)[:, None] * np.ones(3)
    G = np.cos(G_THETA)[:, None] ** 0.1 * np.ones(3)
    return NPFMicrofacetBRDF(D, F, G, [0.05, 0.04, 0.03], [0.3, 0.3, 0.3])


def _sgd_per_channel():
    """Bagher 2012 per-channel SGD lobes (what fit_sgd returns)."""
    from brdffit.microfacet.sgd_model import PerChannelMicrofacetBRDF
    from brdffit.microfacet.sgd import SGD

    return PerChannelMicrofacetBRDF([dict(distribution=SGD(0.15 * c, 1.2), rho_d=0.05 * c,
                                          rho_s=0.3, F0=0.05, F1=0.02) for c in (1, 2, 3)])


def _np(c):
    return np.stack([np.asarray(c[k], dtype=np.float64) for k in range(3)], -1)


def _check_sampling(ev, brdf, theta_deg, n=1 << 17, alpha_scale=1.0, ref_albedo=None):
    from brdffit.evaluation.render import drjit_eval as dj

    mi = dj.mi
    rng = np.random.default_rng(7)
    t = np.radians(theta_deg)
    wi_np = np.tile([np.sin(t), 0.0, np.cos(t)], (n, 1))
    wi = dj.to_vec3(wi_np)
    u = rng.random((n, 3)).astype(np.float32)
    wo, pdf = ev.sample(wi, mi.Float(u[:, 0]), mi.Point2f(u[:, 1], u[:, 2]), alpha_scale, True)
    f = _np(ev.eval(wi, wo, alpha_scale, True))
    pdf = np.asarray(pdf, np.float64)
    wo_np = np.stack([np.asarray(wo[k], np.float64) for k in range(3)], -1)
    pdf2 = np.asarray(ev.pdf(wi, wo, alpha_scale, True), np.float64)
    good = pdf > 0
    # the density reported by sample() is the density of pdf()
    np.testing.assert_allclose(pdf[good], pdf2[good], rtol=2e-3)
    est = np.where(good[:, None], f * np.maximum(wo_np[:, 2:3], 0) / np.where(good, pdf, 1)[:, None], 0).mean(0)
    if ref_albedo is None:
        ref_albedo = brdf.albedo([t], n_samples=1 << 18)[0]
    np.testing.assert_allclose(est, ref_albedo, rtol=0.02, atol=2e-3)
    # ∫ pdf dω ≤ 1 (cosine-sampled estimate of the integral)
    from brdffit.brdf import cosine_hemisphere_sample

    wc = cosine_hemisphere_sample(rng.random((n, 2)))
    pc = np.asarray(ev.pdf(wi, dj.to_vec3(wc), alpha_scale, True), np.float64)
    integral = np.mean(pc / (wc[:, 2] / np.pi))
    assert integral <= 1.03
    assert integral > 0.5
    return est


@pytest.mark.parametrize("name", ["ggx+diffuse", "beckmann-aniso", "ggx-rho", "beckmann-rho", "sum", "npf",
                                  "sgd-per-channel"])
@pytest.mark.parametrize("theta", [25.0, 70.0])
def test_closed_form_sampling_consistent(name, theta):
    from brdffit.evaluation.render.translate import to_evaluator

    brdf = {"npf": _npf, "sgd-per-channel": _sgd_per_channel}.get(name, lambda: _models()[name])()
    ev = to_evaluator(brdf, mode="closed")
    assert ev.path == "closed-form"
    _check_sampling(ev, brdf, theta)


@pytest.fixture(scope="module")
def ggx_table():
    from brdffit.evaluation.render.translate import to_evaluator

    brdf = _models()["ggx+diffuse"]
    return brdf, to_evaluator(brdf, mode="table")


@pytest.mark.parametrize("theta", [25.0, 70.0])
def test_table_sampling_consistent_and_resampling_error(theta, ggx_table):
    from brdffit.evaluation.render.translate import resampling_error

    brdf, ev = ggx_table
    assert ev.kind == "merl-table"
    # the GGX proxy recovers the lobe width of the table
    assert 0.12 < ev.proxy_alpha < 0.3
    _check_sampling(ev, brdf, theta)
    err = resampling_error(brdf, ev, n=1 << 15)
    assert err["rel_cos"] < 0.01 and err["albedo_rel"] < 0.01


def test_radial_table_distribution_roughness_scaling():
    """RadialTableDist of GGX(0.2) scaled by s = 1.5 (Dupuy Eq. 9) equals GGX(0.3)."""
    from brdffit.evaluation.render import drjit_eval as dj
    from brdffit.evaluation.render.translate import evaluate_drjit
    from brdffit.microfacet import GGX, MicrofacetBRDF

    rng = np.random.default_rng(3)
    from brdffit.brdf import cosine_hemisphere_sample

    wi = cosine_hemisphere_sample(rng.random((20000, 2)))
    wo = cosine_hemisphere_sample(rng.random((20000, 2)))
    tab = dj.MicrofacetEval(dj.RadialTableDist.from_distribution(GGX(0.2)), dj.ConstantFresnelDJ(1.0))
    ref = MicrofacetBRDF(GGX(0.3), None)
    got = evaluate_drjit(tab, wi, wo, alpha_scale=1.5)
    want = ref.eval(wi, wo)
    rel = np.abs(got - want).sum() / np.abs(want).sum()
    assert rel < 0.01
    # and it is not trivially equal to the unscaled lobe
    unscaled = evaluate_drjit(tab, wi, wo, alpha_scale=1.0)
    assert np.abs(unscaled - want).sum() / np.abs(want).sum() > 0.1
    _check_sampling(tab, ref, 40.0, alpha_scale=1.5)


def test_translation_is_verified_and_falls_back(monkeypatch):
    """A wrong closed form is detected by the verification and replaced by the table."""
    from brdffit.evaluation.render import drjit_eval as dj
    from brdffit.evaluation.render import translate

    brdf = _models()["ggx+diffuse"]
    monkeypatch.setitem(translate._TRANSLATORS, "MicrofacetBRDF",
                        lambda b: dj.MicrofacetEval(dj.GGXDist(0.4), dj.ConstantFresnelDJ(1.0)))
    with pytest.warns(RuntimeWarning, match="differs from brdf.eval"):
        ev = translate.to_evaluator(brdf)
    assert ev.path == "table"
    from brdffit.errors import BRDFError

    with pytest.raises(BRDFError):
        translate.to_evaluator(brdf, mode="closed")


def test_anisotropic_generic_table():
    from brdffit.evaluation.render.translate import resampling_error, to_evaluator
    from brdffit.microfacet import GGX, MicrofacetBRDF

    brdf = MicrofacetBRDF(GGX(0.4, 0.15, 0.3), None, diffuse=0.1)
    ev = to_evaluator(brdf, mode="table")
    assert ev.kind == "table4d"
    err = resampling_error(brdf, ev, n=1 << 14)
    assert err["rel_cos"] < 0.05
    _check_sampling(ev, brdf, 45.0, n=1 << 16, ref_albedo=brdf.albedo([np.radians(45)], 1 << 16)[0])


def test_non_reciprocal_brdf_gets_full_phi_table():
    """A non-reciprocal isotropic BRDF is tabulated over φd ∈ [0, 2π) (no folding)."""
    from brdffit.brdf import IsotropicBRDF
    from brdffit.evaluation.render import drjit_eval as dj
    from brdffit.evaluation.render.translate import (is_reciprocal, resampling_error,
                                                     to_evaluator)

    class Skewed(IsotropicBRDF):
        name = "skewed"

        def eval(self, wi, wo):  # isotropic (depends on wi·wo and the cosines) but not reciprocal
            wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
            r = wo * np.array([-1.0, -1.0, 1.0])               # mirror direction of wo
            lobe = 0.1 + 3.0 * np.maximum(np.sum(wi * r, -1), 0.0) ** 30
            ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
            f = np.where(ok, lobe * (1.0 + 0.8 * wi[..., 2] ** 2), 0.0)
            return np.repeat(f[..., None], 3, -1)

    b = Skewed()
    assert not is_reciprocal(b) and is_reciprocal(_models()["ggx+diffuse"])
    ev = to_evaluator(b)
    assert ev.kind == "merl-table" and ev.n_phi == 360
    full = resampling_error(b, ev, n=1 << 14)["rel_cos"]
    from brdffit.grid import tabulate_merl_grid

    folded = resampling_error(b, dj.MERLTableEval(tabulate_merl_grid(b)[0]), n=1 << 14)["rel_cos"]
    assert full < 0.01 < folded


def test_log_interpolation_reduces_peak_bias():
    """Sharp lobe: log-space trilinear is less biased than linear (energy of the table)."""
    from brdffit.evaluation.render import drjit_eval as dj
    from brdffit.evaluation.render.translate import resampling_error
    from brdffit.grid import tabulate_merl_grid
    from brdffit.microfacet import GGX, MicrofacetBRDF

    b = MicrofacetBRDF(GGX(0.01), None, diffuse=0.05)
    values, _ = tabulate_merl_grid(b)
    e_log = resampling_error(b, dj.MERLTableEval(values, interp="log"), n=1 << 15)
    e_lin = resampling_error(b, dj.MERLTableEval(values, interp="linear"), n=1 << 15)
    assert e_log["albedo_rel"] < e_lin["albedo_rel"]
    assert e_log["rel_cos"] < 0.1
    # a genuine sharp peak is not a spike; injected isolated outliers are
    assert dj.despike(values)[1] == 0
    spiky = values.copy()
    spiky[40, 88, 10] = 1e9
    spiky[12, 60, 100] = 5e4
    cleaned, n = dj.despike(spiky)
    assert n == 2
    assert cleaned[40, 88, 10].max() < 10 * values[40, 88, 10].max() + 1.0
    assert cleaned[12, 60, 100].max() < 10 * values[12, 60, 100].max() + 1.0
    changed = np.any(cleaned != spiky, axis=-1)
    assert changed.sum() == 2
