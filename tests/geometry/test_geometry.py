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


def test_half_diff_to_io_at_phi_h_zero_equals_the_general_rotation():
    """The φh = 0 shortcut (no rotation about the normal) gives the general path's numbers,
    including at θh = 0, θd = 0 and φd ∈ {0, π}."""
    from brdffit.geometry.rusinkiewicz import half_diff_to_io

    rng = np.random.default_rng(4)
    th, td, pd = rng.random(5000) * 1.6, rng.random(5000) * 1.6, rng.random(5000) * 6.3
    th[:50], td[50:100], pd[100:150], pd[150:200] = 0.0, 0.0, 0.0, np.pi
    fast = half_diff_to_io(th, 0.0, td, pd)
    general = half_diff_to_io(th, np.zeros_like(th), td, pd)
    for a, b in zip(fast, general):
        np.testing.assert_array_equal(a, b)
    wi, wo = half_diff_to_io(0.3, 0, 0.2, 1.0)  # scalars
    assert wi.shape == wo.shape == (3,)
