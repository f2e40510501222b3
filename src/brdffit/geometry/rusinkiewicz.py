"""Rusinkiewicz (1998) half/difference parameterisation.

``h = normalize(wi + wo)``; the difference vector ``d`` is ``wi`` expressed in the frame of
``h``: rotate ``wi`` by ``-φh`` about the normal, then by ``-θh`` about the binormal (the MERL
convention, ``std_coords_to_half_diff_coords`` of the MERL reference code). ``wo`` is then the
reflection of ``d`` about the z axis in that frame.
"""

from __future__ import annotations

import numpy as np

from .frames import cartesian_to_spherical, normalize, spherical_to_cartesian

__all__ = ["io_to_half_diff", "half_diff_to_io"]


def _rot_z(v, angle):
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([c * x - s * y, s * x + c * y, z], axis=-1)


def _rot_y(v, angle):
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([c * x + s * z, y, -s * x + c * z], axis=-1)


def io_to_half_diff(wi, wo):
    """Return ``(θh, φh, θd, φd)`` for directions ``wi``, ``wo`` (shape ``(..., 3)``).

    θh, θd in [0, π/2] for directions above the horizon; φh, φd in [0, 2π). When
    ``wi = -wo`` the half vector is undefined and the normal is used.
    """
    wi = np.asarray(wi, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64)
    h = wi + wo
    degenerate = np.linalg.norm(h, axis=-1) < 1e-12
    h = np.where(degenerate[..., None], np.array([0.0, 0.0, 1.0]), normalize(h))
    theta_h, phi_h = cartesian_to_spherical(h)
    d = _rot_y(_rot_z(wi, -phi_h), -theta_h)
    theta_d, phi_d = cartesian_to_spherical(normalize(d))
    return theta_h, phi_h, theta_d, phi_d


def half_diff_to_io(theta_h, phi_h, theta_d, phi_d):
    """Inverse of :func:`io_to_half_diff`: return ``(wi, wo)`` unit vectors ``(..., 3)``.

    With a scalar ``φh = 0`` (how isotropic BRDFs are evaluated at Rusinkiewicz coordinates)
    the rotation about the normal is the identity and is skipped, and ``wo``'s rotation reuses
    ``wi``'s products: the same numbers, up to the sign of zero components."""
    if np.ndim(phi_h) == 0 and float(phi_h) == 0.0:
        theta_h, theta_d, phi_d = np.broadcast_arrays(
            *(np.asarray(a, dtype=np.float64) for a in (theta_h, theta_d, phi_d)))
        d = spherical_to_cartesian(theta_d, phi_d)
        x, y, z = d[..., 0], d[..., 1], d[..., 2]
        c, s = np.cos(theta_h), np.sin(theta_h)
        cx, sz, sx, cz = c * x, s * z, s * x, c * z   # rotation by θh about y (_rot_y)
        return (np.stack([cx + sz, y, -sx + cz], axis=-1),
                np.stack([-cx + sz, -y, sx + cz], axis=-1))
    theta_h, phi_h, theta_d, phi_d = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (theta_h, phi_h, theta_d, phi_d)))
    d = spherical_to_cartesian(theta_d, phi_d)
    d_reflected = d * np.array([-1.0, -1.0, 1.0])
    wi = _rot_z(_rot_y(d, theta_h), phi_h)
    wo = _rot_z(_rot_y(d_reflected, theta_h), phi_h)
    return wi, wo
