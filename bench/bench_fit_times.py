"""Fit time and parameters of one model over the Neural-BRDF MERL materials, for a before /
after comparison of two source trees (e.g. a change that should only make a fit faster).

    .venv/bin/python bench/bench_fit_times.py --model ggx-diffuse --baseline HEAD~1

fits every material (``merl_nbrdf.zip``, alphabetical; ``--limit N`` the first N) with the
product's defaults, in one process per tree (the baseline tree is ``git archive``-d into a
temporary folder), records the CPU time of each fit (``time.process_time``; the first fit
of a process also pays the one-time imports and is reported apart) and the fitted
parameters, and compares the two trees material by material: the largest relative
difference of α, ρd, F0 and the objective, the Fresnel chosen, the CPU times. Writes
``bench/results/fit_times_<model>.json``. The trees run one after the other: record the load.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ZIP = ROOT.parent / "shared" / "data" / "nbrdf" / "merl_nbrdf.zip"

_CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
import brdffit, brdffit.io
zip_, model, limit = sys.argv[2], sys.argv[3], int(sys.argv[4])
from brdffit.io.nbrdf import list_materials
names = sorted(list_materials(zip_))
names = names[:limit] if limit > 0 else names
out = {}
for m in names:
    ref = brdffit.io.load(f"{zip_}:{m}")
    c = time.process_time()
    fi = brdffit.fit(ref, model=model).fit_info
    out[m] = {"cpu": time.process_time() - c, "alpha": fi.get("alpha_x"),
              "rho_d": fi.get("rho_d"), "F0": fi.get("F0"), "fresnel": fi.get("fresnel"),
              "objective": fi.get("objective"),
              "objective_by_fresnel": fi.get("objective_by_fresnel")}
print(json.dumps(out))
"""


def run_tree(src: Path, model: str, limit: int) -> dict:
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(src), str(ZIP), model, str(limit)],
                          capture_output=True, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _rel(a, b) -> float:
    a, b = np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(b, float))
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(a), 1e-12)))


def _cpu(rows: dict) -> dict:
    cpu = [r["cpu"] for r in rows.values()]
    rest = cpu[1:] or cpu
    return {"first_fit_s": cpu[0], "mean_s": float(np.mean(rest)),
            "median_s": float(np.median(rest)), "max_s": float(np.max(rest)),
            "max_material": max(list(rows)[1:] or list(rows), key=lambda m: rows[m]["cpu"])}


def _by_fresnel(cur: dict, base: dict) -> dict:
    """Per Fresnel candidate (when the fits record them): min / max of the objective ratio
    current / baseline over the materials, and how many are above / below by > 1e-9."""
    out = {}
    for m in cur:
        a, b = cur[m].get("objective_by_fresnel") or {}, base[m].get("objective_by_fresnel") or {}
        for k in set(a) & set(b):
            if b[k] > 0:
                out.setdefault(k, []).append((a[k] / b[k], m))
    return {k: {"min": min(v), "max": max(v), "above": sum(r > 1 + 1e-9 for r, _ in v),
                "below": sum(r < 1 - 1e-9 for r, _ in v), "n": len(v)} for k, v in out.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default="ggx-diffuse")
    ap.add_argument("--baseline", default=None, help="git revision to compare with")
    ap.add_argument("--limit", type=int, default=0)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    if not ZIP.is_file():
        sys.exit(f"needs {ZIP} (../shared/data)")
    result = {"model": args.model, "load_average_before": os.getloadavg()}
    print("fitting with the current tree ...", flush=True)
    cur = run_tree(ROOT / "src", args.model, args.limit)
    result["current"] = {"cpu": _cpu(cur), "materials": cur}
    if args.baseline:
        with tempfile.TemporaryDirectory() as tmp:
            subprocess.run(f"git archive {args.baseline} src | tar -x -C {tmp}", shell=True,
                           cwd=ROOT, check=True)
            print(f"fitting with {args.baseline} ...", flush=True)
            base = run_tree(Path(tmp) / "src", args.model, args.limit)
        diffs = {m: max(_rel(base[m][k], cur[m][k]) for k in ("alpha", "rho_d", "F0", "objective")
                        if base[m][k] is not None) for m in cur}
        worst = max(diffs, key=diffs.get)
        result["baseline"] = {"revision": args.baseline, "cpu": _cpu(base), "materials": base}
        result["comparison"] = {
            "max_relative_parameter_difference": diffs[worst], "at": worst,
            "same_fresnel": sum(base[m]["fresnel"] == cur[m]["fresnel"] for m in cur),
            "n": len(cur),
            "cpu_total_ratio": sum(cur[m]["cpu"] for m in cur) / sum(base[m]["cpu"] for m in cur),
            "objective_ratio_by_fresnel": _by_fresnel(cur, base)}
    result["load_average_after"] = os.getloadavg()
    out = Path(args.out or ROOT / "bench" / "results" / f"fit_times_{args.model}.json")
    out.write_text(json.dumps(result, indent=1) + "\n")
    for k in ("current", "baseline"):
        if k in result:
            print(k, json.dumps(result[k]["cpu"]))
    if "comparison" in result:
        print(json.dumps(result["comparison"]))
    print(f"load {result['load_average_before']} -> {result['load_average_after']}; wrote {out}")


if __name__ == "__main__":
    main()
