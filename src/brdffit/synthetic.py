"""Named synthetic materials: analytic BRDFs with known parameters for tests and the demo.

``synthetic(name)`` builds a fresh BRDF whose ``source`` is ``"synthetic:NAME"``;
``list_synthetic()`` lists the names; ``register_synthetic`` adds materials.

=====================  ===================================================================
name                   model
=====================  ===================================================================
``gold-ggx``           isotropic GGX α = 0.12, exact conductor Fresnel with gold's RGB
                       complex index (η, k)
``plastic-beckmann``   isotropic Beckmann α = 0.18, exact dielectric Fresnel η = 1.5,
                       red Lambertian base ρd = (0.45, 0.06, 0.04)
``aniso-ggx``          anisotropic GGX (αx, αy, ρ) = (0.06, 0.3, 0.45) — a rotated/sheared
                       brushed-metal lobe — with aluminium's conductor Fresnel
``sgd-paint``          SGD (Bagher 2012) α = 0.15, p = 1.2, generalised Schlick
                       (F0, F1) = (0.06, 0.02), blue diffuse base (needs
                       :mod:`brdffit.microfacet.sgd`)
``two-lobe-ggx``       sum of a sharp white GGX lobe (α = 0.04) and a broad copper-coloured
                       GGX lobe (α = 0.35): no single microfacet lobe fits it
=====================  ===================================================================

Parameters use the slope-scale α of Walter 2007 / Dupuy 2015 (not "roughness" √α).
The RGB complex indices are approximate linear-sRGB reductions of the spectral data commonly
used in renderers (gold: Johnson & Christy 1972; aluminium: Rakić 1995).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable

from .errors import BRDFError

if TYPE_CHECKING:
    from .brdf import BRDF

__all__ = ["synthetic", "list_synthetic", "register_synthetic", "describe_synthetic"]

_REGISTRY: dict[str, tuple[Callable[[], object], str]] = {}

ALUMINIUM_ETA = (1.65746, 0.880369, 0.521229)
ALUMINIUM_K = (9.22387, 6.26952, 4.837)


def register_synthetic(name: str, factory: Callable[[], object], description: str = "") -> None:
    """Add a named material: ``factory()`` returns a new BRDF."""
    _REGISTRY[str(name)] = (factory, description)


def list_synthetic() -> list[str]:
    """Names of the registered synthetic materials (sorted)."""
    return sorted(_REGISTRY)


def describe_synthetic() -> dict[str, str]:
    """``{name: one-line description}`` of the registered materials."""
    return {k: _REGISTRY[k][1] for k in sorted(_REGISTRY)}


def synthetic(name: str) -> BRDF:
    """A new instance of the synthetic material ``name`` (``source = "synthetic:NAME"``).

    Parameters
    ----------
    name : str
        One of :func:`list_synthetic` (``gold-ggx``, ``plastic-beckmann``, ``aniso-ggx``...).

    Returns
    -------
    BRDF
        The material, exactly known (the truth of recovery tests and the demo).

    >>> synthetic("gold-ggx").source
    'synthetic:gold-ggx'

    Raises :class:`~brdffit.errors.BRDFError` for an unknown name (listing the known ones)
    or when the material's model is unavailable.
    """
    if name not in _REGISTRY:
        raise BRDFError(f"unknown synthetic material {name!r}; available: "
                        f"{', '.join(list_synthetic())}")
    factory, _ = _REGISTRY[name]
    brdf = factory()
    brdf.name = name
    brdf.source = f"synthetic:{name}"
    return brdf


# -- built-in materials ----------------------------------------------------------------------
def _microfacet():
    """:mod:`brdffit.microfacet`, imported when the first material is built: ``import
    brdffit`` imports this module (and its names) without NumPy."""
    from . import microfacet

    return microfacet


def _gold_ggx():
    m = _microfacet()
    return m.MicrofacetBRDF(m.GGX(0.12), m.ConductorFresnel(m.fresnel.GOLD_ETA, m.fresnel.GOLD_K))


def _plastic_beckmann():
    m = _microfacet()
    return m.MicrofacetBRDF(m.Beckmann(0.18), m.DielectricFresnel(1.5),
                            diffuse=(0.45, 0.06, 0.04))


def _aniso_ggx():
    m = _microfacet()
    return m.MicrofacetBRDF(m.GGX(0.06, 0.3, rho=0.45),
                            m.ConductorFresnel(ALUMINIUM_ETA, ALUMINIUM_K))


def _sgd_paint():
    m = _microfacet()
    try:
        sgd = m.SGD
    except AttributeError as exc:  # brdffit.microfacet.sgd could not be imported
        raise BRDFError(f"synthetic material 'sgd-paint' needs the SGD distribution "
                        f"(brdffit.microfacet.sgd), which could not be imported: "
                        f"{exc.__cause__ or exc}") from exc
    return m.MicrofacetBRDF(sgd(0.15, 1.2), m.GeneralizedSchlickFresnel(0.06, 0.02),
                            diffuse=(0.04, 0.07, 0.30))


def _two_lobe():
    m = _microfacet()
    sharp = m.MicrofacetBRDF(m.GGX(0.04), m.SchlickFresnel(0.9), specular=0.35, name="sharp")
    broad = m.MicrofacetBRDF(m.GGX(0.35), m.SchlickFresnel((0.95, 0.64, 0.54)), specular=0.6,
                             name="broad")
    return m.SumBRDF([sharp, broad])


register_synthetic("gold-ggx", _gold_ggx, "isotropic GGX α=0.12, conductor Fresnel (gold)")
register_synthetic("plastic-beckmann", _plastic_beckmann,
                   "isotropic Beckmann α=0.18, dielectric Fresnel η=1.5, red diffuse base")
register_synthetic("aniso-ggx", _aniso_ggx,
                   "anisotropic GGX (αx, αy, ρ)=(0.06, 0.3, 0.45), conductor Fresnel (aluminium)")
register_synthetic("sgd-paint", _sgd_paint,
                   "SGD α=0.15 p=1.2, generalised Schlick (0.06, 0.02), blue diffuse base")
register_synthetic("two-lobe-ggx", _two_lobe,
                   "sharp white GGX α=0.04 + broad copper GGX α=0.35 (not fit by one lobe)")
