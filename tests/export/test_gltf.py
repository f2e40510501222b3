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
from tests.support.engine_materials import ENGINE_TEST_MATERIALS


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


def cosine_pairs_grid(k=16):
    """``(wi, wo)``: a stratified grid of k⁴ direction pairs, both cosine-distributed, for
    cosine-weighted means over pairs independent of the exporters' random pairs (also used
    by test_materialx)."""
    from brdffit.brdf import cosine_hemisphere_sample

    u = (np.stack(np.meshgrid(*[np.arange(k)] * 4, indexing="ij"), -1).reshape(-1, 4) + 0.5) / k
    return cosine_hemisphere_sample(u[:, :2]), cosine_hemisphere_sample(u[:, 2:])


def _kept_by_schlick(f0, f90, k=16):
    """Cosine-weighted mean of ``1 − Schlick(f0, f90, V·H)`` over a stratified grid of
    direction pairs: the fraction of the base glTF's dielectric keeps on average."""
    wi, wo = cosine_pairs_grid(k)
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    x5 = (1.0 - np.sum(wo * h, -1)) ** 5
    return float(np.mean(1.0 - (f0 + (f90 - f0) * x5)))


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
    info = export(model, "gltf", tmp_path / "m.gltf", optimize=False)      # the rules alone
    doc = json.loads((tmp_path / "m.gltf").read_text())
    assert doc["asset"]["version"] == "2.0"
    pbr = doc["materials"][0]["pbrMetallicRoughness"]
    assert pbr["metallicFactor"] == 0.0
    # ρd divided by the fraction of the base glTF keeps under its specular layer (F0 0.045)
    kept = _kept_by_schlick(0.045, 1.0)
    assert 0.85 < kept < 0.97
    np.testing.assert_allclose(pbr["baseColorFactor"], [0.5 / kept, 0.2 / kept, 0.1 / kept, 1.0],
                               rtol=2e-3)
    assert pbr["roughnessFactor"] == pytest.approx(np.sqrt(0.2))
    assert info["fidelity"]["cos_rel_error"] > 0          # F0 0.045 -> 0.04 etc. is lossy


def test_gold_is_metal_and_non_ggx_raises():
    p = gltf_parameters(brdffit.synthetic("gold-ggx"))
    assert p["metallicFactor"] == 1.0
    for name in ("sgd-paint", "two-lobe-ggx"):
        with pytest.raises(ExportError, match="glTF"):
            gltf_parameters(brdffit.synthetic(name))


def test_beckmann_becomes_ggx_of_the_same_alpha():
    p = gltf_parameters(brdffit.synthetic("plastic-beckmann"))     # Beckmann α = 0.18, η = 1.5
    assert p["roughnessFactor"] == pytest.approx(np.sqrt(0.18), rel=1e-12)
    assert p["metallicFactor"] == 0.0
    assert any("Beckmann" in n for n in p["notes"])


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


# -- KHR_materials_specular / KHR_materials_ior --------------------------------------------
def test_gltf_brdf_extensions_match_the_spec_formula():
    """GLTFBRDF with specular/ior vs the extension's implementation formula written with
    library components: F_d = f90 Schlick(f0/f90), f0 = min(F0(ior) color, 1) f90."""
    wi, wo = _pairs(3000, 3)
    base, r, sf, sc, ior = np.array([0.3, 0.5, 0.2]), 0.4, 0.7, np.array([1.0, 0.6, 0.3]), 1.8
    f0 = np.minimum(((ior - 1) / (ior + 1)) ** 2 * sc, 1.0) * sf
    spec = MicrofacetBRDF(GGX(r * r), SchlickFresnel(f0 / sf),
                          specular=sf, correlated=False).eval(wi, wo)
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    F = sf * SchlickFresnel(f0 / sf).eval(np.abs(np.sum(wo * h, -1)))
    ok = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
    expected = np.where(ok, (1 - F) * base / np.pi + spec, 0.0)
    got = GLTFBRDF(base, 0.0, r, specular_factor=sf, specular_color=sc, ior=ior).eval(wi, wo)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("fresnel, ks", [(SchlickFresnel([0.06, 0.035, 0.02]), 0.65),
                                         (SchlickFresnel([0.05, 0.05, 0.05]), [0.9, 0.8, 0.7])])
def test_dielectric_f0_and_f90_go_through_the_extensions(fresnel, ks):
    from brdffit.microfacet import DielectricFresnel

    model = MicrofacetBRDF(GGX(0.15), fresnel, diffuse=[0.4, 0.3, 0.2], specular=ks)
    p = gltf_parameters(model)
    eq = _gltf_brdf(p)
    f0_d, f90_d = eq.dielectric_f0_f90()
    F0 = np.asarray(ks) * fresnel.eval(1.0)
    np.testing.assert_allclose(f0_d, F0, rtol=1e-9)              # F0 exact, every channel
    assert f90_d == pytest.approx(np.max(ks))                     # F90: the largest channel
    assert np.all(np.asarray(p["specular"]["specularColorFactor"]) <= 1 + 1e-12)
    with_ext = gltf_fidelity(model, 4096, ("cos_rel_error",))["cos_rel_error"]
    core = gltf_fidelity(model, 4096, ("cos_rel_error",), specular=False)["cos_rel_error"]
    assert with_ext < core                                        # the extensions help
    # a dielectric fit of index η and grey ks gives back ior = η and specularFactor = ks
    d = MicrofacetBRDF(GGX(0.15), DielectricFresnel(1.7), diffuse=0.3, specular=0.8)
    q = gltf_parameters(d)["specular"]
    assert q["ior"] == pytest.approx(1.7, rel=1e-9) and q["specularFactor"] == pytest.approx(0.8)


def _gltf_brdf(p):
    from brdffit.export.gltf import _brdf_of

    return _brdf_of(p)


# -- the Khronos glTF-Validator ------------------------------------------------------------
_VALIDATE_JS = r"""
const fs = require('fs');
const validator = require(process.argv[2]);
const data = new Uint8Array(fs.readFileSync(process.argv[3]));
validator.validateBytes(data, {uri: process.argv[3], maxIssues: 1000})
  .then((report) => { process.stdout.write(JSON.stringify(report)); })
  .catch((err) => { process.stderr.write(String(err)); process.exit(2); });
"""


def _validator(tmp_path):
    """``validate(path) -> report`` with the project's gltf-validator (make npmdeps)."""
    import shutil
    import subprocess
    from pathlib import Path

    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed: the Khronos glTF-Validator (npm gltf-validator) "
                    "cannot run")
    pkg = Path(__file__).resolve().parents[2] / ".npm" / "node_modules" / "gltf-validator"
    if not (pkg / "package.json").is_file():
        if shutil.which("npm") is None:
            pytest.skip("npm is not installed: gltf-validator cannot be installed")
        pytest.fail(f"gltf-validator is missing from {pkg.parent}: run `make npmdeps` "
                    "(make install / make test do it)")
    script = tmp_path / "validate.js"
    script.write_text(_VALIDATE_JS)

    def validate(path):
        r = subprocess.run([node, str(script), str(pkg), str(path)], capture_output=True,
                           text=True, timeout=120)
        assert r.returncode == 0, r.stderr
        return json.loads(r.stdout)

    return validate


def _errors(report):
    return [(m["code"], m.get("pointer"), m["message"]) for m in report["issues"]["messages"]
            if m["severity"] == 0]


def test_exports_pass_the_khronos_validator(tmp_path):
    from brdffit.microfacet import DielectricFresnel

    validate = _validator(tmp_path)
    models = {
        "metal": brdffit.synthetic("gold-ggx"),
        "aniso-metal": brdffit.synthetic("aniso-ggx"),
        "beckmann-plastic": brdffit.synthetic("plastic-beckmann"),
        # anisotropic dielectric: KHR_materials_anisotropy + specular + ior at once
        "aniso-dielectric": MicrofacetBRDF(GGX(0.05, 0.2, 0.3), DielectricFresnel(1.8),
                                           diffuse=[0.5, 0.2, 0.1], specular=[0.9, 0.7, 0.6],
                                           name='evil "name" </script>\u0000 \U0001F600'),
        "black": MicrofacetBRDF(GGX(0.3), SchlickFresnel(0.0), diffuse=0.0),
        "coated": _coated(),
        # a rough flat-Fresnel dielectric, its specularFactor lowered for the engines below
        "rough-paint-engines": MicrofacetBRDF(GGX(0.27), SchlickFresnel(0.8), diffuse=0.0,
                                              specular=[0.33, 0.23, 0.08]),
    }
    seen = set()
    for key, model in models.items():
        for mesh in ("sphere", "none"):
            out = tmp_path / f"{key}-{mesh}.gltf"
            info = export(model, "gltf", out, fidelity=False, mesh=mesh,
                          optimize="blender" if key.endswith("-engines") else False)
            seen.update(info["extensions"])
            report = validate(out)
            assert report["issues"]["numErrors"] == 0, (key, mesh, _errors(report))
            assert report["issues"]["numWarnings"] == 0, (key, mesh,
                                                          report["issues"]["messages"])
            info = report["info"]
            assert info["materialCount"] == 1, (key, mesh, info)
            # the sphere: a scene with one drawn primitive using the material
            assert info.get("drawCallCount", 0) == (1 if mesh == "sphere" else 0), (key, info)
    assert seen == {"KHR_materials_anisotropy", "KHR_materials_specular", "KHR_materials_ior",
                    "KHR_materials_clearcoat"}
    engines = json.loads((tmp_path / "rough-paint-engines-none.gltf").read_text())
    assert "fitted to the renders of blender" in engines["materials"][0]["extras"]["brdffit"]["notes"][-1]
    # the check can fail: the validator reports an out-of-range factor and an undeclared
    # extension as errors
    doc = json.loads((tmp_path / "aniso-dielectric-sphere.gltf").read_text())
    doc["materials"][0]["pbrMetallicRoughness"]["roughnessFactor"] = 2.0
    doc["extensionsUsed"].remove("KHR_materials_ior")
    (tmp_path / "bad.gltf").write_text(json.dumps(doc))
    codes = {c for c, _, _ in _errors(validate(tmp_path / "bad.gltf"))}
    assert "VALUE_NOT_IN_RANGE" in codes and "UNDECLARED_EXTENSION" in codes, codes


def test_metal_like_fit_with_low_grazing_reflectance_stays_dielectric():
    """F0 looks metallic (0.2) but F90 is 0.3 (ks·Schlick, as ggx-diffuse finds on metallic
    paints): glTF's metal would force F90 = 1; with the extensions it is a dielectric that
    keeps F0 and whose base keeps ρd (compensated for the layer) — and it is closer to the
    fit. Its flat Fresnel (F0/F90 = 2/3) would need ior 9.9: with the bound ior = 3 the
    specularFactor (f90) rises to F0 / 0.25 = 0.8 (noted); with max_ior = 10 it is 0.3."""
    fit = MicrofacetBRDF(GGX(0.1), SchlickFresnel(2.0 / 3.0), diffuse=[0.05, 0.04, 0.03],
                         specular=[0.3, 0.3, 0.3])
    core = gltf_parameters(fit, specular=False)            # core glTF only: the metal rule
    assert core["metallicFactor"] == 1.0
    core_err = gltf_fidelity(fit, metrics=("normalized_l2",), specular=False,
                             optimize=False)["normalized_l2"]
    for max_ior, f90 in ((3.0, 0.8), (10.0, 0.3)):
        p = gltf_parameters(fit, max_ior=max_ior)
        assert p["metallicFactor"] == 0.0
        assert p["specular"]["ior"] <= max_ior
        assert p["specular"]["specularFactor"] == pytest.approx(f90, rel=1e-9)
        np.testing.assert_allclose(_gltf_brdf(p).dielectric_f0_f90()[0], 0.2, rtol=1e-9)
        assert any("raised from 0.3 to 0.8" in n for n in p["notes"]) == (max_ior == 3.0)
        np.testing.assert_allclose(p["baseColorFactor"][:3],
                                   np.array([0.05, 0.04, 0.03]) / _kept_by_schlick(0.2, f90),
                                   rtol=2e-3)
        mine = gltf_fidelity(fit, metrics=("normalized_l2",), max_ior=max_ior,
                             optimize=False)["normalized_l2"]
        assert mine < (0.7 if max_ior == 3.0 else 0.1) * core_err, (max_ior, mine, core_err)


@pytest.mark.parametrize("F0, F90", [([0.2, 0.2, 0.2], [0.3, 0.3, 0.3]),
                                     ([0.5, 0.4, 0.3], [0.55, 0.5, 0.45]),
                                     ([0.03, 0.04, 0.05], [1.0, 1.0, 1.0]),
                                     ([0.9, 0.9, 0.9], [0.9, 0.9, 0.9])])
def test_exported_ior_and_factors_stay_in_range(F0, F90):
    """ior in [1, 3] when F0 ≤ 0.25 (F0 of ior 3), above only with a note; specular
    factors in [0, 1]; F0 kept."""
    fit = MicrofacetBRDF(GGX(0.2), SchlickFresnel(np.divide(F0, F90)), diffuse=[0.3, 0.2, 0.1],
                         specular=list(F90))
    p = gltf_parameters(fit)
    if p["metallicFactor"] == 1.0:
        return
    sp = p["specular"]
    assert 1.0 <= sp["ior"]
    assert (sp["ior"] <= 3.0) == (max(F0) <= 0.25)
    assert (sp["ior"] <= 3.0) != any("above max_ior" in n for n in p["notes"])
    assert 0.0 <= sp["specularFactor"] <= 1.0
    assert all(0.0 <= c <= 1.0 for c in sp["specularColorFactor"])
    np.testing.assert_allclose(_gltf_brdf(p).dielectric_f0_f90()[0], F0, rtol=1e-9)


def _albedo_on_grid(brdf, k=16):
    """π × the mean of f over :func:`cosine_pairs_grid`: the cosine-weighted mean albedo."""
    wi, wo = cosine_pairs_grid(k)
    return np.pi * np.mean(np.asarray(brdf.eval(wi, wo)), axis=0)


def test_metal_keeps_the_fits_mean_albedo_when_its_grazing_reflectance_exceeds_one():
    """A rough fit whose F90 is ~2 (ks·Schlick, as ggx-diffuse finds on polyethylene) is a
    metal under the rule; glTF's metal stops at F90 = 1, so base colour = F0 loses a third of
    the light. The exported base colour is the one whose cosine-weighted mean albedo is the
    fit's (rendered: polyethylene 13.6 → 33.2 dB)."""
    f0, ks = np.array([0.5, 0.445, 0.375]), np.array([2.14, 1.96, 1.93])   # ks·F at 0°, 90°
    fit = MicrofacetBRDF(GGX(0.79), SchlickFresnel(f0 / ks), diffuse=[0.031, 0.07, 0.098],
                         specular=ks)
    p = gltf_parameters(fit)
    assert p["metallicFactor"] == 1.0
    target = _albedo_on_grid(fit)
    got = _albedo_on_grid(GLTFBRDF(p["baseColorFactor"][:3], 1.0, p["roughnessFactor"]))
    np.testing.assert_allclose(got, target, rtol=1e-2)
    as_f0 = _albedo_on_grid(GLTFBRDF(f0, 1.0, p["roughnessFactor"]))
    assert np.all(np.abs(as_f0 / target - 1) > 0.15)        # what base colour = F0 gave
    assert np.all(np.asarray(p["baseColorFactor"][:3]) > f0)


def _coated(w=0.07, a_coat=0.03):
    """A coated diffuse fit as ggx-diffuse returns it (base lobe + white coat lobe)."""
    from brdffit.microfacet.coat import COAT_F0
    from brdffit.microfacet import SumBRDF

    base = MicrofacetBRDF(GGX(0.005), SchlickFresnel([0.9, 0.85, 0.8]),
                          diffuse=[0.25, 0.04, 0.02], specular=[0.004, 0.0035, 0.0035])
    coat = MicrofacetBRDF(GGX(a_coat), SchlickFresnel(np.full(3, COAT_F0)),
                          specular=np.full(3, w))
    return SumBRDF([base, coat], name="coated")


def test_clearcoat_follows_the_extension_formula():
    """GLTFBRDF with a clear coat is KHR_materials_clearcoat's layering of the core BRDF:
    ``f_base (1 − c Fc) + c Fc D V`` with ``Fc = 0.04 + 0.96 (1 − |N·V|)⁵`` (V = wo) and the
    coat's core GGX D·V of α = roughness²."""
    rng = np.random.default_rng(3)
    v = rng.normal(size=(4000, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    wi, wo = v[:2000], v[2000:]
    base = GLTFBRDF([0.3, 0.2, 0.1], 0.0, 0.4)
    coated = GLTFBRDF([0.3, 0.2, 0.1], 0.0, 0.4, clearcoat=0.6, clearcoat_roughness=0.3)
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    dv = GLTFBRDF._core_dv(0.09, wi, wo, h)[:, None]
    fc = (0.04 + 0.96 * (1.0 - wo[:, 2]) ** 5)[:, None]
    want = base.eval(wi, wo) * (1.0 - 0.6 * fc) + 0.6 * fc * dv
    np.testing.assert_allclose(coated.eval(wi, wo), want, rtol=1e-12, atol=1e-300)
    assert coated.as_microfacet() is None


def test_coated_fit_maps_to_clearcoat_and_stays_close():
    fit = _coated()
    p = gltf_parameters(fit)
    assert p["clearcoat"]["clearcoatFactor"] == pytest.approx(0.07)
    assert p["clearcoat"]["clearcoatRoughnessFactor"] == pytest.approx(np.sqrt(0.03))
    base_only = gltf_parameters(fit.components[0])
    assert p["baseColorFactor"] == base_only["baseColorFactor"]
    err = gltf_fidelity(fit, metrics=("cos_rel_error",))["cos_rel_error"]
    from brdffit.evaluation.metrics import brdf_metrics

    dropped = brdf_metrics(fit, _gltf_brdf(base_only), 1 << 15,
                           metrics=("cos_rel_error",))["cos_rel_error"]
    assert err < 0.03 and err < 0.5 * dropped, (err, dropped)


def test_coated_fit_exported_as_one_lobe_when_that_is_closer():
    """glTF's clearcoat (Fresnel of N·V, layered) departs from a rough, heavy added coat; the
    exporter then writes one lobe fitted to the coated fit when that is closer to it (the
    choice and both errors are in the notes)."""
    from brdffit.evaluation.metrics import brdf_metrics
    from brdffit.export.gltf import _with_clearcoat
    from tests.fit.test_analytic import _coated_material

    fit = brdffit.fit_ggx_diffuse(_coated_material(w=0.6, a_base=0.12, a_coat=0.25))
    assert fit.fit_info["coat"]["kept"]
    p = gltf_parameters(fit)
    coat_only = _with_clearcoat(gltf_parameters(fit.components[0]), fit.components[1])

    def err(q):
        return brdf_metrics(fit, _gltf_brdf(q), 1 << 15, metrics=("cos_rel_error",))[
            "cos_rel_error"]

    assert "coated fit exported as" in p["notes"][-1]
    assert err(p) <= err(coat_only) * 1.05


def test_preview_sphere_is_the_scenes_sphere():
    """Unit radius, normals = positions, u = 0.5 facing +Z (the camera), v = 0 at +Y, every
    triangle counter-clockwise seen from outside, tangents along ∂p/∂u, and the mesh covers
    the sphere: the triangles' area approaches 4π."""
    from brdffit.export.gltf import uv_sphere

    m = uv_sphere(32, 16)
    p, n, uv, t = m["positions"], m["normals"], m["texcoords"], m["tangents"]
    np.testing.assert_allclose(np.linalg.norm(p, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(n, p, atol=0)
    front = np.argmax(p[:, 2])
    assert abs(uv[front, 0] - 0.5) < 1e-6 and abs(uv[front, 1] - 0.5) < 1e-6
    assert np.all(uv[p[:, 1] > 1 - 1e-6, 1] == 0.0)
    tri = m["indices"].reshape(-1, 3).astype(int)
    cross = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    assert np.all(np.sum(cross * p[tri].mean(1), -1) > 0)
    area = 0.5 * np.linalg.norm(cross, axis=1).sum()
    assert 0.97 * 4 * np.pi < area < 4 * np.pi
    # ∂p/∂u by finite differences along a ring at the equator
    ring = np.flatnonzero(np.abs(p[:, 1]) < 1e-6)
    k = ring[np.argsort(uv[ring, 0])]
    dp = p[k[1:]] - p[k[:-1]]
    dp /= np.linalg.norm(dp, axis=1, keepdims=True)
    mid = 0.5 * (t[k[1:], :3] + t[k[:-1], :3])
    assert np.all(np.sum(dp * mid, -1) > 0.99)
    # glTF's bitangent w (n × t) points along +v (down the sphere)
    b = t[:, 3:] * np.cross(n, t[:, :3])
    assert np.all(b[ring, 1] < -0.99)
    with pytest.raises(ValueError, match="segments"):
        uv_sphere(2, 16)


def test_mesh_option_is_checked_and_none_leaves_the_material_alone(tmp_path):
    from brdffit.errors import ExportError

    model = brdffit.synthetic("plastic-beckmann")
    with pytest.raises(ExportError, match="mesh"):
        export(model, "gltf", tmp_path / "a.gltf", fidelity=False, mesh="cube")
    export(model, "gltf", tmp_path / "b.gltf", fidelity=False, mesh="none")
    doc = json.loads((tmp_path / "b.gltf").read_text())
    assert "meshes" not in doc and "nodes" not in doc and len(doc["materials"]) == 1
    # the placeholder image is a PNG that decodes to one white pixel
    import base64
    import zlib

    png = base64.b64decode(doc["images"][0]["uri"].split(",", 1)[1])
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    idat = png.index(b"IDAT")
    size = int.from_bytes(png[idat - 4:idat], "big")
    assert zlib.decompress(png[idat + 4:idat + 4 + size]) == b"\x00\xff\xff\xff\xff"


@pytest.mark.parametrize("kwargs", [
    *ENGINE_TEST_MATERIALS,
    dict(base_color=[0.3, 0.3, 0.3], metallic=0.5, roughness=0.0, clearcoat=1.0)])
def test_gltf_brdf_compiled_eval_is_the_numpy_eval(kwargs, monkeypatch):
    """``GLTFBRDF._eval_compiled`` (``_gltf_kernel``) gives the NumPy path's values to
    rounding, below the horizon included."""
    import brdffit.export.gltf_brdf as gb

    rng = np.random.default_rng(8)
    v = rng.normal(size=(2, 40, 90, 3))
    wi, wo = v / np.linalg.norm(v, axis=-1, keepdims=True)
    brdf = GLTFBRDF(**kwargs)
    got = brdf._eval_compiled(wi, wo)
    monkeypatch.setattr(gb, "_numba", None)
    want = brdf.eval(wi, wo)
    assert got.shape == want.shape == (40, 90, 3)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-15)
    assert np.any(want == 0) and np.all(np.isfinite(want))
