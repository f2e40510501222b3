"""MaterialX documents (OpenPBR Surface) of microfacet fits, and the OpenPBR BRDF as a library BRDF.

:func:`write_materialx` writes, with the official MaterialX Python bindings (``materialx`` on
PyPI), one ``open_pbr_surface`` shader node (OpenPBR Surface 1.1, MaterialX ≥ 1.39) and its
``surfacematerial`` per fit; the document is checked by MaterialX's own ``validate()`` after
importing the standard data libraries (``mx.loadLibraries``) before it is written. Element
names come from ``Document.createValidChildName`` (a hostile fit name cannot break the XML
or collide); nothing else the user controls is written.

Mapping of a fit (a ``MicrofacetBRDF`` with a GGX, Beckmann or tabulated distribution: the
same inputs as :mod:`brdffit.export.gltf`, whose conversions it shares — tabulated → GGX by
Dupuy 2015 App. C, Beckmann → GGX of the same α)::

    specular_roughness = (α_t · √((1 + (1 − a)²)/2))^½, specular_roughness_anisotropy = a,
    a = 1 − α_b/α_t

the inverse of OpenPBR's ``open_pbr_anisotropy`` node (``α_t = r² √(2/(1 + (1 − a)²))``,
``α_b = (1 − a) α_t``), with α_t ≥ α_b the principal roughnesses of (αx, αy, ρ) (Dupuy 2015
App. C); the rougher axis must lie along the tangent: a rotation of the principal axes
relative to the tangent frame (ρ ≠ 0, or αy > αx) is reported (``tangent_rotation_deg``)
and, since ``geometry_tangent`` is the mesh's, not applied (part of the measured loss).
``F0 = ks·F(0°)``, ``F90 = ks·F(90°)`` and ``ρd`` as for glTF, and the same metallic rule
(``brdffit.export.gltf.MATERIAL_METAL_F0``):

* **dielectric** (``base_metalness = 0``): ``base_color = ρd / κ`` (Lambert: ``base_weight =
  1``, ``base_diffuse_roughness = 0``; κ the cosine-weighted mean of the ``1 − E(θo)`` by
  which OpenPBR darkens the base under the specular layer, so the diffuse albedo is the
  fit's on average, :func:`compensated_base`), ``specular_weight = 1``, ``specular_ior =
  (1 + √f)/(1 − √f)`` and ``specular_color = F0/f`` (F(0°) exact; OpenPBR's dielectric
  tint multiplies the whole Fresnel curve) with ``f`` the geometric mean of the two ends of
  that family (:func:`_dielectric_choice`): the mean over channels of ``F0/F90`` (the fit's
  Fresnel shape: exact for a dielectric fit, but MaterialX darkens the base by the albedo of
  the *untinted* dielectric, which a high index with a small tint overstates) and ``max
  F0`` (a low index that keeps the base but reaches F(90°) ≈ 1) — chosen by rendering; a
  dielectric fit of index η gives back ``specular_ior = η``, ``specular_color = ks`` exactly;
* **metal** (``base_metalness = 1``) under glTF's rule (luminance of F0 ≥ 0.08, above ρd's,
  and of F90 ≥ 0.8; or no diffuse term): OpenPBR's metal is ``specular_weight ·
  F_Schlick(base_color, F90 = 1)`` (``specular_color`` = F82 tint, white = plain Schlick):
  ``specular_weight = max F90`` (≤ 1 unless F0 exceeds it), ``base_color = F0 /
  specular_weight`` — exact for a Schlick fit with a grey ks; for a fit with a diffuse
  term (which the metal drops), ``base_color`` is instead the one whose cosine-weighted mean
  albedo is the fit's (:func:`~brdffit.export._common.base_for_albedo`; glTF's rule).

What stays lossy (measured by :func:`materialx_fidelity` against :class:`OpenPBRBRDF`):
MaterialX's GLSL (``mx_dielectric_bsdf``, ``mx_generalized_schlick_bsdf``, ``mx_layer``)
multiplies the specular lobe by the energy compensation ``1 + F (1 − E)/E`` (E the GGX
directional albedo, its rational fit ``mx_ggx_dir_albedo_analytic``), uses the isotropic
height-correlated G2 of the average α = √(αx αy), and attenuates the diffuse base by
``1 − E_F(θo)·comp`` (the dielectric's directional albedo) — the fit adds ρd/π unchanged
(the base colour restores the mean, not the dependence on θo).

A **coated** diffuse fit (base lobe + white coat lobe,
:func:`brdffit.microfacet.coat.coat_parts`):
the base lobe by the rules above, the coat as ``coat_weight`` = w, ``coat_roughness`` =
√α_coat, ``coat_ior`` = 1.5, ``coat_darkening`` = 0 (the fit has no darkening). OpenPBR's
graph mixes, by ``coat_weight``, a coat-roughened base roughness ``(2 r_c⁴ + r⁴)^¼`` and a
base index relative to the coat's into the base: both are inverted, so the effective base
lobe is the fit's; the coat is layered (``mx_layer``: the base weighted by one minus the
coat's directional albedo) where the fit adds it. Three candidates — the coat over the base
mapped as a dielectric, as a metal (a metal-like base flat at grazing: polyethylene), and one
lobe fitted to the coated fit (:func:`~brdffit.export._common.single_lobe_of`) — the one
closest to the fit is written (notes).

:class:`OpenPBRBRDF` re-implements that GLSL evaluation (reflection only: no fuzz, thin film,
transmission or subsurface; Lambert base; an isotropic coat) as a :class:`~brdffit.brdf.BRDF`.
"""

from __future__ import annotations

import numpy as np

from .._atomic import atomic_write
from ..brdf import IsotropicBRDF, _as_dirs
from ._common import (LUMA, base_for_albedo, check_output_path, closer_to,
                      cosine_weighted_albedo, diffuse_kept_fraction, shown, tangent_axes,
                      single_lobe_of, writing)
from ..errors import ExportError
from ..evaluation.metrics import BRDFMetrics, brdf_metrics
from .gltf import _ggx_model, is_metal, reflectances
from ..microfacet import DielectricFresnel
from ..microfacet.coat import coat_alpha_weight, coat_parts

__all__ = ["OpenPBRBRDF", "openpbr_parameters", "openpbr_equivalent", "materialx_fidelity",
           "materialx_document", "write_materialx", "validate_document"]


# ------------------------------------------------------------------------------------------
# the OpenPBR BRDF as MaterialX's GLSL evaluates it
# ------------------------------------------------------------------------------------------
def _dir_albedo_ab(n_dot_v, alpha):
    """``(A, B)`` of ``mx_ggx_dir_albedo_analytic`` (MaterialX's rational fit of the GGX
    directional albedo: ``E(F0, F90) = F0 A + F90 B``)."""
    x, y = np.asarray(n_dot_v, float), float(alpha)
    x2, y2 = x * x, y * y
    c = np.array([[0.1003, 0.9345, 1.0, 1.0], [-0.6303, -2.323, -1.765, 0.2281],
                  [9.748, 2.229, 8.263, 15.94], [-2.038, -3.748, 11.53, -55.83],
                  [29.34, 1.424, 28.96, 13.08], [-8.245, -0.7684, -7.507, 41.26],
                  [-26.44, 1.436, -36.11, 54.9], [19.99, 0.2913, 15.86, 300.2],
                  [-5.448, 0.6286, 33.37, -285.1]])
    terms = [np.ones_like(x), x, np.full_like(x, y), x * y, x2, np.full_like(x, y2), x2 * y,
             x * y2, x2 * y2]
    r = sum(t[..., None] * c[k] for k, t in enumerate(terms))
    return np.clip(r[..., 0] / r[..., 2], 0.0, 1.0), np.clip(r[..., 1] / r[..., 3], 0.0, 1.0)


def _fresnel_dielectric(c, ior):
    """``mx_fresnel_dielectric`` (exact, unpolarised; 1 under total internal reflection)."""
    g2 = ior * ior + c * c - 1.0
    g = np.sqrt(np.maximum(g2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        F = 0.5 * ((g - c) / (g + c)) ** 2 * (1.0 + (((g + c) * c - 1.0) / ((g - c) * c + 1.0)) ** 2)
    return np.where(g2 < 0, 1.0, np.nan_to_num(F, nan=1.0))


def _smith_g2(nl, nv, alpha):
    """``mx_ggx_smith_G2``: the height-correlated Smith masking-shadowing of GGX ``alpha``."""
    a2 = alpha * alpha
    lam_l = np.sqrt(a2 + (1.0 - a2) * nl * nl)
    lam_v = np.sqrt(a2 + (1.0 - a2) * nv * nv)
    return 2.0 * nl * nv / (lam_l * nv + lam_v * nl)


def _dielectric_layer(nl, nv, vh, alpha: float, ior: float):
    """The terms of a GGX dielectric layer as MaterialX's GLSL evaluates it
    (``mx_dielectric_bsdf`` in ``mx_layer``): the height-correlated G2 of ``alpha``, the
    directional albedo ``Ess`` of its rational fit, the exact Fresnel of ``ior`` at V·H, the
    energy compensation ``1 + F (1 − Ess)/Ess`` and the layer's directional albedo
    ``(f0 A + B)·comp`` that darkens what lies below."""
    G = _smith_g2(nl, nv, alpha)
    A, B = _dir_albedo_ab(nv, alpha)
    Ess = (A + B)[..., None]
    F = _fresnel_dielectric(vh, ior)[..., None]
    comp = 1.0 + F * (1.0 - Ess) / Ess
    f0 = ((ior - 1.0) / (ior + 1.0)) ** 2
    return G, Ess, F, comp, (f0 * A + B)[..., None] * comp


class OpenPBRBRDF(IsotropicBRDF):
    """OpenPBR Surface (``open_pbr_surface``) reflection as MaterialX's GLSL evaluates it.

    Parameters: ``base_color`` (RGB), ``base_metalness``, ``specular_weight``,
    ``specular_color`` (RGB), ``specular_roughness``, ``specular_roughness_anisotropy``,
    ``specular_ior``, ``coat_weight``, ``coat_roughness``, ``coat_ior`` (coat_color white,
    coat_darkening 0; the other OpenPBR inputs at their defaults: base_weight 1, no fuzz,
    thin film, transmission, subsurface; base_diffuse_roughness 0 = Lambert). The
    anisotropy's rougher axis is the tangent, at ``tangent_rotation`` (radians,
    counter-clockwise about the normal) from the local x axis (``geometry_tangent``
    connected to the rotated mesh tangent). ``wi`` = L (light), ``wo`` = V (viewer).
    """

    def __init__(self, base_color, base_metalness: float, specular_roughness: float,
                 specular_ior: float = 1.5, specular_color=(1.0, 1.0, 1.0),
                 specular_weight: float = 1.0, specular_roughness_anisotropy: float = 0.0,
                 tangent_rotation: float = 0.0, coat_weight: float = 0.0,
                 coat_roughness: float = 0.0, coat_ior: float = 1.5, name: str = "openpbr"):
        self.coat_weight = float(coat_weight)
        self.coat_roughness = float(coat_roughness)
        self.coat_ior = float(coat_ior)
        if not (0.0 <= self.coat_weight <= 1.0 and 0.0 <= self.coat_roughness <= 1.0
                and self.coat_ior > 1.0):
            raise ValueError(f"OpenPBRBRDF: expected coat_weight, coat_roughness in [0, 1] and "
                             f"coat_ior > 1, found {coat_weight}, {coat_roughness}, {coat_ior}")
        self.tangent_rotation = float(tangent_rotation)
        self.base_color = np.broadcast_to(np.asarray(base_color, float), (3,)).copy()
        self.base_metalness = float(base_metalness)
        self.specular_roughness = float(specular_roughness)
        self.specular_ior = float(specular_ior)
        self.specular_color = np.broadcast_to(np.asarray(specular_color, float), (3,)).copy()
        self.specular_weight = float(specular_weight)
        self.specular_roughness_anisotropy = float(specular_roughness_anisotropy)
        a = self.specular_roughness_anisotropy
        r = self.specular_roughness
        if self.coat_weight > 0:      # the graph's effective_specular_roughness
            r = _coat_roughened(r, self.coat_roughness, self.coat_weight)
        r2 = r ** 2
        ax = r2 * np.sqrt(2.0 / (1.0 + (1.0 - a) ** 2))            # open_pbr_anisotropy
        self.alpha = (float(np.clip(ax, 1e-6, 1.0)), float(np.clip((1.0 - a) * ax, 1e-6, 1.0)))
        self.isotropic = a == 0.0
        self.name = name
        self.source = None

    def _ior(self) -> float:
        """The specular_weight-modulated index of the node graph (``modulated_eta_s``)."""
        eta = self.specular_ior
        if self.coat_weight > 0:      # the graph's eta_s: relative to the coat, TIR fix
            eta = _coat_relative_ior(eta, self.coat_ior, self.coat_weight)
        f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
        s = np.sign(eta - 1.0) * np.sqrt(np.clip(self.specular_weight * f0, 0.0, 0.99999))
        return float((1.0 + s) / (1.0 - s))

    def eval(self, wi, wo) -> np.ndarray:
        wi, wo = _as_dirs(wi, wo)
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        nl = np.clip(wi[..., 2], 1e-6, 1.0)
        nv = np.clip(wo[..., 2], 1e-6, 1.0)
        h = wi + wo
        h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        vh = np.clip(np.sum(wo * h, -1), 1e-6, 1.0)
        ax, ay = self.alpha
        c, s = np.cos(self.tangent_rotation), np.sin(self.tangent_rotation)
        hx, hy = c * h[..., 0] + s * h[..., 1], -s * h[..., 0] + c * h[..., 1]
        he = np.stack([hx / ax, hy / ay], -1)
        D = 1.0 / (np.pi * ax * ay * (np.sum(he * he, -1) + h[..., 2] ** 2) ** 2)
        # dielectric: tint · F_dielectric, layered over the Lambert base
        G, Ess, Fd, comp_d, dir_alb = _dielectric_layer(nl, nv, vh, float(np.sqrt(ax * ay)),
                                                        self._ior())
        lobe = (D * G / (4.0 * nl * nv))[..., None]
        diel = lobe * Fd * comp_d * np.maximum(self.specular_color, 0.0) \
            + (1.0 - dir_alb) * np.maximum(self.base_color, 0.0) / np.pi
        # metal: specular_weight · Schlick(base_color, 1) (F82 tint = specular_color)
        c0 = np.maximum(self.base_color, 0.0)
        Fm = _schlick_f82(vh, c0, np.maximum(self.specular_color, 0.0))
        comp_m = 1.0 + Fm * (1.0 - Ess) / Ess
        metal = self.specular_weight * lobe * Fm * comp_m
        m = self.base_metalness
        f = (1.0 - m) * diel + m * metal
        if self.coat_weight > 0:      # coat_layer: dielectric_bsdf(coat_weight) over the base
            f = self._coat_over(f, nl, nv, h[..., 2], vh)
        return np.where(ok[..., None], np.nan_to_num(f), 0.0)

    def _coat_over(self, f_base, nl, nv, nh, vh):
        """``mx_layer`` of the isotropic coat (``mx_dielectric_bsdf`` with weight
        ``coat_weight``, energy compensation) over ``f_base``: the base weighted by one
        minus the coat's directional albedo at θo (coat_darkening 0, coat_color white)."""
        a = float(np.clip(self.coat_roughness ** 2, 1e-6, 1.0))
        a2 = a * a
        D = a2 / (np.pi * (nh * nh * (a2 - 1.0) + 1.0) ** 2)
        G, _, F, comp, albedo = _dielectric_layer(nl, nv, vh, a, self.coat_ior)
        lobe = (D * G / (4.0 * nl * nv))[..., None]
        return (self.coat_weight * lobe * F * comp
                + (1.0 - self.coat_weight * albedo) * f_base)

    def describe(self) -> dict:
        d = super().describe()
        d.update(base_color=self.base_color.tolist(), base_metalness=self.base_metalness,
                 specular_roughness=self.specular_roughness, specular_ior=self.specular_ior,
                 specular_color=self.specular_color.tolist(),
                 specular_weight=self.specular_weight,
                 specular_roughness_anisotropy=self.specular_roughness_anisotropy,
                 tangent_rotation=self.tangent_rotation, coat_weight=self.coat_weight,
                 coat_roughness=self.coat_roughness, coat_ior=self.coat_ior)
        return d


def _schlick_f82(cos_t, f0, f82_tint):
    """``mx_fresnel_hoffman_schlick`` with F90 = 1, exponent 5 (Hoffman 2023 F82 tint):
    ``Schlick(F0, 1) − a cos θ (1 − cos θ)⁶`` with ``a`` giving ``F(82°) = tint·Schlick(82°)``
    (``a = 0`` for a white tint)."""
    c = np.asarray(cos_t, float)[..., None]
    cb = 1.0 / 7.0
    x = 1.0 - c
    schlick = f0 + (1.0 - f0) * x ** 5
    sb = f0 + (1.0 - f0) * (1.0 - cb) ** 5
    a = sb * (1.0 - f82_tint) / (cb * (1.0 - cb) ** 6)
    return np.clip(schlick - a * c * x ** 6, 0.0, None)


# ------------------------------------------------------------------------------------------
# mapping
# ------------------------------------------------------------------------------------------
def openpbr_parameters(model, metal: bool | None = None) -> dict:
    """OpenPBR inputs of a fit by the rules of the module docstring, with ``notes``,
    ``tangent_rotation_deg`` and the fit's ``F0``, ``F90``, ``rho_d``. A coated diffuse fit
    (:func:`brdffit.microfacet.coat.coat_parts`): the base lobe by these rules, the coat as
    ``coat_weight`` = w, ``coat_roughness`` = √α_coat, ``coat_ior`` = 1.5,
    ``coat_darkening`` = 0."""
    parts = coat_parts(model)
    if parts is not None and metal is None:
        return _closest_coated(model)
    if parts is not None:
        return _with_coat(openpbr_parameters(parts[0], metal=metal), parts[1])
    m, notes = _ggx_model(model, "MaterialX")
    p = _specular_lobe(m.distribution, notes)
    F0, F90, rd = reflectances(m)
    F0c, F90c = np.clip(F0, 0.0, 1.0), np.clip(F90, 0.0, 1.0)
    # as for glTF: a fit whose grazing reflectance stays far below 1 is no metal (OpenPBR's
    # metal would drop its diffuse term; measured gains: docs/design/exports.md)
    metal = is_metal(m, F0c, rd, F90c) if metal is None else bool(metal)
    if metal:
        _metal_base(m, p, F0, F90, notes)
    else:
        p.update(base_metalness=0.0, base_color=np.clip(rd, 0, 1).tolist(), specular_weight=1.0)
        p.update(_dielectric_choice(m, p, F0c, F90c, notes))
    notes.append("MaterialX GLSL: energy compensation and average-alpha G2 on the specular lobe")
    p.update(notes=notes, F0=F0.tolist(), F90=F90.tolist(), rho_d=rd.tolist())
    return p


def _closest_coated(model) -> dict:
    """:func:`openpbr_parameters` of a coated fit as whichever is closer to the fit: the coat
    over a dielectric base, over a metal base (the base lobe of a coated fit can be
    metal-like with a low grazing reflectance, the coat having taken the rise:
    polyethylene, which OpenPBR's dielectric renders badly) or, as for glTF, one lobe
    fitted to the coated fit."""
    cands = {"coat over a dielectric base": openpbr_parameters(model, metal=False),
             "coat over a metal base": openpbr_parameters(model, metal=True),
             "one lobe": openpbr_parameters(single_lobe_of(model))}
    label, p, err = closer_to(model, cands, _brdf_of)
    others = "; ".join(f"{k}: {v:.4g}" for k, v in err.items() if k != label)
    return dict(p, notes=p["notes"] + [f"coated fit exported as {label} (cos_rel_error vs "
                                       f"the fit {err[label]:.4g}; {others})"])


def _with_coat(p: dict, coat) -> dict:
    """``p`` (the base lobe's inputs) with ``coat`` as OpenPBR's coat. OpenPBR roughens the
    base specular under the coat and makes its index relative to the coat's (both mixed in
    by ``coat_weight``): both are inverted so that the effective values are the base
    lobe's."""
    alpha, w = coat_alpha_weight(coat)
    c = float(np.sqrt(min(alpha, 1.0)))
    p.update(coat_weight=w, coat_roughness=c, coat_ior=1.5, coat_darkening=0.0)
    notes = [f"coat (white, index 1.5, weight {w:.4g}, alpha {alpha:.4g}): OpenPBR layers "
             "it over the base (the fit adds it)"]
    r, ok_r = _uncoated(lambda x: _coat_roughened(x, c, w), p["specular_roughness"],
                        0.0, 1.0)
    eta, ok_e = _uncoated(lambda x: _coat_relative_ior(x, 1.5, w), p["specular_ior"],
                          1.0 + 1e-9, max(10.0, 4.0 * p["specular_ior"]))
    p.update(specular_roughness=r, specular_ior=eta)
    notes.append("specular_roughness and specular_ior chosen so that OpenPBR's coat-"
                 "roughened roughness and coat-relative index are the base lobe's"
                 + ("" if ok_r and ok_e else
                    " (not reachable: " + ", ".join(k for k, ok in (("roughness", ok_r),
                                                                     ("index", ok_e))
                                                    if not ok) + " clipped)"))
    p["notes"] = p["notes"] + notes
    return p


def _specular_lobe(d, notes: list) -> dict:
    """``specular_roughness``, ``specular_roughness_anisotropy``, ``base_weight``,
    ``base_diffuse_roughness`` and ``tangent_rotation_deg`` of GGX ``d`` (module
    docstring: αt clipped to 1, a = 1 − αb/αt, the tangent rotated to the rougher principal
    axis); notes go to ``notes``."""
    at, ab, rot = tangent_axes(d)
    if at > 1.0:
        notes.append(f"alpha {at:.4g} > 1 clipped to OpenPBR's largest roughness")
        at, ab = 1.0, min(ab, 1.0)
    a = 1.0 - ab / at if at > 0 else 0.0
    r = float(np.sqrt(at * np.sqrt((1.0 + (1.0 - a) ** 2) / 2.0)))
    if a <= 0:
        rot = 0.0
    elif abs(rot) > 1e-12:
        notes.append(f"anisotropy: geometry_tangent = the mesh tangent rotated by "
                     f"{np.degrees(rot):.6g} deg about the normal (rotate3d), the rougher "
                     "principal axis of the fit")
    return {"specular_roughness": r, "specular_roughness_anisotropy": float(a),
            "base_weight": 1.0, "base_diffuse_roughness": 0.0,
            "tangent_rotation_deg": float(np.degrees(rot))}


def _metal_base(m, p: dict, F0, F90, notes: list) -> None:
    """Set the metal inputs of ``p``: ``specular_weight`` sw = the largest of F0 and F90
    (clipped to [0, 1]) times Schlick(base_color = F0/sw, 1). OpenPBR's metal drops the
    diffuse term and stops at F90 = 1: a fit with a diffuse term takes the base colour whose
    cosine-weighted mean albedo is the fit's (polyethylene), as for glTF."""
    F0c, F90c = np.clip(F0, 0.0, 1.0), np.clip(F90, 0.0, 1.0)
    sw = float(max(F90c.max(), F0c.max(), 1e-12))
    p.update(base_metalness=1.0, base_color=np.clip(F0c / sw, 0, 1).tolist(),
             specular_weight=sw, specular_color=[1.0, 1.0, 1.0], specular_ior=1.5)
    notes.append(f"metal: specular_weight {sw:.4g} x Schlick(base_color, 1) (fit F90: "
                 f"{np.round(F90, 4).tolist()})")
    if m.diffuse is not None:
        target = cosine_weighted_albedo(m)
        base, wanted = base_for_albedo(lambda b: _brdf_of(dict(p, base_color=b)), target)
        p["base_color"] = base.tolist()
        notes.append(f"metal: base_color {np.round(base, 4).tolist()} keeps the fit's "
                     f"cosine-weighted mean albedo {np.round(target, 4).tolist()} (its "
                     f"diffuse term folded in; F0: {np.round(F0c, 4).tolist()})"
                     + (": clipped" if np.any(wanted > 1) else ""))


def _coat_roughened(r: float, coat_roughness: float, coat_weight: float) -> float:
    """OpenPBR's ``effective_specular_roughness`` under a coat."""
    roughened = min(1.0, 2.0 * coat_roughness ** 4 + r ** 4) ** 0.25
    return r + coat_weight * (roughened - r)


def _coat_relative_ior(eta: float, coat_ior: float, coat_weight: float) -> float:
    """OpenPBR's ``eta_s`` under a coat (index relative to the coat's, TIR fix)."""
    rel = eta / coat_ior
    return eta + coat_weight * ((rel if rel > 1.0 else 1.0 / rel) - eta)


def _uncoated(effective, target: float, lo: float, hi: float) -> tuple[float, bool]:
    """The input x in [lo, hi] whose ``effective(x)`` (increasing) is ``target``, by
    bisection; ``(x, reachable)`` (the nearest end when not reachable)."""
    if effective(lo) >= target:
        return lo, effective(lo) - target <= 1e-12
    if effective(hi) <= target:
        return hi, target - effective(hi) <= 1e-12
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if effective(mid) < target else (lo, mid)
    return 0.5 * (lo + hi), True


def _ior_of_f0(f: float) -> float:
    q = float(np.sqrt(np.clip(f, 0.0, 0.95)))
    return float((1.0 + q) / (1.0 - q))


def _dielectric_choice(model, p, F0, F90, notes, n: int = 1 << 15) -> dict:
    """``specular_ior`` and ``specular_color`` of a dielectric. Along the family with F(0°)
    exact — ``F0(ior) = f``, ``specular_color = F0/f`` (so F(90°) = F0/f) — two ends:

    * *shape*: ``f`` = mean of ``F0/F90`` (the Fresnel's own normal reflectance), so
      ``specular_color`` = F90 — the fit's Fresnel exactly when it is a dielectric one, but
      MaterialX attenuates the base by the albedo of the *untinted* dielectric, so a fit whose
      F is almost constant (high index, tiny tint) loses its base;
    * *F0*: ``f`` = the largest channel of F0, tint ≤ 1 — a low index that keeps the base,
      but F(90°) ≈ 1: grazing highlights far brighter than the fit's;

    the mapping used is the *shape* one when the fit's Fresnel is a dielectric one (exact
    index and tint), else the one of *shape* and **balanced** — ``f = √(f_shape · f_F0)``,
    between the two ends — with the lower cosine-weighted error (a dark base loses little to
    the shape's darkening and keeps its exact grazing Fresnel). Why: BRDF-space errors
    do not rank the F0 end as renders do (it has the lowest cosine-weighted error and the
    worst pictures); the balanced index renders far better than either end on most
    dielectrics, but always using it loses on dark bases, where the shape end is right —
    hence the choice between shape and balanced (measurements: docs/design/exports.md).
    ``bench/studies/export_fidelity.py`` measures the result over MERL-100. The
    cosine-weighted errors (2¹⁵ direction pairs: fewer misjudge sharp lobes) of the three
    are in the notes.

    The base colour is the compensated one (:func:`compensated_base`) unless ``ρd`` itself
    has the lower cosine-weighted error with the chosen index and tint (a specular layer
    brighter than the fit's, which a darker base partly offsets); on MERL-100 this keeps ρd
    on a few materials, with a small gain on the mean (docs/design/exports.md).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(F90 > 0, F0 / np.where(F90 > 0, F90, 1.0), 0.0)
    f_shape, f_f0 = float(np.mean(ratio)), float(F0.max())
    f_bal = float(np.sqrt(f_shape * f_f0)) if f_shape > 0 and f_f0 > 0 else max(f_f0, f_shape)
    rho_d = np.asarray(p["base_color"], float)       # the fit's ρd (clipped to [0, 1])

    def candidate(f):
        ior = _ior_of_f0(f)
        f_eta = ((ior - 1.0) / (ior + 1.0)) ** 2
        tint = np.clip(F0 / f_eta, 0.0, 1.0) if f_eta > 0 else np.ones(3)
        c = {"specular_ior": ior, "specular_color": tint.tolist()}
        c["base_color"] = compensated_base(p, c, rho_d)
        return c

    cands = {"balanced": candidate(f_bal), "shape": candidate(f_shape), "F0": candidate(f_f0)}
    metric = BRDFMetrics(model, n, 0, ("cos_rel_error",))
    errs = {}
    for k, c in cands.items():
        eq = _dielectric(p, c)
        e = metric.evaluate(eq).get("cos_rel_error")
        errs[k] = float(e) if e is not None and np.isfinite(e) else np.inf
    if isinstance(getattr(model, "fresnel", None), DielectricFresnel) and np.isfinite(errs["shape"]):
        best = "shape"              # the fit's Fresnel is OpenPBR's: index and tint exact
    else:                           # the F0 end is never used: its grazing peaks ruin renders
        best = min(("shape", "balanced"), key=errs.get)
        if not np.isfinite(errs[best]):
            best = min(errs, key=errs.get)
    c = cands[best]
    # the compensated base only where it lowers the error: where the specular layer is too
    # bright (a strong tinted index on a rough lobe), the base ρd makes up for some of it
    plain = dict(c, base_color=rho_d.tolist())
    e_plain = metric.evaluate(_dielectric(p, plain)).get("cos_rel_error")
    compensated = not (e_plain is not None and e_plain < errs[best])
    if not compensated:
        c = plain
    notes.append(f"dielectric: specular_ior {c['specular_ior']:.4g}, specular_color "
                 f"{np.round(c['specular_color'], 4).tolist()} ('{best}' mapping; cos_rel_error "
                 f"vs fit {', '.join(f'{k} {v:.4g}' for k, v in errs.items())}); base_color "
                 f"{np.round(c['base_color'], 4).tolist()} = "
                 + ("rho_d / the fraction of the base the specular layer lets through "
                    "(cosine-weighted mean)" if compensated else
                    f"rho_d (cos_rel_error {e_plain:.4g}, below the compensated base's)"))
    if np.any(np.asarray(c["base_color"]) >= 1.0):
        notes.append("base_color clipped to 1: the fit's diffuse albedo is not reachable under "
                     "the specular layer")
    return c


def _dielectric(p, c, base_color=None) -> "OpenPBRBRDF":
    """The dielectric :class:`OpenPBRBRDF` of the roughness inputs ``p`` and the Fresnel
    inputs ``c`` (base colour ``base_color``, else ``c["base_color"]``)."""
    return _brdf_of({**p, **c, "base_metalness": 0.0, "specular_weight": 1.0,
                     "base_color": c["base_color"] if base_color is None else base_color})


def compensated_base(p, c, rho_d) -> list:
    """The base colour that gives a dielectric OpenPBR material the fit's diffuse albedo:
    OpenPBR darkens its base by ``1 − E(θo)`` (the specular layer's directional albedo,
    energy compensation included), which the fit (``ρd/π`` added to the lobe) does not, so
    ``base_color = ρd / κ`` with κ the cosine-weighted mean of that factor
    (:func:`brdffit.export._common.diffuse_kept_fraction`), clipped to [0, 1]."""
    kept = diffuse_kept_fraction(lambda b: _dielectric(p, c, b))
    return np.clip(np.asarray(rho_d, float) / np.maximum(kept, 1e-6), 0.0, 1.0).tolist()


def openpbr_equivalent(model) -> OpenPBRBRDF:
    """The :class:`OpenPBRBRDF` of the exported ``open_pbr_surface``."""
    return _brdf_of(openpbr_parameters(model), f"{getattr(model, 'name', 'model')}-openpbr")


def _brdf_of(p: dict, name: str = "openpbr") -> OpenPBRBRDF:
    """The :class:`OpenPBRBRDF` of the inputs ``p`` (as :func:`openpbr_parameters` names them)."""
    return OpenPBRBRDF(p["base_color"], p["base_metalness"], p["specular_roughness"],
                       specular_ior=p["specular_ior"], specular_color=p["specular_color"],
                       specular_weight=p["specular_weight"],
                       specular_roughness_anisotropy=p["specular_roughness_anisotropy"],
                       tangent_rotation=np.radians(p.get("tangent_rotation_deg", 0.0)),
                       coat_weight=p.get("coat_weight", 0.0),
                       coat_roughness=p.get("coat_roughness", 0.0),
                       coat_ior=p.get("coat_ior", 1.5), name=name)


def materialx_fidelity(model, n_samples: int = 1 << 15,
                       metrics=("cos_rel_error", "normalized_l2"),
                       parameters: dict | None = None) -> dict:
    """BRDF-space loss of the OpenPBR material vs the fit
    (:func:`brdffit.evaluation.metrics.brdf_metrics`, the fit as reference); ``parameters``:
    the material's inputs, when already mapped (:func:`openpbr_parameters`)."""
    exported = openpbr_equivalent(model) if parameters is None else _brdf_of(parameters)
    r = brdf_metrics(model, exported, n_samples, metrics=metrics)
    return {k: r.get(k) for k in metrics}


# ------------------------------------------------------------------------------------------
# the document
# ------------------------------------------------------------------------------------------
_LIBRARY = None


def _mx():
    try:
        import MaterialX as mx
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise ExportError(f"the MaterialX export needs the 'materialx' package ({exc})") from None
    return mx


def _library():
    """The standard data libraries (loaded once)."""
    global _LIBRARY
    mx = _mx()
    if _LIBRARY is None:
        lib = mx.createDocument()
        mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
        _LIBRARY = lib
    return _LIBRARY


def validate_document(doc) -> tuple[bool, str]:
    """``doc.validate()`` with the standard libraries imported (on a copy of ``doc``)."""
    mx = _mx()
    check = mx.createDocument()
    check.copyContentFrom(doc)
    check.importLibrary(_library())
    ok, msg = check.validate()
    return bool(ok), str(msg)


def materialx_document(model, name: str | None = None):
    """``(document, parameters)``: an ``open_pbr_surface`` node and its ``surfacematerial``."""
    mx = _mx()
    p = openpbr_parameters(model)
    doc = mx.createDocument()
    base = str(name or getattr(model, "name", None) or "material")
    mat_name = doc.createValidChildName(base if base.strip() else "material")
    shader = doc.addNode("open_pbr_surface", doc.createValidChildName(f"{mat_name}_openpbr"),
                         "surfaceshader")
    for key in ("base_weight", "base_metalness", "base_diffuse_roughness", "specular_weight",
                "specular_roughness", "specular_roughness_anisotropy", "specular_ior"):
        shader.addInput(key, "float").setValueString(_value_string(p[key]))
    for key in ("base_color", "specular_color"):
        shader.addInput(key, "color3").setValueString(", ".join(_value_string(v) for v in p[key]))
    if p.get("coat_weight", 0.0) > 0.0:
        for key in ("coat_weight", "coat_roughness", "coat_ior", "coat_darkening"):
            shader.addInput(key, "float").setValueString(_value_string(p[key]))
    if p["tangent_rotation_deg"] != 0.0:
        # MaterialX's rotate3d turns v into v cos + (v × axis) sin + ...: clockwise about the
        # axis for a positive amount, hence the minus sign
        tangent = doc.addNode("tangent", doc.createValidChildName(f"{mat_name}_tangent"), "vector3")
        tangent.addInput("space", "string").setValueString("world")
        normal = doc.addNode("normal", doc.createValidChildName(f"{mat_name}_normal"), "vector3")
        normal.addInput("space", "string").setValueString("world")
        rot = doc.addNode("rotate3d", doc.createValidChildName(f"{mat_name}_rotated_tangent"),
                          "vector3")
        rot.addInput("in", "vector3").setConnectedNode(tangent)
        rot.addInput("amount", "float").setValueString(_value_string(-p["tangent_rotation_deg"]))
        rot.addInput("axis", "vector3").setConnectedNode(normal)
        shader.addInput("geometry_tangent", "vector3").setConnectedNode(rot)
    doc.addMaterialNode(mat_name, shader)
    return doc, p


def _value_string(v) -> str:
    """A float input's MaterialX value string (9 significant digits: float32 round trip)."""
    return f"{float(v):.9g}"


def write_materialx(model, path, fidelity: bool = True, **_ignored) -> dict:
    """Write the ``.mtlx`` document of ``model`` atomically (validated first)."""
    mx = _mx()
    path = check_output_path(path)
    doc, p = materialx_document(model)
    values = [p[k] for k in ("specular_roughness", "specular_ior", "specular_weight",
                             "specular_roughness_anisotropy", "base_metalness")]
    values += list(p["base_color"]) + list(p["specular_color"]) + [p.get("coat_weight", 0.0),
                                                                    p.get("coat_roughness", 0.0)]
    if not all(np.isfinite(values)):
        raise ExportError(f"cannot export {type(model).__name__} {getattr(model, 'name', '')!r} "
                          f"to {shown(path)}: expected finite parameters, found NaN or infinity")
    ok, msg = validate_document(doc)
    if not ok:
        raise ExportError(f"cannot export to {shown(path)}: MaterialX validate() rejected the "
                          f"document ({' '.join(msg.split())[:300]})")
    data = mx.writeToXmlString(doc).encode("utf-8")
    with writing(path), atomic_write(path, "wb") as fh:
        fh.write(data)
    out = {"files": [str(path)], "target": "materialx", "shader": "open_pbr_surface",
           "parameters": {k: p[k] for k in ("base_color", "base_metalness", "specular_weight",
                                            "specular_color", "specular_roughness",
                                            "specular_roughness_anisotropy", "specular_ior",
                                            "coat_weight", "coat_roughness") if k in p},
           "tangent_rotation_deg": p["tangent_rotation_deg"], "notes": p["notes"]}
    if fidelity:
        out["fidelity"] = materialx_fidelity(model, parameters=p)
    return out
