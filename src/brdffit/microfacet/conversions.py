"""Conversions of a tabulated microfacet model (Dupuy, Heitz, Iehl, Poulin, Ostromoukhov 2015).

* Analytic roughness by slope moments (Appendix C): :func:`to_beckmann` and :func:`to_ggx`
  turn a tabulated ``MicrofacetBRDF`` into a Beckmann or GGX one with the same Fresnel and
  Lambertian ρd (held again by the white furnace under the new lobe), with the ``(αx, αy, ρ)``
  of the distribution's :meth:`~brdffit.microfacet.tabulated.TabulatedSlopeDistribution.beckmann_parameters` /
  :meth:`~brdffit.microfacet.tabulated.TabulatedSlopeDistribution.ggx_parameters`.
* Roughness editing (Eq. 9): :func:`with_roughness` scales the table by ``(αx, αy)``, scalars
  or per-texel arrays, without refitting.
"""

from __future__ import annotations

import numpy as np

from ..furnace import hold_diffuse
from .beckmann import Beckmann
from .ggx import GGX
from .model import MicrofacetBRDF
from .tabulated import TabulatedSlopeDistribution

__all__ = ["to_beckmann", "to_ggx", "with_roughness"]


def _parts(model):
    dist = getattr(model, "distribution", None)
    fres = getattr(model, "fresnel", None)
    if not isinstance(dist, TabulatedSlopeDistribution):
        raise TypeError(f"expected a tabulated microfacet model, got {type(model).__name__}")
    return dist, fres


def _analytic_model(model, kind):
    dist, fres = _parts(model)
    if kind == "beckmann":
        ax, ay, rho = dist.beckmann_parameters()
        d = Beckmann(ax, ay, rho)
    else:
        ax, ay, rho = dist.ggx_parameters()
        d = GGX(ax, ay, rho)
    out = MicrofacetBRDF(d, fres)
    lowered = None
    if getattr(model, "diffuse", None) is not None:   # held again under the converted lobe
        out.diffuse, lowered = hold_diffuse(model.diffuse, [out])
    for attr in ("name", "source"):
        try:
            setattr(out, attr, getattr(model, attr, None))
        except AttributeError:  # pragma: no cover
            pass
    info = dict(getattr(model, "fit_info", None) or {})
    info.update({"alpha_x": ax, "alpha_y": ay, "rho": rho, "converted_from": "tabulated"})
    if lowered is not None:
        info["rho_d_furnace_lowering"] = lowered.tolist()
    out.fit_info = info
    out.fit_options = dict(getattr(model, "fit_options", None) or {}, model=kind)
    return out


def with_roughness(model, alpha_x, alpha_y=None):
    """The fitted model with its table scaled by ``(αx, αy)`` (Eq. 9), without refitting.

    ``alpha_x``/``alpha_y`` may be arrays (per-texel roughness) that broadcast with the
    batch shape of the directions later given to ``eval``/``pdf``/``sample``. The Fresnel
    and every table are shared with ``model``.
    """
    dist, fres = _parts(model)
    out = MicrofacetBRDF(dist.with_roughness(alpha_x, alpha_y), fres,
                         getattr(model, "diffuse", None), name=model.name, source=model.source)
    out.fit_info = getattr(model, "fit_info", None)
    out.fit_options = getattr(model, "fit_options", None)
    return out


def to_beckmann(model):
    """Anisotropic Beckmann ``MicrofacetBRDF`` with the same Fresnel (Appendix C)."""
    return _analytic_model(model, "beckmann")


def to_ggx(model):
    """Anisotropic GGX ``MicrofacetBRDF`` with the same Fresnel (Appendix C)."""
    return _analytic_model(model, "ggx")
