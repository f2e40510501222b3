"""AWLS solvers of Bagher, Snyder & Nowrouzezahrai 2016 (§4.2-4.3).

All state is channel-first: ``D, F, G`` (3, 90), ``H`` (3, 180), ``rho_d, rho_s`` (3,).
The three colour channels are independent problems solved side by side.

Sufficient statistics. For fixed G, every sample of bin (θh, θd) enters the D, F, ρd, ρs
updates and the objective only through ``S1 = Σ w P``, ``S2 = Σ w P²``, ``Spz = Σ w P z``
(``P = G(θi) G(θo)/(cos θi cos θo)``) and the G-independent ``Σ w``, ``Σ w z``, ``Σ w z²``.
One pass over the samples (:func:`._kernels.p_stats`) per change of G therefore replaces the
per-factor passes; the D and F updates (Eq. 14) and Cramer's rule (Eq. 15-18) are then sums
over the 90 × 90 bins. G updates need a second pass (:func:`._kernels.g_normal_equations`).

Stopping rule (all variants): stop after ``patience`` (3) consecutive iterations whose
relative decrease of the total objective ``(E_prev − E)/E`` is below ``tol``, or when
``E ≤ 1e-14 · Σ w ρ*²`` (exact fit), or after ``max_iter`` iterations. Independent-G's
continuation of the best start also stops when the relative decrease over the last ``W``
iterations, ``(E_{k−W} − E_k)/E_k``, is below ``W · k · tol`` (``window = (W, k)``: the
mean decrease per iteration has fallen below ``k · tol``; :class:`Monitor`). The
Levenberg–Marquardt polish (:func:`polish_lm`) stops after 2 such iterations, when no damped
step lowers the objective, or after its own cap.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import solve_banded
from scipy.ndimage import gaussian_filter1d

from ...losses.objective import ObjectiveData
from ...schema import FACTOR_MAX
from ...microfacet.npf_model import smith_g_curvature, smith_g_from_d, smith_g_jacobian
from . import _kernels

NH = ND = NG = 90
NP = 180
#: independent-G G step (:func:`line_search_g`): largest step along the AWLS G update and
#: over-relaxation factor ω of the exact line-search minimiser (ω = 1.9: the lowest objective
#: after a fixed number of iterations among 1-2 on MERL materials; docs/design/npf-fit.md)
G_STEP_CAP = 4.0
G_OVER_RELAX = 1.9
#: results kept per channel by :meth:`Samples.stats` (an exact re-use: the same inputs)
STATS_MEMO = 2
#: G-from-D's D step: growth of the fraction of the step tried next after an accepted trial
#: (:func:`_g_from_d_d_step`; docs/design/npf-fit.md)
D_STEP_GROWTH = 1.25


@dataclass
class Samples:
    """Per-sample precomputation, built once per fit (see :mod:`._kernels`)."""

    hd: np.ndarray
    ip: np.ndarray
    gi0: np.ndarray
    gti: np.ndarray
    go0: np.ndarray
    gto: np.ndarray
    inv_cc: np.ndarray
    w: np.ndarray
    z: np.ndarray
    sum_w: np.ndarray = field(default=None)
    sum_wz: np.ndarray = field(default=None)
    sum_wzz: np.ndarray = field(default=None)

    e_offset: np.ndarray = field(default=None)
    _memo: list = field(default=None, repr=False, compare=False)

    @classmethod
    def from_objective(cls, data: ObjectiveData, fold: bool = True) -> "Samples":
        """Per-sample arrays; with ``fold`` the samples at φd and π − φd (which have the same
        θh, θd and swapped θi, θo, hence the same value of the reciprocal model Eq. 3) are
        merged into one with weight ``w1 + w2`` and measurement ``(w1 z1 + w2 z2)/(w1 + w2)``.
        Eq. 7 then changes only by a constant (kept in ``e_offset``), and every weighted
        least-squares update is unchanged, for half the work."""
        w = np.ascontiguousarray(data.w, dtype=np.float64)
        z = np.ascontiguousarray(data.z, dtype=np.float64)
        index, cos_i, cos_o = data.index, data.cos_i, data.cos_o
        sum_wzz = (w * z * z).sum(axis=1)
        if fold:
            ih, idd, ip = np.unravel_index(index, (NH, ND, NP))
            ipc = np.where(ip > NP // 2, NP - ip, ip)            # φd → min(φd, π − φd)
            key = (ih * ND + idd) * (NP // 2 + 1) + ipc
            # np.unique without its sort: the keys index a table of every (θh, θd, φd ≤ π/2)
            present = np.zeros(NH * ND * (NP // 2 + 1), dtype=bool)
            present[key] = True
            uniq = np.flatnonzero(present)
            inv = (np.cumsum(present) - 1)[key]
            W = np.stack([np.bincount(inv, weights=w[c], minlength=uniq.size) for c in range(3)])
            WZ = np.stack([np.bincount(inv, weights=w[c] * z[c], minlength=uniq.size)
                           for c in range(3)])
            z = np.where(W > 0, WZ / np.where(W > 0, W, 1.0), 0.0)
            w = W
            # geometry of the representative: cos θi/θo are swapped within a pair, so take
            # each unique key's first member and keep its own cosines
            first = np.full(uniq.size, -1, dtype=np.int64)
            first[inv[::-1]] = np.arange(inv.size)[::-1]
            index, cos_i, cos_o = index[first], cos_i[first], cos_o[first]
        ih, idd, ip = np.unravel_index(index, (NH, ND, NP))
        hd = (ih * ND + idd).astype(np.int64)

        def cell(cos):  # noqa: E306
            deg = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
            i0 = np.minimum(np.floor(deg), NG - 2).astype(np.int64)
            return i0, np.clip(deg - i0, 0.0, 1.0)

        gi0, gti = cell(cos_i)
        go0, gto = cell(cos_o)
        w = np.ascontiguousarray(w, dtype=np.float64)
        z = np.ascontiguousarray(z, dtype=np.float64)
        s = cls(hd=hd, ip=ip.astype(np.int64), gi0=gi0, gti=gti, go0=go0, gto=gto,
                inv_cc=1.0 / (cos_i * cos_o), w=w, z=z)
        s.sum_w = w.sum(axis=1)
        s.sum_wz = (w * z).sum(axis=1)
        s.sum_wzz = sum_wzz
        s.e_offset = np.maximum(sum_wzz - (w * z * z).sum(axis=1), 0.0)
        return s

    def stats(self, G, X, rho_d, chans=None):
        """One pass: ``(E, (S1, S2, Spz))`` for G (3, 90), X = ρs D F (3, 8100), for the
        channels in ``chans`` (3 bools, default all; the others' E is NaN and sums 0).
        A channel's result for the same ``G[c]``, ``X[c]``, ``ρd[c]`` as one of its last
        :data:`STATS_MEMO` results is that result (the kernel is deterministic and the
        channels independent): only the other asked channels are passed over."""
        G, X, rho_d = (np.ascontiguousarray(a, dtype=np.float64) for a in (G, X, rho_d))
        asked = np.ones(3, bool) if chans is None else np.asarray(chans, bool)
        keys = [G[c].tobytes() + X[c].tobytes() + rho_d[c].tobytes() for c in range(3)]
        memo = self._memo if self._memo is not None else [[], [], []]
        self._memo = memo
        hits = [next((r for k, r in memo[c] if k == keys[c]), None) if asked[c] else None
                for c in range(3)]
        todo = asked & np.array([h is None for h in hits])
        S1, S2, Spz = (np.zeros((3, NH * ND)) for _ in range(3))
        E = np.full(3, np.nan)
        if todo.any():
            E[todo] = _kernels.p_stats(self.hd, self.gi0, self.gti, self.go0, self.gto,
                                       self.inv_cc, self.w, self.z, G, X, rho_d, S1, S2,
                                       Spz, todo)[todo] + self.e_offset[todo]
        for c in range(3):
            if hits[c] is not None:
                E[c], S1[c], S2[c], Spz[c] = hits[c]
            elif todo[c]:
                memo[c] = ([(keys[c], (E[c], S1[c].copy(), S2[c].copy(), Spz[c].copy()))]
                           + memo[c])[:STATS_MEMO]
        return E, (S1, S2, Spz)

    def line_stats(self, G, dG, chans=None):
        """One pass: the bin statistics along ``G + t dG`` as polynomials in t, (3, 8100, 11)
        (see :func:`._kernels.p_stats_line`), for the channels in ``chans`` (3 bools, default
        all; the others' are 0)."""
        Q = np.empty((3, NH * ND, 11))
        _kernels.p_stats_line(self.hd, self.gi0, self.gti, self.go0, self.gto, self.inv_cc,
                              self.w, self.z, np.ascontiguousarray(G, dtype=np.float64),
                              np.ascontiguousarray(dG, dtype=np.float64), Q, _chans(chans))
        return Q

    def g_system(self, G, X, rho_d, chans=None):
        """One pass: the G normal equations of :func:`._kernels.g_normal_equations` for the
        channels in ``chans`` (default all; the others' are 0)."""
        arrs = [np.empty((3, NG)), np.empty((3, NG)), np.empty((3, NG)),
                np.empty((3, NG)), np.empty((3, NG)), np.empty((3, NG))]
        _kernels.g_normal_equations(self.hd, self.gi0, self.gti, self.go0, self.gto,
                                    self.inv_cc, self.w, self.z,
                                    np.ascontiguousarray(G, dtype=np.float64),
                                    np.ascontiguousarray(X, dtype=np.float64),
                                    np.ascontiguousarray(rho_d, dtype=np.float64), *arrs,
                                    _chans(chans))
        return arrs


def _chans(chans) -> np.ndarray:
    """The channel mask of a pass: 3 bools, all for ``None``."""
    return np.ones(3, bool) if chans is None else np.asarray(chans, bool)


# -- shared algebra ---------------------------------------------------------------------------
def outer_df(D, F):
    return (D[:, :, None] * F[:, None, :]).reshape(3, NH * ND)


def ls_update(num, den, old):
    """Eq. 14 per component; components without data (den ≈ 0) keep their old value."""
    ok = den > 1e-300 * np.maximum(den.max(axis=1, keepdims=True), 1e-300)
    ok &= den > 0
    return np.where(ok, num / np.where(ok, den, 1.0), old)


def normalise(factor, rho_s, eps, power=1):
    """Max-normalise (max = 1), ρs absorbing ``max**power``; then clamp at ``eps`` (§4.3)."""
    m = factor.max(axis=1)
    good = m > 0
    m = np.where(good, m, 1.0)
    out = factor / m[:, None]
    out = np.maximum(out, eps)
    return out, rho_s * m**power


def cramer(sw, sx, sxx, sy, sxy):
    """ρd, ρs from Eq. 16-17, with the a < 0 clamp of Eq. 18 (also applied when b ≤ 0)."""
    det = sw * sxx - sx * sx
    okd = det > 1e-14 * np.maximum(sw * sxx, 1e-300)
    a = np.where(okd, (sy * sxx - sx * sxy) / np.where(okd, det, 1.0), -1.0)
    b = np.where(okd, (sw * sxy - sx * sy) / np.where(okd, det, 1.0), 0.0)
    # a < 0 (Eq. 18), and also b <= 0 (a vanishing specular term would stall the factor
    # updates, whose Eq. 14 denominators are proportional to ρs²): a = 0, b = Σwxy/Σwx² ≥ 0
    neg = (a < 0) | (b <= 0)
    b1 = np.where(sxx > 0, sxy / np.where(sxx > 0, sxx, 1.0), 0.0)
    a = np.where(neg, 0.0, a)
    b = np.where(neg, b1, b)
    return a, np.maximum(b, 0.0)


class Monitor:
    """Objective history and the documented stopping rule; ``window = (W, k)`` adds the
    windowed rule (relative decrease over the last ``W`` iterations below ``W · k · tol``)."""

    def __init__(self, ref_energy, tol, max_iter, patience=3, window=None):
        self.ref = float(np.sum(ref_energy))
        self.tol = tol
        self.max_iter = max_iter
        self.patience = patience
        self.window = window
        self.history: list[float] = []
        self.small = 0
        self.reason = "max_iter"

    def push(self, E) -> bool:
        """Record the objective; return True when the fit should stop."""
        e = float(np.sum(E))
        prev = self.history[-1] if self.history else None
        self.history.append(e)
        if not np.isfinite(e):
            self.reason = "non-finite objective"
            return True
        if e <= 1e-14 * self.ref:
            self.reason = "exact fit"
            return True
        if prev is not None:
            rel = (prev - e) / max(e, 1e-300)
            self.small = self.small + 1 if rel < self.tol else 0
            if self.small >= self.patience:
                self.reason = f"relative decrease < {self.tol:g} for {self.patience} iterations"
                return True
        if self.window is not None and len(self.history) > self.window[0]:
            n_win, factor = self.window
            old = self.history[-1 - n_win]
            limit = n_win * factor * self.tol
            if (old - e) / max(e, 1e-300) < limit:
                self.reason = f"relative decrease < {limit:g} over the last {n_win} iterations"
                return True
        if len(self.history) > self.max_iter:         # history[0] is the start
            self.reason = "max_iter"
            return True
        return False


def parabolic_search(fun, need, e0, e1, aux1, max_eval=2, t_first=0.5, max_total=8,
                     min_t=0.01):
    """Per-channel line search of ``t ∈ (0, 1]`` for the channels in ``need``, whose full
    step (``t = 1``, objective ``e1``, auxiliary data ``aux1``) increased the objective
    ``e0 = E(0)``: successive parabolic interpolation (Press et al. 2007 §10.3), the first
    trial at ``t_first``, each next one the vertex of the parabola through the best three
    points evaluated (``0`` and ``1`` included). A channel stops after ``max_eval``
    evaluations once it has found a decrease; until then the trials shrink (at most a quarter
    of the smallest failed one) until a trial below ``min_t`` has failed (the step is then
    not a descent direction: t = 0) or ``max_total`` evaluations. ``fun(t, active) ->
    (E, aux)`` evaluates the channels still searching (``active``); the others' values are
    not used (a channel, once finished, stays finished), so ``fun`` may skip them.
    Returns ``(t, E, aux, n_eval)`` of the best point; t = 0 where nothing beat ``e0``."""
    pts_t = [np.zeros(3), np.ones(3)]
    pts_e = [np.asarray(e0, dtype=np.float64), np.asarray(e1, dtype=np.float64)]
    best_t = np.where(need, 0.0, 1.0)
    best_e = np.where(need, e0, e1)
    best_aux = aux1
    smallest_failed = np.ones(3)
    t_next = np.clip(np.broadcast_to(np.asarray(t_first, dtype=np.float64), (3,)), 1e-6, 1.0)
    active = np.array(need, dtype=bool)
    n_eval = 0
    while np.any(active) and n_eval < max_total:
        tt = np.where(active, t_next, best_t)
        E, aux = fun(tt, active.copy())
        E = np.where(active, E, best_e)
        n_eval += 1
        better = active & (E < best_e)
        best_aux = tuple(np.where(better[:, None], x, y) if np.ndim(x) == 2 else
                         np.where(better, x, y) for x, y in zip(aux, best_aux))
        best_t = np.where(better, tt, best_t)
        best_e = np.where(better, E, best_e)
        smallest_failed = np.where(active & (E >= e0), np.minimum(smallest_failed, tt),
                                   smallest_failed)
        pts_t.append(tt)
        pts_e.append(np.asarray(E, dtype=np.float64))
        active &= ~((best_t > 0) & (n_eval >= max_eval))
        active &= ~((best_t == 0) & (smallest_failed < min_t))   # not a descent direction
        T = np.stack(pts_t)
        V = np.stack(pts_e)
        order = np.argsort(V, axis=0)[:3]                  # the best three points per channel
        a, b, c = (np.take_along_axis(T, order[i:i + 1], 0)[0] for i in range(3))
        fa, fb, fc = (np.take_along_axis(V, order[i:i + 1], 0)[0] for i in range(3))
        with np.errstate(divide="ignore", invalid="ignore"):
            num = (a - b) ** 2 * (fa - fc) - (a - c) ** 2 * (fa - fb)
            den = (a - b) * (fa - fc) - (a - c) * (fa - fb)
            vertex = a - 0.5 * num / den
            curvature = ((fc - fb) / (c - b) - (fb - fa) / (b - a)) / (c - a)
        convex = np.isfinite(vertex) & np.isfinite(curvature) & (curvature > 0)
        vertex = np.where(convex & (vertex > 0), vertex, np.inf)
        shrink = 0.25 * smallest_failed
        t_next = np.where(best_t > 0, np.where(np.isfinite(vertex), vertex, 0.5 * best_t),
                          np.minimum(vertex, shrink))
        t_next = np.clip(t_next, 1e-6, 1.0)
    return best_t, best_e, best_aux, n_eval


# -- microfacet models (independent-G, G-from-D) ----------------------------------------------
@dataclass
class MFState:
    D: np.ndarray
    F: np.ndarray
    G: np.ndarray
    rho_d: np.ndarray
    rho_s: np.ndarray

    def copy(self) -> "MFState":
        """A state with copies of the factor arrays."""
        return MFState(*(np.array(x) for x in _state_arrays(self)))


def _stats(st: MFState, smp: Samples, chans=None):
    """``(E, S)`` of :meth:`Samples.stats` for the model of ``st``, ``X = ρs D F`` per bin
    (for the channels in ``chans``, default all)."""
    return smp.stats(st.G, st.rho_s[:, None] * outer_df(st.D, st.F), st.rho_d, chans)


def _rho_update(st: MFState, smp: Samples, S):
    S1, S2, Spz = S
    x = outer_df(st.D, st.F)
    st.rho_d, st.rho_s = cramer(smp.sum_w, (x * S1).sum(1), (x * x * S2).sum(1),
                                smp.sum_wz, (x * Spz).sum(1))


def expanded_objective(st: MFState, smp: Samples, S):
    """Eq. 7 from the sufficient statistics (no pass over the samples)."""
    S1, S2, Spz = S
    x = st.rho_s[:, None] * outer_df(st.D, st.F)
    a = st.rho_d
    E = (a * a * smp.sum_w + smp.sum_wzz - 2 * a * smp.sum_wz
         + (x * x * S2).sum(1) + 2 * a * (x * S1).sum(1) - 2 * (x * Spz).sum(1))
    return np.maximum(E, 0.0)


def _factor_update(st: MFState, S, name: str):
    """Eq. 14 for D (``name="D"``, the sums over θd) or F (``"F"``, over θh), the other
    factor, ρd and ρs fixed."""
    S1, S2, Spz = (s.reshape(3, NH, ND) for s in S)
    r = Spz - st.rho_d[:, None, None] * S1
    other, sums = (st.F, "chd,cd->ch") if name == "D" else (st.D, "chd,ch->cd")
    num = st.rho_s[:, None] * np.einsum(sums, r, other)
    den = st.rho_s[:, None] ** 2 * np.einsum(sums, S2, other * other)
    return ls_update(num, den, getattr(st, name))


def _solve_tridiag(diag, off, rhs, old):
    """Solve the (3 channels of) tridiagonal normal equations with a tiny ridge towards the
    old value (keeps components without data unchanged)."""
    out = np.empty_like(old)
    for c in range(3):
        lam = 1e-10 * max(float(diag[c].max()), 1e-300)
        ab = np.zeros((3, NG))
        ab[0, 1:] = off[c, :-1]
        ab[1] = diag[c] + lam
        ab[2, :-1] = off[c, :-1]
        try:
            out[c] = solve_banded((1, 1), ab, rhs[c] + lam * old[c])
        except (np.linalg.LinAlgError, ValueError):
            out[c] = old[c]
    return np.where(np.isfinite(out), out, old)


def _poly_at(coef, t):
    """Evaluate per-channel polynomials ``coef[c, ..., m] t_c^m`` (ascending powers)."""
    t = np.asarray(t, dtype=np.float64).reshape(3, *([1] * (coef.ndim - 2)))
    out = np.zeros(coef.shape[:-1])
    for m in range(coef.shape[-1] - 1, -1, -1):
        out = out * t + coef[..., m]
    return out


def line_search_g(smp: Samples, g_old, g_new, X, rho_d, eps, t_cap, over_relax=1.0,
                  chans=None):
    """Exact line search of the G step (an extension of §4.3, replacing a golden-section
    search of 6 passes over the samples): along ``G(t) = g_old + t (g_new − g_old)`` every
    sample's ``P = G(θi) G(θo)/cc`` is a quadratic in t, so the bin statistics are
    polynomials in t (one pass, :meth:`Samples.line_stats`) and Eq. 7 at fixed ρd and
    ``X = ρs D F`` is a quartic in t.
    Its minimiser ``t*`` over ``[0, t_max]`` is found (roots of the cubic derivative),
    ``t_max = max(1, min(t_cap, the largest t keeping G ≥ eps))``; with ``over_relax = ω``
    the step ``min(ω t*, t_max)`` is taken instead whenever it still lowers the quartic below
    ``E(0)`` (over-relaxation; for a parabola any ω < 2 does). Returns ``(t (3,), G, S)``,
    S the bin statistics at t; a channel whose quartic does not decrease, or not in
    ``chans`` (not passed over), keeps ``t = 0``."""
    dG = g_new - g_old
    Q = smp.line_stats(g_old, dG, chans)
    a = rho_d[:, None]
    s1 = np.einsum("ck,ckm->cm", X, Q[..., 0:3])
    s2 = np.einsum("ck,ckm->cm", X * X, Q[..., 3:8])
    spz = np.einsum("ck,ckm->cm", X, Q[..., 8:11])
    quartic = s2.copy()
    quartic[:, :3] += 2.0 * a * s1 - 2.0 * spz
    quartic[:, 0] += (rho_d * rho_d * smp.sum_w + smp.sum_wzz - 2.0 * rho_d * smp.sum_wz)
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(dG < 0, (g_old - eps) / -dG, np.inf)
    t_max = np.maximum(np.minimum(room.min(axis=1), t_cap), 1.0)   # t = 1 is always feasible
    t_best = np.zeros(3)
    for c in range(3):
        q = quartic[c]
        cands = [0.0, float(t_max[c])]
        deriv = np.array([4 * q[4], 3 * q[3], 2 * q[2], q[1]])
        if np.all(np.isfinite(deriv)) and np.any(deriv != 0):
            for r in np.roots(np.trim_zeros(deriv, "f")):
                if abs(r.imag) <= 1e-9 * max(1.0, abs(r.real)) and 0.0 < r.real < t_max[c]:
                    cands.append(float(r.real))
        vals = [np.polynomial.polynomial.polyval(tc, q) for tc in cands]
        t_best[c] = cands[int(np.argmin(vals))]
    e0 = quartic[:, 0]
    if over_relax != 1.0:
        t_over = np.minimum(over_relax * t_best, t_max)
        t_best = np.where(_poly_at(quartic, t_over) < e0, t_over, t_best)
    e_t = _poly_at(quartic, t_best)
    t_best = np.where((e_t < e0) & _chans(chans), t_best, 0.0)
    G = np.maximum(g_old + t_best[:, None] * dG, eps)
    S = (_poly_at(Q[..., 0:3], t_best), _poly_at(Q[..., 3:8], t_best),
         _poly_at(Q[..., 8:11], t_best))
    return t_best, G, S


@dataclass
class RunResult:
    state: object
    E: np.ndarray
    iterations: int
    history: list
    reason: str
    line_searches: int
    line_search_evals: int
    seconds: float
    extra: dict = field(default_factory=dict)
    #: what :func:`run_independent_g` needs to go on where the run stopped (``carry``)
    carry: dict | None = None


def _extrapolate(st: MFState, prev: MFState, beta, smp: Samples, eps, E, g_from_d=False,
                 chans=None):
    """Over-relaxation of a whole AWLS sweep (an extension, not in the paper): try
    ``θ + β (θ − θ_prev)`` for the factors (D, F, G; with ``g_from_d`` D and F, G derived
    from the new D by Eq. 19), re-normalise, solve ρd/ρs (Cramer) and accept per channel
    when the objective decreases (one pass over the samples, for the channels in ``chans``,
    default all; no other channel accepts). Returns ``(accepted (3,), S or None, E)``;
    ``st`` is updated in place where accepted."""
    b = beta[:, None]
    cand = st.copy()
    for nm in ("D", "F") if g_from_d else ("D", "F", "G"):
        x = getattr(st, nm) + b * (getattr(st, nm) - getattr(prev, nm))
        setattr(cand, nm, np.maximum(x, eps))
    cand.rho_s = np.maximum(st.rho_s + beta * (st.rho_s - prev.rho_s), 1e-300)
    _normalise_factors(cand, eps, g_from_d)
    if g_from_d:
        cand.G = smith_g_from_d(cand.D.T).T
    _, S = _stats(cand, smp, chans)
    _rho_update(cand, smp, S)
    Ec = expanded_objective(cand, smp, S)
    acc = (Ec < E) & _chans(chans)
    if np.any(acc):
        _take(st, cand, acc)
    return acc, S, np.where(acc, Ec, E)


def _take(st: MFState, cand: MFState, acc) -> None:
    """Replace in place the factors and ρd, ρs of ``st`` by those of ``cand`` in the
    channels where ``acc`` (3,) holds."""
    for nm in ("D", "F", "G"):
        setattr(st, nm, np.where(acc[:, None], getattr(cand, nm), getattr(st, nm)))
    for nm in ("rho_d", "rho_s"):
        setattr(st, nm, np.where(acc, getattr(cand, nm), getattr(st, nm)))


def _extrapolation_step(st: MFState, prev: MFState, beta, smp: Samples, eps, E, S,
                        g_from_d=False, chans=None):
    """One :func:`_extrapolate` after a sweep: returns ``(S, E, beta, accepted)``, the bin
    statistics and objective of the channels where it was accepted replaced, ``beta`` grown
    ×1.5 (at most 50) where accepted and halved (at least 0.5) elsewhere, and whether any
    channel accepted."""
    acc, S_e, E = _extrapolate(st, prev, beta, smp, eps, E, g_from_d=g_from_d, chans=chans)
    accepted = bool(np.any(acc))
    if accepted:
        S = tuple(np.where(acc[:, None], a, b) for a, b in zip(S_e, S))
    grown = np.where(acc, np.minimum(beta * 1.5, 50.0), np.maximum(beta * 0.5, 0.5))
    beta = np.where(_chans(chans), grown, beta)
    return S, E, beta, accepted


def _state_arrays(st: MFState):
    return [st.D, st.F, st.G, st.rho_d, st.rho_s]


def _g_sweep(st: MFState, smp: Samples, S, on, eps, smoothing, g_step_cap):
    """One AWLS sweep of independent-G, in place, for the channels ``on`` (the others'
    factors come out undefined: the caller restores them): D, F (Eq. 14), ρd/ρs, the G step
    with its line search, G max-normalised, ρd/ρs again. Returns ``(S, E, t)``: the bin
    statistics and objective (expanded form) after it and the G step's length."""
    st.D, st.rho_s = normalise(_factor_update(st, S, "D"), st.rho_s, eps)
    st.F, st.rho_s = normalise(_factor_update(st, S, "F"), st.rho_s, eps)
    _rho_update(st, smp, S)
    X = st.rho_s[:, None] * outer_df(st.D, st.F)
    Ai_d, Ai_o, bi, Ao_d, Ao_o, bo = smp.g_system(st.G, X, st.rho_d, on)
    # G(θi) (G(θo) fixed) and G(θo) (G(θi) fixed) updates: the paper averages the two
    # solutions; we solve their summed normal equations. With reciprocal data the two
    # systems coincide (so both are the same update), and the sum is what stays exact
    # after folding φd ↔ π − φd (which swaps θi and θo within a pair).
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        g_new = _solve_tridiag(Ai_d + Ao_d, Ai_o + Ao_o, bi + bo, st.G)
    if smoothing and smoothing > 0:
        g_new = gaussian_filter1d(g_new, smoothing, axis=1, mode="nearest")
    g_new = np.maximum(g_new, eps)
    t, st.G, S = line_search_g(smp, st.G, g_new, X, st.rho_d, eps, g_step_cap,
                               G_OVER_RELAX, on)
    # max-normalise G: P scales by 1/m², S1, Spz by 1/m², S2 by 1/m⁴
    m = st.G.max(axis=1)
    m = np.where(m > 0, m, 1.0)
    st.G = np.maximum(st.G / m[:, None], eps)
    st.rho_s = st.rho_s * m**2
    S = (S[0] / m[:, None] ** 2, S[1] / m[:, None] ** 4, S[2] / m[:, None] ** 2)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        _rho_update(st, smp, S)
        E = expanded_objective(st, smp, S)
    return S, E, t


def _jump_cap(st: MFState, anchor: MFState, keep=0.5) -> np.ndarray:
    """Per channel the largest γ for which every sample of D, F and G in
    ``θ + γ (θ − anchor)`` stays at or above ``keep`` times its value."""
    cap = np.full(3, np.inf)
    for nm in ("D", "F", "G"):
        x = getattr(st, nm)
        d = x - getattr(anchor, nm)
        with np.errstate(divide="ignore", invalid="ignore"):
            room = np.where(d < 0, (1.0 - keep) * x / -d, np.inf)
        cap = np.minimum(cap, room.min(axis=1))
    return cap


def _jump(st: MFState, anchor: MFState, smp: Samples, eps, E, S, on, max_tries=4):
    """The long-baseline over-relaxation of :func:`run_independent_g` (``jump_every``), in
    place: ``θ + γ (θ − anchor)`` (:func:`_extrapolate`; ``anchor`` the state some sweeps
    earlier) with γ = 1, then, while a channel accepts, again from the accepted point with
    γ doubled (the direction is that of the last accepted step), at most ``max_tries``
    passes. Returns ``(S, E, accepted)``: the bin statistics and objective, replaced in the
    channels that accepted, and how many (channel, try) pairs did."""
    gamma, todo, accepted = np.ones(3), np.array(on, bool), 0
    for _ in range(max_tries):
        if not todo.any():
            break
        before = st.copy()
        acc, S_e, E = _extrapolate(st, anchor, np.minimum(gamma, _jump_cap(st, anchor)), smp,
                                   eps, E, chans=todo)
        S = tuple(np.where(acc[:, None], a, b) for a, b in zip(S_e, S))
        accepted += int(acc.sum())
        _take(anchor, before, acc)
        todo &= acc
        gamma = gamma * 2.0
    return S, E, accepted


#: :class:`ChannelMonitors`: a channel of a run with a window stops once its decrease over
#: the window is below this share of the summed rule's limit (of the summed objective)
CHANNEL_SHARE = 1.0 / 3.0


class ChannelMonitors:
    """The stopping rule of an independent-G run: :class:`Monitor` on the summed objective
    (``total``: every channel stops when it fires), and with ``window = (W, k)`` a rule per
    channel: a channel stops, and no longer costs, once its own decrease over the last W
    iterations is below a third of the summed rule's limit, ``W · k · tol / 3`` times the
    summed objective. No channel runs longer than under the summed rule alone, and when
    every channel has stopped by its own rule the summed objective fell by less than the
    summed rule's limit over their last W iterations (the same bound). A channel holding a
    small part of Eq. 7 (a dark channel) stops early; per-channel *relative* windows would
    run such channels longer than the summed rule does. The patience rule (``tol`` for 3
    iterations) is not applied per channel: single channels stall for a few iterations and
    go on (an all-ones start's channel after < 20 iterations, pink-plastic)."""

    def __init__(self, smp: Samples, tol, window=None, patience=3):
        self.total = Monitor(smp.sum_wzz, tol, np.inf, patience, window)
        self.channels = [Monitor(smp.sum_wzz[c], tol, np.inf, np.inf) for c in range(3)]
        self.window = window

    @property
    def history(self) -> list[float]:
        """The summed objective per iteration (the channels not run held at their last
        value)."""
        return self.total.history

    def start(self, E) -> None:
        """Record the objective ``E`` (3,) of the starting point."""
        self.total.history.append(float(np.sum(E)))
        for c in range(3):
            self.channels[c].history.append(float(E[c]))

    def push(self, E, on) -> np.ndarray:
        """Record ``E`` (3,); return the channels of ``on`` that stop now."""
        if self.total.push(E):
            return np.array(on, bool)
        stop = np.array([bool(on[c]) and self.channels[c].push(E[c]) for c in range(3)])
        if self.window is None:
            return stop
        n_win, factor = self.window
        limit = n_win * factor * self.total.tol * CHANNEL_SHARE
        for c in np.flatnonzero(on & ~stop):
            h = self.channels[c].history
            if len(h) > n_win and h[-1 - n_win] - h[-1] < limit * self.total.history[-1]:
                self.channels[c].reason = (f"decrease over the last {n_win} iterations < "
                                           f"{limit:g} of the summed objective")
                stop[c] = True
        return stop

    def reason(self) -> str:
        """Why every channel stopped: the summed rule's reason, else the first channel's."""
        if self.total.reason != "max_iter":
            return self.total.reason
        reasons = [m.reason for m in self.channels if m.reason != "max_iter"]
        return reasons[0] if reasons else "max_iter"

    def channel_reasons(self) -> list[str]:
        """Per channel: why it stopped (the summed rule's reason where that stopped it)."""
        return [m.reason if m.reason != "max_iter" else self.total.reason
                for m in self.channels]


def run_independent_g(st: MFState, smp: Samples, *, eps=1e-6, smoothing=1.0, tol=1e-6,
                      max_iter=1000, g_step_cap=None, extrapolate=False, window=None,
                      jump_every=None, active=None, carry=None,
                      callback=None) -> RunResult:
    """Independent-G AWLS (§4.2-4.3): D, F (Eq. 14), G(θi) and G(θo) updates averaged and
    Gaussian-smoothed (σ = ``smoothing`` samples), taken with the exact, over-relaxed line
    search of :func:`line_search_g` (the paper searches along the step only when it increases
    the objective), ρd/ρs by Cramer's rule, max-normalisation and DR clamping at ``eps``
    (:func:`_g_sweep`). With ``extrapolate`` each sweep is followed by an accepted-if-better
    over-relaxation step (:func:`_extrapolate`), which shortens the long AWLS "swamps"
    caused by the near-ambiguity between F(θd) and G(θi)G(θo). With ``jump_every = M``
    every M-th sweep is also followed by a long-baseline over-relaxation along the
    displacement of the last M sweeps (:func:`_jump`, accepted only if better): along the
    slow, steady crawl of that near-ambiguity one sweep's displacement zigzags, M sweeps'
    points along the valley.

    Each channel stops by the rule of :class:`Monitor` on its own objective
    (:class:`ChannelMonitors`; ``window = (W, k)``: also when its relative decrease over the
    last W iterations is below ``W · k · tol``) and then no longer costs: the passes over
    the samples skip it. ``active`` (3 bools, default all): the channels run at all; the
    others are left as they are. ``carry``: an earlier run's ``RunResult.carry`` (the state
    before its last sweep, the over-relaxation factors β, the objective and the monitors),
    to go on where it stopped as one run would (a screening in rounds)."""
    t0 = time.perf_counter()
    frozen = st.copy()
    _normalise_factors(st, eps, g_from_d=False)
    on = _chans(active).copy()
    E, S = _stats(st, smp, on if carry is not None else None)
    _rho_update(st, smp, S)
    E = expanded_objective(st, smp, S)
    _take(st, frozen, ~on)
    g_step_cap = G_STEP_CAP if g_step_cap is None else float(g_step_cap)
    if carry is None:
        mon = ChannelMonitors(smp, tol, window, patience=max(3, jump_every or 0))
        beta = np.ones(3)
        mon.start(E)
    else:
        mon, beta = carry["monitors"], carry["beta"].copy()
        E = np.where(on, E, carry["E"])
    E_frozen, n_it, over_relaxed, n_extra, n_jumps = E.copy(), 0, 0, 0, 0
    anchor = st.copy()
    while np.any(on) and n_it < max_iter:
        prev = st.copy()
        S, E, t = _g_sweep(st, smp, S, on, eps, smoothing, g_step_cap)
        over_relaxed += int(np.sum(t > 1.0))
        if extrapolate and len(mon.history) > 1:
            S, E, beta, accepted = _extrapolation_step(st, prev, beta, smp, eps, E, S,
                                                       chans=on)
            n_extra += accepted
        n_it += 1
        if jump_every and n_it % jump_every == 0:
            S, E, accepted = _jump(st, anchor, smp, eps, E, S, on)
            n_jumps += accepted
            anchor = st.copy()
        _take(st, frozen, ~on)                       # the channels not run stay as they were
        E = np.where(on, E, E_frozen)
        if callback is not None:
            callback(len(mon.history), float(E.sum()))
        stop = mon.push(E, on)
        _take(frozen, st, stop)
        E_frozen, on = np.where(stop, E, E_frozen), on & ~stop
    reason = "max_iter" if np.any(on) else mon.reason()
    E_exact, _ = _stats(st, smp, _chans(active))       # exact final objective
    E = np.where(_chans(active), E_exact, E)
    return RunResult(st, E, n_it, mon.history, reason, n_it, n_it, time.perf_counter() - t0,
                     {"g_steps_over_relaxed": over_relaxed, "sweeps_extrapolated": n_extra,
                      "jumps_accepted": n_jumps,
                      "stop_reason_per_channel": mon.channel_reasons()},
                     carry={"beta": beta, "E": E, "monitors": mon})


def _state_of_channels(states) -> MFState:
    """A state whose channel ``c`` is that of ``states[c]`` (copies)."""
    st = states[0].copy()
    for c, other in enumerate(states):
        for nm in ("D", "F", "G", "rho_d", "rho_s"):
            getattr(st, nm)[c] = getattr(other, nm)[c]
    return st


def combine_channels(results) -> tuple[MFState, dict]:
    """``(state, carry)`` whose channel ``c`` is that of ``results[c]`` (3 :class:`RunResult`
    of :func:`run_independent_g`, their carries included): the channels are independent
    problems, so channels of different runs make one run that goes on (``carry``) as each
    of them would have alone."""
    st = _state_of_channels([res.state for res in results])
    mon = copy.deepcopy(results[0].carry["monitors"])
    mon.channels = [copy.deepcopy(res.carry["monitors"].channels[c])
                    for c, res in enumerate(results)]
    n = max(len(m.history) for m in mon.channels)
    total = mon.total
    total.history = [float(sum(m.history[min(k, len(m.history) - 1)] for m in mon.channels))
                     for k in range(n)]
    total.reason, total.small = "max_iter", 0       # the patience count of the sum, anew
    for k in range(max(1, n - total.patience), n):
        rel = (total.history[k - 1] - total.history[k]) / max(total.history[k], 1e-300)
        total.small = total.small + 1 if rel < total.tol else 0
    carry = {"beta": np.array([res.carry["beta"][c] for c, res in enumerate(results)]),
             "E": np.array([res.E[c] for c, res in enumerate(results)]), "monitors": mon}
    return st, carry


def _g_from_d_d_step(st: MFState, smp: Samples, S, E, t_prev, eps, search_evals):
    """G-from-D's D step, in place: D by Eq. 14, ρs·D max-normalised, G from D (Eq. 19),
    taken per channel at the fraction ``t_prev`` of its length: G's response makes the full
    step overshoot (the accepted fractions are 0.01-0.5 and change slowly), so the trial at
    the previous fraction is the one pass most sweeps need. Where it does not increase the
    objective over ``E`` the step is taken and the next fraction is :data:`D_STEP_GROWTH`
    times larger (at most 1); elsewhere a :func:`parabolic_search` below it (a channel whose
    search finds no decrease keeps D, G, ρs and halves its fraction). Returns the bin
    statistics, the next fractions and the search's evaluations (0: no search)."""
    A_old = st.rho_s[:, None] * st.D                      # ρs·D, the scale-free quantity
    A_step = np.maximum(_factor_update(st, S, "D"), eps) * st.rho_s[:, None] - A_old

    def make(t, chans=None):
        A = A_old + t[:, None] * A_step
        m = A.max(axis=1)
        m = np.where(m > 0, m, 1.0)
        D = np.maximum(A / m[:, None], eps)
        G = smith_g_from_d(D.T).T
        e, s = smp.stats(G, m[:, None] * outer_df(D, st.F), st.rho_d, chans)
        return e, (D, G, m) + s

    t_trial = np.asarray(t_prev, dtype=np.float64)
    e_trial, aux = make(t_trial)
    # E comes from the expanded form: allow for its rounding (≈1e-15 Σwz²)
    need = ~(e_trial <= E + 1e-12 * smp.sum_wzz)
    t_taken, n = np.where(need, 0.0, t_trial), 0
    if np.any(need):

        def fun(u, active):
            return make(u * t_trial, active)

        u, _, aux_s, n = parabolic_search(fun, need, E, e_trial, aux, search_evals)
        t_taken = np.where(need, u * t_trial, t_taken)
        aux = tuple(np.where(need[:, None] if np.ndim(a) == 2 else need, a, b)
                    for a, b in zip(aux_s, aux))
    keep = t_taken == 0.0
    t_next = np.where(need, np.where(keep, 0.5 * t_trial, t_taken),
                      np.minimum(D_STEP_GROWTH * t_trial, 1.0))
    D, G, m = aux[0], aux[1], aux[2]
    S_new = aux[3:]
    st.D = np.where(keep[:, None], st.D, D)
    st.G = np.where(keep[:, None], st.G, G)
    st.rho_s = np.where(keep, st.rho_s, m)
    return tuple(np.where(keep[:, None], a, b) for a, b in zip(S, S_new)), t_next, n


def run_g_from_d(st: MFState, smp: Samples, *, eps=0.0, tol=1e-6, max_iter=300,
                 search_evals=2, extrapolate_after: int | None = None,
                 window=None, callback=None) -> RunResult:
    """G-from-D AWLS (§4.3): D by Eq. 14, G from D (Eq. 19 + Smith Λ), taken at a fraction
    of its length that does not increase the objective (:func:`_g_from_d_d_step`: one trial
    at the fraction accepted last, a :func:`parabolic_search` of ``search_evals``
    evaluations below it when that increases); F by Eq. 14; ρd/ρs by Cramer; negative
    components clamped to 0 (``eps``). The paper does not say how the D step is safeguarded;
    a golden-section search reaches the same objectives at several times the cost
    (docs/design/npf-fit.md).

    ``extrapolate_after`` (an extension): from that iteration on, each sweep is followed by
    an accepted-if-better over-relaxation of D, F, ρ (:func:`_extrapolate`; ``None``:
    never). Plain AWLS crawls on about a third of the MERL materials (300 iterations leave
    a relative decrease of 1e-3 to 1e-6); starting the over-relaxation after the first
    iterations keeps (to 0.1 %) the point the plain sweeps reach where they converge.
    ``window = (W, k)`` adds :class:`Monitor`'s windowed stopping rule."""
    t0 = time.perf_counter()
    st.D, st.rho_s = normalise(np.maximum(st.D, eps), st.rho_s, eps)
    st.F, st.rho_s = normalise(np.maximum(st.F, eps), st.rho_s, eps)
    st.G = smith_g_from_d(st.D.T).T
    _, S = _stats(st, smp)
    _rho_update(st, smp, S)
    E = expanded_objective(st, smp, S)
    mon = Monitor(smp.sum_wzz, tol, max_iter, window=window)
    mon.history.append(float(E.sum()))
    t_prev = np.full(3, 0.5)
    line_searches = line_search_evals = 0
    beta = np.ones(3)
    n_extra = 0
    while True:
        prev = st.copy()
        S, t_prev, n = _g_from_d_d_step(st, smp, S, E, t_prev, eps, search_evals)
        line_searches += n > 0
        line_search_evals += n
        st.F, st.rho_s = normalise(np.maximum(_factor_update(st, S, "F"), eps), st.rho_s, eps)
        _rho_update(st, smp, S)
        E = expanded_objective(st, smp, S)
        if extrapolate_after is not None and len(mon.history) > max(extrapolate_after, 1):
            S, E, beta, accepted = _extrapolation_step(st, prev, beta, smp, eps, E, S,
                                                       g_from_d=True)
            n_extra += accepted
        if callback is not None:
            callback(len(mon.history), float(E.sum()))
        if mon.push(E):
            break
    E, _ = _stats(st, smp)
    return RunResult(st, E, len(mon.history) - 1, mon.history, mon.reason, line_searches,
                     line_search_evals, time.perf_counter() - t0,
                     {"sweeps_extrapolated": n_extra})


# -- naive model (Eq. 4) ----------------------------------------------------------------------
@dataclass
class NaiveState:
    D: np.ndarray
    F: np.ndarray
    H: np.ndarray
    rho_d: np.ndarray
    rho_s: np.ndarray


def dense_tensors(data: ObjectiveData):
    """Dense (3, 8100, 180) weight and weight·measurement tensors (0 where excluded)."""
    W = np.zeros((3, NH * ND * NP))
    W[:, data.index] = data.w
    WZ = np.zeros_like(W)
    WZ[:, data.index] = data.w * data.z
    return W.reshape(3, NH * ND, NP), WZ.reshape(3, NH * ND, NP)


def run_naive(st: NaiveState, W, WZ, sum_wzz, *, eps=0.0, tol=1e-6, max_iter=3000,
              callback=None) -> RunResult:
    """Naive-model AWLS: D, F, H by Eq. 14 (each sample maps to exactly one component of
    each factor), ρd/ρs by Cramer's rule, max-normalisation, clamping at ``eps``."""
    t0 = time.perf_counter()
    sum_w = W.sum(axis=(1, 2))
    sum_wz = WZ.sum(axis=(1, 2))
    mon = Monitor(sum_wzz, tol, max_iter)
    for name in ("D", "F", "H"):
        f, st.rho_s = normalise(np.maximum(getattr(st, name), eps), st.rho_s, eps)
        setattr(st, name, f)

    def p_sums(X):
        return (np.einsum("ck,ckp->cp", X, W), np.einsum("ck,ckp->cp", X * X, W),
                np.einsum("ck,ckp->cp", X, WZ))

    def rho_and_E(B1, B2, Bz):
        H = st.H
        sx, sxx, sxy = (H * B1).sum(1), (H * H * B2).sum(1), (H * Bz).sum(1)
        st.rho_d, st.rho_s = cramer(sum_w, sx, sxx, sum_wz, sxy)
        a, b = st.rho_d, st.rho_s
        E = a * a * sum_w + sum_wzz - 2 * a * sum_wz + b * b * sxx + 2 * a * b * sx - 2 * b * sxy
        return np.maximum(E, 0.0)

    E = rho_and_E(*p_sums(outer_df(st.D, st.F)))
    mon.history.append(float(E.sum()))
    while True:
        H = st.H
        A1 = np.einsum("ckp,cp->ck", W, H).reshape(3, NH, ND)
        A2 = np.einsum("ckp,cp->ck", W, H * H).reshape(3, NH, ND)
        Az = np.einsum("ckp,cp->ck", WZ, H).reshape(3, NH, ND)
        r = Az - st.rho_d[:, None, None] * A1
        rs = st.rho_s[:, None]
        num = rs * np.einsum("chd,cd->ch", r, st.F)
        den = rs**2 * np.einsum("chd,cd->ch", A2, st.F**2)
        st.D, st.rho_s = normalise(np.maximum(ls_update(num, den, st.D), eps), st.rho_s, eps)
        rs = st.rho_s[:, None]
        num = rs * np.einsum("chd,ch->cd", r, st.D)
        den = rs**2 * np.einsum("chd,ch->cd", A2, st.D**2)
        st.F, st.rho_s = normalise(np.maximum(ls_update(num, den, st.F), eps), st.rho_s, eps)
        X = outer_df(st.D, st.F)
        B1, B2, Bz = p_sums(X)
        rs = st.rho_s[:, None]
        num = rs * (Bz - st.rho_d[:, None] * B1)
        den = rs**2 * B2
        st.H, st.rho_s = normalise(np.maximum(ls_update(num, den, st.H), eps), st.rho_s, eps)
        E = rho_and_E(B1, B2, Bz)
        if callback is not None:
            callback(len(mon.history), float(E.sum()))
        if mon.push(E):
            break
    return RunResult(st, E, len(mon.history) - 1, mon.history, mon.reason, 0, 0,
                     time.perf_counter() - t0)


def naive_exact_objective(st: NaiveState, data: ObjectiveData) -> np.ndarray:
    ih, idd, ip = np.unravel_index(data.index, (NH, ND, NP))
    model = (st.rho_d[:, None] + st.rho_s[:, None] * st.D[:, ih] * st.F[:, idd] * st.H[:, ip])
    r = model - data.z
    return np.einsum("cn,cn->c", data.w, r * r)


# -- bivariate (Eq. 5) ------------------------------------------------------------------------
def fit_bivariate_table(data: ObjectiveData) -> tuple[np.ndarray, np.ndarray]:
    """B(θh, θd) = Σ_φd w ρ* / Σ_φd w (Eq. 14 with y = 1), per channel, in one step; bins
    without any included sample take the value of the nearest bin that has one."""
    from scipy.ndimage import distance_transform_edt

    ih, idd, _ = np.unravel_index(data.index, (NH, ND, NP))
    hd = ih * ND + idd
    B = np.zeros((3, NH * ND))
    has = np.zeros(NH * ND, bool)
    has[hd] = True
    for c in range(3):
        num = np.bincount(hd, weights=data.w[c] * data.z[c], minlength=NH * ND)
        den = np.bincount(hd, weights=data.w[c], minlength=NH * ND)
        ok = den > 0
        B[c] = np.where(ok, num / np.where(ok, den, 1.0), 0.0)
        has &= ok
    grid_has = has.reshape(NH, ND)
    if not grid_has.all():
        _, (ii, jj) = distance_transform_edt(~grid_has, return_indices=True)
        B = B.reshape(3, NH, ND)[:, ii, jj].reshape(3, NH * ND)
    model = B[:, hd]
    r = model - data.z
    E = np.einsum("cn,cn->c", data.w, r * r)
    return np.maximum(B.reshape(3, NH, ND), 0.0), E


# -- Gauss–Newton / Levenberg–Marquardt polish (extension) ------------------------------------
def _normal_matrix(st: MFState, smp: Samples, S, curvature: bool = False):
    """Full JᵀWJ (3, 272, 272) and JᵀWr (3, 272) of Eq. 7 for Eq. 3 in the parameters
    (D, F, G, ρd, ρs); with ``curvature`` also ``Σ w r ∇²m`` (:func:`_residual_curvature`),
    else ``None``, from the same pass over the samples."""
    S1, S2, Spz = (s.reshape(3, NH, ND) for s in S)
    D, F, G, a, b = st.D, st.F, st.G, st.rho_d, st.rho_s
    blocks = [np.empty((3, NG, NG)), np.empty((3, NH, NG)), np.empty((3, ND, NG)),
              np.empty((3, NG)), np.empty((3, NG)), np.empty((3, NG))]
    h_blocks = ([np.empty((3, NG, NG)), np.empty((3, NH, NG)), np.empty((3, ND, NG)),
                 np.empty((3, NG))] if curvature
                else [np.empty((1, 1, 1)), np.empty((1, 1, 1)), np.empty((1, 1, 1)),
                      np.empty((1, 1))])
    _kernels.g_jacobian_blocks(smp.hd, smp.gi0, smp.gti, smp.go0, smp.gto, smp.inv_cc,
                               smp.w, smp.z, np.ascontiguousarray(G), np.ascontiguousarray(D),
                               np.ascontiguousarray(F), np.ascontiguousarray(a),
                               np.ascontiguousarray(b), *blocks, bool(curvature), *h_blocks)
    GG, DG, FG, Grd, Grs, gG = blocks
    X = b[:, None, None] * D[:, :, None] * F[:, None, :]
    R = a[:, None, None] * S1 + X * S2 - Spz                       # Σ w r P per bin
    b2 = (b * b)[:, None, None]
    n = NH + ND + NG + 2
    A = np.zeros((3, n, n))
    g = np.zeros((3, n))
    iD, iF, iG = slice(0, NH), slice(NH, NH + ND), slice(NH + ND, NH + ND + NG)
    ia, ib = n - 2, n - 1
    ci = np.arange(3)[:, None]
    A[ci, np.arange(NH)[None], np.arange(NH)[None]] = \
        b2[:, :, 0] * np.einsum("chd,cd->ch", S2, F * F)
    A[ci, NH + np.arange(ND)[None], NH + np.arange(ND)[None]] = \
        b2[:, :, 0] * np.einsum("chd,ch->cd", S2, D * D)
    # D–F: Σ w (b F_d P)(b D_h P) plus the second-order term of the residual (exact Hessian
    # of the bilinear part is not used: Gauss–Newton)
    A[:, iD, iF] = b2 * D[:, :, None] * F[:, None, :] * S2
    A[:, iF, iD] = np.swapaxes(A[:, iD, iF], 1, 2)
    A[:, iG, iG] = GG
    A[:, iD, iG] = DG
    A[:, iG, iD] = np.swapaxes(DG, 1, 2)
    A[:, iF, iG] = FG
    A[:, iG, iF] = np.swapaxes(FG, 1, 2)
    # ρd, ρs
    A[:, ia, ia] = smp.sum_w
    A[:, ia, iD] = b[:, None] * np.einsum("chd,cd->ch", S1, F)
    A[:, ia, iF] = b[:, None] * np.einsum("chd,ch->cd", S1, D)
    A[:, ia, iG] = Grd
    DF = D[:, :, None] * F[:, None, :]
    A[:, ib, ib] = (DF * DF * S2).sum((1, 2))
    A[:, ib, ia] = (DF * S1).sum((1, 2))
    A[:, ib, iD] = b[:, None] * D * np.einsum("chd,cd->ch", S2, F * F)
    A[:, ib, iF] = b[:, None] * F * np.einsum("chd,ch->cd", S2, D * D)
    A[:, ib, iG] = Grs
    A[:, ia, ib] = A[:, ib, ia]
    for i in (ia, ib):
        A[:, :n - 2, i] = A[:, i, :n - 2]
    g[:, iD] = b[:, None] * np.einsum("chd,cd->ch", R, F)
    g[:, iF] = b[:, None] * np.einsum("chd,ch->cd", R, D)
    g[:, iG] = gG
    g[:, ia] = a * smp.sum_w + (X * S1).sum((1, 2)) - smp.sum_wz
    g[:, ib] = (DF * R).sum((1, 2))
    return A, g, (_residual_curvature(st, R, *h_blocks) if curvature else None)


def _residual_curvature(st: MFState, R, HGG, HDG, HFG, HsG) -> np.ndarray:
    """``Σ w r ∇²m`` (3, 272, 272) in the parameters (D, F, G, ρd, ρs) of
    :func:`_normal_matrix`: what Newton's Hessian of Eq. 7 (halved) adds to Gauss–Newton's
    JᵀWJ. Eq. 3 is linear in each factor but a product of them, so only the cross terms
    between different factors (and between G(θi) and G(θo)) are non-zero: those with G from
    the kernel's pass (``HGG`` …), the others from the bin sums ``R = Σ w r P``."""
    D, F, b = st.D, st.F, st.rho_s
    n = NH + ND + NG + 2
    H = np.zeros((3, n, n))
    iD, iF, iG, ib = slice(0, NH), slice(NH, NH + ND), slice(NH + ND, NH + ND + NG), n - 1
    H[:, iD, iF] = b[:, None, None] * R                       # ∂²m/∂D_h∂F_d = ρs P
    H[:, iD, ib] = np.einsum("chd,cd->ch", R, F)              # ∂²m/∂D_h∂ρs = F_d P
    H[:, iF, ib] = np.einsum("chd,ch->cd", R, D)
    H[:, iD, iG] = HDG
    H[:, iF, iG] = HFG
    H[:, iG, ib] = HsG
    H = H + np.swapaxes(H, 1, 2)
    H[:, iG, iG] = HGG                                        # symmetric as accumulated
    return H


def _chain_g_from_d(A, g, J):
    """JᵀWJ and JᵀWr of :func:`_normal_matrix` in the G-from-D parameters (D, F, ρd, ρs):
    with ``dG = ∂G/∂D dD`` (``J`` (3, 90, 90), :func:`smith_g_jacobian`) the parameter map is
    ``P = [[I, 0], [0, I], [J, 0], [0, I₂]]`` and the system becomes ``Pᵀ A P``, ``Pᵀ g``
    (``g`` may be None: the residual curvature is chained the same way). ``P`` is applied by
    its blocks: the G rows and columns folded into D's through ``J``."""
    iG = slice(NH + ND, NH + ND + NG)
    keep = np.r_[0:NH + ND, A.shape[1] - 2:A.shape[1]]
    Jt = np.swapaxes(J, 1, 2)
    AP = A[:, :, keep]                                         # A P, column by column
    AP[:, :, :NH] += A[:, :, iG] @ J
    M = AP[:, keep, :]                                         # Pᵀ (A P), row by row
    M[:, :NH, :] += Jt @ AP[:, iG, :]
    if g is None:
        return M, None
    h = g[:, keep]
    h[:, :NH] += (Jt @ g[:, iG, None])[:, :, 0]
    return M, h


def _g_from_d_curvature(st: MFState, curvature, g, J):
    """Newton's residual curvature in the G-from-D parameters: the product's
    (:func:`_residual_curvature`, chained like JᵀWJ) plus, G being a function of D, the
    gradient in G times Smith's second derivative (:func:`smith_g_curvature`) in the D
    block (without it, Newton's matrix is not the Hessian of Eq. 7 in D)."""
    chained, _ = _chain_g_from_d(curvature, None, J)
    chained[:, :NH, :NH] += smith_g_curvature(st.D, g[:, NH + ND:NH + ND + NG])
    return chained


def _log_params(st: MFState, g_from_d: bool) -> np.ndarray:
    """The polish's parameter values (3, n): D, F, (G,) 1 for ρd (additive), ρs."""
    return np.concatenate([st.D, st.F] + ([] if g_from_d else [st.G])
                          + [np.ones((3, 1)), st.rho_s[:, None]], axis=1)


#: The largest damping of :func:`polish_lm`. A channel whose step fails there is done: its
#: parameters, and so its next step, can no longer change (channels are independent), and
#: trying it again would only re-run the passes over the samples for the others.
LAM_MAX = 1e30


def polish_lm(st: MFState, smp: Samples, *, eps=1e-6, max_iter=30, tol=1e-9,
              g_from_d=False, bound: float | None = None, newton: bool | None = None,
              bounded: tuple[str, ...] | None = None, callback=None, carry=None,
              finish: bool = True) -> RunResult:
    """Levenberg–Marquardt refinement of an AWLS solution (an extension, not in the paper):
    (Gauss–)Newton steps on all parameters of a channel at once, which crosses the long,
    nearly flat valleys of Eq. 7 (the near-ambiguity between F(θd), G(θi)G(θo) and D(θh)
    away from the specular peak) where alternating updates crawl. Steps are accepted per
    channel only if the exact objective decreases; factors stay at or above ``eps`` and ρd at
    or above 0 (held there when the descent points below: an active set); the starting max
    samples fix the scale gauge and the factors are max-normalised at the end (the model is
    unchanged by it). No smoothing is applied to G.

    Independent-G: 272 parameters (D, F, G, ρd, ρs). ``g_from_d``: 182 (D, F, ρd, ρs), G
    following D through Smith's integrals (Eq. 19), differentiated exactly
    (:func:`smith_g_jacobian`). G-from-D's AWLS D step (Eq. 14) holds G fixed although G
    depends on D, so the points where it stops are not stationary points of Eq. 7; this
    polish continues from there.

    ``bound`` (> 1): a trust region around the starting point — every factor sample and ρs
    stays within ``[x₀/bound, x₀·bound]`` (a box in the log parameters, relative to the
    gauge samples; see :func:`_damped_step_in_box` for how steps respect it).
    Independent-G needs it: the near-ambiguity F(θd)·G(θi)G(θo) ≈ F(θd)/h(θd)²·G(θi)h(θi)
    ·G(θo)h(θo) is broken only weakly by the data, and the unbounded polish runs along it to
    degenerate factors (F(0) at the clamp ``eps``, ρs grown 10-10⁶×) that fit Eq. 7 better
    but are no longer a Fresnel and a shadowing term. ρd is additive and not bounded.

    ``newton`` (default on; off: Gauss–Newton): the residual-curvature term ``Σ w r ∇²m``
    (:func:`_residual_curvature`) is added to JᵀWJ, i.e. Newton's method damped à la
    Levenberg–Marquardt (the damping scaled by JᵀWJ's diagonal). Eq. 7 is a large-residual
    problem for most materials (the model cannot fit them), where Gauss–Newton converges
    linearly and slowly; Newton's steps converge in ≈ 10-20 iterations.
    ``bounded``: the factor groups the trust region applies to (``"D"``, ``"F"``, ``"G"``,
    ``"rho_s"``; default all). G-from-D's Newton matrix adds the gradient in G times Smith's
    second derivative (:func:`_g_from_d_curvature`). Unbounded, G-from-D's polish drifts
    like independent-G's (F's grazing samples rise against the rest with ρs); bounding every
    factor stops it on the box's faces; bounding F alone (``bounded=("F",)``) is G-from-D's
    default. Measured figures: docs/design/npf-fit.md. ``finish=False``: no final
    max-normalisation, and the result's ``carry`` lets a later call (``carry=``) go on as this
    run would (per channel: :func:`combine_polish`; the stopping rule's patience starts anew)."""
    t0 = time.perf_counter()
    newton = True if newton is None else bool(newton)
    n = NH + ND + (0 if g_from_d else NG) + 2
    start, lam, gauge_free = _polish_carry(st, n, g_from_d, carry)
    if g_from_d:
        st.G = smith_g_from_d(st.D.T).T
    E, S = _stats(st, smp)
    mon = Monitor(smp.sum_wzz, tol, max_iter, patience=2)
    mon.history.append(float(E.sum()))
    log_bound = None if bound is None else _polish_log_bound(n, g_from_d, bound, bounded)
    while True:
        A, g, A_newton, sc = _polish_system(st, smp, S, g_from_d, newton)
        free, room_down, room_up = _polish_box(st, sc, g, gauge_free, start, log_bound, eps,
                                               g_from_d)
        todo = lam < LAM_MAX                            # the channels not done
        for _attempt in range(8 if todo.any() else 0):  # raise the damping until it helps
            step = _polish_step(A, g, A_newton, lam, todo, free, room_down, room_up)
            cand = _polish_candidate(st, step, eps, g_from_d)
            Ec, Sc = _stats(cand, smp, todo)       # the others' results are not used
            acc = todo & np.isfinite(Ec) & (Ec < E) & _storable(cand, g_from_d)
            _take(st, cand, acc)
            S = tuple(np.where(acc[:, None], x, y) for x, y in zip(Sc, S))
            E = np.where(acc, Ec, E)
            lam = _next_damping(lam, acc, todo)
            todo &= ~acc
            if not np.any(todo):
                break
        if callback is not None:
            callback(len(mon.history), float(E.sum()))
        if mon.push(E):
            break
        if np.all(lam >= 1e3):
            mon.reason = "damping limit (no further decrease)"
            break
    if finish:
        _normalise_factors(st, 0.0, g_from_d)    # a change of gauge: the model is unchanged
        E, _ = _stats(st, smp)
    return RunResult(st, E, len(mon.history) - 1, mon.history, mon.reason, 0, 0,
                     time.perf_counter() - t0, carry=None if finish else
                     dict(start=start, lam=lam, gauge_free=gauge_free))


def _polish_carry(st: MFState, n, g_from_d, carry):
    """``(start, lam, gauge_free)`` of :func:`polish_lm`: from ``carry`` when it continues a
    run, else the trust region centred on ``st``, the least damping, ``st``'s gauge."""
    if carry is not None:
        return carry["start"], carry["lam"].copy(), carry["gauge_free"]
    return (np.log(np.maximum(_log_params(st, g_from_d), 1e-300)), np.full(3, 1e-12),
            _gauge_free(st, n, g_from_d))


def combine_polish(results, pick) -> tuple[MFState, np.ndarray, dict]:
    """``(state, E, carry)`` whose channel ``c`` is that of ``results[pick[c]]``: the channels
    are independent problems, so for runs of :func:`polish_lm` with ``finish=False`` the
    combined run goes on (``carry``) as each channel's own would; for others (AWLS runs)
    ``carry`` is None."""
    st = _state_of_channels([results[k].state for k in pick])
    names = results[pick[0]].carry or {}
    carry = {name: np.array([results[k].carry[name][c] for c, k in enumerate(pick)])
             for name in names} or None
    return st, np.array([results[k].E[c] for c, k in enumerate(pick)]), carry


def _polish_log_bound(n, g_from_d, bound, bounded) -> np.ndarray:
    """The trust region of :func:`polish_lm` per log parameter (n,): ``ln bound`` for the
    groups in ``bounded`` (default all), inf for the others."""
    iG = slice(NH + ND, NH + ND + (0 if g_from_d else NG))
    groups = {"D": slice(0, NH), "F": slice(NH, NH + ND), "G": iG, "rho_s": slice(n - 1, n)}
    log_bound = np.full(n, np.inf)
    for name in (groups if bounded is None else bounded):
        if name not in groups:
            raise ValueError(f"polish_lm: bounded expects names among {tuple(groups)}, "
                             f"found {name!r}")
        log_bound[groups[name]] = np.log(bound)
    return log_bound


def _gauge_free(st: MFState, n, g_from_d) -> np.ndarray:
    """(3, n): False at the gauge of :func:`polish_lm`, the starting max samples of D, F (and
    G), which stay fixed throughout, removing the scale ambiguities (ρs absorbs the scale)
    from the system; the factors are max-normalised once, at the end (re-normalising every
    step would move the gauge from one near-maximal sample to another and make the steps
    zigzag)."""
    gauge_free = np.ones((3, n), bool)
    for c in range(3):
        fixed = [int(np.argmax(st.D[c])), NH + int(np.argmax(st.F[c]))]
        if not g_from_d:
            fixed.append(NH + ND + int(np.argmax(st.G[c])))
        gauge_free[c, fixed] = False
    return gauge_free


def _polish_system(st: MFState, smp: Samples, S, g_from_d, newton):
    """The damped system of :func:`polish_lm` in log parameters: ``(A, g, A_newton, sc)``,
    JᵀWJ and JᵀWr scaled by the parameter values ``sc`` (3, n), and with ``newton`` the
    same plus the residual curvature (else ``None``)."""
    A, g, curvature = _normal_matrix(st, smp, S, curvature=newton)
    if g_from_d:
        J = smith_g_jacobian(st.D)[1]
        if newton:
            curvature = _g_from_d_curvature(st, curvature, g, J)
        A, g = _chain_g_from_d(A, g, J)
    # multiplicative (log) parameters for D, F, G and ρs: the near-ambiguity
    # F(θd)·G(θi)G(θo) ≈ F(θd)e^{-2kθd}·G(θi)e^{kθi}·G(θo)e^{kθo} is a straight line in
    # log space, so Gauss–Newton crosses it in few steps
    sc = np.maximum(_log_params(st, g_from_d), 1e-300)
    A = A * sc[:, :, None] * sc[:, None, :]
    g = g * sc
    A_newton = None
    if newton:
        # in log parameters x = ln p: ∂²E/∂x² gains g·p on the diagonal (∂²p/∂x² = p);
        # ρd (index -2) is additive
        n = A.shape[1]
        A_newton = A + curvature * sc[:, :, None] * sc[:, None, :]
        log_diag = g.copy()
        log_diag[:, -2] = 0.0
        A_newton[:, np.arange(n), np.arange(n)] += log_diag
    return A, g, A_newton, sc


def _polish_box(st: MFState, sc, g, gauge_free, start, log_bound, eps, g_from_d):
    """``(free, room_down, room_up)`` (3, n): the parameters free to move, and the room left
    to each face of :func:`polish_lm`'s feasible box in log parameters (≥ 0; a parameter
    pushed out by the clamp may only move back in): the factors' floor ``eps`` (the gauge
    samples stay 1, so the floor is the AWLS's dynamic-range clamp) and, with
    ``log_bound``, the trust region around the start; ρd ≥ 0 (Eq. 18; its step is
    additive, and unbounded above). A parameter at a face whose descent direction (−g)
    leaves the box is held: steps into the clamp are cut by it, and the quadratic model
    then promises decreases the step cannot give (aluminium: a predicted 1.5e-3 for an
    actual 5e-5, every iteration)."""
    n_f = NH + ND + (0 if g_from_d else NG)
    log_p = np.log(sc)
    room_down = np.full(sc.shape, np.inf)
    room_up = np.full(sc.shape, np.inf)
    room_down[:, :n_f] = np.maximum(log_p[:, :n_f] - np.log(max(eps, 1e-300)), 0.0)
    if log_bound is not None:
        room_down = np.minimum(room_down, np.maximum(log_p - (start - log_bound), 0.0))
        room_up = np.maximum(start + log_bound - log_p, 0.0)
    room_down[:, -2], room_up[:, -2] = np.maximum(st.rho_d, 0.0), np.inf   # ρd ≥ 0, additive
    held = ((room_down <= 1e-12) & (g > 0)) | ((room_up <= 1e-12) & (g < 0))
    return gauge_free & ~held, room_down, room_up


def _next_damping(lam, acc, todo) -> np.ndarray:
    """Levenberg–Marquardt's damping after an attempt: ÷10 (at least 1e-12) where the step
    was accepted, ×100 (at most :data:`LAM_MAX`) where it was tried and failed."""
    return np.where(acc, np.maximum(lam / 10.0, 1e-12),
                    np.where(todo, np.minimum(lam * 100.0, LAM_MAX), lam))


def _polish_step(A, g, A_newton, lam, todo, free, room_down, room_up) -> np.ndarray:
    """The damped steps (3, n) of the channels in ``todo`` (0 elsewhere), damping ``lam``
    scaled by JᵀWJ's diagonal: Newton's damped matrix where it is positive definite (far
    from a minimum it may not be, and its step then climbs), else Gauss–Newton's."""
    damping_scale = np.maximum(np.diagonal(A, axis1=1, axis2=2), 1e-300)
    step = np.zeros(g.shape)
    for c in np.flatnonzero(todo):
        damp = np.diag(lam[c] * damping_scale[c] + 1e-300)
        M = A[c] + damp
        if A_newton is not None:
            M_newton = A_newton[c] + damp
            try:
                np.linalg.cholesky(M_newton[np.ix_(free[c], free[c])])
                M = M_newton
            except np.linalg.LinAlgError:
                pass
        step[c] = _damped_step_in_box(M, g[c], free[c], room_down[c], room_up[c])
    return step


def _polish_candidate(st: MFState, step, eps, g_from_d) -> MFState:
    """The state after ``step`` in log parameters (ρd additive), clamped like the AWLS."""
    mult = np.exp(np.clip(step, -5.0, 5.0))
    cand = MFState(np.maximum(st.D * mult[:, :NH], eps),
                   np.maximum(st.F * mult[:, NH:NH + ND], eps),
                   st.G if g_from_d else np.maximum(st.G * mult[:, NH + ND:NH + ND + NG], eps),
                   np.maximum(st.rho_d + step[:, -2], 0.0),
                   np.maximum(st.rho_s * mult[:, -1], 1e-300))
    if g_from_d:
        cand.G = smith_g_from_d(cand.D.T).T
    return cand


def _storable(cand: MFState, g_from_d) -> np.ndarray:
    """Per channel: the model stays storable (a fit file holds factors ≤ FACTOR_MAX; ρs of
    the max-normalised factors)."""
    rho_s_stored = (cand.rho_s * cand.D.max(1) * cand.F.max(1)
                    * (1.0 if g_from_d else cand.G.max(1) ** 2))
    return (rho_s_stored <= FACTOR_MAX) & (cand.rho_d <= FACTOR_MAX)


def _damped_step(M, g, free, held_step=None):
    """−M⁻¹g on the ``free`` parameters (0 elsewhere, or ``held_step`` for the held ones,
    their coupling moved to the right-hand side)."""
    step = np.zeros_like(g) if held_step is None else held_step.copy()
    rhs = g[free] + (M[np.ix_(free, ~free)] @ step[~free] if held_step is not None else 0.0)
    try:
        step[free] = -np.linalg.solve(M[np.ix_(free, free)], rhs)
    except np.linalg.LinAlgError:
        return np.zeros_like(g)
    return step


def _damped_step_in_box(M, g, free, room_down, room_up, max_rounds=8):
    """The damped step within ``[-room_down, room_up]``: parameters whose step would cross
    a face are moved onto it and held, and the others re-solved with them held (an
    active-set loop, as in bounded-variable least squares), up to ``max_rounds`` times; the
    last step is clipped."""
    free = free.copy()
    step = _damped_step(M, g, free)
    for _ in range(max_rounds):
        over = free & ((step < -room_down) | (step > room_up))
        if not over.any():
            return step
        step = np.clip(step, -room_down, room_up)
        free &= ~over
        step = _damped_step(M, g, free, held_step=np.where(free, 0.0, step))
    return np.clip(step, -room_down, room_up)


def _normalise_factors(st: MFState, eps, g_from_d: bool) -> None:
    """Max-normalise D, F (and G, power 2) in place, ρs absorbing the scales."""
    for nm, pw in (("D", 1), ("F", 1), ("G", 2))[:2 if g_from_d else 3]:
        f, st.rho_s = normalise(getattr(st, nm), st.rho_s, eps, pw)
        setattr(st, nm, f)
