"""Numba kernels of the AWLS fit: one pass over the ~1.5 M MERL samples, all 3 channels.

Every sample ``j`` carries precomputed data (built once per fit): its (θh, θd) bin ``hd``
(= ``ih·90 + id``), the G interpolation cell/weight for θi (``gi0``, ``gti``) and θo (``go0``,
``gto``), ``inv_cc = 1/(cos θi cos θo)``, and per channel the weight ``w`` (Eq. 8) and the
measurement ``z``. ``P_j = G(θi) G(θo) inv_cc`` is the G-dependent part of Eq. 3.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _lerp(G, c, k, t):  # pragma: no cover
    """G of channel ``c`` linearly interpolated between samples ``k`` and ``k + 1``."""
    return G[c, k] + t * (G[c, k + 1] - G[c, k])


@njit(cache=True, nogil=True, inline="always")
def _g_pair(G, c, a, t, b, s):  # pragma: no cover
    """G of channel ``c`` at θi (cell ``a``, weight ``t``) and at θo (cell ``b``, weight ``s``)."""
    return _lerp(G, c, a, t), _lerp(G, c, b, s)


@njit(cache=True, nogil=True, inline="always")
def _clear(x, y, z):  # pragma: no cover
    """Set the accumulators ``x``, ``y``, ``z`` to 0."""
    x[:] = 0.0
    y[:] = 0.0
    z[:] = 0.0


@njit(cache=True, nogil=True, inline="always")
def _sample(hd, gi0, gti, go0, gto, inv_cc, j):  # pragma: no cover
    """Sample ``j``: its bin, the G cells and weights of θi and θo, ``1/(cos θi cos θo)``."""
    return hd[j], gi0[j], gti[j], go0[j], gto[j], inv_cc[j]


@njit(cache=True, nogil=True, inline="always")
def _p_terms(G, X, rho_d, w, z, c, j, k, a, t, b, s, ic, s1, s2, spz, e):  # pragma: no cover
    """Sample ``j``'s terms of channel ``c`` added to the running sums of :func:`p_stats`."""
    g_i, g_o = _g_pair(G, c, a, t, b, s)
    P = g_i * g_o * ic
    wj = w[c, j]
    zj = z[c, j]
    wp = wj * P
    r = rho_d[c] + X[c, k] * P - zj
    return s1 + wp, s2 + wp * P, spz + wp * zj, e + wj * r * r


@njit(cache=True, nogil=True, inline="always")
def _p_runs(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d, S1, S2, Spz,
            on0, on1, on2):  # pragma: no cover
    """The pass of :func:`p_stats` for the channels ``on0``, ``on1``, ``on2``."""
    n = hd.shape[0]
    e0 = e1 = e2 = 0.0
    s1_0 = s2_0 = sz_0 = s1_1 = s2_1 = sz_1 = s1_2 = s2_2 = sz_2 = 0.0
    k0 = hd[0] if n else 0
    for j in range(n + 1):
        k = hd[j] if j < n else -1
        if k != k0:                       # flush the run of bin k0
            S1[0, k0] += s1_0
            S2[0, k0] += s2_0
            Spz[0, k0] += sz_0
            S1[1, k0] += s1_1
            S2[1, k0] += s2_1
            Spz[1, k0] += sz_1
            S1[2, k0] += s1_2
            S2[2, k0] += s2_2
            Spz[2, k0] += sz_2
            s1_0 = s2_0 = sz_0 = s1_1 = s2_1 = sz_1 = s1_2 = s2_2 = sz_2 = 0.0
            k0 = k
        if j == n:
            break
        k, a, t, b, s, ic = _sample(hd, gi0, gti, go0, gto, inv_cc, j)
        if on0:
            s1_0, s2_0, sz_0, e0 = _p_terms(G, X, rho_d, w, z, 0, j, k, a, t, b, s, ic,
                                            s1_0, s2_0, sz_0, e0)
        if on1:
            s1_1, s2_1, sz_1, e1 = _p_terms(G, X, rho_d, w, z, 1, j, k, a, t, b, s, ic,
                                            s1_1, s2_1, sz_1, e1)
        if on2:
            s1_2, s2_2, sz_2, e2 = _p_terms(G, X, rho_d, w, z, 2, j, k, a, t, b, s, ic,
                                            s1_2, s2_2, sz_2, e2)
    return np.array([e0, e1, e2])


@njit(cache=True, nogil=True)
def p_stats(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d, S1, S2, Spz,
            chans):  # pragma: no cover
    """Accumulate per (θh, θd) bin ``S1 = Σ w P``, ``S2 = Σ w P²``, ``Spz = Σ w P z`` for the
    given G (3, 90) and return the exact objective (Eq. 7) per channel of the model
    ``ρd + X[hd] P`` (``X = ρs D F`` per bin, (3, 8100)), for the channels where ``chans``
    (3 bools) holds; the others' sums and objective are 0. A channel's sums do not depend on
    the others', so they are the same whichever channels are asked for.

    Samples come in MERL order, so a bin is a run of samples: its sums are kept in scalars
    over the run and added to the bin once (any order stays correct, one run per bin is
    fastest). All three channels take a copy of the pass without the channel tests."""
    _clear(S1, S2, Spz)
    if chans[0] and chans[1] and chans[2]:
        return _p_runs(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d, S1, S2, Spz,
                       True, True, True)
    return _p_runs(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d, S1, S2, Spz,
                   chans[0], chans[1], chans[2])


@njit(cache=True, nogil=True, inline="always")
def _tridiagonal_terms(cell, t, wj, y, r):  # pragma: no cover
    """One sample's terms added to the normal equations of the unknown G cells ``a``,
    ``a + 1`` (weights ``1 - t``, ``t``) of a model ``y ((1 - t) G_a + t G_{a+1})``, residual
    ``r``: ``cell`` = (diagonal a, diagonal a + 1, super-diagonal a, rhs a, rhs a + 1)."""
    wy2 = wj * y * y
    wyr = wj * y * r
    d0, d1, o, r0, r1 = cell
    return (d0 + wy2 * (1.0 - t) * (1.0 - t), d1 + wy2 * t * t, o + wy2 * t * (1.0 - t),
            r0 + wyr * (1.0 - t), r1 + wyr * t)


@njit(cache=True, nogil=True, inline="always")
def _load_cell(A_d, A_o, rhs, c, a):  # pragma: no cover
    """The entries of channel ``c``'s normal equations that a sample in G cell ``a`` adds to."""
    return A_d[c, a], A_d[c, a + 1], A_o[c, a], rhs[c, a], rhs[c, a + 1]


@njit(cache=True, nogil=True, inline="always")
def _store_cell(A_d, A_o, rhs, c, a, cell):  # pragma: no cover
    """Write back what :func:`_load_cell` read, with the samples' terms added."""
    A_d[c, a], A_d[c, a + 1], A_o[c, a], rhs[c, a], rhs[c, a + 1] = cell


@njit(cache=True, nogil=True, inline="always")
def _load_cells(A_d, A_o, rhs, a):  # pragma: no cover
    """:func:`_load_cell` of the three channels."""
    return (_load_cell(A_d, A_o, rhs, 0, a), _load_cell(A_d, A_o, rhs, 1, a),
            _load_cell(A_d, A_o, rhs, 2, a))


@njit(cache=True, nogil=True, inline="always")
def _store_cells(A_d, A_o, rhs, a, cells):  # pragma: no cover
    """:func:`_store_cell` of the three channels."""
    _store_cell(A_d, A_o, rhs, 0, a, cells[0])
    _store_cell(A_d, A_o, rhs, 1, a, cells[1])
    _store_cell(A_d, A_o, rhs, 2, a, cells[2])


@njit(cache=True, nogil=True, inline="always")
def _g_ne_terms(G, X, rho_d, w, z, c, j, k, a, t, b, s, ic, cell_i, cell_o):  # pragma: no cover
    """Sample ``j``'s terms of channel ``c`` added to its θi cell's and θo cell's entries of
    the normal equations of :func:`g_normal_equations`."""
    g_i, g_o = _g_pair(G, c, a, t, b, s)
    wj = w[c, j]
    r = z[c, j] - rho_d[c]
    xk = X[c, k] * ic
    # G(θi) unknown: model = y_i · ((1-t) G_a + t G_{a+1}), y_i = X G(θo) / cc; then G(θo)
    return (_tridiagonal_terms(cell_i, t, wj, xk * g_o, r),
            _tridiagonal_terms(cell_o, s, wj, xk * g_i, r))


@njit(cache=True, nogil=True, inline="always")
def _g_ne_pass(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d,
               Ai_d, Ai_o, bi, Ao_d, Ao_o, bo, on0, on1, on2):  # pragma: no cover
    """The pass of :func:`g_normal_equations` for the channels ``on0``, ``on1``, ``on2``.

    The entries a sample adds to are those of its θi cell and of its θo cell, and the next
    samples mostly share them (5-7 on MERL): they are kept in registers while the cell stays
    and written back when it changes. Every entry still receives the samples' terms one by
    one in sample order, so the sums are the same numbers as with an update in memory per
    sample, in 0.92× its time (the pass is bound by its arithmetic: docs/design/batch.md,
    session 32)."""
    if hd.shape[0] == 0:
        return
    ca, cb = gi0[0], go0[0]
    i0, i1, i2 = _load_cells(Ai_d, Ai_o, bi, ca)
    o0, o1, o2 = _load_cells(Ao_d, Ao_o, bo, cb)
    for j in range(hd.shape[0]):
        k, a, t, b, s, ic = _sample(hd, gi0, gti, go0, gto, inv_cc, j)
        if a != ca:
            _store_cells(Ai_d, Ai_o, bi, ca, (i0, i1, i2))
            ca = a
            i0, i1, i2 = _load_cells(Ai_d, Ai_o, bi, ca)
        if b != cb:
            _store_cells(Ao_d, Ao_o, bo, cb, (o0, o1, o2))
            cb = b
            o0, o1, o2 = _load_cells(Ao_d, Ao_o, bo, cb)
        if on0:
            i0, o0 = _g_ne_terms(G, X, rho_d, w, z, 0, j, k, a, t, b, s, ic, i0, o0)
        if on1:
            i1, o1 = _g_ne_terms(G, X, rho_d, w, z, 1, j, k, a, t, b, s, ic, i1, o1)
        if on2:
            i2, o2 = _g_ne_terms(G, X, rho_d, w, z, 2, j, k, a, t, b, s, ic, i2, o2)
    _store_cells(Ai_d, Ai_o, bi, ca, (i0, i1, i2))
    _store_cells(Ao_d, Ao_o, bo, cb, (o0, o1, o2))


@njit(cache=True, nogil=True)
def g_normal_equations(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d,
                       Ai_d, Ai_o, bi, Ao_d, Ao_o, bo, chans):  # pragma: no cover
    """Tridiagonal weighted least-squares normal equations (Eq. 13-14 generalised to the
    linear interpolation of G) for G(θi) with G(θo) held fixed (``Ai_d`` diagonal, ``Ai_o``
    super-diagonal, ``bi`` right-hand side, each per channel) and for G(θo) with G(θi) fixed
    (``Ao_*``, ``bo``), for the channels where ``chans`` (3 bools) holds (the others' are 0:
    a channel's sums do not depend on the others'). All three channels take a copy of the
    pass without the channel tests."""
    _clear(Ai_d, Ai_o, bi)
    _clear(Ao_d, Ao_o, bo)
    if chans[0] and chans[1] and chans[2]:
        _g_ne_pass(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d,
                   Ai_d, Ai_o, bi, Ao_d, Ao_o, bo, True, True, True)
    else:
        _g_ne_pass(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d,
                   Ai_d, Ai_o, bi, Ao_d, Ao_o, bo, chans[0], chans[1], chans[2])


@njit(cache=True, nogil=True, inline="always")
def _bin_factors(D, F, rho_s, h, d, q):  # pragma: no cover
    """``q = ρs D_h F_d`` per channel of bin (h, d): ``∂m/∂P`` of Eq. 3."""
    for c in range(3):
        q[c] = rho_s[c] * D[c, h] * F[c, d]


@njit(cache=True, nogil=True, inline="always")
def _flush_bin(D, F, rho_s, h, d, lo, hi, UTV, DG, FG, Grd, Grs, gG,
               curvature, HDG, HFG, HsG):  # pragma: no cover
    """Add the partial sums of one bin (h, d) over its G cells ``lo..hi`` (``UTV[c, cell]`` =
    ``U = Σ w ∂P/∂G``, ``T = Σ w P ∂P/∂G``, ``V = Σ w r ∂P/∂G``) times the bin's factors to the
    blocks, and clear them: every G block but GG and HGG is such a sum times a factor
    constant over the bin."""
    for c in range(3):
        rs, Dh, Fd = rho_s[c], D[c, h], F[c, d]
        q = rs * Dh * Fd
        cd, cf, cs = q * rs * Fd, q * rs * Dh, q * Dh * Fd
        for i in range(lo, hi + 1):
            u, tt, v = UTV[c, i, 0], UTV[c, i, 1], UTV[c, i, 2]
            DG[c, h, i] += cd * tt
            FG[c, d, i] += cf * tt
            Grs[c, i] += cs * tt
            Grd[c, i] += q * u
            gG[c, i] += q * v
            if curvature:
                HDG[c, h, i] += rs * Fd * v
                HFG[c, d, i] += rs * Dh * v
                HsG[c, i] += Dh * Fd * v
            UTV[c, i, 0] = 0.0
            UTV[c, i, 1] = 0.0
            UTV[c, i, 2] = 0.0


@njit(cache=True, nogil=True, inline="always")
def _add_cells(A, c, a, t, x, y, v):  # pragma: no cover
    """``A[c, ·] +=`` (``x``, ``y``, ``v``) times the interpolation weights ``1 - t``, ``t`` of
    the cells ``a``, ``a + 1`` (the three sums of a cell are adjacent)."""
    A[c, a, 0] += x * (1.0 - t)
    A[c, a, 1] += y * (1.0 - t)
    A[c, a, 2] += v * (1.0 - t)
    A[c, a + 1, 0] += x * t
    A[c, a + 1, 1] += y * t
    A[c, a + 1, 2] += v * t


@njit(cache=True, nogil=True, inline="always")
def _add_cross(M, c, a, t, b, s, e, f):  # pragma: no cover
    """``M[c, θi cell, θo cell] += (e, f) × weights``: the 2 × 2 block between cells a, a+1 and
    b, b+1 of the two interleaved matrices (one order; :func:`_mirror` adds the other)."""
    M[c, a, b, 0] += e * (1.0 - t) * (1.0 - s)
    M[c, a, b, 1] += f * (1.0 - t) * (1.0 - s)
    M[c, a, b + 1, 0] += e * (1.0 - t) * s
    M[c, a, b + 1, 1] += f * (1.0 - t) * s
    M[c, a + 1, b, 0] += e * t * (1.0 - s)
    M[c, a + 1, b, 1] += f * t * (1.0 - s)
    M[c, a + 1, b + 1, 0] += e * t * s
    M[c, a + 1, b + 1, 1] += f * t * s


@njit(cache=True, nogil=True, inline="always")
def _add_pair(M, c, a, t, e):  # pragma: no cover
    """``M[c, ·, ·, 0] += e (1 - t, t)ᵀ(1 - t, t)`` on cells a, a+1, upper triangle with the
    diagonal halved (:func:`_mirror` restores the whole)."""
    M[c, a, a, 0] += 0.5 * e * (1.0 - t) * (1.0 - t)
    M[c, a, a + 1, 0] += e * (1.0 - t) * t
    M[c, a + 1, a + 1, 0] += 0.5 * e * t * t


@njit(cache=True, nogil=True, inline="always")
def _mirror(M):  # pragma: no cover
    """``M[c] ← M[c] + M[c]ᵀ``, in place."""
    for c in range(M.shape[0]):
        for i in range(M.shape[1]):
            M[c, i, i] *= 2.0
            for j in range(i + 1, M.shape[2]):
                x = M[c, i, j] + M[c, j, i]
                M[c, i, j] = x
                M[c, j, i] = x


@njit(cache=True, nogil=True)
def g_jacobian_blocks(hd, gi0, gti, go0, gto, inv_cc, w, z, G, D, F, rho_d, rho_s,
                      GG, DG, FG, Grd, Grs, gG, curvature,
                      HGG, HDG, HFG, HsG):  # pragma: no cover
    """Blocks of JᵀWJ and JᵀWr involving G for the polish of Eq. 3 (per channel): ``GG``
    (3, 90, 90), ``DG`` (3, 90 θh, 90 G), ``FG`` (3, 90 θd, 90 G), ``Grd``, ``Grs``, ``gG``
    (3, 90). The blocks not involving G follow from the bin statistics.

    With ``P = G(θi) G(θo) / (cos θi cos θo)``, ``q = ρs D_h F_d``, ``r = ρd + q P − z`` and
    ``∂m/∂G_u = q ∂P/∂G_u``: ``GG_uv = Σ w q² ∂P/∂G_u ∂P/∂G_v``,
    ``DG_hu = Σ w q ρs F_d P ∂P/∂G_u``, ``FG_du = Σ w q ρs D_h P ∂P/∂G_u``,
    ``Grs_u = Σ w q D_h F_d P ∂P/∂G_u``, ``Grd_u = Σ w q ∂P/∂G_u``, ``gG_u = Σ w q r ∂P/∂G_u``.

    With ``curvature``, in the same pass, the blocks involving G of the residual-curvature
    term ``Σ w r ∇²m`` that Newton's Hessian adds to JᵀWJ: ``HGG`` (G enters twice, as
    G(θi)G(θo): ``Σ w r q ∂²P/∂G_u∂G_v`` between a θi and a θo cell, in both orders),
    ``HDG_hu = Σ w r ρs F_d ∂P/∂G_u``, ``HFG``, ``HsG`` (with ρs: ``D_h F_d``), shaped as their
    JᵀWJ counterparts.

    Samples come in MERL order, so a bin (h, d) is a run of samples: the factors constant over
    a bin are applied once per run (:func:`_flush_bin`); GG and HGG are accumulated as one
    triangle (one order of the θi–θo block), interleaved (a sample adds to the same cells of
    both), and mirrored at the end."""
    n, ng, nd = hd.shape[0], G.shape[1], F.shape[1]
    _clear(GG, DG, FG)
    _clear(Grd, Grs, gG)
    if curvature:
        _clear(HGG, HDG, HFG)
        HsG[:] = 0.0
    UTV, GH, q = np.zeros((3, ng, 3)), np.zeros((3, ng, ng, 2)), np.zeros(3)
    k0, lo, hi = -1, ng, 0
    for j in range(n):
        k, a, t, b, s, ic = _sample(hd, gi0, gti, go0, gto, inv_cc, j)
        if k != k0:
            if k0 >= 0:
                _flush_bin(D, F, rho_s, k0 // nd, k0 % nd, lo, hi, UTV, DG, FG, Grd, Grs,
                           gG, curvature, HDG, HFG, HsG)
            k0, lo, hi = k, ng, 0
            _bin_factors(D, F, rho_s, k // nd, k % nd, q)
        lo = min(lo, a, b)
        hi = max(hi, a + 1, b + 1)
        for c in range(3):
            g_i, g_o = _g_pair(G, c, a, t, b, s)
            x_i, x_o = ic * g_o, ic * g_i          # ∂P/∂G(θi), ∂P/∂G(θo)
            P = g_i * g_o * ic
            wj = w[c, j]
            r = rho_d[c] + q[c] * P - z[c, j]
            wx_i, wx_o = wj * x_i, wj * x_o
            _add_cells(UTV, c, a, t, wx_i, wx_i * P, wx_i * r)
            _add_cells(UTV, c, b, s, wx_o, wx_o * P, wx_o * r)
            wq2 = wj * q[c] * q[c]
            _add_pair(GH, c, a, t, wq2 * x_i * x_i)
            _add_pair(GH, c, b, s, wq2 * x_o * x_o)
            _add_cross(GH, c, a, t, b, s, wq2 * x_i * x_o,
                       wj * r * q[c] * ic if curvature else 0.0)
    if k0 >= 0:
        _flush_bin(D, F, rho_s, k0 // nd, k0 % nd, lo, hi, UTV, DG, FG, Grd, Grs, gG,
                   curvature, HDG, HFG, HsG)
    GG[:] = GH[..., 0]
    _mirror(GG)
    if curvature:
        HGG[:] = GH[..., 1]
        _mirror(HGG)


@njit(cache=True, nogil=True, inline="always")
def _line_terms(G, dG, w, z, c, j, a, t, b, s, ic, q):  # pragma: no cover
    """Sample ``j``'s terms of channel ``c`` added to the running sums ``q`` (11 values, as
    ``Q[c, bin]``) of :func:`p_stats_line`; returns the new sums."""
    g_i, g_o = _g_pair(G, c, a, t, b, s)
    d_i, d_o = _g_pair(dG, c, a, t, b, s)
    wj = w[c, j] * ic
    p0 = g_i * g_o
    p1 = g_i * d_o + d_i * g_o
    p2 = d_i * d_o
    wz = wj * z[c, j]
    w2 = wj * ic
    return (q[0] + wj * p0, q[1] + wj * p1, q[2] + wj * p2,
            q[3] + w2 * p0 * p0, q[4] + w2 * 2.0 * p0 * p1,
            q[5] + w2 * (p1 * p1 + 2.0 * p0 * p2), q[6] + w2 * 2.0 * p1 * p2,
            q[7] + w2 * p2 * p2, q[8] + wz * p0, q[9] + wz * p1, q[10] + wz * p2)


@njit(cache=True, nogil=True, inline="always")
def _flush_line(Q, c, k, q):  # pragma: no cover
    """Add a run's sums ``q`` to ``Q[c, k]``."""
    for m in range(11):
        Q[c, k, m] += q[m]


_NO_LINE_SUMS = (0.0,) * 11


@njit(cache=True, nogil=True, inline="always")
def _line_pass(hd, gi0, gti, go0, gto, inv_cc, w, z, G, dG, Q, on0, on1, on2):  # pragma: no cover
    """The pass of :func:`p_stats_line` for the channels ``on0``, ``on1``, ``on2``: a bin's
    sums are kept in registers over its run of samples and added to ``Q`` once, like
    :func:`_p_runs`."""
    n = hd.shape[0]
    q0 = q1 = q2 = _NO_LINE_SUMS
    k0 = hd[0] if n else 0
    for j in range(n + 1):
        k = hd[j] if j < n else -1
        if k != k0:                       # flush the run of bin k0
            _flush_line(Q, 0, k0, q0)
            _flush_line(Q, 1, k0, q1)
            _flush_line(Q, 2, k0, q2)
            q0 = q1 = q2 = _NO_LINE_SUMS
            k0 = k
        if j == n:
            break
        k, a, t, b, s, ic = _sample(hd, gi0, gti, go0, gto, inv_cc, j)
        if on0:
            q0 = _line_terms(G, dG, w, z, 0, j, a, t, b, s, ic, q0)
        if on1:
            q1 = _line_terms(G, dG, w, z, 1, j, a, t, b, s, ic, q1)
        if on2:
            q2 = _line_terms(G, dG, w, z, 2, j, a, t, b, s, ic, q2)


@njit(cache=True, nogil=True)
def p_stats_line(hd, gi0, gti, go0, gto, inv_cc, w, z, G, dG, Q, chans):  # pragma: no cover
    """Polynomial coefficients in ``t`` of the bin statistics along the G line
    ``G + t dG``: ``P(t) = p0 + p1 t + p2 t²`` per sample, and per (channel, bin) ``Q[..., 0:3]``
    = ``Σ w p_m`` (S1), ``Q[..., 3:8]`` = the quartic of ``Σ w P²`` (S2), ``Q[..., 8:11]`` =
    ``Σ w z p_m`` (Spz). ``Q`` is (3, 8100, 11); channels where ``chans`` (3 bools) does not
    hold are 0."""
    Q[:] = 0.0
    if chans[0] and chans[1] and chans[2]:
        _line_pass(hd, gi0, gti, go0, gto, inv_cc, w, z, G, dG, Q, True, True, True)
    else:
        _line_pass(hd, gi0, gti, go0, gto, inv_cc, w, z, G, dG, Q, chans[0], chans[1],
                   chans[2])
