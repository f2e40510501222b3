"""The coat of a coated diffuse model: a second, white specular lobe of index 1.5 (glTF's
clearcoat, OpenPBR's coat) over a ``MicrofacetBRDF`` base, the two held in a ``SumBRDF``.

:func:`coat_parts` recognises such a model, :func:`coat_alpha_weight` gives the figures of its
coat lobe; :func:`brdffit.fit.analytic.fit_analytic_diffuse` fits it (``coat=``).
"""

from __future__ import annotations

import numpy as np

from .fresnel import SchlickFresnel
from .model import MicrofacetBRDF, SumBRDF

__all__ = ["COAT_F0", "coat_parts", "coat_alpha_weight"]

#: normal reflectance of the coat: index 1.5, the fixed index of glTF's clearcoat
COAT_F0 = 0.04


def coat_parts(model):
    """``(base, coat)`` when ``model`` is a coated diffuse fit — a ``SumBRDF`` of a
    ``MicrofacetBRDF`` and a white coat lobe (Schlick F0 = ``COAT_F0``, no diffuse term, the
    same grey scale ``w`` ∈ [0, 1] on the three channels) — else ``None``."""
    comps = getattr(model, "components", None) if isinstance(model, SumBRDF) else None
    if not comps or len(comps) != 2 or not all(isinstance(c, MicrofacetBRDF) for c in comps):
        return None
    base, coat = comps
    f0 = np.asarray(getattr(coat.fresnel, "f0", np.nan), dtype=float)
    w = np.asarray(coat.specular if coat.specular is not None else 1.0, dtype=float)
    if (not isinstance(coat.fresnel, SchlickFresnel) or coat.diffuse is not None
            or not np.allclose(f0, COAT_F0, rtol=0, atol=1e-12)
            or not (np.ptp(w) <= 1e-12 and 0.0 <= float(np.max(w)) <= 1.0)):
        return None
    return base, coat


def coat_alpha_weight(coat) -> tuple[float, float]:
    """``(α, w)`` of the coat lobe of :func:`coat_parts`: its slope scale (√(αx αy), the
    fits' coat is isotropic) and its grey weight."""
    d = coat.distribution
    return float(np.sqrt(d.alpha_x * d.alpha_y)), float(np.max(coat.specular))
