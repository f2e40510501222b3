"""Evaluation: rendering, error metrics, plots and the HTML comparison report.

* :mod:`.render` – Mitsuba 3 rendering of any BRDF of the library (``render``)
* :mod:`.metrics` – rendered PSNR (Bagher et al. 2016 §5), CIE dE2000 images, BRDF-space
  metrics (cosine-weighted relative error; normalised L2 of Bagher et al. 2012 §6.3 from
  :mod:`brdffit.losses.l2`; the compressive objective of Bagher et al. 2016 from
  :mod:`brdffit.losses.objective`), wins
  and ties within 2 dB
* :mod:`.plots` – lobes in the incidence plane, fitted factors, slices
* :mod:`.compare` / :mod:`.report` – fit, render, measure and write the static HTML report
* :mod:`.tonemap`, :mod:`.imageio` – NPF tone mapping, EXR/PNG output

The functions ``compare``, ``render`` and ``tonemap`` share their name with their module:
use ``brdffit.evaluation.compare.compare`` etc. Names are imported lazily so that ``import brdffit.evaluation`` stays cheap (no matplotlib,
colour-science or Mitsuba until used).
"""

from __future__ import annotations

from importlib import import_module

_LAZY = {
    "rendered_psnr": ".metrics", "delta_e2000_image": ".metrics", "mean_delta_e2000": ".metrics",
    "colorize_delta_e": ".metrics", "cosine_weighted_relative_error": ".metrics",
    "brdf_metrics": ".metrics", "count_wins": ".metrics", "normalized_l2": ".metrics",
    "compressive_objective": ".metrics",
    "plot_lobes": ".plots", "plot_factors": ".plots", "plot_slices": ".plots",
    "compare_many": ".compare",
    "write_index": ".report", "write_material_page": ".report", "summarize": ".report",
}

__all__ = sorted(_LAZY)


def __getattr__(name):
    if name in _LAZY:
        return getattr(import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
