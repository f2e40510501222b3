"""Fitting methods, one module per paper.

* :mod:`.tabulated` – Dupuy et al. 2015, tabulated slope-space NDF by power iteration, and the
  GGX/Beckmann conversions by slope moments (``fit_tabulated``, ``fit_ggx``, ``fit_beckmann``)
* :mod:`.sgd` – Bagher, Soler, Holzschuch 2012, Shifted Gamma Distribution (``fit_sgd``) and
  the two-slice / full-data analytic fits
* :mod:`.npf` – Bagher, Snyder, Nowrouzezahrai 2016, non-parametric factor model (``fit_npf``)
* :mod:`.analytic` – GGX/Beckmann + Lambert with Schlick F0 fitted on the whole data with the
  compressive objective of Bagher 2016 (``fit_ggx_diffuse``, ``fit_beckmann_diffuse``)
* :mod:`.registry` – every model by its name (the names of ``brdffit models`` and the CLI)
* :mod:`.result` – :class:`~.result.FitResult`, a scipy-style view of any fit's report

This package is also callable: ``brdffit.fit(brdf, model="ggx", **options)`` fits any BRDF
(or load spec) with any registered model, by name (colour-science's ``method=`` habit). The
package stays a package (``brdffit.fit.registry`` etc.): only its module type gains a
``__call__`` that calls :func:`fit`.
"""

from __future__ import annotations

import sys
import types
from importlib import import_module
from typing import TYPE_CHECKING

from ..loading import load
from .registry import check_options, known_names
from .registry import fit as _fit

if TYPE_CHECKING:
    from ..brdf import BRDF

_MODULES = ("tabulated", "sgd", "npf", "analytic")
_EXPORTS = {
    "fit_tabulated": "tabulated", "fit_ggx": "tabulated", "fit_beckmann": "tabulated",
    "fit_sgd": "sgd", "fit_beckmann_two_slice": "sgd", "fit_ggx_two_slice": "sgd",
    "fit_cook_torrance": "sgd", "fit_npf": "npf",
    "fit_ggx_diffuse": "analytic", "fit_beckmann_diffuse": "analytic",
    "fit_analytic_diffuse": "analytic", "FitResult": "result", "fit_result": "result",
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


def fit(brdf: BRDF | str, model: str = "ggx-diffuse", **options) -> BRDF:
    """Fit ``brdf`` with the model named ``model``; returns the fitted model (a BRDF).

    Parameters
    ----------
    brdf : BRDF or str
        Any BRDF of the library (measured, synthetic, another fit) or a load spec for
        :func:`brdffit.load` (``"gold.binary"``, ``"merl_nbrdf.zip:gold-metallic-paint"``,
        ``"synthetic:gold-ggx"``).
    model : str, default "ggx-diffuse"
        A model name of :data:`brdffit.fit.registry.MODELS` (``brdffit models`` lists them:
        ``tabulated``, ``ggx``, ``beckmann``, ``ggx-diffuse``, ``beckmann-diffuse``, ``sgd``,
        ``npf``, ``npf-g-from-d``, ``npf-naive``, ``npf-bivariate``, ...), the same names as
        ``brdffit fit --model``.
    **options
        Keyword options of the model's fitting function (e.g. ``tol=1e-8`` for
        ``tabulated``, ``max_iter=200`` for the NPF models), declared with their types and
        defaults by the model's options dataclass (:mod:`brdffit.fit.options`; ``brdffit
        models --options`` lists them); see ``help`` of :func:`fit_tabulated`,
        :func:`fit_sgd`, :func:`fit_npf`, :func:`fit_ggx_diffuse`.

    Returns
    -------
    BRDF
        The fitted model, with ``fit_info`` (the method's report, with the recorded
        outcome under ``"result"``) and ``fit_options``; :func:`brdffit.fit_result` gives its
        :class:`~brdffit.fit.result.FitResult`.

    Raises
    ------
    ValueError
        Unknown model name (the message lists the known ones), or an option the fitter
        does not take or a value of the wrong type or range
        (:class:`brdffit.fit.options.OptionError`, checked before the input is read).
    brdffit.FitError
        The fit failed on this input.

    Examples
    --------
    >>> import brdffit
    >>> ggx = brdffit.fit("synthetic:gold-ggx", model="ggx")
    >>> round(float(ggx.distribution.alpha_x), 3)
    0.12
    """
    if not isinstance(model, str) or model not in known_names():
        raise ValueError(f"unknown model {model!r}; expected one of {', '.join(known_names())}")
    options = check_options(model, options)
    if isinstance(brdf, str):
        brdf = load(brdf)
    return _fit(model, brdf, options)


class _CallableModule(types.ModuleType):
    """The type of this package: calling it calls :func:`fit`."""

    def __call__(self, brdf, model: str = "ggx-diffuse", **options):
        return fit(brdf, model, **options)


sys.modules[__name__].__class__ = _CallableModule
