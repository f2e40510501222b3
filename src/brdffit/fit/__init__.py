"""Fitting methods, one module per paper.

* :mod:`.tabulated` – Dupuy et al. 2015, tabulated slope-space NDF by power iteration, and the
  GGX/Beckmann conversions by slope moments (``fit_tabulated``, ``fit_ggx``, ``fit_beckmann``)
* :mod:`.sgd` – Bagher, Soler, Holzschuch 2012, Shifted Gamma Distribution (``fit_sgd``) and
  the two-slice / full-data analytic fits
* :mod:`.npf` – Bagher, Snyder, Nowrouzezahrai 2016, non-parametric factor model (``fit_npf``)
* :mod:`.analytic` – GGX/Beckmann + Lambert with Schlick F0 fitted on the whole data with the
  compressive objective of Bagher 2016 (``fit_ggx_diffuse``, ``fit_beckmann_diffuse``)
"""

from __future__ import annotations

from importlib import import_module

_MODULES = ("tabulated", "sgd", "npf", "analytic")
_EXPORTS = {
    "fit_tabulated": "tabulated", "fit_ggx": "tabulated", "fit_beckmann": "tabulated",
    "fit_sgd": "sgd", "fit_beckmann_two_slice": "sgd", "fit_ggx_two_slice": "sgd",
    "fit_cook_torrance": "sgd", "fit_npf": "npf",
    "fit_ggx_diffuse": "analytic", "fit_beckmann_diffuse": "analytic",
    "fit_analytic_diffuse": "analytic",
}


def import_all() -> None:
    """Import every fitting module that exists (registers their fit-file model kinds)."""
    for name in _MODULES:
        try:
            import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise


def __getattr__(name):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
