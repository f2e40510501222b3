import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from brdffit.geometry import (cartesian_to_spherical, half_diff_to_io, io_to_half_diff,
                              normal_to_slope, slope_to_normal, spherical_to_cartesian)
from tests.conftest import random_hemisphere


def test_spherical_round_trip(rng):
    v = random_hemisphere(rng, 1000)
    t, p = cartesian_to_spherical(v)
    np.testing.assert_allclose(spherical_to_cartesian(t, p), v, atol=1e-12)


def test_rusinkiewicz_round_trip(rng):
    wi = random_hemisphere(rng, 2000)
    wo = random_hemisphere(rng, 2000)
    th, ph, td, pd = io_to_half_diff(wi, wo)
    wi2, wo2 = half_diff_to_io(th, ph, td, pd)
    np.testing.assert_allclose(wi2, wi, atol=1e-9)
    np.testing.assert_allclose(wo2, wo, atol=1e-9)


def test_rusinkiewicz_known_configurations():
    # backscattering: wi = wo -> theta_d = 0, theta_h = theta
    w = spherical_to_cartesian(0.7, 1.1)
    th, ph, td, _ = io_to_half_diff(w, w)
    np.testing.assert_allclose([th, ph, td], [0.7, 1.1, 0.0], atol=1e-12)
    # mirror configuration: theta_h = 0, theta_d = theta
    wi = spherical_to_cartesian(0.4, 0.0)
    wo = spherical_to_cartesian(0.4, np.pi)
    th, _, td, _ = io_to_half_diff(wi, wo)
    np.testing.assert_allclose([th, td], [0.0, 0.4], atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(st.floats(-50, 50), st.floats(-50, 50))
def test_slope_round_trip(x, y):
    s = np.array([x, y])
    m = slope_to_normal(s)
    assert np.isclose(np.linalg.norm(m), 1.0)
    assert m[2] > 0
    np.testing.assert_allclose(normal_to_slope(m), s, rtol=1e-9, atol=1e-9)


def test_slope_matches_dupuy_eq5():
    theta, phi = 0.5, 2.0
    m = spherical_to_cartesian(theta, phi)
    np.testing.assert_allclose(normal_to_slope(m),
                               [-np.tan(theta) * np.cos(phi), -np.tan(theta) * np.sin(phi)])
