"""What three.js r187 renders for a glTF material lit by an environment map: its PMREM and
split-sum shading, noise-free in NumPy (the cheap estimate of the three.js round trip in the
map scenes ``sphere-env`` and ``sphere-<map>``).

**PMREM** (``PMREMGenerator.fromEquirectangular``, ``src/extras/PMREMGenerator.js`` of three
0.187.0), :class:`PMREM`:

* the source cube: face size S = max(256, 2^⌊log2(width/4)⌋), each texel the mean of four
  bilinear reads of the map at ± ¼ texel; its mip chain by 2 × 2 box filtering
  (``generateMipmap``);
* PMREM levels ``lod`` = 0 … M, M = log2 S − 3, faces S/2^lod, prefiltered for roughness
  ``r(lod) = 1 − √(1 − lod/M)`` with V = N:

  - lod 0: the source (a mirror);
  - the sharp levels (lod ≤ M − 3): 256 Hammersley samples of the GGX lobe of α = r²
    around N (``N·L = (1 − ξ − α²ξ)/(1 − ξ + α²ξ)``, ``sin θ = 2α√(ξ(1 − ξ))/(1 − ξ + α²ξ)``),
    each read trilinearly from the source mip of its solid angle,
    ``lod_s = max(log2(α² / (1 − ξ + α²ξ)) + log2 S + ½ log2(6 / (256 r⁴)) + ½, 0)``,
    weighted by N·L;
  - the rough levels (the last three): every texel of the source's 16² mip, the texel in
    N's hemisphere of each opposite pair, weight ``N·L dω / (1 + α² + (α² − 1) N·L)²``
    (GGX D of the half vector with V = N, times N·L and the texel's solid angle);

**Shading** (``lights_physical_fragment``, ``envmap_physical_pars_fragment``,
``RE_IndirectSpecular_Physical``, ``computeMultiscattering`` of
``lights_physical_pars_fragment``; Fdez-Agüera 2019 for the multiple scattering), per sample
of the pixel with roughness ``r = min(max(roughness, 0.045) + g, 1)`` (g: geometry roughness,
:class:`~brdffit.evaluation.engines.threejs_brdf.CameraSphere`)::

    R' = normalize(mix(reflect(−V, N), N, r⁴))
    L_r = PMREM(R', M r (2 − r))     (trilinear between levels)     E/π = PMREM(N, M)
    (a, b) = DFG(r, N·V)                                            (three's 16 × 16 table)
    ss(f0, f90) = f0 a + f90 b,  Ess = a + b,  F̄ = f0 + (1 − f0)/21
    ms(f0, f90) = ss F̄ / (1 − (1 − Ess) F̄) (1 − Ess)
    f90 = mix(specularFactor, 1, metallic)
    L = L_r mix(ss(f0_d), ss(base), m) + E/π [mix(ms(f0_d), ms(base), m)
        + base (1 − m)(1 − ss(f0_d) − ms(f0_d))]

and with a clear coat (factor c, roughness r_c, ``F_cc = F(0.04, 1; N·V)``)::

    L ← L (1 − c F_cc) + c PMREM(R'_c, M r_c (2 − r_c)) (0.04 a_c + b_c)

Departures, each a fraction of a dB on our spheres: the cube is sampled with clamp-to-edge
filtering per face (WebGL 2's seamless filtering blends across the seam), in float64 (three
stores half floats); the sphere is the analytic one (three renders a 256 × 128 UV sphere).
The map is the page's own texture (:func:`~brdffit.evaluation.engines.threejs.environment_rgba`,
half floats), read in Mitsuba's lat-long convention, which the page's orientation matches.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from .threejs import compare_render, environment_rgba, resolve_scene
from .threejs_brdf import CameraSphere, ThreeJSBRDF, _lut_bilinear, from_gltf

__all__ = ["PMREM", "pmrem", "shade_ibl", "shade_sphere_env", "estimate_env", "latlong_uv",
           "latlong_bilinear", "map_of_scene", "estimate_figures"]

MIN_SIZE = 256
LOD_MIN = 3
GGX_SAMPLES = 256
INTEGRATION_SIZE = 16
INTEGRATION_LEVELS = 3


def _face_dirs(n: int) -> np.ndarray:
    """Unnormalised texel-centre directions ``(6, n, n, 3)`` of a cube of face ``n``: face
    ``2a + (sign < 0)`` has axis ``a`` = ±1 and the next two axes (cyclic) = the texel's
    (u, v) in [−1, 1]."""
    c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    V, U = np.meshgrid(c, c, indexing="ij")               # [row v, column u]
    out = np.empty((6, n, n, 3))
    for f in range(6):
        a, sgn = f // 2, (1.0 if f % 2 == 0 else -1.0)
        out[f, ..., a] = sgn
        out[f, ..., (a + 1) % 3] = U
        out[f, ..., (a + 2) % 3] = V
    return out


def _face_uv(d: np.ndarray):
    """Face and (u, v) ∈ [−1, 1]² of directions ``d`` on the cube of :func:`_face_dirs`."""
    a = np.argmax(np.abs(d), axis=-1)
    rows = np.arange(a.size)
    flat = d.reshape(-1, 3)
    a1 = a.reshape(-1)
    major = flat[rows, a1]
    inv = 1.0 / np.maximum(np.abs(major), 1e-300)
    u = flat[rows, (a1 + 1) % 3] * inv
    v = flat[rows, (a1 + 2) % 3] * inv
    return (2 * a1 + (major < 0)).reshape(a.shape), u.reshape(a.shape), v.reshape(a.shape)


def _bilinear_cube(level: np.ndarray, face, u, v) -> np.ndarray:
    """``level`` ``(6, n, n, 3)`` read bilinearly at (face, u, v), clamped to the face's
    edge (texel centres at (i + ½)/n)."""
    n = level.shape[1]
    flat = level.reshape(-1, 3)
    if n == 1:
        return flat[face]
    x = np.clip((u + 1.0) * (0.5 * n) - 0.5, 0.0, n - 1.0)
    y = np.clip((v + 1.0) * (0.5 * n) - 0.5, 0.0, n - 1.0)
    x0 = np.minimum(x.astype(np.intp), n - 2)
    y0 = np.minimum(y.astype(np.intp), n - 2)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    base = (face * n + y0) * n + x0
    top = flat[base] + (flat[base + 1] - flat[base]) * fx
    bottom = flat[base + n] + (flat[base + n + 1] - flat[base + n]) * fx
    return top + (bottom - top) * fy


def _trilinear(levels: list[np.ndarray], d: np.ndarray, lod) -> np.ndarray:
    """``textureLod(cube, d, lod)`` with linear filtering between mip levels."""
    face, u, v = _face_uv(d)
    top = len(levels) - 1.0
    if np.ndim(lod) == 0:                       # one level pair for every direction
        lod = min(max(float(lod), 0.0), top)
        k = int(lod)
        c = _bilinear_cube(levels[k], face, u, v)
        if k < top and lod > k:
            c = c + (_bilinear_cube(levels[k + 1], face, u, v) - c) * (lod - k)
        return c
    lod = np.clip(np.broadcast_to(np.asarray(lod, float), d.shape[:-1]), 0.0, top)
    lo = np.floor(lod).astype(int)
    out = np.zeros(d.shape[:-1] + (3,))
    for k in np.unique(lo):
        m = lo == k
        c = _bilinear_cube(levels[k], face[m], u[m], v[m])
        if k < top:
            t = (lod[m] - k)[:, None]
            c = c + (_bilinear_cube(levels[k + 1], face[m], u[m], v[m]) - c) * t
        out[m] = c
    return out


def latlong_uv(d: np.ndarray):
    """``(u, v)`` of unit directions in Mitsuba's lat-long convention (row 0 at +y,
    ``u = atan2(x, −z)/2π`` in [0, 1), ``v = ½ − asin(y)/π``)."""
    u = np.arctan2(d[..., 0], -d[..., 2]) / (2 * np.pi) % 1.0
    return u, 0.5 - np.arcsin(np.clip(d[..., 1], -1.0, 1.0)) / np.pi


def latlong_bilinear(img: np.ndarray, u, v) -> np.ndarray:
    """Bilinear read of a lat-long map ``(H, W, 3)`` at ``(u, v)`` (texel centres at
    (i + ½)/n), repeating in u and clamped in v, as a WebGL texture with ``RepeatWrapping``
    / ``ClampToEdgeWrapping`` and linear filtering reads it."""
    h, w = img.shape[:2]
    x = np.asarray(u) * w - 0.5
    y = np.clip(np.asarray(v) * h - 0.5, 0.0, h - 1.0)
    x0 = np.floor(x).astype(np.intp)
    y0 = np.floor(y).astype(np.intp)
    y1 = np.minimum(y0 + 1, h - 1)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    x0, x1 = x0 % w, (x0 + 1) % w
    top = img[y0, x0] + (img[y0, x1] - img[y0, x0]) * fx
    bottom = img[y1, x0] + (img[y1, x1] - img[y1, x0]) * fx
    return top + (bottom - top) * fy


def _source_cube(img: np.ndarray, size: int) -> list[np.ndarray]:
    """The source cube of face ``size`` (four reads per texel at ± ¼ texel) and its box-filtered
    mip chain down to 1 × 1."""
    q = 0.5 / size                                      # ¼ texel in (u, v) ∈ [−1, 1]
    base = _face_dirs(size)
    acc = np.zeros(base.shape)
    for du, dv in ((-q, -q), (q, -q), (-q, q), (q, q)):
        d = base.copy()
        for f in range(6):
            a = f // 2
            d[f, ..., (a + 1) % 3] += du
            d[f, ..., (a + 2) % 3] += dv
        acc += latlong_bilinear(img, *latlong_uv(d / np.linalg.norm(d, axis=-1, keepdims=True)))
    chain = [acc / 4.0]
    while chain[-1].shape[1] > 1:
        c = chain[-1]
        chain.append(0.25 * (c[:, 0::2, 0::2] + c[:, 1::2, 0::2] + c[:, 0::2, 1::2]
                             + c[:, 1::2, 1::2]))
    return chain


def _radical_inverse(i: np.ndarray) -> np.ndarray:
    bits = i.astype(np.uint32)
    bits = (bits << np.uint32(16)) | (bits >> np.uint32(16))
    for shift, mask in ((1, 0x55555555), (2, 0x33333333), (4, 0x0F0F0F0F), (8, 0x00FF00FF)):
        m = np.uint32(mask)
        bits = ((bits & m) << np.uint32(shift)) | ((bits & ~m) >> np.uint32(shift))
    return bits.astype(np.float64) * 2.3283064365386963e-10


def _tangent_frame(N: np.ndarray):
    """The shader's frame: ``up`` = +z (or +x near the poles), T = up × N / |…|, B = N × T."""
    up = np.where((np.abs(N[..., 2]) < 0.999)[..., None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    T = np.cross(up, N)
    T /= np.linalg.norm(T, axis=-1, keepdims=True)
    return T, np.cross(N, T)


def _ggx_level(chain: list[np.ndarray], n: int, roughness: float) -> np.ndarray:
    """A sharp PMREM level of face ``n``: 256 VNDF samples per texel (module docstring)."""
    size = chain[0].shape[1]
    N = _face_dirs(n)
    N /= np.linalg.norm(N, axis=-1, keepdims=True)
    T, B = _tangent_frame(N)
    alpha = roughness * roughness
    a2 = alpha * alpha
    bias = math.log2(size) + 0.5 * math.log2(6.0 / (GGX_SAMPLES * roughness ** 4)) + 0.5
    xs = np.arange(GGX_SAMPLES) / GGX_SAMPLES
    ys = _radical_inverse(np.arange(GGX_SAMPLES))
    acc, total = np.zeros(N.shape), 0.0
    for x, y in zip(xs, ys):
        inv_q = 1.0 / (1.0 - x + a2 * x)
        nl = (1.0 - x - a2 * x) * inv_q
        if nl <= 0.0:
            continue
        phi = 2.0 * np.pi * y
        sin_t = 2.0 * alpha * math.sqrt(x * (1.0 - x)) * inv_q
        L = N * nl + (T * math.cos(phi) + B * math.sin(phi)) * sin_t
        lod = max(math.log2(a2 * inv_q) + bias, 0.0)
        acc += _trilinear(chain, L, lod) * nl
        total += nl
    return acc / total


def _integration_level(chain: list[np.ndarray], n: int, roughness: float) -> np.ndarray:
    """A rough PMREM level of face ``n``: the 16² source mip integrated (module docstring)."""
    src = chain[int(round(math.log2(chain[0].shape[1] / INTEGRATION_SIZE)))]
    dirs = _face_dirs(INTEGRATION_SIZE)[0::2].reshape(-1, 3)    # the three + faces
    inv_dist = 1.0 / np.linalg.norm(dirs, axis=-1)
    plus = src[0::2].reshape(-1, 3)
    minus = src[1::2][:, ::-1, ::-1].reshape(-1, 3)             # the opposite texels
    a2 = roughness ** 4
    N = _face_dirs(n).reshape(-1, 3)
    N /= np.linalg.norm(N, axis=-1, keepdims=True)
    out = np.empty(N.shape)
    for s in range(0, len(N), 4096):
        nl = N[s:s + 4096] @ dirs.T
        front = nl >= 0.0
        nl = np.abs(nl) * inv_dist
        d = 1.0 + a2 + (a2 - 1.0) * nl
        w = nl * inv_dist ** 3 / (d * d)
        out[s:s + 4096] = ((w * front) @ plus + (w * ~front) @ minus) / w.sum(-1, keepdims=True)
    return out.reshape(6, n, n, 3)


class PMREM:
    """three's PMREM of an equirectangular map (module docstring): ``levels[lod]`` ``(6, n, n,
    3)``, ``roughness[lod]``, ``max_lod`` M; :meth:`read` is ``textureLod`` of the result."""

    def __init__(self, img: np.ndarray):
        img = np.asarray(img, float)
        if img.ndim != 3 or img.shape[2] != 3 or img.shape[1] < 8:
            raise ValueError(f"PMREM: expected an (H, W, 3) lat-long map, got {img.shape}")
        size = max(MIN_SIZE, 2 ** int(math.floor(math.log2(img.shape[1] / 4))))
        chain = _source_cube(img, size)
        self.max_lod = int(math.log2(size)) - LOD_MIN
        self.roughness = [1.0 - math.sqrt(1.0 - lod / self.max_lod)
                          for lod in range(self.max_lod + 1)]
        self.levels = [chain[0]]
        for lod in range(1, self.max_lod + 1):
            n, r = size >> lod, self.roughness[lod]
            if lod > self.max_lod - INTEGRATION_LEVELS:
                self.levels.append(_integration_level(chain, n, r))
            else:
                self.levels.append(_ggx_level(chain, n, r))

    def read(self, d: np.ndarray, lod) -> np.ndarray:
        """``textureLod(pmrem, d, lod)``: trilinear across the PMREM's levels."""
        return _trilinear(self.levels, d, lod)

    def mip(self, roughness) -> np.ndarray:
        """three's ``roughnessToMip``: ``M r (2 − r)``, r clamped to [0, 1]."""
        r = np.clip(roughness, 0.0, 1.0)
        return self.max_lod * r * (2.0 - r)


@lru_cache(maxsize=4)
def pmrem(envmap: str | None) -> PMREM:
    """The PMREM three builds of the map of ``sphere-<envmap>`` (``None``: ``sphere-env``'s
    procedural map), from the page's own half-float texture; cached per map."""
    data, w, h = environment_rgba(envmap, convention="mitsuba")
    img = np.frombuffer(data, "<f2").reshape(h, w, 4)[..., :3].astype(np.float64)
    return PMREM(img)


def _multiscatter(fab, f0, f90):
    """``computeMultiscattering``: ``(single, multi)`` (module docstring)."""
    a, b = fab[..., 0:1], fab[..., 1:2]
    ss = f0 * a + f90 * b
    ems = 1.0 - (a + b)
    favg = f0 + (1.0 - f0) / 21.0
    return ss, ss * favg / (1.0 - ems * favg) * ems


def _radiance(env: PMREM, N, V, nv, r):
    """``getIBLRadiance``: the PMREM along the reflection bent toward N by r⁴."""
    R = 2.0 * nv[:, None] * N - V
    R = R + (N - R) * (r ** 4)[:, None]
    R /= np.linalg.norm(R, axis=-1, keepdims=True)
    return env.read(R, env.mip(r))


def shade_ibl(model: ThreeJSBRDF, env: PMREM, N: np.ndarray, V: np.ndarray,
              g: np.ndarray) -> np.ndarray:
    """Radiance ``(K, 3)`` three shades at K surface samples (normals ``N``, directions to the
    camera ``V``, geometry roughness ``g``), world frame (module docstring)."""
    nv = np.clip(np.sum(N * V, -1), 0.0, 1.0)
    r = np.broadcast_to(model._rough(model.roughness, g), nv.shape)
    fab = _lut_bilinear(model.lut, r, nv)
    m = model.metallic
    f0_d, f90_spec = model.dielectric_f0_f90()
    f90 = f90_spec * (1.0 - m) + m
    ss_d, ms_d = _multiscatter(fab, f0_d, f90)
    ss_m, ms_m = _multiscatter(fab, model.base_color, f90)
    e_over_pi = env.read(N, env.max_lod)
    out = (_radiance(env, N, V, nv, r) * (ss_d * (1 - m) + ss_m * m)
           + e_over_pi * (ms_d * (1 - m) + ms_m * m
                          + model.base_color * (1 - m) * (1.0 - ss_d - ms_d)))
    if model.clearcoat > 0.0:
        rc = np.broadcast_to(model._rough(model.clearcoat_roughness, g), nv.shape)
        fab_c = _lut_bilinear(model.lut, rc, nv)
        f_cc = model._fresnel(0.04, 1.0, nv)[:, None]
        coat = _radiance(env, N, V, nv, rc) * (0.04 * fab_c[:, 0:1] + fab_c[:, 1:2])
        out = out * (1.0 - model.clearcoat * f_cc) + model.clearcoat * coat
    return out


def shade_sphere_env(model: ThreeJSBRDF, envmap: str | None = None, resolution: int = 96,
                     supersample: int = 4):
    """Noise-free three.js render of ``model`` on the unit sphere of ``sphere-<envmap>``
    (``None``: ``sphere-env``): ``(image (H, W, 3), alpha (H, W))``, ``supersample``²
    pixel-centred samples per pixel, box averaged, as the round trip renders it."""
    cam = CameraSphere(resolution, supersample)
    hit = cam.hit
    return cam.average(shade_ibl(model, pmrem(envmap), cam.N[hit], cam.V[hit],
                                 cam.geometry_roughness()[hit]))


def estimate_env(gltf, ref_stack, ref_alpha, scene: str = "sphere-env", supersample: int = 4,
                 index: int = 0, rim: float = 0.85) -> dict:
    """The cheap estimate of the three.js round trip in a map scene (``sphere-env`` or
    ``sphere-<map>``), without a browser: :func:`shade_sphere_env` of
    :func:`~brdffit.evaluation.engines.threejs_brdf.from_gltf` of material ``index`` of
    ``gltf``, compared with our render of the fit (``ref_stack`` (K, H, W, 3), ``ref_alpha``:
    :func:`~brdffit.evaluation.engines.threejs.reference_renders`) as the engine's render is
    (:func:`~brdffit.evaluation.engines.threejs.compare_render`). Returns ``psnr``,
    ``psnr_se``, ``mean_ratio``, ``rim_ratio``, the ``model`` and its ``image`` and
    ``alpha``."""
    envmap = map_of_scene(scene, "estimate_env")
    model = from_gltf(gltf, index)
    img, alpha = shade_sphere_env(model, envmap, np.shape(ref_alpha)[1], supersample)
    return estimate_figures(img, alpha, ref_stack, ref_alpha, rim) | {
        "model": model.describe()}


def map_of_scene(scene: str, what: str) -> str | None:
    """The map of a map scene (``None``: ``sphere-env``'s procedural one); ``what`` names the
    caller in the error a scene without a map gives."""
    base, envmap = resolve_scene(scene)
    if base != "sphere-env":
        raise ValueError(f"{what}: expected sphere-env or sphere-<map>, got {scene!r}")
    return envmap


def estimate_figures(img, alpha, ref_stack, ref_alpha, rim: float = 0.85) -> dict:
    """An estimate's image against our render of the fit, as an engine's render is compared
    (:func:`~brdffit.evaluation.engines.threejs.compare_render`): ``psnr``, ``psnr_se``,
    ``mean_ratio``, ``rim_ratio``, and the ``image`` and ``alpha``."""
    c = compare_render(img, alpha, ref_stack, ref_alpha, rim)
    return {k: c[k] for k in ("psnr", "psnr_se", "mean_ratio", "rim_ratio")} | {
        "image": img, "alpha": alpha}
