"""A scipy-style view of how a fit went, for every model kind.

Every fitter leaves a ``fit_info`` dict on the model it returns, with fields that follow its
method (power iterations, local least squares, AWLS sweeps, multi-start bounded fits).
:func:`fit_result` reads it into one :class:`FitResult`, the way ``scipy.optimize`` reports
(``success``, ``message``, ``nit``, ``fun``) plus ``converged`` and ``time``; ``fit_info``
itself is left as it is.

>>> import brdffit
>>> model = brdffit.fit("synthetic:gold-ggx", model="tabulated")
>>> res = brdffit.fit_result(model)
>>> res.success, res.converged, res.nit > 0
(True, True, True)
"""

from __future__ import annotations

import dataclasses
from typing import Any

__all__ = ["FitResult", "fit_result"]


@dataclasses.dataclass(frozen=True)
class FitResult:
    """How a fit went (read from ``model.fit_info`` by :func:`fit_result`).

    Attributes
    ----------
    model : BRDF
        The fitted model.
    success : bool
        The fit produced a valid model and, for iterative methods, stopped on its criterion.
    converged : bool or None
        Stopped on its documented convergence criterion (``False``: a safety cap was
        reached); ``None`` for methods that report no criterion (closed forms).
    message : str
        One line: the stop reason.
    nit : int or None
        Iterations (power iterations, AWLS sweeps, function evaluations of the local
        least-squares runs), as the method counts them.
    fun : float or None
        Final value of the method's own objective (``None`` when it has none, e.g. the
        tabulated power iteration, which solves a fixed-point equation).
    time : float or None
        Seconds spent in the fit (wall clock).
    fit_info : dict
        The method's full report.
    """

    model: Any
    success: bool
    converged: bool | None
    message: str
    nit: int | None
    fun: float | None
    time: float | None
    fit_info: dict

    def __repr__(self) -> str:
        rows = [("success", self.success), ("converged", self.converged),
                ("message", self.message), ("nit", self.nit), ("fun", self.fun),
                ("time", None if self.time is None else round(self.time, 4)),
                ("model", type(self.model).__name__)]
        return "\n".join(f"{k:>9}: {v}" for k, v in rows)


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


def fit_result(model) -> FitResult:
    """The :class:`FitResult` of a fitted ``model`` (any model the registry fits).

    Parameters
    ----------
    model : BRDF
        A model returned by a fitter (it carries ``fit_info``); a model loaded from a fit
        file carries the ``fit_info`` saved with it.

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
    time_s = _first(info, "time", "time_s")
    fun = _first(info, "objective", "fun", "cost")
    if "converged" in info:                         # tabulated (+ moments), SGD two-slice
        converged = bool(info["converged"])
        success = bool(info.get("success", converged))
        message = info.get("message") or ("converged" if converged else "NOT converged")
        nit = _first(info, "nit", "iterations")
    elif "variant" in info:                         # NPF
        converged, message, nit = _npf(info)
        success = converged is not False
    else:                                           # bounded multi-start fits, closed forms
        converged, nit = None, _first(info, "nit", "iterations", "nfev")
        success = True
        message = info.get("message") or info.get("method") or "done"
    return FitResult(model=model, success=success, converged=converged, message=str(message),
                     nit=None if nit is None else int(nit),
                     fun=None if fun is None else float(fun),
                     time=None if time_s is None else float(time_s), fit_info=info)
