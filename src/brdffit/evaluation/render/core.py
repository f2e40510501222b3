"""Rendering entry points: :func:`render`, :func:`render_ex`, :func:`noise_floor`.

A render builds the Dr.Jit evaluator of the BRDF (:func:`.translate.to_evaluator`), wraps it
in the Mitsuba plugin (:class:`.plugin.BRDFBSDF`), loads the named scene
(:func:`.scenes.scene_dict`) and runs Mitsuba's ``direct`` (sphere scenes) or ``path``
(knot) integrator, both with MIS between the BSDF's sampling and emitter sampling. Output
is linear RGB ``(H, W, 3)`` float32 in the units of the lights (environment radiance ×
BRDF); the film's alpha gives the coverage and the foreground mask (pixels fully covered by the object, as Bagher 2016 §5 counts for PSNR).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..metrics import rendered_psnr as psnr  # Bagher 2016 §5 (one implementation)

__all__ = ["RenderResult", "Renderer", "render", "render_ex", "noise_floor", "psnr",
           "foreground_mask"]


@dataclasses.dataclass
class RenderResult:
    """A rendering: ``image`` (H, W, 3) linear float32, ``alpha`` (H, W) coverage,
    ``mask`` (H, W) bool foreground, ``seconds`` (render only, excluding set-up, wall
    clock), ``cpu_seconds`` (CPU time of the process during the render, all threads: a
    load-independent cost on a shared machine),
    ``setup_seconds`` (tabulation, translation, scene load) and ``info`` (scene, spp, seed,
    evaluator path/kind)."""

    image: np.ndarray
    alpha: np.ndarray
    mask: np.ndarray
    seconds: float
    setup_seconds: float
    info: dict
    cpu_seconds: float = float("nan")


def foreground_mask(alpha, threshold: float = 0.999) -> np.ndarray:
    """Pixels fully covered by the object (coverage ≥ ``threshold``)."""
    return np.asarray(alpha) >= threshold


def describe_evaluator(ev) -> str:
    """Short description of a Dr.Jit evaluator (kind and, for microfacet ones, components)."""
    d = getattr(ev, "describe", None)
    return d() if callable(d) else getattr(ev, "kind", type(ev).__name__)


class Renderer:
    """A prepared scene for one BRDF: build once, render with several seeds/spp.

    Parameters as :func:`render`; ``mode`` is passed to :func:`.translate.to_evaluator`
    (``"auto"``, ``"table"``, ``"closed"``); ``evaluator`` bypasses translation.
    """

    def __init__(self, brdf=None, scene: str = "sphere-env", envmap=None, spp: int = 256,
                 resolution: int = 256, mode: str = "auto", evaluator=None,
                 alpha_texture=None):
        from ._mitsuba import load

        self.mi, self.dr = load()
        from .plugin import make_bsdf
        from .scenes import roughness_texture, scene_dict
        from .translate import to_evaluator

        t0 = time.perf_counter()
        if evaluator is None:
            if brdf is None:
                raise ValueError("Renderer needs a brdf or an evaluator")
            evaluator = to_evaluator(brdf, mode=mode)
        self.evaluator = evaluator
        if scene == "sphere-svrough" and alpha_texture is None:
            alpha_texture = roughness_texture()
        if alpha_texture is not None and not getattr(evaluator, "supports_roughness", False):
            import warnings

            warnings.warn(f"the {getattr(evaluator, 'kind', 'table')} evaluator has no "
                          "microfacet roughness: the roughness texture is ignored (only "
                          "microfacet models, closed-form or tabulated, support Eq. 9 scaling)",
                          RuntimeWarning, stacklevel=2)
        self.bsdf = make_bsdf(evaluator, alpha_texture=alpha_texture)
        self.scene_name, self.spp, self.resolution = scene, int(spp), int(resolution)
        self.envmap = envmap
        self.scene = self.mi.load_dict(scene_dict(self.bsdf, scene, envmap, spp, resolution))
        self.setup_seconds = time.perf_counter() - t0

    def render(self, seed: int = 0, spp: int | None = None) -> RenderResult:
        spp = self.spp if spp is None else int(spp)
        t0, c0 = time.perf_counter(), time.process_time()
        img = self.mi.render(self.scene, seed=int(seed), spp=spp)
        arr = np.array(img, dtype=np.float32)  # forces evaluation
        seconds = time.perf_counter() - t0
        cpu = time.process_time() - c0
        rgb = np.ascontiguousarray(arr[..., :3])
        alpha = np.ascontiguousarray(arr[..., 3]) if arr.shape[-1] > 3 else np.ones(arr.shape[:2], np.float32)
        info = {"scene": self.scene_name, "spp": spp, "seed": int(seed),
                "resolution": self.resolution,
                "envmap": None if self.envmap is None or isinstance(self.envmap, np.ndarray)
                else str(self.envmap),
                "evaluator": describe_evaluator(self.evaluator),
                "path": getattr(self.evaluator, "path", None)}
        return RenderResult(rgb, alpha, foreground_mask(alpha), seconds, self.setup_seconds, info,
                            cpu)


def render_ex(brdf, scene: str = "sphere-env", envmap=None, spp: int = 256,
              resolution: int = 256, seed: int = 0, mode: str = "auto",
              alpha_texture=None) -> RenderResult:
    """Render ``brdf`` and return a :class:`RenderResult` (image, alpha, mask, timings)."""
    return Renderer(brdf, scene, envmap, spp, resolution, mode,
                    alpha_texture=alpha_texture).render(seed)


def render(brdf, scene: str = "sphere-env", envmap=None, spp: int = 256, resolution: int = 256,
           seed: int = 0, mode: str = "auto", return_mask: bool = False):
    """Render any BRDF of the library with Mitsuba 3; linear ``(H, W, 3)`` float32.

    ``scene``: one of :data:`.scenes.SCENES`; ``envmap``: ``None`` (procedural), a name of
    ``../shared/data/envmaps`` or an EXR path; ``mode``: evaluator choice (``"auto"``,
    ``"table"``, ``"closed"``). With ``return_mask=True`` returns ``(image, mask)`` where
    ``mask`` marks fully covered foreground pixels.
    """
    res = render_ex(brdf, scene, envmap, spp, resolution, seed, mode)
    return (res.image, res.mask) if return_mask else res.image


def noise_floor(brdf, scene: str = "sphere-env", envmap=None, spp: int = 256,
                resolution: int = 256, seeds=(0, 1), mode: str = "auto") -> dict:
    """Monte Carlo noise floor: PSNR (Bagher 2016 §5) between two renders of the same BRDF
    with different seeds. A model-vs-reference PSNR difference is only meaningful when it is
    clearly below this value. Returns ``{"psnr": ..., "seeds": ..., "spp": ..., ...}``."""
    r = Renderer(brdf, scene, envmap, spp, resolution, mode)
    a, b = r.render(seeds[0]), r.render(seeds[1])
    return {"psnr": psnr(a.image, b.image, a.mask), "seeds": list(seeds), "spp": int(spp),
            "resolution": int(resolution), "scene": scene,
            "render_seconds": [a.seconds, b.seconds], "path": a.info["path"]}
