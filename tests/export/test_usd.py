"""brdffit.export.usd: UsdPreviewSurface + the OpenPBR MaterialX binding, checked by USD's
validators; hostile names stay data; the CLI's --to usd."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pxr", reason="usd-core is not installed")

from pxr import Usd, UsdGeom, UsdShade  # noqa: E402

import brdffit  # noqa: E402
from brdffit.cli import main  # noqa: E402
from brdffit.errors import ExportError  # noqa: E402
from brdffit.export import export  # noqa: E402
from brdffit.export.gltf import gltf_parameters  # noqa: E402
from brdffit.export.materialx import openpbr_parameters  # noqa: E402
from brdffit.export.usd import MTLX_SHADER_ID, check_usd  # noqa: E402
from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel  # noqa: E402


def _material(stage):
    (prim,) = [p for p in stage.Traverse() if p.IsA(UsdShade.Material)]
    return UsdShade.Material(prim)


def _inputs(shader) -> dict:
    return {i.GetBaseName(): i.Get() for i in shader.GetInputs()}


@pytest.mark.parametrize("model", [
    MicrofacetBRDF(GGX(0.2), SchlickFresnel([0.04] * 3), diffuse=[0.5, 0.2, 0.1], name="plastic"),
    MicrofacetBRDF(GGX(0.1), SchlickFresnel([0.95, 0.7, 0.3]), name="gold")])
def test_preview_surface_and_openpbr_carry_the_export_mappings(model, tmp_path):
    path = tmp_path / "m.usda"
    info = export(model, "usd", path)
    assert check_usd(path) == []
    stage = Usd.Stage.Open(str(path))
    material = _material(stage)
    preview = material.ComputeSurfaceSource()[0]
    mtlx = material.ComputeSurfaceSource("mtlx")[0]
    assert preview.GetIdAttr().Get() == "UsdPreviewSurface"
    assert mtlx.GetIdAttr().Get() == MTLX_SHADER_ID
    p, o = gltf_parameters(model), openpbr_parameters(model)
    got = _inputs(preview)
    np.testing.assert_allclose(list(got["diffuseColor"]), p["baseColorFactor"][:3], rtol=1e-6)
    assert got["metallic"] == p["metallicFactor"] and got["useSpecularWorkflow"] == 0
    assert got["roughness"] == pytest.approx(p["roughnessFactor"], rel=1e-6)
    got = _inputs(mtlx)
    np.testing.assert_allclose(list(got["base_color"]), o["base_color"], rtol=1e-6)
    assert got["specular_roughness"] == pytest.approx(o["specular_roughness"], rel=1e-6)
    sphere = stage.GetPrimAtPath("/Root/Sphere")
    assert sphere.IsA(UsdGeom.Mesh) and len(UsdGeom.Mesh(sphere).GetPointsAttr().Get()) > 1000
    bound = UsdShade.MaterialBindingAPI(sphere).ComputeBoundMaterial()[0]
    assert bound.GetPath() == material.GetPath() and info["mesh"] == "sphere"


def test_a_hostile_name_is_stored_as_data_and_the_layer_still_validates(tmp_path):
    name = 'evil"\n) def Sphere "x" { } #\x1b[31m'
    model = MicrofacetBRDF(GGX(0.3), SchlickFresnel([0.5] * 3), name=name)
    path = tmp_path / "h.usda"
    export(model, "usd", path, mesh="none")
    assert check_usd(path) == []
    stage = Usd.Stage.Open(str(path))
    material = _material(stage)
    assert material.GetPrim().GetDisplayName() == name
    assert [p.GetName() for p in stage.Traverse() if p.IsA(UsdGeom.Gprim)] == []


def test_the_check_rejects_a_shader_input_openpbr_does_not_have(tmp_path):
    path = tmp_path / "m.usda"
    export(MicrofacetBRDF(GGX(0.3), SchlickFresnel([0.5] * 3)), "usd", path)
    stage = Usd.Stage.Open(str(path))
    mtlx = _material(stage).ComputeSurfaceSource("mtlx")[0]
    from pxr import Sdf

    mtlx.CreateInput("specular_shininess", Sdf.ValueTypeNames.Float).Set(1.0)
    bad = tmp_path / "bad.usda"
    stage.GetRootLayer().Export(str(bad))
    assert any("specular_shininess" in p for p in check_usd(bad))


def test_cli_exports_usd_and_refuses_an_unknown_mesh_before_any_work(tmp_path, capsys):
    fit = tmp_path / "g.npz"
    brdffit.save_fit(MicrofacetBRDF(GGX(0.2), SchlickFresnel([0.9, 0.6, 0.3])), fit)
    out = tmp_path / "g.usda"
    assert main(["export", str(fit), "--to", "usd", "-o", str(out)]) == 0
    assert out.is_file() and check_usd(out) == []
    assert main(["export", str(fit), "--to", "usd", "-o", str(tmp_path / "x.usda"),
                 "--option", "mesh=cube"]) == 2
    assert not (tmp_path / "x.usda").exists()
    assert "expected mesh to be one of 'sphere', 'none', found 'cube'" in capsys.readouterr().err
    with pytest.raises(ExportError):
        export(MicrofacetBRDF(GGX(0.2)), "usd", tmp_path / "y.usda", mesh="cube")


def test_a_dielectric_with_a_low_flat_fresnel_keeps_its_f0_in_the_ior(tmp_path):
    """glTF holds F0 0.05 with F90 0.06 as ior 3 + specularFactor; UsdPreviewSurface has no
    such factor, so its ior is the one of F0 0.05 (≈ 1.58), not 3 (F0 0.25, five times too
    bright at normal incidence)."""
    model = MicrofacetBRDF(GGX(0.1), SchlickFresnel([0.05 / 0.06] * 3), specular=[0.06] * 3,
                           diffuse=[0.01] * 3, name="steel-like")
    path = tmp_path / "s.usda"
    info = export(model, "usd", path)
    stage = Usd.Stage.Open(str(path))
    got = _inputs(_material(stage).ComputeSurfaceSource()[0])
    assert gltf_parameters(model)["specular"]["ior"] == pytest.approx(3.0)
    f0 = ((got["ior"] - 1) / (got["ior"] + 1)) ** 2
    assert f0 == pytest.approx(0.05, rel=1e-3), got["ior"]
    assert any("KHR_materials_specular dropped" in n for n in info["notes"])
