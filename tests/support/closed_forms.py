"""Textbook closed forms written independently of the library's models, as references for
tests and benchmarks (never used by the code under test).

* Beckmann and GGX slope PDFs ``P22(r)`` of roughness α (Dupuy et al. 2015 Eq. 7 and
  Appendix; Walter et al. 2007) and their Smith Λ(θ) (Heitz 2014 Eq. 72 and 86).
* The backscattering of a white microfacet BRDF (Dupuy et al. 2015 Eq. 12 with F = 1):
  ``D(θ) G1(θ) / (4 cos²θ)`` with ``D = P22(tan θ)/cos⁴θ`` and ``G1 = 1/(1 + Λ)``.
"""

from __future__ import annotations

import numpy as np
from scipy.special import erf

__all__ = ["beckmann_P", "beckmann_lambda", "ggx_P", "ggx_lambda", "backscatter_eq12",
           "directions"]


def beckmann_P(r, a):
    return np.exp(-(r / a) ** 2) / (np.pi * a * a)


def beckmann_lambda(theta, a):
    t = np.tan(theta)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        nu = 1.0 / (a * t)
        lam = 0.5 * (erf(nu) - 1.0) + np.exp(-nu * nu) / (2.0 * nu * np.sqrt(np.pi))
    return np.where(t > 0, np.nan_to_num(lam, nan=0.0), 0.0)


def ggx_P(r, a):
    return 1.0 / (np.pi * a * a * (1.0 + (r / a) ** 2) ** 2)


def ggx_lambda(theta, a):
    t = np.tan(theta)
    return 0.5 * (-1.0 + np.sqrt(1.0 + (a * t) ** 2))


def backscatter_eq12(theta, a, kind: str = "beckmann"):
    """White backscattering ``D G1 / (4 cos²θ)`` of a Beckmann or GGX surface (Eq. 12)."""
    c = np.cos(theta)
    P, lam = (beckmann_P, beckmann_lambda) if kind == "beckmann" else (ggx_P, ggx_lambda)
    return P(np.tan(theta), a) / c**4 / (1.0 + lam(theta, a)) / (4.0 * c * c)


def directions(theta, phi=0.0):
    """Unit vectors of spherical angles (broadcast)."""
    theta, phi = np.broadcast_arrays(theta, phi)
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
