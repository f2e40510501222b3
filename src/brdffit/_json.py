"""JSON encoding of the values brdffit writes (NumPy scalars and arrays, paths)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["json_default", "strict_json_default"]


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
