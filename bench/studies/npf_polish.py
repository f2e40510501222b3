"""The NPF polish from stored AWLS fits: how far it lowers Eq. 7, whether it
converges, and what it does to the factors, with and without its trust region.

For each material of a ``brdffit batch`` output whose ``fits/<material>/<model>.npz`` holds an
AWLS fit (``--start``, e.g. a batch folder of fits made with ``polish=0``), the Neural-BRDF MERL
data are tabulated and ``_solver.polish_lm`` runs from the stored factors once per
``--configs`` entry (``bound=<b>`` or ``bound=none``, ``newton=<0|1>``, ``cap=<n>``, joined by
``+``), side by side. Recorded per material × config: objective ratio polished / start,
iterations, stop, CPU time, ρs ratio polished / start (max over channels), F(0) / max F
(min over channels) before and after. The summary counts the degenerate factorisations:
ρs moved more than 10× and F(0) below 1e-3 of F's max.

    .venv/bin/python bench/studies/npf_polish.py --start runs/db100v4 \\
        --configs "bound=2+cap=100,bound=none+cap=100"

Writes ``<out>.json`` (summary, load average) and ``<out>_materials.csv`` atomically after
every material; re-running resumes.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "bench"))  # _common

from brdffit._blas import single_thread_env  # noqa: E402

single_thread_env()          # one BLAS thread, as the CLI and batch fits (brdffit._blas)

import numpy as np  # noqa: E402

from _common import write_csv_and_summary  # noqa: E402

ZIP = ROOT.parent / "shared" / "data" / "nbrdf" / "merl_nbrdf.zip"
FIELDS = ["material", "config", "ratio", "iterations", "stop_reason", "converged", "cpu_s",
          "rho_s_ratio_max", "f0_start_min", "f0_min"]


def parse_config(text: str) -> dict:
    out = {"bound": None, "newton": None, "cap": 100, "bounded": None}
    for item in text.split("+"):
        key, val = item.split("=")
        if key == "bound":
            out["bound"] = None if val == "none" else float(val)
        elif key == "newton":
            out["newton"] = bool(int(val))
        elif key == "cap":
            out["cap"] = int(val)
        elif key == "bounded":          # the factor groups the bound applies to, e.g. F/rho_s
            out["bounded"] = tuple(val.split("/"))
        else:
            raise SystemExit(f"--configs: unknown key {key!r} in {text!r}")
    return out


def summarise(rows, args, load0) -> dict:
    out = {"benchmark": "NPF polish from stored AWLS fits", "command": " ".join(sys.argv),
           "start": args.start, "model": args.model, "load_average_start": load0,
           "load_average_now": list(os.getloadavg()), "per_config": {}}
    for cfg in args.configs.split(","):
        rs = [r for r in rows if r["config"] == cfg]
        if not rs:
            continue
        ratio = np.array([float(r["ratio"]) for r in rs])
        its = np.array([int(r["iterations"]) for r in rs])
        cpu = np.array([float(r["cpu_s"]) for r in rs])
        rho = np.array([float(r["rho_s_ratio_max"]) for r in rs])
        f0 = np.array([float(r["f0_min"]) for r in rs])
        f0s = np.array([float(r["f0_start_min"]) for r in rs])
        out["per_config"][cfg] = {
            "materials": len(rs), "converged": sum(r["converged"] == "True" for r in rs),
            "ratio": {"min": ratio.min(), "median": float(np.median(ratio)),
                      "mean": ratio.mean(), "max": ratio.max()},
            "iterations": {"median": float(np.median(its)), "p90": float(np.percentile(its, 90)),
                           "max": int(its.max())},
            "cpu_s": {"mean": cpu.mean(), "median": float(np.median(cpu)), "max": cpu.max()},
            "rho_s_moved_more_than_10x": int(np.sum((rho > 10) | (rho < 0.1))),
            "rho_s_ratio_max": rho.max(),
            "f0_below_1e-3": int(np.sum(f0 < 1e-3)), "f0_below_1e-3_at_start": int(np.sum(f0s < 1e-3)),
            "not_converged": [r["material"] for r in rs if r["converged"] != "True"]}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--zip", default=str(ZIP))
    ap.add_argument("--start", required=True, help="brdffit batch output holding AWLS fits")
    ap.add_argument("--model", default="npf", choices=("npf", "npf-g-from-d"))
    ap.add_argument("--configs", default="bound=2+cap=100,bound=none+cap=100")
    ap.add_argument("--only", default="", help="comma-separated material names")
    ap.add_argument("--tol", type=float, default=1e-6)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "npf_polish"))
    args = ap.parse_args(argv)
    if not Path(args.zip).exists():
        print(f"skipped: {args.zip} not found (needs ../shared/data)")
        return 0
    from brdffit import load_fit
    from brdffit.fit.npf import _solver
    from brdffit.grid import tabulate_merl_grid
    from brdffit.io import load
    from brdffit.losses.objective import ObjectiveOptions, prepare_objective

    fits = Path(args.start) / "fits"
    names = (args.only.split(",") if args.only
             else sorted(p.name for p in fits.iterdir() if (p / f"{args.model}.npz").exists()))
    g_from_d = args.model == "npf-g-from-d"
    eps = 0.0 if g_from_d else 1e-6
    csv_path, json_path = Path(args.out + "_materials.csv"), Path(args.out + ".json")
    rows = list(csv.DictReader(open(csv_path))) if csv_path.exists() else []
    done = {(r["material"], r["config"]) for r in rows}
    load0 = list(os.getloadavg())
    for name in names:
        todo = [c for c in args.configs.split(",") if (name, c) not in done]
        if not todo:
            continue
        values, valid = tabulate_merl_grid(load(f"{args.zip}:{name}"))
        smp = _solver.Samples.from_objective(
            prepare_objective(values, valid, ObjectiveOptions(), source=name))
        fit = load_fit(fits / name / f"{args.model}.npz")

        def start():
            return _solver.MFState(*(np.array(a, dtype=np.float64).T.copy()
                                     for a in (fit.D, fit.F, fit.G)),
                                   np.array(fit.rho_d, np.float64),
                                   np.array(fit.rho_s, np.float64))

        st0 = start()
        E0, _ = smp.stats(st0.G, st0.rho_s[:, None] * _solver.outer_df(st0.D, st0.F),
                          st0.rho_d)
        for cfg in todo:
            kw = parse_config(cfg)
            c0 = time.process_time()
            res = _solver.polish_lm(start(), smp, eps=eps, max_iter=kw["cap"], tol=args.tol,
                                    g_from_d=g_from_d, bound=kw["bound"], newton=kw["newton"],
                                    bounded=kw["bounded"])
            st = res.state
            rows.append({
                "material": name, "config": cfg, "ratio": float(res.E.sum() / E0.sum()),
                "iterations": res.iterations, "stop_reason": res.reason,
                "converged": not res.reason.startswith("max_iter"),
                "cpu_s": round(time.process_time() - c0, 2),
                "rho_s_ratio_max": float(np.max(st.rho_s / st0.rho_s)),
                "f0_start_min": float(np.min(st0.F[:, 0] / st0.F.max(1))),
                "f0_min": float(np.min(st.F[:, 0] / st.F.max(1)))})
            r = rows[-1]
            print(f"{name:28s} {cfg:22s} ratio {r['ratio']:.4f} it {r['iterations']:3d} "
                  f"cpu {r['cpu_s']:5.1f} s  ρs×{r['rho_s_ratio_max']:.3g}  "
                  f"F(0) {r['f0_start_min']:.2g} → {r['f0_min']:.2g}", flush=True)
        rows = write_csv_and_summary(csv_path, json_path, FIELDS, rows,
                                     lambda rs: summarise(rs, args, load0))
    print(json.dumps(summarise(rows, args, load0)["per_config"], indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
