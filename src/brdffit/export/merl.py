"""MERL ``.binary`` export of any isotropic fit (wrapper of :func:`brdffit.io.merl.resample_to_merl`).

The model is tabulated on the MERL grid (90 θh × 90 θd × 180 φd, Matusik et al. 2003) with
:func:`brdffit.grid.tabulate_merl_grid` and written in MERL units (values divided by the MERL
colour scales, so the file reads back as the model's RGB). Written atomically; a failed write
is one error naming the file (:func:`brdffit.export._common.writing`). Anisotropic
models raise :class:`~brdffit.errors.ExportError`: the MERL grid has no φh.
"""

from __future__ import annotations

import numpy as np

from ._common import check_output_path, fail, writing
from ..io.merl import resample_to_merl, write_merl

__all__ = ["export_merl"]


def export_merl(model, path, **_ignored) -> dict:
    """Write ``model`` as a MERL ``.binary`` file; returns a summary (samples, invalid)."""
    if not getattr(model, "isotropic", False):
        fail(model, "MERL .binary", "an isotropic BRDF (the MERL grid has no φh axis); "
             "anisotropic fits can go to 'rgl', 'mitsuba-xml', 'json', 'mitsuba' or 'glsl'")
    path = check_output_path(path)
    table = resample_to_merl(model)
    with writing(path):
        write_merl(table, path)
    vals, valid = table.merl_table()
    return {"files": [str(path)], "target": "merl", "n_samples": int(table.n_samples),
            "n_invalid": int(table.n_invalid),
            "max_value": float(np.max(np.where(valid[..., None], vals, 0.0)))}
