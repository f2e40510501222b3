"""A zoo of the library's models for the furnace test (:mod:`brdffit.furnace`): :func:`model_zoo`
builds one model per sampler/translator at a given roughness (the tests and
``bench/bench_furnace.py`` run the furnace on each).
"""

from __future__ import annotations

import functools

import numpy as np
from ..microfacet import Beckmann, ConductorFresnel, GGX, MicrofacetBRDF, SchlickFresnel, SumBRDF
from ..microfacet.fresnel import GeneralizedSchlickFresnel
from ..microfacet.npf_model import (
    D_THETA_H, F_THETA_D, G_THETA, H_PHI_D, NPFBivariateBRDF, NPFMicrofacetBRDF, NPFNaiveBRDF,
)
from ..microfacet.per_channel import PerChannelBRDF
from ..microfacet.sgd import SGD
from ..microfacet.sgd_model import PerChannelMicrofacetBRDF
from ..microfacet.tabulated import TabulatedSlopeDistribution, radial_rule

__all__ = ["model_zoo"]


# -- a zoo of the library's models at a given roughness (tests and bench/bench_furnace.py) ----
def _ggx_slope_table(n: int = 90) -> np.ndarray:
    """Unit GGX slope pdf ``1/(π(1 + r²)²)`` on the MERL radial nodes (a tabulated fit)."""
    r = radial_rule(n, "merl")[2]
    return 1.0 / (np.pi * (1.0 + r * r) ** 2)


def _ggx_slope_table_2d(n: int = 40, n_phi: int = 40, ay: float = 0.5) -> np.ndarray:
    """Elliptical GGX slope pdf (αx, αy) = (1, ``ay``) on an anisotropic (θ, φ) table."""
    r = radial_rule(n, "merl")[2][:, None]
    phi = 2.0 * np.pi * np.arange(n_phi)[None, :] / n_phi
    q = (r * np.cos(phi)) ** 2 + (r * np.sin(phi) / ay) ** 2
    return 1.0 / (np.pi * ay * (1.0 + q) ** 2)


@functools.lru_cache(maxsize=1)
def _unit_tables():
    """The unit-roughness tabulated distributions of the zoo (shared by every α, so that
    their lazily built sampling tables are built once; the 2D table's visible-normal
    normaliser is built here, before ``with_roughness`` copies share it)."""
    iso = TabulatedSlopeDistribution(_ggx_slope_table())
    aniso = TabulatedSlopeDistribution(_ggx_slope_table_2d())
    n = np.array([0.0, 0.0, 1.0])
    iso.pdf_visible(n, n)         # builds the sampler's normaliser tables
    aniso.pdf_visible(n, n)
    return iso, aniso


def model_zoo(alpha: float) -> dict:
    """The library's BRDF models with (main) lobe roughness ``alpha``, one per render
    translator / sampler: name → BRDF.

    ``ggx`` (closed form, Schlick, diffuse), ``beckmann`` (closed form, conductor Fresnel →
    table Fresnel), ``ggx-aniso``/``beckmann-aniso`` (αy = 2α capped at 1, ρ ≠ 0), ``sgd``
    (SGD(α, 0.84) radial table, generalised Schlick, diffuse), ``tabulated`` (tabulated slope
    pdf of Dupuy 2015 scaled by α), ``tabulated-aniso`` (a 2D table: elliptical GGX (1, 0.5)
    scaled by α, rendered through the generic 4D table), ``sum`` (GGX α + GGX min(10α, 1) +
    diffuse),
    ``per-channel-sgd`` (Bagher 2012 lobes of widths R α, G 0.05, B 0.5),
    ``per-channel-tabulated`` (tabulated fits R α, G 0.05, B 0.5), ``npf``, ``npf-naive``,
    ``npf-bivariate`` (Bagher 2016 tables of a GGX α lobe).
    """
    a = float(alpha)
    a2 = min(2.0 * a, 1.0)
    widths = (a, 0.05, 0.5)
    tab, tab2d = _unit_tables()
    gold = ConductorFresnel([0.143, 0.374, 1.442], [3.983, 2.386, 1.603])
    out = {
        "ggx": MicrofacetBRDF(GGX(a), SchlickFresnel([0.9, 0.6, 0.3]), diffuse=[0.1, 0.1, 0.2]),
        "beckmann": MicrofacetBRDF(Beckmann(a), gold),
        "ggx-aniso": MicrofacetBRDF(GGX(a, a2, 0.3), None, diffuse=0.05),
        "beckmann-aniso": MicrofacetBRDF(Beckmann(a2, a, -0.4), SchlickFresnel(0.5)),
        "sgd": MicrofacetBRDF(SGD(a, 0.84), GeneralizedSchlickFresnel(0.9, -0.3),
                              diffuse=[0.2, 0.04, 0.03], specular=0.5),
        "tabulated": MicrofacetBRDF(tab.with_roughness(a), gold),
        "sum": SumBRDF([MicrofacetBRDF(GGX(a), None, specular=0.6),
                        MicrofacetBRDF(GGX(min(10.0 * a, 1.0)), SchlickFresnel([0.9, 0.5, 0.2]),
                                       diffuse=[0.05, 0.1, 0.1])]),
        "per-channel-sgd": PerChannelMicrofacetBRDF(
            [dict(distribution=SGD(w, 0.84), rho_d=d, rho_s=0.05, F0=1.0, F1=-0.3)
             for w, d in zip(widths, (0.2, 0.04, 0.03))]),
        "tabulated-aniso": MicrofacetBRDF(
            tab2d.with_roughness(a), None,
            diffuse=0.05),
        "per-channel-tabulated": PerChannelBRDF(
            [MicrofacetBRDF(tab.with_roughness(w), SchlickFresnel(0.8), diffuse=0.05)
             for w in widths]),
    }
    # NPF tables of a GGX α lobe (D on the MERL θh grid, F Schlick, G Smith GGX, H flat)
    ggx = GGX(a)
    m = np.stack([np.sin(D_THETA_H), 0.0 * D_THETA_H, np.cos(D_THETA_H)], -1)
    D = ggx.D(m)[:, None] * np.array([1.0, 0.8, 0.6]) / ggx.D(np.array([0.0, 0.0, 1.0]))
    F = (0.5 + 0.5 * (1.0 - np.cos(F_THETA_D)) ** 5)[:, None] * np.ones(3)
    wg = np.stack([np.sin(G_THETA), 0.0 * G_THETA, np.cos(G_THETA)], -1)
    G = ggx.G1(wg)[:, None] * np.ones(3)
    rho_s = np.array([0.3, 0.3, 0.3]) * float(ggx.D(np.array([0.0, 0.0, 1.0]))) / 4.0
    out["npf"] = NPFMicrofacetBRDF(D, F, G, [0.05, 0.04, 0.03], rho_s)
    H = (1.0 + 0.2 * np.cos(2.0 * H_PHI_D))[:, None] * np.ones(3)
    out["npf-naive"] = NPFNaiveBRDF(D, F, H, [0.05, 0.04, 0.03], rho_s)
    th, td = np.meshgrid(D_THETA_H, F_THETA_D, indexing="ij")
    B = (np.interp(th, D_THETA_H, D[:, 0])[..., None] * F[None, :, :] * rho_s
         / np.maximum(np.cos(th) ** 2, 1e-3)[..., None] + np.array([0.05, 0.04, 0.03]))
    out["npf-bivariate"] = NPFBivariateBRDF(B)
    for k, v in out.items():
        v.name = k
    return out
