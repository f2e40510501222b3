"""An engine's render of an environment-map scene against our render of the engine's model,
in the same scene and with the map turned half a turn (the engine round-trip tests)."""

from __future__ import annotations

import numpy as np

from brdffit.evaluation.engines import threejs as T
from brdffit.evaluation.render import Renderer
from brdffit.evaluation.render.scenes import load_envmap


def compare_with_turned_map(engine_render, model, scene: str, resolution: int):
    """``(same, turned)``: :func:`~brdffit.evaluation.engines.threejs.compare_render` of the
    engine's image against 3 × 64 spp Mitsuba renders of ``model`` in ``scene``, and against
    the same with the scene's map turned half a turn about the vertical axis."""
    refs, ra = T.reference_renders(model, scene, resolution=resolution, spp=64, batches=3)
    same = T.compare_render(engine_render.image, engine_render.alpha, refs, ra)
    env = load_envmap(T.resolve_scene(scene)[1])
    turned = Renderer(model, "sphere-env", np.roll(env, env.shape[1] // 2, axis=1), 64,
                      resolution)
    other = T.compare_render(engine_render.image, engine_render.alpha,
                             np.stack([turned.render(s).image for s in range(3)]), ra)
    print(f"{scene}: PSNR {same['psnr']:.1f} ± {same['psnr_se']:.2f} dB, mean "
          f"{np.round(same['mean_ratio'], 3).tolist()}, rim "
          f"{np.round(same['rim_ratio'], 3).tolist()}; turned {other['psnr']:.1f} dB, mean "
          f"{np.round(other['mean_ratio'], 3).tolist()}")
    return same, other
