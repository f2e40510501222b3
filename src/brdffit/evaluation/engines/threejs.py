"""glTF materials rendered by three.js (``MeshPhysicalMaterial``, WebGL 2) in headless Chromium.

The export round trip for three.js: an exported ``.gltf`` (``brdffit export FIT --to
gltf``) is loaded by three's own ``GLTFLoader``; its material ``materials[i]``
(``parser.getDependency('material', i)``: a ``MeshPhysicalMaterial`` when the file uses
``KHR_materials_*`` extensions, else a ``MeshStandardMaterial``) is put on a
``THREE.SphereGeometry`` (radius 1, 256 × 128 segments: the polygon lies within 1 − cos(π/256)
= 7.5e-5 of the sphere) in our scene rebuilt in three.js, rendered into a ``FloatType``
``WebGLRenderTarget`` and read back with ``readRenderTargetPixels`` (linear values, no tone
mapping, no output colour-space conversion: a render target stays in three's linear working
space). The page (``threejs_page/``, package data) gets the scene as JSON and posts the pixels
back to a server on 127.0.0.1 that serves it, the ``three`` package of the project's
``.npm/`` (``make npmdeps``) and the glTF file's folder: offline, no CDN.

Scenes (:data:`SCENES`, constants of :mod:`brdffit.evaluation.render.scenes`):

* camera: ``PerspectiveCamera`` at (0, 0, 4.2) looking at the origin, +y up, 30° field of view
  (three's is vertical, Mitsuba's horizontal: equal on a square film);
* ``sphere-distant``: a ``DirectionalLight`` placed at ``−direction`` aiming at the origin, of
  intensity E = 3. three's lights are physically based (r155+: no π factor): the direct
  radiance is ``E · (N·L) · f_r``, with ``f_r = c/π`` for Lambert, exactly Mitsuba's
  ``directional`` emitter of irradiance E;
* ``sphere-point``: a ``PointLight`` of intensity I = 40 (W/sr as cd), no cut-off distance,
  decay 2: ``E = I / d²``, Mitsuba's ``point`` emitter;
* ``sphere-env`` (the procedural map) and ``sphere-<map>`` (a map of
  :func:`~brdffit.evaluation.render.scenes.envmap_names`, e.g. the paper suite's
  ``sphere-courtyard``, ``sphere-studio``, ``sphere-sunrise``): no light, the map alone
  through three's image-based lighting, ``scene.environment`` = ``PMREMGenerator
  .fromEquirectangular`` of a ``HalfFloatType`` RGBA ``DataTexture`` (:func:`environment_rgba`)
  of the map at its own resolution (1024 × 512 for the shared maps, 512 × 256 for the
  procedural one: :func:`~brdffit.evaluation.report_viewer.environment_image` at the native
  width is the map unchanged, so nothing is resampled before three; PMREM's cube faces are
  ``max(256, width/4)`` = 256 texels, 0.35° at a face's centre, the map's own pixel pitch),
  clamped at 0 as :func:`~brdffit.evaluation.render.scenes.load_envmap` loads it (and at the
  half-float maximum 65504; the brightest shared map, sunrise, peaks at 34560), turned into
  three's equirectangular convention by
  :func:`~brdffit.evaluation.report_viewer.three_equirect` (the orientation of Mitsuba's
  ``envmap`` emitter in the same world frame). What three then computes is its split-sum
  approximation (Karis 2013): radiance from the PMREM level of the material's roughness (GGX
  prefiltered for V = N), times its analytic DFG term, plus the diffuse irradiance read from
  PMREM's roughest level, not our Monte Carlo integral of the map.

Pixels: Mitsuba integrates each pixel with a box filter (random positions in the pixel);
three's rasteriser samples pixel centres. The page renders ``supersample``² samples per pixel
(default 4 × 4) and they are box-averaged here, which gives the same coverage at the
silhouette (alpha = covered fraction) and the pixel-mean radiance.

What three.js r187 renders for a directional or point light (``lights_physical_*``,
``lights_fragment_begin`` of the shader chunks), versus the glTF specification's BRDF:

* ``α = max(roughness, 0.045)² `` after adding ``geometryRoughness`` = the largest screen
  derivative of the normal (specular anti-aliasing: ~1/(sphere radius in pixels) at the centre,
  growing towards the silhouette);
* Schlick's Fresnel in Epic's spherical-Gaussian form ``2^((−5.55473 x − 6.98316) x)``,
  ``x = V·H``, instead of ``(1 − x)⁵``;
* the height-correlated Smith ``V`` (the glTF core's sample implementation is separable);
* the specular lobe multiplied by a multiple-scattering compensation ``1 + F0 (1/E_ss − 1)``
  (Turquin 2019, Eq. 16; ``E_ss`` from three's DFG table at (roughness, N·V)): rough
  specular lobes are brighter than the single-scattering glTF BRDF;
* the diffuse ``(1 − F(V·H)) · c (1 − metallic)/π`` with the dielectric F (glTF's
  ``fresnel_mix``);
* the clear coat ``f (1 − c F_c(N·V)) + c · coat`` with F0 = 0.04, f90 = 1 (as glTF).

Comparison (:func:`compare_render`): PSNR (Bagher 2016 §5) ± se against K Mitsuba renders of
the fit (the engine's image is deterministic; :func:`brdffit.evaluation.metrics.crn_psnr`
removes the reference's own noise), per-channel mean ratio, the same ratio on the rim (pixels
at r > 0.85 R of the silhouette radius R), HDR-FLIP (``flip-evaluator``, NVIDIA's reference
implementation; Andersson et al. 2021) over the foreground, and the alignment (coverage, peak
pixel).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import subprocess
import tempfile
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np

from ..metrics import crn_psnr
from ..render import Renderer
from ..render.scenes import CAMERA, DISTANT_LIGHT, POINT_LIGHT, envmap_names, load_envmap
from ..report_viewer import environment_image, three_equirect

__all__ = ["SCENES", "ThreeRender", "EngineUnavailable", "three_dir", "three_version",
           "chromium_path", "available", "scene_json", "render_gltf", "run_page", "sphere_geometry_px",
           "compare_render", "reference_renders", "resolve_scene", "environment_rgba",
           "environment_width", "rgba_half",
           "HALF_MAX"]

#: the scenes rebuilt in three.js: the two lights, and the sphere under an environment map
#: (``sphere-env``: the procedural map; ``sphere-<map>``: a map of the shared set)
SCENES = ("sphere-distant", "sphere-point", "sphere-env", "sphere-<map>")
#: the largest finite IEEE half float: environment maps are carried as half floats
HALF_MAX = 65504.0
_PAGE = Path(__file__).with_name("threejs_page")
_ROOT = Path(__file__).resolve().parents[4]   # the source tree's root (src/brdffit/...)


class EngineUnavailable(RuntimeError):
    """three.js or Chromium is not installed here (the message says what is missing)."""


def three_dir() -> Path | None:
    """The ``three`` npm package: ``$BRDFFIT_NPM_PREFIX/node_modules/three``, else the
    project's ``.npm/`` (``make npmdeps``), else ``./.npm/``; ``None`` when absent."""
    cands = []
    if os.environ.get("BRDFFIT_NPM_PREFIX"):
        cands.append(Path(os.environ["BRDFFIT_NPM_PREFIX"]))
    cands += [_ROOT / ".npm", Path.cwd() / ".npm"]
    for c in cands:
        d = c / "node_modules" / "three"
        if (d / "build" / "three.module.js").is_file() and (d / "package.json").is_file():
            return d.resolve()
    return None


def three_version(d: Path | None = None) -> str | None:
    """Version of the ``three`` package (its package.json)."""
    d = d or three_dir()
    if d is None:
        return None
    return str(json.loads((d / "package.json").read_text())["version"])


def chromium_path() -> Path | None:
    """Chromium: ``$BRDFFIT_CHROMIUM``, else ``chromium`` on the PATH, else /usr/bin/chromium."""
    for c in (os.environ.get("BRDFFIT_CHROMIUM"), shutil.which("chromium"), "/usr/bin/chromium"):
        if c and Path(c).is_file() and os.access(c, os.X_OK):
            return Path(c)
    return None


def available() -> tuple[bool, str]:
    """``(True, "")`` when three.js and Chromium are present, else ``(False, reason)``."""
    if chromium_path() is None:
        return False, ("needs Chromium (Debian 'chromium', installed by `make sysdeps` as root; "
                       "or $BRDFFIT_CHROMIUM)")
    if three_dir() is None:
        return False, ("needs the npm package three in .npm/node_modules (`make npmdeps`; or "
                       "$BRDFFIT_NPM_PREFIX)")
    return True, ""


def resolve_scene(scene) -> tuple[str, str | None]:
    """``(base, envmap)`` of a scene name: ``base`` is ``sphere-distant``, ``sphere-point`` or
    ``sphere-env``; ``envmap`` the name of the shared map of ``sphere-<map>`` (``None``: the
    procedural map of ``sphere-env``, or no map). Only names of :func:`envmap_names` are
    maps (not paths)."""
    if scene in ("sphere-distant", "sphere-point", "sphere-env"):
        return scene, None
    if isinstance(scene, str) and scene.startswith("sphere-") and scene[7:] in envmap_names():
        return "sphere-env", scene[7:]
    raise ValueError(f"three.js scene: expected sphere-distant, sphere-point, sphere-env or "
                     f"sphere-<map> with a map of {', '.join(envmap_names()) or '(none present)'}"
                     f", got {scene!r}")


def environment_width(envmap: str | None, width: int | None = None) -> int:
    """Width of the texture of a map: ``width`` (validated: a multiple of 4 in [8, 8192]),
    or the map's own width when ``None``."""
    if width is None:
        return int(load_envmap(envmap).shape[1])
    if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or not (
            8 <= width <= 8192 and width % 4 == 0):
        raise ValueError(f"environment width must be a multiple of 4 in [8, 8192], got {width!r}")
    return int(width)


def environment_rgba(envmap: str | None, convention: str = "three",
                     width: int | None = None) -> tuple[bytes, int, int]:
    """The map of ``sphere-env`` (``envmap`` ``None``) or ``sphere-<envmap>`` as the pages'
    texture: ``(bytes, width, height)``, little-endian half floats RGBA (alpha 1), rows in
    upload order (row 0 at texture v = 0), at the map's own resolution (or ``width`` ×
    ``width/2``: :func:`environment_image`'s solid-angle weighted area average), clamped to
    [0, :data:`HALF_MAX`]. ``convention``: ``"three"`` (three's equirectangular mapping,
    :func:`three_equirect`: v = 0 at the nadir) or ``"mitsuba"`` (the map as Mitsuba's
    ``envmap`` reads it: row 0 at the zenith, ``u = atan2(x, −z)/2π``)."""
    if convention not in ("three", "mitsuba"):
        raise ValueError(f"environment_rgba: convention must be 'three' or 'mitsuba', got "
                         f"{convention!r}")
    img = environment_image(envmap, environment_width(envmap, width))  # native: unchanged
    if convention == "three":
        img = three_equirect(img)
    return rgba_half(img), int(img.shape[1]), int(img.shape[0])


def rgba_half(img: np.ndarray) -> bytes:
    """An (H, W, 3) image as the pages' texels: little-endian half floats RGBA, alpha 1,
    colour clamped to [0, :data:`HALF_MAX`], rows in the order given."""
    img = np.asarray(img)
    if img.ndim != 3 or img.shape[-1] != 3:
        raise ValueError(f"rgba_half: expected an (H, W, 3) image, got shape {img.shape}")
    rgba = np.ones(img.shape[:2] + (4,), "<f2")
    rgba[..., :3] = np.clip(np.nan_to_num(img, nan=0.0, posinf=HALF_MAX), 0.0, HALF_MAX)
    return np.ascontiguousarray(rgba).tobytes()


def scene_json(scene: str = "sphere-distant", resolution: int = 128, supersample: int = 4,
               segments: tuple[int, int] = (256, 128), material_index: int = 0,
               env_width: int | None = None) -> dict:
    """The scene description sent to the page (plain data, serialised as JSON): size of the
    render target, camera, light (for an environment-map scene: ``{"type": "environment",
    "envmap", "width", "height"}``, the texels served at ``/environment.bin``), sphere
    tessellation and the material index."""
    base, envmap = resolve_scene(scene)
    for nm, v, lo, hi in (("resolution", resolution, 8, 2048), ("supersample", supersample, 1, 8),
                          ("material_index", material_index, 0, 1 << 20)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
            raise ValueError(f"three.js scene: {nm} must be an integer in [{lo}, {hi}], got {v!r}")
    if resolution * supersample > 4096:
        raise ValueError(f"three.js scene: resolution × supersample must be ≤ 4096, got "
                         f"{resolution} × {supersample}")
    seg = tuple(int(s) for s in segments)
    if len(seg) != 2 or not (3 <= seg[0] <= 2048 and 2 <= seg[1] <= 1024):
        raise ValueError(f"three.js scene: segments must be (3..2048, 2..1024), got {segments!r}")
    n = int(resolution) * int(supersample)
    if base == "sphere-distant":
        light = {"type": "directional", "direction": [float(x) for x in DISTANT_LIGHT["direction"]],
                 "irradiance": float(DISTANT_LIGHT["irradiance"])}
    elif base == "sphere-env":
        w = environment_width(envmap, env_width)
        light = {"type": "environment", "envmap": envmap or "procedural", "width": w,
                 "height": w // 2}
    else:
        light = {"type": "point", "position": [float(x) for x in POINT_LIGHT["position"]],
                 "intensity": float(POINT_LIGHT["intensity"])}
    return {"name": scene, "width": n, "height": n, "material_index": int(material_index),
            "sphere_segments": list(seg),
            "camera": {"origin": [float(x) for x in CAMERA["origin"]],
                       "target": [float(x) for x in CAMERA["target"]],
                       "up": [float(x) for x in CAMERA["up"]],
                       "fov": float(CAMERA["fov_degrees"])},
            "light": light}


def sphere_geometry_px(resolution: int) -> tuple[float, float, float]:
    """``(cx, cy, R)``: centre (pixel coordinates, pixel centres at i + 0.5) and radius in
    pixels of the unit sphere's silhouette seen by the scenes' camera:
    ``R = (n/2) tan(asin(1/d)) / tan(fov/2)``."""
    half = math.tan(math.radians(CAMERA["fov_degrees"]) / 2.0)
    r = (resolution / 2.0) * math.tan(math.asin(1.0 / CAMERA["origin"][2])) / half
    return resolution / 2.0, resolution / 2.0, r


@dataclasses.dataclass
class ThreeRender:
    """A three.js rendering: ``image`` (H, W, 3) linear float32 (pixel means), ``alpha``
    (H, W) covered fraction, ``info`` (three revision, WebGL renderer string, the material as
    three built it, the scene, seconds)."""

    image: np.ndarray
    alpha: np.ndarray
    info: dict

    @property
    def mask(self) -> np.ndarray:
        """Fully covered pixels (as :func:`brdffit.evaluation.render.foreground_mask`)."""
        return self.alpha >= 0.999


class _Handler(BaseHTTPRequestHandler):
    server: "_Server"

    def log_message(self, *a):  # quiet
        pass

    def _send(self, body: bytes, ctype: str, code: int = 200):
        self.send_response(code)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def _file(self, base: Path, rel: str):
        p = (base / rel).resolve()
        if not p.is_relative_to(base) or not p.is_file():
            return self._send(b"not found", "text/plain", 404)
        ctype = {".js": "text/javascript", ".html": "text/html", ".json": "application/json",
                 ".gltf": "model/gltf+json", ".bin": "application/octet-stream",
                 ".png": "image/png", ".jpg": "image/jpeg"}.get(p.suffix.lower(),
                                                              "application/octet-stream")
        self._send(p.read_bytes(), ctype)

    def do_GET(self):  # noqa: N802
        path = self.path.split("?", 1)[0]
        s = self.server
        if path in ("/", "/index.html"):
            return self._file(_PAGE, "index.html")
        if path == "/page/render.js":          # the entry point: the page's own script
            return self._file(_PAGE, s.script)
        if path.startswith("/page/"):            # the modules it imports (common.js)
            return self._file(_PAGE, path[len("/page/"):])
        if path == "/scene.json":
            return self._send(json.dumps(s.scene).encode(), "application/json")
        if path in s.data:
            return self._send(s.data[path], "application/octet-stream" if path.endswith(".bin")
                              else "application/json")
        if path == "/material.gltf" and s.gltf_name:
            return self._file(s.gltf_dir, s.gltf_name)
        if path.startswith("/three/"):
            rel = path[len("/three/"):]
            if rel.startswith(("build/", "examples/jsm/")):
                return self._file(s.three, rel)
        elif s.gltf_name and path.startswith("/") and "/" not in path[1:]:
            return self._file(s.gltf_dir, path[1:])    # buffers/images next to the .gltf
        self._send(b"not found", "text/plain", 404)

    def do_POST(self):  # noqa: N802
        n = int(self.headers.get("Content-Length", "0"))
        body = self.rfile.read(n) if n > 0 else b""
        key = {"/result": "result", "/info": "info", "/error": "error"}.get(self.path)
        self._send(b"ok", "text/plain", 200 if key else 404)
        if key:
            self.server.posted[key] = body
            if key in ("result", "error"):
                self.server.done.set()


class _Server(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, scene: dict, three: Path, script: str, gltf: Path | None = None,
                 data: dict[str, bytes] | None = None):
        super().__init__(("127.0.0.1", 0), _Handler)
        self.scene, self.three, self.script = scene, three, script
        self.gltf_dir = gltf.parent.resolve() if gltf is not None else None
        self.gltf_name = gltf.name if gltf is not None else None
        self.data = dict(data or {})
        self.posted: dict[str, bytes] = {}
        self.done = threading.Event()


def _chromium_args(chromium: Path, profile: Path) -> list[str]:
    # the report test's flags, with WebGL on SwiftShader (CPU) instead of --disable-gpu
    return [str(chromium), "--headless", "--no-sandbox", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            "--disable-extensions", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
            "--ignore-gpu-blocklist", f"--user-data-dir={profile}"]


def render_gltf(gltf, scene: str = "sphere-distant", resolution: int = 128,
                supersample: int = 4, material_index: int = 0,
                segments: tuple[int, int] = (256, 128), timeout: float = 120.0,
                env_width: int | None = None) -> ThreeRender:
    """Render material ``material_index`` of the glTF file ``gltf`` on a unit sphere with
    three.js in headless Chromium (see the module docstring; ``env_width``: the map's texture
    width, default its own). Raises
    :class:`EngineUnavailable` when three.js or Chromium is missing, ``RuntimeError`` with the
    page's error when the page fails, ``TimeoutError`` after ``timeout`` seconds."""
    path = Path(gltf)
    if not path.is_file() or path.suffix.lower() != ".gltf":
        raise ValueError(f"render_gltf: expected an existing .gltf file, got {str(gltf)!r}")
    sc = scene_json(scene, resolution, supersample, segments, material_index, env_width)
    data = None
    if sc["light"]["type"] == "environment":
        data = {"/environment.bin": environment_rgba(resolve_scene(scene)[1], "three",
                                                     sc["light"]["width"])[0]}
    return run_page("render.js", sc, resolution, supersample, gltf=path, data=data,
                    timeout=timeout)


def run_page(script: str, sc: dict, resolution: int, supersample: int, gltf: Path | None = None,
             data: dict[str, bytes] | None = None, timeout: float = 120.0) -> ThreeRender:
    """Serve ``threejs_page/index.html`` with ``script`` (a file of ``threejs_page/``) as its
    module, the scene ``sc`` at ``/scene.json``, the ``three`` package, the glTF file's folder
    and ``data`` (path → bytes: JSON, or binary for a path ending in ``.bin``); run it in headless Chromium until it posts ``/result``
    (Float32 RGBA, rows bottom to top) or ``/error``; box-average ``supersample``² samples per
    pixel."""
    ok, why = available()
    if not ok:
        raise EngineUnavailable(why)
    three = three_dir()
    server = _Server(sc, three, script, gltf, data)
    th = threading.Thread(target=server.serve_forever, daemon=True)
    th.start()
    t0 = time.perf_counter()
    proc = None
    try:
        with tempfile.TemporaryDirectory(prefix="brdffit-chromium-") as profile:
            url = f"http://127.0.0.1:{server.server_address[1]}/index.html"
            log = Path(profile) / "chromium-stderr.txt"      # a file: a pipe could fill up
            with open(log, "wb") as err_fh:
                proc = subprocess.Popen(_chromium_args(chromium_path(), Path(profile)) + [url],
                                        stdout=subprocess.DEVNULL, stderr=err_fh,
                                        start_new_session=True)
                finished = server.done.wait(timeout)
                _stop(proc)
            if not finished:
                err = log.read_bytes().decode(errors="replace")[-2000:]
                raise TimeoutError(f"{script}: no result after {timeout:.0f} s "
                                   f"(Chromium's stderr: {err})")
    finally:
        if proc is not None:
            _stop(proc)
        server.shutdown()
        server.server_close()
    seconds = time.perf_counter() - t0
    if "error" in server.posted:
        raise RuntimeError(f"{script} failed: " + server.posted["error"].decode(errors="replace"))
    n = sc["width"]
    raw = np.frombuffer(server.posted["result"], dtype="<f4")
    if raw.size != n * n * 4:
        raise RuntimeError(f"{script}: expected {n * n * 4} floats, got {raw.size}")
    px = raw.reshape(n, n, 4)[::-1]            # WebGL rows run bottom to top
    s = int(supersample)
    px = px.reshape(resolution, s, resolution, s, 4).mean(axis=(1, 3), dtype=np.float64)
    info = json.loads(server.posted.get("info", b"{}").decode() or "{}")
    info |= {"scene": sc.get("name"), "resolution": int(resolution), "supersample": s,
             "segments": list(sc["sphere_segments"]), "seconds": seconds,
             "three_package": three_version(three)}
    return ThreeRender(image=px[..., :3].astype(np.float32),
                       alpha=np.clip(px[..., 3], 0.0, 1.0).astype(np.float32), info=info)


def _stop(proc: subprocess.Popen) -> None:
    """End the Chromium started by :func:`render_gltf` (its own process group)."""
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, 15)
    except ProcessLookupError:
        return
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, 9)
        proc.wait(10)


def reference_renders(brdf, scene: str = "sphere-distant", resolution: int = 128,
                      spp: int = 64, batches: int = 4):
    """Our Mitsuba render of ``brdf`` in ``scene``: ``(stack (K, H, W, 3), alpha (H, W))``
    of ``batches`` independent seeds (K ≥ 2 for the standard error of :func:`compare_render`)."""
    resolve_scene(scene)                       # validates the name
    if batches < 2:
        raise ValueError(f"reference_renders: batches must be ≥ 2, got {batches}")
    r = Renderer(brdf, scene, None, int(spp), int(resolution))
    outs = [r.render(seed) for seed in range(int(batches))]
    return (np.stack([o.image for o in outs]).astype(np.float32),
            np.mean([o.alpha for o in outs], axis=0).astype(np.float32))


def _flip(ref: np.ndarray, test: np.ndarray, mask: np.ndarray) -> dict:
    """HDR-FLIP (flip-evaluator): mean over the foreground and over the whole image."""
    try:
        import flip_evaluator as flip
    except ImportError:
        return {"flip": None, "flip_image": None,
                "flip_note": "flip-evaluator is not installed (pip install flip-evaluator)"}
    emap, mean, params = flip.evaluate(np.ascontiguousarray(ref, np.float32),
                                       np.ascontiguousarray(test, np.float32), "HDR",
                                       inputsRGB=False, applyMagma=False)
    emap = np.asarray(emap).reshape(ref.shape[:2])
    return {"flip": float(emap[mask].mean()), "flip_image": float(mean),
            "flip_exposures": [float(params.get("startExposure", float("nan"))),
                               float(params.get("stopExposure", float("nan")))]}


def compare_render(test_image, test_alpha, ref_stack, ref_alpha, rim: float = 0.85) -> dict:
    """Figures of an engine's render against our render of the fit (module docstring).

    ``test_image`` (H, W, 3) and ``test_alpha`` (H, W): the engine's; ``ref_stack``
    (K, H, W, 3) and ``ref_alpha`` (H, W): :func:`reference_renders`. The foreground is the
    pixels fully covered in both. Returns ``psnr``, ``psnr_se`` (and the rest of
    :func:`~brdffit.evaluation.metrics.crn_psnr` under ``crn``), ``mean_ratio`` and
    ``rim_ratio`` (RGB, engine / fit sums over the foreground and over its part beyond
    ``rim`` R), ``flip`` (HDR-FLIP, foreground mean), ``coverage`` (the sum of alpha, in pixels: engine, fit
    and the analytic πR² of :func:`sphere_geometry_px`), ``coverage_px`` (pixels with
    alpha > 0.5), ``peak_pixel`` ((row, col) of the brightest luminance, engine and fit).
    """
    t = np.asarray(test_image, np.float64)
    refs = np.asarray(ref_stack, np.float64)
    if refs.ndim != 4 or refs.shape[1:] != t.shape or t.shape[-1] != 3:
        raise ValueError(f"compare_render: expected (H, W, 3) and (K, H, W, 3), got {t.shape} "
                         f"and {refs.shape}")
    ta, ra = np.asarray(test_alpha, np.float64), np.asarray(ref_alpha, np.float64)
    if ta.shape != t.shape[:2] or ra.shape != t.shape[:2]:
        raise ValueError("compare_render: alpha shapes differ from the images'")
    if not 0.0 < rim < 1.0:
        raise ValueError(f"compare_render: rim must be in (0, 1), got {rim}")
    mask = (ta >= 0.999) & (ra >= 0.999)
    ref = refs.mean(0)
    crn = crn_psnr(refs, np.broadcast_to(t, refs.shape), mask)
    h, w = mask.shape
    cx, cy, R = sphere_geometry_px(w)
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    rim_m = mask & (np.hypot(xx - cx, yy - cy) > rim * R)
    lum = np.array([0.2126, 0.7152, 0.0722])

    def ratio(m):
        return (t[m].sum(0) / np.maximum(ref[m].sum(0), 1e-300)).tolist()

    def peak(img):
        return [int(v) for v in np.unravel_index(np.argmax(img @ lum), img.shape[:2])]

    out = {"psnr": crn["psnr"], "psnr_se": crn.get("psnr_se"), "crn": crn,
           "mean_ratio": ratio(mask), "rim_ratio": ratio(rim_m), "rim_pixels": int(rim_m.sum()),
           "foreground_pixels": int(mask.sum()),
           "coverage": {"engine": float(ta.sum()), "fit": float(ra.sum()),
                        "analytic": float(math.pi * R * R)},
           "coverage_px": {"engine": int((ta > 0.5).sum()), "fit": int((ra > 0.5).sum())},
           "alpha_l1": float(np.abs(ta - ra).sum()),
           "peak_pixel": {"engine": peak(t), "fit": peak(ref)}}
    return out | _flip(ref.astype(np.float32), t.astype(np.float32), mask)
