"""The per-channel Cook-Torrance model of Bagher 2012 (brdffit.microfacet.sgd_model)."""

from __future__ import annotations

from brdffit.microfacet.beckmann import Beckmann
from brdffit.microfacet.ggx import GGX
from brdffit.microfacet.sgd_model import PerChannelMicrofacetBRDF


def test_sampling_chi_square_beckmann_ggx_lobes():
    from brdffit.testing.chi2 import check_sampling

    rows = [dict(rho_d=0.2, rho_s=0.5, F0=0.05, F1=0.0), dict(rho_d=0.1, rho_s=0.3, F0=0.5, F1=0.1),
            dict(rho_d=0.0, rho_s=0.8, F0=0.9, F1=0.0)]
    dists = [Beckmann(0.1), GGX(0.3), Beckmann(0.05)]
    model = PerChannelMicrofacetBRDF([{"distribution": d, **r} for d, r in zip(dists, rows)])
    ok, results = check_sampling(model, [[0, 0, 1], [0.8, 0.0, 0.6]], sample_count=50000,
                                 res_theta=24, res_phi=48)
    assert ok, [str(r) for r in results]
