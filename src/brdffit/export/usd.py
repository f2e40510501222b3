"""USD export (``usd-core``): a ``UsdPreviewSurface`` material with the OpenPBR MaterialX
binding, on a preview sphere.

:func:`write_usd` writes one ``.usda`` layer holding

* ``/Root/Looks/<name>``, a ``UsdShade.Material`` with two surface outputs:

  - ``outputs:surface`` (the universal render context) ← a ``UsdPreviewSurface`` shader
    (Pixar's UsdPreviewSurface specification, metallic workflow): ``diffuseColor`` = glTF's
    base colour, ``metallic``, ``roughness`` (perceptual, α = roughness²), ``ior``,
    ``clearcoat`` and ``clearcoatRoughness``, all from the glTF mapping of the fit
    (:func:`brdffit.export.gltf.gltf_parameters`: the same rules, notes and bounds, ior ≤ 3;
    a dielectric's ior holds the fit's F0, :func:`preview_surface_inputs`);
  - ``outputs:mtlx:surface`` (the ``mtlx`` render context, read by USD's MaterialX support)
    ← a shader whose ``info:id`` is ``ND_open_pbr_surface_surfaceshader`` with the inputs of
    the ``.mtlx`` export (:func:`brdffit.export.materialx.openpbr_parameters`).

* ``/Root/Sphere``, the glTF export's unit UV sphere as a ``UsdGeom.Mesh`` bound to the
  material (``mesh="none"``: the material alone).

What UsdPreviewSurface cannot hold is dropped and said in ``notes``: glTF's
``KHR_materials_specular`` (a coloured F0 and F90 below 1: UsdPreviewSurface's dielectric
reflectance is the exact Fresnel of ``ior`` reaching 1 at grazing), anisotropy, and the
OpenPBR tangent rotation (the MaterialX binding keeps the rest of the ``.mtlx`` inputs). The
layer is checked by USD's own validation framework (``UsdValidation``, every registered
validator: what ``usdchecker`` runs) before it is written; a failed check writes nothing.

Names: the material's prim name is ``Tf.MakeValidIdentifier`` of the fit's name (USD
identifiers only); the name itself is stored as the prim's display name, a string that USD
writes escaped.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Literal

import numpy as np

from .._atomic import atomic_write
from ..errors import ExportError
from ._common import check_output_path, label, shown, writing
from .gltf import gltf_parameters, uv_sphere
from .materialx import _ior_of_f0, _library, openpbr_parameters

__all__ = ["usd_layer", "write_usd", "check_usd", "PREVIEW_INPUTS", "MTLX_SHADER_ID"]

#: the OpenPBR node definition of MaterialX's standard library
MTLX_SHADER_ID = "ND_open_pbr_surface_surfaceshader"
#: UsdPreviewSurface inputs written (name, Sdf type)
PREVIEW_INPUTS = (("diffuseColor", "Color3f"), ("metallic", "Float"), ("roughness", "Float"),
                  ("ior", "Float"), ("clearcoat", "Float"), ("clearcoatRoughness", "Float"),
                  ("useSpecularWorkflow", "Int"))
_MTLX_FLOATS = ("base_weight", "base_metalness", "base_diffuse_roughness", "specular_weight",
                "specular_roughness", "specular_roughness_anisotropy", "specular_ior",
                "coat_weight", "coat_roughness", "coat_ior", "coat_darkening")
_MTLX_COLORS = ("base_color", "specular_color")
#: the largest dielectric F0 written as UsdPreviewSurface's ior (ior 3)
USD_F0_MAX = 0.25


def _pxr():
    try:
        from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdShade, UsdUtils
    except ImportError as exc:  # pragma: no cover - usd-core is a dependency
        raise ExportError(f"the USD export needs usd-core (pip install usd-core): {exc}") from None
    return Gf, Sdf, Tf, Usd, UsdGeom, UsdShade, UsdUtils


def preview_surface_inputs(p: dict) -> tuple[dict, list[str]]:
    """``(inputs, notes)``: UsdPreviewSurface inputs of the glTF parameters ``p``.

    A dielectric whose glTF material needs ``KHR_materials_specular`` (a coloured F0, or an
    F90 below 1 that the glTF index raised to keep F0) has no such input here: its ``ior``
    is the one whose Fresnel reflectance at normal incidence is the fit's mean F0 (at most
    :data:`USD_F0_MAX`, ior ≤ 3), not the glTF ``ior``, which only holds F0 together with
    the extension's factors. UsdPreviewSurface's specular workflow (``specularColor`` = F0)
    would keep the colour, but Blender's USD importer (5.0) reads ``specularColor`` as the
    Principled BSDF's specular tint, a factor on the F0 of ``ior``."""
    base = [float(x) for x in p["baseColorFactor"][:3]]
    spec = p.get("specular") or {}
    inputs = {"diffuseColor": base, "metallic": float(p["metallicFactor"]),
              "roughness": float(p["roughnessFactor"]), "ior": float(spec.get("ior", 1.5)),
              "clearcoat": 0.0, "clearcoatRoughness": 0.01, "useSpecularWorkflow": 0}
    notes = []
    coat = p.get("clearcoat")
    if coat:
        inputs["clearcoat"] = float(coat["clearcoatFactor"])
        inputs["clearcoatRoughness"] = float(coat["clearcoatRoughnessFactor"])
    if spec and (spec.get("specularFactor", 1.0) != 1.0
                 or np.any(np.asarray(spec.get("specularColorFactor", [1.0] * 3)) != 1.0)):
        f0 = float(np.clip(np.mean(p["F0"]), 0.0, USD_F0_MAX))
        inputs["ior"] = _ior_of_f0(f0)
        notes.append("UsdPreviewSurface: KHR_materials_specular dropped (specularFactor "
                     f"{float(spec.get('specularFactor', 1.0)):.4g}, specularColorFactor "
                     f"{np.round(spec.get('specularColorFactor', [1.0] * 3), 4).tolist()}): the "
                     f"dielectric reflectance is the Fresnel of ior {inputs['ior']:.4g}, the "
                     f"fit's mean F0 {f0:.4g} at normal incidence, reaching 1 at grazing")
    if p.get("anisotropy"):
        notes.append("UsdPreviewSurface: anisotropy dropped (no such input; the MaterialX "
                     "binding keeps specular_roughness_anisotropy)")
    return inputs, notes


def usd_layer(model, name: str | None = None, mesh: str = "sphere") -> tuple[str, dict]:
    """``(usda_text, summary)``: the layer of :func:`write_usd` as text."""
    if mesh not in ("sphere", "none"):
        raise ExportError(f"mesh: expected 'sphere' or 'none', found {mesh!r}")
    Gf, Sdf, Tf, Usd, UsdGeom, UsdShade, _ = _pxr()
    p = gltf_parameters(model)
    preview, notes = preview_surface_inputs(p)
    mtlx = openpbr_parameters(model)
    values = [*preview["diffuseColor"], preview["metallic"], preview["roughness"],
              preview["ior"], preview["clearcoat"], preview["clearcoatRoughness"]]
    values += [float(mtlx[k]) for k in _MTLX_FLOATS if k in mtlx]
    values += [float(v) for k in _MTLX_COLORS for v in mtlx[k]]
    if not all(np.isfinite(values)):
        raise ExportError(f"cannot export {label(model)} to USD: expected finite parameters, "
                          "found NaN or infinity")
    display = str(name or getattr(model, "name", None) or "material")
    ident = Tf.MakeValidIdentifier(display) or "material"

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/Root")
    stage.SetDefaultPrim(root.GetPrim())
    UsdGeom.Scope.Define(stage, "/Root/Looks")
    material = UsdShade.Material.Define(stage, f"/Root/Looks/{ident}")
    material.GetPrim().SetDisplayName(display)

    surface = UsdShade.Shader.Define(stage, f"/Root/Looks/{ident}/PreviewSurface")
    surface.CreateIdAttr("UsdPreviewSurface")
    for key, kind in PREVIEW_INPUTS:
        value = preview[key]
        value = Gf.Vec3f(*value) if kind == "Color3f" else value
        surface.CreateInput(key, getattr(Sdf.ValueTypeNames, kind)).Set(value)
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")

    openpbr = UsdShade.Shader.Define(stage, f"/Root/Looks/{ident}/OpenPBR")
    openpbr.CreateIdAttr(MTLX_SHADER_ID)
    for key in _MTLX_FLOATS:
        if key in mtlx:
            openpbr.CreateInput(key, Sdf.ValueTypeNames.Float).Set(float(mtlx[key]))
    for key in _MTLX_COLORS:
        openpbr.CreateInput(key, Sdf.ValueTypeNames.Color3f).Set(
            Gf.Vec3f(*[float(v) for v in mtlx[key]]))
    material.CreateSurfaceOutput("mtlx").ConnectToSource(openpbr.ConnectableAPI(), "out")
    if mtlx.get("tangent_rotation_deg", 0.0) != 0.0:
        notes.append("MaterialX binding: the tangent rotation of the .mtlx export "
                     f"({mtlx['tangent_rotation_deg']:.6g} deg) is not carried")

    if mesh == "sphere":
        _preview_sphere(stage, material)
    text = stage.GetRootLayer().ExportToString()
    summary = {"target": "usd", "material": f"/Root/Looks/{ident}",
               "preview_surface": preview,
               "openpbr": {k: mtlx[k] for k in (*_MTLX_FLOATS, *_MTLX_COLORS) if k in mtlx},
               "notes": list(p["notes"]) + notes + [f"MaterialX binding: {n}"
                                                    for n in mtlx["notes"]],
               "mesh": mesh}
    return text, summary


def _preview_sphere(stage, material) -> None:
    """``/Root/Sphere``: the glTF export's preview sphere (:func:`brdffit.export.gltf.uv_sphere`)
    as a ``UsdGeom.Mesh`` (triangles, vertex normals, ``primvars:st``, no subdivision), bound
    to ``material``. A mesh, not a ``UsdGeom.Sphere``: Blender's USD importer (5.0) makes a
    coarse mesh of a sphere shape and does not bind its material."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade, Vt

    s = uv_sphere()
    sphere = UsdGeom.Mesh.Define(stage, "/Root/Sphere")
    sphere.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(s["positions"]))
    sphere.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(s["normals"]))
    sphere.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    indices = s["indices"].astype(np.int32)
    sphere.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(indices) // 3, 3,
                                                                    np.int32)))
    sphere.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(indices))
    sphere.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    sphere.CreateExtentAttr([Gf.Vec3f(-1.0, -1.0, -1.0), Gf.Vec3f(1.0, 1.0, 1.0)])
    st = UsdGeom.PrimvarsAPI(sphere).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                   UsdGeom.Tokens.vertex)
    st.Set(Vt.Vec2fArray.FromNumpy(s["texcoords"]))
    UsdShade.MaterialBindingAPI.Apply(sphere.GetPrim()).Bind(material)


def _mtlx_problems(stage) -> list[str]:
    """The MaterialX shaders of ``stage`` checked against MaterialX's own standard library:
    the node definition of their ``info:id`` exists and every input is one of its inputs,
    of its type."""
    from pxr import UsdShade

    types = {"float": "float", "color3f": "color3"}
    problems = []
    for prim in stage.Traverse():
        shader = UsdShade.Shader(prim)
        if not shader or shader.GetIdAttr().Get() != MTLX_SHADER_ID:
            continue
        nodedef = _library().getNodeDef(MTLX_SHADER_ID)
        if nodedef is None:
            problems.append(f"{prim.GetPath()}: MaterialX has no node definition "
                            f"{MTLX_SHADER_ID}")
            continue
        for inp in shader.GetInputs():
            spec = nodedef.getActiveInput(inp.GetBaseName())
            kind = types.get(str(inp.GetTypeName()))
            if spec is None or spec.getType() != kind:
                problems.append(f"{prim.GetPath()}: input {inp.GetBaseName()} ({kind}) is not "
                                f"an input of {MTLX_SHADER_ID}")
    return problems


def check_usd(path) -> list[str]:
    """USD's validation framework (``UsdValidation``, the validators ``usdchecker`` runs) on
    the layer at ``path``, every registered validator: the errors and warnings it reports,
    one line each (empty when it passes).

    One deviation: ``usd-core`` (PyPI) is built without USD's MaterialX plug-in, so its shader
    registry does not know MaterialX's node ids and ``ShaderSdrCompliance`` reports
    ``MissingShaderIdInRegistry`` for the OpenPBR shader. That one report is replaced by a
    check of the shader against MaterialX's own library (:func:`_mtlx_problems`)."""
    from pxr import Usd, UsdValidation

    stage = Usd.Stage.Open(str(path))
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    found = UsdValidation.ValidationContext(validators).Validate(stage)
    serious = (UsdValidation.ValidationErrorType.Error, UsdValidation.ValidationErrorType.Warn)
    return [f"{e.GetName()}: {e.GetMessage()}" for e in found
            if e.GetType() in serious
            and not (e.GetName() == "MissingShaderIdInRegistry"
                     and f"'{MTLX_SHADER_ID}'" in e.GetMessage())] + _mtlx_problems(stage)


def write_usd(model, path, name: str | None = None, mesh: Literal["sphere", "none"] = "sphere",
              **_ignored) -> dict:
    """Write the ``.usda`` layer of ``model`` atomically, after USD's validators passed on it
    (module docstring)."""
    path = check_output_path(path)
    text, summary = usd_layer(model, name=name, mesh=mesh)
    with tempfile.TemporaryDirectory() as tmp:
        probe = Path(tmp) / "check.usda"
        probe.write_text(text, encoding="utf-8")
        problems = check_usd(probe)
    if problems:
        raise ExportError(f"cannot export to {shown(path)}: USD's validators rejected the "
                          f"layer ({' '.join(' '.join(problems).split())[:300]})")
    with writing(path), atomic_write(path, "wb") as fh:
        fh.write(text.encode("utf-8"))
    return dict(summary, files=[str(path)])
