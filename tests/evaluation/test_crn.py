"""Common random numbers (issue 13): the model-independent proposal, the multi-model CRN
integrator, PSNR ± standard error in comparisons. Small images; Mitsuba tests skip without
the LLVM back-end."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.evaluation.render import available
from brdffit.evaluation.render.proposal import _ggx_backscatter, fit_proposal

needs_mitsuba = pytest.mark.skipif(not available(), reason="Mitsuba 3 LLVM back-end unavailable")


def test_fit_proposal_recovers_lobes():
    """NumPy fit: a GGX lobe plus a diffuse term → one lobe of that α, albedo-share weights."""
    th = (np.arange(256) / 256) ** 2 * (np.pi / 2)
    th = th[th < np.radians(85)]
    fit = fit_proposal(th, 0.8 * _ggx_backscatter(th, 0.07) + 0.05)
    assert len(fit["alphas"]) >= 1 and fit["alphas"][0] == pytest.approx(0.07, rel=0.15)
    share = 0.8 / (0.8 + np.pi * 0.05)
    assert fit["weights"][0] == pytest.approx(0.85 * share, rel=0.1)
    assert fit["cosine_weight"] + sum(fit["weights"]) == pytest.approx(1.0)
    two = fit_proposal(th, 0.5 * _ggx_backscatter(th, 0.02) + 0.5 * _ggx_backscatter(th, 0.3))
    assert sorted(round(a, 2) for a in two["alphas"]) == pytest.approx([0.02, 0.3], rel=0.2)
    flat = fit_proposal(th, np.zeros_like(th))
    assert flat["alphas"] == [] and flat["cosine_weight"] == 1.0


def _ggx(alpha=0.2, diffuse=(0.05, 0.05, 0.1)):
    from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel

    return MicrofacetBRDF(GGX(alpha), SchlickFresnel([0.9, 0.6, 0.3]), diffuse=list(diffuse))


@needs_mitsuba
@pytest.mark.render
def test_proposal_is_a_consistent_sampler():
    """Furnace test of the proposal: the albedo of a sharp GGX lobe estimated with the
    proposal's sample/pdf equals the estimate with the model's own (exact VNDF) sampler."""
    from brdffit.evaluation.render import drjit_eval as dj
    from brdffit.evaluation.render.proposal import Proposal
    from brdffit.evaluation.render.translate import to_evaluator

    mi, dr = dj.mi, dj.dr
    ev = to_evaluator(_ggx(0.03, (0.0, 0.0, 0.0)))
    prop = Proposal([0.05, 0.4], [0.5, 0.3], 0.2)
    rng = np.random.default_rng(3)
    n = 1 << 20
    for deg in (0.0, 45.0, 75.0):
        t = np.radians(deg)
        wi = mi.Vector3f(np.full(n, np.sin(t), np.float32), np.zeros(n, np.float32),
                         np.full(n, np.cos(t), np.float32))
        u1 = mi.Float(rng.random(n).astype(np.float32))
        u2 = mi.Point2f(*(rng.random((2, n)).astype(np.float32)))
        est = []
        for sampler in (prop, ev):
            wo, pdf = sampler.sample(wi, u1, u2, 1.0, True)
            ok = (wo.z > 0) & (pdf > 0)
            f = ev.eval(wo, wi, 1.0, ok)
            w = dr.select(ok, f * wo.z / dr.select(ok, pdf, 1.0), 0.0)
            est.append(np.mean(np.asarray(w[1], np.float64)))
            if sampler is prop:  # sample and pdf agree with the standalone pdf
                np.testing.assert_allclose(np.asarray(prop.pdf(wi, wo, 1.0, ok))[np.asarray(ok)],
                                           np.asarray(pdf)[np.asarray(ok)], rtol=1e-4)
        assert est[0] == pytest.approx(est[1], rel=0.01), (deg, est)


@needs_mitsuba
@pytest.mark.render
def test_plugin_proposal_gives_same_directions_for_any_model():
    """Under a proposal, the plugin's sample() returns the same directions and pdfs whatever
    the model and its evaluator path (closed form vs table)."""
    from brdffit.evaluation.render import drjit_eval as dj
    from brdffit.evaluation.render.plugin import make_bsdf
    from brdffit.evaluation.render.proposal import proposal_for
    from brdffit.evaluation.render.translate import to_evaluator

    mi = dj.mi
    ref = _ggx(0.2)
    prop = proposal_for(ref)
    rng = np.random.default_rng(0)
    n = 4096
    wi = rng.normal(size=(n, 3))
    wi[:, 2] = np.abs(wi[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    si = mi.SurfaceInteraction3f()
    si.wi = dj.to_vec3(wi)
    si.uv = mi.Point2f(0.5, 0.5)
    u1 = mi.Float(rng.random(n).astype(np.float32))
    u2 = mi.Point2f(*(rng.random((2, n)).astype(np.float32)))
    ctx = mi.BSDFContext()
    outs = []
    for ev in (to_evaluator(ref, mode="closed"), to_evaluator(ref, mode="table", cache=False),
               to_evaluator(_ggx(0.5, (0.3, 0.3, 0.3)))):
        bs, _ = make_bsdf(ev, proposal=prop).sample(ctx, si, u1, u2, True)
        outs.append((dj.to_numpy(bs.wo), np.asarray(bs.pdf)))
    for wo, pdf in outs[1:]:
        np.testing.assert_array_equal(wo, outs[0][0])
        np.testing.assert_array_equal(pdf, outs[0][1])
    without = make_bsdf(to_evaluator(_ggx(0.5, (0.3, 0.3, 0.3)))).sample(ctx, si, u1, u2, True)[0]
    assert not np.array_equal(dj.to_numpy(without.wo), outs[0][0])  # own sampling differs


@needs_mitsuba
@pytest.mark.render
def test_crn_integrator_reproduces_mitsuba_direct_with_the_plugin():
    """One pass of the multi-model integrator = Mitsuba's direct integrator rendering the
    plugin with the same proposal and seed (same random numbers, same estimator), for every
    model; and a model scaled by 1/2 renders exactly half the image (same directions, same
    number of sample draws)."""
    from brdffit.evaluation.render.core import MultiRenderer, Renderer

    ref, other = _ggx(0.2), _ggx(0.3, (0.2, 0.1, 0.1))
    mr = MultiRenderer({"ref": ref, "other": other}, scene="sphere-env", resolution=24,
                       reference=ref)
    res = mr.render(seed=5, spp=8)
    for key, brdf in (("ref", ref), ("other", other)):
        own = Renderer(brdf, scene="sphere-env", spp=8, resolution=24, proposal=mr.proposal)
        img = own.render(5).image
        np.testing.assert_allclose(res.images[key], img, rtol=1e-4, atol=1e-5)

    class Half:
        kind = "half"
        has_diffuse = True

        def __init__(self, ev):
            self.ev = ev

        def eval(self, wi, wo, s=1.0, active=True):
            return 0.5 * self.ev.eval(wi, wo, s, active)

    ev = mr.evaluators["ref"]
    half = Renderer(scene="sphere-env", spp=8, resolution=24, evaluator=Half(ev),
                    proposal=mr.proposal).render(5).image
    full = Renderer(scene="sphere-env", spp=8, resolution=24, evaluator=ev,
                    proposal=mr.proposal).render(5).image
    np.testing.assert_allclose(half, 0.5 * full, rtol=1e-5, atol=1e-6)


@needs_mitsuba
@pytest.mark.render
@pytest.mark.parametrize("scene", ["sphere-env", "knot"])
def test_crn_model_vs_itself_is_infinite_and_a_perturbed_model_is_stable(scene):
    """With CRN, a model identical to the reference (another object, another evaluator)
    renders the same image (PSNR ∞), and a slightly perturbed model's PSNR is estimated with a
    small standard error that matches its spread over independent seeds; without CRN (each
    model with its own sampling) the same PSNR is swamped by the Monte Carlo noise."""
    from brdffit.evaluation.metrics import crn_psnr
    from brdffit.evaluation.render.core import MultiRenderer, Renderer

    ref = _ggx(0.2)
    models = {"ref": ref, "same": _ggx(0.2), "near": _ggx(0.201)}
    mr = MultiRenderer(models, scene=scene, resolution=32, reference=ref)
    K, spp = 6, 4
    runs = []
    for rep in range(3):
        res = [mr.render(100 * rep + k, spp) for k in range(K)]
        mask = np.mean([r.alpha for r in res], 0) >= 0.999
        st = {k: np.stack([r.images[k] for r in res]) for k in models}
        assert crn_psnr(st["ref"], st["same"], mask)["psnr"] == np.inf
        runs.append(crn_psnr(st["ref"], st["near"], mask))
    ps = np.array([r["psnr"] for r in runs])
    ses = np.array([r["psnr_se"] for r in runs])
    assert np.all(np.isfinite(ps)) and np.all(ses < 1.0), runs
    assert ps.max() - ps.min() < 4 * ses.mean() + 0.2, runs
    # without CRN (each model with its own sampling; the near model through the table path,
    # whose proxy sampler differs from the closed form's): swamped by the noise
    a = Renderer(ref, scene=scene, spp=K * spp, resolution=32).render(0)
    b = Renderer(models["near"], scene=scene, spp=K * spp, resolution=32, mode="table").render(0)
    from brdffit.evaluation.metrics import rendered_psnr

    assert rendered_psnr(a.image, b.image, a.mask) < ps.mean() - 10.0


@needs_mitsuba
@pytest.mark.render
def test_compare_with_mitsuba_reports_psnr_se(tmp_path):
    """compare() end to end with Mitsuba on one small scene: the reference itself is ∞ dB,
    a perturbed model gets a finite PSNR ± a small standard error, result.json has the
    public fields."""
    import json

    from brdffit.evaluation.compare import compare

    ref = _ggx(0.2)
    ref.name = "crn-test"
    res = compare(ref, {"self": ref, "near": _ggx(0.22)}, tmp_path, scenes="sphere-env",
                  spp=48, batches=4, resolution=32, brdf_metrics=("cos_rel_error",),
                  brdf_metric_samples=1 << 8)
    by = {m["name"]: m for m in res["models"]}
    assert by["self"]["psnr"] == np.inf and by["self"]["psnr_se"] == 0.0
    near = by["near"]
    assert np.isfinite(near["psnr"]) and 0 < near["psnr_se"] < 1.0, near
    saved = json.loads((tmp_path / res["slug"] / "result.json").read_text())
    assert [s["name"] for s in saved["scenes"]] == ["sphere-env"]
    assert saved["scenes"][0]["reference"]["peak"] > 0 and "peak_psnr_se" in saved["scenes"][0]["reference"]
    m = next(m for m in saved["models"] if m["name"] == "near")
    assert {"psnr", "psnr_se", "scenes"} <= set(m) and m["scenes"][0]["scene"] == "sphere-env"
    assert "proposal" in saved and saved["proposal"]["cosine_weight"] > 0


def _cached_evaluators() -> int:
    from brdffit.evaluation.render import translate

    return len(translate._CACHE or ())


@needs_mitsuba
@pytest.mark.render
def test_consecutive_comparisons_of_a_thread_share_one_renderer_child(tmp_path):
    """The second comparison of a thread renders in the first one's child (its kernels
    compiled, the first one's evaluators freed), with the same figures as in a new child;
    ``render_cpu_seconds`` counts the child's CPU of that comparison only."""
    from brdffit.evaluation import scene_engines as se
    from brdffit.evaluation.compare import compare

    def run(ref, out):
        return compare(ref, {"near": _ggx(0.22)}, out, scenes="sphere-env", spp=16,
                       batches=2, resolution=32, brdf_metrics=())

    ref_a, ref_b = _ggx(0.2), _ggx(0.3)
    ref_a.name, ref_b.name = "crn-a", "crn-b"
    run(ref_a, tmp_path / "a")
    child, uses, _ = se._RENDERER_CHILD.slot
    assert uses == 1 and child.running and child.init == []
    assert child.call(_cached_evaluators) == 0     # the comparison's evaluators are freed
    before = child.cpu_seconds
    second = run(ref_b, tmp_path / "b")
    assert se._RENDERER_CHILD.slot[0] is child and child.starts == 1
    cpu = second["timing"]["render_cpu_seconds"]   # the child's CPU of this comparison only
    assert 0.5 * (child.cpu_seconds - before) < cpu < child.cpu_seconds
    se._RENDERER_CHILD.slot = (None, 0, None)     # a new child for the same comparison
    child.close()
    fresh = run(ref_b, tmp_path / "c")
    assert se._RENDERER_CHILD.slot[0] is not child
    assert [m["psnr"] for m in fresh["models"]] == [m["psnr"] for m in second["models"]]
