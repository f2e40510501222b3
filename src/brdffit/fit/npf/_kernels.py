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


@njit(cache=True, nogil=True)
def p_stats(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d, S1, S2, Spz):  # pragma: no cover
    """Accumulate per (θh, θd) bin ``S1 = Σ w P``, ``S2 = Σ w P²``, ``Spz = Σ w P z`` for the
    given G (3, 90) and return the exact objective (Eq. 7) per channel of the model
    ``ρd + X[hd] P`` (``X = ρs D F`` per bin, (3, 8100))."""
    n = hd.shape[0]
    E = np.zeros(3)
    _clear(S1, S2, Spz)
    for j in range(n):
        k, a, t, b, s, ic = _sample(hd, gi0, gti, go0, gto, inv_cc, j)
        for c in range(3):
            g_i, g_o = _g_pair(G, c, a, t, b, s)
            P = g_i * g_o * ic
            wj = w[c, j]
            zj = z[c, j]
            wp = wj * P
            S1[c, k] += wp
            S2[c, k] += wp * P
            Spz[c, k] += wp * zj
            r = rho_d[c] + X[c, k] * P - zj
            E[c] += wj * r * r
    return E


@njit(cache=True, nogil=True, inline="always")
def _add_tridiagonal(A_d, A_o, rhs, c, a, t, wj, y, r):  # pragma: no cover
    """Add one sample's terms to the normal equations of the unknown G cells ``a``, ``a + 1``
    (weights ``1 - t``, ``t``) of a model ``y ((1 - t) G_a + t G_{a+1})``, residual ``r``."""
    wy2 = wj * y * y
    wyr = wj * y * r
    A_d[c, a] += wy2 * (1.0 - t) * (1.0 - t)
    A_d[c, a + 1] += wy2 * t * t
    A_o[c, a] += wy2 * t * (1.0 - t)
    rhs[c, a] += wyr * (1.0 - t)
    rhs[c, a + 1] += wyr * t


@njit(cache=True, nogil=True)
def g_normal_equations(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d,
                       Ai_d, Ai_o, bi, Ao_d, Ao_o, bo):  # pragma: no cover
    """Tridiagonal weighted least-squares normal equations (Eq. 13-14 generalised to the
    linear interpolation of G) for G(θi) with G(θo) held fixed (``Ai_d`` diagonal, ``Ai_o``
    super-diagonal, ``bi`` right-hand side, each per channel) and for G(θo) with G(θi) fixed
    (``Ao_*``, ``bo``)."""
    n = hd.shape[0]
    _clear(Ai_d, Ai_o, bi)
    _clear(Ao_d, Ao_o, bo)
    for j in range(n):
        k, a, t, b, s, ic = _sample(hd, gi0, gti, go0, gto, inv_cc, j)
        for c in range(3):
            g_i, g_o = _g_pair(G, c, a, t, b, s)
            wj = w[c, j]
            r = z[c, j] - rho_d[c]
            xk = X[c, k] * ic
            # G(θi) unknown: model = y_i · ((1-t) G_a + t G_{a+1}), y_i = X G(θo) / cc
            _add_tridiagonal(Ai_d, Ai_o, bi, c, a, t, wj, xk * g_o, r)
            # G(θo) unknown
            _add_tridiagonal(Ao_d, Ao_o, bo, c, b, s, wj, xk * g_i, r)


@njit(cache=True, nogil=True)
def g_jacobian_blocks(hd, gi0, gti, go0, gto, inv_cc, w, z, G, D, F, rho_d, rho_s,
                      GG, DG, FG, Grd, Grs, gG, curvature,
                      HGG, HDG, HFG, HsG):  # pragma: no cover
    """Blocks of JᵀWJ and JᵀWr involving G for the polish of Eq. 3 (per channel): ``GG``
    (3, 90, 90), ``DG`` (3, 90 θh, 90 G), ``FG`` (3, 90 θd, 90 G), ``Grd``, ``Grs``, ``gG``
    (3, 90). The blocks not involving G follow from the bin statistics.

    With ``curvature``, in the same pass, the blocks involving G of the residual-curvature
    term ``Σ w r ∇²m`` that Newton's Hessian adds to JᵀWJ: ``HGG`` (G enters twice, as
    G(θi)G(θo)), ``HDG``, ``HFG``, ``HsG`` (with ρs), shaped as their JᵀWJ counterparts."""
    n = hd.shape[0]
    nd = F.shape[1]
    _clear(GG, DG, FG)
    _clear(Grd, Grs, gG)
    if curvature:
        _clear(HGG, HDG, HFG)
        HsG[:] = 0.0
    idx = np.empty(4, dtype=np.int64)
    dp = np.empty(4)
    for j in range(n):
        k, a, t, b, s, ic = _sample(hd, gi0, gti, go0, gto, inv_cc, j)
        h = k // nd
        d = k - h * nd
        idx[0] = a
        idx[1] = a + 1
        idx[2] = b
        idx[3] = b + 1
        for c in range(3):
            g_i, g_o = _g_pair(G, c, a, t, b, s)
            P = g_i * g_o * ic
            df = D[c, h] * F[c, d]
            # ∂P/∂G_u, P = G(θi) G(θo) / (cos θi cos θo); ∂m/∂G_u = ρs D F ∂P/∂G_u
            dp[0] = ic * g_o * (1.0 - t)
            dp[1] = ic * g_o * t
            dp[2] = ic * g_i * (1.0 - s)
            dp[3] = ic * g_i * s
            q = rho_s[c] * df
            wj = w[c, j]
            r = rho_d[c] + rho_s[c] * df * P - z[c, j]
            jd = rho_s[c] * F[c, d] * P
            jf = rho_s[c] * D[c, h] * P
            js = df * P
            for u in range(4):
                e = wj * q * dp[u]
                iu = idx[u]
                DG[c, h, iu] += e * jd
                FG[c, d, iu] += e * jf
                Grs[c, iu] += e * js
                Grd[c, iu] += e
                gG[c, iu] += e * r
                for v in range(4):
                    GG[c, iu, idx[v]] += e * q * dp[v]
            if curvature:
                # ∂²m/∂D_h∂G_u = ρs F_d ∂P/∂G_u, likewise F_d and ρs; ∂²P/∂G_u∂G_v between
                # the θi cell (u) and the θo cell (v), in both orders
                wr = wj * r
                for u in range(4):
                    e = wr * dp[u]
                    iu = idx[u]
                    HDG[c, h, iu] += e * rho_s[c] * F[c, d]
                    HFG[c, d, iu] += e * rho_s[c] * D[c, h]
                    HsG[c, iu] += e * df
                e_io = wr * q * ic
                for u in range(2):
                    wu = (1.0 - t) if u == 0 else t
                    for v in range(2, 4):
                        e = e_io * wu * ((1.0 - s) if v == 2 else s)
                        HGG[c, idx[u], idx[v]] += e
                        HGG[c, idx[v], idx[u]] += e


@njit(cache=True, nogil=True)
def p_stats_line(hd, gi0, gti, go0, gto, inv_cc, w, z, G, dG, Q):  # pragma: no cover
    """Polynomial coefficients in ``t`` of the bin statistics along the G line
    ``G + t dG``: ``P(t) = p0 + p1 t + p2 t²`` per sample, and per (channel, bin) ``Q[..., 0:3]``
    = ``Σ w p_m`` (S1), ``Q[..., 3:8]`` = the quartic of ``Σ w P²`` (S2), ``Q[..., 8:11]`` =
    ``Σ w z p_m`` (Spz). ``Q`` is (3, 8100, 11)."""
    n = hd.shape[0]
    Q[:] = 0.0
    for j in range(n):
        k, a, t, b, s, ic = _sample(hd, gi0, gti, go0, gto, inv_cc, j)
        for c in range(3):
            g_i, g_o = _g_pair(G, c, a, t, b, s)
            d_i, d_o = _g_pair(dG, c, a, t, b, s)
            wj = w[c, j] * ic
            p0 = g_i * g_o
            p1 = g_i * d_o + d_i * g_o
            p2 = d_i * d_o
            wz = wj * z[c, j]
            w2 = wj * ic
            q = Q[c, k]
            q[0] += wj * p0
            q[1] += wj * p1
            q[2] += wj * p2
            q[3] += w2 * p0 * p0
            q[4] += w2 * 2.0 * p0 * p1
            q[5] += w2 * (p1 * p1 + 2.0 * p0 * p2)
            q[6] += w2 * 2.0 * p1 * p2
            q[7] += w2 * p2 * p2
            q[8] += wz * p0
            q[9] += wz * p1
            q[10] += wz * p2

