"""Spherical <-> Cartesian conversions in the local frame (normal = +z)."""

from __future__ import annotations

import numpy as np

__all__ = ["normalize", "spherical_to_cartesian", "cartesian_to_spherical", "cos_theta"]


def normalize(v: np.ndarray) -> np.ndarray:
    """Return ``v / |v|`` along the last axis (zero vectors stay zero)."""
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def spherical_to_cartesian(theta, phi) -> np.ndarray:
    """Unit vector ``(sin θ cos φ, sin θ sin φ, cos θ)``, shape ``broadcast(θ, φ) + (3,)``."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, np.float64), np.asarray(phi, np.float64))
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def cartesian_to_spherical(v) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(θ, φ)`` of unit vectors, θ in [0, π], φ in [0, 2π)."""
    v = np.asarray(v, dtype=np.float64)
    theta = np.arccos(np.clip(v[..., 2], -1.0, 1.0))
    phi = np.mod(np.arctan2(v[..., 1], v[..., 0]), 2.0 * np.pi)
    return theta, phi


def cos_theta(v) -> np.ndarray:
    """z component of unit vectors."""
    return np.asarray(v)[..., 2]
