"""NumPy translation of :data:`brdffit.export.glsl.GLSL_LIBRARY`, function by function.

Every function here has the name, arguments and formulas of its GLSL twin (vectorised over
the leading axis of the direction arrays; scalars stay scalars); ``texelFetch`` reads the
same float32 texture arrays ``(rows, width, 3)``. :func:`eval_spec` is ``brdffit_eval`` of
:func:`brdffit.export.glsl.glsl_source`. Used by the tests to check the GLSL numerically
against the library's ``eval`` (the GLSL itself is compiled by ``glslangValidator``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["eval_spec"]

BF_PI = np.pi


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def _clamp(x, lo, hi):
    return np.clip(x, lo, hi)


def bf_quad_inv(s, ell):
    X = s[..., 0] / ell[0]
    Y = s[..., 1] / ell[1]
    return (X * X - 2.0 * ell[2] * X * Y + Y * Y) / (1.0 - ell[2] * ell[2])


def bf_quad(w, ell):
    return (ell[0] * ell[0] * w[..., 0] * w[..., 0] + 2.0 * ell[2] * ell[0] * ell[1] * w[..., 0] * w[..., 1]
            + ell[1] * ell[1] * w[..., 1] * w[..., 1])


def bf_det_sqrt(ell):
    return ell[0] * ell[1] * np.sqrt(1.0 - ell[2] * ell[2])


def bf_ggx_D(m, ell):
    q = m[..., 2] * m[..., 2] + bf_quad_inv(m[..., :2], ell)
    return np.where(m[..., 2] <= 0.0, 0.0, 1.0 / (BF_PI * bf_det_sqrt(ell) * q * q))


def bf_ggx_lambda(w, ell):
    return 0.5 * (np.sqrt(1.0 + bf_quad(w[..., :2], ell) / (w[..., 2] * w[..., 2])) - 1.0)


def bf_erfc(x):
    t = 1.0 / (1.0 + 0.3275911 * x)
    poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741
                + t * (-1.453152027 + t * 1.061405429))))
    return poly * np.exp(-x * x)


def bf_beckmann_D(m, ell):
    mz2 = m[..., 2] * m[..., 2]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        v = np.exp(-bf_quad_inv(m[..., :2], ell) / mz2) / (BF_PI * bf_det_sqrt(ell) * mz2 * mz2)
    return np.where(m[..., 2] <= 0.0, 0.0, v)


def bf_beckmann_lambda(w, ell):
    q = bf_quad(w[..., :2], ell)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = w[..., 2] / np.sqrt(q)
        v = 0.5 * (np.exp(-a * a) / (a * np.sqrt(BF_PI)) - bf_erfc(a))
    return np.where(q <= 0.0, 0.0, v)


def bf_sgd_D(m, alpha, p, log_norm):
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        x = _dot(m[..., :2], m[..., :2]) / (m[..., 2] * m[..., 2])
        t = alpha + x / alpha
        mz2 = m[..., 2] * m[..., 2]
        v = np.exp(-p * np.log(t) - t - log_norm) / (mz2 * mz2)
    return np.where(m[..., 2] <= 0.0, 0.0, v)


def bf_g1_eq9(theta, lam, c, k):
    theta0 = 0.5 * BF_PI - (np.log(1.0 + 1.0 / lam) / c) ** (1.0 / k)
    with np.errstate(invalid="ignore", over="ignore"):
        g = 1.0 + lam * (1.0 - np.exp(c * np.maximum(theta - theta0, 0.0) ** k))
    g = np.clip(g, 0.0, 1.0)
    g = np.where(theta <= theta0, 1.0, g)
    return np.where(theta >= 0.5 * BF_PI, 0.0, g)


def bf_lambda_eq9(w, lam, c, k):
    g = bf_g1_eq9(np.arccos(_clamp(w[..., 2], -1.0, 1.0)), lam, c, k)
    with np.errstate(divide="ignore"):
        return 1.0 / g - 1.0


def texelFetch(tex, x, row):                                         # noqa: N802 (GLSL name)
    return np.asarray(tex[row, x], dtype=np.float64)


def bf_row_lerp(tex, row, offset, n, u):
    u = _clamp(u, 0.0, float(n - 1))
    i0 = np.minimum(u.astype(np.int64), n - 2)
    t = (u - i0)[..., None]
    a = texelFetch(tex, offset + i0, row)
    b = texelFetch(tex, offset + i0 + 1, row)
    return a * (1.0 - t) + b * t


def bf_table_D(m, tex, n):
    u = np.sqrt(np.arccos(_clamp(m[..., 2], 0.0, 1.0)) * (2.0 / BF_PI)) * float(n - 1)
    return np.where(m[..., 2] <= 0.0, 0.0, np.exp(bf_row_lerp(tex, 0, 0, n, u)[..., 0]))


def bf_table_lambda(w, tex, n):
    u = np.sqrt(np.arccos(_clamp(w[..., 2], 0.0, 1.0)) * (2.0 / BF_PI)) * float(n - 1)
    return bf_row_lerp(tex, 1, 0, n, u)[..., 0] / w[..., 2] - 1.0


def _mix(x, y, a):
    return x * (1.0 - a) + y * a


def bf_table2_lookup(tex, row0, nu, nphi, u, phi):
    u = _clamp(u, 0.0, float(nu - 1))
    i0 = np.minimum(u.astype(np.int64), nu - 2)
    s = u - i0
    v = np.mod(phi, 2.0 * BF_PI) / (2.0 * BF_PI) * float(nphi)
    j0 = np.floor(v).astype(np.int64) % nphi
    j1 = (j0 + 1) % nphi
    t = v - np.floor(v)
    a = _mix(texelFetch(tex, i0, row0 + j0)[..., 0], texelFetch(tex, i0 + 1, row0 + j0)[..., 0], s)
    b = _mix(texelFetch(tex, i0, row0 + j1)[..., 0], texelFetch(tex, i0 + 1, row0 + j1)[..., 0], s)
    return _mix(a, b, t)


def bf_table2_D(m, tex, nu, nphi):
    u = np.sqrt(np.arccos(_clamp(m[..., 2], 0.0, 1.0)) * (2.0 / BF_PI)) * float(nu - 1)
    v = np.exp(bf_table2_lookup(tex, 0, nu, nphi, u, np.arctan2(m[..., 1], m[..., 0])))
    return np.where(m[..., 2] <= 0.0, 0.0, v)


def bf_table2_lambda(w, tex, nu, nphi):
    u = np.sqrt(np.arccos(_clamp(w[..., 2], 0.0, 1.0)) * (2.0 / BF_PI)) * float(nu - 1)
    return bf_table2_lookup(tex, nphi, nu, nphi, u, np.arctan2(w[..., 1], w[..., 0])) / w[..., 2] - 1.0


def bf_fresnel_schlick2(cosd, F0, F1):
    c = _clamp(cosd, 0.0, 1.0)[..., None]
    x = 1.0 - c
    x5 = x * x
    x5 = x5 * x5 * x
    return F0 + (1.0 - F0) * x5 - F1 * c


def bf_fresnel_conductor(cosd, eta, k):
    c = _clamp(cosd, 0.0, 1.0)[..., None]
    c2 = c * c
    s2 = 1.0 - c2
    eta2 = eta * eta
    k2 = k * k
    t0 = eta2 - k2 - s2
    a2b2 = np.sqrt(t0 * t0 + 4.0 * eta2 * k2)
    a = np.sqrt(np.maximum(0.5 * (a2b2 + t0), 0.0))
    t1 = a2b2 + c2
    t2 = 2.0 * a * c
    Rs = (t1 - t2) / (t1 + t2)
    t3 = c2 * a2b2 + s2 * s2
    t4 = t2 * s2
    Rp = Rs * (t3 - t4) / (t3 + t4)
    return _clamp(0.5 * (Rs + Rp), 0.0, 1.0)


def bf_fresnel_dielectric(cosd, eta):
    c = _clamp(cosd, 0.0, 1.0)[..., None]
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (g - c) / (g + c)
        b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        F = _clamp(0.5 * a * a * (1.0 + b * b), 0.0, 1.0)
    return np.where(g2 < 0.0, 1.0, F)


def bf_fresnel_table(cosd, tex, row, n, t0, dt):
    td = np.arccos(_clamp(cosd, 0.0, 1.0))
    return bf_row_lerp(tex, row, 0, n, (td - t0) / dt)


def bf_microfacet(wi, wo, D, G, F, ks, rho_d):
    return rho_d / BF_PI + ks * F * (D * G / (4.0 * wi[..., 2] * wo[..., 2]))[..., None]


def bf_smith_G(Li, Lo, correlated):
    if correlated:
        return 1.0 / (1.0 + Li + Lo)
    return 1.0 / ((1.0 + Li) * (1.0 + Lo))


def bf_npf_G(uber, row, theta):
    u = _clamp(theta, 0.0, 0.5 * BF_PI) * (180.0 / BF_PI)
    i0 = np.minimum(u.astype(np.int64), 89)
    t = (u - i0)[..., None]
    a = texelFetch(uber, 180 + i0, row)
    b = np.where((i0 + 1 <= 89)[..., None], texelFetch(uber, 180 + np.minimum(i0 + 1, 89), row), 0.0)
    return a * (1.0 - t) + b * t


def _normalize(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def bf_npf(wi, wo, uber, row):
    ok = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        h = _normalize(wi + wo)
        th = np.arccos(_clamp(h[..., 2], -1.0, 1.0))
        td = np.arccos(_clamp(_dot(wi, h), -1.0, 1.0))
        th, td = np.nan_to_num(th), np.nan_to_num(td)
        uh = np.sqrt(_clamp(th, 0.0, 0.5 * BF_PI) / (0.5 * BF_PI)) * 90.0
        ud = _clamp(td, 0.0, 0.5 * BF_PI) / (0.5 * BF_PI / 90.0)
        D = bf_row_lerp(uber, row, 0, 90, uh)
        F = bf_row_lerp(uber, row, 90, 90, ud)
        G = (bf_npf_G(uber, row, np.arccos(_clamp(wi[..., 2], -1.0, 1.0)))
             * bf_npf_G(uber, row, np.arccos(_clamp(wo[..., 2], -1.0, 1.0))))
        rho_d = texelFetch(uber, 270, row)
        rho_s = texelFetch(uber, 271, row)
        f = rho_d + rho_s * D * F * G / (wi[..., 2] * wo[..., 2])[..., None]
    return np.where(ok[..., None], f, 0.0)


def bf_phi_d(wi, h):
    ph = np.arctan2(h[..., 1], h[..., 0])
    th = np.arccos(_clamp(h[..., 2], -1.0, 1.0))
    cp = np.cos(ph)
    sp = np.sin(ph)
    a = np.stack([cp * wi[..., 0] + sp * wi[..., 1], -sp * wi[..., 0] + cp * wi[..., 1],
                  wi[..., 2]], -1)
    ct = np.cos(th)
    st = np.sin(th)
    d = np.stack([ct * a[..., 0] - st * a[..., 2], a[..., 1], st * a[..., 0] + ct * a[..., 2]], -1)
    return np.arctan2(d[..., 1], d[..., 0])


def bf_npf_naive(wi, wo, tex, row):
    ok = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        h = _normalize(wi + wo)
        th = np.nan_to_num(np.arccos(_clamp(h[..., 2], -1.0, 1.0)))
        td = np.nan_to_num(np.arccos(_clamp(_dot(wi, h), -1.0, 1.0)))
        uh = np.sqrt(_clamp(th, 0.0, 0.5 * BF_PI) / (0.5 * BF_PI)) * 90.0
        ud = _clamp(td, 0.0, 0.5 * BF_PI) / (0.5 * BF_PI / 90.0)
        up = np.mod(np.mod(np.nan_to_num(bf_phi_d(wi, h)), BF_PI) / (BF_PI / 180.0), 180.0)
        i0 = np.floor(up).astype(np.int64) % 180
        t = (up - np.floor(up))[..., None]
        H = (texelFetch(tex, 180 + i0, row) * (1.0 - t)
             + texelFetch(tex, 180 + (i0 + 1) % 180, row) * t)
        D = bf_row_lerp(tex, row, 0, 90, uh)
        F = bf_row_lerp(tex, row, 90, 90, ud)
        rho_d = texelFetch(tex, 360, row)
        rho_s = texelFetch(tex, 361, row)
        f = rho_d + rho_s * D * F * H
    return np.where(ok[..., None], f, 0.0)


def bf_npf_bivariate(wi, wo, tex):
    ok = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        h = _normalize(wi + wo)
        th = np.nan_to_num(np.arccos(_clamp(h[..., 2], -1.0, 1.0)))
        td = np.nan_to_num(np.arccos(_clamp(_dot(wi, h), -1.0, 1.0)))
        uh = _clamp(np.sqrt(_clamp(th, 0.0, 0.5 * BF_PI) / (0.5 * BF_PI)) * 90.0, 0.0, 89.0)
        ud = _clamp(_clamp(td, 0.0, 0.5 * BF_PI) / (0.5 * BF_PI / 90.0), 0.0, 89.0)
        i0 = np.minimum(uh.astype(np.int64), 88)
        j0 = np.minimum(ud.astype(np.int64), 88)
        s = (uh - i0)[..., None]
        t = (ud - j0)[..., None]
        f = ((1.0 - s) * (1.0 - t) * texelFetch(tex, j0, i0)
             + s * (1.0 - t) * texelFetch(tex, j0, i0 + 1)
             + (1.0 - s) * t * texelFetch(tex, j0 + 1, i0)
             + s * t * texelFetch(tex, j0 + 1, i0 + 1))
    return np.where(ok[..., None], f, 0.0)


# ------------------------------------------------------------------------------------------
def _lobe(lobe, textures, wi, wo):
    if lobe["type"] == "npf":
        return bf_npf(wi, wo, textures[lobe["tex"]], lobe["row"])
    if lobe["type"] == "npf_naive":
        return bf_npf_naive(wi, wo, textures[lobe["tex"]], lobe["row"])
    if lobe["type"] == "npf_bivariate":
        return bf_npf_bivariate(wi, wo, textures[lobe["tex"]])
    ok = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        h = _normalize(wi + wo)
        cosd = _dot(wi, h)
        d, f = lobe["dist"], lobe["fresnel"]
        if d["kind"] == "ggx":
            ell = d["ell"]
            D, Li, Lo = bf_ggx_D(h, ell), bf_ggx_lambda(wi, ell), bf_ggx_lambda(wo, ell)
        elif d["kind"] == "beckmann":
            ell = d["ell"]
            D, Li, Lo = bf_beckmann_D(h, ell), bf_beckmann_lambda(wi, ell), bf_beckmann_lambda(wo, ell)
        elif d["kind"] == "sgd":
            g = (d["lam"], d["c"], d["k"])
            D = bf_sgd_D(h, d["alpha"], d["p"], d["log_norm"])
            Li, Lo = bf_lambda_eq9(wi, *g), bf_lambda_eq9(wo, *g)
        elif d["kind"] == "table2":
            tex, nu, nphi = textures[d["tex"]], d["nu"], d["nphi"]
            D, Li, Lo = (bf_table2_D(h, tex, nu, nphi), bf_table2_lambda(wi, tex, nu, nphi),
                         bf_table2_lambda(wo, tex, nu, nphi))
        else:
            tex = textures[d["tex"]]
            D, Li, Lo = bf_table_D(h, tex, d["n"]), bf_table_lambda(wi, tex, d["n"]), \
                bf_table_lambda(wo, tex, d["n"])
        G = bf_smith_G(Li, Lo, lobe["correlated"])
        k = f["kind"]
        if k == "none":
            F = np.ones(cosd.shape + (3,))
        elif k == "schlick2":
            F = bf_fresnel_schlick2(cosd, np.asarray(f["F0"]), np.asarray(f["F1"]))
        elif k == "conductor":
            F = bf_fresnel_conductor(cosd, np.asarray(f["eta"]), np.asarray(f["k"]))
        elif k == "dielectric":
            F = bf_fresnel_dielectric(cosd, np.asarray(f["eta"]))
        else:
            F = bf_fresnel_table(cosd, textures[f["tex"]], f["row"], f["n"], f["t0"], f["dt"])
        out = bf_microfacet(wi, wo, D, G, F, np.asarray(lobe["ks"]), np.asarray(lobe["rho_d"]))
    return np.where(ok[..., None], np.nan_to_num(out), 0.0)


def eval_spec(spec: dict, wi, wo) -> np.ndarray:
    """``brdffit_eval(wi, wo)`` of the GLSL generated from ``spec`` (NumPy, float64)."""
    wi = np.asarray(wi, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64)
    f = np.zeros(np.broadcast_shapes(wi.shape, wo.shape))
    for lobe in spec["lobes"]:
        v = _lobe(lobe, spec["textures"], wi, wo)
        if lobe.get("channel") is None:
            f = f + v
        else:
            c = int(lobe["channel"])
            f[..., c] += v[..., c]
    return f
