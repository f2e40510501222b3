"""Scenes for judging BRDF fits: Mitsuba scene dicts with a fixed camera and sampler.

Every scene function takes the BSDF object (from :func:`.plugin.make_bsdf`) and returns a
dict for ``mi.load_dict``; reference and fits rendered with the same scene name, resolution,
spp and seed see the same camera rays and sample streams (Mitsuba's ``independent`` sampler
seeded per render; the plugin always consumes the same sample dimensions).

Scenes (:data:`SCENES`)
-----------------------
``sphere-env``    unit sphere under an HDR environment map

``sphere-point``  unit sphere lit by one point light (no environment: black background)
``sphere-distant`` unit sphere lit by one directional light
``knot``          a (2, 3) torus knot tube (NumPy mesh, concavities) under the environment,
                  max depth 4 for interreflections
``sphere-svrough`` the sphere with a spatially varying roughness texture (Dupuy 2015
                  Fig. 1/4): the plugin scales the distribution's α per texel (Eq. 9) with
                  :func:`roughness_texture`

The sphere scenes use Mitsuba's ``direct`` integrator (one emitter sample and one BSDF
sample per spp, combined by MIS with the power heuristic), which for a convex object equals
``path`` with max depth 2 at ~20 % less cost; the knot uses ``path`` (max depth 4, no
Russian roulette before depth 100) for interreflections. Emitters are hidden
(``hide_emitters``): the background is black and the film's alpha is the object's coverage.

Environment maps: ``envmap=None`` uses :func:`procedural_envmap` (the project's own, no
external data); a name (``"studio"``) picks ``../shared/data/envmaps/<name>.exr``; a path
loads that EXR. Maps are clamped at 0 (the CC0 maps have small negative values). A scene
name may carry its map: ``sphere-<map>`` / ``knot-<map>`` (e.g. ``sphere-sunrise``).

The paper's scene suite (Bagher, Snyder, Nowrouzezahrai 2016 §5)
----------------------------------------------------------------
The NPF paper scores every material on four scenes: a sphere in three HDR light probes of
different character (Grace, Ennis, St. Peter's) and a mesh (the Stanford Buddha) in two of
them, and reports the PSNR of each scene and their mean. :data:`SUITES` ``["paper"]`` is our
equivalent with the CC0 maps of ``../shared/data/envmaps`` (:func:`scene_suite`):

=====================  ==================================================================
``sphere-courtyard``   low dynamic range: a covered courtyard, soft light, no sun
                       (luminance max/median 1.0e3, 4.0 decades between the max and the 1st
                       percentile, 3 % of the energy in the brightest 0.1 % of the sphere)
``sphere-studio``      studio: black surroundings and two area lights (max/median 1.2e5,
                       6.0 decades, 55 % of the energy in the brightest 0.1 %)
``sphere-sunrise``     sunny, high dynamic range: open field with the sun low on the horizon
                       (max 3.3e4, max/median 2.9e5, 6.5 decades, 58 % of the energy in the
                       sun)
``knot-courtyard``     the torus-knot mesh (:func:`torus_knot`; concavities,
                       interreflections, every normal direction) in the low-DR courtyard,
                       as the paper puts its Buddha in its low-DR Ennis map
=====================  ==================================================================

Why these maps (measured with ``bench/bench_render.py --envmaps``): they span the range of
the eight maps from the softest (courtyard) through concentrated artificial lights (studio)
to the brightest point-like source (the sun of sunrise), like Grace / St. Peter's / Ennis;
``interior`` and ``city`` are as high-DR as ``sunrise`` but their bright pixels are
windows/lamps rather than one sun, ``night`` is mostly black. Without the shared data set the
suite falls back to the procedural environment (``sphere-env`` and ``knot``), with a note.

Tone mapping of pictures (:func:`scene_exposure`): the paper's fixed operator
``(1 − 2^(−exposure·x))^(1/γ)`` with one exposure per *scene*, not per material. The paper's
0.02 belongs to its light probes' units; ours is ``1 / mean radiance`` of the map (a grey
Lambertian of albedo ρ then maps to ``x·exposure ≈ ρ``, about the paper's look), and
``γ = 2.2`` for every scene (deviation: the paper switches to exposure 1, γ 2.8 for its dark
Ennis map only because of its units, which this normalisation makes unnecessary).
"""

from __future__ import annotations

import dataclasses
import os
from functools import lru_cache
from pathlib import Path

import numpy as np

from ...errors import BRDFFormatError
from ._mitsuba import load as _load
from ..imageio import read_exr

__all__ = ["SCENES", "scene_dict", "procedural_envmap", "load_envmap", "torus_knot",
           "roughness_texture", "ENVMAP_DIR", "envmap_names", "SUITES", "SceneSpec",
           "scene_suite", "scene_spec", "scene_exposure", "envmap_stats", "CAMERA",
           "DISTANT_LIGHT"]

ENVMAP_DIR = Path(os.environ.get("BRDFFIT_ENVMAP_DIR", "")
                  or Path(__file__).resolve().parents[5] / "shared" / "data" / "envmaps")
SCENES = ("sphere-env", "sphere-point", "sphere-distant", "knot", "sphere-svrough")
#: the camera of every scene: at (0, 0, distance) looking at the origin, +Y up, horizontal
#: field of view in degrees (square film)
CAMERA = {"origin": (0.0, 0.0, 4.2), "target": (0.0, 0.0, 0.0), "up": (0.0, 1.0, 0.0),
          "fov_degrees": 30.0}
#: ``sphere-point``: position and radiant intensity (W/sr per RGB channel) of the point light
POINT_LIGHT = {"position": (3.0, 3.5, 4.0), "intensity": 40.0}
#: the directional light of ``sphere-distant``: direction of travel and irradiance (W/m²,
#: on a plane facing it; the same in R, G, B)
DISTANT_LIGHT = {"direction": (-0.5, -0.6, -0.62), "irradiance": 3.0}


def envmap_names() -> list[str]:
    """Names of the shared CC0 environment maps (empty when the data set is absent)."""
    return sorted(p.stem for p in ENVMAP_DIR.glob("*.exr")) if ENVMAP_DIR.is_dir() else []


# -- procedural content (NumPy) -------------------------------------------------------------
def procedural_envmap(width: int = 512, height: int = 256) -> np.ndarray:
    """The built-in environment: lat-long float32 ``(height, width, 3)``, all ≥ 0 (a fresh
    copy of a cached image: every rendering of a report uses it).

    Sky gradient (blue zenith → warm horizon), a darker ground, a sun-like blob
    (≈ 3° Gaussian, peak radiance 400), and two rectangular area-light-like spots
    (radiance 30 and 15) on the sides, so that both broad and sharp lobes get features to
    reflect. Mitsuba's lat-long convention: +Y up, row 0 at the zenith.
    """
    return _procedural_envmap(int(width), int(height)).copy()


@lru_cache(maxsize=4)
def _procedural_envmap(width: int, height: int) -> np.ndarray:
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    theta = v * np.pi                      # from +Y
    phi = u * 2.0 * np.pi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(T) * np.sin(P), np.cos(T), -np.sin(T) * np.cos(P)], -1)
    up = d[..., 1]
    sky_t = np.clip(up, 0.0, 1.0)[..., None]
    zenith, horizon = np.array([0.25, 0.45, 1.0]), np.array([1.1, 0.95, 0.8])
    sky = horizon + (zenith - horizon) * sky_t**0.5
    ground = np.array([0.18, 0.15, 0.12]) * (0.6 + 0.4 * np.clip(-up, 0, 1))[..., None]
    img = np.where((up >= 0)[..., None], sky, ground)
    sun = np.array([0.45, 0.75, 0.5])
    sun /= np.linalg.norm(sun)
    ang = np.arccos(np.clip(d @ sun, -1.0, 1.0))
    img = img + 400.0 * np.exp(-0.5 * (ang / np.radians(1.5)) ** 2)[..., None] * np.array([1.0, 0.9, 0.75])
    # two area-light-like rectangles (in θ/φ)
    for (t0, t1, p0, p1, rad, col) in ((0.30, 0.42, 0.10, 0.22, 30.0, (1.0, 1.0, 1.0)),
                                       (0.40, 0.48, 0.62, 0.80, 15.0, (0.7, 0.8, 1.0))):
        box = (v[:, None] >= t0) & (v[:, None] < t1) & (u[None, :] >= p0) & (u[None, :] < p1)
        img = img + rad * box[..., None] * np.array(col)
    return img.astype(np.float32)


def torus_knot(p: int = 2, q: int = 3, n_u: int = 384, n_v: int = 24, R: float = 0.62,
               r: float = 0.28, tube: float = 0.17):
    """Tube around a (p, q) torus knot: ``(vertices (N,3), faces (M,3) uint32, normals (N,3),
    uv (N,2))``, outward normals and consistent counter-clockwise winding. Frame along the
    curve: tangent from finite differences, normal from the curve's centre direction
    (Gram-Schmidt), so it twists smoothly with no Frenet flips."""
    t = np.arange(n_u) / n_u * 2.0 * np.pi
    def curve(t):
        rr = R + r * np.cos(q * t)
        return np.stack([rr * np.cos(p * t), rr * np.sin(p * t), r * np.sin(q * t)], -1)
    c = curve(t)
    T = curve(t + 1e-4) - curve(t - 1e-4)
    T /= np.linalg.norm(T, axis=-1, keepdims=True)
    N = c - np.sum(c * T, -1, keepdims=True) * T
    N /= np.linalg.norm(N, axis=-1, keepdims=True)
    B = np.cross(T, N)
    a = np.arange(n_v) / n_v * 2.0 * np.pi
    nrm = (np.cos(a)[None, :, None] * N[:, None, :] + np.sin(a)[None, :, None] * B[:, None, :])
    verts = c[:, None, :] + tube * nrm
    i = np.arange(n_u)[:, None]
    j = np.arange(n_v)[None, :]
    i1, j1 = (i + 1) % n_u, (j + 1) % n_v
    v00, v10, v01, v11 = i * n_v + j, i1 * n_v + j, i * n_v + j1, i1 * n_v + j1
    faces = np.concatenate([np.stack([v00, v10, v11], -1).reshape(-1, 3),
                            np.stack([v00, v11, v01], -1).reshape(-1, 3)])
    # make the winding agree with the outward normals
    vv = verts.reshape(-1, 3)
    fn = np.cross(vv[faces[:, 1]] - vv[faces[:, 0]], vv[faces[:, 2]] - vv[faces[:, 0]])
    nn = nrm.reshape(-1, 3)
    if np.mean(np.sum(fn * nn[faces[:, 0]], -1)) < 0:
        faces = faces[:, [0, 2, 1]]
    uv = np.stack(np.meshgrid(np.arange(n_u) / n_u, np.arange(n_v) / n_v, indexing="ij"), -1)
    return (vv.astype(np.float32), faces.astype(np.uint32), nn.astype(np.float32),
            uv.reshape(-1, 2).astype(np.float32))


def roughness_texture(size: int = 256) -> np.ndarray:
    """Roughness scale texture ``(size, size)`` for the spatially varying scene: smooth
    stripes along u (×0.35 … ×2.5, log-spaced) crossed with a checker in v, like the
    roughness-painted spheres of Dupuy 2015 Fig. 1/4. Positive float32."""
    u = (np.arange(size) + 0.5) / size
    stripes = np.exp(np.log(0.35) + (np.log(2.5) - np.log(0.35)) * 0.5 * (1 + np.sin(8 * np.pi * u)))
    checker = np.where((np.floor(u * 6) % 2) == 0, 1.0, 0.6)
    return (checker[:, None] * stripes[None, :]).astype(np.float32)


# -- Mitsuba objects ------------------------------------------------------------------------
def load_envmap(envmap=None) -> np.ndarray:
    """Environment as float32 ``(H, W, 3)``, clamped ≥ 0 (None → procedural)."""
    if envmap is None or (isinstance(envmap, str) and envmap in ("procedural", "default")):
        return procedural_envmap()
    if isinstance(envmap, np.ndarray):
        arr = np.asarray(envmap, np.float32)
    else:
        arr = _read_envmap(str(envmap))
    if arr.ndim != 3 or arr.shape[-1] < 3:
        raise BRDFFormatError(envmap if not isinstance(envmap, np.ndarray) else None,
                              f"expected an RGB lat-long environment map, found shape {arr.shape}")
    return np.maximum(np.nan_to_num(arr[..., :3], nan=0.0, posinf=0.0), 0.0).astype(np.float32)


@lru_cache(maxsize=8)
def _read_envmap(spec: str) -> np.ndarray:
    path = Path(spec)
    if not path.suffix and not path.exists():
        path = ENVMAP_DIR / f"{spec}.exr"
        if not path.is_file():
            raise BRDFFormatError(path, f"expected an environment map named {spec!r} in "
                                        f"{ENVMAP_DIR}, found {envmap_names() or 'none'}")
    return read_exr(path)


def _film(width: int, height: int) -> dict:
    """The scenes' film: RGBA float32, box filter (one pixel is the mean of its samples)."""
    return {"type": "hdrfilm", "width": int(width), "height": int(height),
            "rfilter": {"type": "box"}, "pixel_format": "rgba", "component_format": "float32"}


def _camera(resolution: int, spp: int):
    """The scenes' camera (:data:`CAMERA`) with a ``resolution²`` film."""
    mi, _ = _load()
    return {
        "type": "perspective", "fov": CAMERA["fov_degrees"], "fov_axis": "x",
        "to_world": mi.ScalarTransform4f().look_at(origin=list(CAMERA["origin"]),
                                                   target=list(CAMERA["target"]),
                                                   up=list(CAMERA["up"])),
        "film": _film(resolution, resolution),
        "sampler": {"type": "independent", "sample_count": int(spp)},
    }


_WINDOW_PLUGIN = "brdffit_window"
_window_registered = False


def window_sensor(resolution: int, width: int, height: int):
    """A sensor that renders a ``width × height`` window of the scenes' camera at
    ``resolution`` (the same pixels, camera rays and random numbers as that crop of the full
    film; rays equal to float32 rounding). Place it with ``sensor.move(x0, y0)`` (top-left
    pixel of the window) before each ``mi.render``.

    A film crop would do the same, but Mitsuba writes a crop's offset into the render kernel
    as a constant, so every new window is a new kernel to compile (≈ 0.2 s for a sphere
    scene, 3 windows per scene and material for the peaks). Here the offset is an opaque
    Dr.Jit value: one kernel renders every window of that size.
    """
    global _window_registered
    mi, dr = _load()
    if not _window_registered:
        mi.register_sensor(_WINDOW_PLUGIN, lambda props: _window_sensor_class(mi, dr)(props))
        _window_registered = True
    sensor = mi.load_dict({"type": _WINDOW_PLUGIN, "film": _film(width, height),
                           "sampler": {"type": "independent", "sample_count": 4}})
    sensor.setup(mi.load_dict(_camera(resolution, 4)), resolution)
    return sensor


@lru_cache(maxsize=1)
def _window_sensor_class(mi, dr):
    """The ``mi.Sensor`` subclass of :func:`window_sensor` (made once Mitsuba is loaded)."""

    class WindowSensor(mi.Sensor):
        """Forwards ray sampling to the full-film ``camera``: a position ``p`` ∈ [0, 1]² on
        the window's film is ``origin + p · extent`` on the full film."""

        def __init__(self, props):
            mi.Sensor.__init__(self, props)
            self.camera, self.resolution = None, None
            self.origin = self.extent = None

        def setup(self, camera, resolution: int):
            self.camera, self.resolution = camera, int(resolution)
            # draw the camera's samples only (a pinhole needs no aperture sample), so the
            # window gets the random numbers a crop of the full film gets
            self.m_needs_sample_2 = camera.needs_sample_2()
            self.m_needs_sample_3 = camera.needs_sample_3()
            size = self.film().size()
            self.extent = mi.Vector2f(*(dr.opaque(mi.Float, float(n) / self.resolution)
                                        for n in size))
            self.move(0, 0)

        def move(self, x0: int, y0: int):
            self.origin = mi.Point2f(dr.opaque(mi.Float, float(x0) / self.resolution),
                                     dr.opaque(mi.Float, float(y0) / self.resolution))

        def _on_full_film(self, p):
            return mi.Point2f(self.origin.x + p.x * self.extent.x,
                              self.origin.y + p.y * self.extent.y)

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            return self.camera.sample_ray(time, sample1, self._on_full_film(sample2), sample3,
                                          active)

        def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
            return self.camera.sample_ray_differential(time, sample1,
                                                       self._on_full_film(sample2), sample3,
                                                       active)

        def to_string(self):
            return f"WindowSensor[{self.film().size()} of {self.resolution}²]"

    return WindowSensor


def _env_emitter(envmap):
    mi, _ = _load()
    arr = load_envmap(envmap)
    return {"type": "envmap", "bitmap": mi.Bitmap(arr),
            "to_world": mi.ScalarTransform4f().rotate([0, 1, 0], 0.0)}


def _sphere(bsdf):
    """Unit sphere with its poles on ±y and the texture seam at the back: u runs around the
    vertical axis with u = 0.5 facing the camera, v from the top (0) to the bottom (1)."""
    mi, _ = _load()
    tw = mi.ScalarTransform4f().rotate([0, 1, 0], 90.0) @ mi.ScalarTransform4f().rotate([1, 0, 0], -90.0)
    return {"type": "sphere", "bsdf": bsdf, "to_world": tw}


def _knot_mesh(bsdf):
    mi, _ = _load()
    v, f, n, uv = torus_knot()
    props = mi.Properties()
    props["bsdf"] = bsdf
    mesh = mi.Mesh("knot", v.shape[0], f.shape[0], props=props, has_vertex_normals=True,
                   has_vertex_texcoords=True)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(v.ravel())
    params["faces"] = mi.UInt32(f.ravel())
    params["vertex_normals"] = mi.Float(n.ravel())
    params["vertex_texcoords"] = mi.Float(uv.ravel())
    params.update()
    return mesh


def scene_dict(bsdf, scene: str = "sphere-env", envmap=None, spp: int = 256,
               resolution: int = 256) -> dict:
    """Mitsuba scene dict of the named scene with ``bsdf`` on the object (``scene`` may be a
    suite name such as ``sphere-studio``: its map then replaces ``envmap``)."""
    mi, _ = _load()
    if scene not in SCENES:
        spec = scene_spec(scene, envmap)
        scene, envmap = spec.base, spec.envmap
    d = {"type": "scene", "sensor": _camera(resolution, spp),
         "integrator": {"type": "direct", "hide_emitters": True}}
    if scene in ("sphere-env", "sphere-svrough"):
        d["emitter"] = _env_emitter(envmap)
        d["object"] = _sphere(bsdf)
    elif scene == "sphere-point":
        d["emitter"] = {"type": "point", "position": list(POINT_LIGHT["position"]),
                        "intensity": {"type": "rgb", "value": [POINT_LIGHT["intensity"]] * 3}}
        d["object"] = _sphere(bsdf)
    elif scene == "sphere-distant":
        d["emitter"] = {"type": "directional", "direction": list(DISTANT_LIGHT["direction"]),
                        "irradiance": {"type": "rgb",
                                       "value": [DISTANT_LIGHT["irradiance"]] * 3}}
        d["object"] = _sphere(bsdf)
    elif scene == "knot":
        d["emitter"] = _env_emitter(envmap)
        d["integrator"] = {"type": "path", "max_depth": 4, "rr_depth": 100,
                           "hide_emitters": True}
        d["object"] = _knot_mesh(bsdf)
    return d


# -- the scene suite (Bagher 2016 §5) ---------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class SceneSpec:
    """One scene of a comparison: ``name`` (as reported), ``base`` (one of :data:`SCENES`),
    ``envmap`` (a map name/path or ``None`` = procedural), ``max_depth`` (2 = direct lighting
    of a convex object, 4 = up to three bounces on the knot), the tone map of its pictures
    (``exposure``, ``gamma``) and a ``note``."""

    name: str
    base: str
    envmap: object = None
    max_depth: int = 2
    exposure: float = 1.0
    gamma: float = 2.2
    note: str = ""

    def as_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["envmap"] = None if self.envmap is None else (
            self.envmap if isinstance(self.envmap, str) else "array")
        return d


#: Named scene suites: ``paper`` is the four scenes of the module docstring.
SUITES = {"paper": (("sphere-courtyard", "low dynamic range (overcast-like courtyard)"),
                    ("sphere-studio", "studio lights (concentrated area lights)"),
                    ("sphere-sunrise", "sunny, high dynamic range (low sun)"),
                    ("knot-courtyard", "torus-knot mesh, interreflections"))}
_FALLBACK = (("sphere-env", "procedural environment (../shared/data/envmaps absent)"),
             ("knot", "torus-knot mesh in the procedural environment (../shared/data/envmaps absent)"))


def _lum_mean(arr) -> float:
    """Solid-angle weighted mean luminance of a lat-long map."""
    lum = np.asarray(arr, np.float64)[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    h = lum.shape[0]
    w = np.sin((np.arange(h) + 0.5) / h * np.pi)[:, None]
    return float((lum * w).sum() / (w.sum() * lum.shape[1]))


def envmap_stats(envmap=None) -> dict:
    """Dynamic-range figures of an environment map (luminance, solid-angle weighted):
    ``max``, ``mean``, ``median``, ``max_over_median``, ``decades`` (log10 of max over the
    1st percentile of positive pixels) and ``top_energy`` (share of the energy in the
    brightest 0.1 % of the sphere)."""
    arr = load_envmap(envmap)
    lum = arr.astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    h = lum.shape[0]
    w = np.broadcast_to(np.sin((np.arange(h) + 0.5) / h * np.pi)[:, None], lum.shape)
    order = np.argsort(-lum.ravel())
    cs = np.cumsum(w.ravel()[order]) / w.sum()
    ce = np.cumsum((lum * w).ravel()[order]) / max((lum * w).sum(), 1e-300)
    pos = lum[lum > 0]
    med = float(np.median(lum))
    return {"max": float(lum.max()), "mean": _lum_mean(arr), "median": med,
            "max_over_median": float(lum.max() / med) if med > 0 else float("inf"),
            "decades": float(np.log10(lum.max() / np.percentile(pos, 1))) if pos.size else 0.0,
            "top_energy": float(ce[min(np.searchsorted(cs, 0.001), ce.size - 1)])}


def scene_exposure(base: str, envmap=None) -> float:
    """The fixed tone-mapping exposure of a scene (independent of the material): ``1 / mean
    radiance`` of its environment map, ``π / E`` for the point (E = 40/|p|², |p|² = 37.25)
    and distant (E = 3) lights."""
    if base == "sphere-point":
        return float(np.pi / (40.0 / 37.25))
    if base == "sphere-distant":
        return float(np.pi / DISTANT_LIGHT["irradiance"])
    return float(1.0 / max(_lum_mean(load_envmap(envmap)), 1e-12))


def scene_spec(name: str, envmap=None, note: str = "") -> SceneSpec:
    """Resolve a scene name: one of :data:`SCENES` (``envmap`` applies to its environment) or
    ``sphere-<map>`` / ``knot-<map>`` with a map of :func:`envmap_names`."""
    base, env = name, envmap
    if name not in SCENES:
        for prefix, b in (("sphere-", "sphere-env"), ("knot-", "knot")):
            if name.startswith(prefix) and name[len(prefix):]:
                base, env = b, name[len(prefix):]
                break
        else:
            raise ValueError(f"unknown scene {name!r}; expected one of {', '.join(SCENES)}, "
                             "a suite (paper) or sphere-<map>/knot-<map> with a map of "
                             f"{ENVMAP_DIR} ({', '.join(envmap_names()) or 'none present'})")
        if env not in envmap_names() and not Path(env).is_file():
            raise ValueError(f"scene {name!r}: no environment map {env!r} in {ENVMAP_DIR} "
                             f"({', '.join(envmap_names()) or 'none present'})")
    uses_env = base in ("sphere-env", "knot", "sphere-svrough")
    if not uses_env:
        env = None
    return SceneSpec(name=name, base=base, envmap=env, max_depth=4 if base == "knot" else 2,
                     exposure=scene_exposure(base, env if uses_env else None), gamma=2.2,
                     note=note)


def scene_suite(scenes="paper", envmap=None) -> tuple[list[SceneSpec], list[str]]:
    """The scenes of a comparison and notes about them.

    ``scenes``: a suite name of :data:`SUITES` (``"paper"``), one scene name or a list /
    comma-separated string of names (see :func:`scene_spec`; ``envmap`` applies to the plain
    :data:`SCENES` names). When the shared environment maps are absent the paper suite falls
    back to the procedural environment (``sphere-env``, ``knot``), with a note saying so.
    """
    notes: list[str] = []
    if isinstance(scenes, str):
        names = [s.strip() for s in scenes.split(",") if s.strip()]
    else:
        names = [str(s) for s in scenes]
    if not names:
        raise ValueError("expected at least one scene")
    out: list[SceneSpec] = []
    for n in names:
        if n in SUITES:
            members = SUITES[n]
            have = set(envmap_names())
            if not all(m.split("-", 1)[1] in have for m, _ in members):
                notes.append(f"scene suite {n!r}: the environment maps of {ENVMAP_DIR} are "
                             "absent, so the procedural environment replaces them "
                             f"({', '.join(m for m, _ in _FALLBACK)} instead of "
                             f"{', '.join(m for m, _ in members)})")
                members = _FALLBACK
            out += [scene_spec(m, None, note) for m, note in members]
        else:
            out.append(scene_spec(n, envmap))
    seen = set()
    uniq = []
    for s in out:
        if s.name not in seen:
            seen.add(s.name)
            uniq.append(s)
    return uniq, notes
