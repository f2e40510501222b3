"""The live viewer of a material page: the fits' glTF exports in three.js, beside the reference.

A material page whose result has an environment-map sphere scene (``sphere-env``, e.g.
``sphere-courtyard``) and at least one model with a ``.gltf`` export gets a section with the
reference rendering of that scene and a canvas where three.js (r187, ``MeshPhysicalMaterial``
through its own ``GLTFLoader``) shows the export on a unit sphere:

* lit by the scene's environment map only, through three's image-based lighting (the map
  prefiltered by ``PMREMGenerator``; the split-sum approximation of Karis 2013, not the
  Monte Carlo integral of our renders), downsampled to :data:`ENV_WIDTH` × ``ENV_WIDTH/2``
  (area average weighted by sin θ, so the map's power is kept) and carried as half floats;
* the map turned into three's equirectangular convention (:func:`three_equirect`): Mitsuba's
  lat-long has row 0 at the zenith and ``u = atan2(x, −z)/2π``, three's has ``v`` = 0 at the
  nadir and ``u = atan2(z, x)/2π + 1/2``, so the columns roll by a quarter turn and the rows
  flip;
* the scenes' camera (:data:`~brdffit.evaluation.render.scenes.CAMERA`; three's vertical field
  of view equals Mitsuba's horizontal one on the square canvas), orbit controls around the
  origin;
* the page's tone map ``(1 − 2^(−exposure·x))^(1/γ)`` with the scene's exposure and γ (three's
  custom tone mapping, no output sRGB conversion), black background (hidden emitter).

Everything runs from ``file://`` offline: three, its ``OrbitControls`` and ``GLTFLoader`` and
the viewer's code are one classic script (``engines/threejs_page/vendor/viewer.bundle.js``,
built by ``tools/build_viewer_bundle.py``) copied once to ``OUT/assets/`` (:data:`ASSET`); the
material, the map and the settings are JSON in a ``<script type="application/json">`` of the
page, with ``<``, ``>`` and ``&`` escaped (:func:`json_script`), read by the viewer as text.
With JavaScript off the reference image stays and the canvas says it needs JavaScript.
"""

from __future__ import annotations

import base64
import html
import json
import math
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np

from .._atomic import atomic_write
from ..errors import printable
from .render.scenes import CAMERA, envmap_names, load_envmap

__all__ = ["BUNDLE", "ASSET", "ENV_WIDTH", "viewer_scene", "environment_image",
           "three_equirect", "environment_data", "material_document", "json_script",
           "copy_bundle", "viewer_sections"]

#: the viewer's classic-script bundle (package data)
BUNDLE = Path(__file__).parent / "engines" / "threejs_page" / "vendor" / "viewer.bundle.js"
#: where a report keeps it, relative to the report's folder
ASSET = "assets/three-viewer.js"
#: width of the environment map sent to the page (height ENV_WIDTH / 2)
ENV_WIDTH = 256
#: glTF files larger than this are not inlined (bytes)
MAX_GLTF_BYTES = 8 << 20
_DATA_ID = "brdffit-viewer-data"


def _e(s) -> str:
    return html.escape(printable(str(s)), quote=True)


def _positive(x) -> bool:
    return (isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
            and x > 0)


def viewer_scene(result: dict) -> dict | None:
    """The first rendered ``sphere-env`` scene of ``result`` whose map the viewer can load
    (the procedural one or a shared map by name) and whose tone map is valid, else ``None``."""
    for sc in result.get("scenes") or []:
        if (isinstance(sc, dict) and sc.get("base") == "sphere-env" and not sc.get("error")
                and (sc.get("envmap") is None or sc.get("envmap") in envmap_names())
                and _positive(sc.get("exposure")) and _positive(sc.get("gamma"))):
            return sc
    return None


def _overlap(n_in: int, n_out: int) -> np.ndarray:
    """``(n_out, n_in)`` lengths of the overlaps of the two partitions of [0, 1]."""
    a, b = np.arange(n_in + 1) / n_in, np.arange(n_out + 1) / n_out
    lo = np.maximum(b[:-1, None], a[None, :-1])
    hi = np.minimum(b[1:, None], a[None, 1:])
    return np.clip(hi - lo, 0.0, None)


@lru_cache(maxsize=8)
def _environment_image(envmap: str | None, width: int) -> np.ndarray:
    img = load_envmap(envmap).astype(np.float64)
    h, w = img.shape[:2]
    rows = _overlap(h, width // 2) * np.sin((np.arange(h) + 0.5) / h * np.pi)[None, :]
    cols = _overlap(w, width)
    rows /= rows.sum(1, keepdims=True)
    cols /= cols.sum(1, keepdims=True)
    out = np.einsum("jw,iwc->ijc", cols, np.tensordot(rows, img, axes=(1, 0)))
    return out.astype(np.float32)


def environment_image(envmap: str | None = None, width: int = ENV_WIDTH) -> np.ndarray:
    """The map the viewer gets, in Mitsuba's lat-long convention: ``(width/2, width, 3)``
    float32, the area average of :func:`~brdffit.evaluation.render.scenes.load_envmap`'s map
    weighted by sin θ (a copy)."""
    if width < 8 or width % 4:
        raise ValueError(f"environment width must be a multiple of 4, ≥ 8, got {width}")
    return _environment_image(envmap, int(width)).copy()


def three_equirect(img: np.ndarray) -> np.ndarray:
    """A Mitsuba lat-long map as three's ``DataTexture`` rows (module docstring)."""
    return np.roll(img, img.shape[1] // 4, axis=1)[::-1]


def environment_data(envmap: str | None = None, width: int = ENV_WIDTH) -> dict:
    """The viewer's map: ``width``, ``height`` and ``rgb_f16`` (base64 of little-endian half
    floats, RGB, :func:`three_equirect` order; values clamped to the half range)."""
    img = three_equirect(environment_image(envmap, width))
    half = np.clip(img, 0.0, 65504.0).astype("<f2")
    return {"width": int(img.shape[1]), "height": int(img.shape[0]),
            "rgb_f16": base64.b64encode(np.ascontiguousarray(half).tobytes()).decode("ascii")}


def material_document(path: Path) -> dict | None:
    """The viewer's copy of a glTF export: its ``asset``, material 0 and ``extensionsUsed``
    (the preview mesh is left out: the viewer has its own sphere); ``None`` when the file is
    not a readable glTF with a material."""
    try:
        if path.stat().st_size > MAX_GLTF_BYTES:
            return None
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    mats = doc.get("materials") if isinstance(doc, dict) else None
    if not isinstance(mats, list) or not mats or not isinstance(mats[0], dict):
        return None
    out = {"asset": doc.get("asset") or {"version": "2.0"}, "materials": [mats[0]]}
    if isinstance(doc.get("extensionsUsed"), list):
        out["extensionsUsed"] = doc["extensionsUsed"]
    return out


def _gltf_models(mdir: Path, result: dict) -> list[dict]:
    """``[{"name", "gltf"}]`` of the page's fitted models with a glTF export inside ``mdir``."""
    out, root = [], mdir.resolve()
    for m in result.get("models") or []:
        if not isinstance(m, dict) or m.get("status", "ok") != "ok":
            continue
        rel = next((f for f in m.get("exports") or []
                    if isinstance(f, str) and f.lower().endswith(".gltf")), None)
        if rel is None or rel.startswith("/") or "\\" in rel:
            continue
        path = (root / rel).resolve()
        doc = material_document(path) if path.is_relative_to(root) else None
        if doc is not None:
            out.append({"name": str(m.get("name", "model")), "gltf": doc})
    return out


def json_script(obj, element_id: str) -> str:
    """``obj`` as a ``<script type="application/json">`` element: standard JSON, ASCII, with
    ``<``, ``>`` and ``&`` as ``\\u`` escapes so that no string in it can end the element."""
    text = json.dumps(obj, ensure_ascii=True, allow_nan=False, separators=(",", ":"))
    text = text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
    return f'<script type="application/json" id="{_e(element_id)}">{text}</script>'


@lru_cache(maxsize=1)
def _bundle_bytes() -> bytes | None:
    return BUNDLE.read_bytes() if BUNDLE.is_file() else None


def copy_bundle(out_dir) -> bool:
    """Put the bundle at ``OUT/``:data:`ASSET` unless an identical copy is there; ``False``
    when this installation has no bundle."""
    data = _bundle_bytes()
    if data is None:
        return False
    dest = Path(out_dir) / ASSET
    if not (dest.is_file() and dest.stat().st_size == len(data) and dest.read_bytes() == data):
        dest.parent.mkdir(parents=True, exist_ok=True)
        with atomic_write(dest, "wb") as fh:       # pages of a batch may be written at once
            fh.write(data)
    return True


def viewer_sections(out_dir, mdir: Path, result: dict, disp: int,
                    cell: Callable[[str, str, int, str], str]) -> list[str]:
    """The page's viewer section (``[]`` without an environment-map sphere scene or a glTF
    export). ``cell(src, alt, width, caption)`` draws the reference image as the page does."""
    sc = viewer_scene(result)
    models = _gltf_models(Path(mdir), result) if sc is not None else []
    ref = sc.get("reference") if sc is not None else None
    if not models or not isinstance(ref, dict) or not isinstance(ref.get("png"), str):
        return []
    name = str(sc.get("name"))
    head = f"<h2>Live viewer: glTF exports in three.js, {_e(name)}</h2>"
    if not copy_bundle(out_dir):
        return [head + '<p class="fail">Live viewer not available: this installation has no '
                "three.js bundle (engines/threejs_page/vendor/viewer.bundle.js).</p>"]
    data = {"size": int(disp), "exposure": float(sc["exposure"]), "gamma": float(sc["gamma"]),
            "camera": {k: [float(x) for x in CAMERA[k]] for k in ("origin", "target", "up")}
            | {"fov": float(CAMERA["fov_degrees"])},
            "environment": environment_data(sc.get("envmap")), "models": models}
    note = ("<p class=\"note\">Each fit's glTF export (material 0) on a unit sphere in three.js, "
            f"lit by the map of {_e(name)} alone ({ENV_WIDTH}×{ENV_WIDTH // 2}, three's "
            "prefiltered image-based lighting, not our path-traced integral), with the "
            "scenes' camera and the page's tone map; drag to orbit. Offline, from the "
            "report's assets folder.</p>")
    canvas = (f'<div class="cell"><canvas width="{int(disp)}" height="{int(disp)}" '
              f'style="width:{int(disp)}px;height:{int(disp)}px;background:#000;'
              'border:1px solid #999;display:block"></canvas>'
              '<b class="viewer-model"></b><select aria-label="model" hidden></select><br>'
              '<span class="viewer-status">Live viewer: needs JavaScript and WebGL.</span></div>')
    ref_cell = cell(ref["png"], f"reference rendering, {name}", disp,
                    "<b>Reference</b><br>&nbsp;")
    return [head + note + f'<div class="grid" data-brdffit-viewer="{_DATA_ID}">' + ref_cell
            + canvas + "</div>" + json_script(data, _DATA_ID)
            + f'<script src="../{ASSET}"></script>']
