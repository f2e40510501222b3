"""NPF fits with the product's defaults: convergence rate, time and
objective against a reference run.

For each Neural-BRDF MERL material (tabulated once): ``fit_npf(variant="independent-g")``
(all starts) and ``fit_npf(variant="g-from-d")`` with no options (``--models
npf-g-from-d,npf-g-from-d-plain``: also G-from-D without over-relaxation, side by side); CPU time of the process
(all threads) and wall time, the final objective (Eq. 7), ``converged``, iterations, stop
reason. With ``--reference DIR`` (a ``brdffit batch`` output whose ``fits/<material>/npf.npz``
and ``npf-g-from-d.npz`` were made by an earlier version) the objective ratio new / reference
per material, i.e. "never above today's capped fit". Materials of the reference run first.

    nice .venv/bin/python bench/studies/npf_defaults.py --reference runs/db20

Writes ``bench/results/npf_defaults.json`` (summary, load average) and
``npf_defaults_materials.csv`` (one row per material × variant) atomically after every
material; re-running resumes.
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
#: model → (variant, options); ``npf-awls`` is independent-G without the Newton polish (the
#: defaults compared in docs/design/npf-fit.md); ``npf-g-from-d-plain`` is G-from-D without
#: the over-relaxed sweeps and the polish, ``npf-g-from-d-awls`` without the polish, run side
#: by side with ``--models``
VARIANTS = {"npf": ("independent-g", {}), "npf-awls": ("independent-g", {"polish": 0}),
            "npf-g-from-d": ("g-from-d", {}),
            "npf-g-from-d-awls": ("g-from-d", {"polish": 0}),
            "npf-g-from-d-plain": ("g-from-d", {"extrapolate": False, "polish": 0})}
DEFAULT_MODELS = ("npf", "npf-g-from-d")
FIELDS = ["material", "model", "cpu_s", "wall_s", "objective", "converged", "nit",
          "stop_reason", "continuation_iterations", "polish_iterations", "awls_objective",
          "ratio_to_awls", "reference_objective", "ratio_to_reference", "reference_converged",
          "reference_time_s"]


def _stats(xs):
    xs = [float(x) for x in xs]
    return {"min": min(xs), "avg": float(np.mean(xs)), "median": float(np.median(xs)),
            "max": max(xs), "n": len(xs)} if xs else {}


def summarise(rows, args, load0):
    out = {"benchmark": "NPF with product defaults", "command": " ".join(sys.argv),
           "independent_g_max_iter": args.max_iter or "default",
           "load_average_start": load0, "load_average_now": list(os.getloadavg()),
           "cpus": os.cpu_count(), "per_model": {}}
    for model in VARIANTS:
        rs = [r for r in rows if r["model"] == model]
        if not rs:
            continue
        ratios = [float(r["ratio_to_reference"]) for r in rs if r["ratio_to_reference"]]
        out["per_model"][model] = {
            "materials": len(rs),
            "converged": sum(r["converged"] == "True" for r in rs),
            "cpu_s": _stats(r["cpu_s"] for r in rs),
            "wall_s": _stats(r["wall_s"] for r in rs),
            "iterations": _stats(r["nit"] for r in rs),
            "with_reference": len(ratios),
            "ratio_to_reference": _stats(ratios),
            "above_reference": sum(x > 1.0 for x in ratios),
            "above_reference_by_more_than_1e-3": sum(x > 1.001 for x in ratios),
            "ratio_to_awls": _stats(float(r["ratio_to_awls"]) for r in rs
                                    if r.get("ratio_to_awls")),
            "polish_iterations": _stats(r["polish_iterations"] for r in rs
                                        if r.get("polish_iterations")),
            "not_converged": [r["material"] for r in rs if r["converged"] != "True"],
        }
    # side by side in this run: objective and CPU of each model against each other, per material
    by = {(r["material"], r["model"]): r for r in rows}
    models = [m for m in VARIANTS if m in out["per_model"]]
    for i, a in enumerate(models):
        for b in models[i + 1:]:
            both = [m for (m, mod) in by if mod == a and (m, b) in by]
            if not both:
                continue
            ratio = [float(by[m, a]["objective"]) / float(by[m, b]["objective"]) for m in both]
            cpu_a = sum(float(by[m, a]["cpu_s"]) for m in both)
            cpu_b = sum(float(by[m, b]["cpu_s"]) for m in both)
            out.setdefault("side_by_side", {})[f"{a} / {b}"] = {
                "materials": len(both), "objective_ratio": _stats(ratio),
                "above": sum(x > 1.0 for x in ratio), "above_materials":
                    {m: x for m, x in zip(both, ratio) if x > 1.0},
                "cpu_total_ratio": cpu_a / cpu_b if cpu_b else None}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--zip", default=str(ZIP))
    ap.add_argument("--reference", default=None, help="brdffit batch output of an earlier run")
    ap.add_argument("--only", default="", help="comma-separated material names")
    ap.add_argument("--models", default=",".join(DEFAULT_MODELS),
                    help=f"comma-separated, among {', '.join(VARIANTS)}")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "npf_defaults"))
    ap.add_argument("--max-iter", type=int, default=None,
                    help="independent-G cap instead of the default (a study, not the product)")
    args = ap.parse_args(argv)
    if not Path(args.zip).exists():
        print(f"skipped: {args.zip} not found (needs ../shared/data)")
        return 0
    from brdffit import load_fit
    from brdffit.batch import enumerate_materials
    from brdffit.fit.npf import fit_npf
    from brdffit.grid import tabulate_merl_grid
    from brdffit.io import load

    names = [n for n, _ in enumerate_materials(args.zip)]
    ref_dir = Path(args.reference) if args.reference else None
    if ref_dir:
        first = [n for n in names if (ref_dir / "fits" / n).is_dir()]
        names = first + [n for n in names if n not in first]
    if args.only:
        names = args.only.split(",")
    models = args.models.split(",")
    csv_path, json_path = Path(args.out + "_materials.csv"), Path(args.out + ".json")
    rows = list(csv.DictReader(open(csv_path))) if csv_path.exists() else []
    done = {(r["material"], r["model"]) for r in rows}
    load0 = list(os.getloadavg())
    for name in names:
        todo = [m for m in models if (name, m) not in done]
        if not todo:
            continue
        data = tabulate_merl_grid(load(f"{args.zip}:{name}"))
        for model in todo:
            c0, w0 = time.process_time(), time.perf_counter()
            variant, kw = VARIANTS[model]
            if args.max_iter and model == "npf":
                kw = dict(kw, max_iter=args.max_iter)
            fi = fit_npf(data=data, variant=variant, name=name, **kw).fit_info
            row = {"material": name, "model": model,
                   "cpu_s": round(time.process_time() - c0, 2),
                   "wall_s": round(time.perf_counter() - w0, 2),
                   "objective": fi["objective"], "converged": fi["converged"],
                   "nit": fi["nit"], "stop_reason": fi["stop_reason"],
                   "continuation_iterations": fi.get("continuation", {}).get("iterations", 0)}
            if "polish" in fi:
                awls = float(fi["polish"]["awls_objective"])   # where AWLS stopped
                row.update(polish_iterations=fi["polish"]["iterations"], awls_objective=awls,
                           ratio_to_awls=fi["objective"] / awls)
            ref_model = "npf-g-from-d" if model.startswith("npf-g-from-d") else model
            ref = ref_dir / "fits" / name / f"{ref_model}.npz" if ref_dir else None
            if ref is not None and ref.exists():
                rfi = load_fit(ref).fit_info
                row.update(reference_objective=rfi["objective"],
                           ratio_to_reference=fi["objective"] / rfi["objective"],
                           reference_converged=rfi.get("converged"),
                           reference_time_s=rfi.get("time", rfi.get("time_s")))
            rows.append(row)
            print(f"{name:28s} {model:13s} cpu {row['cpu_s']:6.1f} s  wall {row['wall_s']:6.1f} s"
                  f"  conv {fi['converged']!s:5s} it {fi['nit']:5d}"
                  f"  ratio {row.get('ratio_to_reference', float('nan')):.5f}", flush=True)
        rows = write_csv_and_summary(csv_path, json_path, FIELDS, rows,
                                     lambda rs: summarise(rs, args, load0))
    print(json.dumps(summarise(rows, args, load0)["per_model"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
