"""The AWLS / Newton kernels of the NPF fit (``brdffit.fit.npf._kernels``) against the
straightforward per-sample loops they replace (kept here as references): same sums, to
rounding, on random samples in MERL order (bins in runs, as the fit passes them) and shuffled
(every bin split in several runs), with and without the residual-curvature blocks."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from brdffit.fit.npf import _kernels

NH, ND, NG = 90, 90, 90


@njit
def ref_p_stats(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d, S1, S2, Spz):
    """Reference: per-sample accumulation into the bins."""
    E = np.zeros(3)
    S1[:] = 0.0
    S2[:] = 0.0
    Spz[:] = 0.0
    for j in range(hd.shape[0]):
        k, a, t, b, s, ic = hd[j], gi0[j], gti[j], go0[j], gto[j], inv_cc[j]
        for c in range(3):
            g_i = G[c, a] + t * (G[c, a + 1] - G[c, a])
            g_o = G[c, b] + s * (G[c, b + 1] - G[c, b])
            P = g_i * g_o * ic
            wp = w[c, j] * P
            S1[c, k] += wp
            S2[c, k] += wp * P
            Spz[c, k] += wp * z[c, j]
            r = rho_d[c] + X[c, k] * P - z[c, j]
            E[c] += w[c, j] * r * r
    return E


@njit
def ref_g_jacobian_blocks(hd, gi0, gti, go0, gto, inv_cc, w, z, G, D, F, rho_d, rho_s,
                          GG, DG, FG, Grd, Grs, gG, curvature, HGG, HDG, HFG, HsG):
    """Reference: every term of every sample, both orders of every G pair."""
    for A in (GG, DG, FG, HGG, HDG, HFG):
        A[:] = 0.0
    for A in (Grd, Grs, gG, HsG):
        A[:] = 0.0
    nd = F.shape[1]
    idx = np.empty(4, dtype=np.int64)
    dp = np.empty(4)
    for j in range(hd.shape[0]):
        k, a, t, b, s, ic = hd[j], gi0[j], gti[j], go0[j], gto[j], inv_cc[j]
        h, d = k // nd, k % nd
        idx[0], idx[1], idx[2], idx[3] = a, a + 1, b, b + 1
        for c in range(3):
            g_i = G[c, a] + t * (G[c, a + 1] - G[c, a])
            g_o = G[c, b] + s * (G[c, b + 1] - G[c, b])
            P = g_i * g_o * ic
            df = D[c, h] * F[c, d]
            dp[0], dp[1] = ic * g_o * (1.0 - t), ic * g_o * t
            dp[2], dp[3] = ic * g_i * (1.0 - s), ic * g_i * s
            q = rho_s[c] * df
            wj = w[c, j]
            r = rho_d[c] + q * P - z[c, j]
            for u in range(4):
                e = wj * q * dp[u]
                iu = idx[u]
                DG[c, h, iu] += e * rho_s[c] * F[c, d] * P
                FG[c, d, iu] += e * rho_s[c] * D[c, h] * P
                Grs[c, iu] += e * df * P
                Grd[c, iu] += e
                gG[c, iu] += e * r
                for v in range(4):
                    GG[c, iu, idx[v]] += e * q * dp[v]
            if curvature:
                wr = wj * r
                for u in range(4):
                    e = wr * dp[u]
                    HDG[c, h, idx[u]] += e * rho_s[c] * F[c, d]
                    HFG[c, d, idx[u]] += e * rho_s[c] * D[c, h]
                    HsG[c, idx[u]] += e * df
                for u in range(2):
                    wu = (1.0 - t) if u == 0 else t
                    for v in range(2, 4):
                        e = wr * q * ic * wu * ((1.0 - s) if v == 2 else s)
                        HGG[c, idx[u], idx[v]] += e
                        HGG[c, idx[v], idx[u]] += e


def _samples(order, n_bins=300, seed=0):
    """Random samples of ``n_bins`` (θh, θd) bins, 1-40 samples each, G cells anywhere (also
    a = b and |a − b| = 1), w ≥ 0 with some zeros, z around the model (residuals of both
    signs); ``order``: "merl" (bins in runs, ascending) or "shuffled"."""
    rng = np.random.default_rng(seed)
    bins = np.sort(rng.choice(NH * ND, n_bins, replace=False))
    hd = np.repeat(bins, rng.integers(1, 41, n_bins)).astype(np.int64)
    n = hd.size
    gi0 = rng.integers(0, NG - 1, n).astype(np.int64)
    go0 = np.where(rng.random(n) < 0.2, gi0 + rng.integers(-1, 2, n), rng.integers(0, NG - 1, n))
    go0 = np.clip(go0, 0, NG - 2).astype(np.int64)
    gti, gto = rng.random(n), rng.random(n)
    gti[:5], gto[5:10] = 0.0, 1.0
    inv_cc = 1.0 / (rng.uniform(0.05, 1.0, n) * rng.uniform(0.05, 1.0, n))
    w = rng.random((3, n)) * (rng.random((3, n)) > 0.05)
    z = rng.uniform(0.0, 3.0, (3, n))
    arrays = [hd, gi0, gti, go0, gto, inv_cc, w, z]
    if order == "shuffled":
        p = rng.permutation(n)
        arrays = [a[..., p] for a in arrays]
    factors = dict(G=rng.uniform(0.2, 1.2, (3, NG)), D=rng.uniform(0.0, 2.0, (3, NH)),
                   F=rng.uniform(0.3, 1.0, (3, ND)), rho_d=rng.uniform(0.0, 0.3, 3),
                   rho_s=rng.uniform(0.2, 1.0, 3))
    return [np.ascontiguousarray(a) for a in arrays], factors


def _close(new, ref, rtol=1e-12):
    """Equal to rounding: elementwise ``rtol``, with the floor ``rtol × max |ref|`` for sums
    whose terms cancel (the residual has both signs)."""
    np.testing.assert_allclose(new, ref, rtol=rtol, atol=rtol * np.abs(ref).max())


@pytest.mark.parametrize("order", ["merl", "shuffled"])
def test_p_stats_matches_reference(order):
    arrays, f = _samples(order)
    X = (f["rho_s"][:, None, None] * f["D"][:, :, None] * f["F"][:, None, :]).reshape(3, -1)
    out_new = [np.full((3, NH * ND), np.nan) for _ in range(3)]
    out_ref = [np.full((3, NH * ND), np.nan) for _ in range(3)]
    E_new = _kernels.p_stats(*arrays, f["G"], X, f["rho_d"], *out_new, np.ones(3, bool))
    E_ref = ref_p_stats(*arrays, f["G"], X, f["rho_d"], *out_ref)
    _close(E_new, E_ref)
    for a, b in zip(out_new, out_ref):
        _close(a, b)
    if order == "merl":              # one run per bin: the same additions in the same order
        assert all(np.array_equal(a, b) for a, b in zip(out_new, out_ref))
        assert np.array_equal(E_new, E_ref)


@pytest.mark.parametrize("chans", [(True, False, True), (False, True, False), (False,) * 3])
def test_p_stats_channels_asked_are_those_of_all_channels(chans):
    """A channel's sums and objective are bit for bit those of the all-channel pass; the
    channels not asked for are 0."""
    arrays, f = _samples("merl", seed=2)
    X = (f["rho_s"][:, None, None] * f["D"][:, :, None] * f["F"][:, None, :]).reshape(3, -1)
    full = [np.full((3, NH * ND), np.nan) for _ in range(3)]
    part = [np.full((3, NH * ND), np.nan) for _ in range(3)]
    E_full = _kernels.p_stats(*arrays, f["G"], X, f["rho_d"], *full, np.ones(3, bool))
    E_part = _kernels.p_stats(*arrays, f["G"], X, f["rho_d"], *part, np.array(chans))
    on = np.array(chans)
    assert np.array_equal(E_part[on], E_full[on]) and np.all(E_part[~on] == 0.0)
    for a, b in zip(part, full):
        assert np.array_equal(a[on], b[on]) and np.all(a[~on] == 0.0)


def _blocks(fill):
    shapes = [(3, NG, NG), (3, NH, NG), (3, ND, NG), (3, NG), (3, NG), (3, NG),
              (3, NG, NG), (3, NH, NG), (3, ND, NG), (3, NG)]
    return [np.full(s, fill) for s in shapes]


@pytest.mark.parametrize("order", ["merl", "shuffled"])
@pytest.mark.parametrize("curvature", [False, True])
def test_g_jacobian_blocks_match_reference(order, curvature):
    arrays, f = _samples(order, seed=1)
    args = [*arrays, f["G"], f["D"], f["F"], f["rho_d"], f["rho_s"]]
    new, ref = _blocks(np.nan), _blocks(0.0)
    _kernels.g_jacobian_blocks(*args, *new[:6], curvature, *new[6:])
    ref_g_jacobian_blocks(*args, *ref[:6], curvature, *ref[6:])
    names = ["GG", "DG", "FG", "Grd", "Grs", "gG", "HGG", "HDG", "HFG", "HsG"]
    for name, a, b in zip(names[:6] if not curvature else names, new, ref):
        assert np.all(np.isfinite(a)), name
        _close(a, b)
    assert np.array_equal(new[0], np.swapaxes(new[0], 1, 2))          # GG symmetric
    if curvature:
        assert np.array_equal(new[6], np.swapaxes(new[6], 1, 2))      # HGG symmetric
        assert np.abs(new[6]).max() > 0 and np.abs(new[7]).max() > 0


def test_g_jacobian_blocks_without_samples_are_zero():
    arrays, f = _samples("merl")
    arrays = [a[..., :0] for a in arrays]
    new = _blocks(np.nan)
    _kernels.g_jacobian_blocks(*arrays, f["G"], f["D"], f["F"], f["rho_d"], f["rho_s"],
                               *new[:6], True, *new[6:])
    assert all(np.all(a == 0.0) for a in new)


@njit
def ref_g_normal_equations(hd, gi0, gti, go0, gto, inv_cc, w, z, G, X, rho_d,
                           Ai_d, Ai_o, bi, Ao_d, Ao_o, bo, chans):
    """Reference: every sample's terms added to the entries in memory, one by one."""
    for A in (Ai_d, Ai_o, bi, Ao_d, Ao_o, bo):
        A[:] = 0.0
    for j in range(hd.shape[0]):
        k, a, t, b, s, ic = hd[j], gi0[j], gti[j], go0[j], gto[j], inv_cc[j]
        for c in range(3):
            if not chans[c]:
                continue
            g_i = G[c, a] + t * (G[c, a + 1] - G[c, a])
            g_o = G[c, b] + s * (G[c, b + 1] - G[c, b])
            r = z[c, j] - rho_d[c]
            xk = X[c, k] * ic
            for A_d, A_o, rhs, u, v, y in ((Ai_d, Ai_o, bi, a, t, xk * g_o),
                                           (Ao_d, Ao_o, bo, b, s, xk * g_i)):
                wy2 = w[c, j] * y * y
                wyr = w[c, j] * y * r
                A_d[c, u] += wy2 * (1.0 - v) * (1.0 - v)
                A_d[c, u + 1] += wy2 * v * v
                A_o[c, u] += wy2 * v * (1.0 - v)
                rhs[c, u] += wyr * (1.0 - v)
                rhs[c, u + 1] += wyr * v


@pytest.mark.parametrize("order", ["merl", "shuffled"])
@pytest.mark.parametrize("chans", [(True,) * 3, (True, False, True), (False, True, False)])
def test_g_normal_equations_are_the_per_sample_sums(order, chans):
    """The entries kept in registers over a run of samples in one G cell get the same terms
    in the same order as per-sample updates in memory: the same numbers, bit for bit."""
    arrays, f = _samples(order, seed=3)
    X = (f["rho_s"][:, None, None] * f["D"][:, :, None] * f["F"][:, None, :]).reshape(3, -1)
    new = [np.full((3, NG), np.nan) for _ in range(6)]
    ref = [np.full((3, NG), np.nan) for _ in range(6)]
    _kernels.g_normal_equations(*arrays, f["G"], X, f["rho_d"], *new, np.array(chans))
    ref_g_normal_equations(*arrays, f["G"], X, f["rho_d"], *ref, np.array(chans))
    for a, b in zip(new, ref):
        assert np.array_equal(a, b)
    on = np.array(chans)
    assert all(np.abs(a[on]).max() > 0 and np.all(a[~on] == 0.0) for a in new[:1])
    empty = [a[..., :0] for a in arrays]
    _kernels.g_normal_equations(*empty, f["G"], X, f["rho_d"], *new, np.array(chans))
    assert all(np.all(a == 0.0) for a in new)
