"""What Blender (Cycles 5.0) renders for a glTF material imported with its own importer.

:class:`CyclesPrincipledBRDF` is the Principled BSDF of Cycles as the glTF importer sets it
up, written from Cycles' kernel sources (``kernel/svm/closure.h``, case
``CLOSURE_BSDF_PRINCIPLED_ID``; ``kernel/closure/bsdf_microfacet.h``; ``bsdf_util.h``), for the
inputs the importer writes (``io_scene_gltf2/blender/imp/pbrMetallicRoughness.py``):
Base Color = baseColorFactor, Metallic, Roughness = roughnessFactor (α = r²), IOR = glTF ior,
**Specular IOR Level = specularFactor / 2**, Specular Tint = specularColorFactor, Coat Weight
= clearcoatFactor, Coat Roughness = clearcoatRoughnessFactor (Coat IOR 1.5). With
``L = wi``, ``V = wo``, ``c = V·H``, ``μ = N·V``:

* microfacet lobes: GGX ``D`` of α, height-correlated Smith ``G2 = 1/(1 + Λ(L) + Λ(V))``,
  ``f = F D G2 / (4 |N·L| |N·V|)``;
* dielectric specular: ``f0 = F0(ior) · 2 · level`` (= F0(ior) · specularFactor) and, when
  level ≠ 0.5, the index becomes ``η = ior_from_F0(f0)`` (f0 clamped to 0.99);
  ``F = f0t + (1 − f0t) s(c)`` with ``f0t = min(f0 · tint, 1)`` and ``s(c) = (F_η(c) −
  F0(η)) / (1 − F0(η))`` clamped to [0, 1] (F_η the exact dielectric Fresnel): the curve of
  the real index rescaled to reach **1** at grazing whatever specularFactor (glTF's
  ``f90 = specularFactor`` is not carried);
* metal (weight ``metallic``; the rest weighted ``1 − metallic``): F82-tint Fresnel with a
  white tint, i.e. Schlick ``base + (1 − base)(1 − c)⁵``;
* multiscatter GGX (the importer's default distribution) multiplies each lobe by ``1 +
  F_ms (1 − E(μ)) / E(μ)`` with ``E`` the lobe's directional albedo for F = 1, ``E_avg = 2
  ∫ E μ dμ``, ``F_ms = F_ss E_avg / (1 − F_ss (1 − E_avg))`` and ``F_ss`` the hemispherical
  mean Fresnel (Kulla & Conty 2017, as Cycles): ``mix(f0t, 1, s_ss)`` with ``s_ss`` from
  Cycles' fit ``F_ss(η) = (η − 1)/(4.08567 + 1.00071 η)``; metal ``base + (1 − base)/21``;
  the coat always gets it (its set-up preserves energy in either mode);
* layering (``closure_layering_weight``): each layer below the coat and the specular one is
  weighted by ``1 − max_channel(albedo)`` — **one scalar**, the largest channel — of the
  layer above, at ``μ``: ``albedo = darkening · mix(f0t, 1, s̄(μ))`` where ``s̄(μ)`` is
  ``s(c)`` averaged over the lobe (weights ``F = 1`` lobe's reflected energy) and
  ``darkening = (1 + F_ms (1 − E)/E) E`` with multiscatter, 1 without;
* diffuse: Lambert ``base/π`` times the specular layer's weight and ``1 − metallic``.

Deviations: the albedo tables ``E(μ)``, ``E_avg`` and ``s̄(μ)`` are computed here per lobe
by quadrature over stratified samples of the visible normals (Heitz 2018; 64 × 64 per μ, 32
values of μ, linear interpolation in μ) where Cycles reads precomputed 16³ / 32² tables in
``(√α, μ, √((η−1)/(η+1)))``; anisotropy (``KHR_materials_anisotropy``) is not modelled
(:class:`ValueError`); Cycles' shading-normal correction at grazing angles
(``maybe_ensure_valid_specular_reflection``) is not modelled.

With Numba, :meth:`CyclesPrincipledBRDF.eval` and the albedo tables run compiled per-sample
kernels (``_cycles_kernel``, ``_lobe_tables_kernel``): the NumPy paths' operations in their
order, the same values to rounding (tested).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .._jit import lazy_numba
from ..brdf import _as_dirs, _dot3, _run_per_sample, _unit_half, _visible_half_kernel
from .gltf_brdf import GLTFBRDF

_numba = lazy_numba()

__all__ = ["CyclesPrincipledBRDF"]

_MU_NODES = np.linspace(0.02, 1.0, 32)


def _fresnel_dielectric(c, eta: float):
    """Exact unpolarised Fresnel reflectance of a dielectric of relative index ``eta`` ≥ 1
    for the cosine ``c`` of the angle of incidence."""
    c = np.clip(np.abs(c), 0.0, 1.0)
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (g - c) / (g + c)
        b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        f = 0.5 * a * a * (1.0 + b * b)
    return np.where(g2 > 0, np.nan_to_num(f, nan=1.0), 1.0)


def _f0_of(eta: float) -> float:
    return ((eta - 1.0) / (eta + 1.0)) ** 2


def _ior_from_f0(f0: float) -> float:
    q = np.sqrt(np.clip(f0, 0.0, 0.99))
    return float((1.0 + q) / (1.0 - q))


def _lambda(alpha: float, mu):
    mu = np.clip(mu, 1e-9, 1.0)
    return 0.5 * (-1.0 + np.sqrt(1.0 + alpha * alpha * (1.0 / (mu * mu) - 1.0)))


def _lobe_tables_kernel(alpha, eta, nodes, u, E, S):  # pragma: no cover  (compiled by numba)
    """:class:`_Lobe`'s tables ``E[m]`` and ``S[m]`` at ``μ = nodes[m]`` from the VNDF samples
    of the stratified grid ``u × u``: the operations of :meth:`_Lobe._tables_numpy`, per node
    a branch-free pass over the samples (NumPy's error model, no division checks: the
    compiler vectorises it), then the sums in order rather than pairwise; ``eta`` 0: no
    index (``S`` = 0)."""
    n = u.size
    p1 = np.empty(n * n)
    q2 = np.empty(n * n)
    q1 = np.empty(n * n)
    for i in range(n):
        r = np.sqrt(u[i])
        for j in range(n):
            phi = 2.0 * np.pi * u[j]
            p1[i * n + j] = r * np.cos(phi)
            q2[i * n + j] = r * np.sin(phi)
            q1[i * n + j] = np.sqrt(1.0 - p1[i * n + j] * p1[i * n + j])
    f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
    w = np.empty(n * n)
    cos = np.empty(n * n)                      # V·H of each sample, then s(V·H)
    for m in range(nodes.size):
        mu = nodes[m]
        wx = np.sqrt(1.0 - mu * mu)
        vx, vz = alpha * wx, mu
        norm = np.sqrt(vx * vx + vz * vz)
        vx, vz = vx / norm, vz / norm
        if vx * vx > 0:
            t1x, t1y = -0.0, vx / np.sqrt(vx * vx)
        else:
            t1x, t1y = 1.0, 0.0
        t2x, t2y, t2z = -vz * t1y, vz * t1x, vx * t1y
        s = 0.5 * (1.0 + vz)
        lam_o = _lambda_kernel(alpha, mu)
        g1o = 1.0 / (1.0 + lam_o)
        for k in range(n * n):
            a1 = p1[k]
            a2 = (1.0 - s) * q1[k] + s * q2[k]
            a3 = np.sqrt(max(0.0, 1.0 - a1 * a1 - a2 * a2))
            hx = alpha * (a1 * t1x + a2 * t2x + a3 * vx)
            hy = alpha * (a1 * t1y + a2 * t2y)
            hz = max(1e-9, a2 * t2z + a3 * vz)
            hn = np.sqrt(hx * hx + hy * hy + hz * hz)
            hx, hz = hx / hn, hz / hn
            c = hx * wx + hz * mu
            wi_z = 2.0 * c * hz - mu
            lam_i = _lambda_kernel(alpha, wi_z)
            w[k] = (1.0 / (1.0 + lam_i + lam_o)) / g1o if wi_z > 0 else 0.0
            cos[k] = c
        e_sum = 0.0
        s_sum = 0.0
        for k in range(n * n):
            e_sum += w[k]
        if eta > 0:
            for k in range(n * n):
                cos[k] = min(max((_fresnel_kernel(cos[k], eta) - f0) / (1.0 - f0), 0.0), 1.0)
            for k in range(n * n):
                s_sum += w[k] * cos[k]
        E[m] = e_sum / (n * n)
        S[m] = s_sum / (n * n) / max(E[m], 1e-300)


def _lambda_kernel(alpha, mu):  # pragma: no cover  (compiled by numba)
    """:func:`_lambda` of one cosine."""
    mu = min(max(mu, 1e-9), 1.0)
    return 0.5 * (-1.0 + np.sqrt(1.0 + alpha * alpha * (1.0 / (mu * mu) - 1.0)))


def _fresnel_kernel(c, eta):  # pragma: no cover  (compiled by numba)
    """:func:`_fresnel_dielectric` of one cosine."""
    c = min(max(abs(c), 0.0), 1.0)
    g2 = eta * eta - 1.0 + c * c
    if g2 <= 0:
        return 1.0
    g = np.sqrt(g2)
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    f = 0.5 * a * a * (1.0 + b * b)
    return 1.0 if np.isnan(f) else f


def _interp_kernel(nodes, values, x):  # pragma: no cover  (compiled by numba)
    """``np.interp(x, nodes, values)`` for ``x`` in ``[nodes[0], nodes[-1]]``."""
    j = np.searchsorted(nodes, x, side="right") - 1
    if j >= nodes.size - 1 or nodes[j] == x:
        return values[min(j, nodes.size - 1)]
    slope = (values[j + 1] - values[j]) / (nodes[j + 1] - nodes[j])
    return slope * (x - nodes[j]) + values[j]


def _ggx_dv_kernel(alpha, a2, nl, nv, nh):  # pragma: no cover  (compiled by numba)
    """:meth:`_Lobe.dv` of one sample (``nan_to_num`` included)."""
    D = a2 / (np.pi * (nh * nh * (a2 - 1.0) + 1.0) ** 2)
    G2 = 1.0 / (1.0 + _lambda_kernel(alpha, nl) + _lambda_kernel(alpha, nv))
    x = D * G2 / (4.0 * nl * nv)
    if np.isnan(x):
        return 0.0
    return min(max(x, -1.7976931348623157e308), 1.7976931348623157e308)


def _cycles_kernel(wi, wo, lobe, tables, base, metallic, f0t, fms_d, fms_m, coat,
                   out):  # pragma: no cover  (compiled by numba)
    """:meth:`CyclesPrincipledBRDF.eval` per sample (its order of operations): ``lobe`` =
    (α, α², η or 0, F0(η), multiscatter 1/0), ``tables`` (4, 32) = the lobe's E and S, the
    coat's E and S at :data:`_MU_NODES`; ``fms_d``, ``fms_m`` the layers' ``F_ms`` per
    channel; ``coat`` = (weight, α, α², F_ms) (weight 0: none)."""
    alpha, a2, eta, f0_eta, ms = lobe[0], lobe[1], lobe[2], lobe[3], lobe[4] > 0
    nodes = _MU_NODES_K
    f0_c = ((1.5 - 1.0) / (1.5 + 1.0)) ** 2
    cf = under = 0.0
    for k in range(wi.shape[0]):
        visible, hx, hy, hz = _visible_half_kernel(wi, wo, k, out)
        if not visible:
            continue
        nl, nv = wi[k, 2], wo[k, 2]
        c = abs(wo[k, 0] * hx + wo[k, 1] * hy + nv * hz)
        mu = min(max(nv, nodes[0]), 1.0)
        dv = _ggx_dv_kernel(alpha, a2, nl, nv, hz)
        x5 = (1.0 - c) ** 5.0
        E = _interp_kernel(nodes, tables[0], mu)
        s = s_mean = 0.0
        if eta > 0:
            s = min(max((_fresnel_kernel(c, eta) - f0_eta) / (1.0 - f0_eta), 0.0), 1.0)
            s_mean = _interp_kernel(nodes, tables[1], mu)
        top = -np.inf
        for ch in range(3):
            albedo = f0t[ch] + (1.0 - f0t[ch]) * s_mean if eta > 0 else 0.0
            dark = (1.0 + fms_d[ch] * (1.0 - E) / E) * E if ms else 1.0
            top = max(top, albedo * dark)
        layer = min(max(1.0 - top, 0.0), 1.0)
        if coat[0] > 0:
            Ec = _interp_kernel(nodes, tables[2], mu)
            scale_c = 1.0 + coat[3] * (1.0 - Ec) / Ec
            alb_c = f0_c + (1.0 - f0_c) * _interp_kernel(nodes, tables[3], mu)
            cf = (coat[0] * _fresnel_kernel(c, 1.5) * _ggx_dv_kernel(coat[1], coat[2], nl, nv, hz)
                  * scale_c)
            under = min(max(1.0 - coat[0] * alb_c * (scale_c * Ec), 0.0), 1.0)
        for ch in range(3):
            b = base[ch]
            F_m = b + (1.0 - b) * x5
            F_d = f0t[ch] + (1.0 - f0t[ch]) * s if eta > 0 else 0.0
            scale_m = 1.0 + fms_m[ch] * (1.0 - E) / E if ms else 1.0
            scale_d = 1.0 + fms_d[ch] * (1.0 - E) / E if ms else 1.0
            f = (metallic * F_m * dv * scale_m
                 + (1.0 - metallic) * (F_d * dv * scale_d + layer * b / np.pi))
            out[k, ch] = cf + under * f if coat[0] > 0 else f


_MU_NODES_K = _MU_NODES.copy()
#: the coat's mean Fresnel ``F_ss`` (index 1.5, Cycles' fit)
_COAT_FSS = (1.5 - 1.0) / (4.08567 + 1.00071 * 1.5)


if _numba is not None:
    _inline = _numba.njit(cache=True, nogil=True, inline="always", error_model="numpy")
    _lambda_kernel, _fresnel_kernel = _inline(_lambda_kernel), _inline(_fresnel_kernel)
    _interp_kernel, _ggx_dv_kernel = _inline(_interp_kernel), _inline(_ggx_dv_kernel)
    _lobe_tables_kernel, _cycles_kernel = (
        _numba.njit(cache=True, nogil=True, error_model="numpy")(f)
        for f in (_lobe_tables_kernel, _cycles_kernel))


class _Lobe:
    """GGX lobe of slope scale ``alpha``: ``dv(wi, wo, h) = D G2 / (4 μi μo)`` and its
    tables in μ: ``E`` (albedo for F = 1), ``E_avg`` and ``s̄`` (the mean of ``s(c)`` for
    the index ``eta``, weighted by the lobe's reflected energy)."""

    def __init__(self, alpha: float, eta: float | None, n: int = 64):
        self.alpha = max(float(alpha), 1e-4)
        self.eta = eta
        u = (np.arange(n) + 0.5) / n
        if _numba is not None and _lobe_tables_kernel.worth_compiling(_MU_NODES.size * n * n):
            self.E, self.S = np.empty(_MU_NODES.size), np.empty(_MU_NODES.size)
            _lobe_tables_kernel(self.alpha, float(eta or 0.0), _MU_NODES, u, self.E, self.S)
        else:
            self.E, self.S = self._tables_numpy(u)
        mu = np.linspace(0.0, 1.0, 257)
        self.E_avg = float(2.0 * np.trapezoid(np.interp(mu, _MU_NODES, self.E) * mu, mu))

    def _tables_numpy(self, u):
        """``(E, S)`` at the nodes :data:`_MU_NODES` by quadrature over the VNDF samples of the
        stratified grid ``u × u`` (all nodes in one pass)."""
        U1, U2 = np.meshgrid(u, u, indexing="ij")
        mu = _MU_NODES[:, None]                                 # (32, 1) × n² samples
        wo = np.stack([np.sqrt(1.0 - _MU_NODES**2), np.zeros_like(_MU_NODES), _MU_NODES], -1)
        h = self._sample_visible_normals(wo, U1.ravel(), U2.ravel())
        c = np.einsum("msk,mk->ms", h, wo)
        wi_z = 2.0 * c * h[..., 2] - mu
        a = self.alpha
        g1o = 1.0 / (1.0 + _lambda(a, mu))
        g2 = 1.0 / (1.0 + _lambda(a, wi_z) + _lambda(a, mu))
        w = np.where(wi_z > 0, g2 / g1o, 0.0)          # f μi / pdf for F = 1 (VNDF sampling)
        E = w.mean(axis=1)
        if not self.eta:
            return E, np.zeros_like(E)
        return E, (w * self.s(c)).mean(axis=1) / np.maximum(E, 1e-300)

    def _sample_visible_normals(self, wo, u1, u2):
        """Heitz 2018, "Sampling the GGX Distribution of Visible Normals" (isotropic): the
        normals ``(m, s, 3)`` of the samples ``(u1, u2)`` (s) for each of the directions
        ``wo`` (m, 3)."""
        a = self.alpha
        vh = np.stack([a * wo[:, 0], a * wo[:, 1], wo[:, 2]], -1)
        vh /= np.linalg.norm(vh, axis=1, keepdims=True)
        lensq = vh[:, 0] ** 2 + vh[:, 1] ** 2
        safe = np.sqrt(np.where(lensq > 0, lensq, 1.0))
        t1 = np.where((lensq > 0)[:, None],
                      np.stack([-vh[:, 1], vh[:, 0], np.zeros_like(lensq)], -1) / safe[:, None],
                      np.array([1.0, 0.0, 0.0]))
        t2 = np.cross(vh, t1)
        r = np.sqrt(u1)
        phi = 2.0 * np.pi * u2
        p1 = r * np.cos(phi)
        p2 = r * np.sin(phi)
        s = 0.5 * (1.0 + vh[:, 2:3])
        p2 = (1.0 - s) * np.sqrt(1.0 - p1 * p1) + s * p2          # (m, s)
        p3 = np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))
        nh = [p1 * t1[:, k:k + 1] + p2 * t2[:, k:k + 1] + p3 * vh[:, k:k + 1] for k in range(3)]
        n = np.stack([a * nh[0], a * nh[1], np.maximum(1e-9, nh[2])], -1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def s(self, c):
        """``s(c)``: the real index's Fresnel rescaled from [F0(η), 1] to [0, 1]."""
        f0 = _f0_of(self.eta)
        return np.clip((_fresnel_dielectric(c, self.eta) - f0) / (1.0 - f0), 0.0, 1.0)

    def table(self, values, mu):
        return np.interp(np.clip(mu, _MU_NODES[0], 1.0), _MU_NODES, values)

    def dv(self, wi, wo, h):
        a2 = self.alpha**2
        nl, nv, nh = wi[..., 2], wo[..., 2], h[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            D = a2 / (np.pi * (nh * nh * (a2 - 1.0) + 1.0) ** 2)
            G2 = 1.0 / (1.0 + _lambda(self.alpha, nl) + _lambda(self.alpha, nv))
            return np.nan_to_num(D * G2 / (4.0 * nl * nv))

    def f_ms(self, F_ss):
        """``F_ms = F_ss E_avg / (1 − F_ss (1 − E_avg))`` for the mean Fresnel ``F_ss``."""
        F_ss = np.asarray(F_ss, float)
        return F_ss * self.E_avg / (1.0 - F_ss * (1.0 - self.E_avg))

    def energy(self, F_ss, mu):
        """``(1 + F_ms (1 − E)/E, darkening)`` at ``μ`` for the mean Fresnel ``F_ss``."""
        E = self.table(self.E, mu)[..., None]
        scale = 1.0 + self.f_ms(F_ss) * (1.0 - E) / E
        return scale, scale * E


@lru_cache(maxsize=64)
def _lobe(alpha: float, eta: float | None) -> _Lobe:
    """The lobe of ``(alpha, eta)``, shared (its tables are read-only once computed)."""
    return _Lobe(alpha, eta)


class CyclesPrincipledBRDF(GLTFBRDF):
    """Cycles' Principled BSDF for a glTF material imported by Blender (module docstring);
    the parameters of :class:`GLTFBRDF` and ``multiscatter`` (the importer's default
    distribution, "Multiscatter GGX"; ``False``: "GGX")."""

    def __init__(self, *args, multiscatter: bool = True, **kwargs):
        super().__init__(*args, **kwargs)
        if self.anisotropy_strength != 0.0:
            raise ValueError("CyclesPrincipledBRDF: KHR_materials_anisotropy is not modelled")
        self.multiscatter = bool(multiscatter)
        self.name = kwargs.get("name", "cycles")
        level = 0.5 * self.specular_factor
        f0 = _f0_of(self.ior) * 2.0 * level
        self.eta = self.ior if level == 0.5 else _ior_from_f0(f0)
        self.f0_tinted = np.clip(f0 * self.specular_color, 0.0, 1.0)
        alpha = self.roughness**2
        self.lobe = _lobe(alpha, self.eta if self.eta > 1.0 else None)
        self.coat = (_lobe(self.clearcoat_roughness**2, 1.5) if self.clearcoat > 0 else None)

    def _mean_fresnels(self) -> tuple[np.ndarray, np.ndarray]:
        """The layers' mean Fresnels ``F_ss`` (module docstring): metal ``mix(base, 1,
        1/21)``, dielectric ``mix(f0t, 1, s_ss)`` with Cycles' fit of ``F_ss(η)`` (0 without
        an index)."""
        metal = self.base_color + (1.0 - self.base_color) / 21.0
        if not self.lobe.eta:
            return metal, np.zeros(3)
        f_ss = (self.eta - 1.0) / (4.08567 + 1.00071 * self.eta)
        s_ss = np.clip((f_ss - _f0_of(self.eta)) / (1.0 - _f0_of(self.eta)), 0.0, 1.0)
        return metal, self.f0_tinted + (1.0 - self.f0_tinted) * s_ss

    def eval(self, wi, wo) -> np.ndarray:
        wi, wo = _as_dirs(wi, wo)
        if _numba is not None and _cycles_kernel.worth_compiling(wi[..., 0].size):
            return self._eval_compiled(wi, wo)
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        h = _unit_half(wi, wo)
        c = np.abs(_dot3(wo, h))
        mu = wo[..., 2]
        lobe, m = self.lobe, self.metallic
        dv = lobe.dv(wi, wo, h)[..., None]
        x5 = ((1.0 - c) ** 5)[..., None]
        # metal: Schlick (F82-tint with a white tint)
        F_m = self.base_color + (1.0 - self.base_color) * x5
        # dielectric specular: the real index's curve from f0t to 1
        if lobe.eta:
            s = lobe.s(c)[..., None]
            F_d = self.f0_tinted + (1.0 - self.f0_tinted) * s
            s_mean = lobe.table(lobe.S, mu)[..., None]
            albedo = self.f0_tinted + (1.0 - self.f0_tinted) * s_mean
        else:                               # index 1: no specular layer
            F_d = albedo = np.zeros(3)
        if self.multiscatter:
            fss_metal, fss_dielectric = self._mean_fresnels()
            scale_d, dark_d = lobe.energy(fss_dielectric, mu)
            scale_m, _ = lobe.energy(fss_metal, mu)
        else:
            scale_d, dark_d, scale_m = 1.0, 1.0, 1.0
        spec_d = F_d * dv * scale_d
        top = albedo * dark_d                # its largest channel, without a reduction
        top = np.maximum(np.maximum(top[..., 0], top[..., 1]), top[..., 2])[..., None]
        layer = np.clip(1.0 - top, 0.0, 1.0)
        f = m * F_m * dv * scale_m + (1.0 - m) * (spec_d + layer * self.base_color / np.pi)
        if self.coat is not None:
            cl = self.coat
            F_c = _fresnel_dielectric(c, 1.5)[..., None]
            scale_c, dark_c = cl.energy(_COAT_FSS, mu)
            alb_c = _f0_of(1.5) + (1.0 - _f0_of(1.5)) * cl.table(cl.S, mu)[..., None]
            coat = self.clearcoat * F_c * cl.dv(wi, wo, h)[..., None] * scale_c
            f = coat + np.clip(1.0 - self.clearcoat * alb_c * dark_c, 0.0, 1.0) * f
        return np.where(ok[..., None], f, 0.0)

    def _eval_compiled(self, wi, wo) -> np.ndarray:
        """:meth:`eval` by :func:`_cycles_kernel` (the NumPy path's values to rounding)."""
        lobe, coat = self.lobe, self.coat
        eta = float(lobe.eta or 0.0)
        fss_metal, fss_dielectric = self._mean_fresnels()
        tables = np.stack([lobe.E, lobe.S] + ([coat.E, coat.S] if coat else [lobe.E, lobe.S]))
        coat_args = (np.array([self.clearcoat, coat.alpha, coat.alpha**2, coat.f_ms(_COAT_FSS)])
                     if coat else np.zeros(4))
        return _run_per_sample(_cycles_kernel, wi, wo,
                               np.array([lobe.alpha, lobe.alpha**2, eta,
                                         _f0_of(eta) if eta else 0.0, float(self.multiscatter)]),
                               tables, self.base_color, self.metallic, self.f0_tinted,
                               lobe.f_ms(fss_dielectric), lobe.f_ms(fss_metal), coat_args)

    def as_microfacet(self):
        return None

    def describe(self) -> dict:
        d = super().describe()
        d.update(engine="Blender Cycles Principled BSDF", multiscatter=self.multiscatter)
        return d
