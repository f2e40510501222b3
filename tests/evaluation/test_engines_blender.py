"""Blender round trip of glTF exports (brdffit.evaluation.engines.blender): Blender's own
importer and Cycles, in our sphere-distant scene, against our Mitsuba render of the fit.

Needs bpy (``make blender`` installs it in .venv-blender) and Mitsuba's LLVM back-end."""

from __future__ import annotations

import json

import numpy as np
import pytest

from brdffit.evaluation.engines import blender
from brdffit.evaluation.render import available as mitsuba_available
from brdffit.export import export
from brdffit.export.gltf import gltf_parameters
from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel

needs_blender = pytest.mark.skipif(
    not blender.available(),
    reason="bpy (Blender as a Python module) is not installed: `make blender` installs it in "
           ".venv-blender, or set $BRDFFIT_BLENDER_PYTHON")
needs_mitsuba = pytest.mark.skipif(not mitsuba_available(),
                                   reason="Mitsuba 3 LLVM back-end unavailable")


def _plastic(diffuse=(0.6, 0.3, 0.1)):
    """A fit glTF holds without extensions: GGX, Schlick F0 0.04 → F90 1, a diffuse term."""
    return MicrofacetBRDF(GGX(0.2), SchlickFresnel(0.04), diffuse=list(diffuse),
                          name="plastic")


@needs_blender
@needs_mitsuba
def test_blender_round_trip_is_aligned_and_sees_a_changed_colour(tmp_path):
    fit = _plastic()
    export(fit, "gltf", tmp_path / "fit.gltf", fidelity=False)
    res = blender.round_trip(fit, tmp_path / "fit.gltf", resolution=48, spp=32, seeds=(0, 1, 2))
    # alignment: same sphere outline (the scene's 256 × 128 polygon is inscribed in the
    # sphere: a fraction of a percent less coverage) and the same highlight pixel
    cov = res["coverage"]
    assert 0.995 < cov["blender"] / cov["fit"] <= 1.001, cov
    assert np.max(np.abs(np.subtract(res["peak_pixel"]["blender"],
                                     res["peak_pixel"]["fit"]))) <= 1, res["peak_pixel"]
    # what the importer made of the file: one mesh carrying the material, the factors as written
    rep = res["blender"]
    meshes = [o for o in rep["objects"] if o["type"] == "MESH"]
    assert len(meshes) == 1 and meshes[0]["materials"] == ["plastic"], rep["objects"]
    # rendered on the scene's sphere, not the file's 64 × 32 preview mesh
    assert rep["scene_sphere"] == {"segments": [256, 128], "vertices": [256 * 127 + 2]}, rep
    inputs = rep["materials"][0]["principled"][0]["inputs"]
    p = json.loads((tmp_path / "fit.gltf").read_text())["materials"][0]["pbrMetallicRoughness"]
    np.testing.assert_allclose(inputs["Base Color"][:3], p["baseColorFactor"][:3], rtol=1e-6)
    assert inputs["Roughness"] == pytest.approx(p["roughnessFactor"], rel=1e-6)
    # Blender renders this exactly representable material close to the fit
    assert np.all(np.abs(np.subtract(res["mean_ratio"], 1.0)) < 0.05), res["mean_ratio"]
    assert res["psnr"] > 30.0 and res["psnr_se"] < 0.5, res
    assert 0.0 <= res["flip"] < 0.2, res["flip"]
    # a file whose red base colour is 30 % lower: the comparison sees it
    darker = _plastic((0.42, 0.3, 0.1))
    export(darker, "gltf", tmp_path / "darker.gltf", fidelity=False)
    b = blender.render_file(tmp_path / "darker.gltf", resolution=48, spp=32, seeds=(0, 1, 2))
    ref, alpha = blender.render_fit(fit, resolution=48, spp=32, seeds=(0, 1, 2))
    worse = blender.compare_renders(ref, alpha, b.images, b.alpha)
    assert worse["psnr"] < res["psnr"] - 6.0, (worse["psnr"], res["psnr"])
    assert worse["mean_ratio"][0] < res["mean_ratio"][0] - 0.1
    assert abs(worse["mean_ratio"][1] - res["mean_ratio"][1]) < 0.03


@needs_blender
def test_a_file_without_mesh_imports_nothing_and_unused_materials_import(tmp_path):
    fit = _plastic()
    export(fit, "gltf", tmp_path / "bare.gltf", fidelity=False, mesh="none")
    assert blender.import_report(tmp_path / "bare.gltf")["objects"] == []
    rep = blender.import_report(tmp_path / "bare.gltf", import_unused_materials=True)
    assert [m["name"] for m in rep["materials"]] == ["plastic"], rep
    with pytest.raises(blender.BlenderFailed, match="no mesh"):
        blender.render_file(tmp_path / "bare.gltf", resolution=16, spp=1, seeds=(0,))


def test_rim_mask_is_the_outer_ring_of_the_disc():
    n = 200
    y, x = np.mgrid[0:n, 0:n]
    r = np.hypot(x + 0.5 - n / 2, y + 0.5 - n / 2)
    alpha = (r < 80).astype(float)
    rim = blender.rim_mask(alpha, 0.85)
    inside = alpha > 0
    assert np.all(r[rim & inside] > 0.85 * 80 - 1) and np.all(r[inside & ~rim] <= 0.85 * 80 + 1)
    # the ring holds 1 − 0.85² of the disc
    assert (rim & inside).sum() / inside.sum() == pytest.approx(1 - 0.85**2, abs=0.02)
    with pytest.raises(ValueError):
        blender.rim_mask(alpha, 1.5)


def test_comparison_reports_a_mirrored_render_and_a_dimmer_one():
    rng = np.random.default_rng(0)
    n = 32
    y, x = np.mgrid[0:n, 0:n]
    r = np.hypot(x + 0.5 - n / 2, y + 0.5 - n / 2)
    alpha = (r < 12).astype(np.float32)
    shade = np.clip(1.0 - np.hypot(x - 10.0, y - 12.0) / 20.0, 0, None) * alpha
    img = np.stack([shade, 0.5 * shade, 0.25 * shade], -1)
    ref = np.stack([img + rng.normal(0, 1e-3, img.shape) * alpha[..., None] for _ in range(3)])
    same = blender.compare_renders(ref, alpha, ref[::-1].copy(), alpha, flip=False)
    assert same["peak_pixel"]["fit"] == same["peak_pixel"]["blender"]
    mirrored = blender.compare_renders(ref, alpha, ref[:, :, ::-1].copy(), alpha, flip=False)
    assert mirrored["peak_pixel"]["fit"] != mirrored["peak_pixel"]["blender"]
    dim = blender.compare_renders(ref, alpha, ref * [0.9, 1.0, 1.0], alpha)
    np.testing.assert_allclose(dim["mean_ratio"], [0.9, 1.0, 1.0], rtol=1e-9)
    np.testing.assert_allclose(dim["rim_ratio"], [0.9, 1.0, 1.0], rtol=1e-9)
    assert dim["psnr"] < same["psnr"] and dim["flip"] > 0


@needs_blender
@needs_mitsuba
def test_cycles_equivalent_predicts_blender_where_the_specification_does_not(tmp_path):
    """A fit with a coloured specular (as chm_mint's): Blender dims the diffuse by one scalar,
    its f90 is 1 and its GGX is multiscatter. Our model of that
    (gltf_equivalent(engine="blender")) is much closer to Blender's render than the
    specification's BRDF is."""
    from brdffit.export.gltf import gltf_equivalent

    fit = MicrofacetBRDF(GGX(0.15), SchlickFresnel([0.02, 0.1, 0.08]), diffuse=[0.1, 0.3, 0.3],
                         specular=0.5, name="tinted")
    export(fit, "gltf", tmp_path / "tinted.gltf", fidelity=False)
    seeds = (0, 1, 2)
    b = blender.render_file(tmp_path / "tinted.gltf", resolution=48, spp=32, seeds=seeds)
    res = {}
    for engine in ("specification", "blender"):
        img, alpha = blender.render_fit(gltf_equivalent(fit, engine=engine), resolution=48,
                                        spp=32, seeds=seeds)
        res[engine] = blender.compare_renders(img, alpha, b.images, b.alpha, flip=False)
    assert res["blender"]["psnr"] > res["specification"]["psnr"] + 10.0, res
    assert np.all(np.abs(np.subtract(res["blender"]["mean_ratio"], 1.0)) < 0.01), res["blender"]
    # the specification's BRDF misses Blender's dimmer red diffuse by several percent
    assert res["specification"]["mean_ratio"][0] < 0.97, res["specification"]


@needs_blender
@needs_mitsuba
def test_usd_export_imports_with_its_material_and_renders_like_the_gltf(tmp_path):
    """Blender's USD importer (default options) reads the USD export's preview mesh with the
    material bound, as UsdPreviewSurface's values, and Cycles renders it like the glTF of the
    same fit (a fit both formats hold exactly: F0 0.04 is ior 1.5)."""
    fit = _plastic()
    export(fit, "usd", tmp_path / "fit.usda")
    export(fit, "gltf", tmp_path / "fit.gltf", fidelity=False)
    seeds = (0, 1, 2)
    u = blender.render_file(tmp_path / "fit.usda", resolution=48, spp=32, seeds=seeds)
    meshes = [o for o in u.report["objects"] if o["type"] == "MESH"]
    assert len(meshes) == 1 and meshes[0]["materials"] == ["plastic"], u.report["objects"]
    inputs = u.report["materials"][0]["principled"][0]["inputs"]
    p = gltf_parameters(fit)
    np.testing.assert_allclose(inputs["Base Color"][:3], p["baseColorFactor"][:3], rtol=1e-6)
    assert inputs["Roughness"] == pytest.approx(p["roughnessFactor"], rel=1e-6)
    assert inputs["IOR"] == pytest.approx(1.5, rel=1e-6)
    g = blender.render_file(tmp_path / "fit.gltf", resolution=48, spp=32, seeds=seeds)
    same = blender.compare_renders(g.images, g.alpha, u.images, u.alpha, flip=False)
    assert same["peak_pixel"]["fit"] == same["peak_pixel"]["blender"], same["peak_pixel"]
    assert 0.999 < same["coverage"]["blender"] / same["coverage"]["fit"] < 1.001
    assert np.all(np.abs(np.subtract(same["mean_ratio"], 1.0)) < 0.01), same["mean_ratio"]
    assert same["psnr"] > 50.0, same


@needs_blender
@needs_mitsuba
def test_environment_map_scene_is_rebuilt_with_mitsubas_orientation(tmp_path):
    """sphere-env in Blender (the procedural map as the world, turned to Mitsuba's lat-long
    convention) against our render of what Cycles shades (the Blender model of the export):
    the same light, where the map turned half a turn is far off."""
    from brdffit.evaluation.render.core import Renderer
    from brdffit.evaluation.render.scenes import procedural_envmap
    from brdffit.export.gltf import gltf_equivalent

    fit = MicrofacetBRDF(GGX(0.1), SchlickFresnel(0.04), diffuse=[0.6, 0.3, 0.1], name="p")
    export(fit, "gltf", tmp_path / "p.gltf", fidelity=False)
    seeds = (0, 1, 2)
    b = blender.render_file(tmp_path / "p.gltf", "sphere-env", resolution=32, spp=64,
                            seeds=seeds)
    model = gltf_equivalent(fit, engine="blender")
    ref, alpha = blender.render_fit(model, "sphere-env", resolution=32, spp=64, seeds=seeds)
    same = blender.compare_renders(ref, alpha, b.images, b.alpha, flip=False)
    assert np.all(np.abs(np.subtract(same["mean_ratio"], 1.0)) < 0.02), same["mean_ratio"]
    turned = np.roll(procedural_envmap(), procedural_envmap().shape[1] // 2, axis=1)
    r = Renderer(model, "sphere-env", turned, 64, 32)
    other = np.stack([r.render(seed=s).image for s in seeds])
    wrong = blender.compare_renders(other, alpha, b.images, b.alpha, flip=False)
    assert np.max(np.abs(np.subtract(wrong["mean_ratio"], 1.0))) > 0.1, wrong["mean_ratio"]
    assert wrong["psnr"] < same["psnr"] - 10.0, (wrong["psnr"], same["psnr"])
    with pytest.raises(ValueError, match="not rebuilt"):
        blender.render_file(tmp_path / "p.gltf", "knot", resolution=16, spp=1, seeds=(0,))
