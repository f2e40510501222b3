"""brdffit.furnace.sampled_albedo: the white furnace the physical checks and the ggx-diffuse
fit's ρd hold read."""

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
