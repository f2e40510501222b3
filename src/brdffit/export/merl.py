"""MERL ``.binary`` export of any isotropic fit (wrapper of :func:`brdffit.io.merl.resample_to_merl`).

The model is tabulated on the MERL grid (90 θh × 90 θd × 180 φd, Matusik et al. 2003) with
:func:`brdffit.grid.tabulate_merl_grid` and written in MERL units (values divided by the MERL
colour scales, so the file reads back as the model's RGB). Written atomically. Anisotropic
models raise :class:`~brdffit.errors.ExportError`: the MERL grid has no φh.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._common import fail

__all__ = ["export_merl"]


def export_merl(model, path, **_ignored) -> dict:
    """Write ``model`` as a MERL ``.binary`` file; returns a summary (samples, invalid)."""
    from ..io.merl import resample_to_merl

    if not getattr(model, "isotropic", False):
        fail(model, "MERL .binary", "an isotropic BRDF (the MERL grid has no φh axis); "
             "anisotropic fits can go to 'json', 'mitsuba' or 'glsl'")
    table = resample_to_merl(model, Path(path))
    vals, valid = table.merl_table()
    return {"files": [str(path)], "target": "merl", "n_samples": int(table.n_samples),
            "n_invalid": int(table.n_invalid),
            "max_value": float(np.max(np.where(valid[..., None], vals, 0.0)))}
