"""What MaterialX's generated GLSL renders for an ``open_pbr_surface`` lit by an environment
map with ``SPECULAR_ENVIRONMENT_FIS``, noise-free in NumPy (the cheap estimate of the MaterialX
round trip of :mod:`brdffit.evaluation.engines.materialx_web` in the map scenes).

The closures in their indirect mode (``CLOSURE_TYPE_INDIRECT`` of ``mx_dielectric_bsdf``,
``mx_conductor_bsdf``, ``mx_oren_nayar_diffuse_bsdf`` in MaterialX 1.39's ``pbrlib/genglsl``),
layered as :class:`~brdffit.export.materialx.OpenPBRBRDF` layers them for a light::

    L_spec(F) = Σ_i  M(L_i, lod_i) F(V·H_i) G2(N·L_i, N·V) / (G1(N·V) n)      (FIS, below)
    comp(F)   = 1 + F(N·V) (1 − E)/E,    E = A(N·V, ᾱ) + B(N·V, ᾱ)         (rational fit)
    dielectric: tint comp L_spec(F_ior) + (1 − (f0 A + B) comp) · base_color · I(N)
    metal:      specular_weight · comp L_spec(F82-tinted Schlick of base_color)
    base  = (1 − metalness) dielectric + metalness metal
    coat:       c comp_c L_spec,c(F_coat) + (1 − c (f0_c A_c + B_c) comp_c) · base

``I(N)`` is ``u_envIrradiance`` at the normal (E/π, :func:`~brdffit.evaluation.engines.
materialx_web.irradiance_map`), the diffuse's directional albedo is 1 (Oren-Nayar roughness
0). FIS (``mx_environment_radiance``, Křivánek & Colbert 2008): n = 256 spherical-Fibonacci
points ``ξ_i = ((i + ½)/n, frac((i + 1) φ))`` mapped to GGX visible normals ``H_i`` (Heitz
2018) in the tangent frame of the mesh's tangent (three's ``computeTangents`` on its UV
sphere: ``T ∝ (N_z, 0, −N_x)``), ``L_i = reflect(−V, H_i)``, read from the map's mip chain
(WebGL's 2 × 2 box filter, trilinear) at ``lod_i = max(M − 1.5 − ½ log2(n pdf_i √(1 −
L_y²)), 0)``, ``pdf_i = D(H_i) G1(N·V)/(4 N·V)``, M = log2(width) the last level.

The map is the page's own texture (half floats, Mitsuba's lat-long order, which the
generator's ``u_envMatrix`` reads as Mitsuba does). Departures: float64, the analytic sphere
(the page draws a 256 × 128 UV sphere), exact trigonometry.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from ..evaluation.engines.materialx_web import ENV_SAMPLES, irradiance_map
from ..evaluation.engines.threejs import environment_rgba
from ..evaluation.engines.threejs_brdf import CameraSphere
from ..evaluation.engines.threejs_ibl import (estimate_figures, latlong_bilinear, latlong_uv,
                                                map_of_scene)
from .materialx import (OpenPBRBRDF, _dir_albedo_ab, _fresnel_dielectric, _schlick_f82,
                        _smith_g2)

__all__ = ["LatLongMips", "latlong_mips", "shade_fis", "shade_sphere_fis", "estimate_fis"]

_EPS = 1e-6              # M_FLOAT_EPS
_GOLDEN_RATIO = 1.6180339887498948
_MIP_LEVEL_OFFSET = 1.5


class LatLongMips:
    """A lat-long map (Mitsuba's order: row 0 at +y, ``u = atan2(x, −z)/2π``) and its box
    mip chain down to 1 × 1; :meth:`read` is ``textureLod`` with repeat in u, clamp in v."""

    def __init__(self, img: np.ndarray):
        img = np.asarray(img, float)
        if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] < 1 or img.shape[1] < 2:
            raise ValueError(f"LatLongMips: expected an (H, W, 3) map, got {img.shape}")
        self.levels = [img]
        while self.levels[-1].shape[0] > 1 or self.levels[-1].shape[1] > 1:
            c = self.levels[-1]
            if c.shape[0] > 1:
                c = 0.5 * (c[0::2] + c[1::2])
            if c.shape[1] > 1:
                c = 0.5 * (c[:, 0::2] + c[:, 1::2])
            self.levels.append(c)

    def read(self, d: np.ndarray, lod) -> np.ndarray:
        """The map along unit directions ``d`` ``(K, 3)`` at mip level ``lod`` (per row)."""
        u, v = latlong_uv(d)
        lod = np.clip(np.broadcast_to(np.asarray(lod, float), u.shape), 0.0,
                      len(self.levels) - 1.0)
        lo = np.floor(lod).astype(int)
        out = np.empty(u.shape + (3,))
        for k in np.unique(lo):
            m = lo == k
            c = latlong_bilinear(self.levels[k], u[m], v[m])
            if k + 1 < len(self.levels):
                c = c + (latlong_bilinear(self.levels[k + 1], u[m], v[m]) - c) * (lod[m] - k)[:, None]
            out[m] = c
        return out


@lru_cache(maxsize=4)
def latlong_mips(envmap: str | None) -> tuple[LatLongMips, np.ndarray]:
    """``(radiance mips, irradiance map)`` the MaterialX page sends for ``sphere-<envmap>``
    (``None``: the procedural map), as half floats; cached per map."""
    data, w, h = environment_rgba(envmap, convention="mitsuba")
    img = np.frombuffer(data, "<f2").reshape(h, w, 4)[..., :3].astype(np.float64)
    irr = irradiance_map(envmap).astype(np.float16).astype(np.float64)
    return LatLongMips(img), irr


def _smith_g1(nv, alpha):
    """``mx_ggx_smith_G1``."""
    c2 = nv * nv
    return 2.0 / (1.0 + np.sqrt(1.0 + alpha * alpha * (1.0 - c2) / c2))


def _fibonacci(n: int) -> np.ndarray:
    i = np.arange(n)
    return np.stack([(i + 0.5) / n, ((i + 1.0) * _GOLDEN_RATIO) % 1.0], -1)


def fis_radiance(mips: LatLongMips, frame, Vt: np.ndarray, alpha: float, fresnel,
                 samples: int = ENV_SAMPLES) -> np.ndarray:
    """``mx_environment_radiance`` (module docstring) at K points: ``frame`` = (X, Y, N)
    world axes ``(K, 3)`` each, ``Vt`` the view direction in that frame, ``alpha`` the
    isotropic GGX α, ``fresnel(cos)`` → ``(K, 3)`` or ``(K,)``."""
    X, Y, N = frame
    nv = np.clip(Vt[:, 2], _EPS, 1.0)
    g1v = _smith_g1(nv, alpha)
    max_mip = len(mips.levels) - 1.0
    Vh = Vt * np.array([alpha, alpha, 1.0])
    Vh /= np.linalg.norm(Vh, axis=-1, keepdims=True)
    acc = np.zeros(Vt.shape)
    for xi0, xi1 in _fibonacci(samples):
        phi = 2.0 * np.pi * xi0
        z = (1.0 - xi1) * (1.0 + Vh[:, 2]) - Vh[:, 2]
        s = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
        H = np.stack([s * math.cos(phi), s * math.sin(phi), z], -1) + Vh
        H = H * np.array([alpha, alpha, 1.0])
        H[:, 2] = np.maximum(H[:, 2], 0.0)
        H /= np.linalg.norm(H, axis=-1, keepdims=True)
        vh_raw = np.sum(Vt * H, -1)
        L = 2.0 * vh_raw[:, None] * H - Vt
        nl = np.clip(L[:, 2], _EPS, 1.0)
        vh = np.clip(vh_raw, _EPS, 1.0)
        Lw = L[:, 0:1] * X + L[:, 1:2] * Y + L[:, 2:3] * N
        D = 1.0 / (np.pi * alpha * alpha * ((H[:, 0] ** 2 + H[:, 1] ** 2) / (alpha * alpha)
                                            + H[:, 2] ** 2) ** 2)
        pdf = D * g1v / (4.0 * nv)
        distortion = np.sqrt(np.maximum(1.0 - Lw[:, 1] ** 2, 0.0))
        with np.errstate(divide="ignore"):
            lod = np.maximum(max_mip - _MIP_LEVEL_OFFSET
                             - 0.5 * np.log2(samples * pdf * distortion), 0.0)
        F = np.asarray(fresnel(vh))
        F = F if F.ndim == 2 else F[:, None]
        acc += mips.read(Lw, lod) * F * _smith_g2(nl, nv, alpha)[:, None]
    return acc / (g1v * samples)[:, None]


def _comp(nv, alpha, F):
    """``mx_ggx_energy_compensation``: ``1 + F (1 − E)/E``, ``(A, B)`` of the rational fit."""
    A, B = _dir_albedo_ab(nv, alpha)
    E = (A + B)[:, None]
    return 1.0 + F * (1.0 - E) / E, A[:, None], B[:, None]


def shade_fis(model: OpenPBRBRDF, mips: LatLongMips, irradiance: np.ndarray, N: np.ndarray,
              V: np.ndarray, samples: int = ENV_SAMPLES) -> np.ndarray:
    """Radiance ``(K, 3)`` MaterialX renders at K surface points (world normals ``N``,
    directions to the camera ``V``) of ``model`` (isotropic) under the map (module
    docstring)."""
    if not model.isotropic:
        raise ValueError("shade_fis: anisotropic OpenPBR lobes are not modelled")
    T = np.stack([N[:, 2], np.zeros(len(N)), -N[:, 0]], -1)
    T = T - np.sum(T * N, -1, keepdims=True) * N
    X = T / np.maximum(np.linalg.norm(T, axis=-1, keepdims=True), 1e-12)
    Y = np.cross(N, X)
    Vt = np.stack([np.sum(V * X, -1), np.sum(V * Y, -1), np.sum(V * N, -1)], -1)
    nv = np.clip(Vt[:, 2], _EPS, 1.0)
    irr = latlong_bilinear(irradiance, *latlong_uv(N))
    frame = (X, Y, N)
    alpha = float(np.sqrt(model.alpha[0] * model.alpha[1]))
    m = model.base_metalness
    base = np.zeros(N.shape)

    def dielectric(a, ior):     # (response without tint, directional albedo) of the layer
        comp, A, B = _comp(nv, a, _fresnel_dielectric(nv, ior)[:, None])
        f0 = ((ior - 1.0) / (ior + 1.0)) ** 2
        spec = fis_radiance(mips, frame, Vt, a, lambda c: _fresnel_dielectric(c, ior), samples)
        return spec * comp, (f0 * A + B) * comp

    if m < 1.0:
        spec, albedo = dielectric(alpha, model._ior())
        base += (1.0 - m) * (spec * np.maximum(model.specular_color, 0.0)
                             + (1.0 - albedo) * np.maximum(model.base_color, 0.0) * irr)
    if m > 0.0:
        c0, tint = np.maximum(model.base_color, 0.0), np.maximum(model.specular_color, 0.0)
        comp = _comp(nv, alpha, _schlick_f82(nv, c0, tint))[0]
        spec = fis_radiance(mips, frame, Vt, alpha, lambda c: _schlick_f82(c, c0, tint), samples)
        base += m * model.specular_weight * spec * comp
    if model.coat_weight <= 0.0:
        return base
    coat, albedo = dielectric(float(np.clip(model.coat_roughness ** 2, 1e-6, 1.0)),
                              model.coat_ior)
    return model.coat_weight * coat + (1.0 - model.coat_weight * albedo) * base


def shade_sphere_fis(model: OpenPBRBRDF, envmap: str | None = None, resolution: int = 96,
                     supersample: int = 2, samples: int = ENV_SAMPLES):
    """Noise-free MaterialX (FIS) render of ``model`` on the unit sphere of
    ``sphere-<envmap>`` (``None``: ``sphere-env``): ``(image (H, W, 3), alpha (H, W))``,
    ``supersample``² pixel-centred samples per pixel, box averaged."""
    cam = CameraSphere(resolution, supersample)
    mips, irr = latlong_mips(envmap)
    return cam.average(shade_fis(model, mips, irr, cam.N[cam.hit], cam.V[cam.hit], samples))


def estimate_fis(model: OpenPBRBRDF, ref_stack, ref_alpha, scene: str = "sphere-env",
                 supersample: int = 2, samples: int = ENV_SAMPLES, rim: float = 0.85) -> dict:
    """The cheap estimate of the MaterialX round trip in a map scene: :func:`shade_sphere_fis`
    of ``model`` (the exporter's :class:`~brdffit.export.materialx.OpenPBRBRDF` of the fit)
    against our render of the fit (``ref_stack``, ``ref_alpha``:
    :func:`~brdffit.evaluation.engines.threejs.reference_renders`), compared as the engine's
    render is. Returns ``psnr``, ``psnr_se``, ``mean_ratio``, ``rim_ratio`` and the model's
    ``image`` and ``alpha``."""
    envmap = map_of_scene(scene, "estimate_fis")
    img, alpha = shade_sphere_fis(model, envmap, np.shape(ref_alpha)[1], supersample, samples)
    return estimate_figures(img, alpha, ref_stack, ref_alpha, rim)
