"""Physical validity of a fitted BRDF: what a renderer assumes of a material, checked.

:func:`check_validity` runs four checks on any BRDF of the library and returns one
:class:`Violation` per failed check (an empty list for a valid fit):

``fresnel``
    ``ks·F(θd) ≤ 1 + FRESNEL_TOLERANCE`` per channel for every lobe that defines a Fresnel term
    (:class:`~brdffit.microfacet.MicrofacetBRDF` and sums of them, per-channel lobes), on
    :data:`FRESNEL_NODES` values of cos θd in [0, 1]; for models that only report an F0
    (:func:`brdffit.fit.registry.figures`), that F0. A Fresnel reflectance above 1 creates
    energy at every angle; engines clamp F0 to [0, 1] and then draw another material.
``albedo``
    The directional albedo ``a(θi) = ∫ f cos θo dωo ≤ 1 + ALBEDO_TOLERANCE`` (the white
    furnace) at the incidences :data:`ALBEDO_ANGLES_DEG`, estimated by importance sampling
    with the model's own ``sample``/``pdf`` (:data:`ALBEDO_SAMPLES` stratified samples per
    angle) and flagged only when the excess exceeds three standard errors.
``non_negative``
    ``f ≥ 0`` on :data:`PAIRS` fixed quasi-random direction pairs (cosine distributed).
``reciprocity``
    ``|f(wi, wo) − f(wo, wi)| ≤ RECIPROCITY_TOLERANCE · (f(wi, wo) + f(wo, wi))/2`` on the same
    pairs (the relative difference of the largest channel, above 1 % of the pairs' median value).

Each violation names the check, the figure that broke it and what to do (e.g. a fit without
a diffuse term whose F0 exceeds 1 absorbed a diffuse base: ``--model ggx-diffuse``). The
same list is printed by ``brdffit fit`` (``warnings`` in ``--json``), written to the batch's
``summary.csv`` (``warnings``) and shown as a badge in the report.

>>> from brdffit.synthetic import synthetic
>>> check_validity(synthetic("gold-ggx"))
[]
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from ..brdf import cosine_pairs
from ..fit.registry import figures
from ..furnace import sampled_albedo

__all__ = ["Violation", "check_validity", "CHECKS", "ALBEDO_TOLERANCE", "ALBEDO_ANGLES_DEG"]

#: The checks, in the order they run.
CHECKS = ("fresnel", "albedo", "non_negative", "reciprocity")
FRESNEL_NODES = 257
#: F above 1 by less than this is a fit's rounding (a conductor fitted with ks = 1.00001).
FRESNEL_TOLERANCE = 1e-3
ALBEDO_ANGLES_DEG = (0.0, 30.0, 60.0, 75.0, 85.0)
ALBEDO_SAMPLES = 1 << 14
#: Albedo above 1 by less than this is within the estimate's own accuracy (1 %).
ALBEDO_TOLERANCE = 0.01
PAIRS = 4096
RECIPROCITY_TOLERANCE = 0.01
_CHANNELS = ("red", "green", "blue")


@dataclasses.dataclass(frozen=True)
class Violation:
    """A failed check: ``check`` (one of :data:`CHECKS`), the ``figure`` that broke it,
    ``message`` (one line) and ``advice`` (what to do; may be empty)."""

    check: str
    figure: float
    message: str
    advice: str = ""

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def _lobes(model, channel=None):
    """``(lobe, channel)`` for every lobe that defines a Fresnel (``channel``: the one
    colour channel a per-channel lobe stands for, else ``None``)."""
    if hasattr(model, "_fresnel") and hasattr(model, "distribution"):
        yield model, channel
        return
    components = getattr(model, "components", None)
    if isinstance(components, (list, tuple)):
        for c in components:
            yield from _lobes(c, channel)
        return
    for attr in ("lobes", "models"):
        members = getattr(model, attr, None)
        if isinstance(members, (list, tuple)) and len(members) == 3:
            for c, member in enumerate(members):
                yield from _lobes(member, c)
            return


def _has_diffuse(model) -> bool:
    for lobe, _ in _lobes(model):
        d = getattr(lobe, "diffuse", None)
        if d is not None and np.any(np.asarray(d) > 0):
            return True
    return False


def _fresnel(model) -> list[Violation]:
    cos_d = np.linspace(0.0, 1.0, FRESNEL_NODES)
    worst = (1.0, None, None)           # (value, channel, θd in degrees)
    found = False
    for lobe, channel in _lobes(model):
        found = True
        F = np.asarray(lobe._fresnel(cos_d), dtype=np.float64).reshape(FRESNEL_NODES, -1)
        F = np.broadcast_to(F, (FRESNEL_NODES, 3))
        cols = [channel] if channel is not None else range(3)
        for c in cols:
            k = int(np.argmax(F[:, c]))
            if F[k, c] > worst[0]:
                worst = (float(F[k, c]), c, math.degrees(math.acos(min(1.0, cos_d[k]))))
    if not found:
        try:
            f0 = figures(model).get("f0")
        except Exception:  # noqa: BLE001 – a model without figures has nothing to check here
            f0 = None
        for c, v in enumerate(f0 or ()):
            if v is not None and v > worst[0]:
                worst = (float(v), c, 0.0)
    value, c, theta = worst
    if c is None or value <= 1.0 + FRESNEL_TOLERANCE:
        return []
    advice = ("the specular lobe absorbed a diffuse base: fit it with --model ggx-diffuse "
              "(GGX + Lambert)") if not _has_diffuse(model) else (
              "the fit put energy in the Fresnel scale: an engine clamps F to 1 and renders "
              "the material darker")
    return [Violation("fresnel", value, f"F reaches {value:.3g} in {_CHANNELS[c]} at θd = "
                                        f"{theta:.0f}° (expected ≤ 1)", advice)]


def _albedo(model) -> list[Violation]:
    means, ses = sampled_albedo(model, np.radians(ALBEDO_ANGLES_DEG), ALBEDO_SAMPLES)
    worst = None
    for deg, a, se in zip(ALBEDO_ANGLES_DEG, means, ses):
        c = int(np.argmax(a - 3 * se))
        excess = a[c] - 3 * se[c] - (1.0 + ALBEDO_TOLERANCE)
        if excess > 0 and (worst is None or a[c] > worst[0]):
            worst = (float(a[c]), float(se[c]), c, deg)
    if worst is None:
        return []
    a, se, c, deg = worst
    advice = ("the fit reflects more than it receives; a fit with a diffuse term may not: "
              "--model ggx-diffuse") if not _has_diffuse(model) else (
              "the fit's diffuse and specular terms together reflect more than they receive "
              "(they are not energy-coupled); check the measurement's own albedo with "
              "brdffit info")
    return [Violation("albedo", a, f"directional albedo {a:.3g} ± {se:.2g} in {_CHANNELS[c]} at "
                                   f"θi = {deg:.0f}° (expected ≤ 1; the furnace, tolerance "
                                   f"{ALBEDO_TOLERANCE:g})", advice)]


def _values(model) -> list[Violation]:
    wi, wo = cosine_pairs(PAIRS)
    f = np.asarray(model.eval(wi, wo), dtype=np.float64)
    out = []
    low = float(np.min(f)) if f.size else 0.0
    if not np.all(np.isfinite(f)):
        out.append(Violation("non_negative", float("nan"), "the model gives non-finite values",
                             "refit; the fit file is damaged or the fit diverged"))
    elif low < -1e-9:
        out.append(Violation("non_negative", low, f"the model gives values down to {low:.3g} "
                                                  "(expected ≥ 0)",
                             "negative reflectance is clamped by engines: refit"))
    g = np.asarray(model.eval(wo, wi), dtype=np.float64)
    scale = max(float(np.median(np.abs(f))), 1e-12)
    both = 0.5 * (np.abs(f) + np.abs(g))
    rel = np.abs(f - g).max(-1) / np.maximum(both.max(-1), 0.01 * scale)
    worst = float(np.nanmax(rel)) if rel.size else 0.0
    if worst > RECIPROCITY_TOLERANCE:
        out.append(Violation("reciprocity", worst, f"f(wi, wo) and f(wo, wi) differ by up to "
                                                   f"{100 * worst:.3g} % (expected equal)",
                             "a path tracer needs a reciprocal BRDF: use a microfacet model"))
    return out


def check_validity(model, checks=CHECKS) -> list[Violation]:
    """The violations of ``model`` (module docstring), in the order of ``checks``."""
    out: list[Violation] = []
    if "fresnel" in checks:
        out += _fresnel(model)
    if "albedo" in checks:
        out += _albedo(model)
    if "non_negative" in checks or "reciprocity" in checks:
        out += [v for v in _values(model) if v.check in checks]
    return out
