"""Engine-aware glTF parameters (brdffit.export.gltf.optimize_for_engines, ``optimize="engines"``):
on a rough lobe the parameters fitted to the engines' renders bring the engines' models
(Blender's Cycles, three.js) closer to the fit; sharp lobes keep the rule's; the option is checked; three's DFG table computed
by quadrature is three's own. The real engines are measured in bench/bench_engines*.py."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.evaluation.engines import threejs_brdf as TB
from brdffit.evaluation.metrics import rendered_psnr
from brdffit.export.gltf import (_engine_fit_gradient, _engine_fit_loss, _engine_fit_vector,
                                 _fit_to_engines, _with_engine_fit_vector,
                                 engine_brdf, gltf_equivalent, gltf_parameters,
                                 optimize_for_engines, threejs_dfg_table)
from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel


def _rough_paint():
    """A ggx-diffuse fit like MERL gold-metallic-paint's: rough (α 0.27), a flat coloured
    Fresnel (F0 0.26/0.18/0.06, F90 0.33/0.23/0.08), no diffuse: a dielectric of high index."""
    return MicrofacetBRDF(GGX(0.27), SchlickFresnel(0.8), diffuse=0.0,
                          specular=[0.33, 0.23, 0.08], name="rough-paint")


def _sphere(brdf, ref, ref_alpha, geometry_roughness=False):
    img, alpha = TB.shade_sphere(brdf, resolution=32, supersample=2,
                                 geometry_roughness=geometry_roughness)
    m = (alpha >= 0.999) & (ref_alpha >= 0.999)
    return rendered_psnr(ref, img, m), img[m].sum(0) / ref[m].sum(0)


def test_engine_aware_parameters_raise_the_modelled_engines_psnr_on_a_rough_lobe():
    fit = _rough_paint()
    rule = gltf_parameters(fit)
    eng = optimize_for_engines(fit, rule, engines=("blender", "threejs"))
    assert rule["metallicFactor"] == eng["metallicFactor"] == 0.0
    k = eng["specular"]["specularFactor"] / rule["specular"]["specularFactor"]
    assert 0.8 < k < 0.995, eng["notes"][-1]                      # lowered, by a few %
    assert eng["specular"]["ior"] == rule["specular"]["ior"]
    assert eng["specular"]["specularColorFactor"] == rule["specular"]["specularColorFactor"]
    assert "fitted to the renders of blender, threejs" in eng["notes"][-1]
    ref, ra = TB.shade_sphere(fit, resolution=32, supersample=4, geometry_roughness=False)
    for engine, gain in (("blender", 8.0), ("threejs", 3.0)):
        before_db, before_ratio = _sphere(engine_brdf(rule, engine), ref, ra)
        after_db, after_ratio = _sphere(engine_brdf(eng, engine), ref, ra)
        # the engine's mean brightness is closer to the fit's, its render closer
        assert np.max(np.abs(after_ratio - 1)) < np.max(np.abs(before_ratio - 1)) - 0.01, (
            engine, before_ratio, after_ratio)
        assert after_db > before_db + gain, (engine, before_db, after_db)
    # the specification's BRDF, which adds no energy, is darker than the fit now
    _, spec_ratio = _sphere(engine_brdf(eng, "specification"), ref, ra)
    assert np.all(spec_ratio < 0.995), spec_ratio


def test_the_default_export_is_fitted_to_three_renderers_and_never_worse_in_the_specification(
        tmp_path):
    from brdffit.export import export

    # a rough plastic: the specification's BRDF, three.js and Blender (within its figure's
    # noise) closer to the fit than with the rules
    fit = MicrofacetBRDF(GGX(0.2), SchlickFresnel(0.045), diffuse=[0.5, 0.2, 0.1])
    info = export(fit, "gltf", tmp_path / "plastic.gltf", fidelity=False)
    note = info["notes"][-1]
    assert "fitted to the renders of specification, blender, threejs" in note, note
    assert info["material"]["roughnessFactor"] == gltf_equivalent(fit).roughness
    ref, ra = TB.shade_sphere(fit, resolution=32, supersample=4, geometry_roughness=False)
    for engine, gain in (("specification", 3.0), ("threejs", 3.0), ("blender", -1.0)):
        before_db, _ = _sphere(gltf_equivalent(fit, optimize=False, engine=engine), ref, ra)
        after_db, _ = _sphere(gltf_equivalent(fit, engine=engine), ref, ra)
        assert after_db > before_db + gain, (engine, before_db, after_db)
    # an exact glTF lobe: any change would render the specification further from the fit
    exact = MicrofacetBRDF(GGX(0.25), SchlickFresnel([0.9, 0.6, 0.3]), correlated=False)
    kept = optimize_for_engines(exact, gltf_parameters(exact))
    assert "rule kept" in kept["notes"][-1], kept["notes"][-1]
    assert kept["baseColorFactor"] == gltf_parameters(exact)["baseColorFactor"]


def test_engine_aware_parameters_keep_sharp_lobes_and_are_checked(tmp_path):
    sharp = MicrofacetBRDF(GGX(0.01), SchlickFresnel(0.04), diffuse=[0.4, 0.1, 0.1],
                           specular=[0.6, 0.6, 0.6])
    rule = gltf_parameters(sharp)
    eng = optimize_for_engines(sharp, rule)
    # sharp highlights: the rule's parameters are kept
    assert {k: v for k, v in eng.items() if k != "notes"} == {
        k: v for k, v in rule.items() if k != "notes"}
    assert "sharp highlights: the rule's parameters are kept" in eng["notes"][-1]
    with pytest.raises(ValueError, match="optimize"):
        gltf_equivalent(sharp, optimize="nope")
    with pytest.raises(ValueError, match="engine"):
        optimize_for_engines(sharp, rule, engines=("unreal",))
    # the command line's option: a boolean, null or a name (write_gltf's Literal annotation)
    from brdffit.cli.export import check_options
    from brdffit.errors import ExportError
    from brdffit.export.gltf import write_gltf

    for value in (True, False, None, "engines", "blender"):
        check_options("gltf", {"optimize": value})
    for value in (1, 0, "nope", 2.5):                  # 1 == True, but not a boolean
        with pytest.raises(ValueError, match="optimize"):
            check_options("gltf", {"optimize": value})
    with pytest.raises(ExportError, match="optimize"):
        write_gltf(sharp, tmp_path / "m.gltf", fidelity=False, optimize="nope")


def test_quadrature_dfg_table_is_threes():
    from brdffit.evaluation.engines.threejs import three_dir

    if three_dir() is None:
        pytest.skip("three.js not installed (make npmdeps)")
    three = TB.dfg_lut()
    mine = threejs_dfg_table()
    e3, em = three[..., 0] + three[..., 1], mine[..., 0] + mine[..., 1]
    assert np.max(np.abs(e3 - em)[1:]) < 0.012                   # N·V ≥ 3/32
    assert np.max(np.abs(e3 - em)) < 0.03                        # the grazing row


def test_the_same_fit_is_optimised_once_per_process(monkeypatch):
    """A report writes a material's glTF file and its fidelity from the same fit: the second
    call returns the kept result (a copy), a changed fit or rule runs the optimiser again."""
    import brdffit.export.gltf as G

    calls = []
    run = G._fit_to_engines
    monkeypatch.setattr(G, "_fit_to_engines", lambda *a: calls.append(1) or run(*a))
    monkeypatch.setattr(G, "_ENGINE_FITS", type(G._ENGINE_FITS)())
    fit = _rough_paint()
    rule = gltf_parameters(fit)
    first = optimize_for_engines(fit, rule, engines=("threejs",))
    first["notes"].append("changed by the caller")
    again = optimize_for_engines(fit, gltf_parameters(fit), engines=("threejs",))
    assert len(calls) == 1 and "changed by the caller" not in again["notes"]
    assert again == {**first, "notes": first["notes"][:-1]}
    optimize_for_engines(fit, dict(rule, roughnessFactor=0.6), engines=("threejs",))
    other = MicrofacetBRDF(GGX(0.27), SchlickFresnel(0.8), diffuse=0.0,
                           specular=[0.33, 0.23, 0.09])
    optimize_for_engines(other, rule, engines=("threejs",))
    optimize_for_engines(fit, rule, engines=("blender",))
    assert len(calls) == 4


_ENGINE_MATERIALS = [
    dict(baseColorFactor=[0.9, 0.6, 0.3, 1.0], metallicFactor=1.0, roughnessFactor=0.4),
    dict(baseColorFactor=[0.2, 0.5, 0.05, 1.0], metallicFactor=0.0, roughnessFactor=0.3,
         specular={"specularFactor": 0.7, "specularColorFactor": [1.0, 0.8, 0.5], "ior": 2.2}),
    dict(baseColorFactor=[0.6, 0.1, 0.3, 1.0], metallicFactor=0.3, roughnessFactor=0.5,
         clearcoat={"clearcoatFactor": 0.5, "clearcoatRoughnessFactor": 0.2}),
]


def _material(d):
    return dict(d, alpha=d["roughnessFactor"] ** 2, anisotropy=None, notes=[])


@pytest.mark.parametrize("engine", ["specification", "blender", "blender-ggx", "threejs"])
@pytest.mark.parametrize("p", _ENGINE_MATERIALS)
def test_a_render_channel_depends_on_the_same_base_colour_channel_only(engine, p):
    """What the engine-aware gradient relies on: stepping base channel c changes channel c
    of every engine model's values and leaves the others bit for bit (metals, Cycles'
    max-channel layering, coats included)."""
    p = _material(p)
    rng = np.random.default_rng(3)
    wi, wo = (v / np.linalg.norm(v, axis=1, keepdims=True)
              for v in np.abs(rng.normal(size=(2, 2000, 3))) + [0, 0, 0.05])
    f0 = engine_brdf(p, engine).eval(wi, wo)
    for c in range(3):
        base = list(p["baseColorFactor"])
        base[c] += 0.05
        f1 = engine_brdf(dict(p, baseColorFactor=base), engine).eval(wi, wo)
        others = [k for k in range(3) if k != c]
        np.testing.assert_array_equal(f1[:, others], f0[:, others])
        assert np.any(f1[:, c] != f0[:, c])


def test_engine_fit_gradient_is_scipys_forward_difference():
    """``_engine_fit_gradient`` (three base-colour differences from one render) equals
    scipy's 2-point difference of the objective with step 1e-4 and the bounds: inside, on
    the upper bounds (a step back) and with a fixed channel (NaN, as scipy's 0/0)."""
    from scipy.optimize._numdiff import approx_derivative

    p = _material(_ENGINE_MATERIALS[1])
    fit = _rough_paint()
    sphere = TB.SphereSamples("sphere-distant", 12, 2)
    ref, alpha = sphere.shade(fit)
    mask = alpha >= 0.999
    engines = ("specification", "blender", "threejs")

    def mse_channels(q):
        pp = _with_engine_fit_vector(p, q, True)
        return np.array([np.mean((sphere.shade(engine_brdf(pp, e))[0][mask] - ref[mask]) ** 2,
                                 axis=0) for e in engines]) / 3.0

    def loss(q):                            # the objective as one MSE per engine
        pp = _with_engine_fit_vector(p, q, True)
        return _engine_fit_loss(np.array([np.mean((sphere.shade(engine_brdf(pp, e))[0][mask]
                                                   - ref[mask]) ** 2) for e in engines]))

    for q, bounds in (([0.2, 0.5, 0.05, 0.7, 0.3], [(0, 1)] * 5),
                      ([1.0, 0.4, 1.0, 1.0, 1.0], [(0, 1)] * 5),
                      ([0.3, 0.0, 0.6, 0.2, 0.45], [(0, 1), (0, 0), (0, 1), (0, 1), (0, 1)])):
        q, bounds = np.array(q, float), np.array(bounds, float)
        f, g = _engine_fit_gradient(mse_channels, bounds)(q)
        with np.errstate(invalid="ignore"):
            want = approx_derivative(loss, q, method="2-point", abs_step=1e-4,
                                     bounds=(bounds[:, 0], bounds[:, 1]))
        assert f == pytest.approx(loss(q), rel=1e-12)
        np.testing.assert_array_equal(np.isnan(g), np.isnan(want))
        ok = ~np.isnan(want)
        np.testing.assert_allclose(g[ok], want[ok], rtol=1e-8, atol=0)


@pytest.mark.parametrize("fit", [_rough_paint(),
                                 MicrofacetBRDF(GGX(0.2), SchlickFresnel([0.9, 0.6, 0.3]),
                                                diffuse=0.0, name="rough-metal")])
def test_engine_fit_takes_the_steps_of_lbfgsb_with_scipys_differences(fit):
    """``_fit_to_engines`` (its own gradient, fixed channels left out) ends where L-BFGS-B
    with scipy's forward differences of the objective ends, options as documented."""
    from scipy import optimize

    p = gltf_parameters(fit)
    sphere = TB.SphereSamples("sphere-distant", 12, 2)
    ref, alpha = sphere.shade(fit)
    mask = alpha >= 0.999
    engines = ("blender", "threejs")
    q0, has_sp = _engine_fit_vector(p)

    def loss(q):
        pp = _with_engine_fit_vector(p, q, has_sp)
        return _engine_fit_loss(np.array([np.mean((sphere.shade(engine_brdf(pp, e))[0][mask]
                                                   - ref[mask]) ** 2) for e in engines])
                                / np.max(ref[mask]) ** 2)

    bounds = [(0.0, 0.0) if i < 3 and q0[i] <= 0.0 else (0.0, 1.0) for i in range(len(q0))]
    want = optimize.minimize(loss, q0, method="L-BFGS-B", bounds=bounds,
                             options={"maxfun": 200, "maxiter": 40, "eps": 1e-4, "ftol": 1e-4})
    got = _fit_to_engines(p, sphere, ref, alpha, engines)
    assert got is not p and "fitted to the renders" in got["notes"][-1]
    q1, _ = _engine_fit_vector(got)
    np.testing.assert_allclose(q1, np.clip(want.x, 0, 1), rtol=0, atol=1e-6)


def test_sphere_samples_pixel_means_are_the_image_pixels():
    """``SphereSamples.pixel_means`` (the objective's renders) gives the pixels of
    ``shade``'s image to rounding."""
    brdf = TB.ThreeJSBRDF([0.6, 0.3, 0.1], 0.4, 0.35, lut=np.full((16, 16, 2), 0.5))
    for res, ss in ((16, 3), (9, 1)):
        sphere = TB.SphereSamples("sphere-distant", res, ss)
        img, alpha = sphere.shade(brdf)
        pixels = alpha > 0.5
        np.testing.assert_allclose(sphere.pixel_means(brdf, pixels), img[pixels],
                                   rtol=1e-13, atol=1e-300)
