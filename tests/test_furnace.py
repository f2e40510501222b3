"""brdffit.furnace: the white furnace the physical checks read (sampled_albedo) and the ρd
hold of the ggx-diffuse and tabulated fits (hold_diffuse)."""

from __future__ import annotations

import numpy as np

from brdffit.furnace import sampled_albedo
from tests.test_brdf import RHO, Lambert


class Singular(Lambert):
    """Infinite at one direction pair: the furnace must not lose it."""

    def eval(self, wi, wo):
        f = super().eval(wi, wo)
        return np.where((np.asarray(wo)[..., 2] > 0.999)[..., None], np.inf, f)


def test_sampled_albedo_of_a_lambertian_is_its_rho():
    a, se = sampled_albedo(Lambert(), np.radians([0.0, 45.0, 85.0]), n_samples=1024)
    np.testing.assert_allclose(a, np.broadcast_to(RHO, a.shape), rtol=1e-2)
    assert np.all(se < 0.01)


def test_an_infinite_value_fails_the_furnace_instead_of_vanishing():
    a, _ = sampled_albedo(Singular(), [0.0], n_samples=1 << 16)
    assert np.all(a > 1e20)


def test_hold_diffuse_lowers_rho_d_only_as_far_as_the_furnace_needs():
    from brdffit.furnace import hold_diffuse
    from brdffit.microfacet import GGX, MicrofacetBRDF

    lobe = MicrofacetBRDF(GGX(0.5))                        # F = 1: albedo ≈ 0.9 at normal
    spec = sampled_albedo(lobe, np.radians([0.0, 30.0, 45.0, 60.0, 70.0, 75.0, 80.0, 85.0, 88.0]),
                          4096)[0].max(axis=0)
    held, lowering = hold_diffuse([0.05, 0.5, 0.0], [lobe])
    np.testing.assert_allclose(held[1], 1.0 - spec[1], rtol=1e-12)
    assert held[0] == min(0.05, 1.0 - spec[0]) and held[2] == 0.0
    np.testing.assert_allclose(held + lowering, [0.05, 0.5, 0.0])
