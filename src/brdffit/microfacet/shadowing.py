"""Smith shadowing for any slope distribution, and elliptical (scale-matrix) distributions.

Contents
--------
* :func:`sigma_numerical`, :func:`lambda_numerical`, :func:`g1_numerical` – the projected
  area ``σ(w) = ∫_{Ω+} <w, m>₊ D(m) dm`` of Dupuy et al. 2015 **Eq. 3** by direct numerical
  integration, for *any* :class:`~brdffit.microfacet.base.SlopeDistribution`, and the Smith
  ``G1 = cos θ / σ`` / ``Λ = σ / cos θ − 1`` derived from it. The height-correlated G2
  (Dupuy Eq. 2) lives in :meth:`SlopeDistribution.G2`.
* :class:`EllipticalSlopeDistribution` – the common base of the anisotropic Beckmann and GGX
  distributions with the scale matrix ``S = [[αx², ραxαy], [ραxαy, αy²]]`` of Dupuy 2015
  **Appendix C**: ``P(s) = g(sᵀ S⁻¹ s) / √|S|`` for a radial unit profile ``g``.

Numerical integration of Eq. 3
------------------------------
With the slope parameterisation of Eq. 5-7 (``D(m) dm = P(m̃) dm̃ / cos θm`` and
``<w, m> / cos θm = w_z − w_xy · m̃``) Eq. 3 becomes an integral over slope space,

    σ(w) = ∫_{R²} (w_z − w_xy · s)₊ P(s) ds,

which is exactly the same integral (a change of variables, not an approximation). In the
frame aligned with ``w_xy`` (``s = q e∥ + p e⊥``) the positive part is the half plane
``q < μ = w_z / |w_xy|``, on which the integrand is smooth, so no kink or horizon
discontinuity is left to spoil the quadrature (a (θ, φ) product rule on the hemisphere sees
both the kink of ``<w, m>₊`` and the jump of ``D`` at ``m_z = 0`` for heavy-tailed NDFs).
The slopes are first whitened with a shape matrix estimated from 4096 stratified samples
of the distribution (exact for elliptical laws), then the half plane is integrated in polar
coordinates with the angle split where the boundary runs to infinity and the radius mapped by
``r = c tan(πv/2)``: Gauss-Legendre in both variables, spectrally convergent for Beckmann and
GGX alike (heavy tails included), adaptive to any roughness, anisotropy and correlation.

Smith Λ of elliptical distributions (derivation)
------------------------------------------------
Smith's Λ depends only on the 1D marginal of the slope projected on the azimuth of ``w``
(Heitz 2014, "Understanding the masking-shadowing function", Eq. 72). For
``P(s) = g(sᵀ S⁻¹ s)/√|S|`` the projection ``q = u · s`` (``u`` a unit vector) is
``q = (uᵀ S u)^{1/2} z`` where ``z`` is the 1D marginal of the unit isotropic profile
(write ``s = L z⃗`` with ``L Lᵀ = S``: ``u · L z⃗ = (Lᵀu) · z⃗`` and ``|Lᵀu|² = uᵀ S u``).
Hence Λ is the isotropic unit Λ with the effective roughness
``α(φ)² = uᵀ S u = αx² cos²φ + 2ρ αx αy cos φ sin φ + αy² sin²φ`` (for ρ = 0 this is the
familiar formula of Heitz 2014 Eq. 80). With ``a = 1 / (α(φ) tan θ) = w_z / √Q`` and
``Q = w_xyᵀ S w_xy``:

* Beckmann: ``Λ = (erf(a) − 1)/2 + exp(−a²)/(2a√π)``,
  ``σ = w_z (1 + erf a)/2 + √Q exp(−a²)/(2√π)``;
* GGX: ``Λ = (−1 + √(1 + 1/a²))/2``, ``σ = (w_z + √(w_z² + Q))/2``.

The σ forms hold for every ``w`` (also below the horizon) and satisfy
``σ(w) − σ(−w) = w_z``.

Visible normals of elliptical distributions
-------------------------------------------
The visible-slope density for a direction ``w`` is ``∝ (w_z − w_xy · s)₊ P(s)``. With
``s = L s₀`` it becomes ``∝ (w_z − (Lᵀ w_xy) · s₀)₊ g(|s₀|²)``: the visible slopes of the
unit isotropic distribution seen from ``w' = (Lᵀ w_xy, w_z)``. For ρ = 0 this is the usual
stretch ``(αx wx, αy wy, wz)`` of Heitz & d'Eon 2014 §4; with ρ ≠ 0 it is its linear
generalisation, so subclasses only sample the *isotropic unit* visible slopes.
"""

from __future__ import annotations

import numpy as np

from ..geometry import normalize, slope_to_normal
from ..schema import ALPHA_MAX, ALPHA_MIN, Number, Opt, Schema
from .base import SlopeDistribution, _check_float

__all__ = ["sigma_numerical", "lambda_numerical", "g1_numerical",
           "EllipticalSlopeDistribution"]


# ----------------------------------------------------------------------------------------
# Numerical integration of Dupuy 2015 Eq. 3
# ----------------------------------------------------------------------------------------
def _shape_from_samples(dist) -> tuple[np.ndarray, float]:
    """A whitening matrix ``W`` and radial scale ``c`` estimated from 4096 stratified samples.

    ``W = E[s sᵀ / |s|²]`` (always finite, also for heavy tails): for an elliptical law it is
    ``S^{1/2}/tr S^{1/2}`` (angular central Gaussian), so ``z = W⁻¹ s`` is exactly isotropic;
    for other laws it is a robust shape normalisation. ``c`` is the median of ``|z|``.
    """
    side = 64
    g = (np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1)
         .reshape(-1, 2) + 0.5) / side
    s = np.asarray(dist.sample(g), dtype=np.float64)
    s = s[np.all(np.isfinite(s), axis=-1)]
    r2 = np.sum(s * s, axis=-1)
    s = s[r2 > 0]
    r2 = r2[r2 > 0]
    W = np.einsum("ni,nj->ij", s / r2[:, None], s) / max(len(s), 1)
    if not np.all(np.isfinite(W)) or np.linalg.det(W) <= 1e-12 * np.trace(W) ** 2:
        W = 0.5 * np.eye(2)
    z = np.linalg.solve(W, s.T).T
    c = float(np.median(np.linalg.norm(z, axis=-1))) if len(z) else 1.0
    return W, max(c, 1e-12)


def sigma_numerical(dist: SlopeDistribution, w, n: int = 96, chunk: int = 32) -> np.ndarray:
    """Projected area ``σ(w) = ∫ <w, m>₊ D(m) dm`` (Dupuy 2015 Eq. 3) by quadrature.

    Works for any :class:`SlopeDistribution` using only its ``pdf`` and ``sample``: Eq. 3
    is written in slope space (``σ = ∫ (w_z − w_xy·s)₊ P(s) ds``, Eq. 5-7), the slopes are
    whitened by ``s = W z`` (see :func:`_shape_from_samples`), and the half plane where the
    integrand is positive is integrated in polar coordinates ``z = r (cos ψ, sin ψ)``:
    ψ is split at the two directions where the half-plane boundary goes to infinity (the
    integrand is smooth on each arc), and ``r = c tan(πv/2)`` maps ``[0, r_max(ψ))`` to a
    finite ``v`` interval. Gauss-Legendre with ``n`` nodes in ``v`` and ``n`` per arc in ψ.
    """
    w = np.asarray(w, dtype=np.float64)
    shape = w.shape[:-1]
    w = w.reshape(-1, 3)
    W, c = _shape_from_samples(dist)
    detW = abs(np.linalg.det(W))
    b = w[:, :2] @ W.T                                                 # W w_xy (W symmetric)
    bn = np.linalg.norm(b, axis=-1)
    phib = np.arctan2(b[:, 1], b[:, 0])
    wz = w[:, 2]
    x, xw = np.polynomial.legendre.leggauss(n)
    # ψ nodes relative to the direction of b: front arc (−π/2, π/2), back arc (π/2, 3π/2)
    delta = np.concatenate([0.5 * np.pi * x, np.pi + 0.5 * np.pi * x])      # (2n,)
    dw = np.concatenate([0.5 * np.pi * xw, 0.5 * np.pi * xw])
    cosd = np.cos(delta)
    front = np.arange(2 * n) < n
    out = np.empty(w.shape[0])
    for s0 in range(0, w.shape[0], chunk):
        sl = slice(s0, s0 + chunk)
        k = wz[sl].size
        with np.errstate(divide="ignore", invalid="ignore"):
            rb = wz[sl, None] / (bn[sl, None] * cosd[None, :])          # boundary radius
        up = wz[sl, None] >= 0
        fr = front[None, :]
        # positive part along each ray: front arc [0, rb] (wz >= 0) or empty (wz < 0);
        # back arc [0, ∞) (wz >= 0) or [rb, ∞) (wz < 0); no boundary when b = 0.
        flat = ~(bn[sl, None] > 0)
        rlo = np.where(up | flat, 0.0, np.where(fr, 0.0, rb))
        rhi = np.where(flat, np.where(up, np.inf, 0.0),
                       np.where(fr, np.where(up, rb, 0.0), np.inf))
        rlo = np.nan_to_num(np.maximum(rlo, 0.0), nan=0.0)
        rhi = np.nan_to_num(np.maximum(rhi, rlo), nan=0.0, posinf=np.inf)
        vlo = (2.0 / np.pi) * np.arctan(rlo / c)
        vhi = (2.0 / np.pi) * np.arctan(rhi / c)                       # (k, 2n)
        v = vlo[:, :, None] + 0.5 * (vhi - vlo)[:, :, None] * (x[None, None, :] + 1.0)
        vw = 0.5 * (vhi - vlo)[:, :, None] * xw[None, None, :]
        t = np.tan(0.5 * np.pi * v)
        r = c * t
        jac = c * 0.5 * np.pi * (1.0 + t * t) * vw * r                # dr · r
        psi = phib[sl, None] + delta[None, :]                          # (k, 2n)
        zx = r * np.cos(psi)[:, :, None]
        zy = r * np.sin(psi)[:, :, None]
        sx = W[0, 0] * zx + W[0, 1] * zy
        sy = W[1, 0] * zx + W[1, 1] * zy
        P = np.asarray(dist.pdf(np.stack([sx, sy], -1)), dtype=np.float64).reshape(k, 2 * n, n)
        lin = np.maximum(wz[sl, None, None] - bn[sl, None, None] * r * cosd[None, :, None], 0.0)
        out[sl] = detW * np.einsum("kij,kij,kij,i->k", P, jac, lin, dw)
    return out.reshape(shape)


def lambda_numerical(dist: SlopeDistribution, w, n: int = 96) -> np.ndarray:
    """Smith ``Λ(w) = σ(w)/cos θ − 1`` from :func:`sigma_numerical` (inf below the horizon)."""
    w = np.asarray(w, dtype=np.float64)
    cz = w[..., 2]
    sig = sigma_numerical(dist, w, n=n)
    return np.where(cz > 0, sig / np.where(cz > 0, cz, 1.0) - 1.0, np.inf)


def g1_numerical(dist: SlopeDistribution, w, n: int = 96) -> np.ndarray:
    """Smith ``G1(w) = cos θ / σ(w)`` (Dupuy 2015 Eq. 3) by numerical integration."""
    w = np.asarray(w, dtype=np.float64)
    cz = w[..., 2]
    sig = sigma_numerical(dist, w, n=n)
    return np.where(cz > 0, cz / np.where(sig > 0, sig, 1.0), 0.0)


# ----------------------------------------------------------------------------------------
# Elliptical distributions with the scale matrix of Dupuy 2015 Appendix C
# ----------------------------------------------------------------------------------------
class EllipticalSlopeDistribution(SlopeDistribution):
    """``P(s) = g(sᵀ S⁻¹ s) / √|S|`` with ``S = [[αx², ραxαy], [ραxαy, αy²]]`` (Dupuy App. C).

    Parameters
    ----------
    alpha_x, alpha_y:
        Slope scales αx, αy > 0 (``alpha_y`` defaults to ``alpha_x``). This α is the
        slope-space roughness of Walter et al. 2007 / Dupuy 2015 Eq. 9 — the parameter
        Mitsuba calls ``alpha``; the perceptual "roughness" ``r`` with ``α = r²`` is *not*
        used anywhere in brdffit.
    rho:
        Slope correlation ρ ∈ (−1, 1). ρ ≠ 0 rotates/shears the anisotropy.

    Subclasses define the unit radial profile ``_g(r²)`` (with ``∫ g(|z|²) dz = 1``), its
    radial quantile ``_radius(u)``, the closed-form ``sigma``/``Lambda`` and
    ``_sample_visible_unit``.
    """

    kind: str = ""
    #: fit-file state (:mod:`brdffit.schema`): slope scales in (0, ALPHA_MAX], ρ in (−1, 1)
    state_schema = Schema({"alpha_x": Number(ge=ALPHA_MIN, le=ALPHA_MAX),
                           "alpha_y": Opt(Number(ge=ALPHA_MIN, le=ALPHA_MAX)),
                           "rho": Number(gt=-1, lt=1)}, required=("alpha_x",), strict=True)

    def __init__(self, alpha_x, alpha_y=None, rho=0.0):
        ax = _check_float("alpha_x", alpha_x)
        ay = ax if alpha_y is None else _check_float("alpha_y", alpha_y)
        rho = _check_float("rho", rho)
        if ax <= 0 or ay <= 0:
            raise ValueError(f"{type(self).__name__}: slope scales must be > 0, got "
                             f"alpha_x={ax}, alpha_y={ay}")
        if not -1.0 < rho < 1.0:
            raise ValueError(f"{type(self).__name__}: correlation rho must be in (-1, 1), "
                             f"got {rho}")
        self.alpha_x, self.alpha_y, self.rho = ax, ay, rho
        self.isotropic = bool(ax == ay and rho == 0.0)
        sr = np.sqrt(1.0 - rho * rho)
        self._sr = sr
        self._det_sqrt = ax * ay * sr                                      # √|S|
        self.S = np.array([[ax * ax, rho * ax * ay], [rho * ax * ay, ay * ay]])
        self.L = np.array([[ax, 0.0], [rho * ay, ay * sr]])               # L Lᵀ = S

    # -- construction helpers --------------------------------------------------------------
    def params(self) -> dict:
        return {"alpha_x": self.alpha_x, "alpha_y": self.alpha_y, "rho": self.rho}

    def scaled(self, ax: float, ay: float | None = None):
        """Roughness scaling (Dupuy 2015 Eq. 9): ``P(x̃/ax, ỹ/ay)/(ax ay)``; S → A S A."""
        ay = ax if ay is None else ay
        return type(self)(self.alpha_x * ax, self.alpha_y * ay, self.rho)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(alpha_x={self.alpha_x:.6g}, alpha_y={self.alpha_y:.6g}, "
                f"rho={self.rho:.6g})")

    def __eq__(self, other) -> bool:
        return type(self) is type(other) and self.params() == other.params()

    def __hash__(self) -> int:
        return hash((type(self).__name__, self.alpha_x, self.alpha_y, self.rho))

    # -- quadratic forms ---------------------------------------------------------------------
    def _quad_inv(self, x, y):
        """``(x, y) S⁻¹ (x, y)ᵀ``."""
        X = x / self.alpha_x
        Y = y / self.alpha_y
        return (X * X - 2.0 * self.rho * X * Y + Y * Y) / (self._sr * self._sr)

    def _quad(self, x, y):
        """``(x, y) S (x, y)ᵀ`` (projected squared roughness times |w_xy|²)."""
        ax, ay = self.alpha_x, self.alpha_y
        if self.rho == 0.0:
            return (ax * ax) * (x * x) + (ay * ay) * (y * y)
        return (ax * ax) * (x * x) + (2.0 * self.rho * ax * ay) * (x * y) + (ay * ay) * (y * y)

    # -- profile hooks -----------------------------------------------------------------------
    def _g(self, r2):  # pragma: no cover - abstract
        raise NotImplementedError

    def _radius(self, u):  # pragma: no cover - abstract
        raise NotImplementedError

    def _sample_visible_unit(self, w, u):  # pragma: no cover - abstract
        raise NotImplementedError

    # -- slope space -------------------------------------------------------------------------
    def pdf(self, slopes) -> np.ndarray:
        """``P22(s) = g(sᵀ S⁻¹ s)/√|S|`` (Dupuy 2015 App. C)."""
        s = np.asarray(slopes, dtype=np.float64)
        return self._g(self._quad_inv(s[..., 0], s[..., 1])) / self._det_sqrt

    def sample(self, u) -> np.ndarray:
        """Slopes ``L z`` with ``z`` drawn from the unit profile by its radial quantile."""
        u = np.asarray(u, dtype=np.float64)
        r = self._radius(u[..., 0])
        phi = 2.0 * np.pi * u[..., 1]
        z = np.stack([r * np.cos(phi), r * np.sin(phi)], -1)
        return z @ self.L.T

    # -- hemisphere --------------------------------------------------------------------------
    def D(self, m) -> np.ndarray:
        """NDF ``P(m̃)/cos⁴θm`` (Dupuy Eq. 7); 0 for ``m_z <= 0``."""
        m = np.asarray(m, dtype=np.float64)
        mz = m[..., 2]
        up = mz > 0
        mzs = np.where(up, mz, 1.0)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            val = self._D_upper(m[..., 0], m[..., 1], mzs)
        return np.where(up, val, 0.0)

    def _D_upper(self, mx, my, mz):
        return self._g(self._quad_inv(mx / mz, my / mz)) / (self._det_sqrt * mz**4)

    def Lambda(self, w) -> np.ndarray:
        """Smith Λ (closed form, see module docstring); inf at or below the horizon."""
        w = np.asarray(w, dtype=np.float64)
        cz = w[..., 2]
        up = cz > 0
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            lam = self._lambda_upper(w[..., 0], w[..., 1], np.where(up, cz, 1.0))
        return np.where(up, lam, np.inf)

    def _lambda_upper(self, wx, wy, wz):  # pragma: no cover - abstract
        raise NotImplementedError

    # -- isotropic distributions: functions of the polar angle alone --------------------------
    def _require_isotropic(self, what: str) -> None:
        if not self.isotropic:
            raise ValueError(f"{type(self).__name__}.{what}: only for an isotropic distribution "
                             f"(alpha_x == alpha_y, rho == 0), got alpha_x={self.alpha_x}, "
                             f"alpha_y={self.alpha_y}, rho={self.rho}")

    def D_cos4(self, tan2_m) -> np.ndarray:
        """``D(m) cos⁴θm`` = ``P22`` of the slope of length ``tan θm`` (Dupuy Eq. 7) from
        ``tan2_m`` = tan²θm, for an isotropic distribution (whatever the azimuth); the fits
        evaluate many lobes on fixed directions with it."""
        self._require_isotropic("D_cos4")
        a2 = self.alpha_x * self.alpha_x
        return self._g(np.asarray(tan2_m, dtype=np.float64) / a2) / a2

    def Lambda_of_tan(self, tan_theta) -> np.ndarray:
        """Smith Λ of a direction of ``tan θ`` = ``tan_theta`` ≥ 0 (above the horizon), for an
        isotropic distribution (whatever the azimuth): ``Λ`` of ``(tan θ, 0, 1)``."""
        self._require_isotropic("Lambda_of_tan")
        with np.errstate(divide="ignore"):
            return self._lambda_upper(np.asarray(tan_theta, dtype=np.float64), 0.0, 1.0)

    def G1(self, w, m=None) -> np.ndarray:
        """Smith ``G1 = 1/(1 + Λ)`` (Heitz 2014 Eq. 43), ``χ⁺(w·m)`` applied when ``m`` given."""
        return super().G1(w, m)

    def sample_visible(self, w, u) -> np.ndarray:
        """Visible normals for ``w`` (above the horizon), by the linear slope transform."""
        w = np.asarray(w, dtype=np.float64)
        u = np.asarray(u, dtype=np.float64)
        shape = np.broadcast_shapes(w.shape[:-1], u.shape[:-1])
        w = np.broadcast_to(w, shape + (3,))
        u = np.broadcast_to(u, shape + (2,))
        wxy = w[..., :2] @ self.L                                        # Lᵀ w_xy
        wp = normalize(np.concatenate([wxy, w[..., 2:3]], -1))
        s0 = self._sample_visible_unit(wp, u)
        return slope_to_normal(s0 @ self.L.T)

    # -- moments -----------------------------------------------------------------------------
    def _unit_abs_moment(self) -> float:  # E|z_x| of the unit profile
        raise NotImplementedError

    def _unit_second_moment(self) -> float:  # E z_x² of the unit profile
        raise NotImplementedError

    def angular_moments(self) -> dict[str, float]:
        """``b1 = E[x̃ỹ/(x̃²+ỹ²)]`` and ``b2 = E[ỹ²/(x̃²+ỹ²)]`` of Dupuy 2015 App. C.

        For any elliptical law the direction of ``s`` follows the angular central Gaussian
        of ``S``, whose second-moment matrix is ``S^{1/2} / tr(S^{1/2})`` (closed form:
        ``E cos²ψ = √λ1/(√λ1 + √λ2)`` in the eigenbasis of S).
        """
        evals, evecs = np.linalg.eigh(self.S)
        root = (evecs * np.sqrt(evals)) @ evecs.T
        M = root / np.trace(root)
        return {"b1": float(M[0, 1]), "b2": float(M[1, 1])}

    def slope_moments(self) -> dict[str, float]:
        """Closed-form slope moments (Dupuy 2015 App. C).

        Keys (shared with the SGD and tabulated distributions): ``"E|x|"``, ``"E|y|"``,
        ``"Exx"``, ``"Eyy"``, ``"Exy"``, plus the angular ``"b1"``, ``"b2"``. The marginals of
        an elliptical law are the unit marginal scaled by αx and αy, so ``E|x̃| = αx E|z|``,
        ``E x̃² = αx² E z²`` and ``E x̃ỹ = ραxαy E z²``. For GGX the second moments are
        ``inf`` and ``Exy`` is undefined (NaN).
        """
        a1 = self._unit_abs_moment()
        a2 = self._unit_second_moment()
        ax, ay, r = self.alpha_x, self.alpha_y, self.rho
        exy = r * ax * ay * a2 if np.isfinite(a2) else np.nan
        out = {"E|x|": ax * a1, "E|y|": ay * a1, "Exx": ax * ax * a2, "Eyy": ay * ay * a2,
               "Exy": exy}
        out.update(self.angular_moments())
        return out
