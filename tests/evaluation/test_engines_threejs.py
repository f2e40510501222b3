"""The three.js round trip: a glTF export rendered by three.js (WebGL 2 on SwiftShader in
headless Chromium) lines up with our Mitsuba render of the fit and with our model of three.js.

One small material (a red plastic in the form of a ggx-diffuse fit: GGX α = 0.19, coloured
Schlick F0, Lambert; exported as a dielectric with the KHR specular/ior extensions), 64² pixels
with 4 × 4 samples each; the full sweep over MERL
stand-ins and RGL is ``bench/bench_engines_threejs.py``.

Tolerances (stated, measured on this material: three vs fit 50.9 ± 0.2 dB, mean ratio 1.004 /
1.010 / 1.013, three vs its model 83.7 dB, the estimate 51.1 dB):
* alignment: covered area (sum of alpha) within 0.2 % of the analytic πR² for both renders,
  brightest pixel within 1 px;
* three.js vs :class:`ThreeJSBRDF` (our model of its shader): ≥ 75 dB;
* three.js vs our render of the fit: ≥ 45 dB, per-channel mean ratio within ±4 %, and the
  cheap estimate (model vs fit, noise-free shader) within 1 dB of the measured PSNR.
"""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.evaluation.engines import threejs as T
from brdffit.evaluation.engines import threejs_brdf as TB
from brdffit.evaluation.metrics import rendered_psnr
from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel

OK, WHY = T.available()
pytestmark = pytest.mark.skipif(not OK, reason=WHY)
RES = 64


@pytest.fixture(scope="module")
def roundtrip(tmp_path_factory):
    from brdffit.export.gltf import write_gltf

    out = tmp_path_factory.mktemp("threejs")
    # a ggx-diffuse fit's form (GGX + Schlick + Lambert), built directly: a fit and the
    # coated export's lobe choice would add ~5 s
    fit = MicrofacetBRDF(GGX(0.19, 0.19), SchlickFresnel([0.035, 0.063, 0.093]),
                         diffuse=[0.43, 0.043, 0.024])
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
    """ThreeJSBRDF reproduces three's shading; with (1 − x)⁵ for three's Fresnel, without
    the geometry roughness or without the multiple-scattering compensation it does not (the
    check can fail; measured 62, 49 and 67 dB)."""
    _, path, r = roundtrip
    full, _ = TB.shade_sphere(TB.from_gltf(path), resolution=RES)
    assert rendered_psnr(r.image, full, r.mask) >= 75.0
    pow5, _ = TB.shade_sphere(TB.from_gltf(path, sg_fresnel=False), resolution=RES)
    no_g, _ = TB.shade_sphere(TB.from_gltf(path), resolution=RES, geometry_roughness=False)
    no_ms, _ = TB.shade_sphere(TB.from_gltf(path, multiscatter=False), resolution=RES)
    assert rendered_psnr(r.image, pow5, r.mask) < 70.0
    assert rendered_psnr(r.image, no_g, r.mask) < 70.0
    assert rendered_psnr(r.image, no_ms, r.mask) < 70.0


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
    assert c["psnr"] >= 45.0, c
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
