"""The rows of a batch's ``summary.csv`` / ``summary.json`` and the recommended model.

:func:`summary_rows` turns the fit records of a batch (and its render records, when the
batch rendered) into one flat row per material × model, with named columns (:data:`COLUMNS`):

* ``material``, ``model``, ``status`` (``ok``, ``failed``, ``skipped``), ``error``;
* ``recommended`` (the recommended model of the material, on every row of the material) and
  ``is_recommended`` (this row is it);
* the fitted parameters (:func:`brdffit.fit.registry.figures`): ``alpha_x``, ``alpha_y``,
  ``alpha_rho`` (slope scales α and their correlation ρ; ``alpha_kind`` names the
  distribution, ``ggx-equivalent`` for a tabulated NDF) and glTF's ``gltf_roughness_x/y``
  = √α; per-channel models (SGD, two-slice, Cook-Torrance) fill ``alpha_r/g/b`` and
  ``gltf_roughness_r/g/b`` instead; ``f0_r/g/b`` (ks·F at normal incidence), ``rho_d_r/g/b``
  (Lambertian albedo) and ``table_bytes`` (bytes of the fit file's tables);
* BRDF-space errors of the fit against its input (:mod:`brdffit.evaluation.metrics`):
  ``cos_rel_error``, ``normalized_l2``, ``compressive_objective``, computed over the
  input's measured domain, which ``error_domain`` names (``everywhere`` when the input has
  no smaller domain; :meth:`brdffit.brdf.BRDF.measured`);
* rendered errors when the batch rendered (``--render``): ``psnr`` (mean over the scenes,
  dB), ``psnr_se`` (its standard error) and ``mean_de2000``;
* ``warnings``: the physical checks the fit failed (:mod:`brdffit.evaluation.validity`:
  ``fresnel``, ``albedo``, ``non_negative``, ``reciprocity``; each with its figure, e.g.
  ``fresnel 1.49; albedo 1.05``), empty when every check passed;
* ``fit_time_s`` and ``fit_file`` (relative to the batch folder).

Empty cells mean "does not apply" (e.g. no α for NPF, no PSNR without renders).

**Recommended model** (:func:`recommend`, rule in :data:`RECOMMENDATION_RULE`): among the
material's ``ok`` fits, the *smallest* — fewest fit-file table bytes, ties broken by the
lower error — whose error is within a tolerance of the best fit's. The error is the
rendered PSNR when every candidate was rendered (within :data:`PSNR_TOLERANCE_DB` dB of the
best, or within two standard errors of the difference when that is larger), else the
BRDF-space ``cos_rel_error`` (at most the best's × (1 + :data:`ERROR_TOLERANCE_REL`), and at
least :data:`ERROR_TOLERANCE_ABS` above it).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any
from .fit.registry import figures
from .io.fitfile import load_fit

__all__ = ["COLUMNS", "RECOMMENDATION_RULE", "PSNR_TOLERANCE_DB", "ERROR_TOLERANCE_REL",
           "ERROR_TOLERANCE_ABS", "summary_rows", "recommend", "read_render_records"]

#: A model within this many dB of the best PSNR is as good as the best (Bagher et al. 2016 §5
#: call 2 dB a tie; 1 dB is stricter).
PSNR_TOLERANCE_DB = 1.0
#: ... or, without renders, within this fraction of the best cos_rel_error,
ERROR_TOLERANCE_REL = 0.10
#: ... and at least this much above it (absolute; cos_rel_error is a fraction).
ERROR_TOLERANCE_ABS = 0.005

RECOMMENDATION_RULE = (
    "the smallest ok fit (fewest fit-file table bytes; ties: lower error) whose error is "
    f"within tolerance of the material's best: rendered PSNR >= best - max({PSNR_TOLERANCE_DB:g}"
    " dB, 2 standard errors of the difference) when every fit was rendered, else "
    f"cos_rel_error <= max(best x {1 + ERROR_TOLERANCE_REL:g}, best + {ERROR_TOLERANCE_ABS:g})")

_RGB = ("r", "g", "b")
METRICS = ("cos_rel_error", "normalized_l2", "compressive_objective")
COLUMNS = (["material", "model", "status", "recommended", "is_recommended",
            "alpha_x", "alpha_y", "alpha_rho", "alpha_kind", "gltf_roughness_x",
            "gltf_roughness_y"]
           + [f"alpha_{c}" for c in _RGB] + [f"gltf_roughness_{c}" for c in _RGB]
           + [f"f0_{c}" for c in _RGB] + [f"rho_d_{c}" for c in _RGB]
           + ["table_bytes", *METRICS, "error_domain", "psnr", "psnr_se", "mean_de2000",
              "warnings",
              "fit_time_s", "fit_file", "error"])


def _num(v) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) or math.isinf(f) else None


def read_render_records(out: Path) -> dict[str, dict]:
    """``{material: {model: {psnr, psnr_se, mean_de2000, status, finished}}}`` from
    ``OUT/renders/*.json`` (records that cannot be read are ignored: their materials simply
    have no rendered figures). A render finished before the fit it would describe (the fit
    was redone since) is not used."""
    found: dict[str, dict] = {}
    for p in sorted((Path(out) / "renders").glob("*.json")):
        if p.name.startswith("."):
            continue
        try:
            rec = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, ValueError, UnicodeDecodeError):
            continue
        if not (isinstance(rec, dict) and isinstance(rec.get("material"), str)
                and isinstance(rec.get("models"), dict)):
            continue
        finished = rec.get("finished") if isinstance(rec.get("finished"), str) else ""
        found[rec["material"]] = {str(k): dict(v, finished=finished)
                                  for k, v in rec["models"].items() if isinstance(v, dict)}
    return found


def _figures(rec: dict, out: Path) -> dict:
    """The :func:`~brdffit.fit.registry.figures` of a record's fit: saved in the record
    (``params.figures``), else computed from its fit file (records of older versions)."""
    params = rec.get("params") if isinstance(rec.get("params"), dict) else {}
    fig = params.get("figures")
    if isinstance(fig, dict):
        return fig
    if rec.get("status") != "ok" or not isinstance(rec.get("fit_file"), str):
        return {}
    try:
        return figures(load_fit(out / rec["fit_file"]))
    except Exception:  # noqa: BLE001 - a damaged fit: the row says what the record says
        return {}


def _flat_figures(fig: dict) -> dict[str, Any]:
    row: dict[str, Any] = {}
    alpha = fig.get("alpha")
    if isinstance(alpha, (list, tuple)) and len(alpha) == 3:
        ax, ay, rho = (_num(a) for a in alpha)
        row.update(alpha_x=ax, alpha_y=ay, alpha_rho=rho)
        row["gltf_roughness_x"] = math.sqrt(ax) if ax is not None and ax >= 0 else None
        row["gltf_roughness_y"] = math.sqrt(ay) if ay is not None and ay >= 0 else None
    per = fig.get("alpha_rgb")
    if isinstance(per, (list, tuple)) and len(per) == 3:
        for c, a in zip(_RGB, per):
            a = _num(a)
            row[f"alpha_{c}"] = a
            row[f"gltf_roughness_{c}"] = math.sqrt(a) if a is not None and a >= 0 else None
    row["alpha_kind"] = fig.get("alpha_kind")
    for key in ("f0", "rho_d"):
        vals = fig.get(key)
        if isinstance(vals, (list, tuple)) and len(vals) == 3:
            for c, v in zip(_RGB, vals):
                row[f"{key}_{c}"] = _num(v)
    tb = fig.get("table_bytes")
    row["table_bytes"] = int(tb) if isinstance(tb, (int, float)) else None
    return row


def summary_rows(records: list, out: Path) -> tuple[list[dict], dict[str, dict]]:
    """``(rows, recommended)``: one row per record (entries that are not dicts are skipped)
    with the :data:`COLUMNS`, and :func:`recommend`'s choice per material."""
    out = Path(out)
    renders = read_render_records(out)
    rows = []
    for r in records:
        if not isinstance(r, dict):
            continue
        material, model = r.get("material"), r.get("model")
        row: dict[str, Any] = dict.fromkeys(COLUMNS)
        row.update(material=material, model=model, status=r.get("status"),
                   error=r.get("error") or "", fit_time_s=_num(r.get("fit_time_s")),
                   fit_file=r.get("fit_file") if r.get("status") == "ok" else None)
        row.update(_flat_figures(_figures(r, out)))
        warns = r.get("warnings")
        if isinstance(warns, list):
            row["warnings"] = "; ".join(f"{w.get('check')} {w.get('figure'):.3g}"
                                        if isinstance(w.get("figure"), (int, float))
                                        else str(w.get("check"))
                                        for w in warns if isinstance(w, dict))
        if r.get("metrics") is not None:
            domain = r.get("error_domain")
            row["error_domain"] = domain if isinstance(domain, str) else "everywhere"
        metrics = r.get("metrics") if isinstance(r.get("metrics"), dict) else {}
        for k, v in metrics.items():
            if not isinstance(v, (dict, list)):
                row[k] = _num(v) if k in METRICS else v
        rend = renders.get(material, {}).get(model) if isinstance(material, str) else None
        fit_done = r.get("finished") if isinstance(r.get("finished"), str) else ""
        if isinstance(rend, dict) and rend.get("status") == "ok" \
                and rend.get("finished", "") >= fit_done:  # not a render of an older fit
            row.update(psnr=_num(rend.get("psnr")), psnr_se=_num(rend.get("psnr_se")),
                       mean_de2000=_num(rend.get("mean_de2000")))
        rows.append(row)
    recommended = recommend(rows)
    for row in rows:
        choice = recommended.get(row["material"]) if isinstance(row["material"], str) else None
        row["recommended"] = choice["model"] if choice else None
        row["is_recommended"] = bool(choice) and choice["model"] == row["model"]
    return rows, recommended


def recommend(rows: list[dict]) -> dict[str, dict]:
    """``{material: {"model", "by", "best_model", "best", "value", "tolerance",
    "candidates"}}`` by :data:`RECOMMENDATION_RULE` over ``rows`` (summary rows; ``ok``
    rows with the error measure and ``table_bytes`` only). A material without such a row is
    absent."""
    by_material: dict[str, list[dict]] = {}
    for row in rows:
        if row.get("status") == "ok" and isinstance(row.get("material"), str):
            by_material.setdefault(row["material"], []).append(row)
    result = {}
    for material, cands in by_material.items():
        rendered = all(_num(c.get("psnr")) is not None for c in cands)
        if rendered:
            best = max(cands, key=lambda c: c["psnr"])

            def within(c, best=best):
                se = math.hypot(_num(c.get("psnr_se")) or 0.0, _num(best.get("psnr_se")) or 0.0)
                return c["psnr"] >= best["psnr"] - max(PSNR_TOLERANCE_DB, 2.0 * se)

            def error(c):
                return -c["psnr"]
            by, tolerance = "psnr", f"{PSNR_TOLERANCE_DB:g} dB or 2 standard errors"
        else:
            cands = [c for c in cands if _num(c.get("cos_rel_error")) is not None]
            if not cands:
                continue
            best = min(cands, key=lambda c: c["cos_rel_error"])
            limit = max(best["cos_rel_error"] * (1 + ERROR_TOLERANCE_REL),
                        best["cos_rel_error"] + ERROR_TOLERANCE_ABS)

            def within(c, limit=limit):
                return c["cos_rel_error"] <= limit

            def error(c):
                return c["cos_rel_error"]
            by, tolerance = "cos_rel_error", f"<= {limit:.4g}"
        ok = [c for c in cands if within(c)]
        sized = [c for c in ok if isinstance(c.get("table_bytes"), int)]
        pick = min(sized or ok, key=lambda c: (c.get("table_bytes") if sized else 0, error(c)))
        result[material] = {"model": pick["model"], "by": by, "best_model": best["model"],
                            "best": best["psnr"] if by == "psnr" else best["cos_rel_error"],
                            "value": pick["psnr"] if by == "psnr" else pick["cos_rel_error"],
                            "table_bytes": pick.get("table_bytes"), "tolerance": tolerance,
                            "candidates": sorted(c["model"] for c in ok)}
    return result
