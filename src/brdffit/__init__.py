"""brdffit: fit compact, physically based microfacet models to measured BRDFs.

The public API is deliberately small; everything else lives in the subpackages:

* :mod:`brdffit.geometry` – spherical, Rusinkiewicz and slope-space parameterisations
* :mod:`brdffit.io` – readers/writers of measured formats and of fitted models
* :mod:`brdffit.microfacet` – slope distributions, shadowing, Fresnel, ``MicrofacetBRDF``
* :mod:`brdffit.fit` – the fitting methods, one module per paper; ``brdffit.fit(brdf,
  model="ggx")`` fits with any model by name, ``brdffit.fit_result(model)`` tells how it went
* :mod:`brdffit.evaluation` – rendering, metrics, plots and the HTML report
"""

# Nothing here imports NumPy: `import brdffit` (and `brdffit --help`) stay instant; the
# public names below are imported on first use by __getattr__.
from ._version import __version__
from .errors import BRDFError, BRDFFormatError, ExportError, FitError
from .synthetic import list_synthetic, synthetic  # eager: the function shadows the module name

__all__ = ["BRDF", "IsotropicBRDF", "BRDFError", "BRDFFormatError", "FitError", "ExportError",
           "synthetic", "list_synthetic", "load", "resample_to_merl", "write_merl",
           "MicrofacetBRDF", "Beckmann", "GGX", "SGD", "SchlickFresnel",
           "GeneralizedSchlickFresnel", "DielectricFresnel", "ConductorFresnel",
           "TabulatedFresnel", "fit", "fit_result", "FitResult", "fit_tabulated", "fit_ggx",
           "fit_beckmann", "fit_sgd", "fit_npf", "fit_ggx_diffuse", "fit_beckmann_diffuse",
           "save_fit", "load_fit", "__version__"]


def __getattr__(name):  # lazy public API: keeps `import brdffit` fast and cycle-free
    from importlib import import_module

    lazy = {
        "BRDF": ".brdf", "IsotropicBRDF": ".brdf",
        "load": ".loading", "resample_to_merl": ".io.merl", "write_merl": ".io.merl",
        "MicrofacetBRDF": ".microfacet", "Beckmann": ".microfacet", "GGX": ".microfacet",
        "SGD": ".microfacet", "SchlickFresnel": ".microfacet",
        "GeneralizedSchlickFresnel": ".microfacet", "DielectricFresnel": ".microfacet",
        "ConductorFresnel": ".microfacet", "TabulatedFresnel": ".microfacet",
        "fit_tabulated": ".fit", "fit_ggx": ".fit", "fit_beckmann": ".fit", "fit_sgd": ".fit",
        "fit_npf": ".fit", "fit_ggx_diffuse": ".fit", "fit_beckmann_diffuse": ".fit",
        "fit_result": ".fit.result", "FitResult": ".fit.result",
        "save_fit": ".io.fitfile", "load_fit": ".io.fitfile",
    }
    if name == "fit":          # the subpackage itself: callable, brdffit.fit(brdf, model=...)
        return import_module(".fit", __name__)
    if name in lazy:
        value = getattr(import_module(lazy[name], __name__), name)
        globals()[name] = value  # cached: later lookups do not come back here
        return value
    raise AttributeError(f"module 'brdffit' has no attribute {name!r}")
