"""MaterialX export: open_pbr_surface documents accepted by MaterialX's validate(), the
mapping back to a BRDF (OpenPBRBRDF), hostile names."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit.export import TARGETS, export
from brdffit.microfacet import GGX, DielectricFresnel, MicrofacetBRDF, SchlickFresnel
from tests.export.test_gltf import _albedo_on_grid, cosine_pairs_grid

mx = pytest.importorskip("MaterialX")

from brdffit.export.materialx import (OpenPBRBRDF, compensated_base,  # noqa: E402
                                      materialx_document, materialx_fidelity,
                                      openpbr_parameters, validate_document)


def _read(path):
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(path))
    return doc


def _diffuse_albedo(p, n=1 << 16):
    """Cosine-weighted mean of the exported dielectric's base term, ``π (f(base) − f(0))``,
    on a stratified grid of direction pairs (independent of the exporter's random pairs)."""
    wi, wo = cosine_pairs_grid(int(round(n ** 0.25)))

    def brdf(base):
        return OpenPBRBRDF(base, 0.0, p["specular_roughness"], specular_ior=p["specular_ior"],
                           specular_color=p["specular_color"],
                           specular_roughness_anisotropy=p["specular_roughness_anisotropy"])

    return np.pi * np.mean(brdf(p["base_color"]).eval(wi, wo) - brdf(np.zeros(3)).eval(wi, wo),
                           axis=0)


def _inputs(doc):
    (shader,) = doc.getNodes("open_pbr_surface")
    out = {}
    for i in shader.getInputs():
        out[i.getName()] = i.getNodeName() if i.getNodeName() else i.getValue()
    return shader, out


def test_target_registered_and_documents_validate(tmp_path):
    assert "materialx" in TARGETS
    models = {"metal": brdffit.synthetic("gold-ggx"), "aniso": brdffit.synthetic("aniso-ggx"),
              "plastic": brdffit.synthetic("plastic-beckmann"),
              "diel": MicrofacetBRDF(GGX(0.1), DielectricFresnel(1.7), diffuse=[0.4, 0.2, 0.1],
                                     specular=[0.9, 0.8, 0.7])}
    for key, model in models.items():
        info = export(model, "materialx", tmp_path / f"{key}.mtlx", fidelity=False)
        doc = _read(tmp_path / f"{key}.mtlx")
        ok, msg = validate_document(doc)
        assert ok, (key, msg)
        assert len(doc.getMaterialNodes()) == 1
        shader, inp = _inputs(doc)
        assert shader.getType() == "surfaceshader"
        assert inp["specular_ior"] == pytest.approx(info["parameters"]["specular_ior"], rel=1e-6)
    # the dielectric fit's index and tint come back exactly
    _, inp = _inputs(_read(tmp_path / "diel.mtlx"))
    assert inp["specular_ior"] == pytest.approx(1.7, rel=1e-6)            # (float32 in files)
    np.testing.assert_allclose(list(inp["specular_color"]), [0.9, 0.8, 0.7], rtol=1e-6)
    assert inp["base_metalness"] == 0.0
    # the base colour is ρd compensated for the specular layer's darkening: same hue, and the
    # diffuse albedo (cosine-weighted mean over direction pairs) is the fit's ρd
    base = np.array(list(inp["base_color"]))
    np.testing.assert_allclose(base / base[0], [1.0, 0.5, 0.25], rtol=1e-6)
    assert 1.05 < base[0] / 0.4 < 1.25
    p = openpbr_parameters(models["diel"])
    np.testing.assert_allclose(_diffuse_albedo(p), [0.4, 0.2, 0.1], rtol=2e-3)
    # the correlated anisotropic metal connects a rotated tangent
    _, inp = _inputs(_read(tmp_path / "aniso.mtlx"))
    assert inp["geometry_tangent"] and inp["specular_roughness_anisotropy"] > 0.5


def test_validate_can_fail():
    doc, _ = materialx_document(brdffit.synthetic("gold-ggx"))
    (shader,) = doc.getNodes("open_pbr_surface")
    shader.addInput("geometry_normal", "vector3").setNodeName("no_such_node")
    ok, msg = validate_document(doc)
    assert not ok and "no_such_node" in msg


def test_roughness_mapping_inverts_open_pbr_anisotropy():
    for ax, ay, rho in ((0.2, 0.2, 0.0), (0.3, 0.06, 0.0), (0.06, 0.3, 0.45)):
        model = MicrofacetBRDF(GGX(ax, ay, rho), SchlickFresnel(0.9))
        p = openpbr_parameters(model)
        eq = OpenPBRBRDF(p["base_color"], p["base_metalness"], p["specular_roughness"],
                         specular_roughness_anisotropy=p["specular_roughness_anisotropy"],
                         tangent_rotation=np.radians(p["tangent_rotation_deg"]))
        S = np.array([[ax * ax, rho * ax * ay], [rho * ax * ay, ay * ay]])
        lam = np.sqrt(np.linalg.eigvalsh(S))
        np.testing.assert_allclose(sorted(eq.alpha), sorted(lam), rtol=1e-9)
    # applying the tangent rotation is what makes a correlated lobe right
    model = brdffit.synthetic("aniso-ggx")
    good = materialx_fidelity(model, 8192, ("cos_rel_error",))["cos_rel_error"]
    p = openpbr_parameters(model)
    unrotated = OpenPBRBRDF(p["base_color"], 1.0, p["specular_roughness"],
                            specular_roughness_anisotropy=p["specular_roughness_anisotropy"])
    from brdffit.evaluation.metrics import brdf_metrics

    bad = brdf_metrics(model, unrotated, 8192, metrics=("cos_rel_error",))["cos_rel_error"]
    assert good < 0.2 < bad


def test_openpbr_base_is_lambert_times_view_throughput():
    """specular_color 0: only the base is left, ``base/π`` times the specular layer's
    throughput ``1 − E(θo)·comp`` (MaterialX's layer), which depends on the viewer (and
    slightly on the light, through the Fresnel in the energy compensation ``comp``)."""
    rng = np.random.default_rng(0)
    v = rng.normal(size=(2000, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    base = np.array([0.5, 0.3, 0.1])
    brdf = OpenPBRBRDF(base, 0.0, 0.5, specular_ior=1.5, specular_color=0.0)
    for wo in ([0.0, 0.0, 1.0], [0.8, 0.0, 0.6]):
        t = brdf.eval(v, np.broadcast_to(wo, v.shape)) / (base / np.pi)
        np.testing.assert_allclose(t, t[0, 0], rtol=5e-3)              # ~ same for every wi
        assert 0.8 < t[0, 0] < 1.0


@pytest.mark.parametrize("name", ['a<b>&"c\'', "\x00\x1b[2J", "", "   ", "../../etc/passwd",
                                  "\U0001F600" * 40, "1abc", "mat", "mat_openpbr"])
def test_hostile_names(tmp_path, name):
    model = MicrofacetBRDF(GGX(0.2), DielectricFresnel(1.5), diffuse=0.3, name=name)
    export(model, "materialx", tmp_path / "m.mtlx", fidelity=False)
    assert [p.name for p in tmp_path.iterdir()] == ["m.mtlx"]
    doc = _read(tmp_path / "m.mtlx")
    ok, msg = validate_document(doc)
    assert ok, msg
    names = [e.getName() for e in doc.getChildren()]
    assert len(set(names)) == len(names) and all(mx.isValidName(n) for n in names)


def test_fitted_plastic_round_trip(tmp_path):
    """ggx-diffuse on synthetic:plastic-beckmann → .mtlx: ior 1.5, base = ρd, and a bounded
    loss against the fit (Beckmann → GGX lobe and MaterialX's energy compensation)."""
    from brdffit.fit.analytic import fit_beckmann_diffuse

    fit = fit_beckmann_diffuse(brdffit.synthetic("plastic-beckmann"), moments=False)
    info = export(fit, "materialx", tmp_path / "p.mtlx")
    _, inp = _inputs(_read(tmp_path / "p.mtlx"))
    assert inp["specular_ior"] == pytest.approx(1.5, rel=1e-4)
    np.testing.assert_allclose(_diffuse_albedo(info["parameters"]), [0.45, 0.06, 0.04],
                               rtol=3e-3)
    assert 0 < info["fidelity"]["cos_rel_error"] < 0.3


def test_compensated_base_lowers_the_loss_of_a_diffuse_dielectric():
    """The base colour ρd (uncompensated) renders darker than the fit: its cosine-weighted
    error against the fit is several times the compensated one's."""
    from brdffit.evaluation.metrics import brdf_metrics

    fit = MicrofacetBRDF(GGX(0.2), DielectricFresnel(1.5), diffuse=[0.6, 0.5, 0.4])
    p = openpbr_parameters(fit)
    err = {}
    for key, base in (("compensated", p["base_color"]), ("rho_d", [0.6, 0.5, 0.4])):
        eq = OpenPBRBRDF(base, 0.0, p["specular_roughness"], specular_ior=p["specular_ior"],
                         specular_color=p["specular_color"])
        err[key] = brdf_metrics(fit, eq, 1 << 15, metrics=("cos_rel_error",))["cos_rel_error"]
    assert err["compensated"] < 0.5 * err["rho_d"], err


def test_base_is_rho_d_where_the_compensated_base_has_the_higher_error():
    """A rough lobe with a tinted conductor Fresnel (ggx-diffuse on white-fabric2): the
    dielectric index and tint that carry it make the specular layer brighter than the fit's,
    and the compensated base adds more light still; ρd is exported because its
    cosine-weighted error is lower (rendered: white-fabric2 23.6 -> 29.7 dB). The diffuse
    dielectric above keeps the compensated base."""
    from brdffit.evaluation.metrics import brdf_metrics
    from brdffit.microfacet import ConductorFresnel

    rho_d = [0.0614, 0.0542, 0.0602]
    fit = MicrofacetBRDF(GGX(0.96), ConductorFresnel([0.533, 0.489, 0.470], [0.729, 0.722, 0.776]),
                         diffuse=rho_d, specular=[0.370, 0.360, 0.371])
    p = openpbr_parameters(fit)
    assert p["base_metalness"] == 0.0
    np.testing.assert_allclose(p["base_color"], rho_d)
    err = {}
    for key, base in (("exported", p["base_color"]),
                      ("compensated", compensated_base(p, p, rho_d))):
        eq = OpenPBRBRDF(base, 0.0, p["specular_roughness"], specular_ior=p["specular_ior"],
                         specular_color=p["specular_color"])
        err[key] = brdf_metrics(fit, eq, 1 << 15, metrics=("cos_rel_error",))["cos_rel_error"]
    assert err["exported"] < 0.9 * err["compensated"], err


def test_dielectric_with_a_flat_fresnel_gets_the_balanced_index():
    """A fit whose Fresnel is almost constant and small (ks·Schlick(0.9), ks = 0.01, as
    ggx-diffuse finds on many MERL dielectrics): neither end of the F(0°)-exact family (the
    shape's high index darkens the base; max F0's low index reaches F(90°) ≈ 1), but the
    index of f = √(f_shape · f_F0), F(0°) still exact."""
    from brdffit.export.materialx import _ior_of_f0, openpbr_parameters
    from brdffit.microfacet import SchlickFresnel

    fit = MicrofacetBRDF(GGX(0.05), SchlickFresnel(0.9), diffuse=[0.3, 0.2, 0.1],
                         specular=[0.01, 0.01, 0.01])
    p = openpbr_parameters(fit)
    assert p["base_metalness"] == 0.0 and any("'balanced' mapping" in n for n in p["notes"])
    f_shape, f_f0 = 0.9, 0.009
    assert p["specular_ior"] == pytest.approx(_ior_of_f0(np.sqrt(f_shape * f_f0)), rel=1e-9)
    f = ((p["specular_ior"] - 1) / (p["specular_ior"] + 1)) ** 2
    np.testing.assert_allclose(np.array(p["specular_color"]) * f, 0.009, rtol=1e-9)  # F(0°)
    assert 0.01 < p["specular_color"][0] < 1.0                                         # F(90°)


def test_metal_like_fit_with_low_grazing_reflectance_is_a_dielectric():
    """The glTF rule: F0 0.2 but F90 0.3 keeps the diffuse term as a dielectric."""
    from brdffit.export.materialx import openpbr_parameters

    fit = MicrofacetBRDF(GGX(0.1), SchlickFresnel(2.0 / 3.0), diffuse=[0.05, 0.04, 0.03],
                         specular=[0.3, 0.3, 0.3])
    p = openpbr_parameters(fit)
    assert p["base_metalness"] == 0.0
    np.testing.assert_allclose(_diffuse_albedo(p), [0.05, 0.04, 0.03], rtol=3e-3)
    gold = openpbr_parameters(brdffit.synthetic("gold-ggx"))      # F90 = 1: still a metal
    assert gold["base_metalness"] == 1.0


def test_metal_keeps_the_fits_mean_albedo_when_its_grazing_reflectance_exceeds_one():
    """glTF's rule for OpenPBR: a rough fit with F90 ~2 and a diffuse term (ggx-diffuse on
    polyethylene) is a metal; OpenPBR's metal (energy compensation included, quadratic in the
    base colour) drops the diffuse term and stops at F90 = 1, so base_color = F0 gave too much
    light here (the compensation of a rough lobe); the exported base_color has the fit's
    cosine-weighted mean albedo (rendered: polyethylene 16.2 -> 27.6 dB)."""
    f0, ks = np.array([0.5, 0.445, 0.375]), np.array([2.14, 1.96, 1.93])
    fit = MicrofacetBRDF(GGX(0.79), SchlickFresnel(f0 / ks), diffuse=[0.031, 0.07, 0.098],
                         specular=ks)
    p = openpbr_parameters(fit)
    assert p["base_metalness"] == 1.0

    def openpbr(base):
        return OpenPBRBRDF(base, 1.0, p["specular_roughness"],
                           specular_weight=p["specular_weight"])

    target = _albedo_on_grid(fit)
    np.testing.assert_allclose(_albedo_on_grid(openpbr(p["base_color"])), target, rtol=1e-2)
    as_f0 = _albedo_on_grid(openpbr(np.clip(f0 / p["specular_weight"], 0, 1)))
    assert np.all(np.abs(as_f0 / target - 1) > 0.05)          # what base_color = F0 gave


def test_coated_fit_with_a_flat_base_fresnel_keeps_its_high_index():
    """A base lobe whose Fresnel is flat (F0 = F90: the coat took the rise) maps to a high
    specular_ior; under the coat the index to write is higher still, and it must be reached
    (a clipped index darkens the base far less than its compensated colour assumes)."""
    from brdffit.microfacet.coat import COAT_F0
    from brdffit.microfacet import SumBRDF

    base = MicrofacetBRDF(GGX(0.0085), SchlickFresnel(1.0), diffuse=0.0076,
                          specular=[0.0112, 0.0101, 0.0096])
    coat = MicrofacetBRDF(GGX(0.058), SchlickFresnel(np.full(3, COAT_F0)),
                          specular=np.full(3, 0.063))
    fit = SumBRDF([base, coat])
    p, alone = openpbr_parameters(fit), openpbr_parameters(base)
    assert alone["specular_ior"] > 10.0
    assert not any("not reachable" in n for n in p["notes"]), p["notes"]
    err = materialx_fidelity(fit, metrics=("cos_rel_error",))["cos_rel_error"]
    assert err < 2.0 * materialx_fidelity(base, metrics=("cos_rel_error",))["cos_rel_error"]


def test_coated_fit_writes_a_valid_coat_with_the_base_lobe_kept(tmp_path):
    """A coated ggx-diffuse fit: coat_weight = w, coat_roughness = √α_coat, index 1.5,
    darkening off; the base inputs are chosen so that OpenPBR's coat-roughened roughness and
    coat-relative index are those of the base lobe exported alone, and the coat lowers the
    loss against the fit compared with dropping it."""
    from brdffit.evaluation.metrics import brdf_metrics
    from brdffit.export.materialx import _brdf_of, _coat_relative_ior, _coat_roughened
    from tests.export.test_gltf import _coated

    fit = _coated()
    export(fit, "materialx", tmp_path / "coated.mtlx", fidelity=False)
    doc = _read(tmp_path / "coated.mtlx")
    assert validate_document(doc)[0]
    _, inp = _inputs(doc)
    assert inp["coat_weight"] == pytest.approx(0.07, rel=1e-6)
    assert inp["coat_roughness"] == pytest.approx(np.sqrt(0.03), rel=1e-6)
    assert inp["coat_ior"] == pytest.approx(1.5) and inp["coat_darkening"] == 0.0
    p, alone = openpbr_parameters(fit), openpbr_parameters(fit.components[0])
    assert _coat_roughened(p["specular_roughness"], p["coat_roughness"], 0.07) == \
        pytest.approx(alone["specular_roughness"], rel=1e-9)
    assert _coat_relative_ior(p["specular_ior"], 1.5, 0.07) == \
        pytest.approx(alone["specular_ior"], rel=1e-9)
    err = materialx_fidelity(fit, metrics=("cos_rel_error",))["cos_rel_error"]
    dropped = brdf_metrics(fit, _brdf_of(alone), 1 << 15,
                           metrics=("cos_rel_error",))["cos_rel_error"]
    assert err < dropped, (err, dropped)


def test_coated_fit_with_a_metal_like_base_is_mapped_the_closer_way():
    """A coated fit whose base lobe is metal-like but flat at grazing (F0 = F90 = 0.5: the
    coat took the rise, as on polyethylene) is mapped as a dielectric, as a metal and as one
    lobe; the closest to the fit is kept (the metal mapping beats the dielectric one here:
    OpenPBR's dielectric cannot hold a flat 0.5 reflectance)."""
    from brdffit.evaluation.metrics import brdf_metrics
    from brdffit.export.materialx import _brdf_of
    from brdffit.microfacet.coat import COAT_F0
    from brdffit.microfacet import SumBRDF

    base = MicrofacetBRDF(GGX(0.8), SchlickFresnel(1.0), diffuse=[0.015, 0.066, 0.094],
                          specular=[0.53, 0.45, 0.37])
    coat = MicrofacetBRDF(GGX(0.55), SchlickFresnel(np.full(3, COAT_F0)),
                          specular=np.full(3, 0.66))
    fit = SumBRDF([base, coat])
    def err(p):
        return brdf_metrics(fit, _brdf_of(p), 1 << 15, metrics=("cos_rel_error",))["cos_rel_error"]

    as_metal = openpbr_parameters(fit, metal=True)
    assert as_metal["base_metalness"] == 1.0 and as_metal["coat_weight"] == pytest.approx(0.66)
    as_dielectric = err(openpbr_parameters(fit, metal=False))
    assert err(as_metal) < 0.5 * as_dielectric
    chosen = openpbr_parameters(fit)             # the closest of the candidates (notes say)
    assert "coated fit exported as" in chosen["notes"][-1]
    assert err(chosen) <= err(as_metal) * 1.05
