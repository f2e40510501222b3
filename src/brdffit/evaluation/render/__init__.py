"""Rendering BRDFs of the library with Mitsuba 3 (``llvm_ad_rgb``).

Public API (Mitsuba is imported lazily, on first use):

* :func:`render` / :func:`render_ex` / :class:`Renderer` – image of any BRDF in a scene;
* :class:`MultiRenderer` / :func:`render_models` – the reference and several models in one
  pass with common random numbers (one model-independent :class:`Proposal` fitted to the
  reference, :func:`proposal_for`), for comparisons with standard errors;
* :data:`SUITES`, :func:`scene_suite` – the paper's four-scene suite (Bagher 2016 §5);
* :func:`noise_floor` – PSNR between two seeds (Monte Carlo noise level);
* :func:`psnr`, :func:`foreground_mask` – Bagher 2016 §5 rendered PSNR;
* :func:`to_evaluator`, :func:`register_translator` – BRDF → Dr.Jit translation layer;
* :func:`resampling_error` – error of the Dr.Jit evaluator (table or closed form) vs
  ``brdf.eval``;
* :func:`make_bsdf` – the Mitsuba BSDF object (:class:`BRDFBSDF`) for custom scenes;
* :func:`scene_dict`, :data:`SCENES`, :func:`procedural_envmap`, :func:`load_envmap`,
  :func:`torus_knot`, :func:`roughness_texture`;
* :func:`available` – whether Mitsuba's LLVM back-end can be used here.

Design (details in the submodules): :mod:`.translate` turns a BRDF into a Dr.Jit
*evaluator* (:mod:`.drjit_eval`): the model's own formula/tables when a translator is known
(``MicrofacetBRDF`` with GGX/Beckmann (αx, αy, ρ) in closed form, any other isotropic
slope distribution — SGD, tabulated fits — as a radial D/Λ table with Eq. 9 roughness
scaling; Schlick Fresnel in closed form, others tabulated over cos θd; ``SumBRDF``;
per-channel fits; NPF Eq. 3-5), verified against ``brdf.eval`` before use; anything else
through a generic table (MERL grid, log-trilinear; 4D for anisotropic BRDFs).
:mod:`.plugin` wraps the evaluator in a ``mi.BSDF`` subclass; :mod:`.scenes` builds the
scenes; :mod:`.core` renders. Measured figures: ``bench/bench_render.py`` →
``bench/results/render.json``.
"""

from __future__ import annotations

from importlib import import_module

from ._mitsuba import MitsubaUnavailable, available

__all__ = ["render", "render_ex", "Renderer", "RenderResult", "noise_floor", "psnr",
           "foreground_mask", "to_evaluator", "register_translator", "resampling_error",
           "make_bsdf", "BRDFBSDF", "scene_dict", "SCENES", "procedural_envmap", "load_envmap",
           "torus_knot", "roughness_texture", "envmap_names", "available", "MitsubaUnavailable",
           "is_reciprocal", "describe_evaluator", "MultiRenderer", "MultiRenderResult",
           "render_models", "Proposal", "proposal_for", "SUITES", "scene_suite",
           "envmap_stats"]

_LAZY = {
    "render": ".core", "render_ex": ".core", "Renderer": ".core", "RenderResult": ".core",
    "noise_floor": ".core", "psnr": ".core", "foreground_mask": ".core",
    "to_evaluator": ".translate", "register_translator": ".translate",
    "resampling_error": ".translate", "is_reciprocal": ".translate",
    "describe_evaluator": ".core",
    "make_bsdf": ".plugin", "BRDFBSDF": ".plugin",
    "scene_dict": ".scenes", "SCENES": ".scenes", "procedural_envmap": ".scenes",
    "load_envmap": ".scenes", "torus_knot": ".scenes", "roughness_texture": ".scenes",
    "envmap_names": ".scenes", "SUITES": ".scenes", "scene_suite": ".scenes",
    "envmap_stats": ".scenes",
    "MultiRenderer": ".core", "MultiRenderResult": ".core", "render_models": ".core",
    "Proposal": ".proposal", "proposal_for": ".proposal",
}


def __getattr__(name):
    if name in _LAZY:
        return getattr(import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
