"""Rendering BRDFs of the library with Mitsuba 3 (``llvm_ad_rgb``), issue 5.

Public API (Mitsuba is imported lazily, on first use):

* :func:`render` / :func:`render_ex` / :class:`Renderer` – image of any BRDF in a scene;
* :func:`noise_floor` – PSNR between two seeds (Monte Carlo noise level);
* :func:`psnr`, :func:`foreground_mask` – Bagher 2016 §5 rendered PSNR;
* :func:`to_evaluator`, :func:`register_translator` – BRDF → Dr.Jit translation layer;
* :func:`resampling_error` – error of the Dr.Jit evaluator (table or closed form) vs
  ``brdf.eval``;
* :func:`make_bsdf` – the Mitsuba BSDF object (:class:`BRDFBSDF`) for custom scenes;
* :func:`scene_dict`, :data:`SCENES`, :func:`procedural_envmap`, :func:`load_envmap`,
  :func:`torus_knot`, :func:`roughness_texture`;
* :func:`available` – whether Mitsuba's LLVM back-end can be used here.
"""

from __future__ import annotations

from importlib import import_module

from ._mitsuba import MitsubaUnavailable, available

__all__ = ["render", "render_ex", "Renderer", "RenderResult", "noise_floor", "psnr",
           "foreground_mask", "to_evaluator", "register_translator", "resampling_error",
           "make_bsdf", "BRDFBSDF", "scene_dict", "SCENES", "procedural_envmap", "load_envmap",
           "torus_knot", "roughness_texture", "envmap_names", "available", "MitsubaUnavailable"]

_LAZY = {
    "render": ".core", "render_ex": ".core", "Renderer": ".core", "RenderResult": ".core",
    "noise_floor": ".core", "psnr": ".core", "foreground_mask": ".core",
    "to_evaluator": ".translate", "register_translator": ".translate",
    "resampling_error": ".translate",
    "make_bsdf": ".plugin", "BRDFBSDF": ".plugin",
    "scene_dict": ".scenes", "SCENES": ".scenes", "procedural_envmap": ".scenes",
    "load_envmap": ".scenes", "torus_knot": ".scenes", "roughness_texture": ".scenes",
    "envmap_names": ".scenes",
}


def __getattr__(name):
    if name in _LAZY:
        return getattr(import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
