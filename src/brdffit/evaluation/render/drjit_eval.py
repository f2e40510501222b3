"""Dr.Jit evaluators: BRDFs of the library as code that runs inside Mitsuba's kernels.

An *evaluator* exposes, on Dr.Jit arrays (``mi.Vector3f`` directions in the local frame,
normal = +z, both pointing away from the surface, library convention of
:mod:`brdffit.brdf`; ``wi`` towards the light, ``wo`` towards the viewer):

* ``eval(wi, wo, alpha_scale, active) -> mi.Color3f``: f_r (not cosine-weighted), 0 below
  the horizon;
* ``sample(wi, u1, u2, alpha_scale, active) -> (wo, pdf)``: importance sampling of ``wo``
  given ``wi`` with its solid-angle density;
* ``pdf(wi, wo, alpha_scale, active) -> mi.Float``: that density.

``alpha_scale`` is a per-lane roughness multiplier (Dupuy 2015 Eq. 9, spatially varying
roughness, Fig. 1/4) read from a texture by the plugin; evaluators without a roughness
ignore it. Everything here is vectorised Dr.Jit; this module imports Mitsuba and must only be
imported lazily (through :func:`brdffit.evaluation.render._mitsuba.load`).

Evaluators
----------
:class:`MERLTableEval`
    Generic path for any isotropic BRDF: the BRDF resampled on the MERL grid
    (90 θh × 90 θd × 180 φd, :func:`brdffit.grid.tabulate_merl_grid`) and looked up with
    trilinear interpolation (θh in MERL's ``sqrt`` index space, θd linear, φd periodic mod π)
    through ``dr.gather``. Sampling: a mixture of cosine-weighted hemisphere sampling and
    GGX visible-normal sampling (Heitz 2018) of a proxy lobe whose α is fitted to the table's
    θd = 0 slice (see :func:`fit_ggx_proxy`).
:class:`Table4DEval`
    Generic path for anisotropic BRDFs: a 4D table over (θh, φh, θd, φd) with
    quadrilinear interpolation (θh in sqrt space, angles periodic), same proxy sampling.
:class:`MicrofacetEval`
    Closed form ``kd/π + ks · F(θd) · D(h) · G2(wi, wo) / (4 cos θi cos θo)`` (Dupuy 2015
    Eq. 1-2, height-correlated Smith) with a distribution (:class:`GGXDist`,
    :class:`BeckmannDist` in closed form, :class:`RadialTableDist` for any other isotropic
    slope distribution) and a Fresnel (:class:`SchlickFresnelDJ` in closed form,
    :class:`TableFresnelDJ` for any other Fresnel, tabulated over cos θd).
"""

from __future__ import annotations

import numpy as np

from ._mitsuba import load as _load
from ...grid import N_THETA_D, N_THETA_H, merl_theta_d, merl_theta_h

mi, dr = _load()

__all__ = ["MERLTableEval", "tabulate_full_phi", "despike", "Table4DEval", "MicrofacetEval", "GGXDist", "BeckmannDist",
           "RadialTableDist", "SumEval", "PerChannelEval", "NPFEval", "SchlickFresnelDJ", "TableFresnelDJ", "ConstantFresnelDJ",
           "fit_ggx_proxy", "half_diff", "ggx_vndf_sample", "ggx_D", "ggx_lambda",
           "cosine_sample", "to_vec3", "to_numpy"]

INV_PI = 1.0 / np.pi


def kernel_params(obj, *names):
    """The attributes ``names`` of ``obj`` (Python floats, ``mi.ScalarColor3f``, or lists of
    floats, which give lists) as opaque Dr.Jit values (``dr.opaque``): parameters of the
    compiled kernel, not constants in it.

    Dr.Jit compiles a new kernel for every new constant it finds in a trace; a material's
    roughness, F0 or proxy lobe written as literals would make every material's renders
    (≈ 0.5 s of LLVM compilation per sphere scene, 1.2 s for the knot) miss the kernel cache.
    As opaque values, one kernel per scene serves every material. The opaque copies are made
    once per value (kept in ``obj._kernel_params``, remade when the attribute changes) and
    shared by every trace: callers must not update them in place (``x += …`` on a Dr.Jit
    array changes that array).
    """
    cache = obj.__dict__.setdefault("_kernel_params", {})
    out = []
    for name in names:
        value = getattr(obj, name)
        color = isinstance(value, mi.ScalarColor3f)
        several = color or isinstance(value, (list, tuple))
        key = tuple(float(v) for v in value) if several else float(value)
        hit = cache.get(name)
        if hit is None or hit[0] != key:
            opaque = ([dr.opaque(mi.Float, v) for v in key] if several
                      else dr.opaque(mi.Float, key))
            hit = cache[name] = (key, mi.Color3f(*opaque) if color else opaque)
        out.append(hit[1])
    return out if len(out) > 1 else out[0]


# -- helpers --------------------------------------------------------------------------------
def to_vec3(a) -> "mi.Vector3f":
    """``(N, 3)`` NumPy array → ``mi.Vector3f``."""
    a = np.asarray(a, dtype=np.float32)
    return mi.Vector3f(a[:, 0], a[:, 1], a[:, 2])


def to_numpy(v) -> np.ndarray:
    """Dr.Jit array → NumPy: ``mi.Float`` → ``(N,)``; 3-vectors/colours → ``(N, 3)``."""
    if isinstance(v, (mi.Vector3f, mi.Color3f, mi.Point3f)):
        return np.stack([np.asarray(v[k], dtype=np.float64) for k in range(3)], axis=-1)
    return np.asarray(v, dtype=np.float64)


def half_vector(wi, wo):
    """``normalize(wi + wo)``, and ``+z`` where ``wi + wo`` is zero or not finite.

    Lanes that a kernel carries but does not use (paths that left the scene, directions below
    the horizon) can hold ``wi = wo = 0`` (Mitsuba's invalid surface interaction) or
    ``wi = −wo``; a plain ``normalize`` gives NaN there, and NaN must never become a table
    index (``UInt32(NaN)`` is 2³¹ or 2³² − 1 depending on the CPU)."""
    s = wi + wo
    n2 = dr.squared_norm(s)
    good = (n2 > 1e-30) & (n2 < 1e30)
    return dr.select(good, s * dr.rsqrt(dr.select(good, n2, 1.0)), mi.Vector3f(0.0, 0.0, 1.0))


def table_coordinate(x, hi):
    """``x`` limited to ``[0, hi]`` for a table lookup, NaN → 0 (±∞ → the nearest end).

    ``dr.clip`` is ``min(max(x, lo), hi)``, whose result for NaN depends on the instruction
    set; a comparison is false for NaN on every CPU, so select on it. Every index that
    reaches ``dr.gather`` in this module goes through here; the gathers are also masked with
    the lanes in use wherever the caller knows them."""
    return dr.select(x > 0.0, dr.minimum(x, hi), 0.0)


def table_cell(x, n):
    """Lower node ``i0 ∈ [0, n − 2]`` and weight ``t ∈ [0, 1]`` of linear interpolation at
    continuous index ``x`` on ``n ≥ 2`` nodes (NaN-safe, :func:`table_coordinate`)."""
    x = table_coordinate(x, n - 1.0)
    i0 = dr.minimum(mi.UInt32(dr.floor(x)), n - 2)
    return i0, x - mi.Float(i0)


def periodic_coordinate(x, period, n):
    """Continuous index in ``[0, n)`` of angle ``x`` on a periodic axis of ``n`` nodes over
    ``period`` (NaN → 0)."""
    u = (x - period * dr.floor(x / period)) * (n / period)
    return table_coordinate(u, n - 1e-4)


def periodic_cell(x, n):
    """Nodes ``i0, i1`` (``i1`` wraps to 0 after the last) and weight ``t`` of linear
    interpolation at a continuous index ``x`` of :func:`periodic_coordinate`."""
    i0 = dr.minimum(mi.UInt32(dr.floor(x)), n - 1)
    return i0, dr.select(i0 + 1 >= n, 0, i0 + 1), x - mi.Float(i0)


def half_diff(wi, wo):
    """Rusinkiewicz (θh, θd, φd) of Dr.Jit directions (MERL convention, as
    :func:`brdffit.geometry.io_to_half_diff`; φh is not needed by isotropy). Also returns
    ``h`` and φh for the anisotropic table."""
    h = half_vector(wi, wo)
    sh = dr.sqrt(dr.square(h.x) + dr.square(h.y))
    small = sh < 1e-7
    cph = dr.select(small, 1.0, h.x / dr.select(small, 1.0, sh))
    sph = dr.select(small, 0.0, h.y / dr.select(small, 1.0, sh))
    ch = h.z
    # d = (wi·t, wi·b, wi·h), t = Rz(φh) Ry(θh) x̂, b = Rz(φh) ŷ
    t = mi.Vector3f(ch * cph, ch * sph, -sh)
    b = mi.Vector3f(-sph, cph, 0.0)
    dx, dy, dz = dr.dot(wi, t), dr.dot(wi, b), dr.dot(wi, h)
    # atan2 of (sin, cos), not acos(cos): in single precision acos(h.z) is quantised to
    # ≈ 3e-4 rad steps near the normal (cos θ rounds to 1 below 2.4e-4), coarser than the
    # first MERL/NPF θh cells (1.9e-4, 7.8e-4) of a sharp specular peak
    theta_h = dr.atan2(sh, ch)
    theta_d = dr.atan2(dr.sqrt(dr.square(dx) + dr.square(dy)), dz)
    phi_d = dr.atan2(dy, dx)
    phi_h = dr.atan2(sph, cph)
    return theta_h, theta_d, phi_d, phi_h


def cosine_sample(u):
    """Cosine-weighted hemisphere direction from ``mi.Point2f`` (same map as
    :func:`brdffit.brdf.cosine_hemisphere_sample`)."""
    r = dr.sqrt(u.x)
    s, c = dr.sincos(2.0 * dr.pi * u.y)
    return mi.Vector3f(r * c, r * s, dr.safe_sqrt(1.0 - u.x))


# -- GGX closed forms (also used as sampling proxy) -----------------------------------------
def ggx_D(m, ax, ay):
    """GGX NDF, anisotropic: ``1/(π αx αy cos⁴θ (1 + x̃²/αx² + ỹ²/αy²)²)`` (Dupuy 2015 Eq. 9
    applied to the GGX slope PDF ``1/(π (1 + r²)²)``)."""
    cz = dr.maximum(m.z, 1e-7)
    t = dr.square(m.x / (ax * cz)) + dr.square(m.y / (ay * cz)) + 1.0
    d = 1.0 / (dr.pi * ax * ay * dr.square(dr.square(cz)) * dr.square(t))
    return dr.select(m.z > 0, d, 0.0)


def ggx_lambda(w, ax, ay):
    """Smith Λ of GGX: ``(−1 + sqrt(1 + (αx² wx² + αy² wy²)/wz²))/2`` (Heitz 2014)."""
    wz2 = dr.maximum(dr.square(w.z), 1e-14)
    a2t2 = (dr.square(ax * w.x) + dr.square(ay * w.y)) / wz2
    return 0.5 * (dr.sqrt(1.0 + a2t2) - 1.0)


def ggx_vndf_sample(wi, u, ax, ay):
    """Visible GGX normal for direction ``wi`` (Heitz 2018, "Sampling the GGX distribution of
    visible normals", JCGT 7(4), listing 1)."""
    vh = dr.normalize(mi.Vector3f(ax * wi.x, ay * wi.y, dr.maximum(wi.z, 1e-7)))
    lensq = dr.square(vh.x) + dr.square(vh.y)
    inv = dr.rsqrt(dr.select(lensq > 0, lensq, 1.0))
    t1v = dr.select(lensq > 0, mi.Vector3f(-vh.y * inv, vh.x * inv, 0.0), mi.Vector3f(1, 0, 0))
    t2v = dr.cross(vh, t1v)
    r = dr.sqrt(u.x)
    s, c = dr.sincos(2.0 * dr.pi * u.y)
    t1, t2 = r * c, r * s
    sw = 0.5 * (1.0 + vh.z)
    t2 = (1.0 - sw) * dr.safe_sqrt(1.0 - dr.square(t1)) + sw * t2
    nh = t1 * t1v + t2 * t2v + dr.safe_sqrt(1.0 - dr.square(t1) - dr.square(t2)) * vh
    return dr.normalize(mi.Vector3f(ax * nh.x, ay * nh.y, dr.maximum(nh.z, 1e-7)))


def _reflect(w, m):
    return 2.0 * dr.dot(w, m) * m - w


def _ggx_reflect_pdf(wi, wo, ax, ay):
    """Solid-angle density of ``wo = reflect(wi, m)`` with ``m`` a visible GGX normal:
    ``G1(wi) D(h) / (4 cos θi)`` (Heitz 2018 Eq. 17 with the reflection Jacobian)."""
    h = half_vector(wi, wo)
    g1 = 1.0 / (1.0 + ggx_lambda(wi, ax, ay))
    p = g1 * ggx_D(h, ax, ay) / (4.0 * dr.maximum(wi.z, 1e-7))
    return dr.select((wi.z > 0) & (wo.z > 0) & (dr.dot(wi, h) > 0), p, 0.0)


def fit_ggx_proxy(theta_h: np.ndarray, profile: np.ndarray) -> tuple[float, float]:
    """Fit ``kd + ks · D_GGX(θh; α) / (4 cos²θh)`` to a θd = 0 luminance slice.

    At θd = 0, ``wi = wo = h``: a microfacet lobe is ``F G D / (4 cos²θh)`` with G ≈ 1 near
    the peak. For 80 log-spaced α in [5e-4, 1] we solve non-negative weighted least squares
    for (kd, ks) (weights emphasise the peak) and keep the α of smallest relative residual
    (the range reaches 5e-4: a proxy 5× wider than an α = 0.001 table lobe raises the furnace
    standard error at 2^20 samples from 0.1 % to 0.5 %).
    Returns ``(alpha, specular_weight)`` where the weight ``ks / (ks + π kd)`` estimates the
    share of the specular lobe in the albedo; it is the proxy's mixture probability (clamped
    to [0.1, 0.9] so that both strategies always contribute). Pure NumPy (no Mitsuba needed).
    """
    th = np.asarray(theta_h, dtype=np.float64)
    p = np.nan_to_num(np.asarray(profile, dtype=np.float64), nan=0.0, posinf=0.0)
    p = np.maximum(p, 0.0)
    keep = th < np.radians(80.0)
    th, p = th[keep], p[keep]
    if p.size < 3 or p.max() <= 0:
        return 0.5, 0.5
    w = 1.0 / np.maximum(p, p.max() * 1e-4)  # relative fit
    best = (np.inf, 0.5, 0.5)
    c2 = np.cos(th) ** 2
    for alpha in np.geomspace(5e-4, 1.0, 80):  # 80 candidates, each a vectorised 2×2 solve
        d = alpha**2 / (np.pi * (c2 * (alpha**2 - 1.0) + 1.0) ** 2) / (4.0 * c2)
        A = np.stack([np.ones_like(d), d], -1) * w[:, None]
        coef, *_ = np.linalg.lstsq(A, p * w, rcond=None)
        kd, ks = np.maximum(coef, 0.0)
        res = np.sum(((kd + ks * d) - p) ** 2 * w**2)
        if res < best[0]:
            best = (res, float(alpha), float(ks / max(ks + np.pi * kd, 1e-12)))
    return best[1], float(np.clip(best[2], 0.1, 0.9))


class _ProxySampling:
    """Mixture ``w · GGX-VNDF reflection + (1 − w) · cosine`` with exact mixture pdf."""

    proxy_alpha: float = 0.5
    proxy_weight: float = 0.5

    def pdf(self, wi, wo, alpha_scale=1.0, active=True):
        a, w = kernel_params(self, "proxy_alpha", "proxy_weight")
        p = (w * _ggx_reflect_pdf(wi, wo, a, a)
             + (1.0 - w) * dr.maximum(wo.z, 0.0) * INV_PI)
        return dr.select(active & (wi.z > 0) & (wo.z > 0), p, 0.0)

    def sample(self, wi, u1, u2, alpha_scale=1.0, active=True):
        a, w = kernel_params(self, "proxy_alpha", "proxy_weight")
        m = ggx_vndf_sample(wi, u2, a, a)
        spec = u1 < w
        wo = dr.select(spec, _reflect(wi, m), cosine_sample(u2))
        return wo, self.pdf(wi, wo, alpha_scale, active)


# -- generic tables -------------------------------------------------------------------------
def _table_buffer(v: np.ndarray, interp: str):
    """``(ε, buffer)`` of a large RGB table ``v`` (float64, ≥ 0) as the evaluators interpolate
    it: ``log(v + ε)`` with ε = 5 % of the median of the positive values (at least 1e-6) for
    ``interp="log"``, ``v`` itself with ε = 0 for ``"linear"``; the buffer is a flat float32
    ``mi.Float`` of RGBA entries (A = 0), read by :func:`_gather_rgb`."""
    if interp == "log":
        pos = v[v > 0]
        eps = float(max(0.05 * np.median(pos), 1e-6)) if pos.size else 1e-6
        table = np.log(v + eps)
    else:
        eps, table = 0.0, v
    rgba = np.zeros(table.shape[:-1] + (4,), np.float32)
    rgba[..., :3] = table
    return eps, mi.Float(rgba.ravel())


def _gather_rgb(buffer, index, active):
    """Entry ``index`` of a :func:`_table_buffer` as a ``mi.Color3f``, read with one packet
    load (``JitFlag.PacketOps``) instead of three gathers: the MERL reference's 8 lookups
    take 0.8× the time with the same values (57 → 45 ms for 2²⁰ uniformly drawn direction
    pairs, one thread). Only for the large tables (MERL, 4D): with packet loads from small
    tables (the NPF factors, a Fresnel curve) the render kernel's hash changed from one
    material to the next, so every material compiled its renders again (Dr.Jit 1.5; three
    live 1-KB buffers gave two kernels), while the MERL tables give one kernel for every
    reference (``tests/evaluation/test_render_kernels.py``)."""
    c = dr.gather(mi.Vector4f, buffer, index, active)
    return mi.Color3f(c.x, c.y, c.z)


class MERLTableEval(_ProxySampling):
    """Trilinear lookup in a MERL-grid table ``(90, 90, Nφ, 3)`` (generic isotropic path).

    θh index ``sqrt(θh/(π/2))·90`` (MERL's mapping, :mod:`brdffit.grid`), clamped to the
    last sample; θd index ``θd/(π/2)·90`` clamped; φd periodic. ``Nφ = 180`` is MERL's own
    grid on [0, π) (reciprocity folds φd mod π); ``Nφ = 360`` covers [0, 2π) with the same
    1° spacing and is used for BRDFs that are *not* reciprocal (Neural-BRDF networks and RGL
    measurements are not exactly: swapping wi and wo changes them by a few %), so that
    nothing is folded away. Invalid samples (``valid == False``) are replaced by 0, as MERL's
    readers do.

    ``interp="log"`` (default) interpolates ``log(f + ε)`` and returns ``exp(·) − ε`` with
    ``ε = 0.05 · median(f)``: the specular peak is close to exponential between samples, where
    linear interpolation is biased upwards (measured on the Neural-BRDF chrome-steel: albedo
    error 2.3 % linear vs 0.2 % log; cosine-weighted L1 2.9 % vs 1.7 %; on diffuse and
    glossy paints both are ≈ 0.1 %). ``interp="linear"`` is plain trilinear.
    """

    kind = "merl-table"

    def __init__(self, values, valid=None, interp: str = "log"):
        if interp not in ("log", "linear"):
            raise ValueError(f"interp must be 'log' or 'linear', got {interp!r}")
        v = np.asarray(values, dtype=np.float64)
        if v.ndim != 4 or v.shape[:2] != (N_THETA_H, N_THETA_D) or v.shape[2] not in (180, 360) \
                or v.shape[3] != 3:
            raise ValueError(f"expected a MERL table of shape (90, 90, 180|360, 3), found {v.shape}")
        v = np.where(np.isfinite(v), np.maximum(v, 0.0), 0.0)
        if valid is not None:
            v = np.where(np.asarray(valid, bool)[..., None], v, 0.0)
        self.n_phi = v.shape[2]
        self.period = np.pi if self.n_phi == 180 else 2.0 * np.pi
        self.values = v.astype(np.float32)
        self.interp = interp
        self.eps, self.buffer = _table_buffer(v, interp)
        lum = self.values[:, 0, 0, :] @ np.array([0.2126, 0.7152, 0.0722], np.float32)
        self.proxy_alpha, self.proxy_weight = fit_ggx_proxy(merl_theta_h(), lum)

    def eval(self, wi, wo, alpha_scale=1.0, active=True):
        th, td, pd, _ = half_diff(wi, wo)
        n_phi, period = self.n_phi, self.period
        ih0, fh = table_cell(dr.sqrt(th * (2.0 / dr.pi)) * 90.0, 90)
        id0, fd = table_cell(td * (180.0 / dr.pi), 90)
        ih1, id1 = ih0 + 1, id0 + 1
        ip0, ip1, fp = periodic_cell(periodic_coordinate(pd, period, n_phi), n_phi)
        ok = active & (wi.z > 0) & (wo.z > 0)
        out = mi.Color3f(0.0)
        for ih, wh in ((ih0, 1.0 - fh), (ih1, fh)):
            for idd, wd in ((id0, 1.0 - fd), (id1, fd)):
                base = (ih * 90 + idd) * n_phi
                for ip, wp in ((ip0, 1.0 - fp), (ip1, fp)):
                    out += (wh * wd * wp) * _gather_rgb(self.buffer, base + ip, ok)
        if self.interp == "log":
            out = dr.maximum(dr.exp(out) - kernel_params(self, "eps"), 0.0)
        return dr.select(ok, out, 0.0)


def despike(values, factor: float = 100.0):
    """Replace isolated spikes of a MERL-grid table by their 3×3×3 neighbourhood median.

    A sample is a spike when its RGB mean exceeds ``factor`` × the median of its 3×3×3
    neighbourhood *and* ``factor`` × the median of the whole table. Measured evaluators can
    produce such values at grazing angles (the RGL ``paper_white`` reader gives 1e4-1e14 at
    θd ≥ 87°, 228 of 2.9 M samples) and a single one ruins a render with fireflies; genuine
    specular peaks are smooth at the grid scale and are left alone (0 samples changed on the
    Neural-BRDF chrome-steel). Neighbourhoods repeat the edge samples (``median_filter``'s
    ``mode="nearest"``); their medians are computed only where the sample exceeds ``factor``
    × the table's median and × its neighbourhood's minimum (a necessary condition). Returns
    ``(values, n_replaced)``.
    """
    v = np.asarray(values, dtype=np.float64)
    lum = v.mean(-1)
    pos = lum[lum > 0]
    if pos.size == 0:
        return v, 0
    from scipy.ndimage import minimum_filter

    # the neighbourhood median is at least its minimum: only samples above factor × that
    # minimum can be spikes (a smooth specular peak has none)
    near_min = minimum_filter(lum, size=3, mode="nearest")
    candidates = np.flatnonzero((lum > factor * np.median(pos))
                                & (lum > factor * np.maximum(near_min, 1e-30)))
    bad = candidates[lum.flat[candidates]
                     > factor * np.maximum(_local_medians(lum, candidates), 1e-30)]
    if bad.size:
        v = v.copy()
        for c in range(v.shape[-1]):
            channel = v[..., c]
            channel.flat[bad] = _local_medians(channel, bad)
    return v, int(bad.size)


def _local_medians(a: np.ndarray, flat_index: np.ndarray) -> np.ndarray:
    """Medians of the 3×3×… neighbourhoods of ``a`` at ``flat_index``, edge samples repeated
    (``scipy.ndimage.median_filter(a, size=3, mode="nearest")`` at those samples)."""
    padded = np.pad(a, 1, mode="edge")
    centre = np.ravel_multi_index(tuple(c + 1 for c in np.unravel_index(flat_index, a.shape)),
                                  padded.shape)
    offsets = np.ravel_multi_index(
        tuple(np.stack(np.meshgrid(*[(0, 1, 2)] * a.ndim, indexing="ij")).reshape(a.ndim, -1)),
        padded.shape) - np.ravel_multi_index((1,) * a.ndim, padded.shape)
    middle = offsets.size // 2     # 3^ndim samples: the median is the middle one
    return np.partition(padded.ravel()[centre[:, None] + offsets], middle, axis=1)[:, middle]


def tabulate_full_phi(brdf, chunk: int = 1 << 18) -> np.ndarray:
    """Evaluate an isotropic BRDF on the MERL θh × θd grid with 360 φd samples on [0, 2π)
    (1° steps, no reciprocity folding): ``(90, 90, 360, 3)``."""
    pd_axis = np.arange(360) * (np.pi / 180.0)
    th, td, pd = (a.ravel() for a in np.meshgrid(merl_theta_h(), merl_theta_d(), pd_axis,
                                                  indexing="ij"))
    out = np.empty((th.size, 3))
    for s in range(0, th.size, chunk):
        sl = slice(s, s + chunk)
        out[sl] = brdf.eval_hd(th[sl], td[sl], pd[sl])
    return out.reshape(90, 90, 360, 3)


class Table4DEval(_ProxySampling):
    """Quadrilinear lookup in ``(Nth, Nph, Ntd, Npd, 3)`` over (θh, φh, θd, φd).

    Generic anisotropic path. θh uses the MERL sqrt mapping ``θh = (i/Nth)² π/2``; θd is
    uniform on [0, π/2); φh and φd are uniform on [0, 2π) and periodic (no reciprocity folding,
    so non-reciprocal tables also work). Linear interpolation by default: on the synthetic
    aniso-GGX (αx, αy, ρ) = (0.06, 0.3, 0.45) with the default 40 × 40 × 32 × 40 table,
    linear gives a cosine-weighted L1 error of 6.2 % and an albedo error of 0.35 %, while
    ``interp="log"`` gives 4.4 % but a 3.7 % albedo bias (56 × 48 × 32 × 48: 4.0 % / 0.3 %
    linear). Anisotropic BRDFs with a known model should use their closed form instead.
    """

    kind = "table4d"

    def __init__(self, values, proxy_alpha=0.3, proxy_weight=0.5, interp: str = "linear"):
        v = np.asarray(values, dtype=np.float64)
        if v.ndim != 5 or v.shape[-1] != 3:
            raise ValueError(f"expected a table (Nθh, Nφh, Nθd, Nφd, 3), found {v.shape}")
        if interp not in ("log", "linear"):
            raise ValueError(f"interp must be 'log' or 'linear', got {interp!r}")
        self.shape = v.shape[:4]
        v = np.where(np.isfinite(v), np.maximum(v, 0.0), 0.0)
        self.values = v.astype(np.float32)
        self.interp = interp
        self.eps, self.buffer = _table_buffer(v, interp)
        self.proxy_alpha, self.proxy_weight = float(proxy_alpha), float(proxy_weight)

    @staticmethod
    def grid(shape):
        """(θh, φh, θd, φd) sample positions of a table of ``shape`` (4 sizes)."""
        nth, nph, ntd, npd = shape
        return ((np.arange(nth) / nth) ** 2 * (np.pi / 2), np.arange(nph) * (2 * np.pi / nph),
                np.arange(ntd) * (np.pi / 2 / ntd), np.arange(npd) * (2 * np.pi / npd))

    def eval(self, wi, wo, alpha_scale=1.0, active=True):
        nth, nph, ntd, npd = self.shape
        th, td, pd, ph = half_diff(wi, wo)
        two_pi = 2.0 * dr.pi
        xh = table_coordinate(dr.sqrt(th * (2.0 / dr.pi)) * nth, nth - 1.0)
        xd = table_coordinate(td * (2.0 / dr.pi) * ntd, ntd - 1.0)
        xph = periodic_coordinate(ph, two_pi, nph)
        xpd = periodic_coordinate(pd, two_pi, npd)

        def axis(x, n, periodic):
            if periodic:
                i0, i1, f = periodic_cell(x, n)
            else:
                i0 = dr.minimum(mi.UInt32(dr.floor(x)), n - 1)
                f = x - mi.Float(i0)
                i1 = dr.minimum(i0 + 1, n - 1)
            return ((i0, 1.0 - f), (i1, f))

        ok = active & (wi.z > 0) & (wo.z > 0)
        out = mi.Color3f(0.0)
        for a, wa in axis(xh, nth, False):
            for b, wb in axis(xph, nph, True):
                for c, wc in axis(xd, ntd, False):
                    base = ((a * nph + b) * ntd + c) * npd
                    for d, wd in axis(xpd, npd, True):
                        out += (wa * wb * wc * wd) * _gather_rgb(self.buffer, base + d, ok)
        if self.interp == "log":
            out = dr.maximum(dr.exp(out) - kernel_params(self, "eps"), 0.0)
        return dr.select(ok, out, 0.0)


# -- distributions --------------------------------------------------------------------------
class _Elliptical:
    """Scale matrix ``S = [[αx², ραxαy], [ραxαy, αy²]]`` (Dupuy 2015 App. C), Cholesky
    ``L = [[αx, 0], [ραy, αy√(1−ρ²)]]``; a roughness scale ``s`` multiplies ``L`` by ``s``.

    ``q_inv(m) = m_xyᵀ S⁻¹ m_xy`` (for the NDF) and ``q(w) = w_xyᵀ S w_xy`` (for Λ); for
    ρ = 0 these are the usual ``mx²/αx² + my²/αy²`` and ``αx² wx² + αy² wy²``.
    """

    def __init__(self, alpha_x, alpha_y=None, rho=0.0):
        self.ax = float(alpha_x)
        self.ay = float(alpha_x if alpha_y is None else alpha_y)
        self.rho = float(rho)
        if not (self.ax > 0 and self.ay > 0 and -1.0 < self.rho < 1.0):
            raise ValueError(f"invalid (alpha_x, alpha_y, rho) = ({self.ax}, {self.ay}, {self.rho})")
        self.sr = float(np.sqrt(1.0 - self.rho**2))

    def _params(self):
        """``(αx, αy, ρ, √(1−ρ²))`` as kernel parameters (:func:`kernel_params`); the
        Python floats decide only the structure (``ρ = 0``)."""
        return kernel_params(self, "ax", "ay", "rho", "sr")

    def _q_inv(self, x, y, s):
        ax, ay, rho, sr = self._params()
        X, Y = x / (ax * s), y / (ay * s)
        if self.rho == 0.0:
            return dr.square(X) + dr.square(Y)
        return (dr.square(X) - 2.0 * rho * X * Y + dr.square(Y)) / (sr * sr)

    def _q(self, x, y, s):
        ax, ay, rho, _ = self._params()
        ax, ay = ax * s, ay * s
        if self.rho == 0.0:
            return dr.square(ax * x) + dr.square(ay * y)
        return dr.square(ax * x) + 2.0 * rho * ax * ay * x * y + dr.square(ay * y)

    def _det_sqrt(self, s):
        ax, ay, _, sr = self._params()
        return ax * ay * sr * s * s

    def _L(self, x, y, s):
        """``L (x, y)``."""
        ax, ay, rho, sr = self._params()
        return (ax * s * x, rho * ay * s * x + ay * sr * s * y)

    def _Lt(self, x, y, s):
        """``Lᵀ (x, y)``."""
        ax, ay, rho, sr = self._params()
        return (ax * s * x + rho * ay * s * y, ay * sr * s * y)

    def pdf_m(self, wi, m, s=1.0):
        """Visible-normal density ``G1(wi) <wi, m>₊ D(m) / cos θi`` (Heitz & d'Eon 2014)."""
        g1 = 1.0 / (1.0 + self.Lambda(wi, s))
        return g1 * dr.maximum(dr.dot(wi, m), 0.0) * self.D(m, s) / dr.maximum(wi.z, 1e-7)


class GGXDist(_Elliptical):
    """GGX in closed form with (αx, αy, ρ) (Dupuy App. C; ``brdffit.microfacet.GGX``):
    ``D = 1/(π √|S| (m_z² + m_xyᵀ S⁻¹ m_xy)²)``, ``Λ = (−1 + √(1 + q(w)/w_z²))/2``;
    visible normals by Heitz 2018 on the unit GGX seen from ``(Lᵀ w_xy, w_z)``, mapped back
    with ``L`` (for ρ = 0: Heitz's stretch)."""

    kind = "ggx"

    def D(self, m, s=1.0):
        cz = dr.maximum(m.z, 1e-7)
        t = dr.square(cz) + self._q_inv(m.x, m.y, s)
        return dr.select(m.z > 0, 1.0 / (dr.pi * self._det_sqrt(s) * dr.square(t)), 0.0)

    def Lambda(self, w, s=1.0):
        wz2 = dr.maximum(dr.square(w.z), 1e-14)
        return 0.5 * (dr.sqrt(1.0 + self._q(w.x, w.y, s) / wz2) - 1.0)

    def sample(self, wi, u, s=1.0):
        """Returns ``(m, pdf_m)`` with the visible-normal density."""
        x, y = self._Lt(wi.x, wi.y, s)
        n0 = ggx_vndf_sample(mi.Vector3f(x, y, wi.z), u, 1.0, 1.0)
        mx, my = self._L(n0.x, n0.y, s)
        m = dr.normalize(mi.Vector3f(mx, my, n0.z))
        return m, self.pdf_m(wi, m, s)


class BeckmannDist(_Elliptical):
    """Beckmann in closed form with (αx, αy, ρ): ``D = exp(−q⁻¹(m)/m_z²)/(π √|S| m_z⁴)``,
    Smith ``Λ = (erf(a) − 1)/2 + exp(−a²)/(2a√π)`` with ``a = w_z/√q(w)`` (Walter 2007
    Eq. 27, Heitz 2014). Sampling: visible normals through Mitsuba's own
    ``MicrofacetDistribution`` when ρ = 0; for ρ ≠ 0 the NDF itself (``D cos θ``: Gaussian
    slopes ``L z``, Walter 2007 Eq. 28 generalised), with the matching pdf."""

    kind = "beckmann"

    def D(self, m, s=1.0):
        cz = dr.maximum(m.z, 1e-7)
        e = self._q_inv(m.x, m.y, s) / dr.square(cz)
        d = dr.exp(-e) / (dr.pi * self._det_sqrt(s) * dr.square(dr.square(cz)))
        return dr.select(m.z > 0, d, 0.0)

    def Lambda(self, w, s=1.0):
        at = dr.sqrt(self._q(w.x, w.y, s)) / dr.maximum(dr.abs(w.z), 1e-7)
        a = 1.0 / dr.maximum(at, 1e-7)
        lam = 0.5 * (dr.erf(a) - 1.0) + dr.exp(-dr.square(a)) / (2.0 * a * dr.sqrt(dr.pi))
        return dr.select(a > 20.0, 0.0, dr.maximum(lam, 0.0))

    def sample(self, wi, u, s=1.0):
        if self.rho == 0.0:
            ax, ay, _, _ = self._params()
            md = mi.MicrofacetDistribution(mi.MicrofacetType.Beckmann, ax * s, ay * s, True)
            m, _ = md.sample(wi, u)
        else:
            r = dr.sqrt(-dr.log(dr.maximum(1.0 - u.x, 1e-12)))
            sp, cp = dr.sincos(2.0 * dr.pi * u.y)
            mx, my = self._L(r * cp, r * sp, s)
            m = dr.normalize(mi.Vector3f(mx, my, 1.0))
        return m, self.pdf_m(wi, m, s)

    def pdf_m(self, wi, m, s=1.0):
        if self.rho == 0.0:
            return _Elliptical.pdf_m(self, wi, m, s)
        return dr.select(m.z > 0, self.D(m, s) * m.z, 0.0)


def _tan_theta(w):
    """``(tan θ, cos θ)`` of Dr.Jit directions, with ``sin θ`` from the x/y components.

    ``sqrt(1 − cos²θ)`` loses every digit near the normal in single precision: ``cos θ``
    rounds to 1 for θ < 2.4e-4 and moves in steps of 6e-8 (θ steps of ≈ 3e-4 near 0), so a
    lobe of width α ≈ 0.001 would be evaluated on a handful of quantised angles (and at
    θ = 0 exactly for every half vector within 2.4e-4 of the normal). ``x² + y²`` keeps the
    relative precision of ``sin θ`` at any angle."""
    cz = dr.maximum(dr.abs(w.z), 1e-7)
    return dr.sqrt(dr.square(w.x) + dr.square(w.y)) / cz, cz


class RadialTableDist:
    """Any isotropic slope distribution, tabulated (Dupuy 2015 §3-4, tabulated P; Eq. 9 for
    the per-texel roughness scale).

    Tables, on ``n`` (default 1024) nodes ``θ_k = (k/(n−1))² · π/2`` (sqrt spacing like the
    MERL θh axis, dense near the normal: θ_1 = 1.5e-6, spacing 8e-5 at θ = 0.001, so a lobe
    of α = 0.001 spans ≈ 13 nodes; 256 nodes gave albedo errors of 1 % there): ``D(θ_k)``
    (stored as ``log D`` for interpolation) and ``Λ(θ_k)``. Angles are computed from
    ``tan θ = |w_xy| / w_z`` (:func:`_tan_theta`), never from ``1 − cos²θ``. A roughness
    scale ``s`` (Eq. 9, ``P_s(x̃) = P(x̃/s)/s²``) is applied exactly:
    ``D_s(θ) = D(θ′) cos⁴θ′ / (s² cos⁴θ)`` with ``tan θ′ = tan θ / s``, and
    ``Λ_s(θ) = Λ(θ″)`` with ``tan θ″ = s · tan θ`` (stretch invariance of Smith Λ).

    Sampling: ``D cos θ`` (not visible normals; Dupuy 2015 App. A samples the tabulated P the
    same way) through the node variable ``u = sqrt(θ/(π/2))``: a piecewise-linear density
    in ``u`` on 4096 uniform nodes (``mi.ContinuousDistribution``) proportional to
    ``D(θ) cos θ sin θ dθ/du`` from the interpolated log-D table (uniform nodes in θ cannot
    resolve a lobe narrower than their spacing: with 1024 nodes over [0, π/2], the whole
    α = 0.002 peak sat in the first interval). The reported pdf is the exact density of that
    sampler, ``p(u) / (dθ/du · 2π sin θ)`` per solid angle (so sample/pdf are consistent
    even though it only approximates ``D cos θ``), mapped through the slope scaling by its
    Jacobian ``p_s(m) = p(m′) cos³θ′ / (s² cos³θ)`` (slope area element ``dω/cos³θ``).
    """

    kind = "radial-table"
    N_SAMPLER = 4096

    def __init__(self, D_values, Lambda_values):
        D_values = np.asarray(D_values, dtype=np.float64)
        Lambda_values = np.asarray(Lambda_values, dtype=np.float64)
        self.n = D_values.size
        self.theta = self.nodes(self.n)
        logd_nodes = np.log(np.maximum(D_values, 1e-30))
        self.logD = mi.Float(logd_nodes.astype(np.float32))
        self.lam = mi.Float(np.maximum(np.nan_to_num(Lambda_values, posinf=1e6), 0.0)
                            .astype(np.float32))
        # sampler in u = sqrt(θ/(π/2)): density ∝ D(θ) cos θ sin θ · dθ/du, dθ/du = π u
        uu = np.linspace(0.0, 1.0, self.N_SAMPLER)
        tu = 0.5 * np.pi * uu**2
        logd = np.interp(uu * (self.n - 1), np.arange(self.n), logd_nodes)   # as _lookup
        g = np.exp(logd - logd.max()) * np.cos(tu) * np.sin(tu) * (np.pi * uu)
        g[-1] = 0.0
        self.u_dist = mi.ContinuousDistribution(mi.ScalarVector2f(0.0, 1.0),
                                                mi.Float(g.astype(np.float32)))

    @staticmethod
    def nodes(n):
        return (np.arange(n) / (n - 1)) ** 2 * (np.pi / 2)

    @classmethod
    def from_distribution(cls, dist, n: int = 1024):
        """Tabulate any :class:`brdffit.microfacet.base.SlopeDistribution` (isotropic) with
        its own ``D`` and ``Lambda`` methods."""
        th = cls.nodes(n)
        m = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], -1)
        m[-1] = [np.sin(th[-2] + 0.5 * (th[-1] - th[-2])), 0.0, 1e-6]
        m /= np.linalg.norm(m, axis=-1, keepdims=True)
        D = np.asarray(dist.D(m), dtype=np.float64)
        lam = np.asarray(dist.Lambda(m), dtype=np.float64)
        return cls(D, lam)

    def _lookup(self, buf, theta):
        i0, f = table_cell(dr.sqrt(theta * (2.0 / dr.pi)) * (self.n - 1), self.n)
        return dr.lerp(dr.gather(mi.Float, buf, i0), dr.gather(mi.Float, buf, i0 + 1), f)

    def D(self, m, s=1.0):
        tan_t, cz = _tan_theta(m)
        tp = dr.atan(tan_t / s)
        cp = dr.cos(tp)
        d = dr.exp(self._lookup(self.logD, tp)) * dr.square(dr.square(cp)) / (
            dr.square(s) * dr.square(dr.square(cz)))
        return dr.select(m.z > 0, d, 0.0)

    def Lambda(self, w, s=1.0):
        tan_t, _ = _tan_theta(w)
        return self._lookup(self.lam, dr.atan(s * tan_t))

    def _pdf_unit(self, theta):
        """Solid-angle density of the unit-roughness sampler at polar angle θ."""
        u = dr.sqrt(dr.maximum(theta, 0.0) * (2.0 / dr.pi))
        g = self.u_dist.eval_pdf_normalized(dr.minimum(u, 1.0))
        # dω = 2π sin θ dθ, dθ = π u du  (θ → 0: g ∝ u³, the ratio stays finite)
        return g / (2.0 * dr.pi * dr.maximum(dr.pi * u * dr.sin(theta), 1e-30))

    def sample(self, wi, u, s=1.0):
        uu = self.u_dist.sample(u.x)
        tp = 0.5 * dr.pi * dr.square(uu)
        phi = 2.0 * dr.pi * u.y
        t = dr.atan(s * dr.tan(tp))
        st, ct = dr.sincos(t)
        sp, cp = dr.sincos(phi)
        m = mi.Vector3f(st * cp, st * sp, ct)
        return m, self.pdf_m(wi, m, s)

    def pdf_m(self, wi, m, s=1.0):
        tan_t, cz = _tan_theta(m)
        tp = dr.atan(tan_t / s)
        cp = dr.cos(tp)
        p = self._pdf_unit(tp) * cp * dr.square(cp) / (dr.square(s) * cz * dr.square(cz))
        return dr.select(m.z > 0, p, 0.0)


# -- Fresnel --------------------------------------------------------------------------------
class SchlickFresnelDJ:
    """Schlick: ``F0 + (1 − F0)(1 − cos θd)⁵`` per RGB channel."""

    kind = "schlick"

    def __init__(self, f0):
        f0 = np.broadcast_to(np.asarray(f0, np.float64), (3,))
        self.f0 = mi.ScalarColor3f(*map(float, f0))

    def eval(self, c, active=True):
        k = dr.square(dr.square(1.0 - c)) * (1.0 - c)
        f0 = kernel_params(self, "f0")
        return f0 + (1.0 - f0) * k


class ConstantFresnelDJ:
    """Constant RGB reflectance (e.g. white Fresnel for furnace tests)."""

    kind = "constant"

    def __init__(self, value=1.0):
        v = np.broadcast_to(np.asarray(value, np.float64), (3,))
        self.v = mi.ScalarColor3f(*map(float, v))

    def eval(self, c, active=True):
        return kernel_params(self, "v") + 0.0 * c


class TableFresnelDJ:
    """Any Fresnel (``brdffit.microfacet.base.Fresnel``), tabulated over cos θd on ``n``
    uniform nodes in [0, 1] and linearly interpolated (smooth curves: error < 1e-5 for
    n = 1024 on Schlick/conductor/dielectric)."""

    kind = "table"

    def __init__(self, values):
        v = np.asarray(values, dtype=np.float64)
        self.n = v.shape[0]
        self.buf = mi.Float(v.astype(np.float32).ravel())

    @classmethod
    def from_fresnel(cls, fresnel, n: int = 1024):
        c = np.linspace(0.0, 1.0, n)
        return cls(np.broadcast_to(np.asarray(fresnel.eval(c), np.float64), (n, 3)))

    def eval(self, c, active=True):
        i0, f = table_cell(c * (self.n - 1), self.n)
        return dr.lerp(dr.gather(mi.Color3f, self.buf, i0, active),
                       dr.gather(mi.Color3f, self.buf, i0 + 1, active), f)


# -- microfacet model -----------------------------------------------------------------------
class MicrofacetEval:
    """``f = kd/π + ks · F(wi·h) · D(h) · G2(wi, wo) / (4 cos θi cos θo)``.

    Dupuy 2015 Eq. 1 (microfacet BRDF) with the height-correlated Smith term of its Eq. 2,
    ``G2 = 1/(1 + Λ(wi) + Λ(wo))``, plus an optional Lambertian term. ``kd`` and ``ks`` are
    RGB. Sampling: with probability ``w`` the distribution's own sampler (VNDF for GGX and
    Beckmann, D cos θ for tables) followed by reflection, else cosine-weighted; ``w = 1`` when
    there is no diffuse term. The pdf is the exact mixture density.
    """

    kind = "microfacet"
    supports_roughness = True

    def __init__(self, dist, fresnel, ks=1.0, kd=0.0, g_mode: str = "correlated"):
        self.dist, self.fresnel = dist, fresnel
        ks = np.broadcast_to(np.asarray(ks, np.float64), (3,))
        kd = np.broadcast_to(np.asarray(kd, np.float64), (3,))
        self.ks = mi.ScalarColor3f(*map(float, ks))
        self.kd = mi.ScalarColor3f(*map(float, kd))
        self.has_diffuse = bool(np.any(kd > 0))
        if g_mode not in ("correlated", "uncorrelated"):
            raise ValueError(f"g_mode must be 'correlated' or 'uncorrelated', got {g_mode!r}")
        self.g_mode = g_mode
        if self.has_diffuse:
            lum = np.array([0.2126, 0.7152, 0.0722])
            spec = float(ks @ lum)
            diff = float(kd @ lum)
            self.spec_weight = float(np.clip(spec / max(spec + diff, 1e-12), 0.1, 0.95))
        else:
            self.spec_weight = 1.0

    def describe(self) -> str:
        return f"microfacet({self.dist.kind}, {self.fresnel.kind} Fresnel)"

    def eval(self, wi, wo, alpha_scale=1.0, active=True):
        ok = active & (wi.z > 0) & (wo.z > 0)
        h = half_vector(wi, wo)
        li, lo = self.dist.Lambda(wi, alpha_scale), self.dist.Lambda(wo, alpha_scale)
        if self.g_mode == "correlated":
            g = 1.0 / (1.0 + li + lo)
        else:
            g = 1.0 / ((1.0 + li) * (1.0 + lo))
        F = self.fresnel.eval(dr.clip(dr.dot(wi, h), 0.0, 1.0), ok)
        denom = 4.0 * dr.maximum(wi.z, 1e-7) * dr.maximum(wo.z, 1e-7)
        ks, kd = kernel_params(self, "ks", "kd")
        f = ks * F * (self.dist.D(h, alpha_scale) * g / denom)
        if self.has_diffuse:
            f += kd * INV_PI
        return dr.select(ok, f, 0.0)

    def pdf(self, wi, wo, alpha_scale=1.0, active=True):
        ok = active & (wi.z > 0) & (wo.z > 0)
        h = half_vector(wi, wo)
        # wo = reflect(wi, m): density of m times the Jacobian 1/(4 |wo·h|)
        pm = self.dist.pdf_m(wi, h, alpha_scale) / (4.0 * dr.maximum(dr.abs(dr.dot(wo, h)), 1e-7))
        pm = dr.select(dr.dot(wi, h) > 0, pm, 0.0)
        w = kernel_params(self, "spec_weight")
        p = w * pm
        if self.has_diffuse:
            p += (1.0 - w) * dr.maximum(wo.z, 0.0) * INV_PI
        return dr.select(ok, p, 0.0)

    def sample(self, wi, u1, u2, alpha_scale=1.0, active=True):
        m, _ = self.dist.sample(wi, u2, alpha_scale)
        wo = _reflect(wi, m)
        if self.has_diffuse:
            wo = dr.select(u1 < kernel_params(self, "spec_weight"), wo, cosine_sample(u2))
        return wo, self.pdf(wi, wo, alpha_scale, active)


class SumEval:
    """Sum of evaluators ``f = Σ f_k``; sampling picks component k with probability
    ``1/K`` (``u1`` is rescaled and reused) and the pdf is the mixture ``Σ p_k / K``."""

    kind = "sum"

    def __init__(self, components):
        self.components = list(components)
        if not self.components:
            raise ValueError("SumEval needs at least one component")
        self.has_diffuse = any(getattr(c, "has_diffuse", True) for c in self.components)
        self.supports_roughness = all(getattr(c, "supports_roughness", False)
                                      for c in self.components)

    def eval(self, wi, wo, alpha_scale=1.0, active=True):
        out = mi.Color3f(0.0)
        for c in self.components:
            out += c.eval(wi, wo, alpha_scale, active)
        return out

    def pdf(self, wi, wo, alpha_scale=1.0, active=True):
        p = mi.Float(0.0)
        for c in self.components:
            p += c.pdf(wi, wo, alpha_scale, active)
        return p / len(self.components)

    def sample(self, wi, u1, u2, alpha_scale=1.0, active=True):
        k = len(self.components)
        x = u1 * k
        wo = mi.Vector3f(0.0, 0.0, 1.0)
        for i, c in enumerate(self.components):
            sel = (x >= i) & (x < i + 1) if i < k - 1 else (x >= i)
            w_i, _ = c.sample(wi, dr.clip(x - i, 0.0, 0.99999994), u2, alpha_scale, active)
            wo = dr.select(sel, w_i, wo)
        return wo, self.pdf(wi, wo, alpha_scale, active)


class PerChannelEval(SumEval):
    """Channel ``c`` of the result is channel ``c`` of ``components[c]`` (three
    single-channel fits); sampling is the equal-weight mixture of the three."""

    kind = "per-channel"

    def __init__(self, components):
        if len(components) != 3:
            raise ValueError(f"PerChannelEval needs 3 components, got {len(components)}")
        super().__init__(components)

    def eval(self, wi, wo, alpha_scale=1.0, active=True):
        vals = [c.eval(wi, wo, alpha_scale, active) for c in self.components]
        return mi.Color3f(vals[0][0], vals[1][1], vals[2][2])


# -- NPF (Bagher, Snyder, Nowrouzezahrai 2016) ----------------------------------------------
def _lerp1(buf, u, n, active=True):
    """Linear interpolation of an RGB table (n entries, flat) at continuous index ``u``
    (clamped to [0, n−1]), like ``brdffit.microfacet.npf_model._lerp``."""
    i0, t = table_cell(u, n)
    return dr.lerp(dr.gather(mi.Color3f, buf, i0, active), dr.gather(mi.Color3f, buf, i0 + 1, active), t)


class NPFEval(_ProxySampling):
    """The NPF models in Dr.Jit (Bagher 2016 Eq. 3-5), per RGB channel:

    * ``"npf"``: ``ρd + ρs D(θh) F(θd) G(θi) G(θo) / (cos θi cos θo)`` (Eq. 3);
    * ``"naive"``: ``ρd + ρs D(θh) F(θd) H(φd)`` (Eq. 4), H periodic over [0, π);
    * ``"bivariate"``: ``B(θh, θd)`` bilinear on the 90 × 90 MERL (θ'h, θd) grid (Eq. 5).

    D on the MERL θh grid (index ``sqrt(θh/(π/2))·90``), F on the θd grid, G at 1° steps
    with a linear taper to 0 at 90° (as :mod:`brdffit.microfacet.npf_model`). Sampling: the
    table paths' cosine + GGX-proxy mixture, proxy α fitted to the model's θd = 0 slice.
    """

    kind = "npf"

    def __init__(self, variant, tables: dict, proxy_profile=None):
        self.variant = variant
        self.kind = {"npf": "npf", "naive": "npf-naive", "bivariate": "npf-bivariate"}[variant]
        self.has_diffuse = True
        f32 = lambda a: mi.Float(np.asarray(a, np.float32).ravel())  # noqa: E731
        if variant == "bivariate":
            self.B = f32(tables["B"])
        else:
            self.D, self.F = f32(tables["D"]), f32(tables["F"])
            self.rho_d = mi.ScalarColor3f(*map(float, tables["rho_d"]))
            self.rho_s = mi.ScalarColor3f(*map(float, tables["rho_s"]))
            if variant == "npf":
                G = np.concatenate([np.asarray(tables["G"], np.float64), np.zeros((1, 3))], 0)
                self.G = f32(G)
            else:
                self.H = f32(tables["H"])
        if proxy_profile is not None:
            self.proxy_alpha, self.proxy_weight = fit_ggx_proxy(merl_theta_h(), proxy_profile)

    def eval(self, wi, wo, alpha_scale=1.0, active=True):
        ok = active & (wi.z > 0) & (wo.z > 0)
        th, td, pd, _ = half_diff(wi, wo)
        uh = dr.sqrt(th * (2.0 / dr.pi)) * 90.0
        ud = td * (180.0 / dr.pi)
        if self.variant == "bivariate":
            i0, s = table_cell(uh, 90)
            j0, t = table_cell(ud, 90)
            g = lambda i, j: dr.gather(mi.Color3f, self.B, i * 90 + j, ok)  # noqa: E731
            v = ((1 - s) * (1 - t) * g(i0, j0) + s * (1 - t) * g(i0 + 1, j0)
                 + (1 - s) * t * g(i0, j0 + 1) + s * t * g(i0 + 1, j0 + 1))
            return dr.select(ok, v, 0.0)
        spec = _lerp1(self.D, uh, 90, ok) * _lerp1(self.F, ud, 90, ok)
        if self.variant == "npf":
            ti = dr.safe_acos(wi.z) * (180.0 / dr.pi)
            to = dr.safe_acos(wo.z) * (180.0 / dr.pi)
            spec *= _lerp1(self.G, ti, 91, ok) * _lerp1(self.G, to, 91, ok) / (
                dr.maximum(wi.z, 1e-7) * dr.maximum(wo.z, 1e-7))
        else:
            i0, i1, t = periodic_cell(periodic_coordinate(pd, dr.pi, 180), 180)
            spec *= dr.lerp(dr.gather(mi.Color3f, self.H, i0, ok), dr.gather(mi.Color3f, self.H, i1, ok), t)
        rho_d, rho_s = kernel_params(self, "rho_d", "rho_s")
        f = rho_d + rho_s * spec
        return dr.select(ok, f, 0.0)
