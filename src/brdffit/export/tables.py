"""Import of published parameter tables: SGD (Bagher 2012) CSV and NPF (Bagher 2016) textures.

SGD table — CSV layout (``write_sgd_table`` writes it, ``load_sgd_table`` reads it)
-------------------------------------------------------------------------------------
One row per material and colour channel (long format), ``#`` comment lines allowed::

    material,channel,rho_d,rho_s,alpha,p,F0,F1[,lambda,c,k]
    blue-acrylic,R,0.0152,0.0187,0.0231,1.0810,0.0491,0.0
    blue-acrylic,G,...
    blue-acrylic,B,...

``channel`` is ``R``/``G``/``B`` (or 0/1/2); the values are the per-channel parameters of
Bagher et al. 2012 Eq. 1 (ρd, ρs: dimensionless, the BRDF is ``ρd/π + ρs F D G/(π cos θi
cos θo)``), Eq. 8 (SGD α, p) and Eq. 11 (F0, F1), and optionally the Eq. 9 G1 approximation
(λ, c, k; then ``g1="approx"`` models can be built). Transcribe the paper's supplemental
tables into this layout (one row per channel). Each material becomes a
:class:`~brdffit.microfacet.sgd_model.PerChannelMicrofacetBRDF` with SGD channels.

NPF table — the uber-texture of :func:`brdffit.export.glsl.pack_npf_uber_texture`
-----------------------------------------------------------------------------------
A float32 array ``(n_materials, 272, 3)`` (``.npy`` or ``.exr``) with the JSON index next to
it (``rows`` = material names): per row D(θ'h) [0, 90), F(θd) [90, 180), G(θ = k°) [180, 270),
ρd at 270, ρs at 271, RGB = channels (Bagher 2016 Eq. 3, Fig. 16). ``load_npf_table`` returns
:class:`~brdffit.microfacet.npf_model.NPFMicrofacetBRDF` models.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from .._atomic import atomic_write
from ..errors import BRDFFormatError, ExportError
from ..evaluation.imageio import read_exr
from ..microfacet.npf_model import NPFMicrofacetBRDF
from ..microfacet.sgd import SGD
from ..microfacet.sgd_model import PerChannelMicrofacetBRDF

__all__ = ["load_sgd_table", "write_sgd_table", "load_npf_table", "SGD_COLUMNS"]

SGD_COLUMNS = ("material", "channel", "rho_d", "rho_s", "alpha", "p", "F0", "F1")
_G1_COLUMNS = ("lambda", "c", "k")
_CH = {"r": 0, "g": 1, "b": 2, "0": 0, "1": 1, "2": 2}


def load_sgd_table(path) -> dict:
    """``{material: PerChannelMicrofacetBRDF}`` from an SGD CSV table (layout above)."""
    path = Path(path)
    text = "\n".join(ln for ln in path.read_text(encoding="utf-8").splitlines()
                     if ln.strip() and not ln.lstrip().startswith("#"))
    reader = csv.DictReader(io.StringIO(text))
    cols = [c.strip() for c in (reader.fieldnames or [])]
    missing = [c for c in SGD_COLUMNS if c not in cols]
    if missing:
        raise BRDFFormatError(path, f"expected CSV columns {', '.join(SGD_COLUMNS)} (+ optional "
                                    f"{', '.join(_G1_COLUMNS)}), found {cols}; missing {missing}")
    has_g1 = all(c in cols for c in _G1_COLUMNS)
    rows: dict[str, list] = {}
    for lineno, raw in enumerate(reader, start=2):
        r = {k.strip(): (v or "").strip() for k, v in raw.items() if k}
        ch = _CH.get(r["channel"].lower())
        if ch is None:
            raise BRDFFormatError(path, f"row {lineno}: expected channel R, G or B, found "
                                        f"{r['channel']!r}")
        try:
            vals = {k: float(r[k]) for k in SGD_COLUMNS[2:]}
            g1 = {k: float(r[k]) for k in _G1_COLUMNS} if has_g1 and r.get("lambda") else None
        except ValueError as exc:
            raise BRDFFormatError(path, f"row {lineno}: expected numbers, found {exc}") from None
        rows.setdefault(r["material"], [None, None, None])
        if rows[r["material"]][ch] is not None:
            raise BRDFFormatError(path, f"row {lineno}: channel {r['channel']} of "
                                        f"{r['material']!r} given twice")
        rows[r["material"]][ch] = (vals, g1)
    out = {}
    for name, chans in rows.items():
        if any(c is None for c in chans):
            raise BRDFFormatError(path, f"expected three channel rows for {name!r}, found "
                                        f"{sum(c is not None for c in chans)}")
        try:
            lobes = [{"distribution": SGD(v["alpha"], v["p"]), "rho_d": v["rho_d"],
                      "rho_s": v["rho_s"], "F0": v["F0"], "F1": v["F1"]} for v, _ in chans]
        except ValueError as exc:
            raise BRDFFormatError(path, f"invalid SGD parameters for {name!r}: {exc}") from None
        g1 = [g for _, g in chans]
        g1 = g1 if all(g is not None for g in g1) else None
        model = PerChannelMicrofacetBRDF(lobes, g1_approx=g1, name=name,
                                         source=f"{path}:{name}")
        out[name] = model
    return out


def write_sgd_table(models, path) -> Path:
    """Write PerChannelMicrofacetBRDF models with SGD channels as an SGD CSV table."""
    path = Path(path)
    models = list(models.values()) if isinstance(models, dict) else list(models)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    with_g1 = all(getattr(m, "g1_approx", None) for m in models)
    w.writerow(SGD_COLUMNS + (_G1_COLUMNS if with_g1 else ()))
    for m in models:
        for c, ch in enumerate(getattr(m, "channels", [])):
            d = ch["distribution"]
            if not isinstance(d, SGD):
                raise ExportError(f"cannot write {type(m).__name__} {m.name!r} to an SGD table: "
                                  f"channel {c} has a {type(d).__name__} distribution, expected SGD")
            row = [m.name, "RGB"[c], *(repr(float(ch[k])) for k in ("rho_d", "rho_s")),
                   repr(d.alpha), repr(d.p), repr(float(ch["F0"])), repr(float(ch["F1"]))]
            if with_g1:
                row += [repr(float(m.g1_approx[c][k])) for k in _G1_COLUMNS]
            w.writerow(row)
    with atomic_write(path, "w") as fh:
        fh.write(buf.getvalue())
    return path


def load_npf_table(path) -> dict:
    """``{material: NPFMicrofacetBRDF}`` from an uber-texture (``.npy``/``.exr``, or its
    ``.json`` index)."""
    path = Path(path)
    index_path = path if path.suffix == ".json" else path.with_suffix(".json")
    if not index_path.is_file():
        raise BRDFFormatError(index_path, "expected the JSON index of the NPF uber-texture "
                                          "(rows = material names), found no file")
    index = json.loads(index_path.read_text(encoding="utf-8"))
    if index.get("format") != "brdffit-npf-uber":
        raise BRDFFormatError(index_path, f"expected format 'brdffit-npf-uber', found "
                                          f"{index.get('format')!r}")
    if path.suffix == ".json":
        path = index_path.with_name(index.get("npy") or index.get("exr"))
    if path.suffix == ".exr":
        tex = np.asarray(read_exr(path), np.float32)[..., :3]
    else:
        tex = np.load(path)
    names = index.get("rows") or []
    if tex.ndim != 3 or tex.shape[1:] != (272, 3) or tex.shape[0] != len(names):
        raise BRDFFormatError(path, f"expected a texture of shape ({len(names)}, 272, 3), found "
                                    f"{tex.shape}")
    return {n: NPFMicrofacetBRDF(tex[i, 0:90], tex[i, 90:180], tex[i, 180:270], tex[i, 270],
                                 tex[i, 271], name=n, source=f"{path}:{n}")
            for i, n in enumerate(names)}
