"""Numba kernels of the AWLS fit: one pass over the ~1.5 M MERL samples, all 3 channels.

Every sample ``j`` carries precomputed data (built once per fit): its (θh, θd) bin ``hd``
(= ``ih·90 + id``), the G interpolation cell/weight for θi (``gi0``, ``gti``) and θo (``go0``,
``gto``), ``inv_cc = 1/(cos θi cos θo)``, and per channel the weight ``w`` (Eq. 8) and the
measurement ``z``. ``P_j = G(θi) G(θo) inv_cc`` is the G-dependent part of Eq. 3.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def p_stats(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d, S1, S2, Spz):  # pragma: no cover
    """Accumulate per (θh, θd) bin ``S1 = Σ w P``, ``S2 = Σ w P²``, ``Spz = Σ w P z`` for the
    given G (3, 90) and return the exact objective (Eq. 7) per channel of the model
    ``ρd + X[hd] P`` (``X = ρs D F`` per bin, (3, 8100))."""
    n = hd.shape[0]
    E = np.zeros(3)
    S1[:] = 0.0
    S2[:] = 0.0
    Spz[:] = 0.0
    for j in range(n):
        k = hd[j]
        a = gi0[j]
        t = gti[j]
        b = go0[j]
        s = gto[j]
        ic = inv_cc[j]
        for c in range(3):
            g_i = G[c, a] + t * (G[c, a + 1] - G[c, a])
            g_o = G[c, b] + s * (G[c, b + 1] - G[c, b])
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


@njit(cache=True, nogil=True)
def g_normal_equations(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d,
                       Ai_d, Ai_o, bi, Ao_d, Ao_o, bo):  # pragma: no cover
    """Tridiagonal weighted least-squares normal equations (Eq. 13-14 generalised to the
    linear interpolation of G) for G(θi) with G(θo) held fixed (``Ai_d`` diagonal, ``Ai_o``
    super-diagonal, ``bi`` right-hand side, each per channel) and for G(θo) with G(θi) fixed
    (``Ao_*``, ``bo``)."""
    n = hd.shape[0]
    Ai_d[:] = 0.0
    Ai_o[:] = 0.0
    bi[:] = 0.0
    Ao_d[:] = 0.0
    Ao_o[:] = 0.0
    bo[:] = 0.0
    for j in range(n):
        k = hd[j]
        a = gi0[j]
        t = gti[j]
        b = go0[j]
        s = gto[j]
        ic = inv_cc[j]
        for c in range(3):
            g_i = G[c, a] + t * (G[c, a + 1] - G[c, a])
            g_o = G[c, b] + s * (G[c, b + 1] - G[c, b])
            wj = w[c, j]
            r = z[c, j] - rho_d[c]
            xk = X[c, k] * ic
            # G(θi) unknown: model = y_i · ((1-t) G_a + t G_{a+1}), y_i = X G(θo) / cc
            y = xk * g_o
            wy2 = wj * y * y
            wyr = wj * y * r
            Ai_d[c, a] += wy2 * (1.0 - t) * (1.0 - t)
            Ai_d[c, a + 1] += wy2 * t * t
            Ai_o[c, a] += wy2 * t * (1.0 - t)
            bi[c, a] += wyr * (1.0 - t)
            bi[c, a + 1] += wyr * t
            # G(θo) unknown
            y = xk * g_i
            wy2 = wj * y * y
            wyr = wj * y * r
            Ao_d[c, b] += wy2 * (1.0 - s) * (1.0 - s)
            Ao_d[c, b + 1] += wy2 * s * s
            Ao_o[c, b] += wy2 * s * (1.0 - s)
            bo[c, b] += wyr * (1.0 - s)
            bo[c, b + 1] += wyr * s
