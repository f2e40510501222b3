"""G-from-D from two starts: after how many polish iterations the start that ends lower can be
told (the evidence for ``G_FROM_D_STARTS`` and ``G_FROM_D_SCREEN_POLISH`` of
:mod:`brdffit.fit.npf`).

Per Neural-BRDF MERL material: G-from-D's AWLS (the product's settings) from the data slices
and from all ones; from each AWLS point the product's polish run to its cap (60) and, apart,
its first ``k`` iterations for each ``--screens`` k. Per material and channel the summary
compares the start that is lower after ``k`` polish iterations (k = 0: after the AWLS) with
the one that ends lower: the objective of the fit that keeps the start picked at k, over
the better of the two ends and over the best-known objective of ``best_known.csv`` (the
default's Eq. 7 there scaled by the solver's ratio; materials without a best-known row are
left out of that count)::

    .venv/bin/python bench/studies/gfd_starts.py --part 0/2 &
    .venv/bin/python bench/studies/gfd_starts.py --part 1/2; \\
        .venv/bin/python bench/studies/gfd_starts.py --summarise

Writes ``bench/results/gfd_starts_materials.jsonl`` (one record per material, appended,
resumable) and, with ``--summarise``, ``bench/results/gfd_starts.json``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "bench"))  # _common

import numpy as np  # noqa: E402

from _common import NBRDF, merl_materials  # noqa: E402

RECORDS = ROOT / "bench" / "results" / "gfd_starts_materials.jsonl"
SUMMARY = ROOT / "bench" / "results" / "gfd_starts.json"
BEST_KNOWN = ROOT / "bench" / "results" / "best_known.csv"
STARTS = ("slices", "ones")


def measure(name: str, screens) -> dict:
    from brdffit.fit.npf import (DEFAULT_POLISH, G_FROM_D_EXTRAPOLATE_AFTER, POLISH_BOUNDED,
                                 _slice_start, _ones_start, _solver)
    from brdffit.grid import tabulate_merl_grid
    from brdffit.io import load
    from brdffit.losses.objective import prepare_objective

    values, valid = tabulate_merl_grid(load(f"{NBRDF}:{name}"))
    smp = _solver.Samples.from_objective(prepare_objective(values, valid))
    polish = dict(eps=0.0, tol=1e-6, g_from_d=True, bound=2.0, newton=True,
                  bounded=POLISH_BOUNDED["g-from-d"])
    rec = {"material": name, "load": os.getloadavg()[0]}
    for start in STARTS:
        st = _slice_start(values, valid) if start == "slices" else _ones_start()
        c0 = time.process_time()
        awls = _solver.run_g_from_d(st, smp, eps=0.0, tol=1e-6, max_iter=300,
                                    extrapolate_after=G_FROM_D_EXTRAPOLATE_AFTER)
        c1 = time.process_time()
        full = _solver.polish_lm(awls.state.copy(), smp, max_iter=DEFAULT_POLISH["g-from-d"],
                                 **polish)
        c2 = time.process_time()
        rec[start] = {"awls_E": awls.E.tolist(), "awls_it": awls.iterations,
                      "awls_cpu": c1 - c0, "pol_E": np.minimum(full.E, awls.E).tolist(),
                      "pol_it": full.iterations, "pol_cpu": c2 - c1}
        for k in screens:
            short = _solver.polish_lm(awls.state.copy(), smp, max_iter=k, **polish)
            rec[f"{start}_{k}"] = {"E": np.minimum(short.E, awls.E).tolist(),
                                   "it": short.iterations}
    return rec


def _best_known() -> dict:
    """material -> (Eq. 7 of the single-start default, ``slices``; the best-known)."""
    best, slices = defaultdict(lambda: np.inf), {}
    if BEST_KNOWN.is_file():
        with open(BEST_KNOWN, newline="") as f:
            for r in csv.DictReader(f):
                if r["model"] == "npf-g-from-d":
                    best[r["material"]] = min(best[r["material"]], float(r["objective"]))
                    if r["config"] == "slices":
                        slices[r["material"]] = float(r["objective"])
    return {m: (slices[m], best[m]) for m in slices}


def summarise(records: list[dict], screens) -> dict:
    """Per k (0: the AWLS objective): channels where the start picked at k is not the one
    that ends lower (by more than 0.05 %), materials whose kept fit ends more than 1 %
    above the better end, and within 1 % / 5 % of the best-known."""
    known = _best_known()
    out = {}
    for k in (0, *screens):
        wrong = above = w1 = w5 = n_known = 0
        worst = (1.0, None)
        for rec in records:
            ends = np.array([rec[s]["pol_E"] for s in STARTS])
            at_k = np.array([rec[s]["awls_E"] if k == 0 else rec[f"{s}_{k}"]["E"]
                             for s in STARTS])
            pick = np.argmin(at_k, axis=0)
            kept = ends[pick, np.arange(3)]
            wrong += int(np.sum(kept > ends.min(axis=0) * 1.0005))
            above += bool(kept.sum() > ends.min(axis=0).sum() * 1.01)
            if rec["material"] in known:           # the single-start default's Eq. 7, scaled
                default, best = known[rec["material"]]
                ratio = default * kept.sum() / ends[0].sum() / best
                n_known += 1
                w1 += int(ratio <= 1.01)
                w5 += int(ratio <= 1.05)
                worst = max(worst, (float(ratio), rec["material"]), key=lambda t: t[0])
        out[str(k)] = {"channels_picked_wrong": wrong, "materials_above_better_end_1pc": above,
                       "within_1pc_of_best_known": w1, "within_5pc_of_best_known": w5,
                       "with_best_known": n_known, "worst_vs_best_known": worst}
    loads = [float(r["load"]) for r in records if r.get("load") is not None]
    cpu = {s: float(np.mean([r[s]["awls_cpu"] for r in records])) for s in STARTS}
    pol = {s: float(np.mean([r[s]["pol_cpu"] for r in records])) for s in STARTS}
    return {"study": "gfd_starts", "materials": len(records), "screens": list(screens),
            "per_screen": out, "awls_cpu_s_mean": cpu, "polish_cpu_s_mean": pol,
            "load": [min(loads, default=None), max(loads, default=None)]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--part", default="0/1", help="i/n: every n-th material from the i-th")
    ap.add_argument("--screens", default="4,8,15")
    ap.add_argument("--summarise", action="store_true")
    args = ap.parse_args(argv)
    screens = tuple(int(k) for k in args.screens.split(",") if k)
    done = ([json.loads(line) for line in RECORDS.read_text().splitlines() if line]
            if RECORDS.is_file() else [])
    if args.summarise:
        SUMMARY.write_text(json.dumps(summarise(done, screens), indent=1) + "\n")
        return 0
    i, n = (int(x) for x in args.part.split("/"))
    seen = {r["material"] for r in done}
    for name in merl_materials(NBRDF)[i::n]:
        if name not in seen:
            with open(RECORDS, "a") as f:
                f.write(json.dumps(measure(name, screens)) + "\n")
            print(name, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
