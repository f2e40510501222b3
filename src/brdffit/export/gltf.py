"""glTF 2.0 metallic-roughness materials of microfacet fits, and the glTF BRDF as a library BRDF.

:class:`GLTFBRDF` is the BRDF of the glTF 2.0 specification, **Appendix B** ("BRDF
Implementation"), with the ``KHR_materials_specular``, ``KHR_materials_ior``,
``KHR_materials_anisotropy`` and ``KHR_materials_clearcoat`` extensions:

* ``α = roughness²`` — glTF's ``roughnessFactor`` is the *perceptual* roughness ``r``; our
  (and Mitsuba's) α is the GGX slope scale, so **glTF roughness = √α**;
* ``D = α² χ⁺(N·H) / (π ((N·H)² (α² − 1) + 1)²)`` (isotropic GGX / Trowbridge-Reitz);
* ``V = χ⁺(H·L) χ⁺(H·V) / ((|N·L| + √(α² + (1 − α²)(N·L)²)) (|N·V| + √(α² + (1 − α²)(N·V)²)))``
  (separable Smith, ``V = G / (4 |N·L| |N·V|)``);
* Fresnel (Schlick) of the dielectric part, with the extensions' implementation formulas
  (``KHR_materials_ior``, ``KHR_materials_specular`` "Implementation"):
  ``f0_d = min(((ior − 1)/(ior + 1))² · specularColorFactor, 1) · specularFactor``,
  ``f90_d = specularFactor``, ``F_d = f0_d + (f90_d − f0_d)(1 − |V·H|)⁵`` (the core spec:
  ior 1.5, both factors 1, i.e. ``f0 = 0.04``, ``f90 = 1``); of the metal:
  ``F_m = baseColor + (1 − baseColor)(1 − |V·H|)⁵``;
* ``f = (1 − metallic) ((1 − F_d) baseColor/π + F_d D V) + metallic F_m D V``;
* clear coat (``KHR_materials_clearcoat``, "Implementation"): ``f (1 − c Fc) + c Fc D_c V_c``
  with ``c = clearcoatFactor``, ``Fc = 0.04 + 0.96 (1 − |N·V|)⁵`` and the core's GGX ``D V``
  of ``α_c = clearcoatRoughnessFactor²``.

Mapping of a fit (:func:`gltf_material`) — one specular lobe (``MicrofacetBRDF``) with a
GGX or Beckmann distribution (``fit_ggx``, ``fit_ggx_diffuse``, ``fit_beckmann_diffuse``...;
tabulated fits are first converted with :func:`brdffit.microfacet.conversions.to_ggx`,
Dupuy 2015 App. C; a Beckmann α becomes the GGX α of the same value — same
D(0) = 1/(πα²), heavier GGX tails; the loss is measured):

* roughness: ``roughnessFactor = √α``. Anisotropic / correlated: with the
  ``KHR_materials_anisotropy`` extension (default) the slope matrix is diagonalised, the
  smoother principal α is the material's, the rougher one ``αt = mix(α, 1, s²)`` gives the
  strength s and its axis the rotation (exact D, correlation included; needs αt ≤ 1);
  without it ``α = √(αx αy)`` (geometric mean, anisotropy dropped and reported);
* reflectances of the fit: ``F0 = ks · F(θd = 0)`` and ``F90 = ks · F(θd = 90°)`` (ks the
  fit's specular scale, F its Fresnel), clipped to [0, 1];
* **metallic rule**: a metal (``metallic = 1``, ``baseColorFactor = F0``, the fit's diffuse
  term dropped, F90 = 1; for a fit with a diffuse term, the base colour whose
  cosine-weighted mean albedo is the fit's, which also carries the grazing reflectance above
  1 and the dropped diffuse; docs/design/exports.md) when
  the luminance of F0 is ≥ 0.08 (``MATERIAL_METAL_F0``: common dielectrics, η ≤ 1.8, have F0
  ≤ 0.08), exceeds the luminance of the fit's ρd and — with the extensions — the luminance
  of the fit's F90 is ≥ 0.8 (``METAL_MIN_F90``; measured fits such as the ggx-diffuse ones
  of MERL's metallic paints reach only 0.1-0.5 at grazing, which glTF's metal would raise to
  1: 7.7-29 dB against the fit; as dielectrics with ``specularFactor`` = F90 they keep both
  reflectances and the diffuse term), or when the fit has no diffuse term at all (the
  paper's tabulated lobe alone, ``diffuse=False``: its Fresnel table absorbs the diffuse
  part; a dielectric would be black);
* otherwise a **dielectric Lambert + Schlick F0**: ``metallic = 0``, ``baseColorFactor =
  ρd / κ`` (clipped to [0, 1]; κ per channel the cosine-weighted mean over direction pairs
  of the ``1 − F_d`` by which glTF weights the base, so the diffuse albedo is the fit's on
  average: :func:`brdffit.export._common.diffuse_kept_fraction`), and with
  ``specular=True`` (default) the extensions carry F0 and F90:
  ``specularFactor = min(1, max(max F90, max F0))`` (f90 of the dielectric: exact when the
  fit's F90 is grey), ``r = F0 / specularFactor``, ``ior = (1 + √max r)/(1 − √max r)``
  (``KHR_materials_ior``; F0 of the ior = the largest channel of r) and
  ``specularColorFactor = r / max r`` ≤ 1, so ``f0_d = F0`` exactly. The index stays
  within [1, ``IOR_MAX`` = 3] (F0 ≤ 0.25): a flatter Fresnel curve (F0 close to F90, as
  ggx-diffuse fits of metallic paints find) would need ior 10-40 or more, which only the
  specification's f90 = specularFactor turns into a flat curve (Blender keeps f90 = 1, see
  :mod:`brdffit.evaluation.engines.blender`); there ``ior = 3`` and ``specularFactor`` is
  raised to ``max F0 / 0.25``, F0 kept and f90 raised (noted); a fit with F0 > 0.25 and
  F90 < 0.8 (measured conductors fitted with a low F90, e.g. metallic paints) keeps the
  index it needs, noted: as glTF's metal it renders worse (measured). A dielectric fit of index η ≤ 3 and grey ks gives back
  ``ior = η`` and ``specularFactor = ks``. The extensions are
  written only when they differ from the defaults (ior 1.5, factors 1). With
  ``specular=False`` the core's fixed f0 = 0.04, f90 = 1 are used (lossy, reported);
* what stays lossy (measured): glTF weights the diffuse term by ``(1 − F_d)`` (the fit adds
  ρd/π unweighted: κ restores the mean, not the dependence on the directions), its Fresnel
  curve is Schlick's (a dielectric fit's exact curve is replaced), and its Smith V is
  separable (core) or the extension's height-correlated form;
* a **coated** diffuse fit (base lobe + white coat lobe of index 1.5,
  :func:`brdffit.microfacet.coat.coat_parts`): the base lobe by the rules above, the coat as
  ``KHR_materials_clearcoat`` (``clearcoatFactor`` = w, ``clearcoatRoughnessFactor`` =
  √α_coat); glTF layers it — ``f_base (1 − w Fc) + w Fc D V`` with the coat's Fresnel ``Fc``
  of N·V (:class:`GLTFBRDF`) — where the fit adds ``w S_c Schlick(0.04; V·H)``, which departs
  on rough, heavy coats; so one lobe fitted to the coated fit
  (:func:`~brdffit.export._common.single_lobe_of`) is mapped too, and whichever is closer to
  the fit (cosine-weighted relative error) is written, the choice in the notes;
* by default (``optimize="engines"``) base colour, ``specularFactor`` and roughness are then
  fitted to what three renderers draw from the file: the specification's BRDF, Blender's
  Cycles and three.js (their models, in ``sphere-distant``: :func:`optimize_for_engines`,
  :data:`ENGINE_TARGETS`); over 15 materials that choice is at least as close to the fit as
  the rules alone in every one of the three, on the mean and on the lowest PSNR
  (``bench/studies/engines_default.py``). ``"blender"`` / ``"threejs"`` fit one engine;
  ``optimize=True`` or ``"brdf"`` refines baseColor, metallic and roughness by least squares
  in BRDF space (:func:`optimize_parameters`); ``optimize=False`` (CLI ``--option
  optimize=false``) keeps the rules alone;
* what Blender's importer and Cycles make of the file (f90 = 1, multiscatter GGX, the
  diffuse dimmed by one scalar) is modelled by
  :class:`brdffit.export.gltf_cycles.CyclesPrincipledBRDF`
  (``gltf_equivalent(..., engine="blender")``), checked against Blender's renders
  (:mod:`brdffit.evaluation.engines.blender`, ``bench/bench_engines.py``);
* the loss of fidelity is measured by :func:`gltf_fidelity` (BRDF-space metrics of
  :class:`GLTFBRDF` vs the fit; rendered PSNR in ``bench/bench_export.py``); the exported
  file passes the Khronos glTF-Validator (``tests/export/test_gltf.py``).

Colours are the fit's linear RGB, written unchanged (glTF factors are linear).
"""

from __future__ import annotations

import copy
import hashlib
import json
from collections import OrderedDict
from functools import lru_cache
from typing import Literal

import numpy as np

from .._atomic import atomic_write
from ..errors import ExportError
from ..evaluation.engines.threejs_brdf import SphereSamples, from_gltf
from ..evaluation.metrics import brdf_metrics
from ..microfacet import GGX
from ..microfacet.coat import coat_alpha_weight, coat_parts
from ..microfacet.conversions import to_ggx
from ..microfacet.model import MicrofacetBRDF
from ..microfacet.tabulated import TabulatedSlopeDistribution
from ._common import (LUMA, base_for_albedo, check_output_path, closer_to,
                      cosine_weighted_albedo, diffuse_kept_fraction, fail, is_elliptical, shown,
                      single_lobe_of, tangent_axes, writing)
from .gltf_brdf import GLTFBRDF
from .gltf_cycles import CyclesPrincipledBRDF, _Lobe

__all__ = ["GLTFBRDF", "gltf_parameters", "optimize_parameters", "gltf_material",
           "gltf_equivalent", "gltf_fidelity", "write_gltf", "MATERIAL_METAL_F0",
           "METAL_MIN_F90", "IOR_MAX", "MESHES", "ENGINES", "ENGINE_TARGETS", "OPTIMIZE",
           "DEFAULT_OPTIMIZE", "engine_brdf", "optimize_for_engines", "threejs_dfg_table",
           "uv_sphere"]

MATERIAL_METAL_F0 = 0.08
#: the largest glTF ``ior`` exported (F0 = 0.25): common dielectrics lie in 1.3-2.5; a
#: larger index only imitates a flat Fresnel curve, which engines do not all render (Blender
#: keeps f90 = 1) and artists do not expect
IOR_MAX = 3.0
#: with the KHR extensions (``specular=True``), a fit is exported as a metal only when the
#: luminance of its F90 is at least this (glTF's metal reaches 1 at grazing)
METAL_MIN_F90 = 0.8


def _ggx_model(model, target: str = "glTF 2.0"):
    """``(model as single GGX lobe, notes)`` or ExportError (naming ``target``)."""
    notes = []
    if isinstance(model, MicrofacetBRDF) and isinstance(model.distribution,
                                                       TabulatedSlopeDistribution):
        model = to_ggx(model)
        notes.append("tabulated NDF converted to GGX by Dupuy 2015 App. C (first moments)")
    if isinstance(model, MicrofacetBRDF) and is_elliptical(model.distribution, ("beckmann",)):
        d = model.distribution
        name, source = model.name, model.source
        model = MicrofacetBRDF(GGX(d.alpha_x, d.alpha_y, d.rho), model.fresnel, model.diffuse,
                               specular=model.specular, correlated=model.correlated,
                               name=name, source=source)
        notes.append("Beckmann distribution replaced by GGX of the same (alpha_x, alpha_y, rho) "
                     "(same D at the normal, heavier tails)")
    if not (isinstance(model, MicrofacetBRDF) and is_elliptical(model.distribution, ("ggx",))):
        fail(model, target, f"{target} holds a single GGX lobe (+ Lambert); expected a "
             "MicrofacetBRDF with a GGX, Beckmann or tabulated distribution, e.g. a ggx-diffuse "
             "fit (this model can go to --to mitsuba-xml, mitsuba, glsl or json)")
    return model, notes


def _anisotropy(d):
    """``(αb, strength, rotation)`` of KHR_materials_anisotropy for GGX(αx, αy, ρ): principal
    axes (Dupuy 2015 App. C), the rougher one is the extension's direction t with
    ``αt = mix(αb, 1, s²)``; ``None`` when αt > 1 (not representable)."""
    at, ab, rot = tangent_axes(d)
    if at > 1.0 or ab >= 1.0:
        return None
    return ab, float(np.sqrt((at - ab) / (1.0 - ab))), rot


def _specular_extension(F0, F90, max_ior: float = IOR_MAX) -> dict:
    """KHR_materials_specular / KHR_materials_ior parameters whose dielectric ``f0_d`` is
    ``F0`` and ``f90_d`` the largest channel of F90, within what engines and artists expect
    (see the module docstring): ``ior`` in [1, ``max_ior``], factors in [0, 1].

    ``specularFactor`` s = min(1, max(max F90, max F0)) and ``r = F0 / s``; when max r ≤
    F0(IOR_MAX) = ((IOR_MAX − 1)/(IOR_MAX + 1))², ``ior`` is the index of F0 = max r and
    ``specularColorFactor = r / max r``: F0 and F90 exact. A flatter Fresnel (max r above
    F0(max_ior)) would need a larger index; then ``ior = max_ior`` and s is raised to
    ``max F0 / F0(max_ior)`` (≤ 1), which keeps F0 exactly and raises f90 to s; when even
    s = 1 is not enough (max F0 > F0(max_ior)), the index the flat curve needs is kept: F0
    and F90 exact, ior above the bound (as a metal, f90 = 1, it renders further from such
    fits: gold-metallic-paint 47.7 → 40.3 dB in Blender, 73.5 → 38.4 dB in our glTF
    equivalent, ``bench/results/engines_blender.json``). The entry ``"note"`` says which."""
    F0 = np.clip(np.asarray(F0, float), 0.0, 1.0)
    F90 = np.clip(np.asarray(F90, float), 0.0, 1.0)
    sf = float(min(1.0, max(float(F90.max()), float(F0.max()))))
    if sf <= 0.0:
        return {"specularFactor": 0.0, "specularColorFactor": [1.0, 1.0, 1.0], "ior": 1.5}
    r = F0 / sf
    rmax = float(r.max())
    if rmax <= 0.0:
        return {"specularFactor": sf, "specularColorFactor": [0.0, 0.0, 0.0], "ior": 1.5}
    max_ior = float(max_ior)
    if not (np.isfinite(max_ior) and max_ior > 1.0):
        raise ValueError(f"max_ior: expected a finite index > 1, got {max_ior}")
    f0_max = ((max_ior - 1.0) / (max_ior + 1.0)) ** 2
    note = None
    if rmax > f0_max:
        wanted = (1.0 + np.sqrt(min(rmax, 1.0 - 1e-9))) / (1.0 - np.sqrt(min(rmax, 1.0 - 1e-9)))
        if F0.max() <= f0_max:
            raised = float(F0.max() / f0_max)
            note = (f"ior {max_ior:g} (the largest exported, max_ior) instead of {wanted:.4g}: "
                    f"specularFactor (glTF's f90) raised from {sf:.4g} to {raised:.4g}")
            sf = raised
            r = F0 / sf
            rmax = float(r.max())
        else:
            max_ior = np.inf
            note = (f"ior {wanted:.4g} above max_ior: F0 {np.round(F0, 4).tolist()} exceeds the "
                    f"F0 {f0_max:.4g} of any lower index, and glTF's metal (f90 = 1) is further "
                    "from this fit (bench/bench_engines.py)")
    q = float(np.sqrt(min(rmax, 1.0 - 1e-9)))
    ior = min((1.0 + q) / (1.0 - q), max_ior)
    f0_ior = ((ior - 1.0) / (ior + 1.0)) ** 2
    color = np.clip(r / f0_ior, 0.0, 1.0)
    out = {"specularFactor": sf, "specularColorFactor": [float(c) for c in color],
           "ior": float(ior)}
    if note:
        out["note"] = note
    return out


def _is_default_specular(ext) -> bool:
    return (abs(ext["specularFactor"] - 1.0) < 1e-12 and abs(ext["ior"] - 1.5) < 1e-9
            and all(abs(c - 1.0) < 1e-12 for c in ext["specularColorFactor"]))


def is_metal(m, F0c, rd, F90=None) -> bool:
    """The metallic rule (module docstring) shared by glTF and MaterialX: no diffuse term,
    or F0's luminance ≥ ``MATERIAL_METAL_F0`` above ρd's and — when ``F90`` is given (a
    target that can carry F90 otherwise) — F90's luminance ≥ ``METAL_MIN_F90``."""
    lum = float(LUMA @ F0c)
    if m.diffuse is None:
        return lum > 0
    grazing_ok = F90 is None or float(LUMA @ F90) >= METAL_MIN_F90
    return lum >= MATERIAL_METAL_F0 and grazing_ok and float(LUMA @ rd) < lum


def reflectances(m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(F0, F90, ρd)`` of a GGX/Beckmann model with optional ``specular`` (ks), ``fresnel``
    and ``diffuse``: ``F0 = ks·F(θd = 0)``, ``F90 = ks·F(θd = 90°)`` (unclipped)."""
    ks = np.ones(3) if m.specular is None else np.asarray(m.specular, float)
    F0 = ks * (np.ones(3) if m.fresnel is None else np.asarray(m.fresnel.eval(1.0), float))
    F90 = ks * (np.ones(3) if m.fresnel is None else np.asarray(m.fresnel.eval(0.0), float))
    rd = np.zeros(3) if m.diffuse is None else np.asarray(m.diffuse, float)
    return F0, F90, rd


def gltf_parameters(model, anisotropy: bool = True, specular: bool = True,
                    max_ior: float = IOR_MAX) -> dict:
    """``{"baseColorFactor", "metallicFactor", "roughnessFactor", "alpha", "notes",
    "anisotropy", "specular", ...}`` of a fit by the rules of the module docstring; with
    ``anisotropy`` an anisotropic or correlated GGX uses ``KHR_materials_anisotropy``
    (``"anisotropy"`` entry: strength and rotation; exact D, rotation included), else
    α = √(αx αy); with ``specular`` a dielectric carries its F0/F90 in
    ``KHR_materials_specular`` + ``KHR_materials_ior`` (``"specular"`` entry, ``None`` when
    the core's defaults are exact or for a metal). A coated diffuse fit
    (:func:`brdffit.microfacet.coat.coat_parts`) maps its base lobe by these rules and its coat
    to ``KHR_materials_clearcoat`` (``"clearcoat"`` entry)."""
    parts = coat_parts(model)
    if parts is not None:
        return _coated_parameters(model, parts, anisotropy, specular, max_ior)
    m, notes = _ggx_model(model)
    alpha, aniso = _roughness(m.distribution, anisotropy, notes)
    F0, F90, rd = reflectances(m)
    F0c = np.clip(F0, 0.0, 1.0)
    # a metal's F90 is 1 in glTF: with the extensions, a fit whose grazing reflectance is far
    # below 1 keeps it (and its diffuse term) as a dielectric with specularFactor = F90
    metal = is_metal(m, F0c, rd, np.clip(F90, 0.0, None) if specular else None)
    base, spec = _base_and_specular(m, metal, (F0, F90, rd), specular, max_ior, notes)
    if m.correlated and aniso is None:
        notes.append("height-correlated Smith G of the fit replaced by glTF's separable Smith")
    if not m.correlated and aniso is not None:
        notes.append("uncorrelated Smith G of the fit replaced by the extension's "
                     "height-correlated V")
    notes.append("Fresnel curve replaced by Schlick's with the F0/F90 above")
    out = {"baseColorFactor": [float(x) for x in base] + [1.0],
           "metallicFactor": 1.0 if metal else 0.0,
           "roughnessFactor": float(np.sqrt(min(alpha, 1.0))), "alpha": alpha,
           "anisotropy": None if aniso is None else {"anisotropyStrength": aniso[1],
                                                     "anisotropyRotation": aniso[2]},
           "specular": spec, "F0": F0.tolist(), "F90": F90.tolist(), "rho_d": rd.tolist(),
           "notes": notes}
    _match_base(out, m, metal, base, F0c)
    return out


def _coated_parameters(model, parts, anisotropy: bool, specular: bool, max_ior: float) -> dict:
    """:func:`gltf_parameters` of a coated fit (``parts`` = its base and coat lobes):
    glTF's clearcoat (Fresnel of N·V, layered) departs from the fit's added coat on rough,
    heavy coats, so whichever is closer to the fit is exported, the coat or one lobe."""
    cands = {"clearcoat": _with_clearcoat(gltf_parameters(parts[0], anisotropy, specular,
                                                          max_ior),
                                          parts[1]),
             "one lobe": gltf_parameters(single_lobe_of(model), anisotropy, specular,
                                         max_ior)}
    label, p, err = closer_to(model, cands, _brdf_of)
    other = next(k for k in err if k != label)
    return dict(p, notes=p["notes"] + [f"coated fit exported as {label} (cos_rel_error vs the "
                                        f"fit {err[label]:.4g}; as {other}: {err[other]:.4g})"])


def _roughness(d, anisotropy: bool, notes: list) -> tuple[float, tuple | None]:
    """``(α, anisotropy)`` of GGX ``d``: α = √(αx αy), or αb with ``anisotropy`` =
    :func:`_anisotropy` ``(αb, strength, rotation)`` when the distribution is anisotropic
    or correlated, ``anisotropy`` is on and the extension can hold it (``None`` otherwise);
    what is lost is appended to ``notes``."""
    alpha = float(np.sqrt(d.alpha_x * d.alpha_y))
    aniso = None
    if d.alpha_x != d.alpha_y or d.rho != 0:
        aniso = _anisotropy(d) if anisotropy else None
        if aniso is None:
            notes.append(f"anisotropy dropped: alpha_x={d.alpha_x:.4g}, alpha_y={d.alpha_y:.4g}, "
                         f"rho={d.rho:.4g} -> isotropic alpha={alpha:.4g} (geometric mean)")
        else:
            alpha = aniso[0]
            notes.append(f"anisotropy via KHR_materials_anisotropy: strength={aniso[1]:.4g}, "
                         f"rotation={aniso[2]:.4g} rad (principal axes of the slope matrix)")
    if alpha > 1.0:
        notes.append(f"alpha={alpha:.4g} > 1 clipped to glTF's largest roughness 1")
    return alpha, aniso


def _base_and_specular(m, metal: bool, reflect, specular: bool, max_ior: float, notes: list):
    """``(base colour, specular extension or None)`` before the albedo matching of
    :func:`_match_base`: a metal's base is its F0 (diffuse term dropped, F90 = 1); a
    dielectric's is ρd, with its F0/F90 in :func:`_specular_extension` when ``specular``
    (``None`` when that is glTF's default), else glTF's fixed F0 = 0.04. ``reflect`` is
    ``(F0, F90, ρd)`` of :func:`reflectances`; the notes go to ``notes``."""
    F0, F90, rd = reflect
    F0c = np.clip(F0, 0.0, 1.0)
    if metal:
        if m.diffuse is not None:
            notes.append("metal: the fit's diffuse term is dropped")
        notes.append("metal: Schlick with F0 = baseColor and F90 = 1 (fit's F90: "
                     f"{np.round(F90, 4).tolist()})")
        return F0c, None
    base = np.clip(rd, 0.0, 1.0)
    if not specular:
        notes.append(f"dielectric: specular F0 fixed by glTF to 0.04 (fit: "
                     f"{np.round(F0, 4).tolist()}), diffuse weighted by (1 - F)")
        return base, None
    spec = _specular_extension(F0, F90, max_ior)
    if "note" in spec:
        notes.append(spec.pop("note"))
    notes.append(f"dielectric: F0 {np.round(F0c, 4).tolist()} via KHR_materials_specular"
                 f" + KHR_materials_ior (ior={spec['ior']:.4g}), F90 = specularFactor "
                 f"{spec['specularFactor']:.4g} (fit: {np.round(F90, 4).tolist()}); "
                 "diffuse weighted by (1 - F)")
    return base, None if _is_default_specular(spec) else spec


def _match_base(out: dict, m, metal: bool, base, F0c) -> None:
    """Set ``out``'s base colour (and a note) so that glTF's material keeps the fit's
    diffuse energy: a metal with a diffuse term takes the base whose cosine-weighted mean
    albedo is the fit's, a dielectric divides ρd by the fraction of the base the specular
    layer lets through."""
    notes = out["notes"]

    def with_base(b) -> GLTFBRDF:  # the material of out with base colour b (affine in b)
        return _brdf_of(dict(out, baseColorFactor=[float(x) for x in b] + [1.0]))

    if metal and m.diffuse is not None:
        # a fit that separated its diffuse term: glTF's metal is affine in its base colour
        # (Schlick F = c + (1 − c)(1 − V·H)⁵), take the c whose cosine-weighted mean albedo is
        # the fit's, which also counts what glTF cannot carry (a grazing reflectance above
        # F90 = 1, the dropped diffuse term). Fits without one (a tabulated or moment GGX fit
        # with ρd = 0) keep c = F0: their Fresnel carries all of it, and matching the albedo was not
        # better there in BRDF space (15 of 30 fits worse), with no render evidence
        target = cosine_weighted_albedo(m)
        base, wanted = base_for_albedo(with_base, target)
        out["baseColorFactor"] = [float(x) for x in base] + [1.0]
        notes.append(f"metal: baseColor {np.round(base, 4).tolist()} keeps the fit's "
                     f"cosine-weighted mean albedo {np.round(target, 4).tolist()} (F0: "
                     f"{np.round(F0c, 4).tolist()})"
                     + (": clipped" if np.any(wanted > 1) else ""))
    if not metal and np.any(base > 0):
        # glTF mixes the base with the specular layer by (1 − F(V·H)): the fit adds ρd/π
        # unattenuated, so divide by the fraction kept (cosine-weighted mean)
        kept = diffuse_kept_fraction(with_base)
        base = np.clip(base / np.maximum(kept, 1e-6), 0.0, 1.0)
        out["baseColorFactor"] = [float(x) for x in base] + [1.0]
        notes.append(f"baseColor {np.round(base, 4).tolist()} = rho_d / the fraction of the "
                     f"base the specular layer lets through ({np.round(kept, 4).tolist()}, "
                     "cosine-weighted mean)" + (": clipped to 1" if np.any(base >= 1) else ""))


def _with_clearcoat(p: dict, coat) -> dict:
    """``p`` (the base lobe's parameters) with the coat lobe as ``KHR_materials_clearcoat``:
    ``clearcoatFactor`` = the coat's weight w, ``clearcoatRoughnessFactor`` = √α_coat."""
    alpha, w = coat_alpha_weight(coat)
    notes = list(p["notes"])
    if not is_elliptical(coat.distribution, ("ggx",)):
        notes.append("coat: Beckmann distribution replaced by GGX of the same alpha")
    if alpha > 1.0:
        notes.append(f"coat: alpha={alpha:.4g} > 1 clipped to glTF's largest roughness 1")
    notes.append(f"coat (white, F0 0.04, weight {w:.4g}, alpha {alpha:.4g}) via "
                 "KHR_materials_clearcoat: glTF layers it, the base weighted by 1 - w F(N.V), "
                 "where the fit adds it; its Fresnel is of N.V, the fit's of V.H")
    return dict(p, notes=notes, clearcoat={"clearcoatFactor": w,
                                           "clearcoatRoughnessFactor": float(np.sqrt(min(alpha,
                                                                                          1.0)))})


def _extensions(p: dict) -> dict:
    """The ``KHR_materials_*`` extensions of the material of parameters ``p``."""
    ext = {}
    if p["anisotropy"]:
        ext["KHR_materials_anisotropy"] = p["anisotropy"]
    sp = p.get("specular")
    if sp:
        ext["KHR_materials_specular"] = {"specularFactor": sp["specularFactor"],
                                         "specularColorFactor": sp["specularColorFactor"]}
        if abs(sp["ior"] - 1.5) > 1e-9:
            ext["KHR_materials_ior"] = {"ior": sp["ior"]}
    if p.get("clearcoat"):
        ext["KHR_materials_clearcoat"] = p["clearcoat"]
    return ext


def _brdf_of(p: dict, name: str = "gltf") -> "GLTFBRDF":
    a = p.get("anisotropy") or {"anisotropyStrength": 0.0, "anisotropyRotation": 0.0}
    sp = p.get("specular") or {"specularFactor": 1.0, "specularColorFactor": [1.0] * 3,
                               "ior": 1.5}
    cc = p.get("clearcoat") or {"clearcoatFactor": 0.0, "clearcoatRoughnessFactor": 0.0}
    return GLTFBRDF(p["baseColorFactor"][:3], p["metallicFactor"], p["roughnessFactor"],
                    name=name, anisotropy_strength=a["anisotropyStrength"],
                    anisotropy_rotation=a["anisotropyRotation"],
                    specular_factor=sp["specularFactor"],
                    specular_color=sp["specularColorFactor"], ior=sp["ior"],
                    clearcoat=cc["clearcoatFactor"],
                    clearcoat_roughness=cc["clearcoatRoughnessFactor"])


def optimize_parameters(model, p: dict, n: int = 8192, seed: int = 0) -> dict:
    """Refine the rule-based parameters ``p`` (baseColor, metallic, roughness; anisotropy
    kept) by least squares (three starts: the rule, a metal with F0, a dielectric with ρd;
    the best of starts and results by the cosine-weighted relative error is kept) on the
    cosine-weighted BRDF difference to ``model`` at ``n`` random direction pairs (residual ``(f_glTF − f) cos θo / (f cos θo + mean)``, a relative
    error that does not let the peak dominate). The result replaces ``p`` only when it lowers
    the cosine-weighted relative error of :func:`brdffit.evaluation.metrics.brdf_metrics`."""
    from scipy import optimize

    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2 * n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    wi, wo = v[:n], v[n:]
    ref = np.asarray(model.eval(wi, wo), float) * wo[:, 2:3]
    scale = np.abs(ref) + np.mean(np.abs(ref))

    def make(q):
        return _brdf_of(dict(p, baseColorFactor=list(np.clip(q[:3], 0, 1)),
                             metallicFactor=float(np.clip(q[3], 0, 1)),
                             roughnessFactor=float(np.clip(q[4], 0.01, 1))))

    def resid(q):
        return ((make(q).eval(wi, wo) * wo[:, 2:3] - ref) / scale).ravel()

    q0 = np.array(p["baseColorFactor"][:3] + [p["metallicFactor"], p["roughnessFactor"]])
    lo, hi = [0, 0, 0, 0, 0.01], [1, 1, 1, 1, 1]
    f0 = np.clip(p["F0"], 0, 1).tolist()
    rd = np.clip(p["rho_d"], 0, 1).tolist()
    starts = [q0, np.array(f0 + [1.0, q0[4]]), np.array(rd + [0.0, q0[4]])]
    metric = ("cos_rel_error",)
    cands = [np.clip(q, lo, hi) for q in starts]
    cands += [optimize.least_squares(resid, q, bounds=(lo, hi), max_nfev=100).x for q in cands]
    errs = [brdf_metrics(model, make(q), 1 << 14, metrics=metric)["cos_rel_error"] for q in cands]
    best = cands[int(np.argmin(errs))]              # best candidate by the reported metric
    before = errs[0]
    after = float(np.min(errs))
    if not after < before:
        return dict(p, notes=p["notes"] + ["optimisation did not lower the error: rule kept"])
    out = dict(p)
    out["baseColorFactor"] = [float(x) for x in np.clip(best[:3], 0, 1)] + [1.0]
    out["metallicFactor"] = float(np.clip(best[3], 0, 1))
    out["roughnessFactor"] = float(np.clip(best[4], 0.01, 1))
    out["alpha"] = out["roughnessFactor"] ** 2
    out["notes"] = p["notes"] + [f"baseColor/metallic/roughness optimised in BRDF space "
                                 f"(cos_rel_error {before:.4g} -> {after:.4g})"]
    return out


#: the engines :func:`gltf_equivalent` models: the specification's BRDF (Appendix B and the
#: extensions), Blender's Cycles with the importer's multiscatter GGX or with GGX, and
#: three.js r187 (``MeshPhysicalMaterial`` under direct light)
ENGINES = ("specification", "blender", "blender-ggx", "threejs")
#: the renderers :func:`optimize_for_engines` fits the parameters to by default: the
#: specification's BRDF (engines that follow it, e.g. the Khronos sample viewer) and the two
#: measured engines
ENGINE_TARGETS = ("specification", "blender", "threejs")
#: the refinements of the rule-based parameters (``optimize`` of :func:`write_gltf`):
#: ``"brdf"`` (= ``True``, :func:`optimize_parameters`), ``"engines"``
#: (:func:`optimize_for_engines` for :data:`ENGINE_TARGETS`), ``"blender"`` / ``"threejs"``
#: (the same for one engine)
OPTIMIZE = ("brdf", "engines", "blender", "threejs")
#: the refinement the glTF export applies unless told otherwise
DEFAULT_OPTIMIZE = "engines"


@lru_cache(maxsize=1)
def threejs_dfg_table() -> np.ndarray:
    """three.js r187's DFG table as :class:`~brdffit.evaluation.engines.threejs_brdf.ThreeJSBRDF`
    reads it, ``(16, 16, 2)`` (rows N·V, columns perceptual roughness, texel centres at
    ``(i + 0.5)/16``), computed here: channel 0 the directional albedo ``E_ss(r, μ)`` of the
    height-correlated GGX lobe of α = max(r, 0.045)² for F = 1 (quadrature over its visible
    normals, :class:`brdffit.export.gltf_cycles._Lobe`), channel 1 zero; three's
    multiple-scattering term reads only ``dfg.x + dfg.y`` = ``E_ss``. Deviation: three ships a
    half-float table (``DFGLUTData.js``); this one lies within 0.011 of it (0.025 in the row
    of grazing N·V, μ = 1/32), so that exports do not depend on the npm package."""
    u = (np.arange(16) + 0.5) / 16
    table = np.zeros((16, 16, 2))
    for j, r in enumerate(u):
        lobe = _Lobe(max(r, 0.045) ** 2, None, n=32)
        table[:, j, 0] = lobe.table(lobe.E, u)
    return table


def engine_brdf(p: dict, engine: str = "specification", name: str = "gltf",
                multiscatter: bool = True):
    """The BRDF ``engine`` (one of :data:`ENGINES`) renders for the material of parameters
    ``p`` (:func:`gltf_parameters`): :class:`GLTFBRDF`; Cycles' Principled BSDF as Blender's
    importer sets it up (:class:`brdffit.export.gltf_cycles.CyclesPrincipledBRDF`,
    multiscatter GGX or GGX); three.js's direct-light shading of the material as its
    ``GLTFLoader`` reads it (:func:`brdffit.evaluation.engines.threejs_brdf.from_gltf`,
    geometry roughness 0, the DFG table of :func:`threejs_dfg_table`). ``multiscatter=False``
    switches the engines' multiple-scattering energy off (Blender's GGX, three's ``M = 1``).
    The engine models raise :class:`ValueError` on ``KHR_materials_anisotropy``."""
    if engine not in ENGINES:
        raise ValueError(f"engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    q = _brdf_of(p, name=name)
    if engine == "specification":
        return q
    if engine == "threejs":
        mat = {"name": name,
               "pbrMetallicRoughness": {"baseColorFactor": list(p["baseColorFactor"]),
                                        "metallicFactor": p["metallicFactor"],
                                        "roughnessFactor": p["roughnessFactor"]},
               "extensions": _extensions(p)}
        return from_gltf({"materials": [mat]}, lut=threejs_dfg_table(),
                         multiscatter=multiscatter)
    return CyclesPrincipledBRDF(q.base_color, q.metallic, q.roughness, name=name,
                                anisotropy_strength=q.anisotropy_strength,
                                anisotropy_rotation=q.anisotropy_rotation,
                                specular_factor=q.specular_factor,
                                specular_color=q.specular_color, ior=q.ior,
                                clearcoat=q.clearcoat,
                                clearcoat_roughness=q.clearcoat_roughness,
                                multiscatter=multiscatter and engine == "blender")


#: the parameters of lobes sharper than this (glTF roughness) are left to the rule by
#: :func:`optimize_for_engines`: the engines' renders there were measured on Blender's 64 × 32
#: preview mesh, whose facets moved sharp highlights by a few % (docs/design/engines.md);
#: not yet measured with the option on the scene's sphere
ENGINE_FIT_MIN_ROUGHNESS = 0.15
#: the render :func:`optimize_for_engines` matches: ``sphere-distant``, this many pixels a side,
#: ``ENGINE_FIT_SUPERSAMPLE``² samples per pixel on both sides
ENGINE_FIT_RESOLUTION = 32
ENGINE_FIT_SUPERSAMPLE = 4
#: the PSNR above which :func:`optimize_for_engines` no longer rewards an engine (dB): its
#: objective is the mean over the engines of ``−10 log10(MSE/peak² + 10^(−cap/10))``
ENGINE_FIT_CAP_DB = 65.0
#: the step of :func:`optimize_for_engines`' forward differences, and its budget of
#: objective evaluations (each difference counted, as scipy counts them)
ENGINE_FIT_STEP = 1e-4
ENGINE_FIT_MAXFUN = 200


def _engine_fit_vector(p: dict) -> tuple[np.ndarray, bool]:
    """``(q, has_specular)``: the parameters :func:`optimize_for_engines` varies, base colour
    (3), ``specularFactor`` when the dielectric carries ``KHR_materials_specular``, roughness."""
    sp = p.get("specular")
    has_sp = bool(sp) and p["metallicFactor"] < 1.0
    q = list(p["baseColorFactor"][:3]) + ([sp["specularFactor"]] if has_sp else [])
    return np.array(q + [p["roughnessFactor"]], float), has_sp


def _with_engine_fit_vector(p: dict, q, has_sp: bool) -> dict:
    base = [float(x) for x in np.clip(q[:3], 0.0, 1.0)]
    r = float(np.clip(q[-1], 0.0, 1.0))
    out = dict(p, baseColorFactor=base + [1.0], roughnessFactor=r, alpha=r * r)
    if has_sp:
        out["specular"] = dict(p["specular"], specularFactor=float(np.clip(q[3], 0.0, 1.0)))
    return out


def optimize_for_engines(model, p: dict, engines=ENGINE_TARGETS,
                         resolution: int = ENGINE_FIT_RESOLUTION) -> dict:
    """Parameters chosen for the engines as they render: the glTF material whose renders in
    the ``engines`` (their models, :func:`engine_brdf`) are closest to the fit's render.

    The objective is the mean over the engines of the capped log error of a noise-free render
    of ``sphere-distant`` (:class:`brdffit.evaluation.engines.threejs_brdf.SphereSamples`,
    ``resolution``² pixels, :data:`ENGINE_FIT_SUPERSAMPLE`² samples each, the same for the fit):
    ``mean_e log10(MSE_e / peak² + 10^(−c/10))`` with the fit's peak and c =
    :data:`ENGINE_FIT_CAP_DB`, i.e. the engines' mean PSNR (Bagher et al. 2016 §5), each
    counted up to c. The cap keeps one engine's figure from being raised far above the goal
    at the other's expense; the log keeps the worse engine from taking all of the parameters
    (a sum of MSEs traded a good engine's 70 dB for a bad one's +1 dB). Varied, bounded to
    [0, 1]: the base colour (a channel the rule leaves at 0 stays 0), ``specularFactor`` of a
    dielectric with ``KHR_materials_specular``, the roughness (L-BFGS-B from the rule's
    values). Kept: metallic, the index and
    ``specularColorFactor`` (the ior rule of :func:`_specular_extension` holds), the coat.
    With ``"specification"`` among the engines the file stays true to its own format: a
    result that renders the specification's BRDF further from the fit than the rules do is
    not taken (an exact glTF material stays exact; the cap applies to the other engines'
    gains only).

    The engines add energy glTF's BRDF does not have (Blender's importer leaves Cycles on
    multiscatter GGX, Kulla & Conty 2017; three.js multiplies its specular by
    ``1 + f0 (1/E_ss − 1)``, Turquin 2019 Eq. 16) and Cycles dims the diffuse by one scalar
    under a specular layer whose F90 is always 1; the rules follow the specification, these
    parameters follow the engines. Unchanged (with a note): anisotropic materials (the engine
    models do not cover ``KHR_materials_anisotropy``) and lobes sharper than
    :data:`ENGINE_FIT_MIN_ROUGHNESS` (not yet measured in the engines with the option). The
    result replaces ``p`` only when it raises the objective's mean PSNR by ≥ 0.1 dB; the
    predicted PSNR per engine before and after is in the notes. Results are kept per process
    (the last 32, by the fit's render and ``p``): the same fit is optimised once."""
    engines = tuple(engines)
    for e in engines:
        if e not in ENGINES:
            raise ValueError(f"engine: expected one of {', '.join(ENGINES)}, got {e!r}")
    if p.get("anisotropy"):
        return dict(p, notes=p["notes"] + ["engine-aware optimisation skipped: "
                                           "KHR_materials_anisotropy is not modelled"])
    if p["roughnessFactor"] < ENGINE_FIT_MIN_ROUGHNESS:
        return dict(p, notes=p["notes"] + [
            f"engine-aware optimisation skipped: roughness {p['roughnessFactor']:.3g} < "
            f"{ENGINE_FIT_MIN_ROUGHNESS} (sharp highlights: the rule's parameters are kept)"])
    sphere = SphereSamples("sphere-distant", resolution, ENGINE_FIT_SUPERSAMPLE)
    ref, alpha = sphere.shade(model)
    key = _engine_fit_key(ref, alpha, p, engines, resolution)
    if key in _ENGINE_FITS:
        _ENGINE_FITS.move_to_end(key)
        return copy.deepcopy(_ENGINE_FITS[key])
    out = _fit_to_engines(p, sphere, ref, alpha, engines)
    _ENGINE_FITS[key] = copy.deepcopy(out)
    while len(_ENGINE_FITS) > _ENGINE_FITS_KEPT:
        _ENGINE_FITS.popitem(last=False)
    return out


#: results of :func:`optimize_for_engines` kept per process, by the fit's render and the
#: rules' parameters (a report writes a material's glTF file and its fidelity from the same
#: fit); the objective is deterministic, so a kept result is the one a new run would give
_ENGINE_FITS: OrderedDict = OrderedDict()
_ENGINE_FITS_KEPT = 32


def _engine_fit_key(ref, alpha, p: dict, engines: tuple, resolution: int) -> str:
    h = hashlib.sha256()
    for a in (ref, alpha):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    h.update(json.dumps([p, list(engines), resolution], sort_keys=True,
                        default=lambda o: o.tolist() if hasattr(o, "tolist") else repr(o))
             .encode())
    return h.hexdigest()


def _fit_to_engines(p: dict, sphere, ref, alpha, engines: tuple) -> dict:
    """:func:`optimize_for_engines` given the fit's render ``ref`` (and coverage ``alpha``).

    L-BFGS-B on the forward-difference gradient of step :data:`ENGINE_FIT_STEP`
    (:func:`_forward_steps`, as scipy takes it); a pixel's channel depends on the base colour's
    same channel only in every engine model, so one render with all three channels stepped
    gives their three differences (:func:`_engine_fit_gradient`). As scipy does with its own
    differences, the parameters fixed by their bounds are left out of the problem, and each
    difference counts as an evaluation: ``maxfun`` is :data:`ENGINE_FIT_MAXFUN` of those."""
    from scipy import optimize

    mask = alpha >= 0.999
    ref_px = ref[mask]
    peak2 = float(np.max(ref_px)) ** 2
    q0, has_sp = _engine_fit_vector(p)

    def mse_channels(q) -> np.ndarray:      # (engine, channel), relative to the fit's peak²
        pp = _with_engine_fit_vector(p, q, has_sp)
        return np.array([np.mean((sphere.pixel_means(engine_brdf(pp, e), mask) - ref_px) ** 2,
                                 axis=0) for e in engines]) / (3.0 * peak2)

    # a base channel the rule leaves black stays black (the fit has no diffuse there)
    bounds = np.array([(0.0, 0.0) if i < 3 and q0[i] <= 0.0 else (0.0, 1.0)
                       for i in range(len(q0))])
    free = bounds[:, 0] < bounds[:, 1]
    full = _engine_fit_gradient(mse_channels, bounds)

    def loss_and_gradient(x):               # of the free parameters (scipy drops the fixed)
        q = q0.copy()
        q[free] = x
        f, g = full(q)
        return f, g[free]

    res = optimize.minimize(loss_and_gradient, q0[free], jac=True, method="L-BFGS-B",
                            bounds=bounds[free],
                            options={"maxfun": ENGINE_FIT_MAXFUN // (1 + int(free.sum())),
                                     "maxiter": 40, "ftol": 1e-4})
    q1 = q0.copy()
    q1[free] = res.x
    mse0, mse1 = mse_channels(q0).sum(1), mse_channels(q1).sum(1)
    return _engine_fit_result(p, engines, q1, has_sp, mse0, mse1,
                              _engine_fit_loss(mse0) - _engine_fit_loss(mse1))


def _engine_fit_loss(mse) -> float:
    """The objective of :func:`optimize_for_engines`: −(mean capped PSNR)/10 of the
    engines' relative MSEs."""
    return float(np.mean(np.log10(mse + 10.0 ** (-ENGINE_FIT_CAP_DB / 10.0))))


def _forward_steps(q, bounds) -> np.ndarray:
    """scipy's 2-point steps at ``q`` within ``bounds`` (n, 2) (``approx_derivative`` with
    ``abs_step``): ``+h``; ``−h`` when ``q + h`` leaves the bounds and ``−h`` does not; else
    the distance to the farther bound (0 for a fixed parameter)."""
    lower, upper = q - bounds[:, 0], bounds[:, 1] - q
    h = np.full(q.shape, ENGINE_FIT_STEP)
    fits = h <= np.maximum(lower, upper)
    h = np.where(((q + h < bounds[:, 0]) | (q + h > bounds[:, 1])) & fits, -h, h)
    return np.where(fits, h, np.where(upper >= lower, upper, -lower))


def _engine_fit_gradient(mse_channels, bounds):
    """``q ↦ (loss, gradient)``: :func:`_engine_fit_loss` of ``mse_channels(q)`` (engine,
    channel) and its forward differences (:func:`_forward_steps`) — the base colour's three
    from one render with all three stepped (channel c of the engines' renders depends on
    base channel c only), the others one render each. A fixed parameter's difference is 0/0,
    NaN as scipy's."""
    def fun(q):
        q = np.asarray(q, float)
        m0 = mse_channels(q)
        f0 = _engine_fit_loss(m0.sum(1))
        h = _forward_steps(q, bounds)
        dx = (q + h) - q
        grad = np.empty(q.size)
        stepped = q.copy()
        stepped[:3] += h[:3]
        m_base = mse_channels(stepped) if np.any(h[:3] != 0.0) else m0
        for c in range(3):
            m = m0.copy()
            m[:, c] = m_base[:, c]
            grad[c] = _engine_fit_loss(m.sum(1)) - f0
        for i in range(3, q.size):
            stepped = q.copy()
            stepped[i] += h[i]
            grad[i] = _engine_fit_loss(mse_channels(stepped).sum(1)) - f0
        with np.errstate(invalid="ignore", divide="ignore"):
            return f0, grad / dx
    return fun


def _engine_fit_result(p: dict, engines: tuple, q, has_sp: bool, mse0, mse1,
                       gain: float) -> dict:
    """The parameters :func:`optimize_for_engines` returns: ``p`` with the fitted vector
    ``q`` when the objective ``gain`` (mean capped PSNR / 10) is ≥ 0.1 dB and the
    specification, when targeted, is no further from the fit than with ``p``; else ``p``.
    The engines' figures before and after (``mse0``, ``mse1``) go into the notes."""
    figures = ", ".join(f"{e} {-10 * np.log10(b):.1f} -> {-10 * np.log10(a):.1f} dB"
                        for e, b, a in zip(engines, mse0, mse1))
    if not gain >= 0.01:
        return dict(p, notes=p["notes"] + ["engine-aware optimisation did not raise the engines' "
                                           f"mean PSNR in sphere-distant: rule kept ({figures})"])
    spec = engines.index("specification") if "specification" in engines else None
    if spec is not None and mse1[spec] > mse0[spec]:
        return dict(p, notes=p["notes"] + [
            "engine-aware optimisation would render the specification's BRDF further from "
            f"the fit than the rules in sphere-distant: rule kept ({figures})"])
    out = _with_engine_fit_vector(p, q, has_sp)
    names = "base colour, " + ("specularFactor, " if has_sp else "") + "roughness"
    out["notes"] = p["notes"] + [
        f"{names} fitted to the renders of {', '.join(engines)} in sphere-distant "
        f"(their models' PSNR vs the fit, each counted up to {ENGINE_FIT_CAP_DB:g} dB): {figures}"]
    return out


def _refine(model, p: dict, optimize) -> dict:
    """``p`` refined as ``optimize`` asks (:data:`OPTIMIZE`; ``True`` is ``"brdf"``, a false
    value none)."""
    if optimize is None or optimize is False:
        return p
    kind = "brdf" if optimize is True else optimize
    if kind not in OPTIMIZE:
        raise ValueError(f"glTF optimize: expected true, false or one of {', '.join(OPTIMIZE)}, "
                         f"got {optimize!r}")
    if kind == "brdf":
        return optimize_parameters(model, p)
    return optimize_for_engines(model, p, ENGINE_TARGETS if kind == "engines" else (kind,))


def gltf_equivalent(model, anisotropy: bool = True, optimize: bool | str = DEFAULT_OPTIMIZE,
                    specular: bool = True, max_ior: float = IOR_MAX,
                    engine: str = "specification") -> GLTFBRDF:
    """The BRDF an engine renders for the exported material (:func:`engine_brdf`): the
    specification's :class:`GLTFBRDF` (``engine="specification"``), Cycles' Principled BSDF
    as Blender's importer sets it up (``"blender"``: its default multiscatter GGX,
    ``"blender-ggx"``: GGX), or three.js's (``"threejs"``)."""
    if engine not in ENGINES:
        raise ValueError(f"engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    p = _refine(model, gltf_parameters(model, anisotropy, specular, max_ior), optimize)
    name = f"{getattr(model, 'name', 'model')}-gltf"
    return engine_brdf(p, engine, name if engine == "specification" else f"{name}-{engine}")


def gltf_fidelity(model, n_samples: int = 1 << 15,
                  metrics=("cos_rel_error", "normalized_l2"), anisotropy: bool = True,
                  optimize: bool | str = DEFAULT_OPTIMIZE, specular: bool = True,
                  parameters: dict | None = None, max_ior: float = IOR_MAX) -> dict:
    """BRDF-space loss of fidelity of the glTF material vs the fit
    (:func:`brdffit.evaluation.metrics.brdf_metrics`, the fit as reference); ``parameters``:
    the material's, when already mapped (else they are, with the other options)."""
    exported = (gltf_equivalent(model, anisotropy, optimize, specular, max_ior)
                if parameters is None
                else _brdf_of(parameters))
    r = brdf_metrics(model, exported, n_samples, metrics=metrics)
    return {k: r.get(k) for k in metrics}


def gltf_material(model, name: str | None = None, fidelity: bool = True,
                  anisotropy: bool = True, optimize: bool | str = DEFAULT_OPTIMIZE,
                  specular: bool = True, max_ior: float = IOR_MAX) -> dict:
    """The glTF 2.0 ``material`` object (``pbrMetallicRoughness`` + ``extras.brdffit`` with
    α, conventions, approximations and the measured BRDF-space fidelity; the
    ``KHR_materials_anisotropy`` extension for anisotropic fits when ``anisotropy``,
    ``KHR_materials_specular`` and ``KHR_materials_ior`` for dielectrics when ``specular``)."""
    p = _refine(model, gltf_parameters(model, anisotropy, specular, max_ior), optimize)
    extras = {"alpha": p["alpha"], "F0_fit": p["F0"], "F90_fit": p["F90"],
              "rho_d_fit": p["rho_d"], "notes": p["notes"],
              "conventions": "roughnessFactor = sqrt(alpha), alpha = GGX slope scale; "
                             "linear RGB of the source data; glTF Appendix B BRDF"}
    if fidelity:
        extras["fidelity"] = gltf_fidelity(model, parameters=p)
    mat = {"name": str(name or getattr(model, "name", None) or "material"),
           "pbrMetallicRoughness": {"baseColorFactor": p["baseColorFactor"],
                                    "metallicFactor": p["metallicFactor"],
                                    "roughnessFactor": p["roughnessFactor"]},
           "extras": {"brdffit": extras}}
    ext = _extensions(p)
    if ext:
        mat["extensions"] = ext
    return mat


#: the preview meshes a glTF export can carry (``mesh`` option of :func:`write_gltf`)
MESHES = ("sphere", "none")
#: the preview sphere's divisions: around the vertical axis, and from pole to pole
SPHERE_SEGMENTS, SPHERE_RINGS = 64, 32


def uv_sphere(segments: int = SPHERE_SEGMENTS, rings: int = SPHERE_RINGS) -> dict:
    """The preview mesh: a unit UV sphere laid out like the scenes' sphere
    (:mod:`brdffit.evaluation.render.scenes`): poles on ±Y (glTF's up), ``u`` around the
    vertical axis with ``u = 0.5`` facing +Z (the scenes' camera), ``v`` from the top (0) to
    the bottom (1), the seam at −Z. With ``θ = π v``, ``φ = 2π u``: position = normal =
    ``(−sin θ sin φ, cos θ, −sin θ cos φ)``; tangent = the unit ``∂p/∂u`` ``(−cos φ, 0, sin φ)``
    (defined at the poles too) with ``w = −1``, so that glTF's bitangent ``w (n × t)`` points
    along ``+v``. Triangles counter-clockwise seen from outside, one per quad at the poles
    (no degenerate triangles). Returns float32 ``positions``, ``normals``, ``tangents``
    (x, y, z, w), ``texcoords`` and uint16 ``indices``."""
    segments, rings = int(segments), int(rings)
    if segments < 3 or rings < 2 or (segments + 1) * (rings + 1) > 65535:
        raise ValueError(f"uv_sphere: expected segments >= 3, rings >= 2 and at most 65535 "
                         f"vertices, got {segments} x {rings}")
    u = np.arange(segments + 1) / segments
    v = np.arange(rings + 1) / rings
    V, U = np.meshgrid(v, u, indexing="ij")
    th, ph = np.pi * V, 2.0 * np.pi * U
    pos = np.stack([-np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)], -1)
    tan = np.stack([-np.cos(ph), np.zeros_like(ph), np.sin(ph), -np.ones_like(ph)], -1)
    uv = np.stack([U, V], -1)
    i = np.arange(rings)[:, None]
    j = np.arange(segments)[None, :]
    a, b = i * (segments + 1) + j, i * (segments + 1) + j + 1          # upper edge of a quad
    c, d = a + segments + 1, b + segments + 1                          # lower edge
    first = np.stack([a, c, d], -1)[:-1]           # (c, d) meet at the bottom pole: none there
    second = np.stack([a, d, b], -1)[1:]           # (a, b) meet at the top pole: none there
    tri = np.concatenate([first.reshape(-1, 3), second.reshape(-1, 3)])
    p = pos.reshape(-1, 3)
    normal = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    if np.any(np.sum(normal * p[tri[:, 0]], -1) <= 0):   # an inward or degenerate triangle
        raise AssertionError("uv_sphere: triangle winding is not counter-clockwise outside")
    return {"positions": p.astype(np.float32), "normals": p.astype(np.float32),
            "tangents": tan.reshape(-1, 4).astype(np.float32),
            "texcoords": uv.reshape(-1, 2).astype(np.float32),
            "indices": tri.reshape(-1).astype(np.uint16)}


def _mesh_document(tangents: bool) -> dict:
    """The glTF objects of the preview sphere (:func:`uv_sphere`): one buffer (a base64
    data URI, so that the export stays one file), its views and accessors, one mesh whose
    primitive uses material 0, one node and one scene. ``tangents``: write the TANGENT
    attribute (needed by ``KHR_materials_anisotropy``; else viewers derive it)."""
    import base64

    m = uv_sphere()
    attrs = [("POSITION", "positions", "VEC3"), ("NORMAL", "normals", "VEC3"),
             ("TEXCOORD_0", "texcoords", "VEC2")]
    if tangents:
        attrs.append(("TANGENT", "tangents", "VEC4"))
    blob, views, accessors, attributes = bytearray(), [], [], {}
    for name, key, kind in attrs:
        data = np.ascontiguousarray(m[key], "<f4")
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": data.nbytes,
                      "target": 34962})
        acc = {"bufferView": len(views) - 1, "componentType": 5126, "count": len(data),
               "type": kind}
        if name == "POSITION":
            acc["min"] = [float(x) for x in data.min(0)]
            acc["max"] = [float(x) for x in data.max(0)]
        attributes[name] = len(accessors)
        accessors.append(acc)
        blob += data.tobytes()
    idx = np.ascontiguousarray(m["indices"], "<u2")
    views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": idx.nbytes,
                  "target": 34963})
    accessors.append({"bufferView": len(views) - 1, "componentType": 5123,
                      "count": len(idx), "type": "SCALAR"})
    blob += idx.tobytes()
    blob += b"\0" * (-len(blob) % 4)
    uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode()
    return {"scene": 0, "scenes": [{"name": "preview", "nodes": [0]}],
            "nodes": [{"name": "preview sphere", "mesh": 0}],
            "meshes": [{"name": "preview sphere",
                        "primitives": [{"attributes": attributes,
                                        "indices": len(accessors) - 1, "material": 0}]}],
            "accessors": accessors, "bufferViews": views,
            "buffers": [{"byteLength": len(blob), "uri": uri}]}


def _one_pixel_png() -> bytes:
    """A 1×1 opaque white RGBA PNG (PNG specification: signature, IHDR, one zlib IDAT, IEND;
    each chunk's CRC-32 over its type and data)."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    header = struct.pack(">IIBBBBB", 1, 1, 8, 6, 0, 0, 0)   # 1×1, 8 bits, RGBA, no interlace
    pixels = zlib.compress(b"\x00\xff\xff\xff\xff")       # filter byte 0, then R, G, B, A
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", pixels)
            + chunk(b"IEND", b""))


def _placeholder_image() -> dict:
    """An ``images`` entry no material uses: Blender's glTF importer (5.0), asked to import
    unused materials (``import_unused_materials=True``), takes the length of the file's
    ``images`` array, which must then exist; glTF forbids an empty array, so it holds one
    1×1 white PNG (a data URI, ~100 bytes). The validator reports it as unused (an
    information, not an error)."""
    import base64

    return {"name": "placeholder (unused)",
            "uri": "data:image/png;base64," + base64.b64encode(_one_pixel_png()).decode()}


def write_gltf(model, path, fidelity: bool = True, anisotropy: bool = True,
               optimize: Literal[True, False, None, "brdf", "engines", "blender",
                                 "threejs"] = DEFAULT_OPTIMIZE, specular: bool = True,
               mesh: str = "sphere", max_ior: float = IOR_MAX, **_ignored) -> dict:
    """Write a glTF 2.0 JSON file atomically: ``asset``, one ``material`` and, with
    ``mesh="sphere"`` (default), the preview sphere that uses it (:func:`uv_sphere`, in
    the file as a data URI), so that a viewer or an importer shows the material; with
    ``mesh="none"`` the material alone (an importer then creates nothing); an unused
    placeholder image (:func:`_placeholder_image`) keeps Blender's importer from failing
    when it imports unused materials. ``optimize``
    refines the rule-based parameters (``"engines"``, the default, ``"blender"``,
    ``"threejs"``: :func:`optimize_for_engines`; ``True`` or ``"brdf"``:
    :func:`optimize_parameters`; ``None`` or ``False``: the rules alone), ``specular=False``
    leaves the dielectric extensions out (core glTF only), ``max_ior`` bounds the exported
    ``ior`` (:func:`_specular_extension`; a larger bound keeps a flat Fresnel's f90 for
    engines that follow the specification, at the cost of indices artists do not expect)."""
    if mesh not in MESHES:
        raise ExportError(f"glTF mesh: expected one of {', '.join(MESHES)}, found {mesh!r}")
    if not (optimize is None or isinstance(optimize, bool) or optimize in OPTIMIZE):
        raise ExportError(f"glTF optimize: expected true, false or one of "
                          f"{', '.join(OPTIMIZE)}, found {optimize!r}")
    check_output_path(path)
    mat = gltf_material(model, fidelity=fidelity, anisotropy=anisotropy, optimize=optimize,
                        specular=specular, max_ior=max_ior)
    doc = {"asset": {"version": "2.0", "generator": "brdffit export"}}
    if mesh == "sphere":
        doc.update(_mesh_document(tangents="KHR_materials_anisotropy" in mat.get("extensions",
                                                                                  {})))
    doc["materials"] = [mat]
    doc["images"] = [_placeholder_image()]
    if "extensions" in mat:
        doc["extensionsUsed"] = list(mat["extensions"])
    path = check_output_path(path)
    try:
        data = json.dumps(doc, indent=1, allow_nan=False).encode("ascii")   # names \u-escaped
    except ValueError as exc:
        raise ExportError(f"cannot export {model.__class__.__name__} {getattr(model, 'name', '')!r}"
                          f" to {shown(path)}: expected finite parameters, found NaN or infinity "
                          f"({exc})") from None
    with writing(path), atomic_write(path, "wb") as fh:
        fh.write(data)
    return {"files": [str(path)], "target": "gltf", "material": mat["pbrMetallicRoughness"],
            "extensions": sorted(mat.get("extensions", {})), "mesh": mesh,
            "notes": mat["extras"]["brdffit"]["notes"],
            "fidelity": mat["extras"]["brdffit"].get("fidelity")}
