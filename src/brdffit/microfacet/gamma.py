"""Upper incomplete gamma function Γ(s, x) for every real ``s`` (including s ≤ 0).

The Shifted Gamma Distribution (Bagher, Soler, Holzschuch 2012, §4.2) is normalised by
``Γ(1 − p, α)`` and its radial CDF (§4.5) is ``1 − Γ(1 − p, α + tan²θ/α) / Γ(1 − p, α)``.
Fitted materials have ``p > 1``, i.e. a negative first argument, where
``scipy.special.gammaincc`` (the *regularised* function, defined for s > 0 only) returns NaN.

:func:`upper_gamma` evaluates the non-regularised ``Γ(s, x) = ∫_x^∞ t^{s−1} e^{−t} dt``
(x > 0), vectorised over broadcast ``s`` and ``x``, with four branches:

* ``s ≥ 1/2``: ``scipy.special.gammaincc(s, x) · Γ(s)`` (accurate there);
* integer ``s = −n ≤ 0``: ``Γ(−n, x) = x^{−n} E_{n+1}(x)`` (``scipy.special.expn``,
  ``exp1`` for n = 0);
* ``x > 2`` (other s): Legendre's continued fraction
  ``Γ(s, x) = e^{−x} x^s / (x + 1 − s − 1(1 − s)/(x + 3 − s − 2(2 − s)/(x + 5 − s − …)))``
  evaluated with the modified Lentz algorithm;
* ``x ≤ 2`` (other s < 1/2): the series ``Γ(s, x) = Γ(s) − Σ_n (−1)^n x^{s+n} / (n! (s+n))``
  with the term whose denominator ``s + m`` is closest to 0 combined analytically with the
  pole of ``Γ(s)`` at ``−m``, so that there is no cancellation near non-positive integers
  (the same idea as Temme's ``Γ*`` / Gautschi's treatment of small ``s``):
  ``Γ(s, x) = R_m(ε) − ((−1)^m / m!) · expm1(ε ln x)/ε − Σ_{n≠m} …`` with ``ε = s + m``
  and ``R_m(ε) = Γ(s) − (−1)^m/(m! ε)`` computed from ``(Γ(1+ε) − 1)/ε`` (a Taylor series
  in ζ values). This is equivalent to the recurrence
  ``Γ(s, x) = (Γ(s+1, x) − x^s e^{−x}) / s`` but stays accurate near the poles.

Accuracy: relative error below 1e-12 against ``mpmath.gammainc`` over s ∈ [−6, 3],
x ∈ [1e-6, 300] (tests use the grid s ∈ [−4, 2], x ∈ [1e-4, 50] at 1e-10).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special

__all__ = ["upper_gamma", "upper_gamma_ratio"]

_EULER = 0.57721566490153286061
_N_ZETA = 64
# Coefficients of ln Γ(1+ε) = −γ ε + Σ_{k≥2} (−1)^k ζ(k) ε^k / k  (|ε| < 1).
_LG_COEF = np.array([0.0, -_EULER] + [(-1.0) ** k * special.zeta(k) / k for k in range(2, _N_ZETA)])
_SERIES_X_MAX = 2.0
_N_SERIES = 48
_CF_MAX_ITER = 400
_TINY = 1e-300


def _gam1(eps: np.ndarray) -> np.ndarray:
    """``(Γ(1 + ε) − 1) / ε`` for |ε| ≤ 1/2, accurate near 0 (value −γ at ε = 0).

    |ε| ≤ 0.1: Taylor series of ln Γ(1 + ε) (ζ coefficients, 20 terms, error < 1e-19);
    otherwise directly (the cancellation costs at most a factor 10 in relative accuracy).
    """
    eps = np.asarray(eps, dtype=np.float64)
    small = np.abs(eps) <= 0.1
    es = np.where(small, eps, 0.0)
    lg = np.zeros_like(eps)
    for c in _LG_COEF[20:0:-1]:          # Horner on ln Γ(1+ε) without the constant term
        lg = (lg + c) * es
    with np.errstate(invalid="ignore", divide="ignore"):
        ser = np.expm1(lg) / es
        direct = (special.gamma(1.0 + eps) - 1.0) / np.where(small, 1.0, eps)
    return np.where(eps == 0.0, -_EULER, np.where(small, ser, direct))


def _series_small_x(s: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Γ(s, x) for s < 1/2, 0 < x ≤ 2 (see module docstring), no cancellation near poles."""
    m = np.maximum(np.rint(-s), 0.0)               # nearest pole index, ε = s + m ∈ [−½, ½]
    eps = s + m
    mi = m.astype(np.int64)
    lx = np.log(x)
    # Q(ε) = ∏_{k=1}^m (ε − k), D = (Q(ε) − Q(0))/ε by the recurrence D_j = Q_{j−1} − j D_{j−1}
    q = np.ones_like(s)
    q0 = np.ones_like(s)
    d = np.zeros_like(s)
    for j in range(1, int(mi.max(initial=0)) + 1):
        act = mi >= j
        d = np.where(act, q - j * d, d)
        q = np.where(act, q * (eps - j), q)
        q0 = np.where(act, q0 * (-j), q0)
    r_m = (_gam1(eps) * q0 - d) / (q * q0)             # Γ(s) − (−1)^m / (m! ε)
    sign_m = np.where(mi % 2 == 0, 1.0, -1.0)
    inv_mfact = np.exp(-special.gammaln(m + 1.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        em = np.where(eps == 0.0, lx, np.expm1(eps * lx) / np.where(eps == 0.0, 1.0, eps))
    total = r_m - sign_m * inv_mfact * em
    # remaining terms Σ_{n≠m} (−1)^n x^{s+n} / (n! (s+n))
    xs = np.exp(s * lx)                                # x^s
    term = xs                                          # (−1)^n x^{s+n}/n!
    acc = np.zeros_like(s)
    for n in range(_N_SERIES):
        if n > 0:
            term = term * (-x / n)
        contrib = np.where(mi == n, 0.0, term / np.where(mi == n, 1.0, s + n))
        acc = acc + contrib
        if n > mi.max(initial=0) and np.all(np.abs(contrib) <= 1e-17 * np.abs(acc)):
            break
    return total - acc


def _continued_fraction(s: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Γ(s, x) by Legendre's continued fraction, modified Lentz (converges fast for x > 2)."""
    b = x + 1.0 - s
    c = np.full_like(x, 1.0 / _TINY)
    d = 1.0 / b
    h = d.copy()
    done = np.zeros(x.shape, dtype=bool)
    for i in range(1, _CF_MAX_ITER + 1):
        an = -i * (i - s)
        b = b + 2.0
        d = an * d + b
        d = np.where(np.abs(d) < _TINY, _TINY, d)
        c = b + an / c
        c = np.where(np.abs(c) < _TINY, _TINY, c)
        d = 1.0 / d
        delta = d * c
        h = np.where(done, h, h * delta)
        done |= np.abs(delta - 1.0) < 1e-16
        if done.all():
            break
    return np.exp(s * np.log(x) - x) * h


def _upper_gamma_scalar(s: float, x: float) -> float:
    """Scalar version of :func:`upper_gamma` (same branches, Python floats: ~100× faster
    than the array code for one value; used for normalisation constants inside fits)."""
    if not (x > 0) or not math.isfinite(s) or math.isinf(x):
        return float(upper_gamma(np.array([s]), np.array([x]))[0])
    if s >= 0.5:
        return float(special.gammaincc(s, x) * special.gamma(s))
    if s == round(s):
        n = int(-s)
        return float(special.exp1(x)) if n == 0 else float(special.expn(n + 1, x) * x ** (-n))
    if x > _SERIES_X_MAX:
        b = x + 1.0 - s
        c = 1.0 / _TINY
        d = 1.0 / b
        h = d
        for i in range(1, _CF_MAX_ITER + 1):
            an = -i * (i - s)
            b += 2.0
            d = an * d + b
            d = _TINY if abs(d) < _TINY else d
            c = b + an / c
            c = _TINY if abs(c) < _TINY else c
            d = 1.0 / d
            delta = d * c
            h *= delta
            if abs(delta - 1.0) < 1e-16:
                break
        return math.exp(s * math.log(x) - x) * h
    m = max(int(round(-s)), 0)
    eps = s + m
    lx = math.log(x)
    q, q0, dd = 1.0, 1.0, 0.0
    for j in range(1, m + 1):
        dd = q - j * dd
        q *= eps - j
        q0 *= -j
    if eps == 0.0:
        g1 = -_EULER
    elif abs(eps) <= 0.1:
        lg = 0.0
        for c in _LG_COEF[20:0:-1]:
            lg = (lg + c) * eps
        g1 = math.expm1(lg) / eps
    else:
        g1 = (math.gamma(1.0 + eps) - 1.0) / eps
    r_m = (g1 * q0 - dd) / (q * q0)
    em = lx if eps == 0.0 else math.expm1(eps * lx) / eps
    total = r_m - (1.0 if m % 2 == 0 else -1.0) / math.factorial(m) * em
    term = math.exp(s * lx)
    acc = 0.0
    for n in range(_N_SERIES):
        if n > 0:
            term *= -x / n
        if n == m:
            continue
        contrib = term / (s + n)
        acc += contrib
        if n > m and abs(contrib) <= 1e-17 * abs(acc):
            break
    return total - acc


def upper_gamma(s, x) -> np.ndarray:
    """Non-regularised upper incomplete gamma ``Γ(s, x) = ∫_x^∞ t^{s−1} e^{−t} dt``.

    Valid for every real ``s`` and ``x > 0`` (Bagher et al. 2012 §4.2 need ``s = 1 − p`` with
    ``p > 1``). At ``x = 0`` returns ``Γ(s)`` for ``s > 0`` and ``inf`` for ``s ≤ 0``; NaN for
    ``x < 0`` or NaN input. Inputs broadcast; returns float64 of the broadcast shape.
    """
    if np.ndim(s) == 0 and np.ndim(x) == 0:
        return np.float64(_upper_gamma_scalar(float(s), float(x)))
    s, x = np.broadcast_arrays(np.asarray(s, dtype=np.float64), np.asarray(x, dtype=np.float64))
    shape = s.shape
    s = s.ravel()
    x = x.ravel()
    out = np.full(s.shape, np.nan)

    pos = (x > 0) & np.isfinite(s)
    big_s = pos & (s >= 0.5)
    out[big_s] = special.gammaincc(s[big_s], x[big_s]) * special.gamma(s[big_s])

    integer = pos & ~big_s & (s == np.rint(s))
    if integer.any():
        n = (-s[integer]).astype(np.int64)
        xi = x[integer]
        out[integer] = np.where(n == 0, special.exp1(xi),
                                special.expn(n + 1, xi) * np.exp(-n * np.log(xi)))

    rest = pos & ~big_s & ~integer
    cf = rest & (x > _SERIES_X_MAX)
    if cf.any():
        out[cf] = _continued_fraction(s[cf], x[cf])
    ser = rest & ~cf
    if ser.any():
        out[ser] = _series_small_x(s[ser], x[ser])

    zero = (x == 0) & np.isfinite(s)
    out[zero] = np.where(s[zero] > 0, special.gamma(np.where(s[zero] > 0, s[zero], 1.0)), np.inf)
    out[np.isposinf(x)] = 0.0
    return out.reshape(shape)


def upper_gamma_ratio(s, x, x0) -> np.ndarray:
    """``Γ(s, x) / Γ(s, x0)`` (the complementary radial CDF of the SGD, Bagher 2012 §4.5)."""
    return upper_gamma(s, x) / upper_gamma(s, x0)
