"""NPF independent-G convergence study: objective against CPU time and
iterations for solver configurations, side by side on the same materials in one run.

    nice -n 5 .venv/bin/python bench/studies/npf_convergence.py --materials 5 \\
        --configs default,extrapolate,screen20-extrapolate

Each configuration fits ``merl_nbrdf.zip:<name>`` (materials evenly spaced over the
alphabetical list) from the same tabulated data; CPU time of the process (all threads),
final objective, objective relative to ``default``, stop reason of the final run, and the
objective history. Results: ``bench/results/npf_convergence.json`` (+ ``.csv``) and
``npf_convergence.png`` (objective / final objective of ``default`` against CPU time).
Every configuration is an option of ``fit_npf`` (or the module constant ``G_OVER_RELAX``) of
this tree.
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

CONFIGS = {
    "default": {},
    "extrapolate": {"extrapolate": True},
    "screen20-extrapolate": {"start_max_iter": 20, "extrapolate": True},
    "screen20": {"start_max_iter": 20},
    "polish30": {"polish": 30},
    "cap3000-extrapolate": {"extrapolate": True, "max_iter": 3000},
    "screen20-extrapolate-cap2000": {"start_max_iter": 20, "extrapolate": True, "max_iter": 2000},
    # the over-relaxation ω of the independent-G G step (module constant G_OVER_RELAX)
    "omega1": {"_g_over_relax": 1.0},
    "omega1.3": {"_g_over_relax": 1.3},
    "omega1.9": {"_g_over_relax": 1.9},
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--materials", type=int, default=5, help="how many, evenly spaced")
    ap.add_argument("--only", default="", help="comma-separated names instead")
    ap.add_argument("--configs", default="default,extrapolate,screen20-extrapolate")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "npf_convergence"))
    args = ap.parse_args(argv)

    import numpy as np

    from brdffit.batch import enumerate_materials
    from brdffit.fit.npf import _solver, fit_npf
    from brdffit.grid import tabulate_merl_grid
    from brdffit.io import load

    names = [n for n, _ in enumerate_materials("merl_nbrdf.zip")]
    if args.only:
        chosen = args.only.split(",")
    else:
        step = len(names) / args.materials
        chosen = [names[int(i * step)] for i in range(args.materials)]
    configs = args.configs.split(",")
    load0 = os.getloadavg()
    rows, curves = [], {}
    for name in chosen:
        data = tabulate_merl_grid(load(f"merl_nbrdf.zip:{name}"))
        base = None
        for cfg in configs:
            c0, t0 = time.process_time(), time.perf_counter()
            trace = []

            def cb(it, e, c0=c0, trace=trace):
                trace.append((time.process_time() - c0, e))

            kwargs = dict(CONFIGS[cfg])
            omega = kwargs.pop("_g_over_relax", _solver.G_OVER_RELAX)
            saved, _solver.G_OVER_RELAX = _solver.G_OVER_RELAX, omega
            try:
                m = fit_npf(data=data, variant="independent-g", name=name, callback=cb,
                            **kwargs)
            finally:
                _solver.G_OVER_RELAX = saved
            cpu, wall = time.process_time() - c0, time.perf_counter() - t0
            info = m.fit_info
            last = info.get("continuation") or {}
            reason = last.get("stop_reason") or "screen only"
            E = info["objective"]
            base = E if cfg == "default" else base
            row = {"material": name, "config": cfg, "cpu_s": round(cpu, 2),
                   "wall_s": round(wall, 2), "objective": E,
                   "ratio_to_default": (E / base) if base else None,
                   "iterations": info.get("iterations"), "stop_reason": reason,
                   "converged": reason.startswith(("relative", "exact")),
                   "load": os.getloadavg()[0]}
            rows.append(row)
            curves[f"{name}/{cfg}"] = trace
            print(json.dumps(row), flush=True)
    out = Path(args.out)
    summary = {}
    for cfg in configs:
        r = [x for x in rows if x["config"] == cfg]
        summary[cfg] = {
            "n": len(r), "cpu_s_mean": float(np.mean([x["cpu_s"] for x in r])),
            "cpu_s_max": float(np.max([x["cpu_s"] for x in r])),
            "converged": sum(x["converged"] for x in r),
            "ratio_to_default_max": max((x["ratio_to_default"] or 1.0) for x in r),
            "ratio_to_default_mean": float(np.mean([x["ratio_to_default"] or 1.0 for x in r]))}
    fig = {"benchmark": "NPF independent-G convergence",
           "command": "bench/studies/npf_convergence.py " + " ".join(argv or sys.argv[1:]),
           "configs": {c: CONFIGS[c] for c in configs}, "materials": chosen,
           "timer": "time.process_time (all threads of the process)",
           "load_average_start": load0, "load_average_end": os.getloadavg(),
           "summary": summary, "rows": rows}
    out.with_suffix(".json").write_text(json.dumps(fig, indent=1))
    with open(out.with_suffix(".csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig_, axes = plt.subplots(1, len(chosen), figsize=(3.2 * len(chosen), 3), squeeze=False)
        for ax, name in zip(axes[0], chosen):
            ref = next(x["objective"] for x in rows if x["material"] == name)
            for cfg in configs:
                tr = curves[f"{name}/{cfg}"]
                if tr:
                    t, e = zip(*tr)
                    ax.plot(t, np.asarray(e) / ref, ".", ms=1.5, label=cfg)
            ax.set_ylim(0.97, 1.1)
            ax.set_title(name, fontsize=8)
            ax.set_xlabel("CPU s")
        axes[0][0].set_ylabel("objective / default final")
        axes[0][-1].legend(fontsize=6)
        fig_.tight_layout()
        fig_.savefig(out.with_suffix(".png"), dpi=80)
    except Exception as exc:  # noqa: BLE001 - the figures matter more than the plot
        print(f"plot skipped: {exc}")
    for cfg, s in summary.items():
        print(cfg, s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
