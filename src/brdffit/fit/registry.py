"""Registry of fitting methods, by model name (used by ``brdffit fit``, compare and batch).

**Declared models.** :data:`MODELS` is one table of every built-in model, in the spirit of
colour-science's ``*_METHODS`` mappings: its fitting function and its summary function as
``"module:function"`` references inside :mod:`brdffit.fit`, resolved on first use, a
one-line description, the paper, whether it fits isotropic BRDFs only, and typical figures
(fit-file size, fit time) measured by ``bench/bench_cli.py --models`` (cited in
:data:`TYPICAL_SOURCE`). Nothing registers itself on import: the CLI's help, ``brdffit
models`` and the model-name checks read the table without importing SciPy, Numba or the
fitting stack, and :func:`get` imports only the module of the model asked for.

* ``fit(brdf, **options) -> model``: fits a BRDF; ``options`` are keyword arguments of the
  fitting function (e.g. ``iterations=4``). :func:`fit` accepts them as a dict.
* ``summary(model) -> dict``: a short JSON-able summary of a fitted model (what the CLI
  prints).

**Plug-ins.** Code outside the package adds a model with :func:`register_fitter`
(``register_fitter("my-model", fit_fn, summary_fn)``); a registered name takes precedence
over a declared one.

**Figures of a fitted model.** :func:`figures` gives the numbers a user looks for, the same
way for every model (``brdffit fit``'s summary and the batch ``summary.csv``): the slope
scales (αx, αy, ρ) of its distribution, the Fresnel reflectance at normal incidence F0 per
channel, the Lambertian albedo ρd per channel and the bytes of its fit-file tables
(:func:`table_bytes`).
"""

from __future__ import annotations

import dataclasses
import inspect
import time
from collections.abc import Mapping
from typing import Any, Callable

from .._blas import with_single_blas_thread

# NumPy is imported inside the functions that need it: `brdffit --help` reads MODELS.

__all__ = ["Fitter", "FITTERS", "ModelInfo", "MODELS", "PAPERS", "TYPICAL_SOURCE",
           "register_fitter", "get_fitter", "get", "list_fitters", "known_names", "describe", "fit", "fit_model", "is_isotropic_only",
           "summarize", "model_params", "small_json", "figures", "table_bytes",
           "check_options"]


@dataclasses.dataclass(frozen=True)
class ModelInfo:
    """What is known about a model before its fitting module is imported.

    ``typical_bytes``: size of its fit file (``.npz``) and ``typical_table_bytes``: bytes of
    the tables (arrays) inside it, for a fit of an isotropic MERL material;
    ``typical_time_s``: CPU seconds of that fit on the machine of the bench
    (:data:`TYPICAL_SOURCE`); ``None`` when not measured.
    """

    name: str
    module: str           # the brdffit.fit submodule that holds its functions
    function: str         # its fitting function, "module:function" within brdffit.fit
    summary: str          # its summary function, "module:function"
    description: str      # one line (<= 58 characters: `--help` at 80 columns)
    paper: str            # keys of PAPERS, comma-separated
    isotropic_only: bool = False
    typical_bytes: int | None = None
    typical_table_bytes: int | None = None
    typical_time_s: float | None = None


#: Where the typical figures of :data:`MODELS` come from.
TYPICAL_SOURCE = ("bench/bench_cli.py --models: CPU time of one fit of the MERL file of "
                  "gold-metallic-paint on a 2-core machine (bench/results/cli.json)")

#: The papers of :data:`MODELS` (``ModelInfo.paper`` names them by first author and year).
PAPERS = {
    "Dupuy 2015": "J. Dupuy, E. Heitz, J.-C. Iehl, P. Poulin, V. Ostromoukhov: Extracting "
                  "Microfacet-based BRDF Parameters from Arbitrary Materials with Power "
                  "Iterations. Computer Graphics Forum 34(4), EGSR 2015",
    "Bagher 2012": "M. M. Bagher, C. Soler, N. Holzschuch: Accurate fitting of measured "
                   "reflectances using a Shifted Gamma micro-facet distribution. Computer "
                   "Graphics Forum 31(4), 2012",
    "Bagher 2016": "M. M. Bagher, J. Snyder, D. Nowrouzezahrai: A Non-Parametric Factor "
                   "Microfacet Model for Isotropic BRDFs. ACM Transactions on Graphics, 2016",
    "Cook 1982": "R. L. Cook, K. E. Torrance: A Reflectance Model for Computer Graphics. ACM "
                 "Transactions on Graphics 1(1), 1982",
}

#: Typical figures of each model, ``(fit-file bytes, table bytes, fit CPU seconds)``: one fit
#: of the MERL file of gold-metallic-paint on this project's 2-core machine, measured by
#: ``bench/bench_cli.py --models`` (bench/results/cli.json, "models"; CPU time, 2 significant
#: digits; tests/cli/test_help_models.py checks they match that file).
_TYPICAL = {
    "tabulated": (4396, 1800, 0.019), "ggx": (3195, 1080, 0.018),
    "beckmann": (3211, 1080, 0.014), "ggx-diffuse": (2966, 0, 1.1),
    "beckmann-diffuse": (3098, 0, 1.0), "sgd": (5957, 0, 0.46),
    "beckmann-2s": (5243, 0, 0.11), "ggx-2s": (5099, 0, 0.064),
    "beckmann-ct": (1547, 0, 0.72), "ggx-ct": (1457, 0, 0.55), "npf": (56601, 3264, 52.0),
    "npf-g-from-d": (7214, 3264, 3.0), "npf-naive": (7182, 4344, 1.0),
    "npf-bivariate": (98912, 97200, 0.63),
}


def _model(name, function, description, paper, isotropic_only=False) -> ModelInfo:
    module = function.split(":")[0]
    size, tables, seconds = _TYPICAL.get(name, (None, None, None))
    return ModelInfo(name, module, function, f"{module}:summary", description, paper,
                     isotropic_only, size, tables, seconds)


#: Every built-in model, in the order the CLI lists them (summary function: the module's
#: ``summary``).
MODELS: dict[str, ModelInfo] = {m.name: m for m in (
    _model("tabulated", "tabulated:fit_tabulated", "tabulated NDF + Fresnel by power iteration",
           "Dupuy 2015"),
    _model("ggx", "tabulated:fit_ggx", "GGX from the tabulated fit's slope moments",
           "Dupuy 2015"),
    _model("beckmann", "tabulated:fit_beckmann", "Beckmann from the tabulated fit's slope moments",
           "Dupuy 2015"),
    _model("ggx-diffuse", "analytic:fit_ggx_diffuse",
           "GGX + Lambert (+ coat), Schlick/dielectric/conductor", "Dupuy 2015, Bagher 2016"),
    _model("beckmann-diffuse", "analytic:fit_beckmann_diffuse",
           "Beckmann + Lambert (+ coat), Schlick/diel./conductor", "Dupuy 2015, Bagher 2016"),
    _model("sgd", "sgd:fit_sgd", "Shifted Gamma Distribution per channel", "Bagher 2012", True),
    _model("beckmann-2s", "sgd:fit_beckmann_two_slice", "Beckmann per channel, two-slice fit",
           "Bagher 2012", True),
    _model("ggx-2s", "sgd:fit_ggx_two_slice", "GGX per channel, two-slice fit", "Bagher 2012",
           True),
    _model("beckmann-ct", "sgd:fit_beckmann_ct",
           "Cook-Torrance Beckmann per channel, least squares", "Cook 1982, Bagher 2012", True),
    _model("ggx-ct", "sgd:fit_ggx_ct", "Cook-Torrance GGX per channel, least squares",
           "Cook 1982, Bagher 2012", True),
    _model("npf", "npf:fit_npf_independent_g", "non-parametric factors D, F, G (independent G)",
           "Bagher 2016", True),
    _model("npf-g-from-d", "npf:fit_npf_g_from_d", "non-parametric factors, G derived from D",
           "Bagher 2016", True),
    _model("npf-naive", "npf:fit_npf_naive", "non-parametric factors D, F, H (no shadowing)",
           "Bagher 2016", True),
    _model("npf-bivariate", "npf:fit_npf_bivariate", "non-parametric bivariate D(θh, θd) and F",
           "Bagher 2016", True),
)}


def _module_exists(module: str) -> bool:
    from importlib.util import find_spec

    try:
        return find_spec(f"{__package__}.{module}") is not None
    except (ImportError, ValueError):  # pragma: no cover
        return False


@dataclasses.dataclass(frozen=True)
class Fitter:
    """One registered fitting method."""

    name: str
    fit: Callable[..., Any]
    summary: Callable[[Any], dict] | None = None
    description: str = ""
    isotropic_only: bool = False  # needs eval_hd on an isotropic input (two-slice, NPF, ...)

    def accepts(self, option: str) -> bool:
        """True when the fitting function takes keyword ``option`` (or ``**kwargs``)."""
        try:
            sig = inspect.signature(self.fit)
        except (TypeError, ValueError):  # pragma: no cover - builtins
            return True
        return option in sig.parameters or any(
            p.kind is inspect.Parameter.VAR_KEYWORD for p in sig.parameters.values())


FITTERS: dict[str, Fitter] = {}


def register_fitter(name: str, fn: Callable[..., Any], summary_fn: Callable | None = None,
                    description: str | None = None, *, isotropic_only: bool = False) -> Fitter:
    """Register ``fn`` under ``name`` (re-registering a name replaces it)."""
    if not callable(fn):
        raise TypeError(f"register_fitter({name!r}): fn must be callable, got {fn!r}")
    if summary_fn is not None and not callable(summary_fn):
        raise TypeError(f"register_fitter({name!r}): summary_fn must be callable")
    doc = description if description is not None else (inspect.getdoc(fn) or "").split("\n")[0]
    declared = MODELS.get(str(name))  # the declaration may say "isotropic only" for the module
    iso = bool(isotropic_only) or bool(declared is not None and declared.isotropic_only)
    # one BLAS thread: the fits make many small calls that BLAS threads only slow down
    entry = Fitter(str(name), with_single_blas_thread(fn), summary_fn, doc, iso)
    FITTERS[entry.name] = entry
    return entry


def _resolve(reference: str):
    """The object a ``"module:function"`` reference (within :mod:`brdffit.fit`) names."""
    from importlib import import_module

    module, attr = reference.split(":")
    return getattr(import_module(f"{__package__}.{module}"), attr)


def _declared(info: ModelInfo) -> Fitter:
    fn = _resolve(info.function)
    doc = (inspect.getdoc(fn) or info.description).split("\n")[0]
    # one BLAS thread: the fits make many small calls that BLAS threads only slow down
    return Fitter(info.name, with_single_blas_thread(fn), _resolve(info.summary), doc,
                  info.isotropic_only)


def get(name: str) -> Fitter:
    """The :class:`Fitter` of ``name``: registered (:func:`register_fitter`), or declared in
    :data:`MODELS` (only its module is imported); ``KeyError`` lists the known names."""
    if name not in FITTERS and name in MODELS and _module_exists(MODELS[name].module):
        FITTERS[name] = _declared(MODELS[name])
    try:
        return FITTERS[name]
    except KeyError:
        raise KeyError(f"unknown model {name!r}; known: {known_names()}") from None


def known_names() -> list[str]:
    """Model names a command line may use, *without importing any fitting module*: the
    declared models whose module exists, then every other registered one (sorted)."""
    names = [n for n, m in MODELS.items() if n in FITTERS or _module_exists(m.module)]
    return names + sorted(set(FITTERS) - set(names))


def describe(name: str) -> ModelInfo:
    """The :class:`ModelInfo` of ``name``: declared, or built from its registration."""
    if name in MODELS:
        return MODELS[name]
    entry = get(name)
    module = getattr(entry.fit, "__module__", "?")
    return ModelInfo(name, module, f"{module}:{getattr(entry.fit, '__name__', '?')}", "",
                     entry.description, "", entry.isotropic_only)


def get_fitter(name: str) -> Callable[..., Any]:
    """The fitting function registered under ``name``."""
    return get(name).fit


def list_fitters() -> list[str]:
    """Names of every model: declared (whose module exists) and registered."""
    return sorted(known_names())


def fit(name: str, brdf, options: dict | None = None):
    """Fit ``brdf`` with model ``name`` and keyword ``options``."""
    return get(name).fit(brdf, **(options or {}))


def summarize(name: str, model) -> dict:
    """The registered summary of a fitted ``model`` (basic fields when there is none)."""
    entry = get(name)
    if entry.summary is not None:
        return dict(entry.summary(model))
    info = getattr(model, "fit_info", None) or {}
    return {"model": name, "time_s": info.get("time", info.get("time_s"))}


# -- fitting orchestration (used by compare and batch) --------------------------------------
def model_params(model) -> dict:
    """JSON-friendly parameters of a fitted model for the report (small arrays only), with
    its :func:`figures` under ``"figures"``."""
    import numpy as np

    out: dict[str, Any] = {}
    to_state = getattr(model, "to_state", None)
    if callable(to_state):
        try:
            params, arrays = to_state()
            out.update(params or {})
            out["tables"] = {k: list(np.shape(v)) for k, v in (arrays or {}).items()}
        except Exception:  # noqa: BLE001
            pass
    for attr in ("distribution", "fresnel"):
        part = getattr(model, attr, None)
        if part is not None and callable(getattr(part, "params", None)):
            try:
                out.setdefault(attr, {"type": type(part).__name__, **(part.params() or {})})
            except Exception:  # noqa: BLE001
                pass
    if not out and callable(getattr(model, "describe", None)):
        out = model.describe()
    try:
        out["figures"] = figures(model)
    except Exception:  # noqa: BLE001 - figures are a convenience, never a failure
        pass
    return small_json(out)


def small_json(obj, limit: int = 24):
    """``obj`` with NumPy scalars as Python numbers and arrays above ``limit`` elements
    replaced by a ``"<array shape [...]>"`` note (what reports and records keep)."""
    import numpy as np

    if isinstance(obj, Mapping):
        return {str(k): small_json(v, limit) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        arr = np.asarray(obj, dtype=object) if not isinstance(obj, np.ndarray) else obj
        if arr.size > limit:
            return f"<array shape {list(np.shape(obj))}>"
        return [small_json(v, limit) for v in (obj.tolist() if isinstance(obj, np.ndarray) else obj)]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def is_isotropic_only(name: str) -> bool:
    """True when model ``name`` fits isotropic BRDFs only (False for unknown names)."""
    if name in MODELS and name not in FITTERS:
        return MODELS[name].isotropic_only
    try:
        return get(name).isotropic_only
    except KeyError:
        return False


def check_options(name: str, options: Mapping, command_line: bool = False) -> dict:
    """The options of a fit with model ``name`` checked and converted
    (:func:`brdffit.fit.options.check_fitter_options`); ``KeyError`` for an unknown model."""
    from .options import check_fitter_options  # not at import: `brdffit --help` reads MODELS

    return check_fitter_options(get(name).fit, options, model=name, command_line=command_line)


def fit_model(name: str, reference, options: Mapping | None = None):
    """Fit model ``name`` to ``reference`` with ``options`` checked (:func:`check_options`);
    returns ``(model, seconds)``."""
    fitter = get(name).fit
    options = check_options(name, dict(options or {}))
    t0 = time.perf_counter()
    model = fitter(reference, **options)
    return model, time.perf_counter() - t0


# -- figures of a fitted model ---------------------------------------------------------------
def table_bytes(model) -> int | None:
    """Bytes of the arrays (tables) ``model`` saves in its fit file (``to_state``), ``None``
    for a model that cannot be saved. Scalars stored in the file's JSON header are not
    counted (a few dozen bytes per model)."""
    import numpy as np

    to_state = getattr(model, "to_state", None)
    if not callable(to_state):
        return None
    _, arrays = to_state()
    return int(sum(np.asarray(v).nbytes for v in (arrays or {}).values()))


def _rgb(value):
    import numpy as np

    a = np.broadcast_to(np.asarray(value, dtype=np.float64), (3,))
    return [float(x) for x in a]


def figures(model) -> dict:
    """The figures users look for in a fitted ``model``, the same way for every model.

    * ``alpha``: ``[αx, αy, ρ]``, the slope scales and correlation of the distribution
      (Walter 2007 / Dupuy 2015 α, not "roughness"; glTF's roughness is √α for GGX);
      ``alpha_kind`` names the distribution (``ggx``, ``beckmann``, ``sgd``...). A tabulated
      NDF gives its GGX equivalent by slope moments (Dupuy 2015 App. C,
      ``alpha_kind = "ggx-equivalent"``). Per-channel models (SGD, two-slice, Cook-Torrance)
      give ``alpha_rgb`` (one isotropic α per channel) instead. ``None`` when the model has no
      such parameter (NPF).
    * ``f0``: per channel, the Fresnel factor of the specular term at normal incidence times
      the term's specular scale (``ks·F(θd = 0)``; for SGD ``(4ρs/π)·F0`` of Bagher 2012
      Eq. 1): the reflectance a renderer's F0 means for a normalised distribution. May exceed
      1 when a fit puts energy in the scale. ``None`` for NPF (its factors are defined up to
      a scale, Bagher 2016 §4.3).
    * ``rho_d``: per channel, the Lambertian albedo (the term is ρd/π); 0 without a diffuse
      term.
    * ``coat``: for a coated diffuse fit (:func:`brdffit.microfacet.coat.coat_parts`), the coat
      lobe's ``{"alpha", "weight", "f0"}`` (the other figures are the base lobe's); else
      ``None``.
    * ``table_bytes``: :func:`table_bytes`.

    Each model class says its own figures (``figures()``: ``MicrofacetBRDF`` and its
    distribution's, the per-channel models, the NPF factor models); this function adds the
    coat of a coated fit and the table bytes.
    """
    import numpy as np

    out: dict[str, Any] = {"alpha": None, "alpha_kind": None, "alpha_rgb": None, "f0": None,
                           "rho_d": None, "coat": None}
    from ..microfacet.coat import coat_alpha_weight, coat_parts

    parts = coat_parts(model)
    if parts is not None:
        base, coat = parts
        out.update(base.figures())
        alpha, weight = coat_alpha_weight(coat)
        out["coat"] = {"alpha": alpha, "weight": weight, "f0": float(np.max(coat.fresnel.f0))}
        out["table_bytes"] = 0
        return out
    own = getattr(model, "figures", None)
    if callable(own):
        out.update(own())
    try:
        out["table_bytes"] = table_bytes(model)
    except Exception:  # noqa: BLE001 - a model that cannot describe its state
        out["table_bytes"] = None
    return out
