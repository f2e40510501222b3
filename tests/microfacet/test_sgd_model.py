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


def test_lobe_weights_follow_the_peak_reflectance_of_eq11():
    """A channel with ρs → 0 and F1 ≪ 0 (ρs F = E cos θd, as Eq. 11 holds mirror-like MERL
    channels) has F(θd = 0) = F0 − F1 ≫ 1: its lobe is weighted by ρs·F(0), not ρs alone, and
    the mixture stays a density that the sampler follows."""
    import numpy as np

    from brdffit.testing.chi2 import check_sampling

    rows = [dict(rho_d=0.004, rho_s=2e-4, F0=1.0, F1=-422.0),
            dict(rho_d=0.003, rho_s=0.05, F0=0.9, F1=0.0),
            dict(rho_d=0.004, rho_s=0.002, F0=1.0, F1=-35.0)]
    model = PerChannelMicrofacetBRDF([{"distribution": GGX(0.2), **r} for r in rows])
    probs = model._lobe_probabilities()
    peaks = np.array([2e-4 * 423.0, 0.05 * 1.0, 0.002 * 36.0])
    np.testing.assert_allclose(probs, np.r_[0.011, peaks] / (0.011 + peaks.sum()), rtol=1e-12)
    assert probs[1] > 0.35                # ρs alone would give this lobe 0.3 %
    ok, results = check_sampling(model, [[0, 0, 1], [0.8, 0.0, 0.6]], sample_count=50000,
                                 res_theta=24, res_phi=48)
    assert ok, [str(r) for r in results]
