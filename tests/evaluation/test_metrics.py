"""Tests of brdffit.evaluation.metrics (image and BRDF-space metrics, win counting)."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.brdf import BRDF
from brdffit.evaluation import metrics as M


class Lambert(BRDF):
    isotropic = True

    def __init__(self, albedo):
        self.albedo_rgb = np.asarray(albedo, float)

    def eval(self, wi, wo):
        wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
        up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        return np.where(up[..., None], self.albedo_rgb / np.pi, 0.0)


class Phongish(BRDF):
    """A glossy lobe around the mirror direction (for a non-trivial relative error)."""

    isotropic = True

    def __init__(self, n):
        self.n = n

    def eval(self, wi, wo):
        wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
        r = wi * np.array([-1, -1, 1])
        c = np.clip(np.sum(r * wo, -1), 0, 1) ** self.n * (self.n + 2) / (2 * np.pi)
        up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        return np.where(up, c, 0.0)[..., None] * np.array([1.0, 0.8, 0.6])


def test_psnr_matches_formula_on_known_images():
    ref = np.zeros((4, 5, 3))
    ref[1, 1] = [2.0, 4.0, 1.0]          # peak 4 on the foreground
    ref[3, 4] = [100.0, 0, 0]            # background: must not set the peak
    mask = np.zeros((4, 5), bool)
    mask[:2] = True
    test = ref.copy()
    test[0, 0, 0] += 0.5                 # one foreground component off by 0.5
    test[3, 4] = 0.0                     # background difference is ignored
    mse = 0.25 / (10 * 3)                # 10 foreground pixels x 3 channels
    expected = 10 * np.log10(16.0 / mse)
    assert M.rendered_psnr(ref, test, mask) == pytest.approx(expected, rel=1e-12)
    # without the mask the background changes both peak and error
    assert M.rendered_psnr(ref, test) != pytest.approx(expected)


def test_psnr_identical_is_inf_and_decreases_with_noise(rng):
    ref = rng.random((8, 8, 3)) + 0.1
    assert M.rendered_psnr(ref, ref) == np.inf
    p1 = M.rendered_psnr(ref, ref + rng.normal(0, 0.01, ref.shape))
    p2 = M.rendered_psnr(ref, ref + rng.normal(0, 0.1, ref.shape))
    assert p1 > p2 + 15  # 10x the noise is ~20 dB


def test_psnr_rejects_bad_shapes():
    with pytest.raises(ValueError, match="expected shape"):
        M.rendered_psnr(np.ones((4, 4, 3)), np.ones((4, 5, 3)))
    with pytest.raises(ValueError, match="foreground"):
        M.rendered_psnr(np.ones((4, 4, 3)), np.ones((4, 4, 3)), np.zeros((4, 4), bool))


def test_delta_e_zero_for_identical_positive_otherwise_and_symmetric(rng):
    a = rng.random((6, 7, 3)) * 60
    b = a * np.array([1.2, 1.0, 0.9])
    mask = np.ones((6, 7), bool)
    mask[0] = False
    assert M.mean_delta_e2000(a, a, mask) == pytest.approx(0.0, abs=1e-9)
    d_ab = M.delta_e2000_image(a, b, mask)
    d_ba = M.delta_e2000_image(b, a, mask)
    assert np.all(np.isnan(d_ab[0])) and np.all(d_ab[1:] > 0)
    np.testing.assert_allclose(d_ab[1:], d_ba[1:], rtol=1e-9)


def test_to_lab_white_and_black():
    lab = M.to_lab(np.array([[[0.0, 0, 0], [1e9, 1e9, 1e9]]]))
    np.testing.assert_allclose(lab[0, 0], [0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(lab[0, 1], [100, 0, 0], atol=0.05)


def test_colorize_delta_e_fixed_scale():
    de = np.array([[0.0, 5.0, 10.0, 50.0, np.nan]])
    rgb = M.colorize_delta_e(de)
    assert rgb.dtype == np.uint8 and rgb.shape == (1, 5, 3)
    np.testing.assert_array_equal(rgb[0, 2], rgb[0, 3])        # saturates above vmax
    assert not np.array_equal(rgb[0, 0], rgb[0, 1])
    np.testing.assert_array_equal(rgb[0, 4], [0, 0, 0])         # background


def test_cosine_weighted_relative_error_lambert_exact():
    ref = Lambert([0.5, 0.5, 0.5])
    assert M.cosine_weighted_relative_error(ref, ref, 1 << 10) == 0.0
    # constant BRDFs: |0.6-0.5|/0.5 = 0.2 exactly, whatever the quadrature
    assert M.cosine_weighted_relative_error(ref, Lambert([0.6] * 3), 1 << 10) == pytest.approx(0.2)
    per = M.cosine_weighted_relative_error(ref, Lambert([0.5, 1.0, 0.0]), 1 << 10, per_channel=True)
    np.testing.assert_allclose(per, [0.0, 1.0, 1.0])


def test_cosine_weighted_relative_error_glossy_estimate():
    # Phong-like lobe vs Lambert of equal-ish energy: a deterministic, seed-stable estimate
    a, b = Phongish(20), Lambert([0.5, 0.4, 0.3])
    e1 = M.cosine_weighted_relative_error(a, b, 1 << 14, seed=1)
    e2 = M.cosine_weighted_relative_error(a, b, 1 << 14, seed=2)
    assert 0.1 < e1 < 3.0
    assert abs(e1 - e2) < 0.05 * e1
    assert M.cosine_weighted_relative_error(a, b, 1 << 14, seed=1) == e1


def test_count_wins_two_db_ties():
    ps = {"a": [30.0, 30.0, 30.0, np.nan, np.inf], "b": [27.0, 29.0, 33.0, 10.0, np.inf]}
    w = M.count_wins(ps)
    assert w["a"]["b"] == {"wins": 1, "ties": 2, "losses": 1, "n": 4}
    assert w["b"]["a"] == {"wins": 1, "ties": 2, "losses": 1, "n": 4}
    w1 = M.count_wins(ps, tie_db=0.5)
    assert w1["a"]["b"]["wins"] == 2
    with pytest.raises(ValueError):
        M.count_wins({"a": [1.0], "b": [1.0, 2.0]})


def test_count_wins_ties_within_measured_standard_errors():
    ps = {"a": [30.0, 30.0, 30.0, 30.0], "b": [29.5, 29.5, 29.95, 25.0]}
    se = {"a": [0.1, 1.0, np.nan, 0.1], "b": [0.1, 1.0, 0.01, 0.1]}
    w = M.count_wins(ps, se=se)
    # 0.5 dB: a win at se 0.1 (threshold 0.28), a tie at se 1 (2.8); missing se: 2 dB rule
    assert w["a"]["b"] == {"wins": 2, "ties": 2, "losses": 0, "n": 4}
    assert w["b"]["a"] == {"wins": 0, "ties": 2, "losses": 2, "n": 4}
    assert M.count_wins(ps, se=se, z=10.0)["a"]["b"]["ties"] == 3


def test_prepared_brdf_metrics_match_direct_and_report_missing():
    ref, fit = Phongish(20), Lambert([0.5, 0.4, 0.3])
    bm = M.BRDFMetrics(ref, 1 << 12, seed=3)
    out = bm.evaluate(fit)
    assert out["cos_rel_error"] == pytest.approx(
        M.cosine_weighted_relative_error(ref, fit, 1 << 12, seed=3), rel=1e-12)
    assert bm.evaluate(ref)["cos_rel_error"] == 0.0
    # these stand-ins have no eval_hd: the grid objective is unavailable, and says why
    assert out["compressive_objective"] is None and "compressive_objective" in out["errors"]


def test_brdf_metrics_without_pair_metrics_evaluate_no_pairs_until_asked():
    """Without cos_rel_error and error_regions no sample pair is drawn or evaluated; a later
    cos_rel_error prepares them and equals the one of a fully prepared BRDFMetrics."""
    calls = []

    class Counting(Phongish):
        def eval(self, wi, wo):
            calls.append(len(wi))
            return super().eval(wi, wo)

    ref, fit = Counting(20), Lambert([0.5, 0.4, 0.3])
    bm = M.BRDFMetrics(ref, 1 << 10, seed=3, metrics=())
    assert calls == [] and bm._wi is None
    assert bm.evaluate(fit) == {"seconds": {}}
    lazy = bm.cos_rel_error(fit)
    assert lazy == M.BRDFMetrics(Phongish(20), 1 << 10, seed=3).cos_rel_error(fit)
    assert "cos_rel_error_setup" in bm.timings


# ------------------------------------------------------------------------------------------
# PSNR with standard error from batches rendered with common random numbers (issue 13)
# ------------------------------------------------------------------------------------------
class ToyRenderer:
    """A NumPy stand-in for a CRN renderer: each "pixel" integrates ``f(x) L(x)`` over
    x ∈ [0, 1] (a 1D direction) by importance sampling from a model-independent proposal
    (uniform + a Gaussian around the pixel's lobe), the same samples for the reference lobe
    (width 0.1) and the model (width ``w``); ``L`` has a narrow bright spot per pixel, so the
    estimates are genuinely noisy. ``truth`` gives the converged images by quadrature."""

    def __init__(self, pixels=64, w_model=0.105):
        pix = np.random.default_rng(0)
        self.mu = pix.uniform(0.2, 0.8, pixels)
        self.c = pix.uniform(0.0, 1.0, pixels)
        self.w = (0.1, w_model)

    def f(self, x, w):
        return np.exp(-((x - self.mu[:, None]) / w) ** 2) / (w * np.sqrt(np.pi)) + 0.2

    def L(self, x):
        return 1.0 + 20.0 * np.exp(-((x - self.c[:, None]) / 0.02) ** 2)

    def pdf(self, x):
        g = np.exp(-0.5 * ((x - self.mu[:, None]) / 0.1) ** 2) / (0.1 * np.sqrt(2 * np.pi))
        return 0.3 * ((x >= 0) & (x <= 1)) + 0.7 * g

    def render(self, seed, batches, n):
        """``(reference, model)`` stacks ``(batches, P, 1, 3)``."""
        rng = np.random.default_rng(seed)
        P = self.mu.size
        u = rng.random((P, batches * n))
        x = np.where(rng.random((P, batches * n)) < 0.3, u,
                     self.mu[:, None] + 0.1 * rng.standard_normal((P, batches * n)))
        inside = (x >= 0) & (x <= 1)
        out = []
        for w in self.w:
            v = np.where(inside, self.f(x, w) * self.L(x) / self.pdf(x), 0.0)
            out.append(np.repeat(v.reshape(P, batches, n).mean(-1).T[:, :, None, None], 3, -1))
        return out

    def truth(self):
        xs = np.linspace(0.0, 1.0, 20001)[None]
        return [np.trapezoid(self.f(xs, w) * self.L(xs), xs, axis=-1) for w in self.w]


def test_crn_psnr_standard_error_is_calibrated():
    """Over independent repeats, the spread of the estimated PSNR matches the reported
    standard error, and the estimate is unbiased (truth from quadrature, same peak)."""
    toy = ToyRenderer()
    tr, tm = toy.truth()
    true = M.psnr_from_mse(tr.max(), np.mean((tm - tr) ** 2))
    ps, ses, plain = [], [], []
    for rep in range(300):
        R, T = toy.render(rep + 1, batches=8, n=16)
        r = M.crn_psnr(R, T, peak=tr.max())
        ps.append(r["psnr"])
        ses.append(r["psnr_se"])
        plain.append(r["psnr_plain"])
    ps = np.array(ps)
    ratio = ps.std() / np.mean(ses)
    assert 0.75 < ratio < 1.33, (ps.std(), np.mean(ses))
    assert abs(ps.mean() - true) < 0.15 + 2 * ps.std() / np.sqrt(ps.size), (ps.mean(), true)
    # the plain MSE of the batch means is biased (noise added): lower PSNR on average
    assert np.mean(plain) < ps.mean() - 0.2


def test_crn_psnr_edge_cases(rng):
    ref = rng.random((4, 6, 6, 3)) + 0.5
    r = M.crn_psnr(ref, ref.copy())
    assert r["psnr"] == np.inf and r["psnr_se"] == 0.0 and r["bound"] is None
    # a difference far below its own noise: not resolved → a lower bound
    noise = rng.normal(0, 1e-3, ref.shape)
    r = M.crn_psnr(ref, ref + noise)
    assert r["bound"] == "lower" or not r["resolved"]
    # one batch: PSNR of the single difference, no standard error
    one = M.crn_psnr(ref[:1], ref[:1] + 0.01)
    assert one["psnr_se"] != one["psnr_se"] and one["psnr"] == pytest.approx(
        M.rendered_psnr(ref[0], ref[0] + 0.01), rel=1e-9)
    # a constant offset: exact MSE, zero standard error
    c = M.crn_psnr(ref, ref + 0.02, peak=2.0)
    assert c["mse"] == pytest.approx(4e-4) and c["mse_se"] == pytest.approx(0.0, abs=1e-12)
    assert c["psnr"] == pytest.approx(10 * np.log10(4.0 / 4e-4))
    with pytest.raises(ValueError, match="shape"):
        M.crn_psnr(ref, ref[:, :5])


def test_combine_psnr_over_scenes():
    c = M.combine_psnr([{"psnr": 30.0, "psnr_se": 0.3}, {"psnr": 40.0, "psnr_se": 0.4}])
    assert c["psnr"] == 35.0 and c["psnr_se"] == pytest.approx(0.25) and c["bound"] is None
    inf = M.combine_psnr([{"psnr": np.inf, "psnr_se": 0.0}] * 2)
    assert inf["psnr"] == np.inf and inf["psnr_se"] == 0.0
    low = M.combine_psnr([{"psnr": 30.0, "psnr_se": 0.3}, {"psnr": 50.0, "bound": "lower"}])
    assert low["bound"] == "lower" and low["psnr"] == 40.0


class Sum(BRDF):
    isotropic = True

    def __init__(self, *parts):
        self.parts = parts

    def eval(self, wi, wo):
        return sum(p.eval(wi, wo) for p in self.parts)


class TiltedColour(BRDF):
    """A diffuse whose colour turns from red at normal incidence to blue at grazing."""

    isotropic = True

    def eval(self, wi, wo):
        wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
        c = np.clip(wi[..., 2], 0, 1)[..., None]
        rgb = c * np.array([0.8, 0.2, 0.1]) + (1 - c) * np.array([0.1, 0.2, 0.8])
        up = ((wi[..., 2] > 0) & (wo[..., 2] > 0))[..., None]
        return np.where(up, rgb / np.pi, 0.0)


def test_region_of_sorts_pairs_into_the_documented_regions():
    def d(deg, phi=0.0):
        t, p = np.radians(deg), np.radians(phi)
        return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])

    wi = np.stack([d(30), d(40), d(75), d(30), d(20)])
    wo = np.stack([d(30, 180), d(45), d(10, 180), d(60, 90), d(30, 180)])
    # mirror pair (θh 0), near-retro (θd 2.5°), grazing light, off-specular body, θh 5° peak
    assert [M.REGIONS[k] for k in M.region_of(wi, wo)] == [
        "specular peak", "retro-reflection", "grazing", "body", "specular peak"]


def test_error_regions_name_the_missing_peak_and_the_angle_dependent_colour():
    diffuse = Lambert([0.3, 0.3, 0.3])
    peaky = Sum(diffuse, Phongish(400))
    r = M.error_regions(peaky, diffuse, n_samples=1 << 14)
    shares = [v["error_share"] for v in r["regions"].values()]
    assert sum(shares) == pytest.approx(1.0) and r["worst"] == "specular peak"
    assert r["regions"]["specular peak"]["fit_over_measured"] < 1.0
    assert "second, narrower specular lobe" in r["diagnosis"]
    assert M.error_regions(diffuse, diffuse, n_samples=1 << 12)["diagnosis"] is None
    c = M.error_regions(TiltedColour(), Lambert([0.45, 0.2, 0.45]), n_samples=1 << 14)
    assert c["colour_shift"]["measured"] > 0.15 and c["colour_shift"]["fit"] < 1e-9
    assert any("colour changes with the angle of incidence" in f for f in c["findings"])
    bm = M.BRDFMetrics(peaky, n_samples=1 << 14)
    assert bm.evaluate(diffuse)["error_regions"]["worst"] == "specular peak"


def test_grid_metrics_share_one_evaluation_and_match_the_direct_ones():
    """normalized_l2 and the compressive objective read the fit at the union of their MERL
    nodes, evaluated once: the same figures as each metric alone (L2Reference.error,
    the objective of the fit's own evaluation), and fewer evaluations."""
    from brdffit.losses.l2 import L2Reference
    from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel

    ref = MicrofacetBRDF(GGX(0.2), SchlickFresnel(0.05), diffuse=[0.3, 0.2, 0.1])
    fit = MicrofacetBRDF(GGX(0.25), SchlickFresnel(0.04), diffuse=[0.28, 0.21, 0.12])
    bm = M.BRDFMetrics(ref, 1 << 10, metrics=("normalized_l2", "compressive_objective"))
    calls = []

    class Counted(MicrofacetBRDF):
        def eval_hd(self, th, td, pd):
            calls.append(np.size(th))
            return super().eval_hd(th, td, pd)

    counted = Counted(GGX(0.25), SchlickFresnel(0.04), diffuse=[0.28, 0.21, 0.12])
    out = bm.evaluate(counted)
    assert out["normalized_l2"] == pytest.approx(L2Reference(ref).error(fit).value, rel=1e-12)
    fv = np.nan_to_num(np.asarray(fit.eval_hd(*bm._obj_coords))).T
    direct = bm._obj.value(fv).sum() / bm._obj_ref_energy.sum()
    assert out["compressive_objective"] == pytest.approx(direct, rel=1e-12)
    separate = 90 * 90 * 90 + bm._obj.index.size          # L2's φd planes + the objective's
    assert sum(calls) < 0.8 * separate, (sum(calls), separate)


def test_grid_values_of_fits_evaluated_through_directions_equal_their_eval_hd(monkeypatch):
    """The grid nodes' directions, computed once for every fit whose ``eval_hd`` is ``eval``
    at those directions, give bitwise the values of that ``eval_hd``."""
    from brdffit.brdf import hd_through_directions
    from brdffit.loading import load
    from brdffit.microfacet.npf_model import NPFBivariateBRDF
    from brdffit.microfacet.sgd import SGD
    from brdffit.microfacet.sgd_model import PerChannelMicrofacetBRDF

    bm = M.BRDFMetrics(load("synthetic:plastic-beckmann"))
    sgd = PerChannelMicrofacetBRDF([dict(distribution=SGD(0.1 + 0.1 * c, 1.3), rho_d=0.1,
                                         rho_s=0.5, F0=0.2, F1=0.05) for c in range(3)])
    fits = [load("synthetic:gold-ggx"), sgd]
    assert all(hd_through_directions(f) for f in fits)
    assert not hd_through_directions(NPFBivariateBRDF(np.ones((90, 90, 3))))
    cached = [bm._grid_metric_values(f) for f in fits]
    assert bm._grid_directions is not None
    monkeypatch.setattr(M, "hd_through_directions", lambda brdf: False)
    for f, (grid, samples) in zip(fits, cached):
        grid_hd, samples_hd = bm._grid_metric_values(f)
        assert np.array_equal(grid, grid_hd, equal_nan=True)
        assert np.array_equal(samples, samples_hd, equal_nan=True)
        assert np.isfinite(samples).all() and samples.max() > 0


def test_crn_reference_reused_equals_crn_psnr_of_masked_float64_stacks(rng):
    """One CRNReference measuring several models gives bitwise what crn_psnr gives for
    each model alone, from float64 copies of the stacks masked with a boolean index."""
    K, H, W = 5, 12, 9
    ref = (rng.random((K, H, W, 3)) * 40).astype(np.float32)
    mask = rng.random((H, W)) > 0.4
    tests = [(ref * s + rng.normal(0, 0.5, ref.shape)).astype(np.float32)
             for s in (1.0, 1.1, 0.7)]
    crn = M.CRNReference(ref, mask)
    for tst in tests:
        got = crn.psnr(tst, peak=30.0)
        want = M.crn_psnr(ref.astype(np.float64), tst.astype(np.float64), mask, peak=30.0)
        assert got == want
        full = np.ones((H, W), bool)
        sub = M.crn_psnr(ref[:, mask][:, :, None].astype(np.float64),
                         tst[:, mask][:, :, None].astype(np.float64), full[mask][:, None], 30.0)
        assert got == sub
    np.testing.assert_equal(M.CRNReference(ref[0]).psnr(tests[0][0]),
                            M.crn_psnr(ref[0].astype(np.float64), tests[0][0].astype(np.float64)))
    with pytest.raises(ValueError, match="same shape"):
        crn.psnr(tests[0][:, :-1])
