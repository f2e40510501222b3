"""Microfacet slope space (Dupuy et al. 2015, Eq. 5-6).

A normal ``m = (mx, my, mz)`` with ``mz > 0`` has slope ``(x̃, ỹ) = (-mx/mz, -my/mz)``
``= (-tan θ cos φ, -tan θ sin φ)``; the inverse is ``m = (-x̃, -ỹ, 1)/sqrt(x̃² + ỹ² + 1)``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["normal_to_slope", "slope_to_normal"]


def normal_to_slope(m) -> np.ndarray:
    """Slopes ``(..., 2)`` of upper-hemisphere normals ``(..., 3)`` (Dupuy 2015, Eq. 5)."""
    m = np.asarray(m, dtype=np.float64)
    mz = m[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack([-m[..., 0] / mz, -m[..., 1] / mz], axis=-1)


def slope_to_normal(s) -> np.ndarray:
    """Unit normals ``(..., 3)`` of slopes ``(..., 2)`` (Dupuy 2015, Eq. 6)."""
    s = np.asarray(s, dtype=np.float64)
    inv = 1.0 / np.sqrt(s[..., 0] ** 2 + s[..., 1] ** 2 + 1.0)
    return np.stack([-s[..., 0] * inv, -s[..., 1] * inv, inv], axis=-1)
