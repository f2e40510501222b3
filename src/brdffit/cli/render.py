"""``brdffit render INPUT_OR_FIT -o image.exr|png``: render one BRDF with Mitsuba 3.

INPUT is anything :func:`brdffit.load` reads (MERL, RGL, UTIA, Neural-BRDF
``collection.zip:material``, ``synthetic:NAME``) or a fit file written by
:func:`brdffit.io.fitfile.save_fit`. ``.exr`` output is linear RGBA (alpha = coverage);
``.png`` is tone-mapped with Bagher 2016 §5 (``--exposure auto`` by default: see
:mod:`brdffit.evaluation.tonemap` for why the paper's 0.02 is too dark in our units).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._atomic import WRITE_THROUGH
from ..errors import BRDFError, printable
from ..evaluation.imageio import read_image, write_exr, write_png
from ..evaluation.render import Renderer
from ..evaluation.render.scenes import SCENES
from ..evaluation.render.translate import resampling_error
from ..evaluation.tonemap import tonemap
from ..io.fitfile import is_fit_file, load_fit
from ..loading import load
from ._checks import check_render_size, output_file
from ._parsing import usage_error

__all__ = ["render_cmd", "load_brdf"]


def load_brdf(spec: str):
    """A fit file (``.npz`` with a brdffit header) via ``load_fit``, anything else via
    ``brdffit.load``."""
    p = Path(spec)
    if p.suffix.lower() == ".npz" and p.is_file() and is_fit_file(p):
        return load_fit(p)
    return load(spec)


def render_cmd(spec: str, output: Path, scene: str = "sphere-env", envmap: str | None = None,
               spp: int = 256, resolution: int = 256, seed: int = 0, mode: str = "auto",
               exposure: str = "auto", gamma: float = 2.2,
               roughness_texture: Path | None = None, report_error: bool = False) -> None:
    """Run ``brdffit render`` (its options: :func:`brdffit.cli._commands.render`)."""
    if scene not in SCENES:
        raise usage_error("--scene", f"expected one of {', '.join(SCENES)}, found {scene!r}")
    if mode not in ("auto", "table", "closed"):
        raise usage_error("--mode", f"expected auto, table or closed, found {mode!r}")
    expo = exposure
    check_render_size(resolution, spp)
    # a device or FIFO (no extension) gets a PNG
    ext = ".png" if output_file(output, (".exr", ".png")) in WRITE_THROUGH else \
        output.suffix.lower()
    brdf = load_brdf(spec)
    env = None if envmap in (None, "", "procedural", "default") else envmap
    tex = None
    if roughness_texture is not None:
        t = read_image(roughness_texture)
        tex = (t[..., 0].astype(np.float64) if t.dtype != np.uint8
               else t[..., 0].astype(np.float64) * (2.0 / 255.0))
        tex = np.maximum(np.nan_to_num(tex, nan=1.0), 0.05)
    r = Renderer(brdf, scene=scene, envmap=env, spp=spp, resolution=resolution, mode=mode,
                 alpha_texture=tex)
    res = r.render(seed)
    if not np.all(np.isfinite(res.image)):
        raise BRDFError(f"{spec}: rendering produced non-finite pixels")
    if ext == ".exr":
        write_exr(output, np.concatenate([res.image, res.alpha[..., None]], -1))
    else:
        rgb = tonemap(res.image, expo, gamma, mask=res.mask)
        write_png(output, np.concatenate([rgb, np.clip(res.alpha, 0, 1)[..., None]], -1))
    print(printable(f"{output}: {scene} {resolution}x{resolution} {spp} spp, evaluator "
                    f"{res.info['evaluator']} ({res.info['path']}), set-up "
                    f"{r.setup_seconds:.2f} s, render {res.seconds:.2f} s"))
    if report_error:
        e = resampling_error(brdf, r.evaluator)
        print(f"resampling error vs brdf.eval: cosine-weighted relative {e['rel_cos']:.3g}, "
                   f"RMS {e['rel_rms']:.3g}, albedo {e['albedo_rel']:.3g}")
