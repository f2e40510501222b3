"""Registry of fitting methods, by model name (used by ``brdffit fit``, compare and batch).

**Declared models.** :data:`MODELS` is one table of every built-in model, in the spirit of
colour-science's ``*_METHODS`` mappings: its fitting function and its summary function as
``"module:function"`` references inside :mod:`brdffit.fit`, resolved on first use, a
one-line description, the paper, whether it fits isotropic BRDFs only and its options
dataclass. The typical figures (fit-file size, fit time) are read from the results file of
``bench/bench_cli.py --models`` (:data:`TYPICAL_FILE`, cited in :data:`TYPICAL_SOURCE`). Nothing registers itself on import: the CLI's help, ``brdffit
models`` and the model-name checks read the table without importing SciPy, Numba or the
fitting stack, and :func:`get` imports only the module of the model asked for.

* ``fit(brdf, **options) -> model``: fits a BRDF; ``options`` are keyword arguments of the
  fitting function (e.g. ``iterations=4``), declared, typed and defaulted by the model's
  options dataclass (:mod:`brdffit.fit.options`; :func:`check_options` checks them).
  :func:`fit` accepts them as a dict.
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
import functools
import inspect
import itertools
import json
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Callable

from .._blas import with_single_blas_thread

# NumPy is imported inside the functions that need it: `brdffit --help` reads MODELS.

__all__ = ["Fitter", "FITTERS", "ModelInfo", "MODELS", "PAPERS", "TYPICAL_SOURCE",
           "TYPICAL_FILE", "typical_figures", "register_fitter", "get_fitter", "get",
           "list_fitters", "known_names", "describe", "fit", "fit_model", "is_isotropic_only",
           "summarize", "model_params", "small_json", "figures", "table_bytes",
           "check_options", "options_class"]


@dataclasses.dataclass(frozen=True)
class ModelInfo:
    """What is known about a model before its fitting module is imported.

    ``function``, ``summary`` and ``options`` are ``"module:name"`` references within
    :mod:`brdffit.fit`: the fitting function, the summary function and the frozen dataclass
    of the fitting options (:mod:`brdffit.fit.options`; ``None`` for a plug-in, whose
    options are read from its signature). ``typical_bytes`` (size of its fit file, ``.npz``),
    ``typical_table_bytes`` (bytes of the tables inside it) and ``typical_time_s`` (CPU
    seconds, 2 significant digits) are those of one fit of an isotropic MERL material read
    from the benchmark's results file (:func:`typical_figures`); ``None`` when not measured
    or when that file is absent.
    """

    name: str
    module: str           # the brdffit.fit submodule that holds its functions
    function: str         # its fitting function, "module:function" within brdffit.fit
    summary: str          # its summary function, "module:function"
    description: str      # one line (<= 58 characters: `--help` at 80 columns)
    paper: str            # keys of PAPERS, comma-separated
    isotropic_only: bool = False
    options: str | None = None   # its options dataclass, "module:Class"

    @property
    def typical_bytes(self) -> int | None:
        return typical_figures().get(self.name, (None, None, None))[0]

    @property
    def typical_table_bytes(self) -> int | None:
        return typical_figures().get(self.name, (None, None, None))[1]

    @property
    def typical_time_s(self) -> float | None:
        return typical_figures().get(self.name, (None, None, None))[2]


#: The benchmark's results file the typical figures come from (``"models"`` of
#: ``bench/bench_cli.py --models``). It is in a source checkout (and so in an editable
#: install, ``make install``); an installed wheel has no ``bench/``, and then every typical
#: figure is ``None`` (``brdffit models`` shows "–" and ``--measure`` measures them).
TYPICAL_FILE = Path(__file__).resolve().parents[3] / "bench" / "results" / "cli.json"

#: Where the typical figures of :data:`MODELS` come from.
TYPICAL_SOURCE = ("bench/bench_cli.py --models: CPU time of one fit of the MERL file of "
                  "gold-metallic-paint on a 2-core machine (bench/results/cli.json)")


@functools.cache
def typical_figures() -> dict[str, tuple[int, int, float]]:
    """``{model: (fit-file bytes, table bytes, fit CPU seconds)}`` read from
    :data:`TYPICAL_FILE` (CPU seconds to 2 significant digits, as shown); empty when the
    file is absent or unreadable, and without the models whose figures are incomplete."""
    try:
        rows = json.loads(TYPICAL_FILE.read_text(encoding="utf-8"))["models"]["figures"]
    except (OSError, ValueError, KeyError, TypeError):
        return {}
    out = {}
    for name, m in rows.items() if isinstance(rows, dict) else ():
        try:
            out[name] = (int(m["fit_file_bytes"]), int(m["table_bytes"]),
                         float(f"{float(m['fit_cpu_s']):.2g}"))
        except (KeyError, TypeError, ValueError):
            continue
    return out


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


def _family(module: str, options: str, paper: str, isotropic_only: bool,
            members: dict[str, tuple[str, str]]) -> list[ModelInfo]:
    """The models of the fitting module ``module`` that share an options dataclass of
    :mod:`brdffit.fit.options`, a paper and their isotropy; ``members`` maps each name to
    its fitting function and its description (the summary function: the module's
    ``summary``)."""
    return [ModelInfo(name, module, f"{module}:{function}", f"{module}:summary", description,
                      paper, isotropic_only, f"options:{options}")
            for name, (function, description) in members.items()]


#: Every built-in model, in the order the CLI lists them.
MODELS: dict[str, ModelInfo] = {m.name: m for m in itertools.chain(
    _family("tabulated", "TabulatedOptions", "Dupuy 2015", False, {
        "tabulated": ("fit_tabulated", "tabulated NDF + Fresnel by power iteration"),
        "ggx": ("fit_ggx", "GGX from the tabulated fit's slope moments"),
        "beckmann": ("fit_beckmann", "Beckmann from the tabulated fit's slope moments")}),
    _family("analytic", "DiffuseOptions", "Dupuy 2015, Bagher 2016", False, {
        "ggx-diffuse": ("fit_ggx_diffuse",
                        "GGX + Lambert (+ coat), Schlick/dielectric/conductor"),
        "beckmann-diffuse": ("fit_beckmann_diffuse",
                             "Beckmann + Lambert (+ coat), Schlick/diel./conductor")}),
    _family("sgd", "TwoSliceOptions", "Bagher 2012", True, {
        "sgd": ("fit_sgd", "Shifted Gamma Distribution per channel"),
        "beckmann-2s": ("fit_beckmann_two_slice", "Beckmann per channel, two-slice fit"),
        "ggx-2s": ("fit_ggx_two_slice", "GGX per channel, two-slice fit")}),
    _family("sgd", "CookTorranceOptions", "Cook 1982, Bagher 2012", True, {
        "beckmann-ct": ("fit_beckmann_ct", "Cook-Torrance Beckmann per channel, least squares"),
        "ggx-ct": ("fit_ggx_ct", "Cook-Torrance GGX per channel, least squares")}),
    _family("npf", "NPFOptions", "Bagher 2016", True, {
        "npf": ("fit_npf_independent_g", "non-parametric factors D, F, G (independent G)"),
        "npf-g-from-d": ("fit_npf_g_from_d", "non-parametric factors, G derived from D"),
        "npf-naive": ("fit_npf_naive", "non-parametric factors D, F, H (no shadowing)"),
        "npf-bivariate": ("fit_npf_bivariate", "non-parametric bivariate D(θh, θd) and F")}),
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
    #: the options dataclass (:mod:`brdffit.fit.options`); ``None``: read from the signature
    options: type | None = None

    def option_class(self) -> tuple[type, bool]:
        """``(cls, open_ended)``: the options dataclass of this fitter and whether it also
        takes names it does not declare (a plug-in's ``**kwargs``)."""
        if self.options is not None:
            return self.options, False
        from .options import signature_options

        return signature_options(self.fit)

    def accepts(self, option: str) -> bool:
        """True when the fitter takes keyword ``option`` (declared, or open-ended)."""
        cls, open_ended = self.option_class()
        return open_ended or option in {f.name for f in dataclasses.fields(cls)}


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
                  info.isotropic_only, _resolve(info.options) if info.options else None)


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
    from .result import fit_result

    try:
        return {"model": name, "time_s": fit_result(model).time}
    except ValueError:                      # not made by a fit
        return {"model": name, "time_s": None}


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


def options_class(name: str) -> tuple[type, bool]:
    """``(cls, open_ended)``: the options dataclass of model ``name`` (declared in
    :data:`MODELS`, imported from the light :mod:`brdffit.fit.options` without the fitting
    module; a plug-in's made from its signature) and whether unknown names may pass."""
    info = MODELS.get(name)
    if name not in FITTERS and info is not None and info.options and _module_exists(info.module):
        return _resolve(info.options), False
    return get(name).option_class()


def check_options(name: str, options: Mapping, command_line: bool = False) -> dict:
    """The options of a fit with model ``name`` checked against its options dataclass and
    converted (:func:`brdffit.fit.options.check_values`); ``KeyError`` for an unknown model.
    """
    from .options import check_values  # not at import: `brdffit --help` reads MODELS

    cls, open_ended = options_class(name)
    return check_values(cls, options, model=name, open_ended=open_ended,
                        command_line=command_line)


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
