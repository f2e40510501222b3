"""The MaterialX round trip: an exported .mtlx rendered by MaterialX's own ESSL shaders
(WebGL 2 on SwiftShader in headless Chromium) matches the exporter's model of MaterialX's GLSL
(:class:`OpenPBRBRDF`) and lines up with the scene.

One small material (the built-in GGX gold, exported as a metal), 48² pixels with 2 × 2
samples each: the time goes into SwiftShader compiling MaterialX's OpenPBR shader (~5-10 s).
Tolerances (stated; measured: engine vs model 85-87 dB on gold-metallic-paint): engine vs
:class:`OpenPBRBRDF` ≥ 70 dB (the model 1 % brighter scores 64 dB: the check can fail);
covered area within 0.5 % of πR²; brightest pixel within 1 px of the model's.
"""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit.evaluation.engines import materialx_web as MX
from brdffit.evaluation.engines import threejs as T
from brdffit.evaluation.engines import threejs_brdf as TB
from brdffit.evaluation.metrics import rendered_psnr

OK, WHY = T.available()
RES, SS = 48, 2


@pytest.fixture(scope="module")
def roundtrip(tmp_path_factory):
    from brdffit.export.materialx import openpbr_equivalent, write_materialx

    out = tmp_path_factory.mktemp("mtlx")
    fit = brdffit.synthetic("gold-ggx")
    path = out / "gold.mtlx"
    write_materialx(fit, path, fidelity=False)
    return fit, openpbr_equivalent(fit), path


@pytest.mark.slow
@pytest.mark.skipif(not OK, reason=WHY)
def test_materialx_shaders_match_the_exporters_model(roundtrip):
    _, model, path = roundtrip
    r = MX.render_mtlx(path, "sphere-distant", resolution=RES, supersample=SS)
    assert r.info["materialx"].startswith("1.39")
    img, alpha = TB.shade_sphere(model, resolution=RES, supersample=SS)
    m = r.mask & (alpha >= 0.999)
    assert rendered_psnr(r.image, img, m) >= 70.0
    # the check can fail: the model 1 % brighter fails the threshold
    assert rendered_psnr(r.image, 1.01 * img, m) < 70.0      # measured 64 dB
    _, _, R = T.sphere_geometry_px(RES)
    assert abs(r.alpha.sum() / (np.pi * R * R) - 1) < 0.005
    lum = np.array([0.2126, 0.7152, 0.0722])
    pe = np.unravel_index(np.argmax(r.image @ lum), m.shape)
    pm = np.unravel_index(np.argmax(img @ lum), m.shape)
    assert max(abs(pe[0] - pm[0]), abs(pe[1] - pm[1])) <= 1


def test_generate_essl_validates_and_binds_the_light(roundtrip, tmp_path):
    _, _, path = roundtrip
    sh = MX.generate_essl(path, "sphere-distant")
    assert sh["light_type"] == 1 and "mx_directional_light" in sh["fragment"]
    assert sh["fragment"].lstrip().startswith("#version 300 es")
    assert any(k.endswith("specular_roughness") for k in sh["uniforms"])
    with pytest.raises(ValueError, match="sphere-distant"):
        MX.generate_essl(path, "sphere-env")
    with pytest.raises(ValueError, match="inverse-square"):
        MX.generate_essl(path, "sphere-point")
    with pytest.raises(ValueError, match="mtlx"):
        MX.generate_essl(tmp_path / "missing.mtlx")
