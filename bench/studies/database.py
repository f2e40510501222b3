"""The database comparison: every model the project fits, rendered on the
paper's scene suite with common random numbers, over the Neural-BRDF MERL and RGL materials.

Input: the fits of ``bench/studies/fit_database.py`` (``runs/db/fits/<slug>/<model>.npz``, loaded, not
refitted). For each material whose fits exist, :func:`brdffit.evaluation.compare.compare` runs
with the product's defaults (``scenes="paper"``: sphere × courtyard/studio/sunrise + knot ×
courtyard; 256², 64 spp per scene in 8 CRN batches) and writes ``runs/db/report/<slug>/``.
Resumable: a material is rendered again only when a fit appeared that its ``result.json``
lacks. ``--summarise`` (also done at the end of a run) writes
``bench/results/database.json``:

* per model: mean / median PSNR (mean over the four scenes, dB), the standard error of the
  mean over materials, the median per-material standard error (CRN batches + converged peak),
  dE2000 mean / median;
* wins / ties / losses per pair, where a tie is a difference within ``z`` = 2 combined standard
  errors of that material (``2·sqrt(se_a² + se_b²)``, the measured noise of both PSNRs; the
  median threshold is reported) — not a fixed 2 dB;
* the papers' ordering claim by claim (bivariate > independent-G > naive ≈ G-from-D > SGD >
  analytic), with the materials that break each.

::

    nice -n 5 .venv/bin/python bench/studies/database.py            # render what is missing
    .venv/bin/python bench/studies/database.py --summarise          # tables only
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "src"))

MODELS = ("npf-bivariate", "npf", "npf-naive", "npf-g-from-d", "sgd", "tabulated", "ggx",
          "beckmann")
#: (better, worse, kind): "gt" = a beats b; "eq" = a ties b.
CLAIMS = [("ggx-diffuse", "ggx", "gt"), ("ggx-diffuse", "sgd", "gt"),
          ("npf-bivariate", "npf", "gt"), ("npf", "npf-naive", "gt"),
          ("npf", "npf-g-from-d", "gt"), ("npf-naive", "npf-g-from-d", "eq"),
          ("npf-naive", "sgd", "gt"), ("npf-g-from-d", "sgd", "gt"), ("sgd", "ggx", "gt"),
          ("sgd", "beckmann", "gt"), ("ggx", "beckmann", "gt")]
Z = 2.0


def _models(names) -> list[str]:
    """``names`` in the order of :data:`MODELS`, then any other model (e.g. ggx-diffuse)."""
    names = set(names)
    return [m for m in MODELS if m in names] + sorted(names - set(MODELS))


def fit_folders(fits: Path) -> list[tuple[str, str, dict]]:
    """(material, spec, {model: npz}) for every material with at least one ok fit."""
    out = []
    for d in sorted(p for p in fits.iterdir() if p.is_dir()):
        models, name, spec = {}, None, None
        for m in _models(p.stem for p in d.glob("*.json")):
            rec = d / f"{m}.json"
            try:
                r = json.loads(rec.read_text())
            except (OSError, ValueError):
                continue
            name, spec = r["material"], r["spec"]
            if r.get("status") == "ok" and (d / f"{m}.npz").is_file():
                models[m] = str(d / f"{m}.npz")
        if models:
            out.append((name, spec, models))
    return out


def render(args) -> None:
    from brdffit.evaluation.compare import compare
    from brdffit.paths import slug

    report = Path(args.out) / "report"
    todo = fit_folders(Path(args.out) / "fits")
    todo.sort(key=lambda t: -len(t[2]))  # materials with every fit first
    for name, spec, models in todo:
        if len(models) < args.min_models:
            continue
        res_path = report / slug(name) / "result.json"
        try:
            have = {m["name"] for m in json.loads(res_path.read_text())["models"]}
        except (OSError, ValueError, KeyError):
            have = set()
        if set(models) <= have:
            continue
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            compare(spec, models, report, name=name, save_fits=False, update_index=False,
                    brdf_metrics=())
            status = "ok"
        except Exception as exc:  # noqa: BLE001 - recorded, the run goes on
            status = f"failed: {type(exc).__name__}: {exc}"
        print(f"{name:32s} {len(models)} models {time.perf_counter() - t0:6.1f} s wall "
              f"{time.process_time() - c0:6.1f} s CPU load {os.getloadavg()[0]:.1f} {status}",
              flush=True)


def _table(report: Path) -> dict[str, dict[str, tuple]]:
    """material → model → (psnr, se, de2000, per-scene psnr list)."""
    table = {}
    for p in sorted(report.glob("*/result.json")):
        r = json.loads(p.read_text())
        row = {}
        for m in r.get("models", []):
            if m.get("status") == "ok" and m.get("psnr") is not None:
                row[m["name"]] = (float(m["psnr"]), float(m.get("psnr_se") or 0.0),
                                  m.get("mean_de2000"))
        if row:
            table[r["material"]] = row
    return table


def summarise(args) -> dict:
    from brdffit.batch import enumerate_materials  # noqa: F401  (same import cost as render)

    report = Path(args.out) / "report"
    table = _table(report)
    per_model = {}
    for m in _models(m for row in table.values() for m in row):
        vals = [(row[m][0], row[m][1], row[m][2]) for row in table.values() if m in row]
        if not vals:
            continue
        p = np.array([v[0] for v in vals])
        se = np.array([v[1] for v in vals])
        de = np.array([v[2] for v in vals if v[2] is not None], dtype=float)
        fin = np.isfinite(p)
        per_model[m] = {
            "n": len(vals), "mean_psnr": float(np.mean(p[fin])), "median_psnr": float(np.median(p)),
            "se_of_mean_over_materials": float(np.std(p[fin], ddof=1) / np.sqrt(fin.sum()))
            if fin.sum() > 1 else None,
            "median_psnr_se": float(np.median(se)), "max_psnr_se": float(np.max(se)),
            "median_psnr_se_up_to_60db": float(np.median(se[p <= 60])) if np.any(p <= 60) else None,
            "mean_de2000": float(np.mean(de)) if de.size else None,
            "median_de2000": float(np.median(de)) if de.size else None}
    wins, thresholds = {}, []
    names = list(per_model)
    for a in names:
        wins[a] = {}
        for b in names:
            if a == b:
                continue
            w = t = l = 0
            for row in table.values():
                if a in row and b in row:
                    d = row[a][0] - row[b][0]
                    tie = Z * float(np.hypot(row[a][1], row[b][1]))
                    thresholds.append(tie)
                    if abs(d) <= tie:
                        t += 1
                    elif d > 0:
                        w += 1
                    else:
                        l += 1
            wins[a][b] = {"wins": w, "ties": t, "losses": l}
    claims = []
    for a, b, kind in CLAIMS:
        if a not in per_model or b not in per_model:
            claims.append({"claim": f"{a} {'>' if kind == 'gt' else '≈'} {b}",
                           "status": "not measured (fits missing)"})
            continue
        broken, diffs = [], []
        for mat, row in table.items():
            if a in row and b in row:
                d = row[a][0] - row[b][0]
                diffs.append(d)
                tie = Z * float(np.hypot(row[a][1], row[b][1]))
                if (kind == "gt" and d < -tie) or (kind == "eq" and abs(d) > max(tie, 2.0)):
                    broken.append((mat, round(d, 2)))
        wl = wins[a][b]
        holds = (wl["wins"] + wl["ties"] > wl["losses"] and float(np.median(diffs)) > 0
                 if kind == "gt" else abs(float(np.median(diffs))) <= 1.0)
        claims.append({"claim": f"{a} {'>' if kind == 'gt' else '≈'} {b}", **wl,
                       "n": len(diffs), "median_difference_db": float(np.median(diffs)),
                       "holds": bool(holds),
                       "broken_on": sorted(broken, key=lambda x: x[1] if kind == "gt"
                                           else -abs(x[1]))})
    fig = {"benchmark": "database comparison",
           "protocol": "compare() defaults: paper scene suite (sphere-courtyard, sphere-studio, "
                       "sphere-sunrise, knot-courtyard), 256², 64 spp/scene in 8 CRN batches, "
                       "fits loaded from runs/db/fits (bench/studies/fit_database.py, product defaults)",
           "n_materials": len(table), "materials": sorted(table),
           "tie_rule": f"|ΔPSNR| ≤ {Z}·sqrt(se_a² + se_b²) per material",
           "median_tie_threshold_db": float(np.median(thresholds)) if thresholds else None,
           "per_model": per_model, "wins": wins, "claims": claims,
           "load_average": os.getloadavg()}
    out = ROOT / "bench" / "results" / f"{args.results}.json"
    out.write_text(json.dumps(fig, indent=1))
    # per-material figures beside the summary: the run folder (runs/db) is not kept
    with open(out.with_suffix(".csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["material", "model", "psnr_db", "psnr_se_db", "mean_de2000"])
        for mat in sorted(table):
            for m, (p_db, se_db, de) in table[mat].items():
                w.writerow([mat, m, f"{p_db:.3f}", f"{se_db:.3f}",
                            "" if de is None else f"{de:.4f}"])
    print(f"{len(table)} materials; tie threshold median {fig['median_tie_threshold_db']}")
    for m, s in per_model.items():
        print(f"  {m:>14} n={s['n']:3d} PSNR mean {s['mean_psnr']:6.2f} ± "
              f"{s['se_of_mean_over_materials'] or float('nan'):.2f} median {s['median_psnr']:6.2f}"
              f" (median se {s['median_psnr_se']:.3f}) dE2000 {s['mean_de2000'] or float('nan'):.2f}")
    for c in claims:
        print(f"  {c['claim']:>28}: {c.get('wins')}/{c.get('ties')}/{c.get('losses')} "
              f"median Δ {c.get('median_difference_db', float('nan')):+.2f} dB "
              f"{'holds' if c.get('holds') else 'BROKEN'}; "
              f"{', '.join(m for m, _ in c.get('broken_on', [])[:8])}")
    return fig


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(ROOT / "runs" / "db"))
    ap.add_argument("--summarise", action="store_true")
    ap.add_argument("--results", default=None,
                    help="name of the summary in bench/results/ (.json and .csv); default "
                         "database for the default --out, database_<out folder name> "
                         "otherwise (a run on other fits never overwrites the database's)")
    ap.add_argument("--min-models", type=int, default=7,
                    help="render a material only when this many of its fits exist")
    args = ap.parse_args(argv)
    if args.results is None:
        default_out = Path(ap.get_default("out")).resolve()
        args.results = ("database" if Path(args.out).resolve() == default_out
                        else f"database_{Path(args.out).name}")
    if not args.summarise:
        render(args)
    summarise(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
