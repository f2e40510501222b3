"""The Shifted Gamma Distribution (SGD) of Bagher, Soler & Holzschuch 2012.

Paper: *Accurate fitting of measured reflectances using a Shifted Gamma micro-facet
distribution*, CGF 31(4), 2012 (``../shared/papers/004_*.txt``).

Definitions (x = tan²θm = |slope|²)
------------------------------------
Eq. 8 and §4.2 give ``P22(x) = K e^{−x/α} / (x + α²)^p`` normalised so that
``D(θm) = P22(tan²θm) / (π cos⁴θm)`` integrates to 1 against ``cos θm dωm``, which yields

    P22(x) = α^{p−1} / Γ(1−p, α) · e^{−(α² + x)/α} / (α² + x)^p            (§4.2)

with the *upper incomplete* gamma function ``Γ(s, a) = ∫_a^∞ t^{s−1} e^{−t} dt``
(derivation: substitute ``t = (α² + x)/α``; then ``∫_0^∞ P22 dx = 1``). Writing
``t = α + x/α`` it simplifies to ``P22 = t^{−p} e^{−t} / (α Γ(1−p, α))``. In the slope-space
convention of :class:`~brdffit.microfacet.base.SlopeDistribution` (a pdf on R², Dupuy 2015
Eq. 7: ``D = P(m̃)/cos⁴θm``) the slope pdf is ``P(x̃, ỹ) = P22(x̃² + ỹ²)/π`` (this is the
paper's Eq. 2 ``P22``, which integrates to 1/π over [0, ∞)). ``p`` may be any real number
(fitted MERL materials have ``p`` up to ≈ 2.5, i.e. ``1 − p < 0``): Γ(1 − p, α) is computed
by :func:`brdffit.microfacet.gamma.upper_gamma`. Note that α is *not* a pure scale
parameter (Dupuy 2015 Eq. 9 does not apply): the SGD is a genuine 2-parameter family.

Radial CDF (§4.5): ``P(tan²θm ≤ x) = 1 − Γ(1−p, α + x/α) / Γ(1−p, α)``; :meth:`SGD.sample`
inverts it with a tabulated inverse (in logit/log coordinates) refined by Newton steps.

Smith shadowing (§4.3, Eq. 6)
-----------------------------
Eq. 6 writes ``Λ(θ) = ∫_{1/tanθ}^∞ (r tanθ − 1) P2(r) dr`` with the 1D marginal
``P2(r) = ∫ P22(r² + q²) dq`` (closed form with Tricomi's U in §4.3). Integrating the marginal
in polar coordinates instead gives the equivalent single integral (μ = cot θ)

    μ Λ(μ) = ∫_{μ²}^∞ P(x) (√(x − μ²) − μ arccos(μ/√x)) dx,

where ``P`` is the slope pdf at radius² ``x``. We evaluate it with the trapezoidal rule in
``u = ln(x − μ²)`` (the integrand is analytic in a strip around the real u axis and decays
exponentially at both ends, so the rule converges geometrically; 0.2 spacing gives ≈ 1e-13
relative accuracy). ``μΛ(μ)`` is stored as a table over ``ln μ`` (cubic spline of its log)
and ``Λ = table/μ``, ``G1 = 1/(1 + Λ)``. :meth:`SGD.g1_approximation` fits the paper's
closed-form approximation (Eq. 9, parameters λ, c, k, θ0) to the table.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy import interpolate, optimize, special

from ..schema import ALPHA_MAX, ALPHA_MIN, P_EXPONENT_MAX, Number, Schema
from .base import SlopeDistribution
from .gamma import upper_gamma
from .model import register_distribution

__all__ = ["SGD", "SGDApproxG1", "g1_eq9", "sgd_log_p22", "sgd_mu_lambda"]

_H_LOG = 0.2             # trapezoid spacing in u = ln(x − μ²)
_N_TABLE = 384           # nodes of the μΛ(μ) table (log μ)
_N_INV = 4096            # nodes of the tabulated inverse radial CDF
_N_G1 = 1024             # θ nodes used for G1 tables / the Eq. 9 approximation fit


def _check(alpha: float, p: float) -> tuple[float, float]:
    alpha = float(alpha)
    p = float(p)
    if not (np.isfinite(alpha) and alpha > 0):
        raise ValueError(f"SGD alpha must be finite and > 0, found {alpha!r}")
    if not np.isfinite(p):
        raise ValueError(f"SGD p must be finite, found {p!r}")
    return alpha, p


def _log_norm(alpha, p):
    """``ln(α Γ(1−p, α))`` (the log normaliser of P22 written in ``t = α + x/α``)."""
    return np.log(alpha) + np.log(upper_gamma(1.0 - np.asarray(p, float), alpha))


def sgd_log_p22(x, alpha, p, log_norm=None) -> np.ndarray:
    """``ln P22(x)`` with the paper's normalisation (∫_0^∞ P22 dx = 1, Bagher 2012 §4.2).

    ``P22(x) = t^{−p} e^{−t} / (α Γ(1−p, α))`` with ``t = α + x/α``; broadcasts over
    ``x``, ``alpha``, ``p`` (vectorised for the fits). ``log_norm`` may pass a precomputed
    ``ln(α Γ(1−p, α))``.
    """
    x = np.asarray(x, dtype=np.float64)
    alpha = np.asarray(alpha, dtype=np.float64)
    t = alpha + x / alpha
    return -p * np.log(t) - t - (_log_norm(alpha, p) if log_norm is None else log_norm)


def _z_minus_arctan(z):
    """``z − arctan z`` without cancellation for small ``z`` (≥ 0)."""
    z = np.asarray(z, dtype=np.float64)
    small = z < 0.1
    zs = np.where(small, z, 0.0)
    z2 = zs * zs
    ser = zs * z2 * (1 / 3 - z2 * (1 / 5 - z2 * (1 / 7 - z2 * (1 / 9 - z2 * (1 / 11 - z2 / 13)))))
    return np.where(small, ser, z - np.arctan(z))


def sgd_mu_lambda(mu, alpha, p, h: float = _H_LOG, log_norm=None,
                  small_z_series: bool = True) -> np.ndarray:
    """``μ Λ(μ)`` of the SGD for ``μ = cot θ ≥ 0`` by quadrature of Eq. 6 (see module doc).

    Vectorised over ``mu`` (1D/any shape; ``alpha``, ``p`` scalars). At ``μ = 0`` the value
    is ``E[|slope|]/π`` (so ``Λ ~ E|x̃| / (2μ)`` at grazing angles). ``log_norm``: see
    :func:`sgd_log_p22`.

    ``small_z_series=False`` evaluates the integrand's ``z − arctan z`` (``z = √y/μ``)
    directly, in half the passes over the nodes, for callers that need ``μΛ`` against
    ``μ`` (``G1 = μ/(μ + μΛ)``: the fits): where it cancels (``z ≪ 1``, rounding
    ≈ 3e-16/z² relative) it is ≈ ``z³/3`` and weighs little in the sum, except where ``P``
    makes ``μΛ`` itself ``e^{−μ²/α}``-small; even there (``μ² ≤ 745 α``, beyond it ``P``
    underflows) the integrand peaks at ``z ≥ 0.058``, so ``μΛ`` keeps ≈ 1e-13 relative
    accuracy (2e-13 at most against the series over 1,200 random (α, p, h) sets of up to
    400 μ). The SGD's own table of ``ln μΛ`` keeps the series.
    """
    if not small_z_series:
        return _mu_lambda_direct(mu, alpha, p, h, log_norm)
    alpha, p = _check(alpha, p)
    shape = np.shape(mu)
    mu, mu2, u, y_hi = _log_nodes(mu, alpha, p, h)
    y = np.exp(u)
    y = np.where(y <= y_hi * 1.0000001, y, np.nan)     # nodes past the cut-off contribute 0
    x = mu2 + y
    logp = sgd_log_p22(x, alpha, p, log_norm) - np.log(np.pi)    # slope pdf (∫_R² = 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.sqrt(y) / np.where(mu > 0, mu, 1.0)
        g = np.where(mu > 0, mu * _z_minus_arctan(z), np.sqrt(y))
    f = np.exp(logp) * g * y
    f = np.where(np.isfinite(f), f, 0.0)
    return (h * f.sum(axis=1)).reshape(shape)


def _log_nodes(mu, alpha: float, p: float, h: float):
    """``(μ as a column, μ², u, y_hi)``: the trapezoid nodes ``u = ln y`` of Eq. 6 per μ (a
    row each, from ``y_lo = 1e-13 min(α, α² + μ²)`` in steps ``h``, up to past the cut-off
    ``y_hi = α (62 + 4|p|)`` where ``P`` is below e^−62 of its peak)."""
    mu = np.asarray(mu, dtype=np.float64).ravel()[:, None]
    mu2 = mu * mu
    y_lo = 1e-13 * np.minimum(alpha, alpha * alpha + mu2)
    y_hi = alpha * (62.0 + 4.0 * abs(p))
    n = int(np.ceil(np.log(y_hi / y_lo.min()) / h)) + 1
    return mu, mu2, np.log(y_lo) + np.arange(n)[None, :] * h, y_hi


def _mu_lambda_direct(mu, alpha, p, h, log_norm) -> np.ndarray:
    """:func:`sgd_mu_lambda` with ``z − arctan z`` evaluated directly, the passes in place."""
    alpha, p = _check(alpha, p)
    shape = np.shape(mu)
    mu, mu2, u, y_hi = _log_nodes(mu, alpha, p, h)
    u[u > np.log(y_hi * 1.0000001)] = -np.inf        # nodes past the cut-off: y = 0, no weight
    y = np.exp(u)
    # the slope pdf P22(x)/π (∫_R² = 1) at x = μ² + y, in the form of sgd_log_p22
    t = alpha + (mu2 + y) / alpha
    f = np.log(t)
    f *= -p
    f -= t
    f -= (_log_norm(alpha, p) if log_norm is None else log_norm) + np.log(np.pi)
    np.exp(f, out=f)
    f *= y
    root_y = np.sqrt(y)
    if np.all(mu > 0):
        z = root_y / mu
        z -= np.arctan(z)
        z *= mu
        f *= z
    else:                                             # μ = 0: the integrand's limit √y
        with np.errstate(divide="ignore", invalid="ignore"):
            z = root_y / np.where(mu > 0, mu, 1.0)
            f *= np.where(mu > 0, mu * (z - np.arctan(z)), root_y)
    total = f.sum(axis=1)
    bad = ~np.isfinite(total)
    if bad.any():                                     # e.g. overflow at extreme (α, p)
        rows = f[bad]
        total[bad] = np.where(np.isfinite(rows), rows, 0.0).sum(axis=1)
    return (h * total).reshape(shape)


#: largest Eq. 9 ``c`` a fit produces or a fit file may hold: any finite c gives G1 in [0, 1]
#: (θ0 follows from c), and 1e30 stays finite in the float32 GLSL export; mirror-like MERL
#: SGDs reach ~5e18 (k = 50 at w = π/2 − θ0 ≈ 0.45)
EQ9_C_MAX = 1e30


def g1_eq9(theta, lam: float, c: float, k: float) -> np.ndarray:
    """Bagher 2012 Eq. 9: ``G1 ≈ 1 + λ(1 − exp(c (θ − θ0)^k))`` for θ > θ0, else 1.

    ``θ0 = π/2 − (ln(1 + 1/λ)/c)^{1/k}`` so that ``G1(π/2) = 0``; 0 beyond π/2.
    """
    theta = np.asarray(theta, dtype=np.float64)
    theta0 = np.pi / 2 - (np.log1p(1.0 / lam) / c) ** (1.0 / k)
    d = np.clip(theta - theta0, 0.0, None)
    g = 1.0 + lam * (1.0 - np.exp(c * d**k))
    g = np.where(theta > theta0, g, 1.0)
    return np.where(theta < np.pi / 2, np.clip(g, 0.0, 1.0), 0.0)


def _g1_eq9_jacobian(theta: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``∂ G1≈ / ∂q`` of :func:`g1_eq9` in the parameters ``q = (ln λ, ln w, ln k)`` of
    :meth:`SGD.g1_approximation` (``w = π/2 − θ0``, ``c = ln(1 + 1/λ)/w^k``), ``(n, 3)``.

    With ``L = ln(1 + 1/λ)``, ``r = (θ − θ0)/w`` and ``E = exp(L r^k)`` (``= exp(c (θ−θ0)^k)``):
    ``∂/∂ln λ = λ(1 − E) + λ E L r^k / ((λ + 1) L)``,
    ``∂/∂ln w = −λ E k L r^k (1 − r)/r``, ``∂/∂ln k = −λ E k L r^k ln r``;
    0 where Eq. 9 is constant (θ ≤ θ0, θ ≥ π/2) or clipped to [0, 1].
    """
    lam, w, k = np.exp(q)
    log_term = np.log1p(1.0 / lam)
    d = theta - (np.pi / 2 - w)
    inside = (d > 0) & (theta < np.pi / 2)
    r = np.where(inside, d, w) / w
    c_dk = log_term * r**k
    e = np.exp(c_dk)
    g = 1.0 + lam * (1.0 - e)
    jac = np.stack([lam * (1.0 - e) + lam * e * c_dk / ((lam + 1.0) * log_term),
                    -lam * e * k * c_dk * (1.0 - r) / r,
                    -lam * e * k * c_dk * np.log(r)], axis=-1)
    return np.where((inside & (g > 0.0) & (g < 1.0))[:, None], jac, 0.0)


def _refit_over_cap(solve, c_of, best, over):
    """The best admissible Eq. 9 fit of :meth:`SGD.g1_approximation`: a start that wanted
    ``c = ln(1+1/λ)/w^k`` > :data:`EQ9_C_MAX` (``over``; the sharp G1 edge of mirror-like
    SGDs) is refitted with ``solve(x0, k_max)``, k capped so that ``c`` (``c_of``) stays
    representable at its w, up to 4 times while it beats ``best``; returns ``best`` or the
    better refit."""
    for _ in range(4):
        if over is None or (best is not None and best.cost <= over.cost):
            break
        lam, w, _k = np.exp(over.x)
        if w >= 1.0:
            break
        k_cap = 0.95 * np.log(EQ9_C_MAX / np.log1p(1.0 / lam)) / np.log(1.0 / w)
        if not k_cap > 0.05:
            break
        x0 = over.x.copy()
        x0[2] = np.log(min(np.exp(x0[2]), 0.99 * k_cap))
        res = solve(x0, k_cap)
        if res is None:
            break
        if c_of(res.x) <= EQ9_C_MAX:
            if best is None or res.cost < best.cost:
                best = res
            break
        over = res
    return best

class SGD(SlopeDistribution):
    """Shifted Gamma micro-facet Distribution (Bagher, Soler, Holzschuch 2012, §4.2-4.3).

    Parameters
    ----------
    alpha:
        α > 0: the shift α² in ``(x + α²)^{-p}`` and the scale of the exponential tail
        ``e^{−x/α}`` (x = tan²θm).
    p:
        Exponent of the ``(x + α²)^{−p}`` peak (any real; p > 1 gives very sharp peaks).

    Smith Λ/G1 use a table of Eq. 6 built lazily on first use; :meth:`g1_table` returns it
    over θ, :meth:`g1_approximation` fits the paper's Eq. 9 to it.
    """

    isotropic = True
    kind = "sgd"              # component kind in microfacet.model's registry (fit files)
    #: fit-file state: α in (0, ALPHA_MAX], |p| <= P_EXPONENT_MAX (fits use −2 <= p <= 4)
    state_schema = Schema({"alpha": Number(ge=ALPHA_MIN, le=ALPHA_MAX),
                           "p": Number(ge=-P_EXPONENT_MAX, le=P_EXPONENT_MAX)},
                          required=("alpha", "p"), strict=True)

    def __init__(self, alpha: float, p: float):
        self.alpha, self.p = _check(alpha, p)
        self._gamma_norm = float(upper_gamma(1.0 - self.p, self.alpha))
        if not (np.isfinite(self._gamma_norm) and self._gamma_norm > 0):
            raise ValueError(f"SGD normalisation Γ(1−p, α) is not finite for α={self.alpha}, "
                             f"p={self.p}")
        self._log_norm = np.log(self.alpha) + np.log(self._gamma_norm) + np.log(np.pi)

    # -- slope space --------------------------------------------------------------------------
    def p22(self, x) -> np.ndarray:
        """Paper's ``P22(x)`` (§4.2, ∫_0^∞ P22 dx = 1) at ``x = tan²θm``."""
        return np.exp(sgd_log_p22(x, self.alpha, self.p))

    def pdf(self, slopes) -> np.ndarray:
        """Slope pdf ``P(x̃, ỹ) = P22(x̃² + ỹ²)/π`` (integrates to 1 over R²)."""
        s = np.asarray(slopes, dtype=np.float64)
        x = s[..., 0] ** 2 + s[..., 1] ** 2
        t = self.alpha + x / self.alpha
        return np.exp(-self.p * np.log(t) - t - self._log_norm)

    def D_theta(self, theta) -> np.ndarray:
        """``D(θm) = P22(tan²θm)/(π cos⁴θm)`` for θm in [0, π/2), 0 beyond (§4.2)."""
        theta = np.asarray(theta, dtype=np.float64)
        ok = (theta >= 0) & (theta < np.pi / 2)
        c = np.cos(np.where(ok, theta, 0.0))
        x = np.tan(np.where(ok, theta, 0.0)) ** 2
        t = self.alpha + x / self.alpha
        return np.where(ok, np.exp(-self.p * np.log(t) - t - self._log_norm) / c**4, 0.0)

    def D(self, m) -> np.ndarray:
        """Normal distribution ``D(m)`` (Dupuy 2015 Eq. 7 / Bagher 2012 §4.2)."""
        m = np.asarray(m, dtype=np.float64)
        mz = m[..., 2]
        ok = mz > 0
        mzs = np.where(ok, mz, 1.0)
        x = (m[..., 0] ** 2 + m[..., 1] ** 2) / mzs**2
        t = self.alpha + x / self.alpha
        with np.errstate(over="ignore"):
            return np.where(ok, np.exp(-self.p * np.log(t) - t - self._log_norm) / mzs**4, 0.0)

    def cdf_tan2(self, x) -> np.ndarray:
        """Radial CDF ``P(tan²θm ≤ x) = 1 − Γ(1−p, α + x/α)/Γ(1−p, α)`` (§4.5, F_θ)."""
        x = np.asarray(x, dtype=np.float64)
        return 1.0 - upper_gamma(1.0 - self.p, self.alpha + np.maximum(x, 0.0) / self.alpha) \
            / self._gamma_norm

    @functools.cached_property
    def _inverse_table(self):
        """Tabulated inverse of the radial CDF: logit(u) → ln(t − α)."""
        a, s = self.alpha, 1.0 - self.p
        lo = np.log(1e-14 * a)                  # y = t − α; t^{−p} varies on the scale α
        hi = np.log(80.0 + 4.0 * abs(self.p))   # e^{−t} decays on the scale 1
        ly = np.linspace(lo, hi, _N_INV)
        y = np.exp(ly)
        surv = upper_gamma(s, a + y) / self._gamma_norm
        # ln u and ln(1 − u) without cancellation: u = ∫_α^{α+y} τ^{s−1}e^{−τ}dτ / Γ(s, α);
        # the survival is accurate where u is not tiny; near 0 use u ≈ y·density(α)·(...)
        cdf = 1.0 - surv
        dens0 = np.exp((s - 1.0) * np.log(a) - a) / self._gamma_norm
        small = cdf < 1e-6
        # second-order expansion for tiny y: u ≈ dens0 (y + (s−1−a)/(2a) y²)
        cdf = np.where(small, dens0 * (y + (s - 1.0 - a) / (2 * a) * y * y), cdf)
        keep = (cdf > 0) & (surv > 0)
        logit = np.log(cdf[keep]) - np.log(surv[keep])
        logit, idx = np.unique(logit, return_index=True)
        return interpolate.PchipInterpolator(logit, ly[keep][idx], extrapolate=True)

    def _invert_t(self, u: np.ndarray, refine: bool = False) -> np.ndarray:
        """``t = α + tan²θm/α`` with radial CDF ``u``.

        Tabulated inverse (4096 PCHIP nodes in logit(u) → ln(t − α), CDF error ≈ 1e-9);
        ``refine`` adds two Newton steps on ``ln Γ(1−p, t)`` (≈ 1e-15, 5× slower).
        """
        a, s = self.alpha, 1.0 - self.p
        u = np.clip(np.asarray(u, dtype=np.float64), 1e-300, 1.0 - 1e-16)
        logit = np.log(u) - np.log1p(-u)
        t = a + np.exp(self._inverse_table(logit))
        target = np.log1p(-u) + np.log(self._gamma_norm)          # ln Γ(s, t) wanted
        newton = u > 1e-5                                          # ln Γ form well-conditioned
        for _ in range(2 if refine else 0):
            g = upper_gamma(s, t)
            lg = np.log(np.maximum(g, 1e-300))
            dlg = -np.exp((s - 1.0) * np.log(t) - t - lg)          # d ln Γ(s, t)/dt
            step = (lg - target) / dlg
            t_new = np.clip(t - step, a + 0.5 * (t - a), a + 2.0 * (t - a) + 1.0)
            t = np.where(newton & np.isfinite(t_new), t_new, t)
        return t

    def sample(self, u) -> np.ndarray:
        """Slopes distributed with :meth:`pdf` from uniform ``u`` (..., 2).

        ``u[..., 0]`` picks ``tan²θm`` by inverting the radial CDF of §4.5 (numerically: the
        paper notes there is no closed-form inverse), ``u[..., 1]`` the azimuth ``2π u``.
        """
        u = np.asarray(u, dtype=np.float64)
        t = self._invert_t(u[..., 0])
        r = np.sqrt(np.maximum(self.alpha * (t - self.alpha), 0.0))
        phi = 2.0 * np.pi * u[..., 1]
        return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)

    # -- shadowing -----------------------------------------------------------------------------
    def mu_lambda_exact(self, mu) -> np.ndarray:
        """``μ Λ(μ)`` by direct quadrature of Eq. 6 (no table)."""
        return sgd_mu_lambda(mu, self.alpha, self.p)

    @functools.cached_property
    def _lambda_table(self):
        """(μ_lo, μ_hi, F0, spline of ln(μΛ) over ln μ) — Eq. 6 tabulated."""
        m2 = self.second_moment_closed_form()
        scale = np.sqrt(min(m2, self.alpha)) if m2 > 0 else np.sqrt(self.alpha)
        mu_lo = 1e-5 * scale
        mu_hi = max(np.sqrt(self.alpha * (60.0 + 4.0 * abs(self.p))), 20.0 * np.sqrt(m2))
        lmu = np.linspace(np.log(mu_lo), np.log(mu_hi), _N_TABLE)
        vals = sgd_mu_lambda(np.concatenate([[0.0], np.exp(lmu)]), self.alpha, self.p)
        f0, f = vals[0], np.maximum(vals[1:], 1e-300)
        spline = interpolate.CubicSpline(lmu, np.log(f))
        return mu_lo, mu_hi, f0, spline, f[0]

    def mu_lambda(self, mu) -> np.ndarray:
        """``μ Λ(μ)`` from the stored table (Eq. 6); exact 0 beyond the table's end."""
        mu = np.asarray(mu, dtype=np.float64)
        mu_lo, mu_hi, f0, spline, f_lo = self._lambda_table
        inside = (mu >= mu_lo) & (mu <= mu_hi)
        lm = np.log(np.clip(mu, mu_lo, mu_hi))
        val = np.exp(spline(lm))
        near0 = f0 + (f_lo - f0) * np.clip(mu, 0.0, None) / mu_lo
        return np.where(inside, val, np.where(mu < mu_lo, near0, 0.0))

    def Lambda(self, w) -> np.ndarray:
        """Smith Λ(w) (Eq. 6) from the table; ``inf`` at or below the horizon."""
        w = np.asarray(w, dtype=np.float64)
        cz = w[..., 2]
        sxy = np.sqrt(w[..., 0] ** 2 + w[..., 1] ** 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            mu = np.where(sxy > 0, cz / np.where(sxy > 0, sxy, 1.0), np.inf)
            lam = np.where(np.isinf(mu), 0.0, self.mu_lambda(np.where(np.isinf(mu), 0, mu))
                           / np.where(np.isinf(mu) | (mu == 0), 1.0, mu))
        return np.where(cz > 0, lam, np.inf)

    def G1_theta(self, theta, exact: bool = False) -> np.ndarray:
        """``G1(θ) = 1/(1 + Λ(cot θ))`` for θ in [0, π/2), 0 from π/2 on (Eq. 6)."""
        theta = np.asarray(theta, dtype=np.float64)
        ok = (theta >= 0) & (theta < np.pi / 2)
        th = np.where(ok, theta, 0.0)
        s, c = np.sin(th), np.cos(th)
        mu = c / np.where(s > 0, s, 1.0)
        # exact: μΛ is needed against μ only, the direct integrand does (sgd_mu_lambda)
        f = (sgd_mu_lambda(mu, self.alpha, self.p, small_z_series=False) if exact
             else self.mu_lambda(mu))
        with np.errstate(invalid="ignore", divide="ignore"):
            g = np.where(s > 0, mu / (mu + f), 1.0)       # 1/(1 + Λ), Λ = f/μ
        return np.where(ok, g, 0.0)

    def g1_table(self, n: int = _N_G1) -> tuple[np.ndarray, np.ndarray]:
        """``(θ, G1(θ))`` on ``n`` uniform θ in [0, π/2] from exact quadrature of Eq. 6."""
        theta = np.linspace(0.0, np.pi / 2, n)
        return theta, self.G1_theta(theta, exact=True)

    def g1_approximation(self, n: int = 512) -> dict:
        """Fit Bagher 2012 Eq. 9 ``(λ, c, k, θ0)`` to the G1 table (bounded TRF least squares).

        Returns ``{"lambda", "c", "k", "theta0", "l2", "rms", "mse", "max_abs"}`` where
        ``l2`` is ``(∫_0^{π/2} (G1 − G1≈)² dθ)^{1/2}`` on the uniform table, ``rms`` the
        root-mean-square and ``mse`` the mean-square error over the ``n`` table nodes,
        ``max_abs`` the largest absolute error. The paper's "L2 error mostly below 1e-5"
        (§4.3, Fig. 5) does not say which of these it is; ``mse`` is the one that matches its
        magnitude (rms is typically 1e-4..5e-4 for specular SGDs: Eq. 9 cannot do better).
        Several starts (bounded TRF); never raises.
        """
        theta, g = self.g1_table(n)
        # Parameterisation: (ln λ, ln w, ln k) with w = π/2 − θ0 and c = ln(1+1/λ)/w^k
        below = np.nonzero(g < 1.0 - 1e-6)[0]
        w0 = np.pi / 2 - theta[below[0]] if below.size else 1e-3
        w0 = float(np.clip(w0, 1e-6, np.pi / 2))

        def model(q):
            lam, w, k = np.exp(q)
            c = np.log1p(1.0 / lam) / w**k
            return g1_eq9(theta, lam, c, k)

        def c_of(q):
            lam, w, k = np.exp(q)
            with np.errstate(over="ignore", divide="ignore"):
                return np.log1p(1.0 / lam) / w**k

        def solve(q0, k_max):
            try:
                return optimize.least_squares(
                    lambda q: model(q) - g, q0, jac=lambda q: _g1_eq9_jacobian(theta, q),
                    method="trf",
                    bounds=(np.log([1e-6, 1e-7, 0.05]), np.log([1e6, np.pi / 2, k_max])),
                    xtol=1e-12, ftol=1e-14, gtol=1e-14, max_nfev=150)
            except (ValueError, FloatingPointError):
                return None

        best, over = None, None                      # best admissible / best over the cap
        for lam0, kk in ((0.01, 2.0), (0.3, 4.0), (3.0, 8.0)):
            res = solve(np.log([lam0, w0, kk]), 50.0)
            if res is None:
                continue
            if not c_of(res.x) <= EQ9_C_MAX:
                over = res if over is None or res.cost < over.cost else over
                continue
            if best is None or res.cost < best.cost:
                best = res
            if 2.0 * best.cost / len(theta) < 1e-7:     # mse already at the paper's level
                break
        best = _refit_over_cap(solve, c_of, best, over)
        if best is None:                              # never reached on real SGDs
            best = type("Flat", (), {"x": np.log([1e-6, np.pi / 2, 1.0])})()
        lam, w, k = np.exp(best.x)
        c = np.log1p(1.0 / lam) / w**k
        err = model(best.x) - g
        dtheta = theta[1] - theta[0]
        return {"lambda": float(lam), "c": float(c), "k": float(k),
                "theta0": float(np.pi / 2 - w),
                "l2": float(np.sqrt(np.sum(err**2) * dtheta)),
                "rms": float(np.sqrt(np.mean(err**2))),
                "mse": float(np.mean(err**2)),
                "max_abs": float(np.max(np.abs(err)))}

    # -- moments ------------------------------------------------------------------------------
    def second_moment_closed_form(self) -> float:
        """``E[tan²θm] = E[x̃² + ỹ²] = α (Γ(2−p, α)/Γ(1−p, α) − α)`` (from t = α + x/α)."""
        g2 = float(upper_gamma(2.0 - self.p, self.alpha))
        return float(self.alpha * (g2 / self._gamma_norm - self.alpha))

    def slope_moments(self) -> dict[str, float]:
        """Slope moments by numerical quadrature of the radial density (Dupuy 2015 App. C).

        ``E|x̃| = (2/π) E r``, ``E x̃² = E r²/2`` (isotropy), ``E x̃ỹ = 0``. Both radial moments
        are integrated numerically in ``u = ln x`` (trapezoid, as for Λ).
        """
        a, p, h = self.alpha, self.p, _H_LOG
        lo, hi = np.log(1e-14 * min(a, a * a)), np.log(a * (62.0 + 4.0 * abs(p)))
        x = np.exp(np.arange(lo, hi + h, h))
        w = np.exp(sgd_log_p22(x, a, p)) * x * h          # P22(x) dx in u = ln x
        er = float(np.sum(w * np.sqrt(x)))
        er2 = float(np.sum(w * x))
        return {"E|x|": 2.0 / np.pi * er, "E|y|": 2.0 / np.pi * er,
                "Exx": er2 / 2.0, "Eyy": er2 / 2.0, "Exy": 0.0}

    def params(self) -> dict:
        return {"alpha": self.alpha, "p": self.p}

    def __repr__(self) -> str:
        return f"SGD(alpha={self.alpha:.6g}, p={self.p:.6g})"

    def __eq__(self, other) -> bool:
        return isinstance(other, SGD) and other.alpha == self.alpha and other.p == self.p

    def __hash__(self) -> int:
        return hash(("SGD", self.alpha, self.p))


class SGDApproxG1(SGD):
    """SGD whose Smith G1 is the closed-form approximation of Bagher 2012 **Eq. 9**.

    ``G1(θ) ≈ 1 + λ(1 − exp(c (θ − θ0)^k))`` for θ > θ0 (1 below); the paper uses it for GPU
    rendering instead of the stored table. ``Λ = 1/G1 − 1``. Parameters as returned by
    :meth:`SGD.g1_approximation` (``lambda``, ``c``, ``k``).
    """

    kind = "sgd_eq9"
    #: fit-file state: the SGD's α, p and Eq. 9's λ <= 1e6, c <= EQ9_C_MAX, k <= 1e3 (all > 0)
    state_schema = Schema({"alpha": Number(ge=ALPHA_MIN, le=ALPHA_MAX),
                           "p": Number(ge=-P_EXPONENT_MAX, le=P_EXPONENT_MAX),
                           "lam": Number(gt=0, le=1e6), "c": Number(gt=0, le=EQ9_C_MAX),
                           "k": Number(gt=0, le=1e3)},
                          required=("alpha", "p", "lam", "c", "k"), strict=True)

    def __init__(self, alpha: float, p: float, lam: float, c: float, k: float):
        super().__init__(alpha, p)
        self.lam, self.c, self.k = float(lam), float(c), float(k)
        if not all(np.isfinite(v) and v > 0 for v in (self.lam, self.c, self.k)):
            raise ValueError(f"SGDApproxG1: λ, c, k must be finite and > 0, found "
                             f"{(self.lam, self.c, self.k)}")

    def G1_theta(self, theta, exact: bool = False) -> np.ndarray:
        if exact:
            return super().G1_theta(theta, exact=True)
        return g1_eq9(theta, self.lam, self.c, self.k)

    def Lambda(self, w) -> np.ndarray:
        w = np.asarray(w, dtype=np.float64)
        cz = w[..., 2]
        theta = np.arccos(np.clip(cz, -1.0, 1.0))
        g = self.G1_theta(theta)
        with np.errstate(divide="ignore"):
            return np.where((cz > 0) & (g > 0), 1.0 / np.where(g > 0, g, 1.0) - 1.0, np.inf)

    def params(self) -> dict:
        return {"alpha": self.alpha, "p": self.p, "lam": self.lam, "c": self.c, "k": self.k}

    def __repr__(self) -> str:
        return (f"SGDApproxG1(alpha={self.alpha:.6g}, p={self.p:.6g}, lam={self.lam:.6g}, "
                f"c={self.c:.6g}, k={self.k:.6g})")

    def __eq__(self, other) -> bool:
        return isinstance(other, SGDApproxG1) and other.params() == self.params()

    def __hash__(self) -> int:
        return hash(("SGDApproxG1",) + tuple(self.params().values()))


# the fit-file kinds of these distributions (brdffit.microfacet.model)
register_distribution("sgd", SGD)
register_distribution("sgd_eq9", SGDApproxG1)
