"""The anisotropic GGX (Trowbridge-Reitz) slope distribution with correlation ρ.

``P(s) = 1 / (π √|S| (1 + sᵀ S⁻¹ s)²)`` with ``S = [[αx², ραxαy], [ραxαy, αy²]]`` (Dupuy
2015 App. C; Walter et al. 2007 Eq. 33; Heitz 2014 Eq. 85 for ρ = 0). α is the slope scale
(Mitsuba's ``alpha``), not the perceptual roughness ``√α``.

* NDF: ``D(m) = 1 / (π √|S| (m_z² + m_xyᵀ S⁻¹ m_xy)²)`` (Eq. 7 expanded; stable at grazing m).
* Smith Λ: ``(−1 + √(1 + α(φ)² tan²θ))/2`` (Walter 2007 Eq. 34, Heitz 2014 Eq. 86) with
  ``α(φ)² tan²θ = w_xyᵀ S w_xy / w_z²`` (derivation in :mod:`brdffit.microfacet.shadowing`).
* Visible normals: Heitz 2018, "Sampling the GGX distribution of visible normals" (JCGT 7(4))
  for the unit isotropic GGX seen from the linearly transformed direction ``(Lᵀ w_xy, w_z)``,
  then ``s = L s₀`` (for ρ = 0 exactly Heitz's stretch/unstretch).
* Moments: ``E|x̃| = αx``, ``E|ỹ| = αy`` (Dupuy App. C, exact for GGX); second moments diverge.
"""

from __future__ import annotations

import numpy as np

from .shadowing import EllipticalSlopeDistribution

__all__ = ["GGX"]


class GGX(EllipticalSlopeDistribution):
    """Anisotropic GGX distribution ``GGX(alpha_x, alpha_y=None, rho=0)``.

    See :class:`~brdffit.microfacet.shadowing.EllipticalSlopeDistribution` for the
    parameters and conventions.
    """

    kind = "ggx"

    def _g(self, r2):
        return 1.0 / (np.pi * (1.0 + r2) ** 2)

    def _radius(self, u):
        u = np.clip(u, 0.0, 1.0 - 1e-16)
        return np.sqrt(u / (1.0 - u))

    def _D_upper(self, mx, my, mz):
        return 1.0 / (np.pi * self._det_sqrt * (mz * mz + self._quad_inv(mx, my)) ** 2)

    def _lambda_upper(self, wx, wy, wz):
        return 0.5 * (np.sqrt(1.0 + self._quad(wx, wy) / (wz * wz)) - 1.0)

    def sigma(self, w) -> np.ndarray:
        """``σ(w) = (w_z + √(w_z² + w_xyᵀ S w_xy))/2`` for every ``w`` (Eq. 3 in closed form)."""
        w = np.asarray(w, dtype=np.float64)
        return 0.5 * (w[..., 2] + np.sqrt(w[..., 2] ** 2 + self._quad(w[..., 0], w[..., 1])))

    def _sample_visible_unit(self, v, u):
        """Heitz 2018 Listing 1 with α = 1: a visible normal of the unit GGX, as slopes."""
        vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
        lensq = vx * vx + vy * vy
        inv = np.where(lensq > 0, 1.0 / np.sqrt(np.where(lensq > 0, lensq, 1.0)), 0.0)
        t1x = np.where(lensq > 0, -vy * inv, 1.0)
        t1y = np.where(lensq > 0, vx * inv, 0.0)
        # T2 = cross(V, T1), T1 = (t1x, t1y, 0)
        t2x, t2y, t2z = -vz * t1y, vz * t1x, vx * t1y - vy * t1x
        r = np.sqrt(u[..., 0])
        phi = 2.0 * np.pi * u[..., 1]
        p1 = r * np.cos(phi)
        p2 = r * np.sin(phi)
        s = 0.5 * (1.0 + vz)
        p2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - p1 * p1)) + s * p2
        p3 = np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))
        nx = p1 * t1x + p2 * t2x + p3 * vx
        ny = p1 * t1y + p2 * t2y + p3 * vy
        nz = np.maximum(p1 * 0.0 + p2 * t2z + p3 * vz, 1e-300)
        return np.stack([-nx / nz, -ny / nz], -1)

    def _unit_abs_moment(self) -> float:
        return 1.0

    def _unit_second_moment(self) -> float:
        return np.inf

    @classmethod
    def from_slope_moments(cls, moments: dict) -> "GGX":
        """Dupuy 2015 App. C, exact for GGX: ``αx = E|x̃|``, ``αy = E|ỹ|``,
        ``ρ = (αy/αx) b1/(b1² + b2²)`` (``moments`` as from :meth:`slope_moments`).

        (The ρ formula is exact: with ``M = S^{1/2}/tr S^{1/2}`` = the angular moment matrix,
        one checks ``(αy/αx) M01/(M01² + M11²) = ρ``; tested.)
        """
        ax, ay = float(moments["E|x|"]), float(moments["E|y|"])
        b1, b2 = float(moments["b1"]), float(moments["b2"])
        return cls(ax, ay, (ay / ax) * b1 / (b1 * b1 + b2 * b2))
