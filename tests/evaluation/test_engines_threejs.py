"""The three.js round trip: a glTF export rendered by three.js (WebGL 2 on SwiftShader in
headless Chromium) lines up with our Mitsuba render of the fit and with our model of three.js.

One small material (a ggx-diffuse fit of the built-in Beckmann plastic, a dielectric with the
KHR specular/ior extensions), 64² pixels with 4 × 4 samples each; the full sweep over MERL
stand-ins and RGL is ``bench/bench_engines_threejs.py``.

Tolerances (stated, measured on this material: three vs fit 38.4 dB, mean ratio 1.018 / 1.012 /
1.005, three vs its model 85.7 dB):
* alignment: covered area (sum of alpha) within 0.2 % of the analytic πR² for both renders,
  brightest pixel within 1 px;
* three.js vs :class:`ThreeJSBRDF` (our model of its shader): ≥ 75 dB;
* three.js vs our render of the fit: ≥ 35 dB, per-channel mean ratio within ±4 %, and the
  cheap estimate (model vs fit, noise-free shader) within 1 dB of the measured PSNR.
"""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit.evaluation.engines import threejs as T
from brdffit.evaluation.engines import threejs_brdf as TB
from brdffit.evaluation.metrics import rendered_psnr

OK, WHY = T.available()
pytestmark = pytest.mark.skipif(not OK, reason=WHY)
RES = 64


@pytest.fixture(scope="module")
def roundtrip(tmp_path_factory):
    from brdffit.export.gltf import write_gltf

    out = tmp_path_factory.mktemp("threejs")
    fit = brdffit.fit(brdffit.synthetic("plastic-beckmann"), model="ggx-diffuse")
    path = out / "plastic.gltf"
    write_gltf(fit, path, fidelity=False)
    return fit, path, T.render_gltf(path, "sphere-distant", resolution=RES, supersample=4)


def test_three_renders_the_physical_material_in_float(roundtrip):
    _, _, r = roundtrip
    assert r.info["material_type"] == "MeshPhysicalMaterial"
    assert r.info["three"] == "187" and r.info["three_package"] == "0.187.0"
    assert r.image.dtype == np.float32 and np.isfinite(r.image).all()
    # linear float output: no tone mapping, so values are not squeezed into [0, 1) by a curve
    # and the background is exactly 0
    assert r.image[0, 0].tolist() == [0.0, 0.0, 0.0] and r.alpha[0, 0] == 0.0


def test_engine_matches_its_model(roundtrip):
    """ThreeJSBRDF reproduces three's shading; with (1 − x)⁵ for three's Fresnel, or without
    the geometry roughness, it does not (the check can fail; measured 61 and 52 dB). The
    multiple-scattering compensation is small on this smooth plastic (79 dB without it)."""
    _, path, r = roundtrip
    full, _ = TB.shade_sphere(TB.from_gltf(path), resolution=RES)
    assert rendered_psnr(r.image, full, r.mask) >= 75.0
    pow5, _ = TB.shade_sphere(TB.from_gltf(path, sg_fresnel=False), resolution=RES)
    no_g, _ = TB.shade_sphere(TB.from_gltf(path), resolution=RES, geometry_roughness=False)
    assert rendered_psnr(r.image, pow5, r.mask) < 70.0
    assert rendered_psnr(r.image, no_g, r.mask) < 70.0


@pytest.mark.render
def test_alignment_and_tolerance_vs_our_render(roundtrip):
    from brdffit.evaluation.render import available

    if not available():
        pytest.skip("needs Mitsuba 3 with the LLVM back-end")
    fit, path, r = roundtrip
    refs, ra = T.reference_renders(fit, "sphere-distant", resolution=RES, spp=32, batches=3)
    c = T.compare_render(r.image, r.alpha, refs, ra)
    area = c["coverage"]["analytic"]
    assert abs(c["coverage"]["engine"] / area - 1) < 0.002, c["coverage"]
    assert abs(c["coverage"]["fit"] / area - 1) < 0.002, c["coverage"]
    pe, pf = c["peak_pixel"]["engine"], c["peak_pixel"]["fit"]
    assert max(abs(pe[0] - pf[0]), abs(pe[1] - pf[1])) <= 1, c["peak_pixel"]
    assert c["psnr"] >= 35.0, c
    assert np.all(np.abs(np.array(c["mean_ratio"]) - 1) < 0.04), c["mean_ratio"]
    assert c["flip"] is None or 0.0 <= c["flip"] < 0.3
    # the cheap estimate: our model of three.js against the fit, noise-free, no browser
    est = TB.estimate(fit, path, resolution=RES, supersample=4)
    assert abs(est["psnr"] - c["psnr"]) < 1.0, (est["psnr"], c["psnr"])
    assert np.allclose(est["mean_ratio"], c["mean_ratio"], atol=0.01)


def test_inputs_are_validated(tmp_path):
    with pytest.raises(ValueError, match="scene"):
        T.scene_json("sphere-env")
    with pytest.raises(ValueError, match="resolution"):
        T.scene_json("sphere-distant", resolution="128")
    with pytest.raises(ValueError, match="gltf"):
        T.render_gltf(tmp_path / "missing.gltf")
    bad = tmp_path / "x.gltf"
    bad.write_text('{"materials": [{"pbrMetallicRoughness": {"roughnessFactor": "0.5"}}]}')
    with pytest.raises(ValueError, match="roughnessFactor"):
        TB.from_gltf(bad)
