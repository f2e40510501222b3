"""JSON encoding of the values brdffit writes (NumPy scalars and arrays, paths, non-finite
floats) and reading numbers back from it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["float_or_none", "json_default", "standard_json", "strict_json_default"]


def strict_json_default(obj):
    """``json.dumps(default=...)`` for NumPy scalars/arrays and paths; ``TypeError`` otherwise."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def json_default(obj):
    """As :func:`strict_json_default`, but anything else is written as its ``str``."""
    try:
        return strict_json_default(obj)
    except TypeError:
        return str(obj)


def standard_json(obj):
    """``obj`` as standard JSON values (``json.dump(..., allow_nan=False)`` accepts it):
    dicts with string keys, tuples as lists, NumPy scalars as Python numbers, and non-finite
    floats as the strings ``"inf"``, ``"-inf"`` and ``"nan"``. Other values are returned as
    they are (for ``json.dump``'s ``default``)."""
    if isinstance(obj, dict):
        return {str(k): standard_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [standard_json(v) for v in obj]
    if isinstance(obj, (float, np.floating)) and not math.isfinite(float(obj)):
        return str(float(obj))
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def float_or_none(x, keep_nan: bool = True) -> float | None:
    """``float(x)``, or ``None`` when ``x`` is ``None`` or not a number (a string such as
    ``"inf"`` or ``"nan"`` written by :func:`standard_json` reads back as that float); NaN
    is ``None`` too when ``keep_nan`` is false. For figures read from result files."""
    if x is None:
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return None if not keep_nan and math.isnan(v) else v
