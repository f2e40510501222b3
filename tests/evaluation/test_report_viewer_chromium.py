"""The report's live viewer in headless Chromium, opened from ``file://`` as a user would.

One material page (a red plastic in the form of a ggx-diffuse fit, exported to glTF; the
procedural environment of ``sphere-env``; 96² canvas) is written by the report, opened with
``#brdffit-viewer-image`` so that the viewer leaves its canvas as a PNG on its element, and
read back with ``--dump-dom``. The model's name is hostile (it tries to end the JSON script
and to inject markup): the viewer must still run and show the name as text.

"Our render of the export": Mitsuba renders the export as three.js shades it
(:class:`~brdffit.evaluation.engines.threejs_brdf.ThreeJSBRDF` of the file) in the same scene
with the map the viewer gets (:func:`~brdffit.evaluation.report_viewer.environment_image`),
tone-mapped as the page and quantised to 8 bits. Tolerances (stated; measured on this
material at 96², 256 spp: PSNR 29.4 dB over the sphere in display values, mean ratio 0.999 /
1.017 / 1.024, lit pixels 1.6 % above the analytic πR² (the antialiased silhouette); with the
map turned half a turn the PSNR falls to 19.7 dB; 18 s with Chromium's start):

* coverage: the pixels the canvas lights within 3 % of πR²;
* PSNR ≥ 26 dB over the sphere (display values in [0, 1]), per-channel mean ratio within
  ±5 %: three's image-based lighting is the split-sum approximation of a prefiltered
  256 × 128 map, not our Monte Carlo integral, and the sun of the map is sharper than its
  prefiltered levels;
* the check can fail: against the map turned half a turn it is below 26 dB.

An end-to-end report test: it runs in the mode users run, not in Dr.Jit's debug mode.
"""

from __future__ import annotations

import base64
import html
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from brdffit.evaluation import report as R
from brdffit.evaluation import report_viewer as V
from brdffit.evaluation.engines import threejs as T
from brdffit.evaluation.engines import threejs_brdf as TB
from brdffit.evaluation.imageio import read_png, write_png
from brdffit.evaluation.render.scenes import scene_exposure
from brdffit.evaluation.tonemap import tonemap
from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel

RES = 96
HOSTILE = ('ggx </script><script>document.documentElement.dataset.pwned="1"</script>'
           '<img src=x onerror=alert(1)> & "q"')
pytestmark = [pytest.mark.skipif(T.chromium_path() is None, reason="needs Chromium"),
              pytest.mark.skipif(not V.BUNDLE.is_file(), reason="the viewer bundle is absent")]


def _display(image, exposure) -> np.ndarray:
    """Our tone map and 8-bit quantisation, as the page's PNGs."""
    return np.round(np.clip(tonemap(image, exposure, 2.2), 0.0, 1.0) * 255.0) / 255.0


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    from brdffit.export.gltf import write_gltf
    from brdffit.evaluation.render import Renderer, available

    if not available():
        pytest.skip("needs Mitsuba 3 with the LLVM back-end")
    out = tmp_path_factory.mktemp("viewer")
    mdir = out / "plastic"
    fit = MicrofacetBRDF(GGX(0.19, 0.19), SchlickFresnel([0.035, 0.063, 0.093]),
                         diffuse=[0.43, 0.043, 0.024])
    write_gltf(fit, mdir / "exports" / "fit.gltf", fidelity=False)
    exposure = scene_exposure("sphere-env", None)
    export = TB.from_gltf(mdir / "exports" / "fit.gltf")
    env = V.environment_image(None)
    ours = Renderer(export, "sphere-env", env, 256, RES).render(0)
    turned = Renderer(export, "sphere-env", np.roll(env, env.shape[1] // 2, axis=1), 256,
                      RES).render(0)
    write_png(mdir / "ref.png", tonemap(ours.image, exposure, 2.2))
    result = {"material": "plastic", "slug": "plastic", "scene": {"resolution": RES},
              "scenes": [{"name": "sphere-env", "base": "sphere-env", "envmap": None,
                          "exposure": exposure, "gamma": 2.2, "reference": {"png": "ref.png"}}],
              "models": [{"name": HOSTILE, "status": "ok", "exports": ["exports/fit.gltf"]}]}
    path = R.write_material_page(out, result)
    return path, _display(ours.image, exposure), ours.alpha, _display(turned.image, exposure)


def _open(path: Path, profile: Path) -> str:
    args = T._chromium_args(T.chromium_path(), profile) + [
        "--virtual-time-budget=20000", "--dump-dom",
        path.resolve().as_uri() + "#brdffit-viewer-image"]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def _psnr(a, b, mask) -> float:
    return float(10.0 * np.log10(1.0 / np.mean((a[mask] - b[mask]) ** 2)))


def test_viewer_shows_the_export_as_our_render(page, tmp_path):
    path, ours, alpha, turned = page
    dom = _open(path, tmp_path / "profile")
    assert "data-pwned" not in dom                     # the hostile name stayed text
    status = re.search(r'data-viewer-status="([^"]*)"', dom)
    assert status and status.group(1) == "ok", re.findall(r'viewer-status">([^<]*)', dom)
    shown = re.search(r'data-viewer-model="([^"]*)"', dom)
    assert shown and html.unescape(shown.group(1)) == HOSTILE
    label = re.search(r'class="viewer-model">([^<]*)<', dom)
    assert label and html.unescape(label.group(1)) == "glTF of " + HOSTILE
    m = re.search(r'data-viewer-image="data:image/png;base64,([^"]*)"', dom)
    assert m, "the viewer left no image"
    canvas_png = tmp_path / "canvas.png"
    canvas_png.write_bytes(base64.b64decode(m.group(1)))
    canvas = read_png(canvas_png)[..., :3].astype(np.float64) / 255.0
    assert canvas.shape == ours.shape
    _, _, radius = T.sphere_geometry_px(RES)
    lit = int((canvas.max(-1) > 2.0 / 255.0).sum())
    assert abs(lit / (np.pi * radius**2) - 1.0) < 0.03, lit
    mask = alpha >= 0.999
    psnr = _psnr(canvas, ours, mask)
    ratio = canvas[mask].mean(0) / ours[mask].mean(0)
    print(f"viewer vs our render of the export: PSNR {psnr:.1f} dB, mean ratio "
          f"{np.round(ratio, 3).tolist()}, lit {lit} px vs πR² {np.pi * radius**2:.0f}; "
          f"map turned: {_psnr(canvas, turned, mask):.1f} dB")
    assert psnr >= 26.0
    assert np.all(np.abs(ratio - 1.0) < 0.05), ratio
    assert _psnr(canvas, turned, mask) < 26.0
