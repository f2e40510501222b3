"""Registry of fitting methods, by model name (used by ``brdffit fit``, compare and batch).

A fitting module registers its models when it is imported::

    from .registry import register_fitter
    register_fitter("tabulated", fit_tabulated, summary_fn)

* ``fn(brdf, **options) -> model``: fits a BRDF; ``options`` are keyword arguments of the
  fitting function (e.g. ``iterations=4``). :func:`fit` accepts them as a dict.
* ``summary_fn(model) -> dict``: a short JSON-able summary of a fitted model (what the CLI
  prints); optional.

Lookups import every fitting module first (:func:`brdffit.fit.import_all`), so a name is
known as soon as its module exists.
"""

from __future__ import annotations

import dataclasses
import inspect
import time
from collections.abc import Mapping
from typing import Any, Callable

import numpy as np

__all__ = ["Fitter", "FITTERS", "register_fitter", "get_fitter", "get", "list_fitters",
           "fit", "fit_model", "is_isotropic_only", "summarize", "model_params", "small_json"]


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
    entry = Fitter(str(name), fn, summary_fn, doc, bool(isotropic_only))
    FITTERS[entry.name] = entry
    return entry


def _ensure_loaded() -> None:
    from . import import_all

    import_all()


def get(name: str) -> Fitter:
    """The :class:`Fitter` registered under ``name``; ``KeyError`` lists the known names."""
    if name not in FITTERS:
        _ensure_loaded()
    try:
        return FITTERS[name]
    except KeyError:
        raise KeyError(f"unknown model {name!r}; known: {sorted(FITTERS)}") from None


def get_fitter(name: str) -> Callable[..., Any]:
    """The fitting function registered under ``name``."""
    return get(name).fit


def list_fitters() -> list[str]:
    """Names of every registered model (after importing all fitting modules)."""
    _ensure_loaded()
    return sorted(FITTERS)


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
    """JSON-friendly parameters of a fitted model for the report (small arrays only)."""
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
    return small_json(out)


def small_json(obj, limit: int = 24):
    """``obj`` with NumPy scalars as Python numbers and arrays above ``limit`` elements
    replaced by a ``"<array shape [...]>"`` note (what reports and records keep)."""
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
    try:
        return get(name).isotropic_only
    except KeyError:
        return False


def fit_model(name: str, reference, options: Mapping | None = None):
    """Fit model ``name`` to ``reference``; returns ``(model, seconds)``."""
    fitter = get(name).fit
    t0 = time.perf_counter()
    model = fitter(reference, **dict(options or {}))
    return model, time.perf_counter() - t0
