"""Benchmark of the non-parametric factor fits (Bagher, Snyder & Nowrouzezahrai 2016).

Over the Neural-BRDF MERL materials evaluated on the MERL grid, per variant: fitting time,
AWLS iterations and golden-section (GSS) calls (min / avg / max, as the paper's Table I), the
final objective (Eq. 7, always re-evaluated with compressive weighting so variants compare),
and the cosine-weighted relative error (:func:`brdffit.losses.objective.
relative_error_from_values`). Findings checked: independent-G reaches a lower objective than
G-from-D and naive on most materials; G-from-D ≈ naive; without compressive weighting the
specular materials (nickel, color-changing-paint1, maroon-plastic) are much worse in relative
error.

Variants (``--variants``, comma separated):
  indep1        independent-G, single start (data slices), up to --max-iter AWLS iterations
  indep1lm      indep1 followed by ≥ 20 Levenberg–Marquardt polish iterations (extension)
  indep         independent-G, all starts (random ×4, ones, sgd, g-from-d, slices)
  gfromd        G-from-D
  naive         naive model (Eq. 4)
  bivariate     bivariate model (Eq. 5)
  <v>-nowc      the same without compressive weighting (only on --nowc-materials)

Usage::

    .venv/bin/python bench/bench_npf.py --limit 10
    .venv/bin/python bench/bench_npf.py --materials nickel,maroon-plastic --variants indep1,indep1-nowc

``--from-batch DIR`` instead summarises the NPF fits of a ``brdffit batch`` run (models
``npf`` → variant ``indep``, all starts; ``npf-g-from-d`` → ``gfromd``): fit times measured
inside the batch (2 workers sharing the 2 cores, so pessimistic), iterations and GSS calls
from the saved fits, the normalised objective and the batch's ``cos_rel_error`` metric
(Monte Carlo, 2^16 direction pairs) in the ``relative_error`` column. Writes
``bench/results/npf_batch.json`` and ``npf_batch_materials.csv``::

    .venv/bin/python bench/bench_npf.py --from-batch runs/merl-full

Writes ``bench/results/npf.json`` (summary) and ``bench/results/npf_materials.csv`` (one row
per material × variant), both atomically after every material; re-running resumes (rows
already in the CSV are kept and not recomputed unless ``--fresh``).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from brdffit._atomic import atomic_write  # noqa: E402
from brdffit.losses.objective import (ObjectiveOptions, objective_from_values,  # noqa: E402
                                          relative_error_from_values)
from brdffit.fit.npf import fit_npf  # noqa: E402
from brdffit.grid import tabulate_merl_grid  # noqa: E402

ZIP = ROOT.parent / "shared" / "data" / "nbrdf" / "merl_nbrdf.zip"
SPECULAR = ("nickel", "color-changing-paint1", "maroon-plastic", "white-fabric2")
FIELDS = ["material", "variant", "time_s", "iterations", "line_searches", "objective",
          "normalised_objective", "relative_error", "fit_objective", "stop_reason", "status",
          "starts"]


def variant_kwargs(v: str, args) -> dict:
    base = v[:-5] if v.endswith("-nowc") else v
    kw: dict = {"compressive": not v.endswith("-nowc")}
    if base == "indep1":
        kw.update(variant="independent-g", starts=("slices",), start_max_iter=None,
                  max_iter=args.max_iter, polish=args.polish)
    elif base == "indep1lm":
        kw.update(variant="independent-g", starts=("slices",), start_max_iter=None,
                  max_iter=args.max_iter, polish=max(args.polish, 20))
    elif base == "indep":
        kw.update(variant="independent-g", max_iter=args.max_iter, polish=args.polish,
                  start_max_iter=args.start_iter)
    elif base == "gfromd":
        kw.update(variant="g-from-d")
    elif base == "naive":
        kw.update(variant="naive")
    elif base == "bivariate":
        kw.update(variant="bivariate")
    else:
        raise SystemExit(f"unknown variant {v!r}")
    return kw


def load_rows(path: Path) -> list[dict]:
    if not path.exists():
        return []
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def write_rows(path: Path, rows: list[dict]) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=FIELDS)
    w.writeheader()
    for r in rows:
        w.writerow({k: r.get(k, "") for k in FIELDS})
    with atomic_write(path, "w") as fh:
        fh.write(buf.getvalue())


def _stats(xs):
    xs = [float(x) for x in xs]
    if not xs:
        return None
    return {"min": min(xs), "avg": float(np.mean(xs)), "max": max(xs), "n": len(xs)}


def summarise(rows: list[dict]) -> dict:
    ok = [r for r in rows if r.get("status") == "ok"]
    variants = sorted({r["variant"] for r in ok})
    out: dict = {"per_variant": {}}
    for v in variants:
        rs = [r for r in ok if r["variant"] == v]
        out["per_variant"][v] = {
            "time_s": _stats(r["time_s"] for r in rs),
            "iterations": _stats(r["iterations"] for r in rs),
            "line_searches": _stats(r["line_searches"] for r in rs),
            "materials_with_line_searches": sum(1 for r in rs if float(r["line_searches"]) > 0),
            "normalised_objective_mean": float(np.mean([float(r["normalised_objective"])
                                                        for r in rs])),
            "relative_error_mean": float(np.mean([float(r["relative_error"]) for r in rs])),
        }
    by = {}
    for r in ok:
        by.setdefault(r["material"], {})[r["variant"]] = r
    findings = {}
    for best in ("indep", "indep1", "indep1lm"):
        for other in ("gfromd", "naive"):
            pairs = [(float(m[best]["objective"]), float(m[other]["objective"]))
                     for m in by.values() if best in m and other in m]
            if pairs:
                findings[f"{best}_objective_below_{other}"] = \
                    f"{sum(a < b for a, b in pairs)}/{len(pairs)}"
    pairs = [(float(m["gfromd"]["objective"]), float(m["naive"]["objective"]))
             for m in by.values() if "gfromd" in m and "naive" in m]
    if pairs:
        ratio = [a / b for a, b in pairs if b > 0]
        findings["gfromd_over_naive_objective_median"] = float(np.median(ratio))
    nowc = {}
    for mat, m in by.items():
        for v in list(m):
            if v.endswith("-nowc") and v[:-5] in m:
                nowc.setdefault(mat, {})[v[:-5]] = {
                    "relative_error_with_wc": float(m[v[:-5]]["relative_error"]),
                    "relative_error_without_wc": float(m[v]["relative_error"])}
    findings["compressive_weighting"] = nowc
    out["findings"] = findings
    return out


BATCH_VARIANTS = {"npf": "indep", "npf-g-from-d": "gfromd", "npf-naive": "naive",
                  "npf-bivariate": "bivariate"}


def from_batch(batch_dir: Path, json_path: Path, csv_path: Path) -> dict:
    from brdffit.batch import read_records
    from brdffit.io.fitfile import load_fit

    rows = []
    for rec in read_records(batch_dir):
        v = BATCH_VARIANTS.get(rec["model"])
        if v is None:
            continue
        row = {"material": rec["material"], "variant": v, "status": rec.get("status"),
               "time_s": rec.get("fit_time_s")}
        if rec.get("status") == "ok":
            fit = load_fit(batch_dir / rec["fit_file"])
            info = fit.fit_info or {}
            factors = [np.asarray(getattr(fit, k)) for k in ("D", "F", "G", "H", "B", "rho_d", "rho_s")
                       if getattr(fit, k, None) is not None]
            row["status"] = ("ok" if all(np.all(np.isfinite(f)) and np.all(f >= 0) for f in factors)
                             else "non-finite or negative factor")
            met = rec.get("metrics") or {}
            row.update(iterations=info.get("iterations"), line_searches=info.get("line_searches", 0),
                       objective=info.get("objective"),
                       normalised_objective=met.get("compressive_objective"),
                       relative_error=met.get("cos_rel_error"),
                       stop_reason=info.get("stop_reason", ""),
                       starts=";".join(info.get("best_start_per_channel") or []))
        rows.append(row)
    write_rows(csv_path, rows)
    summary = {"benchmark": "npf fits of a brdffit batch run", "batch_dir": str(batch_dir),
               "note": "times measured inside a 2-worker batch on 2 cores (pessimistic); "
                       "relative_error = batch metric cos_rel_error",
               "machine": {"cpus": os.cpu_count(), "platform": platform.platform()},
               "materials": len({r["material"] for r in rows}),
               "failures": [r for r in rows if r["status"] != "ok"], **summarise(rows)}
    with atomic_write(json_path, "w") as fh:
        json.dump(summary, fh, indent=1, default=str)
    print(json.dumps({k: summary[k] for k in ("materials", "per_variant", "findings")},
                     indent=1, default=str))
    return summary


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--zip", default=str(ZIP))
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--materials", default=None, help="comma-separated names")
    ap.add_argument("--variants", default="indep1,gfromd,naive,bivariate,indep,"
                                          "indep1-nowc,gfromd-nowc,naive-nowc")
    ap.add_argument("--nowc-materials", default=",".join(SPECULAR))
    ap.add_argument("--max-iter", type=int, default=300)
    ap.add_argument("--start-iter", type=int, default=100)
    ap.add_argument("--polish", type=int, default=0)
    ap.add_argument("--json", default=str(ROOT / "bench" / "results" / "npf.json"))
    ap.add_argument("--csv", default=str(ROOT / "bench" / "results" / "npf_materials.csv"))
    ap.add_argument("--fresh", action="store_true")
    ap.add_argument("--rgl", action="store_true",
                    help="fit the RGL materials (../shared/data/rgl/*_rgb.bsdf) instead")
    ap.add_argument("--from-batch", default=None, help="summarise a brdffit batch run instead")
    args = ap.parse_args(argv)
    if args.from_batch:
        res = ROOT / "bench" / "results"
        from_batch(Path(args.from_batch), res / "npf_batch.json", res / "npf_batch_materials.csv")
        return 0

    from brdffit.io import load
    from brdffit.io.nbrdf import list_materials

    if args.rgl:
        rgl = sorted((ROOT.parent / "shared" / "data" / "rgl").glob("*_rgb.bsdf"))
        names = [p.stem for p in rgl]
        spec_of = {p.stem: str(p) for p in rgl}
    else:
        names = (args.materials.split(",") if args.materials else list_materials(args.zip))
        spec_of = {}
    if args.limit:
        names = names[:args.limit]
    variants = args.variants.split(",")
    nowc_set = set(args.nowc_materials.split(",")) if args.nowc_materials else set()
    csv_path, json_path = Path(args.csv), Path(args.json)
    rows = [] if args.fresh else load_rows(csv_path)
    done = {(r["material"], r["variant"]) for r in rows}
    std = ObjectiveOptions()
    t_all = time.perf_counter()
    for name in names:
        todo = [v for v in variants if (name, v) not in done
                and (not v.endswith("-nowc") or name in nowc_set)]
        if not todo:
            continue
        t0 = time.perf_counter()
        brdf = load(spec_of.get(name, f"{args.zip}:{name}"))
        values, valid = tabulate_merl_grid(brdf)
        t_tab = time.perf_counter() - t0
        for v in todo:
            kw = variant_kwargs(v, args)
            row = {"material": name, "variant": v}
            try:
                t1 = time.perf_counter()
                model = fit_npf(data=(values, valid), name=name, **kw)
                row["time_s"] = f"{time.perf_counter() - t1:.3f}"
                info = model.fit_info
                fv, _ = tabulate_merl_grid(model)
                o = objective_from_values(fv, values, valid, std)
                rel = relative_error_from_values(fv, values, valid)
                row.update(iterations=info.get("iterations"), line_searches=info.get("line_searches"),
                           objective=f"{o['objective']:.9g}",
                           normalised_objective=f"{o['normalised']:.6g}",
                           relative_error=f"{rel['relative_error']:.6g}",
                           fit_objective=f"{info['objective']:.9g}",
                           stop_reason=info.get("stop_reason", ""), status="ok")
                if "starts" in info:         # independent-G: per start objective / status
                    row["starts"] = ";".join(
                        f"{st['start']}={st['objective']:.5g}" if "objective" in st
                        else f"{st['start']}:{st.get('status')}" for st in info["starts"])
                    row["starts"] += f";best={'/'.join(info['best_start_per_channel'])}"
                facs = [np.asarray(a) for a in model.factors().values()]
                if any(not np.all(np.isfinite(a)) or np.any(a < 0) for a in facs):
                    row["status"] = "NaN/negative factor"
            except Exception as exc:  # noqa: BLE001 - record and continue
                row.update(status=f"error: {type(exc).__name__}: {exc}")
            rows.append(row)
            print(f"{name:28s} {v:14s} t={row.get('time_s', '-'):>8s}s "
                  f"it={row.get('iterations', '-')!s:>5s} gss={row.get('line_searches', '-')!s:>4s} "
                  f"E/E0={row.get('normalised_objective', '-'):>10s} "
                  f"relerr={row.get('relative_error', '-'):>9s} {row['status']}", flush=True)
        write_rows(csv_path, rows)
        summary = {"benchmark": "npf (Bagher, Snyder, Nowrouzezahrai 2016)",
                   "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                               "load_avg": os.getloadavg()},
                   "tabulation_s_last": t_tab, "options": vars(args),
                   "materials_done": sorted({r["material"] for r in rows}),
                   "failures": [r for r in rows if r.get("status") != "ok"],
                   **summarise(rows)}
        with atomic_write(json_path, "w") as fh:
            json.dump(summary, fh, indent=1)
    print(f"total {time.perf_counter() - t_all:.1f}s")
    print(json.dumps(summarise(rows), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
