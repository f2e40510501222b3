"""The anisotropic Beckmann slope distribution with correlation ρ (Dupuy 2015 App. C).

``P(s) = exp(−sᵀ S⁻¹ s) / (π √|S|)`` with ``S = [[αx², ραxαy], [ραxαy, αy²]]`` — a centred
Gaussian of covariance ``S/2`` (Beckmann & Spizzichino 1963; Walter et al. 2007 Eq. 25 in
slope form). α is the slope scale (Walter's / Mitsuba's ``alpha``, RMS slope ``α/√2``), not
the perceptual roughness ``√α``.

* Smith Λ: Walter et al. 2007 Eq. 27 / Heitz 2014 Eq. 80 with the effective roughness
  ``α(φ)² = uᵀ S u`` (derivation in :mod:`brdffit.microfacet.shadowing`).
* Visible normals: the slopes are reduced to the isotropic unit Gaussian by the linear map
  ``L`` (``L Lᵀ = S``) and the unit visible slopes are drawn as in Heitz & d'Eon 2014
  (EGSR, "Importance sampling microfacet-based BSDFs using the distribution of visible
  normals", §4, Appendix: x̃ from the 1D conditional ``∝ (cot θ − x̃)₊ exp(−x̃²)``, ỹ from the
  independent Gaussian). **Deviation:** instead of Heitz's fitted approximate inverse we
  invert the exact 1D CDF ``F(x) = (√π/2) erfc(−x) + tan θ e^{−x²}/2`` by safeguarded
  Newton iterations to machine precision, so sampling is exact (chi-square tested).
"""

from __future__ import annotations

import numpy as np

from .shadowing import EllipticalSlopeDistribution


class _LazySpecial:
    """``scipy.special``, imported on first use (~0.2 s of CPU): importing the microfacet
    package, e.g. for a tabulated fit, does not need it (start-up time)."""

    def __getattr__(self, name):
        from scipy import special as _special

        return getattr(_special, name)


special = _LazySpecial()

__all__ = ["Beckmann"]

_SQRT_PI = np.sqrt(np.pi)
#: Λ(a) < 2.3e-17 from here on (``_lambda_upper``)
LAMBDA_ZERO_A = 6.0


def _beckmann_visible_x(t: np.ndarray, u: np.ndarray, iterations: int = 80) -> np.ndarray:
    """Sample ``x < 1/t`` with density ``∝ (1 − t x) exp(−x²)`` (``t = tan θ >= 0``).

    Exact inversion of ``F(x) = (√π/2) erfc(−x) + t exp(−x²)/2`` by Newton steps kept inside
    a shrinking bracket (bisection when a step leaves it); only unconverged entries iterate.
    """
    t = np.asarray(t, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    t, u = np.broadcast_arrays(t, u)
    shape = t.shape
    t, u = t.ravel(), u.ravel()
    with np.errstate(divide="ignore", over="ignore"):
        mu = np.where(t > 0, 1.0 / np.where(t > 0, t, 1.0), np.inf)
    hi = np.minimum(mu, 8.0)
    lo = np.full_like(hi, -8.0)

    def F(x, tt):
        return 0.5 * _SQRT_PI * special.erfc(-x) + 0.5 * tt * np.exp(-x * x)

    total = F(hi, t)
    target = u * total
    x = np.clip(special.ndtri(np.clip(u, 1e-300, 1 - 1e-16)) / np.sqrt(2.0), lo, hi)
    x = np.where((x <= lo) | (x >= hi), 0.5 * (lo + hi), x)
    act = np.arange(x.size)
    for _ in range(iterations):
        if act.size == 0:
            break
        xa, ta, la, ha = x[act], t[act], lo[act], hi[act]
        f = F(xa, ta) - target[act]
        pos = f > 0
        ha = np.where(pos, xa, ha)
        la = np.where(pos, la, xa)
        d = (1.0 - ta * xa) * np.exp(-xa * xa)
        with np.errstate(divide="ignore", invalid="ignore"):
            xn = xa - f / d
        bad = ~np.isfinite(xn) | (xn < la) | (xn > ha)
        xn = np.where(bad, 0.5 * (la + ha), xn)
        done = (np.abs(f) <= 2e-16 * total[act]) | (np.abs(xn - xa) <= 1e-15 * np.maximum(1.0, np.abs(xa))) \
            | (ha - la <= 1e-15 * np.maximum(1.0, np.abs(xa)))
        x[act] = np.where(np.abs(f) <= 2e-16 * total[act], xa, xn)
        lo[act], hi[act] = la, ha
        act = act[~done]
    return x.reshape(shape)


class Beckmann(EllipticalSlopeDistribution):
    """Anisotropic Beckmann distribution ``Beckmann(alpha_x, alpha_y=None, rho=0)``.

    See :class:`~brdffit.microfacet.shadowing.EllipticalSlopeDistribution` for the
    parameters and conventions (α = slope scale; ``S`` of Dupuy 2015 App. C).
    """

    kind = "beckmann"

    def _g(self, r2):
        return np.exp(-r2) / np.pi

    def _radius(self, u):
        return np.sqrt(-np.log1p(-np.clip(u, 0.0, 1.0 - 1e-16)))

    def _D_upper(self, mx, my, mz):
        mz2 = mz * mz
        return np.exp(-self._quad_inv(mx, my) / mz2) / (np.pi * self._det_sqrt * mz2 * mz2)

    def _lambda_upper(self, wx, wy, wz):
        """``Λ = (erf a − 1)/2 + e^{−a²}/(2a√π)``, ``a = w_z/√(w_xyᵀ S w_xy)``; 0 for
        ``a ≥ LAMBDA_ZERO_A`` (there Λ < 2.3e-17: ``1 + Λ`` is 1 in float64, so G and σ/cos θ
        are unchanged, and the fits skip erfc/exp on most directions of a smooth lobe)."""
        a = wz / np.sqrt(self._quad(wx, wy))
        out = np.zeros(np.shape(a))
        near = ~(a >= LAMBDA_ZERO_A)                  # NaN stays on the exact formula
        an = a[near]
        out[near] = 0.5 * (np.exp(-an * an) / (an * _SQRT_PI) - special.erfc(an))
        return out

    def sigma(self, w) -> np.ndarray:
        """``σ(w) = w_z (1 + erf a)/2 + √Q e^{−a²}/(2√π)`` for every ``w`` (Eq. 3 closed)."""
        w = np.asarray(w, dtype=np.float64)
        Q = self._quad(w[..., 0], w[..., 1])
        sq = np.sqrt(Q)
        with np.errstate(divide="ignore", invalid="ignore"):
            a = np.where(sq > 0, w[..., 2] / np.where(sq > 0, sq, 1.0), np.sign(w[..., 2]) * np.inf)
        return 0.5 * w[..., 2] * special.erfc(-a) + sq * np.exp(-a * a) / (2.0 * _SQRT_PI)

    def _sample_visible_unit(self, w, u):
        wxy = np.hypot(w[..., 0], w[..., 1])
        cz = w[..., 2]
        t = wxy / cz
        x = _beckmann_visible_x(t, u[..., 0])
        y = special.ndtri(np.clip(u[..., 1], 1e-300, 1 - 1e-16)) / np.sqrt(2.0)
        safe = wxy > 0
        c = np.where(safe, w[..., 0] / np.where(safe, wxy, 1.0), 1.0)
        s = np.where(safe, w[..., 1] / np.where(safe, wxy, 1.0), 0.0)
        return np.stack([c * x - s * y, s * x + c * y], -1)

    def _unit_abs_moment(self) -> float:
        return 1.0 / _SQRT_PI

    def _unit_second_moment(self) -> float:
        return 0.5

    @classmethod
    def from_slope_moments(cls, moments: dict) -> "Beckmann":
        """Dupuy 2015 App. C (LEAN mapping), exact for Beckmann: ``αx² = 2 E x̃²``,
        ``αy² = 2 E ỹ²``, ``ραxαy = 2 E x̃ỹ`` (``moments`` as from :meth:`slope_moments`)."""
        ax, ay = np.sqrt(2.0 * moments["Exx"]), np.sqrt(2.0 * moments["Eyy"])
        return cls(ax, ay, 2.0 * moments["Exy"] / (ax * ay))
