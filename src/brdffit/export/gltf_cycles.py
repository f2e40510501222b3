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
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..brdf import _as_dirs
from .gltf_brdf import GLTFBRDF

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


class _Lobe:
    """GGX lobe of slope scale ``alpha``: ``dv(wi, wo, h) = D G2 / (4 μi μo)`` and its
    tables in μ: ``E`` (albedo for F = 1), ``E_avg`` and ``s̄`` (the mean of ``s(c)`` for
    the index ``eta``, weighted by the lobe's reflected energy)."""

    def __init__(self, alpha: float, eta: float | None, n: int = 64):
        self.alpha = max(float(alpha), 1e-4)
        self.eta = eta
        u = (np.arange(n) + 0.5) / n
        U1, U2 = np.meshgrid(u, u, indexing="ij")
        U1, U2 = U1.ravel(), U2.ravel()
        E, S = [], []
        for mu in _MU_NODES:
            wo = np.array([np.sqrt(1.0 - mu * mu), 0.0, mu])
            h = self._sample_visible_normal(wo, U1, U2)
            c = h @ wo
            wi = 2.0 * c[:, None] * h - wo
            ok = wi[:, 2] > 0
            a = self.alpha
            g1o = 1.0 / (1.0 + _lambda(a, mu))
            g2 = 1.0 / (1.0 + _lambda(a, wi[:, 2]) + _lambda(a, mu))
            w = np.where(ok, g2 / g1o, 0.0)          # f μi / pdf for F = 1 (VNDF sampling)
            E.append(w.mean())
            S.append((w * self.s(c)).mean() / max(w.mean(), 1e-300) if eta else 0.0)
        self.E, self.S = np.array(E), np.array(S)
        mu = np.linspace(0.0, 1.0, 257)
        self.E_avg = float(2.0 * np.trapezoid(np.interp(mu, _MU_NODES, self.E) * mu, mu))

    def _sample_visible_normal(self, wo, u1, u2):
        """Heitz 2018, "Sampling the GGX Distribution of Visible Normals" (isotropic)."""
        a = self.alpha
        vh = np.array([a * wo[0], a * wo[1], wo[2]])
        vh /= np.linalg.norm(vh)
        lensq = vh[0] ** 2 + vh[1] ** 2
        t1 = (np.array([-vh[1], vh[0], 0.0]) / np.sqrt(lensq) if lensq > 0
              else np.array([1.0, 0.0, 0.0]))
        t2 = np.cross(vh, t1)
        r = np.sqrt(u1)
        phi = 2.0 * np.pi * u2
        p1 = r * np.cos(phi)
        p2 = r * np.sin(phi)
        s = 0.5 * (1.0 + vh[2])
        p2 = (1.0 - s) * np.sqrt(1.0 - p1 * p1) + s * p2
        nh = (p1[:, None] * t1 + p2[:, None] * t2
              + np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))[:, None] * vh)
        n = np.stack([a * nh[:, 0], a * nh[:, 1], np.maximum(1e-9, nh[:, 2])], -1)
        return n / np.linalg.norm(n, axis=1, keepdims=True)

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

    def energy(self, F_ss, mu):
        """``(1 + F_ms (1 − E)/E, darkening)`` at ``μ`` for the mean Fresnel ``F_ss``."""
        E = self.table(self.E, mu)[..., None]
        F_ss = np.asarray(F_ss, float)
        F_ms = F_ss * self.E_avg / (1.0 - F_ss * (1.0 - self.E_avg))
        scale = 1.0 + F_ms * (1.0 - E) / E
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

    def eval(self, wi, wo) -> np.ndarray:
        wi, wo = _as_dirs(wi, wo)
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        h = wi + wo
        h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        c = np.abs(np.sum(wo * h, -1))
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
            f_ss = (self.eta - 1.0) / (4.08567 + 1.00071 * self.eta)
            s_ss = np.clip((f_ss - _f0_of(self.eta)) / (1.0 - _f0_of(self.eta)), 0.0, 1.0)
            Fss_d = self.f0_tinted + (1.0 - self.f0_tinted) * s_ss
        else:                               # index 1: no specular layer
            F_d = albedo = Fss_d = np.zeros(3)
        if self.multiscatter:
            scale_d, dark_d = lobe.energy(Fss_d, mu)
            scale_m, _ = lobe.energy(self.base_color + (1.0 - self.base_color) / 21.0, mu)
        else:
            scale_d, dark_d, scale_m = 1.0, 1.0, 1.0
        spec_d = F_d * dv * scale_d
        layer = np.clip(1.0 - np.max(albedo * dark_d, axis=-1, keepdims=True), 0.0, 1.0)
        f = m * F_m * dv * scale_m + (1.0 - m) * (spec_d + layer * self.base_color / np.pi)
        if self.coat is not None:
            cl = self.coat
            F_c = _fresnel_dielectric(c, 1.5)[..., None]
            Fss_c = (1.5 - 1.0) / (4.08567 + 1.00071 * 1.5)
            scale_c, dark_c = cl.energy(Fss_c, mu)
            alb_c = _f0_of(1.5) + (1.0 - _f0_of(1.5)) * cl.table(cl.S, mu)[..., None]
            coat = self.clearcoat * F_c * cl.dv(wi, wo, h)[..., None] * scale_c
            f = coat + np.clip(1.0 - self.clearcoat * alb_c * dark_c, 0.0, 1.0) * f
        return np.where(ok[..., None], f, 0.0)

    def as_microfacet(self):
        return None

    def describe(self) -> dict:
        d = super().describe()
        d.update(engine="Blender Cycles Principled BSDF", multiscatter=self.multiscatter)
        return d
