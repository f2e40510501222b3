"""What three.js r187 renders for a glTF material under a punctual light, as a library BRDF,
and a noise-free shader of our sphere scenes to evaluate it (the cheap engine estimate).

:class:`ThreeJSBRDF` is the direct-light shading of three's ``MeshPhysicalMaterial`` /
``MeshStandardMaterial`` (shader chunks ``lights_physical_fragment``,
``lights_fragment_begin`` and ``lights_physical_pars_fragment`` of three 0.187.0; L = wi,
V = wo, dot products clamped to [0, 1] as ``saturate`` does)::

    r   = min(max(roughness, 0.045) + g, 1),   α = r²            (g: geometry roughness, below)
    D   = α² / (π ((N·H)² (α² − 1) + 1)²)
    V   = 0.5 / (N·L √(α² + (1 − α²)(N·V)²) + N·V √(α² + (1 − α²)(N·L)²))   (height-correlated)
    F(f0, f90; x) = f0 + (f90 − f0) 2^((−5.55473 x − 6.98316) x)           (Epic's Schlick)
    f0_d = min(((ior − 1)/(ior + 1))² specularColor, 1) specularIntensity,  f90_d = specularIntensity
    f0 = mix(f0_d, baseColor, metallic),  f90 = mix(f90_d, 1, metallic)
    M   = 1 + f0 (1/E_ss(r, N·V) − 1)          (multiple-scattering compensation, Turquin 2019
                                                Eq. 16; E_ss = dfg.x + dfg.y of three's 16 × 16
                                                DFG table, bilinear, clamped to its edges)
    f   = F(f0, f90; V·H) D V M + (1 − F(f0_d, f90_d; V·H)) baseColor (1 − metallic) / π

and with ``KHR_materials_clearcoat`` (factor c, roughness r_c → max(r_c, 0.045) + g)::

    f ← f (1 − c F(0.04, 1; N·V)) + c F(0.04, 1; V·H) D_c V_c

A ``MeshStandardMaterial`` (a file without ``KHR_materials_*``) has f0_d = 0.04, f90_d = 1.
three clamps the diffuse colour to [0, 1] only in its EON diffuse (not used by glTF).

Geometry roughness ``g`` (``geometryRoughness``: the largest component of the screen-space
derivatives ``|dN/dx|``, ``|dN/dy|`` of the interpolated normal, per pixel of the render
target) is not a property of the material: :func:`shade_sphere` computes it per pixel from the
ray differentials of the sphere (``dP/dx = t (d_x − d (N·d_x)/(N·d))``, Igehy 1999; N = P on
the unit sphere) and passes it to :meth:`ThreeJSBRDF.eval_g`; :meth:`ThreeJSBRDF.eval` uses
g = 0. The GPU takes finite differences over 2 × 2 pixel quads; the analytic derivative is
the same to first order.

With Numba, :meth:`ThreeJSBRDF.eval_g` runs a compiled per-sample kernel
(``_threejs_kernel``: the NumPy path's operations in their order, its values to rounding).

``KHR_materials_anisotropy`` is not modelled (:func:`from_gltf` raises): our default fits are
isotropic, and the anisotropic lobe needs the mesh's tangent frame.

:func:`shade_sphere` renders a BRDF in ``sphere-distant`` / ``sphere-point`` by ray casting
the unit sphere at ``supersample``² pixel-centred samples per pixel (box average, as the
engine round trip does): radiance ``E (N·L) f(L, V)`` for the directional light (E = 3) and
``(I/d²)(N·L) f`` for the point light. For a punctual light this is what Mitsuba's ``direct``
integrator estimates (its BSDF sample never reaches a delta light), without Monte Carlo noise.
"""

from __future__ import annotations

import json
import math
import re
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..._jit import lazy_numba
from ...brdf import (IsotropicBRDF, _as_dirs, _dot3, _run_per_sample, _unit_half,
                     _visible_half_kernel)
from ..metrics import rendered_psnr
from ..render.scenes import CAMERA, DISTANT_LIGHT, POINT_LIGHT
from .threejs import EngineUnavailable, sphere_geometry_px, three_dir

__all__ = ["ThreeJSBRDF", "from_gltf", "dfg_lut", "CameraSphere", "SphereSamples",
           "shade_sphere", "estimate"]

_MIN_ROUGHNESS = 0.045
_numba = lazy_numba()


def _f_schlick_sg(f0, f90, x):
    """three's ``F_Schlick``: ``f0 + (f90 − f0) 2^((−5.55473 x − 6.98316) x)``."""
    return f0 + (f90 - f0) * np.exp2((-5.55473 * x - 6.98316) * x)


def _half_to_float(u16: np.ndarray) -> np.ndarray:
    return np.asarray(u16, np.uint16).view(np.float16).astype(np.float64)


@lru_cache(maxsize=2)
def dfg_lut(three: str | None = None) -> np.ndarray:
    """three's DFG table ``(16, 16, 2)`` (rows N·V, columns roughness; scale, bias), read from
    ``src/renderers/shaders/DFGLUTData.js`` of the installed ``three`` package."""
    if three is None:
        d = three_dir()
        if d is None:
            raise EngineUnavailable("needs the npm package three (`make npmdeps`) for its DFG table")
        three = str(d)
    text = (Path(three) / "src" / "renderers" / "shaders" / "DFGLUTData.js").read_text()
    m = re.search(r"new Uint16Array\(\s*\[(.*?)\]\s*\)", text, re.S)
    size = re.search(r"new DataTexture\(\s*DATA\s*,\s*(\d+)\s*,\s*(\d+)\s*,\s*RGFormat", text)
    if not m or not size:
        raise ValueError(f"{three}: DFGLUTData.js is not the 16 × 16 RG half-float table "
                         "expected (three 0.187)")
    w, h = int(size.group(1)), int(size.group(2))
    vals = [int(x, 16) for x in re.findall(r"0x([0-9a-fA-F]+)", m.group(1))]
    if len(vals) != w * h * 2:
        raise ValueError(f"{three}: DFG table has {len(vals)} values, expected {w * h * 2}")
    return _half_to_float(np.array(vals)).reshape(h, w, 2)


def _lut_bilinear(lut: np.ndarray, u, v) -> np.ndarray:
    """``texture2D(lut, (u, v))`` with linear filtering and clamp-to-edge: texel centres at
    (i + 0.5)/n."""
    h, w = lut.shape[:2]
    x = np.clip(np.asarray(u, float) * w - 0.5, 0.0, w - 1.0)
    y = np.clip(np.asarray(v, float) * h - 0.5, 0.0, h - 1.0)
    x0 = np.minimum(np.floor(x).astype(int), w - 2)
    y0 = np.minimum(np.floor(y).astype(int), h - 2)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    texels = lut.reshape(h * w, -1)
    i = y0 * w + x0

    def at(k):                                 # the texels at flat offset k from (y0, x0)
        return texels.take(i + k, axis=0)

    return ((at(0) * (1 - fx) + at(1) * fx) * (1 - fy) + (at(w) * (1 - fx) + at(w + 1) * fx) * fy)


def _fresnel_kernel(f0, f90, x, sg):  # pragma: no cover  (compiled by numba)
    """:meth:`ThreeJSBRDF._fresnel` of one value."""
    if sg:
        return f0 + (f90 - f0) * np.exp2((-5.55473 * x - 6.98316) * x)
    return f0 + (f90 - f0) * (1.0 - x) ** 5.0


def _dv_kernel(r, nl, nv, nh):  # pragma: no cover  (compiled by numba)
    """:meth:`ThreeJSBRDF._dv` of one sample."""
    a = r * r
    a2 = a * a
    d = a2 / (np.pi * (nh * nh * (a2 - 1.0) + 1.0) ** 2)
    gv = nl * np.sqrt(a2 + (1.0 - a2) * nv * nv)
    gl = nv * np.sqrt(a2 + (1.0 - a2) * nl * nl)
    return d * 0.5 / max(gv + gl, 1e-6)


def _ess_kernel(lut, u, v):  # pragma: no cover  (compiled by numba)
    """``dfg.x + dfg.y`` of :func:`_lut_bilinear` at one ``(u, v)``."""
    h, w = lut.shape[0], lut.shape[1]
    x = min(max(u * w - 0.5, 0.0), w - 1.0)
    y = min(max(v * h - 0.5, 0.0), h - 1.0)
    x0 = min(int(np.floor(x)), w - 2)
    y0 = min(int(np.floor(y)), h - 2)
    fx, fy = x - x0, y - y0
    ess = 0.0
    for c in range(2):
        ess += ((lut[y0, x0, c] * (1 - fx) + lut[y0, x0 + 1, c] * fx) * (1 - fy)
                + (lut[y0 + 1, x0, c] * (1 - fx) + lut[y0 + 1, x0 + 1, c] * fx) * fy)
    return ess


def _threejs_kernel(wi, wo, g, lut, flags, rough, base, metallic, f0_d, f90_d, coat,
                    out):  # pragma: no cover  (compiled by numba)
    """:meth:`ThreeJSBRDF.eval_g` per sample, its order of operations: ``flags`` = (sg
    Fresnel, 0.045 floor, multiscatter), ``rough`` = (roughness, coat roughness)."""
    sg, floor, ms = flags[0], flags[1], flags[2]
    for k in range(wi.shape[0]):
        visible, hx, hy, hz = _visible_half_kernel(wi, wo, k, out)
        if not visible:
            continue
        nl, nv = min(max(wi[k, 2], 0.0), 1.0), min(max(wo[k, 2], 0.0), 1.0)
        nh = min(max(hz, 0.0), 1.0)
        vh = min(max(wo[k, 0] * hx + wo[k, 1] * hy + wo[k, 2] * hz, 0.0), 1.0)
        r = min((max(rough[0], 0.045) if floor else rough[0]) + g[k], 1.0)
        dv = _dv_kernel(r, nl, nv, nh)
        ess = _ess_kernel(lut, r, nv) if ms else 1.0
        f90 = f90_d * (1 - metallic) + metallic
        fcc_v = cc = 0.0
        if coat > 0:
            rc = min((max(rough[1], 0.045) if floor else rough[1]) + g[k], 1.0)
            rc = max(rc, 0.045) if floor else rc
            fcc_v = _fresnel_kernel(0.04, 1.0, nv, sg)
            cc = _fresnel_kernel(0.04, 1.0, vh, sg) * _dv_kernel(rc, nl, nv, nh)
        for c in range(3):
            f0 = f0_d[c] * (1 - metallic) + base[c] * metallic
            spec = _fresnel_kernel(f0, f90, vh, sg) * dv
            if ms:
                spec = spec * (1.0 + f0 * (1.0 / ess - 1.0))
            f = spec + ((1.0 - _fresnel_kernel(f0_d[c], f90_d, vh, sg)) * base[c]
                        * (1.0 - metallic) / np.pi)
            if coat > 0:
                f = f * (1.0 - coat * fcc_v) + coat * cc
            out[k, c] = 0.0 if np.isnan(f) else min(max(f, -1.7976931348623157e308),
                                                    1.7976931348623157e308)


if _numba is not None:
    _inline = _numba.njit(cache=True, nogil=True, inline="always", error_model="numpy")
    _fresnel_kernel, _dv_kernel, _ess_kernel = (_inline(f) for f in (_fresnel_kernel,
                                                                     _dv_kernel, _ess_kernel))
    _threejs_kernel = _numba.njit(cache=True, nogil=True, error_model="numpy")(_threejs_kernel)


class ThreeJSBRDF(IsotropicBRDF):
    """three.js r187's direct-light BRDF of a glTF material (module docstring).

    ``physical``: ``MeshPhysicalMaterial`` (the file has ``KHR_materials_*``; ior and the
    specular factors apply) or ``MeshStandardMaterial`` (f0 = 0.04, f90 = 1).
    ``multiscatter`` / ``sg_fresnel`` / ``min_roughness`` switch three's departures from the
    glTF specification off (False: M = 1, ``(1 − x)⁵``, no 0.045 floor) to attribute the
    differences; ``lut``: the DFG table (default :func:`dfg_lut`).
    """

    def __init__(self, base_color, metallic: float = 1.0, roughness: float = 1.0,
                 ior: float = 1.5, specular_factor: float = 1.0, specular_color=(1.0, 1.0, 1.0),
                 clearcoat: float = 0.0, clearcoat_roughness: float = 0.0, physical: bool = True,
                 multiscatter: bool = True, sg_fresnel: bool = True, min_roughness: bool = True,
                 lut: np.ndarray | None = None, name: str = "threejs"):
        self.base_color = np.broadcast_to(np.asarray(base_color, float), (3,)).copy()
        self.specular_color = np.broadcast_to(np.asarray(specular_color, float), (3,)).copy()
        self.metallic, self.roughness = float(metallic), float(roughness)
        self.ior, self.specular_factor = float(ior), float(specular_factor)
        self.clearcoat, self.clearcoat_roughness = float(clearcoat), float(clearcoat_roughness)
        for nm, v in (("metallic", self.metallic), ("roughness", self.roughness),
                      ("specular_factor", self.specular_factor), ("clearcoat", self.clearcoat),
                      ("clearcoat_roughness", self.clearcoat_roughness)):
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"ThreeJSBRDF: {nm} must be in [0, 1], got {v}")
        if not (np.all(np.isfinite(self.base_color)) and np.all(self.base_color >= 0)
                and np.all(np.isfinite(self.specular_color)) and np.all(self.specular_color >= 0)):
            raise ValueError("ThreeJSBRDF: colours must be finite and >= 0")
        if not (math.isfinite(self.ior) and self.ior >= 1.0):
            raise ValueError(f"ThreeJSBRDF: ior must be finite and >= 1, got {ior}")
        self.physical, self.multiscatter = bool(physical), bool(multiscatter)
        self.sg_fresnel, self.min_roughness = bool(sg_fresnel), bool(min_roughness)
        self.lut = dfg_lut() if (lut is None and self.multiscatter) else lut
        self.name = name
        self.source = None

    def _fresnel(self, f0, f90, x):
        if self.sg_fresnel:
            return _f_schlick_sg(f0, f90, x)
        return f0 + (f90 - f0) * (1.0 - x) ** 5

    def dielectric_f0_f90(self) -> tuple[np.ndarray, float]:
        """``(f0_d, f90_d)``: ``material.specularColor`` and ``specularF90`` of a dielectric."""
        if not self.physical:
            return np.full(3, 0.04), 1.0
        f0 = ((self.ior - 1.0) / (self.ior + 1.0)) ** 2
        return np.minimum(f0 * self.specular_color, 1.0) * self.specular_factor, self.specular_factor

    def _rough(self, r, g):
        r = max(r, _MIN_ROUGHNESS) if self.min_roughness else r
        return np.minimum(r + g, 1.0)

    @staticmethod
    def _dv(r, nl, nv, nh):
        a = r * r
        a2 = a * a
        d = a2 / (np.pi * (nh * nh * (a2 - 1.0) + 1.0) ** 2)
        gv = nl * np.sqrt(a2 + (1.0 - a2) * nv * nv)
        gl = nv * np.sqrt(a2 + (1.0 - a2) * nl * nl)
        return d * 0.5 / np.maximum(gv + gl, 1e-6)

    def eval(self, wi, wo) -> np.ndarray:
        """``f`` with geometry roughness g = 0 (:meth:`eval_g`)."""
        return self.eval_g(wi, wo, 0.0)

    def eval_g(self, wi, wo, g) -> np.ndarray:
        """``f(wi = L, wo = V)`` with geometry roughness ``g`` (scalar or broadcastable to the
        directions' batch shape), ``(..., 3)``; 0 below the horizon."""
        wi, wo = _as_dirs(wi, wo)
        g = np.asarray(g, float)
        if _numba is not None and _threejs_kernel.worth_compiling(wi[..., 0].size):
            return self._eval_compiled(wi, wo, g)
        h = _unit_half(wi, wo)
        nl = np.clip(wi[..., 2], 0.0, 1.0)
        nv = np.clip(wo[..., 2], 0.0, 1.0)
        nh = np.clip(h[..., 2], 0.0, 1.0)
        vh = np.clip(_dot3(wo, h), 0.0, 1.0)
        r = self._rough(self.roughness, g)
        m = self.metallic
        f0_d, f90_d = self.dielectric_f0_f90()
        f0 = f0_d * (1 - m) + self.base_color * m
        f90 = f90_d * (1 - m) + m
        F = self._fresnel(f0, f90, vh[..., None])
        spec = F * self._dv(r, nl, nv, nh)[..., None]
        if self.multiscatter:
            dfg = _lut_bilinear(self.lut, np.broadcast_to(r, nv.shape), nv)
            ess = dfg[..., 0] + dfg[..., 1]
            spec = spec * (1.0 + f0 * (1.0 / ess - 1.0)[..., None])
        diff = ((1.0 - self._fresnel(f0_d, f90_d, vh[..., None]))
                * self.base_color * (1.0 - m) / np.pi)
        f = spec + diff
        if self.clearcoat > 0.0:
            rc = self._rough(self.clearcoat_roughness, g)
            rc = np.maximum(rc, _MIN_ROUGHNESS) if self.min_roughness else rc
            fcc_v = self._fresnel(0.04, 1.0, nv)[..., None]
            coat = self._fresnel(0.04, 1.0, vh) * self._dv(rc, nl, nv, nh)
            f = f * (1.0 - self.clearcoat * fcc_v) + self.clearcoat * coat[..., None]
        above = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        return np.where(above[..., None], np.nan_to_num(f), 0.0)

    def _eval_compiled(self, wi, wo, g) -> np.ndarray:
        """:meth:`eval_g` by :func:`_threejs_kernel` (the NumPy path's values to rounding)."""
        f0_d, f90_d = self.dielectric_f0_f90()
        g = np.array(np.broadcast_to(g, wi.shape[:-1]), dtype=float).reshape(-1)
        lut = np.ascontiguousarray(self.lut if self.multiscatter else np.zeros((2, 2, 2)),
                                   dtype=float)
        return _run_per_sample(
            _threejs_kernel, wi, wo, g, lut,
            np.array([self.sg_fresnel, self.min_roughness, self.multiscatter]),
            np.array([self.roughness, self.clearcoat_roughness]), self.base_color,
            self.metallic, np.asarray(f0_d, float), float(f90_d), self.clearcoat)

    def describe(self) -> dict:
        return {"base_color": self.base_color.tolist(), "metallic": self.metallic,
                "roughness": self.roughness, "ior": self.ior,
                "specular_factor": self.specular_factor,
                "specular_color": self.specular_color.tolist(), "clearcoat": self.clearcoat,
                "clearcoat_roughness": self.clearcoat_roughness, "physical": self.physical,
                "multiscatter": self.multiscatter, "sg_fresnel": self.sg_fresnel,
                "min_roughness": self.min_roughness}


def _number(x, what: str) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
        raise ValueError(f"glTF material: {what} must be a finite number, got {x!r}")
    return float(x)


def from_gltf(gltf, index: int = 0, **options) -> ThreeJSBRDF:
    """:class:`ThreeJSBRDF` of material ``index`` of a glTF file (path) or its parsed JSON
    (dict), with the glTF defaults (baseColorFactor 1, metallicFactor 1, roughnessFactor 1,
    ior 1.5, specular factors 1) and the parameters as three's ``GLTFLoader`` sets them;
    ``options`` go to :class:`ThreeJSBRDF`. Textures are not read."""
    doc = json.loads(Path(gltf).read_text()) if not isinstance(gltf, dict) else gltf
    mats = doc.get("materials") if isinstance(doc, dict) else None
    if not isinstance(mats, list) or not 0 <= int(index) < len(mats):
        raise ValueError(f"glTF: expected a material {index} in 'materials', found "
                         f"{len(mats) if isinstance(mats, list) else 'none'}")
    mat = mats[int(index)]
    pbr = mat.get("pbrMetallicRoughness", {})
    ext = mat.get("extensions", {}) or {}
    if "KHR_materials_anisotropy" in ext:
        raise ValueError("glTF material: KHR_materials_anisotropy is not modelled by ThreeJSBRDF")
    base = [_number(v, "baseColorFactor") for v in pbr.get("baseColorFactor", [1, 1, 1, 1])[:3]]
    spec = ext.get("KHR_materials_specular", {})
    coat = ext.get("KHR_materials_clearcoat", {})
    return ThreeJSBRDF(
        base, _number(pbr.get("metallicFactor", 1.0), "metallicFactor"),
        _number(pbr.get("roughnessFactor", 1.0), "roughnessFactor"),
        ior=_number(ext.get("KHR_materials_ior", {}).get("ior", 1.5), "ior"),
        specular_factor=_number(spec.get("specularFactor", 1.0), "specularFactor"),
        specular_color=[_number(v, "specularColorFactor")
                        for v in spec.get("specularColorFactor", [1, 1, 1])],
        clearcoat=_number(coat.get("clearcoatFactor", 0.0), "clearcoatFactor"),
        clearcoat_roughness=_number(coat.get("clearcoatRoughnessFactor", 0.0),
                                    "clearcoatRoughnessFactor"),
        physical=any(k.startswith("KHR_materials_") for k in ext),
        name=str(mat.get("name", "threejs")), **options)


def _basis(n):
    """Orthonormal tangent frames (Duff et al. 2017) for unit normals ``(..., 3)``."""
    s = np.where(n[..., 2] >= 0, 1.0, -1.0)
    a = -1.0 / (s + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    t = np.stack([1 + s * n[..., 0] ** 2 * a, s * b, -s * n[..., 0]], -1)
    bt = np.stack([b, s + n[..., 1] ** 2 * a, -n[..., 1]], -1)
    return t, bt


class CameraSphere:
    """The unit sphere of our sphere scenes seen by their camera (``CAMERA``) at
    ``resolution``² pixels of ``supersample``² pixel-centred samples: per sample of the
    ``resolution × supersample`` grid (row 0 on top) whether it hits (``hit``), the hit point
    ``P``, the normal ``N`` (= P) and the direction to the camera ``V``, world frame."""

    def __init__(self, resolution: int, supersample: int):
        n = int(resolution) * int(supersample)
        t = math.tan(math.radians(CAMERA["fov_degrees"]) / 2.0)
        c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
        X, Y = np.meshgrid(c * t, -c * t)                      # +x right, +y up, row 0 on top
        d = np.stack([X, Y, -np.ones_like(X)], -1)             # unnormalised ray directions
        o = np.array(CAMERA["origin"], dtype=float)
        # |o + s d|² = 1
        A = np.sum(d * d, -1)
        B = 2.0 * (d @ o)
        C = float(o @ o) - 1.0
        disc = B * B - 4 * A * C
        self.hit = disc > 0
        self.s = np.where(self.hit, (-B - np.sqrt(np.maximum(disc, 0.0))) / (2 * A), 0.0)
        self.P = o + self.s[..., None] * d
        self.N = self.P / np.maximum(np.linalg.norm(self.P, axis=-1, keepdims=True), 1e-300)
        self.V = -d / np.sqrt(A)[..., None]
        self._d, self._step = d, 2 * t / n
        self.resolution, self.supersample = int(resolution), int(supersample)

    def average(self, values: np.ndarray, where: np.ndarray | None = None):
        """``(image (H, W, 3), alpha (H, W))``: ``values`` ``(K, 3)`` of the samples ``where``
        (default: every sample that hits) box-averaged over each pixel's samples (the others
        black); alpha the share of hits."""
        where = self.hit if where is None else where
        r, k = self.resolution, self.supersample
        img = np.zeros(where.shape + (3,))
        img[where] = values
        return (img.reshape(r, k, r, k, 3).mean(axis=(1, 3)),
                self.hit.reshape(r, k, r, k).mean(axis=(1, 3)))

    def geometry_roughness(self) -> np.ndarray:
        """three's ``geometryRoughness`` per sample (module docstring): the largest component
        of ``|dN/dx|``, ``|dN/dy|`` from the ray differentials ``d_x = (2t/n, 0, 0)``."""
        N, d, s = self.N, self._d, self.s
        ndot = np.sum(N * d, -1)
        g = np.zeros(N.shape[:2])
        for dx in (np.array([self._step, 0.0, 0.0]), np.array([0.0, -self._step, 0.0])):
            dP = s[..., None] * (dx - d * ((N @ dx) / np.where(ndot == 0, -1e-300, ndot))[..., None])
            g = np.maximum(g, np.max(np.abs(dP), -1))
        return g


class SphereSamples:
    """The ``supersample``² pixel-centred samples per pixel of the unit sphere of ``scene``
    (``sphere-distant`` or ``sphere-point``, module docstring) at ``resolution``²: the
    directions ``wi``, ``wo`` (local frames) and the factor ``E (N·L)`` of every sample that
    sees the light, for :meth:`shade`; computed once, so that many BRDFs can be shaded
    (:func:`shade_sphere`, :func:`brdffit.export.gltf.optimize_for_engines`). With
    ``geometry_roughness`` also three's per-pixel geometry roughness ``g`` of the
    ``resolution × supersample`` render target (``None`` otherwise)."""

    def __init__(self, scene: str = "sphere-distant", resolution: int = 128,
                 supersample: int = 4, geometry_roughness: bool = False):
        if scene not in ("sphere-distant", "sphere-point"):
            raise ValueError(f"shade_sphere: expected sphere-distant or sphere-point, got {scene!r}")
        if int(resolution) < 1 or int(supersample) < 1:
            raise ValueError("shade_sphere: resolution and supersample must be ≥ 1")
        self.resolution, self.supersample = int(resolution), int(supersample)
        cam = CameraSphere(self.resolution, self.supersample)
        P, N, Vw, hit = cam.P, cam.N, cam.V, cam.hit
        if scene == "sphere-distant":
            Lw = -np.asarray(DISTANT_LIGHT["direction"], float)
            Lw = np.broadcast_to(Lw / np.linalg.norm(Lw), P.shape)
            E = np.full(P.shape[:2], float(DISTANT_LIGHT["irradiance"]))
        else:
            Lv = np.asarray(POINT_LIGHT["position"], float) - P
            dist2 = np.sum(Lv * Lv, -1)
            Lw = Lv / np.sqrt(dist2)[..., None]
            E = float(POINT_LIGHT["intensity"]) / dist2
        T, Bt = _basis(N)

        def local(w):
            return np.stack([np.sum(w * T, -1), np.sum(w * Bt, -1), np.sum(w * N, -1)], -1)

        wi, wo = local(Lw), local(Vw)
        m = hit & (wi[..., 2] > 0) & (wo[..., 2] > 0)
        self.lit, self.hit, self._cam = m, hit, cam
        self.wi, self.wo = wi[m], wo[m]
        self.weight = E[m] * self.wi[:, 2]
        self.g = cam.geometry_roughness()[m] if geometry_roughness else None
        rows, cols = np.nonzero(m)
        k = self.supersample
        self._pixel = (rows // k) * self.resolution + cols // k     # of each lit sample
        self._subset = (None, None)                                 # of :meth:`_samples_of`

    def shade(self, brdf, geometry_roughness: bool = False):
        """``(image (H, W, 3), alpha (H, W))`` of ``brdf`` (box average of the samples);
        ``geometry_roughness`` passes ``g`` to ``brdf.eval_g`` (the samples must have it)."""
        if geometry_roughness and self.g is None:
            raise ValueError("SphereSamples.shade: built without geometry_roughness")
        f = brdf.eval_g(self.wi, self.wo, self.g) if geometry_roughness else \
            brdf.eval(self.wi, self.wo)
        return self._cam.average(self.weight[:, None] * f, self.lit)

    def pixel_means(self, brdf, pixels: np.ndarray) -> np.ndarray:
        """The values ``(K, 3)`` of the K pixels ``pixels`` (``(H, W)`` bool) of
        :meth:`shade`'s image of ``brdf`` (g = 0), from the samples of those pixels only,
        summed per pixel in their order (the image's to rounding)."""
        wi, wo, weight, pixel = self._samples_of(pixels)
        f = weight[:, None] * brdf.eval(wi, wo)
        n, k2 = self.resolution**2, self.supersample**2
        sums = np.stack([np.bincount(pixel, f[:, c], n) for c in range(3)], -1)
        return sums[pixels.ravel()] / k2

    def _samples_of(self, pixels: np.ndarray) -> tuple:
        """``(wi, wo, weight, pixel)`` of the lit samples in ``pixels`` (the last kept)."""
        key = np.asarray(pixels, bool).tobytes()
        if self._subset[0] != key:
            take = pixels.ravel()[self._pixel]
            self._subset = (key, (self.wi[take], self.wo[take], self.weight[take],
                                  self._pixel[take]))
        return self._subset[1]


def shade_sphere(brdf, scene: str = "sphere-distant", resolution: int = 128,
                 supersample: int = 4, geometry_roughness: bool | None = None):
    """Noise-free render of ``brdf`` on the unit sphere of ``scene`` (module docstring):
    ``(image (H, W, 3) float64, alpha (H, W))``. ``geometry_roughness`` (default: whether the
    BRDF has ``eval_g``) passes three's per-pixel geometry roughness of the
    ``resolution × supersample`` render target to ``brdf.eval_g``."""
    if geometry_roughness is None:
        geometry_roughness = hasattr(brdf, "eval_g")
    return SphereSamples(scene, resolution, supersample,
                         geometry_roughness).shade(brdf, geometry_roughness)


def estimate(fit, gltf, scene: str = "sphere-distant", resolution: int = 128,
             supersample: int = 8, index: int = 0, rim: float = 0.85) -> dict:
    """The cheap estimate of the three.js round trip, without a browser or Monte Carlo:
    :class:`ThreeJSBRDF` of material ``index`` of ``gltf`` on three's sample grid
    (``supersample``², geometry roughness per pixel) against ``fit`` converged (16 × 16
    samples per pixel at least), both through :func:`shade_sphere`. Returns ``psnr`` (Bagher
    2016 §5, the fit as reference), ``mean_ratio`` and ``rim_ratio`` (RGB, model / fit over
    the fully covered pixels and those beyond ``rim`` R). Measured against the engine
    (``bench/bench_engines_threejs.py``): within 0.7 dB of three's PSNR against the
    converged fit on 11 materials (mean +0.09 dB). The map scenes:
    :func:`~brdffit.evaluation.engines.threejs_ibl.estimate_env`."""
    model = from_gltf(gltf, index)
    img, alpha = shade_sphere(model, scene, resolution, supersample)
    ref, ref_alpha = shade_sphere(fit, scene, resolution, max(16, int(supersample)),
                                  geometry_roughness=False)
    mask = (alpha >= 0.999) & (ref_alpha >= 0.999)
    cx, cy, R = sphere_geometry_px(resolution)
    yy, xx = np.mgrid[0:resolution, 0:resolution] + 0.5
    rim_m = mask & (np.hypot(xx - cx, yy - cy) > rim * R)

    def ratio(m):
        return (img[m].sum(0) / np.maximum(ref[m].sum(0), 1e-300)).tolist()

    return {"psnr": rendered_psnr(ref, img, mask), "mean_ratio": ratio(mask),
            "rim_ratio": ratio(rim_m), "model": model.describe()}
