"""glTF export: the Appendix B BRDF, the metallic rule, round trip of an exact glTF material."""

from __future__ import annotations

import json

import numpy as np
import pytest

import brdffit
from brdffit.errors import ExportError
from brdffit.export import export
from brdffit.export.gltf import GLTFBRDF, gltf_fidelity, gltf_parameters
from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel


def _pairs(n=2000, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2 * n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    return v[:n], v[n:]


def test_gltf_brdf_matches_library_components():
    wi, wo = _pairs()
    r, base = 0.45, np.array([0.7, 0.3, 0.1])
    a = r * r
    spec04 = MicrofacetBRDF(GGX(a), SchlickFresnel(0.04), correlated=False).eval(wi, wo)
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    F = SchlickFresnel(0.04).eval(np.sum(wo * h, -1))
    ok = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
    expected = np.where(ok, (1 - F) * base / np.pi + spec04, 0.0)
    np.testing.assert_allclose(GLTFBRDF(base, 0.0, r).eval(wi, wo), expected, rtol=1e-10, atol=1e-12)
    metal = MicrofacetBRDF(GGX(a), SchlickFresnel(base), correlated=False).eval(wi, wo)
    np.testing.assert_allclose(GLTFBRDF(base, 1.0, r).eval(wi, wo), metal, rtol=1e-10, atol=1e-12)


def test_exact_gltf_metal_round_trips():
    base, r = np.array([0.95, 0.64, 0.54]), 0.3
    model = MicrofacetBRDF(GGX(r * r), SchlickFresnel(base), correlated=False, name="copper")
    p = gltf_parameters(model)
    assert p["metallicFactor"] == 1.0
    assert p["roughnessFactor"] == pytest.approx(r, rel=1e-12)       # roughness = sqrt(alpha)
    np.testing.assert_allclose(p["baseColorFactor"][:3], base, rtol=1e-12)
    assert gltf_fidelity(model, 4096, ("cos_rel_error",))["cos_rel_error"] < 1e-9


def test_dielectric_rule_and_file(tmp_path):
    model = MicrofacetBRDF(GGX(0.2), SchlickFresnel(0.045), diffuse=[0.5, 0.2, 0.1])
    info = export(model, "gltf", tmp_path / "m.gltf")
    doc = json.loads((tmp_path / "m.gltf").read_text())
    assert doc["asset"]["version"] == "2.0"
    pbr = doc["materials"][0]["pbrMetallicRoughness"]
    assert pbr["metallicFactor"] == 0.0
    np.testing.assert_allclose(pbr["baseColorFactor"], [0.5, 0.2, 0.1, 1.0])
    assert pbr["roughnessFactor"] == pytest.approx(np.sqrt(0.2))
    assert info["fidelity"]["cos_rel_error"] > 0          # F0 0.045 -> 0.04 etc. is lossy


def test_gold_is_metal_and_non_ggx_raises():
    p = gltf_parameters(brdffit.synthetic("gold-ggx"))
    assert p["metallicFactor"] == 1.0
    for name in ("plastic-beckmann", "two-lobe-ggx"):
        with pytest.raises(ExportError, match="glTF"):
            gltf_parameters(brdffit.synthetic(name))


def test_anisotropy_extension_is_exact_for_correlated_ggx(tmp_path):
    base = np.array([0.9, 0.8, 0.7])
    model = MicrofacetBRDF(GGX(0.06, 0.3, 0.45), SchlickFresnel(base), correlated=True)
    p = gltf_parameters(model)
    assert 0 < p["anisotropy"]["anisotropyStrength"] < 1
    wi, wo = _pairs(3000, 5)
    ref = model.eval(wi, wo)
    got = GLTFBRDF(base, 1.0, p["roughnessFactor"],
                   anisotropy_strength=p["anisotropy"]["anisotropyStrength"],
                   anisotropy_rotation=p["anisotropy"]["anisotropyRotation"]).eval(wi, wo)
    ok = ref > 1e-6 * ref.max()
    assert (np.abs(got - ref)[ok] / ref[ok]).max() < 1e-9
    # without the extension the anisotropy is lost (and the loss is measured)
    lossy = gltf_fidelity(model, 4096, ("cos_rel_error",), anisotropy=False)["cos_rel_error"]
    assert lossy > 0.1
    export(model, "gltf", tmp_path / "a.gltf")
    doc = json.loads((tmp_path / "a.gltf").read_text())
    assert doc["extensionsUsed"] == ["KHR_materials_anisotropy"]
    assert "KHR_materials_anisotropy" in doc["materials"][0]["extensions"]


def test_optimize_does_not_increase_error():
    from brdffit.export.gltf import optimize_parameters

    model = MicrofacetBRDF(GGX(0.2), SchlickFresnel([0.3, 0.2, 0.1]), diffuse=[0.2, 0.1, 0.05])
    p = gltf_parameters(model)
    q = optimize_parameters(model, p, n=2048)
    before = gltf_fidelity(model, 4096, ("cos_rel_error",))["cos_rel_error"]
    after = gltf_fidelity(model, 4096, ("cos_rel_error",), optimize=True)["cos_rel_error"]
    assert after <= before + 1e-12
    assert "optimis" in q["notes"][-1]
