"""Mitsuba 3 exports: built-in plugins where the fit maps to one, else the project's plugin.

Built-in mapping (:func:`builtin_bsdf`)
---------------------------------------
A :class:`~brdffit.microfacet.model.MicrofacetBRDF` with a GGX or Beckmann distribution maps
to Mitsuba's ``roughconductor`` (``distribution`` ``ggx``/``beckmann``, ``alpha_u`` = αx,
``alpha_v`` = αy: **Mitsuba's α is our α**, the slope scale of Walter 2007 / Dupuy 2015
Eq. 9, not the perceptual roughness √α). The Lambertian term ρd/π is Mitsuba's ``diffuse``;
sums of terms are built exactly with ``blendbsdf`` (weight ½ of twice each half: Mitsuba has
no additive BSDF), the scale going into ``specular_reflectance``/``reflectance`` as
unbounded ``srgb`` textures. ``SumBRDF`` (e.g. two GGX lobes) and
``PerChannelMicrofacetBRDF`` with GGX/Beckmann channels (one lobe per channel, masked with
an RGB ``specular_reflectance``) map the same way.

Approximations (measured by :func:`mitsuba_error` against the fit, reported in the export
summary):

* **Fresnel.** ``roughconductor`` evaluates the exact conductor Fresnel of a complex index
  ``eta + i k`` (times ``specular_reflectance``). :class:`ConductorFresnel` maps exactly,
  :class:`DielectricFresnel` as ``k = 0`` (exact), no Fresnel as ``material="none"``
  (F = 1). Schlick, generalised Schlick (Bagher 2012 Eq. 11) and tabulated / fitted Fresnel
  curves are approximated per channel by ``s · F_conductor(θd; η, k)``, (η, k, s) fitted by
  least squares on 90 uniform θd weighted by cos⁴θd (:func:`fit_conductor_fresnel`; the
  fitted curve's maximum absolute error is reported).
* **Shadowing.** Mitsuba uses the uncorrelated Smith ``G1(i) G1(o)``; our fits default to
  the height-correlated G of Dupuy 2015 Eq. 2 (PerChannel SGD/CT fits are uncorrelated,
  exact).
* ``roughdielectric`` is not used: fits are reflection-only BRDFs (no transmission).
  ``roughplastic`` is offered as an alternative (``style="plastic"``, :func:`plastic_bsdf`)
  for dielectric-looking fits; it is approximate (scalar η, energy-coupled diffuse) and its
  error is measured inside Mitsuba (:func:`mitsuba_eval_error`).
* **Correlation ρ ≠ 0.** Mitsuba has no correlated anisotropy. The slope scale matrix is
  diagonalised (:func:`~brdffit.export._common.principal_axes`): the distribution is exactly
  the axis-aligned one with the principal roughnesses in the tangent frame rotated by φ about
  the normal. The snippet carries ``alpha_u``/``alpha_v`` of the principal axes and the angle
  (``frame_rotation_deg`` in the summary and an XML comment): exact when the mesh's tangents
  (uv) are rotated by φ, else the error of ignoring the rotation is reported.

Project plugin (:func:`plugin_bsdf`, :func:`write_mitsuba_python`)
------------------------------------------------------------------
Tabulated, SGD and NPF fits (and anything else the render module translates) use the
``brdffit`` BSDF of :mod:`brdffit.evaluation.render.plugin` (Dr.Jit evaluator registered in
the running process). Such a model has no XML form; the Python export writes the fit next to a
ready-to-render script.

Untrusted names
---------------
Material names, source specs and output file names are never pasted into generated code: the
Python script carries them only as ``ascii()`` string literals (``MATERIAL``, ``FIT_FILE``,
``OUTPUT_NAME``; its docstring is fixed text) and every other value is written by
:func:`py_literal` (finite floats, ints, booleans, ASCII-escaped strings); in XML every string
goes through :func:`~xml.sax.saxutils.quoteattr` (characters XML cannot hold are refused) and
the header comment is neutralised (every ``--`` broken up). Script and fit file are
written as a whole (:class:`~brdffit.export._common.StagedFiles`).
"""

from __future__ import annotations

import math
import re
from xml.sax.saxutils import quoteattr

import numpy as np

from .._atomic import atomic_write
from ..errors import ExportError
from ._common import (StagedFiles, check_output_path, fail, finite_float, is_elliptical,
                      label, principal_axes, writing)
from ..evaluation.metrics import brdf_metrics
from ..evaluation.render import to_evaluator
from ..evaluation.render._mitsuba import load
from ..evaluation.render.plugin import PLUGIN_NAME, register_evaluator
from ..io.fitfile import SerializableModel, save_fit
from ..io.tensorfile import write_tensor_file
from ..microfacet import Beckmann, GGX
from ..microfacet.fresnel import ConductorFresnel, DielectricFresnel
from ..microfacet.model import MicrofacetBRDF, SumBRDF
from ..microfacet.sgd_model import PerChannelMicrofacetBRDF
from ..paths import slug
from . import rgl as _rgl

__all__ = ["fit_conductor_fresnel", "builtin_terms", "builtin_bsdf", "mitsuba_equivalent",
           "mitsuba_error", "mitsuba_eval", "mitsuba_eval_error", "plastic_bsdf", "to_xml", "scene_xml", "plugin_bsdf", "mitsuba_bsdf",
           "example_scene_dict", "write_mitsuba_xml", "write_mitsuba_python", "LLVM_PATH",
           "py_literal", "xml_comment"]

LLVM_PATH = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"


# ------------------------------------------------------------------------------------------
# Fresnel → conductor (η, k) and scale
# ------------------------------------------------------------------------------------------
def fit_conductor_fresnel(fresnel, n: int = 90, weight_power: float = 4.0) -> dict:
    """Per-channel ``(η, k, s)`` with ``s · F_conductor(θd; η + ik) ≈ F(θd)`` (least squares
    on ``n`` uniform θd in [0, π/2) weighted by ``cos^weight_power θd``, η, k in log space, s
    in closed form given η, k). The weights favour small θd, where most reflected energy is:
    fitted tables are residual functions that often blow up at grazing θd (on the synthetic
    fits, power 4 gave the lowest BRDF-space error of 0, 1, 2, 4, 8; bench_export).

    Returns ``{"eta": [3], "k": [3], "scale": [3], "max_abs": float, "rms": float,
    "exact": bool}``; exact mappings (conductor, dielectric, ``None``) are not fitted.
    """
    from scipy import optimize

    if fresnel is None:
        return {"eta": None, "k": None, "scale": [1.0] * 3, "max_abs": 0.0, "rms": 0.0,
                "exact": True, "material": "none"}
    if isinstance(fresnel, ConductorFresnel):
        return {"eta": fresnel.eta.tolist(), "k": fresnel.k.tolist(), "scale": [1.0] * 3,
                "max_abs": 0.0, "rms": 0.0, "exact": True}
    if isinstance(fresnel, DielectricFresnel):
        return {"eta": fresnel.eta.tolist(), "k": [0.0] * 3, "scale": [1.0] * 3,
                "max_abs": 0.0, "rms": 0.0, "exact": True}
    theta = (np.arange(n) + 0.5) * (np.pi / 2 / n)
    c = np.cos(theta)
    target = np.asarray(fresnel.eval(c), dtype=np.float64)          # (n, 3)
    eta, kk, scale = np.zeros(3), np.zeros(3), np.zeros(3)

    def curve(q):
        return ConductorFresnel(np.exp(q[0]), np.exp(q[1])).eval(c)[:, 0]

    wt = np.sqrt(c ** weight_power)           # residual weights: cos^power θd (see docstring)

    def resid(q, y):
        f = curve(q) * wt
        s = max(float(f @ y) / max(float(f @ f), 1e-300), 0.0)
        return s * f - y

    for ch in range(3):
        y = target[:, ch] * wt
        best = None
        for e0, k0 in ((0.2, 3.0), (1.5, 0.01), (1.0, 1.0), (0.5, 8.0)):
            try:
                r = optimize.least_squares(resid, np.log([e0, k0]), args=(y,), method="trf",
                                           bounds=(np.log([1e-3, 1e-6]), np.log([50.0, 50.0])),
                                           xtol=1e-10, ftol=1e-12, max_nfev=200)
            except ValueError:
                continue
            if best is None or r.cost < best.cost:
                best = r
        f = curve(best.x) * wt
        scale[ch] = max(float(f @ y) / max(float(f @ f), 1e-300), 0.0)
        eta[ch], kk[ch] = np.exp(best.x)
    approx = scale * ConductorFresnel(eta, kk).eval(c)
    err = approx - target
    return {"eta": eta.tolist(), "k": kk.tolist(), "scale": scale.tolist(),
            "max_abs": float(np.max(np.abs(err))), "rms": float(np.sqrt(np.mean(err**2))),
            "exact": False}


# ------------------------------------------------------------------------------------------
# model → additive terms
# ------------------------------------------------------------------------------------------
def _lobe_terms(m, mask, notes) -> list[dict]:
    dist, fres = m.distribution, m.fresnel
    if not is_elliptical(dist):
        fail(m, "Mitsuba built-in plugins", f"distribution {type(dist).__name__} has no "
             "built-in equivalent (roughconductor supports ggx and beckmann); use the "
             "project's Python plugin ('--to mitsuba')")
    au, av, phi = principal_axes(dist.alpha_x, dist.alpha_y, dist.rho)
    ff = fit_conductor_fresnel(fres)
    ks = np.ones(3) if m.specular is None else np.asarray(m.specular, float)
    spec = np.asarray(ff["scale"]) * ks * mask
    if m.correlated:
        notes.add("height-correlated Smith G of the fit rendered with Mitsuba's uncorrelated "
                  "G1(i) G1(o)")
    if not ff["exact"]:
        notes.add(f"{type(fres).__name__} approximated by a conductor Fresnel (eta, k, scale "
                  f"per channel); max abs error of F {ff['max_abs']:.3g}")
    if phi != 0.0:
        notes.add(f"correlation rho={dist.rho:.4g}: principal roughnesses with the tangent frame "
                  f"rotated by {math.degrees(phi):.3f} deg about the normal")
    terms = [{"kind": "conductor", "distribution": dist.kind, "alpha_u": au, "alpha_v": av,
              "rotation": phi, "fresnel": ff, "spec": spec}]
    if m.diffuse is not None:
        terms.append({"kind": "diffuse", "rgb": np.asarray(m.diffuse, float) * mask})
    return terms


def builtin_terms(model) -> tuple[list[dict], list[str]]:
    """The additive terms (``roughconductor`` lobes and one ``diffuse``) of ``model`` and the
    notes on approximations; :class:`ExportError` when it has no built-in equivalent."""
    notes: set[str] = set()
    if isinstance(model, MicrofacetBRDF):
        terms = _lobe_terms(model, np.ones(3), notes)
    elif isinstance(model, SumBRDF):
        terms = []
        for c in model.components:
            if not isinstance(c, MicrofacetBRDF):
                fail(model, "Mitsuba built-in plugins", f"component {label(c)} is not a "
                     "MicrofacetBRDF")
            terms += _lobe_terms(c, np.ones(3), notes)
    elif isinstance(model, PerChannelMicrofacetBRDF):
        terms = []
        for ch, lobe in enumerate(model.lobes):
            terms += _lobe_terms(lobe, np.eye(3)[ch], notes)
    else:
        fail(model, "Mitsuba built-in plugins", "only GGX/Beckmann microfacet models (single, "
             "summed or per channel) map to roughconductor/diffuse; use the project's Python "
             "plugin ('--to mitsuba')")
    diff = [t for t in terms if t["kind"] == "diffuse"]
    terms = [t for t in terms if t["kind"] != "diffuse"]
    if diff:
        terms.append({"kind": "diffuse", "rgb": sum(t["rgb"] for t in diff)})
    return terms, sorted(notes)


def _rgb_tex(v) -> dict:
    return {"type": "srgb", "color": [float(x) for x in v], "unbounded": True}


def _term_dict(t, scale: float) -> dict:
    if t["kind"] == "diffuse":
        return {"type": "diffuse", "reflectance": _rgb_tex(scale * t["rgb"])}
    d = {"type": "roughconductor", "distribution": t["distribution"],
         "alpha_u": float(t["alpha_u"]), "alpha_v": float(t["alpha_v"]),
         "specular_reflectance": _rgb_tex(scale * t["spec"])}
    ff = t["fresnel"]
    if ff.get("material") == "none":
        d["material"] = "none"
    else:
        d["eta"] = _rgb_tex(ff["eta"])
        d["k"] = _rgb_tex(ff["k"])
    return d


def _tree(terms, scale: float) -> dict:
    if len(terms) == 1:
        return _term_dict(terms[0], scale)
    h = len(terms) // 2
    return {"type": "blendbsdf", "weight": 0.5,
            "bsdf_0": _tree(terms[:h], 2.0 * scale), "bsdf_1": _tree(terms[h:], 2.0 * scale)}


def builtin_bsdf(model) -> tuple[dict, dict]:
    """``(bsdf, info)``: a plain Mitsuba scene-dict BSDF of built-in plugins for ``model``
    (no Mitsuba objects inside: usable in ``mi.load_dict`` and convertible to XML) and the
    ``info`` on approximations (notes, Fresnel fits, frame rotation in degrees)."""
    terms, notes = builtin_terms(model)
    rot = [math.degrees(t["rotation"]) for t in terms if t["kind"] == "conductor"]
    info = {"notes": notes, "frame_rotation_deg": rot,
            "fresnel_fits": [t["fresnel"] for t in terms if t["kind"] == "conductor"]}
    return _tree(terms, 1.0), info


def mitsuba_equivalent(model, rotate: bool = False):
    """The library BRDF that Mitsuba renders for :func:`builtin_bsdf` (uncorrelated G,
    conductor Fresnel fits, principal roughnesses; with ``rotate`` the tangent frame is
    assumed rotated as reported, i.e. the correlation is kept)."""
    terms, _ = builtin_terms(model)
    comps = []
    src = _source_dists(model)
    for i, t in enumerate(t for t in terms if t["kind"] == "conductor"):
        cls = GGX if t["distribution"] == "ggx" else Beckmann
        dist = src[i] if rotate else cls(t["alpha_u"], t["alpha_v"], 0.0)
        ff = t["fresnel"]
        fres = None if ff.get("material") == "none" else ConductorFresnel(ff["eta"], ff["k"])
        comps.append(MicrofacetBRDF(dist, fres, specular=np.maximum(t["spec"], 0.0),
                                    correlated=False))
    diff = [t for t in terms if t["kind"] == "diffuse"]
    if diff:
        comps[0] = MicrofacetBRDF(comps[0].distribution, comps[0].fresnel, diff[0]["rgb"],
                                  specular=comps[0].specular, correlated=False)
    out = comps[0] if len(comps) == 1 else SumBRDF(comps)
    out.name = f"{getattr(model, 'name', 'model')}-mitsuba"
    return out


def _source_dists(model):
    if isinstance(model, SumBRDF):
        return [c.distribution for c in model.components]
    if isinstance(model, PerChannelMicrofacetBRDF):
        return [lobe.distribution for lobe in model.lobes]
    return [model.distribution]


def mitsuba_error(model, n_samples: int = 1 << 14) -> dict:
    """BRDF-space error of the built-in mapping: cosine-weighted relative error
    (:func:`brdffit.evaluation.metrics.brdf_metrics`) of :func:`mitsuba_equivalent` vs
    ``model``, without and with the frame rotation."""
    out = {"cos_rel_error": brdf_metrics(model, mitsuba_equivalent(model), n_samples,
                                         metrics=("cos_rel_error",))["cos_rel_error"]}
    if any(abs(r) > 0 for r in builtin_bsdf(model)[1]["frame_rotation_deg"]):
        out["cos_rel_error_rotated_frame"] = brdf_metrics(
            model, mitsuba_equivalent(model, rotate=True), n_samples,
            metrics=("cos_rel_error",))["cos_rel_error"]
    return out


# ------------------------------------------------------------------------------------------
# evaluation inside Mitsuba (any plugin dict) and the roughplastic mapping
# ------------------------------------------------------------------------------------------
def _pairs(n: int, seed: int):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2 * n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return v[:n], v[n:]


def mitsuba_eval(bsdf: dict, wi, wo) -> np.ndarray:
    """``f_r(wi, wo)`` (library convention: ``wi`` light, ``wo`` viewer, no cosine) of a
    Mitsuba plugin dict, evaluated by Mitsuba itself (``BSDF.eval / cos θ(wi)``)."""
    mi, dr = load()
    obj = mi.load_dict(bsdf)
    wi = np.asarray(wi, float)
    wo = np.asarray(wo, float)
    n = wi.shape[0]
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.wi = mi.Vector3f(wo[:, 0], wo[:, 1], wo[:, 2])
    val = np.array(obj.eval(mi.BSDFContext(), si, mi.Vector3f(wi[:, 0], wi[:, 1], wi[:, 2])))
    val = val.T if val.shape == (3, n) else val
    return val / np.maximum(wi[:, 2:3], 1e-12)


def mitsuba_eval_error(model, bsdf: dict, n: int = 1 << 13, seed: int = 0) -> dict:
    """Cosine-weighted relative L1 error ``Σ|Δf| cos θo / Σ f cos θo`` of a Mitsuba plugin
    dict (evaluated by Mitsuba) against ``model`` on ``n`` random direction pairs."""
    wi, wo = _pairs(n, seed)
    ref = np.asarray(model.eval(wi, wo), float) * wo[:, 2:3]
    got = mitsuba_eval(bsdf, wi, wo) * wo[:, 2:3]
    return {"cos_rel_error": float(np.abs(got - ref).sum() / max(np.abs(ref).sum(), 1e-300)),
            "n": int(n)}


def plastic_bsdf(model, n: int = 4096) -> tuple[dict, dict]:
    """``(bsdf, info)``: Mitsuba's ``roughplastic`` for an isotropic GGX/Beckmann
    ``MicrofacetBRDF`` (with or without ρd). **Approximate and needs Mitsuba:** roughplastic
    has a scalar dielectric Fresnel (``int_ior``) and an energy-coupled diffuse term
    (``(1 − T(θi))(1 − T(θo))`` with Mitsuba's rough-dielectric transmittance tables), so

    * ``int_ior`` = η of a :class:`DielectricFresnel` (channel mean), else from the luminance
      of F0, ``η = (1 + √F0)/(1 − √F0)``; ``specular_reflectance`` = per-channel least-squares
      scale of the dielectric curve to the fit's Fresnel (cos⁴θd weights);
    * ``diffuse_reflectance`` = per-channel least squares of Mitsuba's own diffuse response
      (evaluated with Mitsuba at ``n`` direction pairs; it is linear in the reflectance) to
      the fit's ρd/π, clipped to [0, 1].

    The error (evaluated in Mitsuba) is in ``info["error"]``.
    """
    m = model
    if not (microfacet_ok := (is_elliptical(getattr(m, "distribution", None))
                              and m.distribution.isotropic)):
        fail(model, "Mitsuba roughplastic", "an isotropic GGX/Beckmann MicrofacetBRDF "
             "(roughplastic has a single alpha)")
    del microfacet_ok
    dist, fres = m.distribution, m.fresnel
    ks = np.ones(3) if m.specular is None else np.asarray(m.specular, float)
    theta = (np.arange(90) + 0.5) * (np.pi / 180)
    c = np.cos(theta)
    if isinstance(fres, DielectricFresnel):
        eta = float(np.mean(fres.eta))
    else:
        F0 = float(np.clip(np.asarray(fres.eval(1.0) if fres is not None else np.ones(3)) @
                           np.array([0.2126, 0.7152, 0.0722]), 1e-4, 0.95))
        eta = float((1 + np.sqrt(F0)) / (1 - np.sqrt(F0)))
    eta = max(eta, 1.0 + 1e-3)
    fd = DielectricFresnel(eta).eval(c)[:, 0]
    target = np.ones((90, 3)) if fres is None else np.asarray(fres.eval(c), float)
    w = c**4
    spec_scale = np.array([float((w * fd) @ target[:, k] / max(float((w * fd) @ fd), 1e-300))
                           for k in range(3)]) * ks
    base = {"type": "roughplastic", "distribution": dist.kind, "alpha": float(dist.alpha_x),
            "int_ior": eta, "ext_ior": 1.0, "nonlinear": False,
            "specular_reflectance": _rgb_tex(spec_scale)}
    wi, wo = _pairs(n, 1)
    zero = mitsuba_eval(dict(base, diffuse_reflectance=_rgb_tex([0.0] * 3)), wi, wo)
    one = mitsuba_eval(dict(base, diffuse_reflectance=_rgb_tex([1.0] * 3)), wi, wo)
    g = (one - zero) * wo[:, 2:3]                                    # diffuse response, ρ' = 1
    rd = np.zeros(3) if m.diffuse is None else np.asarray(m.diffuse, float)
    want = (np.asarray(m.eval(wi, wo), float) - zero) * wo[:, 2:3]
    rho = np.clip([(g[:, k] @ want[:, k]) / max(g[:, k] @ g[:, k], 1e-300) for k in range(3)],
                  0.0, 1.0) if np.any(rd > 0) else np.zeros(3)
    bsdf = dict(base, diffuse_reflectance=_rgb_tex(rho))
    notes = [f"roughplastic: scalar int_ior={eta:.4g}, Fresnel scale per channel "
             f"{np.round(spec_scale, 4).tolist()}, diffuse_reflectance fitted to rho_d/pi "
             "through Mitsuba's energy-coupled diffuse term"]
    if m.correlated:
        notes.append("height-correlated Smith G of the fit rendered with Mitsuba's uncorrelated "
                     "G1(i) G1(o)")
    return bsdf, {"notes": notes, "error": mitsuba_eval_error(model, bsdf),
                  "frame_rotation_deg": [0.0]}


# ------------------------------------------------------------------------------------------
# XML
# ------------------------------------------------------------------------------------------
_BSDF_TYPES = {"diffuse", "roughconductor", "blendbsdf", "roughplastic", "roughdielectric",
               "twosided", "measured"}


def _fmt(x) -> str:
    return repr(finite_float(x, "in a Mitsuba scene"))


# characters XML 1.0 cannot hold at all (not even escaped)
_XML_BAD = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def _xml_attr(v, what: str) -> str:
    """``quoteattr`` of a string, refusing characters that XML 1.0 cannot represent."""
    v = str(v)
    bad = _XML_BAD.search(v)
    if bad:
        raise ExportError(f"cannot write {what} = {v!r} as XML: it contains "
                          f"U+{ord(bad.group()):04X}, which XML cannot represent")
    return quoteattr(v)


def xml_comment(text: str) -> str:
    """``<!-- text -->`` that cannot end early or be malformed: characters XML cannot hold are
    written as ``\\uXXXX`` and every ``--`` is broken up (``- -``)."""
    text = _XML_BAD.sub(lambda m: f"\\u{ord(m.group()):04x}", str(text))
    text = re.sub("-(?=-)", "- ", text)
    return f"<!-- {text} -->"          # the spaces keep a leading/trailing '-' off '--'



def to_xml(d: dict, name: str | None = None, indent: int = 0) -> str:
    """Mitsuba 3 XML of a plain plugin dict (``type`` + properties; srgb textures, floats,
    strings, booleans and nested plugins)."""
    pad = "    " * indent
    typ = d["type"]
    if typ == "srgb":
        tag = "texture"
    elif typ in _BSDF_TYPES:
        tag = "bsdf"
    else:
        tag = {"sphere": "shape", "rectangle": "shape", "constant": "emitter", "point": "emitter",
               "perspective": "sensor", "hdrfilm": "film", "independent": "sampler",
               "path": "integrator", "direct": "integrator"}.get(typ, "bsdf")
    attrs = f" type={_xml_attr(typ, 'type')}" + (f" name={_xml_attr(name, 'name')}" if name else "")
    lines = [f"{pad}<{tag}{attrs}>"]
    for k, v in d.items():
        if k == "type":
            continue
        p = "    " * (indent + 1)
        if k == "color" and typ == "srgb":
            lines.append(f'{p}<rgb name="color" value="{", ".join(_fmt(x) for x in v)}"/>')
        elif isinstance(v, dict):
            child_name = None if k.startswith(("bsdf_", "film", "sampler", "rfilter")) else k
            lines.append(to_xml(v, child_name, indent + 1))
        elif isinstance(v, bool):
            lines.append(f'{p}<boolean name={_xml_attr(k, "name")} value="{str(v).lower()}"/>')
        elif isinstance(v, (int, np.integer)):
            lines.append(f'{p}<integer name={_xml_attr(k, "name")} value="{int(v)}"/>')
        elif isinstance(v, (float, np.floating)):
            lines.append(f'{p}<float name={_xml_attr(k, "name")} value="{_fmt(v)}"/>')
        elif isinstance(v, str):
            lines.append(f'{p}<string name={_xml_attr(k, "name")} value={_xml_attr(v, k)}/>')
        elif k == "rgb_value":
            lines.append(f'{p}<rgb name="radiance" value="{", ".join(_fmt(x) for x in v)}"/>')
        else:
            raise ExportError(f"cannot write property {k!r} = {v!r} of a {typ} plugin as XML")
    lines.append(f"{pad}</{tag}>")
    return "\n".join(lines)


def _count(v, what: str) -> int:
    """A positive integer option (resolution, samples per pixel) or a one-line error."""
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 < int(v) <= 1 << 20:
        raise ExportError(f"expected {what} to be a positive integer (at most 2^20), found {v!r}")
    return int(v)


def scene_xml(bsdf: dict, comment: str = "", resolution: int = 256, spp: int = 64) -> str:
    """A ready-to-render Mitsuba 3 XML scene: the BSDF (``id="material"``) on a sphere under a
    constant environment and a point light, path tracer, perspective camera."""
    body = to_xml(bsdf, None, 1).replace("<bsdf ", '<bsdf id="material" ', 1)
    cmt = xml_comment(comment) + "\n" if comment else ""
    return f"""<?xml version="1.0" encoding="utf-8"?>
{cmt}<scene version="3.0.0">
    <default name="spp" value="{_count(spp, 'spp')}"/>
    <default name="res" value="{_count(resolution, 'resolution')}"/>
    <integrator type="path"><integer name="max_depth" value="4"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="30"/>
        <transform name="to_world"><lookat origin="0, 0, 4.2" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="$res"/>
            <rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
    </sensor>
{body}
    <shape type="sphere"><ref id="material"/></shape>
    <emitter type="constant"><rgb name="radiance" value="0.3, 0.3, 0.3"/></emitter>
    <emitter type="point"><point name="position" x="3" y="3.5" z="4"/>
        <rgb name="intensity" value="40, 40, 40"/></emitter>
</scene>
"""


# ------------------------------------------------------------------------------------------
# live dicts (need Mitsuba)
# ------------------------------------------------------------------------------------------
def plugin_bsdf(model) -> dict:
    """``{"type": "brdffit", "evaluator_id": key}``: the project's plugin with ``model``'s
    Dr.Jit evaluator registered in this process (:mod:`brdffit.evaluation.render.plugin`)."""
    try:
        ev = to_evaluator(model)
    except Exception as exc:  # noqa: BLE001 - report as an export error
        raise ExportError(f"cannot export {label(model)} to the brdffit Mitsuba plugin: "
                          f"no Dr.Jit evaluator ({type(exc).__name__}: {exc})") from exc
    return {"type": PLUGIN_NAME, "evaluator_id": register_evaluator(ev)}


def mitsuba_bsdf(model, prefer: str = "builtin") -> dict:
    """A BSDF for ``mi.load_dict``: built-in plugins when the model maps to them (``prefer``
    = ``"builtin"``), else (or with ``prefer="plugin"``) the project's plugin."""
    if prefer == "builtin":
        try:
            return builtin_bsdf(model)[0]
        except ExportError:
            pass
    return plugin_bsdf(model)


def example_scene_dict(bsdf: dict, resolution: int = 64, spp: int = 16) -> dict:
    """The scene of :func:`scene_xml` as a dict for ``mi.load_dict`` (needs Mitsuba)."""
    mi, _ = load()
    return {"type": "scene",
            "integrator": {"type": "path", "max_depth": 4},
            "sensor": {"type": "perspective", "fov": 30.0,
                       "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4.2],
                                                                  target=[0, 0, 0], up=[0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": int(resolution),
                                "height": int(resolution), "rfilter": {"type": "box"}},
                       "sampler": {"type": "independent", "sample_count": int(spp)}},
            "object": {"type": "sphere", "bsdf": bsdf},
            "ambient": {"type": "constant", "radiance": {"type": "rgb", "value": [0.3] * 3}},
            "light": {"type": "point", "position": [3.0, 3.5, 4.0],
                      "intensity": {"type": "rgb", "value": [40.0] * 3}}}


# ------------------------------------------------------------------------------------------
# files
# ------------------------------------------------------------------------------------------
def write_mitsuba_xml(model, path, resolution: int = 256, spp: int = 64,
                      style: str = "auto", **_ignored) -> dict:
    """Write a ready-to-render XML scene that a plain Mitsuba 3 install loads (no brdffit).

    ``style``:

    * ``"conductor"`` – built-in plugins (roughconductor/diffuse/blendbsdf), exact up to the
      documented approximations; :class:`ExportError` for models without such a mapping;
    * ``"plastic"`` – :func:`plastic_bsdf`;
    * ``"measured"`` – an RGL tensor file (:mod:`.rgl`, Dupuy & Jakob 2018 layout) written
      next to the XML as ``<slug of the XML stem>.bsdf`` and read by Mitsuba's stock
      ``measured`` plugin: any model (tabulated, per-channel SGD, NPF variants; anisotropic
      models with ``phi_i`` slices, see :mod:`.rgl`);
    * ``"auto"`` (default) – ``"conductor"`` where the model maps to built-in plugins, else
      ``"measured"``.

    The XML and the tensor file are written as a whole (:class:`._common.StagedFiles`).
    """
    check_output_path(path)
    _count(resolution, "resolution")
    _count(spp, "spp")
    if style not in ("auto", "conductor", "plastic", "measured"):
        raise ExportError(f"unknown Mitsuba style {style!r}; expected 'auto', 'conductor', "
                          "'plastic' or 'measured'")
    tensor = None
    if style == "plastic":
        bsdf, info = plastic_bsdf(model)
        err = info.pop("error")
    elif style == "conductor":
        bsdf, info = builtin_bsdf(model)
        err = mitsuba_error(model)
    else:
        try:
            if style == "measured":
                raise ExportError("measured requested")
            bsdf, info = builtin_bsdf(model)
            err = mitsuba_error(model)
        except ExportError:
            path = check_output_path(path)
            tensor = path.with_name(slug(path.stem) + ".bsdf")
            bsdf = {"type": "measured", "filename": tensor.name}
            info = {"notes": ["RGL tensor file for Mitsuba's measured plugin (resampled)"]}
    if tensor is None:
        comment = (f"brdffit export of {label(model)}; alpha = slope-scale roughness (Mitsuba's "
                   f"alpha); notes: {'; '.join(info['notes']) or 'exact'}; "
                   f"cosine-weighted relative error vs the fit: {err['cos_rel_error']:.4g}")
        data = scene_xml(bsdf, comment, resolution, spp).encode("utf-8")   # as declared
        path = check_output_path(path)
        with writing(path), atomic_write(path, "wb") as fh:
            fh.write(data)
        return {"files": [str(path)], "target": "mitsuba-xml", **info, "error": err}
    fields = _rgl.rgl_fields(model)
    n_phi, red = int(fields["phi_i"].size), _rgl.phi_i_reduction(fields["phi_i"])
    info.update(phi_i_slices=n_phi, reduction=red)
    if n_phi > 1:
        info["notes"].append(f"anisotropic: {n_phi} phi_i slices over 2pi/{red}")
    with StagedFiles(path) as staged:
        tmp = staged.path(tensor)
        with writing(tensor):
            write_tensor_file(tmp, fields)
        err = _rgl.rgl_error(model, tmp)  # looked up at call time
        comment = (f"brdffit export of {label(model)} as an RGL tensor file for Mitsuba's "
                   f"measured plugin; cosine-weighted relative error vs the fit: "
                   f"{err['cos_rel_error']:.4g}")
        with staged.open(path) as fh:
            fh.write(scene_xml(bsdf, comment, resolution, spp).encode("utf-8"))
    return {"files": [str(tensor), str(path)], "target": "mitsuba-xml", **info, "error": err}


_SCRIPT = '''"""Ready-to-render Mitsuba 3 scene exported by brdffit (the model: EXPORTED, MATERIAL).

Run: python <this script>  [out.exr]   (needs mitsuba 3 + llvm; {how})
Conventions: alpha = slope-scale roughness (Mitsuba's alpha); RGB = the source's linear RGB.
"""
import os
import sys
from pathlib import Path

EXPORTED = {exported}
MATERIAL = {material}
FIT_FILE = {fit_file}
OUTPUT_NAME = {output_name}

os.environ.setdefault("DRJIT_LIBLLVM_PATH", {llvm})
import mitsuba as mi  # noqa: E402

mi.set_variant("llvm_ad_rgb")
HERE = Path(__file__).resolve().parent
{bsdf_code}

def scene_dict(resolution=256, spp=64):
    return {{"type": "scene",
            "integrator": {{"type": "path", "max_depth": 4}},
            "sensor": {{"type": "perspective", "fov": 30.0,
                       "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4.2], target=[0, 0, 0],
                                                                  up=[0, 1, 0]),
                       "film": {{"type": "hdrfilm", "width": resolution, "height": resolution,
                                "rfilter": {{"type": "box"}}}},
                       "sampler": {{"type": "independent", "sample_count": spp}}}},
            "object": {{"type": "sphere", "bsdf": BSDF}},
            "ambient": {{"type": "constant", "radiance": {{"type": "rgb", "value": [0.3] * 3}}}},
            "light": {{"type": "point", "position": [3.0, 3.5, 4.0],
                      "intensity": {{"type": "rgb", "value": [40.0] * 3}}}}}}


if __name__ == "__main__":
    out = sys.argv[1] if len(sys.argv) > 1 else str(HERE / OUTPUT_NAME)
    image = mi.render(mi.load_dict(scene_dict()))
    mi.util.write_bitmap(out, image)
    print("wrote", out)
'''


def py_literal(obj, indent: int = 0) -> str:
    """Python source of a plain value (dict with string keys, list, str, finite float, int,
    bool, None): strings as ``ascii()`` literals, so no value can become code."""
    pad = "    " * (indent + 1)
    if obj is None or isinstance(obj, (bool, np.bool_)):
        return repr(None if obj is None else bool(obj))
    if isinstance(obj, (int, np.integer)):
        return repr(int(obj))
    if isinstance(obj, (float, np.floating)):
        return _fmt(obj)
    if isinstance(obj, str):
        return ascii(obj)
    if isinstance(obj, dict):
        items = []
        for k, v in obj.items():
            if not isinstance(k, str):
                raise ExportError(f"cannot write the key {k!r} in a Python scene; expected str")
            items.append(f"{pad}{ascii(k)}: {py_literal(v, indent + 1)},")
        return "{\n" + "\n".join(items) + "\n" + "    " * indent + "}" if items else "{}"
    if isinstance(obj, (list, tuple, np.ndarray)):
        return "[" + ", ".join(py_literal(v, indent + 1) for v in obj) + "]"
    raise ExportError(f"cannot write a {type(obj).__name__} value in a Python scene")


def write_mitsuba_python(model, path, prefer: str = "builtin", **_ignored) -> dict:
    """Write a ready-to-render Python scene script (``path``, ``.py``).

    Built-in mapping when available (``prefer="builtin"``; the BSDF dict is inlined, no
    brdffit needed to render); otherwise the fit is saved next to it
    (``<stem>.fit.npz``, :func:`brdffit.io.fitfile.save_fit`) and the script loads it and
    uses the project's ``brdffit`` plugin. Both files are written as a whole (nothing is left
    on an error) and names reach the script only as string literals.
    """
    path = check_output_path(path)
    stem = path.stem
    summary: dict = {"target": "mitsuba"}
    bsdf = None
    if prefer == "builtin":
        try:
            bsdf, info = builtin_bsdf(model)
            summary.update(info, error=mitsuba_error(model), plugin="builtin")
        except ExportError as exc:
            summary["builtin_unavailable"] = str(exc)
    elif prefer != "plugin":
        raise ExportError(f"expected prefer='builtin' or 'plugin', found {prefer!r}")
    name = getattr(model, "name", None)
    fit_path = None
    if bsdf is not None:
        code = "BSDF = " + py_literal(bsdf) + "\n"
        how = "built-in plugins only"
    else:
        if not isinstance(model, SerializableModel) or not model.fit_kind:
            fail(model, "the brdffit Mitsuba plugin", "a serialisable fit (save_fit) so that "
                 "the script can load it")
        fit_path = path.with_name(f"{stem}.fit.npz")
        code = (
            "from brdffit.evaluation.render import to_evaluator  # noqa: E402\n"
            "from brdffit.evaluation.render.plugin import register_evaluator  # noqa: E402\n"
            "from brdffit.io.fitfile import load_fit  # noqa: E402\n\n"
            "MODEL = load_fit(HERE / FIT_FILE)\n"
            "BSDF = {\"type\": \"brdffit\", \"evaluator_id\": register_evaluator(to_evaluator(MODEL))}\n")
        how = "the brdffit package for its Python BSDF plugin"
        summary["plugin"] = "brdffit"
    text = _SCRIPT.format(exported=ascii(label(model)),
                          material=ascii(None if name is None else str(name)),
                          fit_file=ascii(None if fit_path is None else fit_path.name),
                          output_name=ascii(f"{stem}.exr"), how=how, llvm=ascii(LLVM_PATH),
                          bsdf_code=code)
    files = [str(path)]
    with StagedFiles(path) as staged:
        if fit_path is not None:
            tmp = staged.path(fit_path)
            with writing(fit_path):
                save_fit(model, tmp)
            files.append(str(fit_path))
        with staged.open(path, "wb") as fh:
            fh.write(text.encode("ascii"))
    summary["files"] = files
    return summary
