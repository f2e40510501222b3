"""Microfacet models: slope distributions, shadowing, Fresnel and ``MicrofacetBRDF``.

* :mod:`.base` – the abstract :class:`SlopeDistribution` and :class:`Fresnel` interfaces,
  roughness scaling of any distribution (Eq. 9).
* :mod:`.beckmann`, :mod:`.ggx` – anisotropic Beckmann and GGX with correlation ρ
  (Dupuy et al. 2015, App. C), closed-form Smith Λ and visible-normal sampling.
* ``SGD`` – the shifted gamma distribution (Bagher et al. 2012), imported lazily from
  :mod:`.sgd` (maintained separately).
* :mod:`.shadowing` – Smith G1 of any distribution by numerical integration of Dupuy Eq. 3.
* :mod:`.fresnel` – Schlick, generalised Schlick (Bagher 2012 Eq. 11), exact dielectric and
  conductor, tabulated.
* :mod:`.model` – :class:`MicrofacetBRDF` (Dupuy Eq. 1), :class:`SumBRDF`, and the component
  registry used by the fit files (``register_distribution`` / ``register_fresnel``).
* :mod:`.coat` – the white coat lobe of a coated diffuse model.
* :mod:`.per_channel` – three models, one per colour channel; :mod:`.sgd_model` – the
  per-channel Cook-Torrance model of Bagher 2012.
* :mod:`.conversions` – tabulated to Beckmann/GGX by slope moments (Dupuy App. C), roughness
  editing (Eq. 9).
"""

from __future__ import annotations

from .base import Fresnel, ScaledDistribution, SlopeDistribution
from .beckmann import Beckmann
from .fresnel import (ConductorFresnel, DielectricFresnel, GeneralizedSchlickFresnel,
                      SchlickFresnel, TabulatedFresnel)
from .ggx import GGX
from .model import (MicrofacetBRDF, SumBRDF, distribution_from_state, distribution_to_state,
                    fresnel_from_state, fresnel_to_state, register_distribution,
                    register_fresnel)
from .shadowing import (EllipticalSlopeDistribution, g1_numerical, lambda_numerical,
                        sigma_numerical)

__all__ = [
    "SlopeDistribution", "Fresnel", "EllipticalSlopeDistribution", "ScaledDistribution",
    "Beckmann", "GGX", "SGD",
    "SchlickFresnel", "GeneralizedSchlickFresnel", "DielectricFresnel", "ConductorFresnel",
    "TabulatedFresnel",
    "MicrofacetBRDF", "SumBRDF", "register_distribution", "register_fresnel",
    "distribution_to_state", "distribution_from_state", "fresnel_to_state", "fresnel_from_state",
    "sigma_numerical", "lambda_numerical", "g1_numerical",
]


def __getattr__(name):
    # SGD lives in .sgd, written separately; import lazily so this package works without it.
    if name == "SGD":
        from importlib import import_module

        try:
            mod = import_module(".sgd", __name__)
        except ImportError as exc:
            raise AttributeError(f"brdffit.microfacet.SGD is unavailable: could not import "
                                 f"brdffit.microfacet.sgd ({exc})") from exc
        return mod.SGD
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
