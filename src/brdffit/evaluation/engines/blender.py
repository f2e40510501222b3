"""glTF and USD files rendered by Blender (Cycles), compared with our render of the fit.

A real engine, used as a user would: Blender as a Python module (``bpy`` from PyPI) imports
the exported ``.gltf`` or ``.usda`` with **its own importer (glTF or USD) and default
options** and renders it with Cycles on the CPU in our scene rebuilt in Blender
(:func:`render_file`; the Blender side is
the script :mod:`._blender_driver`). Only ``sphere-distant`` is rebuilt: the camera
(:data:`~brdffit.evaluation.render.scenes.CAMERA`), the directional light
(:data:`~brdffit.evaluation.render.scenes.DISTANT_LIGHT`: a sun lamp of angle 0 whose
strength is the irradiance) and a black world; the object is the mesh the file carries (the
preview sphere of :func:`brdffit.export.gltf.write_gltf` or
:func:`brdffit.export.usd.write_usd`).

Blender runs in a **child process** with its own interpreter: ``bpy`` pins numpy < 2 and
bundles its own libraries (its own LLVM among them, where ours has Mitsuba's); the job is a
JSON file (paths and numbers, no code), the images come back as ``.npy`` files. The
interpreter is, in this order: ``$BRDFFIT_BLENDER_PYTHON``, the ``.venv-blender`` of the
source tree (``make blender``), the ``.venv-blender`` beside the running venv.

:func:`compare_renders` measures Blender's images against our Mitsuba render of the fit,
both as K independent batches (seeds), over the pixels both cover fully:

* ``psnr`` ± ``psnr_se``: Bagher 2016 §5 PSNR with the U-statistic MSE and its jackknife
  standard error of :func:`brdffit.evaluation.metrics.crn_psnr` (the batches of the two
  renderers are independent, so ``E[D_j D_k] = Δ²`` for ``j ≠ k`` holds as with CRN; only
  the noise, larger without common random numbers, widens the se);
* ``mean_ratio``: per channel, Blender's mean over the foreground / the fit's;
* ``rim_ratio``: the same over the rim, the pixels at ``r > 0.85 R`` from the sphere's
  centre (R its projected radius, from the fit's coverage): grazing angles;
* ``flip``: the mean HDR-FLIP error (Andersson et al. 2021, NVIDIA's ``flip-evaluator``) of
  the mean Blender image against the mean fit image (whole frame, linear Rec.709);
* alignment: ``coverage`` (sum of alpha) of both and the position of each peak pixel.

:func:`round_trip` does all of it for a fit and its exported file.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ...errors import BRDFError
from ..metrics import crn_psnr
from ..render.core import Renderer
from ..imageio import write_exr
from ..render.scenes import CAMERA, DISTANT_LIGHT, load_envmap, scene_spec

__all__ = ["BlenderUnavailable", "BlenderFailed", "BlenderRender", "blender_python",
           "available", "import_report", "render_file", "render_fit", "compare_renders",
           "rim_mask", "round_trip", "RIM_FRACTION", "SCENES"]

#: the scenes rebuilt in Blender: the directional light, and the sphere under an environment
#: map (``sphere-env``: the procedural map; ``sphere-<map>``: a map of the shared set, as the
#: paper suite's ``sphere-courtyard``, ``sphere-studio``, ``sphere-sunrise``)
SCENES = ("sphere-distant", "sphere-env", "sphere-<map>")
#: rotation about Blender's +Z of the direction looked up in the environment texture: Mitsuba's
#: lat-long ``u = atan2(x, −z)/2π`` in its +Y-up frame is Blender's equirectangular ``u``
#: turned by a quarter turn in Blender's +Z-up frame (the importer's (x, y, z) → (x, −z, y))
ENVMAP_ROTATION_DEG = 90.0
#: the rim: pixels farther than this fraction of the sphere's projected radius from its centre
RIM_FRACTION = 0.85
_DRIVER = Path(__file__).with_name("_blender_driver.py")
_ENV_VAR = "BRDFFIT_BLENDER_PYTHON"
_VENV = ".venv-blender"


class BlenderUnavailable(BRDFError):
    """No Python interpreter with ``bpy`` was found (see :func:`blender_python`)."""


class BlenderFailed(BRDFError):
    """Blender ran and failed (import or render); the message ends with its output."""


def _candidates() -> list[Path]:
    out = []
    env = os.environ.get(_ENV_VAR)
    if env:
        out.append(Path(env))
    out.append(Path(__file__).resolve().parents[4] / _VENV / "bin" / "python")
    out.append(Path(sys.prefix).resolve().parent / _VENV / "bin" / "python")
    return out


def blender_python() -> Path | None:
    """The first interpreter that can import ``bpy`` (``$BRDFFIT_BLENDER_PYTHON``, then the
    source tree's ``.venv-blender``, then the one beside the running venv); ``None`` if none.
    Checked with ``importlib.util.find_spec`` (without importing Blender)."""
    for p in _candidates():
        if p.is_file() and os.access(p, os.X_OK) and _has_bpy(str(p)):
            return p
    return None


_HAS_BPY: dict[str, bool] = {}


def _has_bpy(python: str) -> bool:
    if python not in _HAS_BPY:
        try:
            r = subprocess.run([python, "-I", "-c", "import importlib.util, sys; "
                                "sys.exit(importlib.util.find_spec('bpy') is None)"],
                               capture_output=True, timeout=60)
            _HAS_BPY[python] = r.returncode == 0
        except (OSError, subprocess.TimeoutExpired):
            _HAS_BPY[python] = False
    return _HAS_BPY[python]


def available() -> bool:
    """Whether Blender (``bpy``) can be run here (:func:`blender_python`)."""
    return blender_python() is not None


@dataclasses.dataclass
class BlenderRender:
    """Blender's renders of one file: ``images`` (K, H, W, 3) linear Rec.709 float32, one per
    seed of ``seeds``; ``alpha`` (H, W) coverage (of the first seed); ``report`` (Blender's
    version, the objects and materials its importer created, the Principled BSDF inputs);
    ``seconds`` (wall clock of the child process, Blender's start-up included)."""

    images: np.ndarray
    alpha: np.ndarray
    seeds: tuple
    report: dict
    seconds: float


def _scene_job(scene: str, out_dir: Path) -> dict:
    """The job's scene: the camera, and the sun of ``sphere-distant`` or the environment map
    of a ``sphere-env`` scene (written to ``out_dir`` as an EXR, clamped at 0 as our renderer
    loads it)."""
    job = {"camera": {k: (list(v) if isinstance(v, tuple) else v) for k, v in CAMERA.items()}}
    if scene == "sphere-distant":
        job["sun"] = {"direction": list(DISTANT_LIGHT["direction"]),
                      "irradiance": float(DISTANT_LIGHT["irradiance"])}
        return job
    try:
        spec = scene_spec(scene)
    except ValueError:
        spec = None
    if spec is None or spec.base != "sphere-env":
        raise ValueError(f"scene {scene!r} is not rebuilt in Blender; expected "
                         f"sphere-distant, sphere-env or sphere-<map>")
    path = write_exr(out_dir / "envmap.exr", load_envmap(spec.envmap))
    job["world"] = {"exr": str(path), "rotation_z_deg": ENVMAP_ROTATION_DEG}
    return job


def _run_driver(path: Path, job: dict, timeout: float) -> tuple[dict, Path, float]:
    """Run the driver on ``job`` (in a temporary directory, which ``job["out_dir"]`` names)
    and return ``(report, out_dir, seconds)``."""
    python = blender_python()
    if python is None:
        raise BlenderUnavailable(
            "no Python interpreter with bpy found: set $" + _ENV_VAR + " or run `make blender`"
            f" (looked at {', '.join(str(p) for p in _candidates())})")
    out_dir = Path(job["out_dir"])
    job_path = out_dir / "job.json"
    job_path.write_text(json.dumps(job), encoding="utf-8")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    t0 = time.perf_counter()
    try:
        r = subprocess.run([str(python), "-I", str(_DRIVER), str(job_path)],
                           capture_output=True, text=True, timeout=timeout, env=env,
                           cwd=out_dir)
    except subprocess.TimeoutExpired:
        raise BlenderFailed(f"Blender did not finish with {path} within {timeout} s") from None
    seconds = time.perf_counter() - t0
    report_path = out_dir / "report.json"
    if r.returncode != 0 or not report_path.is_file():
        tail = "\n".join((r.stdout + r.stderr).strip().splitlines()[-25:])
        raise BlenderFailed(f"Blender failed on {path} (exit status {r.returncode}):\n{tail}")
    return json.loads(report_path.read_text(encoding="utf-8")), out_dir, seconds


#: the file suffixes Blender imports here: its glTF and its USD importer
SUFFIXES = (".gltf", ".glb", ".usd", ".usda", ".usdc")


def _checked_file(path) -> Path:
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise ValueError(f"{path}: expected a file ending in {', '.join(SUFFIXES)}")
    if not path.is_file():
        raise FileNotFoundError(f"file not found: {path}")
    return path


def import_report(path, import_unused_materials: bool = False,
                  timeout: float = 600.0) -> dict:
    """Import ``path`` with Blender's glTF or USD importer (default options, or with
    ``import_unused_materials``, the USD importer's ``import_all_materials``) and return what
    it created: ``objects`` (name, type,
    materials), ``materials`` (the Principled BSDF's distribution and unlinked inputs),
    ``import_result`` and Blender's version. :class:`BlenderFailed` if the import fails."""
    path = _checked_file(path)
    with tempfile.TemporaryDirectory(prefix="brdffit-blender-") as tmp:
        job = {"file": str(path.resolve()), "out_dir": tmp, "seeds": [],
               "import_unused_materials": bool(import_unused_materials)}
        report, _, _ = _run_driver(path, job, timeout)
    return report


#: the sphere Blender renders (around, along): the scene's, as three.js's round trip
#: (:mod:`brdffit.evaluation.engines.threejs`); the polygon lies within 1 − cos(π/256) of the
#: analytic sphere of our renders
SCENE_SPHERE_SEGMENTS = (256, 128)


def render_file(path, scene: str = "sphere-distant", resolution: int = 64,
                spp: int = 64, seeds=(0, 1, 2, 3), distribution: str | None = None,
                threads: int | None = None, max_bounces: int = 1,
                timeout: float = 1800.0,
                sphere_segments: tuple[int, int] | None = SCENE_SPHERE_SEGMENTS) -> BlenderRender:
    """Import ``path`` (glTF or USD, :data:`SUFFIXES`) with Blender's importer for it (default
    options) and render it with Cycles (CPU) in ``scene``, once per seed (see the module
    docstring).

    ``distribution``: ``None`` leaves the Principled BSDF as imported; ``"GGX"`` or
    ``"MULTI_GGX"`` sets it (to measure what the importer's choice costs). ``max_bounces``:
    Cycles' path depth (1: direct light only, as our ``direct`` integrator; the sphere is
    convex). ``threads``: Cycles' threads (default: all CPUs). ``sphere_segments``: the
    imported mesh's geometry is replaced by the scene's UV sphere of that many faces (around,
    along), smooth shaded, its material kept; ``None`` renders the file's own mesh (the
    exporter's 64 × 32 preview sphere drew sharp highlights up to 0.5 % dimmer than the analytic
    sphere: ss440's mean ratio to our render of Blender's model 0.994 on it, 0.999 on 256 × 128).
    """
    path = _checked_file(path)
    resolution, spp, max_bounces = int(resolution), int(spp), int(max_bounces)
    if not 8 <= resolution <= 4096:
        raise ValueError(f"resolution: expected 8 to 4096 pixels, got {resolution}")
    if spp < 1:
        raise ValueError(f"spp: expected at least 1, got {spp}")
    if max_bounces < 0:
        raise ValueError(f"max_bounces: expected >= 0, got {max_bounces}")
    seeds = tuple(int(s) for s in seeds)
    if not seeds or len(set(seeds)) != len(seeds) or min(seeds) < 0:
        raise ValueError(f"seeds: expected distinct non-negative integers, got {seeds}")
    if distribution not in (None, "GGX", "MULTI_GGX"):
        raise ValueError(f"distribution: expected None, 'GGX' or 'MULTI_GGX', got "
                         f"{distribution!r}")
    threads = int(threads or os.cpu_count() or 1)
    with tempfile.TemporaryDirectory(prefix="brdffit-blender-") as tmp:
        job = {"file": str(path.resolve()), "out_dir": tmp, "resolution": resolution,
               "spp": spp, "seeds": list(seeds), "distribution": distribution,
               "threads": threads, "max_bounces": max_bounces,
               "sphere_segments": list(sphere_segments) if sphere_segments else None,
               "import_unused_materials": False, **_scene_job(scene, Path(tmp))}
        report, out_dir, seconds = _run_driver(path, job, timeout)
        frames = [np.load(out_dir / f"render_{s}.npy") for s in seeds]
    if not any(o["type"] == "MESH" for o in report["objects"]):
        raise BlenderFailed(f"Blender's importer created no mesh from {path}: the file "
                            "holds no mesh to render (export it with mesh='sphere')")
    report["resolution"], report["spp"], report["threads"] = resolution, spp, threads
    report["distribution_forced"] = distribution
    stack = np.stack(frames).astype(np.float32)
    return BlenderRender(np.ascontiguousarray(stack[..., :3]),
                         np.ascontiguousarray(stack[0, ..., 3]), seeds, report, seconds)


def rim_mask(alpha, fraction: float = RIM_FRACTION) -> np.ndarray:
    """Pixels farther than ``fraction`` of the sphere's projected radius from the image
    centre (the sphere is centred on the camera's axis); the radius from the coverage,
    ``R = √(Σ alpha / π)`` pixels."""
    a = np.asarray(alpha, float)
    if a.ndim != 2:
        raise ValueError(f"alpha: expected an (H, W) coverage, found shape {a.shape}")
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"fraction: expected a value in (0, 1), got {fraction}")
    h, w = a.shape
    R = np.sqrt(a.sum() / np.pi)
    y, x = np.mgrid[0:h, 0:w]
    r = np.hypot(x + 0.5 - w / 2.0, y + 0.5 - h / 2.0)
    return r > fraction * R


def _peak_pixel(img) -> list[int]:
    lum = np.asarray(img, float) @ np.array([0.2126, 0.7152, 0.0722])
    return [int(v) for v in np.unravel_index(int(np.argmax(lum)), lum.shape)]


def compare_renders(reference, reference_alpha, test, test_alpha, flip: bool = True) -> dict:
    """Blender (``test``, (K, H, W, 3)) against our render of the fit (``reference``, same
    shape), the coverage of each ((H, W) alpha); the figures of the module docstring."""
    ref = np.asarray(reference, np.float64)
    tst = np.asarray(test, np.float64)
    if ref.ndim != 4 or ref.shape != tst.shape or ref.shape[-1] != 3:
        raise ValueError(f"expected two (K, H, W, 3) stacks of the same shape, found "
                         f"{ref.shape} and {tst.shape}")
    ra, ta = np.asarray(reference_alpha, float), np.asarray(test_alpha, float)
    if ra.shape != ref.shape[1:3] or ta.shape != ref.shape[1:3]:
        raise ValueError(f"alpha: expected shape {ref.shape[1:3]}, found {ra.shape} and "
                         f"{ta.shape}")
    mask = (ra >= 0.999) & (ta >= 0.999)
    p = crn_psnr(ref, tst, mask)
    rm, tm = ref.mean(0), tst.mean(0)
    rim = rim_mask(ra) & mask

    def ratio(m):
        den = rm[m].mean(0)
        return [float(v) for v in tm[m].mean(0) / np.where(den > 0, den, np.nan)]

    out = {"psnr": p["psnr"], "psnr_se": p["psnr_se"], "resolved": p["resolved"],
           "bound": p["bound"], "batches": p["batches"], "pixels": int(mask.sum()),
           "mean_ratio": ratio(mask), "rim_ratio": ratio(rim), "rim_pixels": int(rim.sum()),
           "coverage": {"fit": float(ra.sum()), "blender": float(ta.sum())},
           "peak_pixel": {"fit": _peak_pixel(rm), "blender": _peak_pixel(tm)}}
    if flip:
        try:
            import flip_evaluator
        except ImportError:
            raise ImportError("HDR-FLIP needs NVIDIA's flip-evaluator: pip install -e "
                              "'.[engines]' (make install does), or pass flip=False") from None

        _, mean_flip, _ = flip_evaluator.evaluate(
            np.ascontiguousarray(np.maximum(rm, 0), np.float32),
            np.ascontiguousarray(np.maximum(tm, 0), np.float32), "HDR", applyMagma=False)
        out["flip"] = float(mean_flip)
    return out


def render_fit(model, scene: str = "sphere-distant", resolution: int = 64, spp: int = 64,
               seeds=(0, 1, 2, 3)):
    """Our Mitsuba render of ``model`` in ``scene``, one image per seed: ``(images (K, H, W,
    3), alpha (H, W))``."""
    r = Renderer(model, scene, None, spp, resolution)
    res = [r.render(seed=int(s)) for s in seeds]
    return np.stack([x.image for x in res]), res[0].alpha


def round_trip(model, path, scene: str = "sphere-distant", resolution: int = 64,
               spp: int = 64, seeds=(0, 1, 2, 3), distribution: str | None = None,
               fit_spp: int | None = None, flip: bool = True) -> dict:
    """Render the fit ``model`` (ours) and its exported glTF or USD file ``path`` (Blender)
    with the same seeds and compare them (:func:`compare_renders`). Returns the comparison
    plus ``blender`` (the import report) and the seconds of each side. ``fit_spp``: the spp
    of our render (default ``spp``)."""
    t0 = time.perf_counter()
    ref, ref_alpha = render_fit(model, scene, resolution, fit_spp or spp, seeds)
    fit_seconds = time.perf_counter() - t0
    b = render_file(path, scene, resolution, spp, seeds, distribution)
    out = compare_renders(ref, ref_alpha, b.images, b.alpha, flip=flip)
    out.update(scene=scene, resolution=int(resolution), spp=int(spp),
               fit_spp=int(fit_spp or spp), seeds=list(b.seeds), blender=b.report,
               seconds={"fit": fit_seconds, "blender": b.seconds})
    return out
