"""Tabulated slope distribution of Dupuy et al. 2015 (the fitted microfacet NDF).

The slope PDF ``P`` (Dupuy 2015 Eq. 7-9) is stored on a polar grid of the *normal* direction
``(θ, φ)`` (slope ``h̃ = -tan θ (cos φ, sin φ)``, Eq. 5):

* isotropic: a 1D radial table ``P(θk)`` (Eq. 21), ``N`` nodes;
* anisotropic: a 2D table ``P(θk, φj)``, ``Nθ × Nφ`` nodes, ``φj = 2πj/Nφ``.

The elevation nodes follow a *radial rule* (:func:`radial_rule`) in the variable
``u = sqrt(2θ/π)`` (so ``θ = (π/2) u²``, the MERL half-angle parameterisation of the
supplemental, Eq. 17-22):

* ``"merl"``: ``u_k = k/N`` with rectangle weights ``1/N`` (supplemental Eq. 20-22, the
  paper's choice, required for MERL-grid input so that every backscattering sample is read once);
* ``"gauss"``: Gauss-Legendre nodes and weights in ``u`` on ``[0, 1]`` (a deliberate deviation
  for accuracy: the integrand of Eq. 22 is smooth in ``u``, so the rule converges spectrally
  instead of O(h⁴)).

Continuous lookup (Dupuy 2015 §4.3 "linearly interpolating the values of p") is done here
with a monotone cubic (PCHIP) Hermite interpolant of ``log P`` in ``u`` (and linear in ``φ``
for anisotropic tables); a deliberate deviation from linear interpolation, for accuracy
between nodes. The interpolated variable is ``log(P sec⁴θ)`` (the log-NDF, smooth up to
grazing for ``r⁻⁴`` tails), mirrored to ``u < 0`` (P is even in the slope); beyond the
last node ``P`` decays as ``r⁻⁴`` (the GGX tail: integrable, with a finite ``D`` at grazing).

Derived quantities:

* projected area ``σ(w) = ∫ <w,m>₊ D(m) dm`` (denominator of Eq. 3) computed from ``P`` with
  the same quadrature as the fit, using the closed-form azimuthal integral
  ``∫₀^{2π} (1 + s cos φ)₊ dφ`` (isotropic) or an FFT circular convolution in ``φ``
  (anisotropic); Smith ``Λ = σ/cos θ − 1`` and ``G1 = cos θ/σ``;
* roughness editing (Eq. 9): ``D(h; αx, αy) = P(x̃/αx, ỹ/αy) sec⁴θ/(αx αy)`` with the
  stretch invariance of ``Λ`` (Heitz 2014); ``alpha_x``/``alpha_y`` may be arrays that
  broadcast with the directions (per-texel roughness), without refitting;
* sampling: slopes from ``P`` by quantile tables (Appendix A; in polar form: a marginal in
  ``u`` and conditional in ``φ``), and visible normals (Heitz & d'Eon 2014): for isotropic
  tables by inversion, with a marginal table of ``P1(x̃)`` and a conditional quantile table
  of ``ỹ | x̃``; for anisotropic tables by rejection from the quantile tables (extension);
* slope moments for Appendix C (Beckmann / GGX conversion).
"""

from __future__ import annotations

import numpy as np

from ..geometry import slope_to_normal
from ..schema import (ALPHA_MAX, ALPHA_MIN, FRESNEL_MAX, TABLE_MAX, Array, Bool, Choice,
                      Integer, Numbers, Schema, StateError)
from .base import SlopeDistribution
from .fresnel import TabulatedFresnel
from .model import register_distribution, register_fresnel

__all__ = ["TabulatedSlopeDistribution", "AnisotropicTabulatedSlopeDistribution",
           "FittedFresnel", "radial_rule", "azimuthal_clamped_cosine_integral"]

_LOG_FLOOR = 1e-30  # relative floor of P before taking logs
_SIGMA_DENSE = 4096  # uniform-u resampling of the σ table used for lookups


def _clip_rho(rho):
    return float(np.clip(rho, -0.999, 0.999)) if np.isfinite(rho) else 0.0


def radial_rule(n: int, rule: str = "merl"):
    """Nodes and weights of the radial quadrature in ``u = sqrt(2θ/π)``.

    Returns ``(u, theta, r, w_r)`` with ``r = tan θ`` the radial slope and ``w_r`` such that
    ``∫₀^∞ f(r) r dr ≈ Σ_k w_r[k] f(r_k)`` (change of variable ``r = tan((π/2) u²)``,
    ``dr = π u sec²θ du``; supplemental Eq. 17-18).
    """
    n = int(n)
    if n < 2:
        raise ValueError(f"radial rule needs at least 2 nodes, got {n}")
    if rule == "merl":
        u = np.arange(n, dtype=np.float64) / n
        wu = np.full(n, 1.0 / n)
    elif rule == "gauss":
        x, w = np.polynomial.legendre.leggauss(n)
        u = 0.5 * (x + 1.0)
        wu = 0.5 * w
    else:
        raise ValueError(f"unknown radial rule {rule!r}; expected 'merl' or 'gauss'")
    theta = 0.5 * np.pi * u**2
    c = np.cos(theta)
    r = np.tan(theta)
    w_r = wu * np.pi * u / c**2 * r
    return u, theta, r, w_r


def azimuthal_clamped_cosine_integral(s) -> np.ndarray:
    """``J(s) = ∫₀^{2π} (1 + s cos φ)₊ dφ`` in closed form (s ≥ 0).

    ``2π`` for ``s ≤ 1``, else ``2(φ0 + s sin φ0)`` with ``φ0 = arccos(−1/s)``. With
    ``s = tan θo tan θh`` this is the azimuthal integral of ``<o, h>₊`` of Dupuy 2015 Eq. 23
    (divided by ``cos θo cos θh``), so no azimuthal quadrature is needed.
    """
    s = np.abs(np.asarray(s, dtype=np.float64))
    with np.errstate(divide="ignore"):
        phi0 = np.arccos(np.clip(-1.0 / np.maximum(s, 1.0), -1.0, 1.0))
    return np.where(s <= 1.0, 2.0 * np.pi, 2.0 * (phi0 + s * np.sin(phi0)))


def _spline_slopes(x, y):
    """Node derivatives of the not-a-knot cubic spline through ``(x, y)`` (along axis 0):
    ``scipy.interpolate.CubicSpline(x, y, axis=0).derivative()(x)`` in NumPy -- the same
    tridiagonal system and end conditions (de Boor), solved by the Thomas algorithm (its
    pivots are > 0 for increasing ``x``). Avoids importing scipy.interpolate (~0.45 s of CPU)
    in every fit, and a multi-threaded LAPACK solve that stalls on a busy machine; agrees with SciPy to ~1e-15 (tests/cli/test_startup.py)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    n = x.shape[0]
    h = np.diff(x)
    shape = (-1,) + (1,) * (y.ndim - 1)
    delta = np.diff(y, axis=0) / h.reshape(shape)
    if n == 2:
        return np.repeat(delta, 2, axis=0)
    if n == 3:  # not-a-knot on three nodes: the parabola through them
        c = (delta[1] - delta[0]) / (x[2] - x[0])
        return np.stack([delta[0] - c * h[0], delta[0] + c * h[0], delta[1] + c * h[1]])
    lower = np.zeros(n)   # A[i, i-1]
    diag = np.empty(n)    # A[i, i]
    upper = np.zeros(n)   # A[i, i+1]
    b = np.empty((n,) + y.shape[1:])
    lower[1:-1], diag[1:-1], upper[1:-1] = h[1:], 2.0 * (h[:-1] + h[1:]), h[:-1]
    b[1:-1] = 3.0 * (h[1:].reshape(shape) * delta[:-1] + h[:-1].reshape(shape) * delta[1:])
    d = x[2] - x[0]
    diag[0], upper[0] = h[1], d
    b[0] = ((h[0] + 2.0 * d) * h[1] * delta[0] + h[0] ** 2 * delta[1]) / d
    d = x[-1] - x[-3]
    lower[-1], diag[-1] = d, h[-2]
    b[-1] = (h[-1] ** 2 * delta[-2] + (2.0 * d + h[-1]) * h[-2] * delta[-1]) / d
    cp = np.empty(n)
    bp = np.empty_like(b)
    cp[0], bp[0] = upper[0] / diag[0], b[0] / diag[0]
    for i in range(1, n):  # forward sweep (n ≲ 200: a Python loop over rows is ~1 ms)
        den = diag[i] - lower[i] * cp[i - 1]
        cp[i] = upper[i] / den
        bp[i] = (b[i] - lower[i] * bp[i - 1]) / den
    for i in range(n - 2, -1, -1):
        bp[i] -= cp[i] * bp[i + 1]
    return bp


def _pchip_slopes(x, y, kind: str = "hyman"):
    """Node derivatives for cubic Hermite interpolation of ``y`` (along axis 0) at ``x``.

    ``"hyman"`` (default): not-a-knot cubic-spline slopes passed through Hyman's (1983)
    monotonicity filter (zero at local extrema, ``|d| ≤ 3 min|Δ|``), i.e. spline accuracy on
    smooth data, no overshoot on noisy or clipped data. ``"spline"`` or ``"pchip"`` as named.
    """
    if kind == "pchip":
        from scipy.interpolate import PchipInterpolator

        return PchipInterpolator(x, y, axis=0).derivative()(x)
    d = _spline_slopes(x, y)
    if kind == "spline":
        return d
    h = np.diff(x).reshape((-1,) + (1,) * (y.ndim - 1))
    delta = np.diff(y, axis=0) / h
    left = np.concatenate([delta[:1], delta], axis=0)
    right = np.concatenate([delta, delta[-1:]], axis=0)
    sgn = np.sign(right)
    mono = left * right > 0
    lim = 3.0 * np.minimum(np.abs(left), np.abs(right))
    return np.where(mono, sgn * np.minimum(np.maximum(sgn * d, 0.0), lim), 0.0)


def _hermite(x_nodes, y, dy, x, col=None, clamp=False):
    """Cubic Hermite interpolation at ``x`` of tables ``y``/``dy`` (``(M,)`` or ``(M, C)``).

    ``col`` (int array broadcast with ``x``) picks the column of 2D tables. ``x`` is clipped
    to the node range.
    """
    xn = x_nodes
    x = np.clip(x, xn[0], xn[-1])
    k = np.clip(np.searchsorted(xn, x, side="right") - 1, 0, len(xn) - 2)
    h = xn[k + 1] - xn[k]
    t = (x - xn[k]) / h
    t2, t3 = t * t, t * t * t
    h00 = 2 * t3 - 3 * t2 + 1
    h10 = t3 - 2 * t2 + t
    h01 = -2 * t3 + 3 * t2
    h11 = t3 - t2
    if col is None:
        y0, y1, d0, d1 = y[k], y[k + 1], dy[k], dy[k + 1]
    else:
        y0, y1, d0, d1 = y[k, col], y[k + 1, col], dy[k, col], dy[k + 1, col]
    out = h00 * y0 + h10 * h * d0 + h01 * y1 + h11 * h * d1
    if clamp:  # no overshoot above the larger end value (noisy tables, zeros in log P)
        out = np.minimum(out, np.maximum(y0, y1))
    return out


def _check_table_size(params, arrays, path, field) -> None:
    """2D tables: at most 1024 θ nodes and 65,536 entries (fits use 90 × 90)."""
    P = arrays.get("P")
    if P is not None and len(P.shape) == 2 and (P.shape[0] > 1024
                                                 or P.shape[0] * P.shape[1] > 65536):
        raise StateError(field("P"), f"expected a 2D table of at most 1024 θ nodes and "
                                     f"65,536 entries, found shape {tuple(P.shape)}")


class TabulatedSlopeDistribution(SlopeDistribution):
    """Tabulated slope PDF ``P`` (Dupuy 2015), isotropic (1D) or anisotropic (2D).

    Parameters
    ----------
    p:
        Slope-PDF values at the nodes: ``(N,)`` (isotropic, radial) or ``(Nθ, Nφ)``
        (anisotropic, normal azimuth ``φj = 2πj/Nφ``). Normalised here (Eq. 8) with the
        quadrature of ``rule`` unless ``normalize=False``.
    rule:
        Radial rule of the elevation nodes, ``"merl"`` or ``"gauss"`` (:func:`radial_rule`).
    alpha_x, alpha_y:
        Roughness scales of Eq. 9 (1 = the fitted table). Scalars or arrays broadcasting
        with the batch shape of the directions passed to :meth:`D`, :meth:`Lambda`, ...
    """

    #: fit-file state (:mod:`brdffit.schema`): ``P`` (n,) with 2 <= n <= 4096, or (n, m) with
    #: n <= 1024 and n·m <= 65,536 (load time grows as n²m), finite, >= 0, not all 0;
    #: the optional σ table (n,) >= 0; roughness scales in (0, ALPHA_MAX]
    state_schema = Schema(
        {"rule": Choice("merl", "gauss"), "isotropic": Bool(),
         "n_theta": Integer(ge=2, le=4096), "n_phi": Integer(ge=1, le=1024),
         "alpha_x": Numbers(ge=ALPHA_MIN, le=ALPHA_MAX), "alpha_y": Numbers(ge=ALPHA_MIN, le=ALPHA_MAX)},
        arrays={"P": Array([("n",), ("n", "m")], ge=0, le=TABLE_MAX, nonzero=True),
                "sigma": Array(("n",), ge=0, le=TABLE_MAX, required=False)},
        dims={"n": (2, 4096), "m": (1, 1024)}, checks=(_check_table_size,))

    def __new__(cls, p=None, *args, **kwargs):
        if cls is TabulatedSlopeDistribution and np.ndim(p) == 2:
            cls = AnisotropicTabulatedSlopeDistribution
        return super().__new__(cls)

    def __init__(self, p, rule: str = "merl", alpha_x=1.0, alpha_y=None, normalize: bool = True):
        p = np.asarray(p, dtype=np.float64)
        if p.ndim not in (1, 2):
            raise ValueError(f"tabulated P must be 1D (isotropic) or 2D (anisotropic), got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise ValueError("tabulated P contains NaN or infinite values")
        p = np.maximum(p, 0.0)
        if not np.any(p > 0):
            raise ValueError("tabulated P is identically zero")
        self.rule = rule
        self.table_isotropic = p.ndim == 1
        n_theta = p.shape[0]
        self.u, self.theta, self.r, self.w_r = radial_rule(n_theta, rule)
        self.n_phi = 1 if self.table_isotropic else p.shape[1]
        self.phi = 2.0 * np.pi * np.arange(self.n_phi) / self.n_phi
        self.table = p / self._integral(p) if normalize else p
        self._build_p_lookup()
        if normalize:  # Eq. 8 for the *continuous* (interpolated) P, not only the nodes
            self.table = self.table / self._interpolant_integral()
        self.table = self.table.astype(np.float32).astype(np.float64)  # what a fit file stores
        self._set_alpha(alpha_x, alpha_y)
        self._build_lookup()
        self._sampling = None
        self._visible = None
        self._pdense = None

    # -- construction helpers ----------------------------------------------------------------
    def _integral(self, p) -> float:
        """``∫ P dh̃`` with the quadrature of the table (Eq. 8)."""
        if p.ndim == 1:
            return float(2.0 * np.pi * np.sum(self.w_r * p))
        return float(np.sum(self.w_r[:, None] * p) * 2.0 * np.pi / p.shape[1])

    def with_roughness(self, alpha_x, alpha_y=None) -> "TabulatedSlopeDistribution":
        """The same table with roughness scales ``(αx, αy)`` (Eq. 9), sharing all tables.

        ``alpha_x``/``alpha_y`` may be arrays (per-texel roughness) broadcasting with the
        directions later passed to the evaluation methods.
        """
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        new._set_alpha(alpha_x, alpha_y)
        return new

    def _set_alpha(self, alpha_x, alpha_y=None):
        ax = np.asarray(alpha_x, dtype=np.float64)
        ay = ax if alpha_y is None else np.asarray(alpha_y, dtype=np.float64)
        if np.any(~np.isfinite(ax)) or np.any(~np.isfinite(ay)) or np.any(ax <= 0) or np.any(ay <= 0):
            raise ValueError(f"roughness scales must be finite and > 0, got {alpha_x!r}, {alpha_y!r}")
        self.alpha_x = ax if ax.ndim else float(ax)
        self.alpha_y = ay if ay.ndim else float(ay)
        self.isotropic = bool(self.table_isotropic and ax.shape == ay.shape and np.all(ax == ay))

    def _interpolant_integral(self, m: int = 4096) -> float:
        """``∫ P dh̃`` of the interpolated table: trapezoid on a fine ``u`` grid up to the
        last node, plus the ``r⁻⁴`` tail in closed form (``π P_last r_last²``)."""
        if not self.table_isotropic:
            m = m // 4  # 2D: Nφ lookups per u sample
        uu = np.linspace(0.0, self._u_last, m + 1)
        theta = 0.5 * np.pi * uu**2
        r = np.tan(theta)
        jac = np.pi * uu / np.cos(theta) ** 2 * r
        if self.table_isotropic:
            f = self._p_unit_polar(r) * jac * 2.0 * np.pi
            tail = np.pi * self._p_last * self._r_last**2
        else:
            pp = self._p_unit_polar(r[:, None], self.phi[None, :])
            f = pp.mean(axis=1) * jac * 2.0 * np.pi
            tail = np.pi * float(np.mean(self._p_last)) * self._r_last**2
        return float(np.trapezoid(f, uu) + tail)

    def _build_lookup(self):
        self._build_p_lookup()
        self._build_sigma_lookup()

    def _build_p_lookup(self):
        p = self.table
        floor = _LOG_FLOOR * float(p.max())
        # interpolated variable: log(P sec⁴θ) = log(P (1 + r²)²) (log of the NDF), which
        # stays smooth up to grazing for r⁻⁴ (GGX-like) tails where log P itself is singular
        lift = 2.0 * np.log1p(self.r**2)
        logp = np.log(np.maximum(p, floor)) + (lift if p.ndim == 1 else lift[:, None])
        # nodes in u mirrored to u < 0: log P is even in u (a function of tan²θ), so the
        # spline gets the right behaviour at the pole θ = 0
        u = self.u
        k0 = 1 if u[0] == 0.0 else 0
        u = np.concatenate([-u[k0:][::-1], u])
        logp = np.concatenate([logp[k0:][::-1], logp], axis=0)
        self._lu = u
        self._llogp = logp
        self._ldlogp = _pchip_slopes(u, logp)
        self._p_last = p[-1]
        self._u_last = u[-1]
        self._r_last = float(np.tan(0.5 * np.pi * u[-1] ** 2))

    def _build_sigma_lookup(self):
        # σ at the nodes and the two ends u=0 and u=1, then a PCHIP in u
        sig = self._sigma_nodes()
        self._sigma_table = sig
        us = np.concatenate([[0.0], self.u, [1.0]])
        sig_end = self._sigma_grazing()
        sig0 = np.ones((1,) + sig.shape[1:])
        sig_ext = np.concatenate([sig0, sig, sig_end[None]], axis=0)
        if self.u[0] == 0.0:  # merl rule: node at u=0 already
            us = us[1:]
            sig_ext = sig_ext[1:]
        self._su = us
        self._ssig = sig_ext
        self._sdsig = _pchip_slopes(us, sig_ext)
        # dense uniform-u resampling of σ for fast lookups (index arithmetic, no search)
        m = _SIGMA_DENSE if self.table_isotropic else _SIGMA_DENSE // 4
        self._sig_m = m
        ug = np.linspace(0.0, 1.0, m + 1)
        if self.table_isotropic:
            self._sig_dense = _hermite(us, sig_ext, self._sdsig, ug)
        else:
            cols = np.arange(self.n_phi)
            self._sig_dense = _hermite(us, sig_ext, self._sdsig, ug[:, None], cols[None, :])

    def _sigma_nodes(self) -> np.ndarray:
        """``σ(θk[, φj])`` at the table nodes with the fit quadrature (Eq. 3, 22-23)."""
        t = self.r
        c = np.cos(self.theta)
        if self.table_isotropic:
            J = azimuthal_clamped_cosine_integral(t[:, None] * self.r[None, :])
            return c * (J @ (self.w_r * self.table))
        return c[:, None] * _circular_kernel_apply(t, self.r, self.w_r, self.table)

    def _sigma_grazing(self) -> np.ndarray:
        """``σ`` at θ = π/2: ``∫ (cos Δφ)₊ r P dh̃`` (limit of Eq. 3)."""
        if self.table_isotropic:
            return np.array(2.0 * np.sum(self.w_r * self.r * self.table))
        n = self.n_phi
        dphi = self.phi[:, None] - self.phi[None, :]  # (i, j)
        kern = np.maximum(np.cos(dphi), 0.0) * (2.0 * np.pi / n)
        return np.einsum("ij,kj,k->i", kern, self.table, self.w_r * self.r)

    # -- unit-roughness lookups --------------------------------------------------------------
    def _p_unit_polar(self, r, phi=None) -> np.ndarray:
        """P of the unit-roughness table at radial slope ``r`` and normal azimuth ``phi``."""
        theta = np.arctan(r)
        u = np.sqrt(theta * (2.0 / np.pi))
        if self.table_isotropic:
            val = np.exp(_hermite(self._lu, self._llogp, self._ldlogp, u) - 2.0 * np.log1p(r * r))
            with np.errstate(divide="ignore", over="ignore"):
                tail = self._p_last * (self._r_last / np.maximum(r, self._r_last)) ** 4
            return np.where(u > self._u_last, tail, val)
        n = self.n_phi
        x = np.mod(phi, 2.0 * np.pi) / (2.0 * np.pi) * n
        j0 = np.floor(x).astype(np.int64) % n
        j1 = (j0 + 1) % n
        f = x - np.floor(x)
        v0 = _hermite(self._lu, self._llogp, self._ldlogp, u, j0)
        v1 = _hermite(self._lu, self._llogp, self._ldlogp, u, j1)
        val = ((1.0 - f) * np.exp(v0) + f * np.exp(v1)) / (1.0 + r * r) ** 2  # linear in φ
        with np.errstate(divide="ignore", over="ignore"):
            tail = (((1.0 - f) * self._p_last[j0] + f * self._p_last[j1])
                    * (self._r_last / np.maximum(r, self._r_last)) ** 4)
        return np.where(u > self._u_last, tail, val)

    def _p_radial_dense(self, r) -> np.ndarray:
        """Fast approximate ``P(r)`` of an isotropic table (sampling tables only): linear
        interpolation of ``log P`` on a dense uniform ``u`` grid (8192 cells)."""
        m = 8192
        if getattr(self, "_pdense", None) is None:
            ug = np.linspace(0.0, 1.0, m + 1)
            ug[-1] = 1.0 - 1e-12
            pg = self._p_unit_polar(np.tan(0.5 * np.pi * ug**2))
            self._pdense = np.log(np.maximum(pg, 1e-300))
        u = np.sqrt(np.arctan(r) * (2.0 / np.pi))
        x = u * m
        i0 = np.minimum(x.astype(np.int64), m - 1)
        f = x - i0
        t = self._pdense
        return np.exp(t[i0] + f * (t[i0 + 1] - t[i0]))

    def _sigma_unit(self, w) -> np.ndarray:
        """σ of the unit-roughness table for directions ``w`` (any length, z ≥ 0)."""
        w = np.asarray(w, dtype=np.float64)
        rho = np.hypot(w[..., 0], w[..., 1])
        theta = np.arctan2(rho, w[..., 2])
        u = np.sqrt(np.clip(theta, 0.0, np.pi / 2) * (2.0 / np.pi))
        norm = np.sqrt(rho * rho + w[..., 2] ** 2)
        m = self._sig_m
        xu = u * m
        i0 = np.minimum(xu.astype(np.int64), m - 1)
        fu = xu - i0
        tab = self._sig_dense
        if self.table_isotropic:
            return norm * (tab[i0] + fu * (tab[i0 + 1] - tab[i0]))
        phi = np.arctan2(w[..., 1], w[..., 0])
        n = self.n_phi
        x = np.mod(phi, 2.0 * np.pi) / (2.0 * np.pi) * n
        j0 = np.minimum(x.astype(np.int64), n - 1)
        j1 = (j0 + 1) % n
        f = x - j0
        v0 = tab[i0, j0] + fu * (tab[i0 + 1, j0] - tab[i0, j0])
        v1 = tab[i0, j1] + fu * (tab[i0 + 1, j1] - tab[i0, j1])
        return norm * ((1.0 - f) * v0 + f * v1)

    # -- SlopeDistribution API (roughness-scaled, Eq. 9) ------------------------------------
    def _alphas(self):
        return (np.asarray(self.alpha_x, dtype=np.float64),
                np.asarray(self.alpha_y, dtype=np.float64))

    def pdf(self, slopes) -> np.ndarray:
        """Slope PDF ``P(x̃/αx, ỹ/αy)/(αx αy)`` (Eq. 9) at slopes ``(..., 2)``."""
        s = np.asarray(slopes, dtype=np.float64)
        ax, ay = self._alphas()
        x = s[..., 0] / ax
        y = s[..., 1] / ay
        r = np.hypot(x, y)
        phi = None if self.table_isotropic else np.arctan2(-y, -x)
        return self._p_unit_polar(r, phi) / (ax * ay)

    def D(self, m) -> np.ndarray:
        """NDF ``D(m) = P(m̃) sec⁴θm`` (Eq. 7) with roughness (Eq. 9); 0 for ``m_z ≤ 0``."""
        m = np.asarray(m, dtype=np.float64)
        mz = m[..., 2]
        safe = np.where(mz > 0, mz, 1.0)
        slopes = -m[..., :2] / safe[..., None]
        return np.where(mz > 0, self.pdf(slopes) / safe**4, 0.0)

    def sigma(self, w) -> np.ndarray:
        """Projected area ``σ(w)`` (Eq. 3 denominator), with roughness by stretching."""
        w = np.asarray(w, dtype=np.float64)
        ax, ay = self._alphas()
        ws = np.stack(np.broadcast_arrays(w[..., 0] * ax, w[..., 1] * ay, w[..., 2]), axis=-1)
        ns = np.linalg.norm(ws, axis=-1)
        # σ_α(w) = cos θw (1 + Λ1(w*)), Λ1(w*) = σ1(w*)/cos θ* − 1  (stretch invariance)
        cz = np.maximum(w[..., 2], 0.0)
        cs = np.where(ns > 0, ws[..., 2] / np.where(ns > 0, ns, 1.0), 1.0)
        sig1 = self._sigma_unit(ws / np.where(ns > 0, ns, 1.0)[..., None])
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.where(cs > 0, sig1 / np.where(cs > 0, cs, 1.0) - 1.0, np.inf)
            out = cz * (1.0 + lam)
        # grazing (cos = 0): σ = σ1 of the stretched horizontal direction times |w*|/|w|-ish
        graz = (cz <= 0) & (w[..., 2] >= 0)
        return np.where(graz, sig1 * ns, np.where(cz > 0, out, 0.0))

    def Lambda(self, w) -> np.ndarray:
        """Smith ``Λ(w) = σ(w)/cos θw − 1`` (so ``G1 = 1/(1 + Λ)``, Eq. 3)."""
        w = np.asarray(w, dtype=np.float64)
        ax, ay = self._alphas()
        ws = np.stack(np.broadcast_arrays(w[..., 0] * ax, w[..., 1] * ay, w[..., 2]), axis=-1)
        ns = np.linalg.norm(ws, axis=-1)
        ok = ws[..., 2] > 0
        wn = ws / np.where(ns > 0, ns, 1.0)[..., None]
        sig1 = self._sigma_unit(wn)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = sig1 / np.where(ok, wn[..., 2], 1.0) - 1.0
        return np.where(ok, np.maximum(lam, 0.0), np.inf)

    # -- sampling ----------------------------------------------------------------------------
    def prepare_sampling(self) -> None:
        """Build the sampling tables now (the polar quantile tables and, for an isotropic
        table, the visible-slope tables; 10-15 ms). They are otherwise built by the first
        :meth:`sample`, :meth:`sample_visible` or :meth:`sigma_visible`: a fit that is only
        saved or evaluated never needs them (the fit file stores the slope table only)."""
        if self.table_isotropic:
            self._visible_tables()
        self._sampling_tables()

    def _sampling_tables(self):
        """Polar quantile tables (Appendix A, polar form) for sampling slopes from P."""
        if self._sampling is not None:
            return self._sampling
        m = 2048
        uu = np.linspace(0.0, 1.0, m + 1)
        uu[-1] = 1.0 - 1e-9
        theta = 0.5 * np.pi * uu**2
        r = np.tan(theta)
        jac = np.pi * uu / np.cos(theta) ** 2 * r  # r dr/du
        if self.table_isotropic:
            dens = self._p_unit_polar(r) * jac * 2.0 * np.pi
            cdf = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(uu))])
            cdf /= cdf[-1]
            self._sampling = (uu, cdf, None, None, None, None)
        else:
            n = self.n_phi
            phis = self.phi
            pp = self._p_unit_polar(r[:, None], phis[None, :])  # (m+1, n)
            row = pp.mean(axis=1) * 2.0 * np.pi  # ∫ P dφ (periodic trapezoid)
            dens = row * jac
            cdf = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(uu))])
            cdf /= cdf[-1]
            # conditional φ | u: piecewise-linear P in φ, periodic; CDF over n+1 nodes
            pe = np.concatenate([pp, pp[:, :1]], axis=1)
            seg = 0.5 * (pe[:, 1:] + pe[:, :-1])
            ccdf = np.concatenate([np.zeros((m + 1, 1)), np.cumsum(seg, axis=1)], axis=1)
            tot = ccdf[:, -1:]
            ccdf = np.where(tot > 0, ccdf / np.where(tot > 0, tot, 1.0),
                            np.linspace(0, 1, n + 1)[None, :])
            # the r-weighted law r·P (proposal of anisotropic visible-normal sampling): same
            # conditional in φ, marginal in u weighted by r
            dens_r = dens * r
            cdf_r = np.concatenate([[0.0], np.cumsum(0.5 * (dens_r[1:] + dens_r[:-1]) * np.diff(uu))])
            e_r = cdf_r[-1] / np.sum(0.5 * (dens[1:] + dens[:-1]) * np.diff(uu))
            cdf_r /= cdf_r[-1]
            self._sampling = (uu, cdf, ccdf, pp, cdf_r, float(e_r))
        return self._sampling

    def sample(self, u) -> np.ndarray:
        """Slopes distributed with :meth:`pdf` (Appendix A quantile transform, polar form)."""
        u = np.asarray(u, dtype=np.float64)
        r, phi = self._sample_polar(u, r_weighted=False)
        ax, ay = self._alphas()
        # normal azimuth φ -> slope -r (cos φ, sin φ); scale by α (Eq. 9)
        return np.stack([-r * np.cos(phi) * ax, -r * np.sin(phi) * ay], axis=-1)

    def _sample_polar(self, u, r_weighted=False):
        """``(r, φ)`` of the unit table from ``P`` (or from ``r·P`` if ``r_weighted``)."""
        uu, cdf, ccdf, pnode, cdf_r, _ = self._sampling_tables()
        uv = np.interp(u[..., 0], cdf_r if r_weighted else cdf, uu)
        r = np.tan(0.5 * np.pi * uv**2)
        if self.table_isotropic:
            phi = 2.0 * np.pi * u[..., 1]
        else:
            n = self.n_phi
            x = np.interp(uv, uu, np.arange(len(uu)))
            i0 = np.clip(np.floor(x).astype(np.int64), 0, len(uu) - 2)
            f = x - i0
            rows = (1.0 - f)[..., None] * ccdf[i0] + f[..., None] * ccdf[i0 + 1]
            k = np.sum(rows <= u[..., 1:2], axis=-1) - 1
            k = np.clip(k, 0, n - 1)
            lo = np.take_along_axis(rows, k[..., None], -1)[..., 0]
            hi = np.take_along_axis(rows, (k + 1)[..., None], -1)[..., 0]
            # the density is linear in φ inside a cell: invert its quadratic CDF exactly
            dens = (1.0 - f)[..., None] * pnode[i0] + f[..., None] * pnode[i0 + 1]
            dens = np.concatenate([dens, dens[..., :1]], axis=-1)
            p0 = np.take_along_axis(dens, k[..., None], -1)[..., 0]
            p1 = np.take_along_axis(dens, (k + 1)[..., None], -1)[..., 0]
            c = np.clip(u[..., 1] - lo, 0.0, None) / np.where(hi > lo, hi - lo, 1.0) * 0.5 * (p0 + p1)
            dp = p1 - p0
            with np.errstate(invalid="ignore", divide="ignore"):
                tq = (-p0 + np.sqrt(np.maximum(p0 * p0 + 2.0 * dp * c, 0.0))) / dp
            tl = np.where(p0 > 0, c / np.where(p0 > 0, p0, 1.0), 0.5)
            frac = np.where(np.abs(dp) > 1e-12 * np.maximum(p0 + p1, 1e-300), tq, tl)
            phi = (k + np.clip(frac, 0, 1)) * (2.0 * np.pi / n)
        return r, phi

    def sample_normal(self, u) -> np.ndarray:
        """Normals distributed with ``D(m) cos θm`` (slopes from :meth:`sample`, Eq. 6)."""
        return slope_to_normal(self.sample(u))

    def _visible_tables(self):
        """Tables for visible-slope sampling of an isotropic P (Heitz & d'Eon 2014).

        In the frame where ``w = (sin θ, 0, cos θ)`` the visible slope density is
        ``cos θ (1 − x̃ tan θ)₊ P(x̃, ỹ) / σ(w)``: the marginal in ``x̃`` needs the cumulative
        moments ``A0(x) = ∫ P1`` and ``A1(x) = ∫ x P1`` of the marginal ``P1(x̃)``, and
        ``ỹ | x̃`` follows ``P(x̃, ỹ)/P1(x̃)`` independently of ``w``.
        """
        if self._visible is not None:
            return self._visible
        m = 320
        v = np.linspace(0.0, 1.0, m + 1)[:-1] + 0.5 / m  # avoid the pole at v = 1
        v = np.concatenate([[0.0], v])  # |slope| ≤ tan(89.8°): the mass beyond is negligible
        ygrid = np.tan(0.5 * np.pi * v**2)  # ≥ 0, dense near 0
        xpos = ygrid
        rr = np.hypot(xpos[:, None], ygrid[None, :])
        pv = self._p_radial_dense(rr)  # (Mx, My)
        # conditional CDF of |ỹ| given |x̃| (trapezoid in y)
        dy = np.diff(ygrid)
        seg = 0.5 * (pv[:, 1:] + pv[:, :-1]) * dy[None, :]
        cum = np.concatenate([np.zeros((len(xpos), 1)), np.cumsum(seg, axis=1)], axis=1)
        half = cum[:, -1]  # P1(x)/2
        cond = cum / np.where(half > 0, half, 1.0)[:, None]
        cond[half <= 0] = np.linspace(0, 1, len(ygrid))[None, :]
        p1 = 2.0 * half
        # marginal on the full x line
        x = np.concatenate([-xpos[::-1], xpos[1:]])
        p1f = np.concatenate([p1[::-1], p1[1:]])
        dx = np.diff(x)
        a0 = np.concatenate([[0.0], np.cumsum(0.5 * (p1f[1:] + p1f[:-1]) * dx)])
        xp1 = x * p1f
        a1 = np.concatenate([[0.0], np.cumsum(0.5 * (xp1[1:] + xp1[:-1]) * dx)])
        tot = a0[-1]
        a0 /= tot
        a1 /= tot
        cond = np.clip(cond, 0.0, 1.0)
        self._visible = (x, a0, a1, xpos, ygrid, cond)
        return self._visible

    def _sample_visible_unit(self, t, u1, u2):
        """Visible slopes of the unit-roughness isotropic table for ``tan θ = t`` (φ = 0)."""
        x, a0, a1, xpos, ygrid, cond = self._visible_tables()
        with np.errstate(divide="ignore"):
            xstar = np.where(t > 0, 1.0 / np.where(t > 0, t, 1.0), np.inf)
        xc = np.minimum(xstar, x[-1])
        a0s = np.interp(xc, x, a0)
        a1s = np.interp(xc, x, a1)
        total = a0s - t * a1s
        target = u1 * total
        # binary search for the first grid index whose clamped CDF exceeds the target
        lo = np.zeros(t.shape, dtype=np.int64)
        hi = np.full(t.shape, len(x) - 1, dtype=np.int64)
        for _ in range(int(np.ceil(np.log2(len(x)))) + 1):
            mid = (lo + hi) // 2
            fm = np.where(x[mid] < xc, a0[mid] - t * a1[mid], total)
            go = fm < target
            lo = np.where(go, mid, lo)
            hi = np.where(go, hi, mid)
        k0 = np.clip(lo, 0, len(x) - 2)
        x0 = x[k0]
        x1 = np.minimum(x[k0 + 1], xc)
        f0 = a0[k0] - t * a1[k0]
        f1 = np.where(x[k0 + 1] < xc, a0[k0 + 1] - t * a1[k0 + 1], total)
        frac = np.where(f1 > f0, (target - f0) / np.where(f1 > f0, f1 - f0, 1.0), 0.5)
        xs = x0 + np.clip(frac, 0.0, 1.0) * np.maximum(x1 - x0, 0.0)
        # ỹ | x̃ from the conditional table (rows at |x̃|), sign from u2
        sgn = np.where(u2 < 0.5, -1.0, 1.0)
        uy = np.where(u2 < 0.5, 1.0 - 2.0 * u2, 2.0 * u2 - 1.0)
        ax_ = np.abs(xs)
        xi = np.interp(ax_, xpos, np.arange(len(xpos)))
        i0 = np.clip(np.floor(xi).astype(np.int64), 0, len(xpos) - 2)
        f = xi - i0
        ny = len(ygrid)
        lo = np.zeros(t.shape, dtype=np.int64)
        hi = np.full(t.shape, ny - 1, dtype=np.int64)
        for _ in range(int(np.ceil(np.log2(ny))) + 1):
            mid = (lo + hi) // 2
            cm = (1.0 - f) * cond[i0, mid] + f * cond[i0 + 1, mid]
            go = cm < uy
            lo = np.where(go, mid, lo)
            hi = np.where(go, hi, mid)
        k = np.clip(lo, 0, ny - 2)
        c0 = (1.0 - f) * cond[i0, k] + f * cond[i0 + 1, k]
        c1 = (1.0 - f) * cond[i0, k + 1] + f * cond[i0 + 1, k + 1]
        fr = np.where(c1 > c0, (uy - c0) / np.where(c1 > c0, c1 - c0, 1.0), 0.5)
        ys = ygrid[k] + np.clip(fr, 0.0, 1.0) * (ygrid[k + 1] - ygrid[k])
        return xs, sgn * ys

    def sigma_visible(self, w) -> np.ndarray:
        """Normaliser of :meth:`sample_visible` (isotropic tables): ``cos θw · N(t*)`` with
        ``N(t) = ∫ (1 − x̃ t)₊ P = A0(1/t) − t A1(1/t)`` from the sampler's own cumulative
        moments (:meth:`_visible_tables`) and ``t*`` the tangent of the roughness-stretched
        direction. :meth:`sigma` comes from the fit quadrature of Eq. 3 on the table nodes,
        which is not the integral of the interpolated ``D``: for a GGX-shaped table the two
        differ by 0.8 % at θ = 30° and 2.8 % at 80°, and using σ in the visible-normal pdf
        biased importance-sampled albedos by as much (furnace test)."""
        if not self.table_isotropic:
            return super().sigma_visible(w)
        w = np.asarray(w, dtype=np.float64)
        ax, ay = self._alphas()
        cz = w[..., 2]
        up = cz > 0
        t = np.hypot(w[..., 0] * ax, w[..., 1] * ay) / np.where(up, cz, 1.0)
        x, a0, a1 = self._visible_tables()[:3]
        with np.errstate(divide="ignore"):
            xc = np.minimum(np.where(t > 0, 1.0 / np.where(t > 0, t, 1.0), np.inf), x[-1])
        total = np.interp(xc, x, a0) - t * np.interp(xc, x, a1)
        return np.where(up, np.where(up, cz, 0.0) * total, 0.0)

    def sample_visible(self, w, u) -> np.ndarray:
        """Visible normals for direction ``w`` (Heitz & d'Eon 2014), isotropic tables.

        Uses the stretch invariance for roughness (αx, αy): sample the unit table for the
        stretched direction, then scale the slopes. (Anisotropic tables override this with
        a rejection sampler.)
        """
        if not self.table_isotropic:
            raise NotImplementedError("visible-normal sampling is only tabulated for isotropic P")
        w = np.asarray(w, dtype=np.float64)
        u = np.asarray(u, dtype=np.float64)
        ax, ay = self._alphas()
        shape = np.broadcast_shapes(w.shape[:-1], u.shape[:-1], ax.shape, ay.shape)
        w = np.broadcast_to(w, shape + (3,))
        u = np.broadcast_to(u, shape + (2,))
        wx = w[..., 0] * ax
        wy = w[..., 1] * ay
        wz = np.maximum(w[..., 2], 1e-12)
        rho = np.hypot(wx, wy)
        t = rho / wz
        cphi = np.where(rho > 0, wx / np.where(rho > 0, rho, 1.0), 1.0)
        sphi = np.where(rho > 0, wy / np.where(rho > 0, rho, 1.0), 0.0)
        xs, ys = self._sample_visible_unit(t, u[..., 0], u[..., 1])
        sx = cphi * xs - sphi * ys
        sy = sphi * xs + cphi * ys
        return slope_to_normal(np.stack([sx * ax, sy * ay], axis=-1))

    # -- moments (Appendix C) ---------------------------------------------------------------
    def slope_moments(self) -> dict[str, float]:
        """Slope moments of the roughness-scaled P (Appendix C), by the table's quadrature.

        Returns ``E|x̃|, E|ỹ|, E x̃², E ỹ², E x̃ỹ`` and ``b1 = E[x̃ỹ/(x̃²+ỹ²)]``,
        ``b2 = E[ỹ²/(x̃²+ỹ²)]``. Requires scalar roughness.
        """
        ax, ay = (float(np.asarray(a)) for a in self._alphas())
        r, w = self.r, self.w_r
        if self.table_isotropic:
            p = self.table
            m1 = 4.0 * np.sum(w * p * r)  # ∫|cos φ| dφ = 4
            m2 = np.pi * np.sum(w * p * r**2)  # ∫cos² φ dφ = π
            ex, ey, exx, eyy, exy, b1, b2 = m1, m1, m2, m2, 0.0, 0.0, 0.5
        else:
            n = self.n_phi
            p = self.table
            cphi, sphi = np.cos(self.phi), np.sin(self.phi)  # slope = -r(cos, sin): signs cancel
            wq = w[:, None] * p * (2.0 * np.pi / n)
            ex = np.sum(wq * r[:, None] * np.abs(cphi)[None, :])
            ey = np.sum(wq * r[:, None] * np.abs(sphi)[None, :])
            exx = np.sum(wq * r[:, None] ** 2 * cphi[None, :] ** 2)
            eyy = np.sum(wq * r[:, None] ** 2 * sphi[None, :] ** 2)
            exy = np.sum(wq * r[:, None] ** 2 * (cphi * sphi)[None, :])
            b1 = np.sum(wq * (cphi * sphi)[None, :])
            b2 = np.sum(wq * (sphi**2)[None, :])
        # roughness scaling x̃ → αx x̃, ỹ → αy ỹ
        if not self.table_isotropic or ax != ay:
            if self.table_isotropic:
                # isotropic table with anisotropic scaling: b1, b2 need the angular integral
                phis = np.linspace(0, 2 * np.pi, 721)[:-1]
                c, s = np.cos(phis), np.sin(phis)
                den = (ax * c) ** 2 + (ay * s) ** 2
                b1 = float(np.mean(ax * ay * c * s / den))
                b2 = float(np.mean((ay * s) ** 2 / den))
            else:
                n = self.n_phi
                p = self.table
                cphi, sphi = np.cos(self.phi), np.sin(self.phi)
                den = (ax * cphi) ** 2 + (ay * sphi) ** 2
                wq = w[:, None] * p * (2.0 * np.pi / n)
                b1 = float(np.sum(wq * (ax * ay * cphi * sphi / den)[None, :]))
                b2 = float(np.sum(wq * ((ay * sphi) ** 2 / den)[None, :]))
        return {"E|x|": float(ax * ex), "E|y|": float(ay * ey), "Exx": float(ax * ax * exx),
                "Eyy": float(ay * ay * eyy), "Exy": float(ax * ay * exy),
                "b1": float(b1), "b2": float(b2)}

    def beckmann_parameters(self) -> tuple[float, float, float]:
        """``(αx, αy, ρ)`` from the second slope moments (App. C, LEAN mapping):
        ``E x̃² = αx²/2``, ``E ỹ² = αy²/2``, ``E x̃ỹ = ραxαy/2`` (exact when P is Beckmann)."""
        m = self.slope_moments()
        ax, ay = np.sqrt(2.0 * m["Exx"]), np.sqrt(2.0 * m["Eyy"])
        return float(ax), float(ay), _clip_rho(2.0 * m["Exy"] / (ax * ay))

    def ggx_parameters(self) -> tuple[float, float, float]:
        """``(αx, αy, ρ)`` from first absolute moments and angular moments (App. C):
        ``αx = E|x̃|``, ``αy = E|ỹ|``, ``ρ = (αy/αx) b1/(b1² + b2²)`` (exact when P is GGX)."""
        m = self.slope_moments()
        ax, ay = m["E|x|"], m["E|y|"]
        b1, b2 = m["b1"], m["b2"]
        return float(ax), float(ay), _clip_rho((ay / ax) * b1 / (b1 * b1 + b2 * b2))

    def figures(self) -> dict:
        """The GGX equivalent by slope moments (:meth:`ggx_parameters`):
        ``{"alpha": [αx, αy, ρ], "alpha_kind": "ggx-equivalent"}``."""
        return {"alpha": list(self.ggx_parameters()), "alpha_kind": "ggx-equivalent"}

    # -- state -------------------------------------------------------------------------------
    def params(self) -> dict:
        ax, ay = self._alphas()
        return {"kind": "tabulated", "isotropic": self.table_isotropic, "rule": self.rule,
                "n_theta": int(self.table.shape[0]), "n_phi": int(self.n_phi),
                "alpha_x": ax.tolist(), "alpha_y": ay.tolist()}

    def to_state(self) -> tuple[dict, dict[str, np.ndarray]]:
        """``(params, arrays)``: the float32 ``P`` table, plus for isotropic tables the
        float32 ``sigma`` (G1) table of the paper's 6N-float layout, kept for external
        readers; ``σ`` is always recomputed from ``P`` on load (so evaluation is identical).
        Anisotropic files hold ``P`` only (the 2D ``σ`` would double the size)."""
        arrays = {"P": self.table.astype(np.float32)}
        if self.table_isotropic:
            arrays["sigma"] = self._sigma_table.astype(np.float32)
        return self.params(), arrays

    @classmethod
    def from_state(cls, params: dict, arrays: dict) -> "TabulatedSlopeDistribution":
        p = np.asarray(arrays["P"], dtype=np.float64)
        d = cls(p, rule=params.get("rule", "merl"), normalize=False,
                alpha_x=np.asarray(params.get("alpha_x", 1.0), dtype=np.float64),
                alpha_y=np.asarray(params.get("alpha_y", 1.0), dtype=np.float64))
        return d

    def __repr__(self) -> str:
        shape = "x".join(str(s) for s in self.table.shape)
        return f"<TabulatedSlopeDistribution {shape} rule={self.rule} iso={self.table_isotropic}>"


def _circular_kernel_apply(t, r, w_r, p) -> np.ndarray:
    """``Σ_j w_r[j] (2π/Nφ) Σ_l (1 + t_i r_j cos(φm − φl))₊ p[j, l]`` for all ``(i, m)``.

    The kernel depends on ``φm − φl`` only (circulant), so the azimuthal sum is a circular
    convolution done with real FFTs: ``O(Nθ² Nφ log Nφ)`` instead of ``O(Nθ² Nφ²)``.
    """
    n_phi = p.shape[1]
    dphi = 2.0 * np.pi * np.arange(n_phi) / n_phi
    k = np.maximum(1.0 + (t[:, None, None] * r[None, :, None]) * np.cos(dphi)[None, None, :], 0.0)
    kh = np.fft.rfft(k, axis=-1)  # (Nθ, Nθ, Nφ/2+1)
    ph = np.fft.rfft(p * w_r[:, None], axis=-1)  # (Nθ, Nφ/2+1)
    out = np.fft.irfft(np.einsum("ijm,jm->im", kh, ph), n=n_phi, axis=-1)
    return out * (2.0 * np.pi / n_phi)


class AnisotropicTabulatedSlopeDistribution(TabulatedSlopeDistribution):
    """A 2D ``(θ, φ)`` table (created by ``TabulatedSlopeDistribution(p2d)``).

    Visible normals are sampled by rejection (an extension; the paper samples ``D cos θm``
    with the quantile tables of Appendix A): the visible slope density is
    ``∝ (1 + w̃·h̃)₊ P(h̃)`` (``w̃`` the slope of ``w``), bounded by
    ``(1 + |w̃| |h̃|) P(h̃)``, a mixture of ``P`` and ``|h̃| P`` that the polar quantile
    tables sample exactly. Acceptance is 1 at normal incidence and about 1/π at grazing.
    The first proposal uses ``u``; further uniforms come from a generator seeded by a hash
    of ``u`` (deterministic for given inputs).
    """

    _MAX_ROUNDS = 64
    _VIS_NV = 193       # polar nodes (uniform in θ of the stretched direction) of σ_v
    _VIS_UP = 4         # azimuthal refinement of the table for σ_v

    def _visible_norm_table(self):
        """``S(θ*, φ*) = cos θ* ∫ (1 + tan θ* r cos(φ − φ*))₊ P`` / ``∫ P`` on a grid
        (uniform θ* in [0, π/2), φ* on the table's azimuths refined ×4), where ``P`` is the
        law :meth:`_sample_polar` draws from (dense trapezoid in u, linear in φ): the
        normaliser of the rejection sampler of :meth:`sample_visible` for a unit stretched
        direction (θ*, φ*)."""
        tab = getattr(self, "_vis_norm", None)
        if tab is not None:
            return tab
        uu, _, _, pp, _, _ = self._sampling_tables()
        theta = 0.5 * np.pi * uu**2
        r = np.tan(theta)
        wu = np.zeros_like(uu)
        du = np.diff(uu)
        wu[:-1] += 0.5 * du
        wu[1:] += 0.5 * du
        w_r = wu * np.pi * uu / np.cos(theta) ** 2 * r          # r dr = jac du, trapezoid
        n, up = self.n_phi, self._VIS_UP
        x = np.arange(n * up) / up                               # linear in φ between nodes
        i0 = np.floor(x).astype(np.int64) % n
        f = x - np.floor(x)
        p_up = (1.0 - f)[None, :] * pp[:, i0] + f[None, :] * pp[:, (i0 + 1) % n]
        ts = 0.5 * np.pi * np.linspace(0.0, 1.0, self._VIS_NV)
        ts[-1] = 0.5 * np.pi * (1.0 - 1e-7)
        out = np.empty((ts.size, n * up))
        for a in range(0, ts.size, 8):
            sl = slice(a, a + 8)
            out[sl] = _circular_kernel_apply(np.tan(ts[sl]), r, w_r, p_up) \
                * np.cos(ts[sl])[:, None]
        out /= np.sum(w_r[:, None] * p_up) * (2.0 * np.pi / (n * up))
        self._vis_norm = out
        return out

    def sigma_visible(self, w) -> np.ndarray:
        """Normaliser of the rejection sampler of :meth:`sample_visible`:
        ``cos θw · S(θ*, φ*) / cos θ*`` with (θ*, φ*) the roughness-stretched direction and
        ``S`` tabulated by :meth:`_visible_norm_table` (bilinear). σ from the node
        quadrature of Eq. 3 differs from it by up to 3 % at grazing angles (furnace test)."""
        w = np.asarray(w, dtype=np.float64)
        ax, ay = self._alphas()
        S = self._visible_norm_table()
        sx, sy, cz = w[..., 0] * ax, w[..., 1] * ay, w[..., 2]
        up = cz > 0
        rho = np.hypot(sx, sy)
        th = np.arctan2(rho, np.where(up, cz, 1.0))
        ph = np.mod(np.arctan2(sy, sx), 2.0 * np.pi)
        nv, nphi = S.shape
        xv = np.clip(th / (0.5 * np.pi) * (nv - 1), 0.0, nv - 1.000001)
        iv = np.floor(xv).astype(np.int64)
        fv = xv - iv
        xp = ph / (2.0 * np.pi) * nphi
        ip = np.floor(xp).astype(np.int64) % nphi
        fp = xp - np.floor(xp)
        ip1 = (ip + 1) % nphi
        val = ((1 - fv) * ((1 - fp) * S[iv, ip] + fp * S[iv, ip1])
               + fv * ((1 - fp) * S[iv + 1, ip] + fp * S[iv + 1, ip1]))
        cs = np.cos(th)
        return np.where(up, np.where(up, cz, 0.0) * val / np.maximum(cs, 1e-300), 0.0)

    def sample_visible(self, w, u) -> np.ndarray:
        """Visible normals for direction ``w`` (density :meth:`pdf_visible`), by rejection."""
        import hashlib

        w = np.asarray(w, dtype=np.float64)
        u = np.asarray(u, dtype=np.float64)
        ax, ay = self._alphas()
        shape = np.broadcast_shapes(w.shape[:-1], u.shape[:-1], ax.shape, ay.shape)
        w = np.broadcast_to(w, shape + (3,))
        u = np.broadcast_to(u, shape + (2,)).reshape(-1, 2)
        axb = np.broadcast_to(ax, shape).reshape(-1)
        ayb = np.broadcast_to(ay, shape).reshape(-1)
        # stretched direction (roughness invariance) and its slope w̃* = −(x, y)/z
        wz = np.maximum(w[..., 2].reshape(-1), 1e-12)
        tx = -w[..., 0].reshape(-1) * axb / wz
        ty = -w[..., 1].reshape(-1) * ayb / wz
        amp = np.hypot(tx, ty)
        e_r = self._sampling_tables()[5]
        p_r = amp * e_r / (1.0 + amp * e_r)  # probability of the r·P component
        seed = int.from_bytes(hashlib.blake2b(np.ascontiguousarray(u).tobytes() +
                                              np.ascontiguousarray(w).tobytes(),
                                              digest_size=8).digest(), "little")
        rng = np.random.default_rng(seed)
        n = u.shape[0]
        out = np.zeros((n, 2))
        todo = np.arange(n)
        uu = u
        for _ in range(self._MAX_ROUNDS):
            comp = rng.random(todo.size) < p_r[todo]
            r0, phi0 = self._sample_polar(uu, r_weighted=False)
            r1, phi1 = self._sample_polar(uu, r_weighted=True)
            r = np.where(comp, r1, r0)
            phi = np.where(comp, phi1, phi0)
            hx, hy = -r * np.cos(phi), -r * np.sin(phi)
            ratio = np.maximum(1.0 + tx[todo] * hx + ty[todo] * hy, 0.0) / (1.0 + amp[todo] * r)
            acc = rng.random(todo.size) < ratio
            last = _ == self._MAX_ROUNDS - 1
            take = acc | last
            out[todo[take], 0] = hx[take]
            out[todo[take], 1] = hy[take]
            todo = todo[~take]
            if todo.size == 0:
                break
            uu = rng.random((todo.size, 2))
        slopes = out.reshape(shape + (2,)) * np.stack([np.broadcast_to(ax, shape),
                                                       np.broadcast_to(ay, shape)], -1)
        return slope_to_normal(slopes)


class FittedFresnel(TabulatedFresnel):
    """The extracted microfacet Fresnel of a tabulated fit (Dupuy 2015 Eq. 20).

    A :class:`~brdffit.microfacet.fresnel.TabulatedFresnel` on the 90 MERL ``θd`` samples
    (``j·π/180``) whose values are stored as float32 without the implied grid (the paper's
    3N-float RGB table). For materials outside microfacet theory it is a residual function,
    not a physical Fresnel reflectance.
    """

    kind = "tabulated_merl"
    #: fit-file state: values (n, 3) (or (n,)), 2 <= n <= 8192, in [0, FRESNEL_MAX]
    state_schema = Schema({"n": Integer(ge=2, le=8192)},
                          arrays={"values": Array([("n", 3), ("n",)], ge=0, le=FRESNEL_MAX)},
                          dims={"n": (2, 8192)})

    def __init__(self, values, theta_d_grid=None):
        v = np.asarray(values, dtype=np.float32).astype(np.float64)
        grid = (np.arange(v.shape[0]) * (np.pi / 2 / v.shape[0]) if theta_d_grid is None
                else theta_d_grid)
        super().__init__(grid, v)

    def to_state(self):
        return {"n": int(self.theta_d.size)}, {"values": self.values.astype(np.float32)}

    @classmethod
    def from_state(cls, params, arrays):
        return cls(arrays["values"])

    def __repr__(self) -> str:
        return f"<FittedFresnel n={self.theta_d.size} F(0)={np.round(self.values[0], 4).tolist()}>"


def _register():
    register_fresnel(FittedFresnel.kind, FittedFresnel)

    register_distribution("tabulated", TabulatedSlopeDistribution)
    register_distribution("tabulated_aniso", AnisotropicTabulatedSlopeDistribution)


_register()
