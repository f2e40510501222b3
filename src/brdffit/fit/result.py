"""How a fit went, in one shape for every model: :class:`FitResult`.

Every fitter records its outcome with :func:`record` when it returns: ``success``,
``converged``, ``message``, ``nit``, ``fun`` and ``time``, the fields of
``scipy.optimize.OptimizeResult`` plus ``converged`` and ``time``. The record is kept in
the model's ``fit_info`` under ``"result"``, so it travels wherever ``fit_info`` does: the
conversions of a tabulated fit, ``with_g1``, the fit file's header. :func:`fit_result` reads
it back as a :class:`FitResult` together with the model and the method's full report (the
rest of ``fit_info``, whose other fields follow each method: power iterations, local least
squares, AWLS sweeps, multi-start bounded fits).

Fit files written before fits recorded their result carry only the method's report; for
them :func:`fit_result` derives the same fields from each method's own keys
(:func:`_legacy_fields`).

>>> import brdffit
>>> model = brdffit.fit("synthetic:gold-ggx", model="tabulated")
>>> res = brdffit.fit_result(model)
>>> res.success, res.converged, res.nit > 0
(True, True, True)
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

__all__ = ["FitResult", "fit_result", "record", "RESULT_FIELDS"]

#: The fields every fitter records (:func:`record`), in this order.
RESULT_FIELDS = ("success", "converged", "message", "nit", "fun", "time")


@dataclasses.dataclass(frozen=True)
class FitResult:
    """How a fit went (recorded by the fitter, :func:`record`; read by :func:`fit_result`).

    Attributes
    ----------
    model : BRDF
        The fitted model.
    success : bool
        The fit produced a valid model and, for iterative methods, stopped on its criterion.
    converged : bool or None
        Stopped on its documented convergence criterion (``False``: a safety cap was
        reached); ``None`` for methods that report no criterion (closed forms, bounded
        multi-start fits).
    message : str
        One line: the stop reason (the method, for methods without a criterion).
    nit : int or None
        Iterations (power iterations, AWLS sweeps and polish steps, function evaluations
        of the local least-squares runs), as the method counts them.
    fun : float or None
        Final value of the method's own objective (``None`` when it has none, e.g. the
        tabulated power iteration, which solves a fixed-point equation).
    time : float or None
        Seconds spent in the fit (wall clock).
    info : dict
        The method's full report (the model's ``fit_info``); also readable as
        ``fit_info``.
    """

    model: Any
    success: bool
    converged: bool | None
    message: str
    nit: int | None
    fun: float | None
    time: float | None
    info: dict

    @property
    def fit_info(self) -> dict:
        """The method's full report (:attr:`info`)."""
        return self.info

    def __repr__(self) -> str:
        rows = [("success", self.success), ("converged", self.converged),
                ("message", self.message), ("nit", self.nit), ("fun", self.fun),
                ("time", None if self.time is None else round(self.time, 4)),
                ("model", type(self.model).__name__)]
        return "\n".join(f"{k:>9}: {v}" for k, v in rows)


def record(model, info: dict, *, success: bool, converged: bool | None, message: str,
           nit: int | None = None, fun: float | None = None, time: float | None = None):
    """Set ``model.fit_info = info`` with the fit's outcome under ``info["result"]``
    (:data:`RESULT_FIELDS`, as plain JSON types) and return ``model``: what every fitter
    does when it returns."""
    info["result"] = {"success": bool(success),
                      "converged": None if converged is None else bool(converged),
                      "message": str(message), "nit": None if nit is None else int(nit),
                      "fun": None if fun is None else float(fun),
                      "time": None if time is None else float(time)}
    model.fit_info = info
    return model


def _recorded(rec) -> dict | None:
    """The fields of a ``fit_info["result"]`` record, or ``None`` when it is not one (a
    fit file may hold anything there)."""
    if not (isinstance(rec, dict) and set(rec) == set(RESULT_FIELDS)):
        return None
    number = (int, float)
    ok = (isinstance(rec["success"], bool) and isinstance(rec["message"], str)
          and (rec["converged"] is None or isinstance(rec["converged"], bool))
          and (rec["nit"] is None or (isinstance(rec["nit"], int)
                                      and not isinstance(rec["nit"], bool)))
          and all(rec[k] is None or (isinstance(rec[k], number)
                                     and not isinstance(rec[k], bool)
                                     and not math.isnan(rec[k])) for k in ("fun", "time")))
    return dict(rec) if ok else None


def _first(info: dict, *keys):
    for k in keys:
        if info.get(k) is not None:
            return info[k]
    return None


def _npf(info: dict) -> tuple[bool | None, str, int | None]:
    """Convergence of an NPF fit: the stop reason of its last AWLS run."""
    reason = (info.get("continuation") or {}).get("stop_reason") or info.get("stop_reason")
    if reason is None and info.get("starts"):               # independent-G, screen only
        reasons = [s.get("stop_reason") for s in info["starts"] if s.get("stop_reason")]
        reason = reasons[0] if reasons and len(set(reasons)) == 1 else "; ".join(
            sorted(set(reasons)))
    if reason is None:
        return None, "no stop reason reported", info.get("iterations")
    converged = reason.startswith(("relative decrease", "exact fit", "closed form"))
    if reason == "closed form":
        return None, "closed form (one linear solve)", info.get("iterations")
    return converged, (reason if converged else f"NOT converged: {reason}"), \
        info.get("iterations")


def _legacy_fields(info: dict) -> dict:
    """The result fields of a ``fit_info`` without a ``"result"`` record (fit files written
    before fits recorded it), from each method's own keys: the convergence report of the
    tabulated, two-slice and NPF fits (``converged``, ``message``, ``nit``), the stop reason
    of an older NPF report, or none (closed forms, bounded fits: the method as message);
    ``time`` or NPF's ``time_s``; ``objective``, ``fun`` or ``cost``."""
    time_s = _first(info, "time", "time_s")
    fun = _first(info, "objective", "fun", "cost")
    if "converged" in info:                         # tabulated (+ moments), two-slice, NPF
        converged = bool(info["converged"])
        success = bool(info.get("success", converged))
        message = info.get("message") or ("converged" if converged else "NOT converged")
        nit = _first(info, "nit", "iterations")
    elif "variant" in info:                         # NPF without a convergence report
        converged, message, nit = _npf(info)
        success = converged is not False
    else:                                           # bounded multi-start fits, closed forms
        converged, nit = None, _first(info, "nit", "iterations", "nfev")
        success = True
        message = info.get("message") or info.get("method") or "done"
    return {"success": success, "converged": converged, "message": str(message),
            "nit": None if nit is None else int(nit), "fun": None if fun is None else float(fun),
            "time": None if time_s is None else float(time_s)}


def fit_result(model) -> FitResult:
    """The :class:`FitResult` of a fitted ``model`` (any model the registry fits).

    Parameters
    ----------
    model : BRDF
        A model returned by a fitter (its ``fit_info`` holds the recorded result); a model
        loaded from a fit file carries the ``fit_info`` saved with it (files written before
        fits recorded their result: :func:`_legacy_fields`).

    Returns
    -------
    FitResult

    Raises
    ------
    ValueError
        When ``model`` has no ``fit_info`` (it was not made by a fit).
    """
    info = getattr(model, "fit_info", None)
    if not isinstance(info, dict):
        raise ValueError(f"{type(model).__name__} has no fit_info: it was not made by a fit")
    fields = _recorded(info.get("result")) or _legacy_fields(info)
    return FitResult(model=model, info=info, **fields)
