"""Best-known objectives of the NPF variants and SGD, and how close the product's defaults get.

Per MERL material (Neural-BRDF stand-in on the MERL grid) and model, every configuration of
:data:`CONFIGS` is fitted through the public ``brdffit.fit(..., model=...)``: the product's
defaults first, then more and other starts (random seeds, all-ones, the data slices, more
SGD starts and a finer scan grid) and longer runs. The objective and the constraints stay
the product's (Eq. 7 of Bagher et al. 2016 with compressive weighting, the polish's trust
region): only where the search starts and how long it runs change. For each fit:

* ``objective``: Eq. 7, re-evaluated for every model on the MERL grid with the default
  :class:`brdffit.losses.objective.ObjectiveOptions` (compressive, θi, θo ≤ 89°), so that SGD
  (which minimises its own L2) and every NPF variant are measured alike;
* ``cos_rel``: the cosine-weighted mean relative error
  (:func:`brdffit.losses.objective.relative_error_from_values`);
* ``cpu_s``: the process CPU time of the fit (all threads); the default's includes the
  preparation of its objective but not the tabulation of the Neural-BRDF (:func:`_fresh`).

The best-known objective of a (material, model) is the lowest over its configurations; the
summary gives, per model, on how many materials the default is within 1 % and 5 % of it, the
worst ratios, the cos-rel error of the default against that of the best-known fit, the
spread of the configurations' objectives (distinct basins: objectives more than 1 % apart)
and the default's mean CPU time (fitted from the loaded Neural-BRDF file, as a user would).

Resumable: rows already in ``bench/results/best_known.csv`` are kept, also those of
configurations no longer in :data:`CONFIGS` (their objectives were found, so they count for
the best-known). When a model's defaults change, ``--retire-default LABEL`` renames that
model's existing ``default`` rows to ``LABEL`` (kept as found objectives) so that the new
default is measured. The default materials are those on which the issue's reference fits
beat ours; ``--materials all`` runs the 100::

    nice .venv/bin/python bench/bench_best_known.py
    nice .venv/bin/python bench/bench_best_known.py --models sgd,npf-g-from-d --materials all
    nice .venv/bin/python bench/bench_best_known.py --models npf --configs default \
        --retire-default previous-default
    nice .venv/bin/python bench/bench_best_known.py --merge /tmp/a.csv,/tmp/b.csv

(the last adds the rows of runs with their own ``--out``, e.g. two processes over disjoint
materials, and summarises).

Writes ``bench/results/best_known.csv`` (one row per material × model × configuration) and
``bench/results/best_known.json`` (the summary), atomically after every material.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time

import numpy as np

from _common import NBRDF, ROOT, merl_materials, use_project_sources, write_rows

use_project_sources()

import brdffit  # noqa: E402
from brdffit.grid import tabulate_merl_grid  # noqa: E402
from brdffit.io import load  # noqa: E402
from brdffit.io.merl import MERLBRDF  # noqa: E402
from brdffit.losses.objective import prepare_objective, relative_error_from_values  # noqa: E402

RESULTS = ROOT / "bench" / "results" / "best_known.csv"
#: the materials on which a published fit had a lower objective or error than ours
ISSUE_MATERIALS = ("polyethylene", "yellow-plastic", "black-soft-plastic",
                   "silver-metallic-paint2", "gold-metallic-paint", "violet-acrylic",
                   "pink-plastic", "pvc", "aventurnine")
N_RANDOM_SEEDS = 6


def _random(init_key: str, n: int, **extra) -> list[tuple[str, dict]]:
    return [(f"random-{s}", {init_key: "random", "seed": s, **extra}) for s in range(n)]


#: model -> [(configuration, options)]; the first is the product's default
CONFIGS = {
    "sgd": [("default", {}), ("refine-0", {"refine": 0}), ("starts-20", {"starts": 20}),
            ("starts-100", {"starts": 100}), ("grid-36x16", {"starts": 20, "grid": (36, 16)}),
            ("refine-8", {"starts": 20, "refine": 8})],
    "npf-g-from-d": [("default", {}), ("slices", {"init": "slices"}),
                     ("ones", {"init": "ones"}),
                     *_random("init", N_RANDOM_SEEDS),
                     ("long", {"max_iter": 1200, "polish": 240})],
    "npf-naive": [("default", {}), ("ones", {"init": "ones"}),
                  *_random("init", N_RANDOM_SEEDS), ("long", {"max_iter": 12000})],
    "npf-bivariate": [("default", {})],
    "npf": [("default", {}),
            ("all-starts", {"starts": ("random", "ones", "sgd", "g-from-d", "slices")}),
            ("informed-starts", {"starts": ("ones", "sgd", "slices")}),
            *[(f"random16-seed{s}", {"n_random": 16, "seed": s}) for s in (1, 2)],
            ("long", {"max_iter": 12000, "start_max_iter": None, "polish": 400})],
}
FIELDS = ("material", "model", "config", "objective", "normalised", "cos_rel", "cpu_s",
          "converged", "load")


def _measure(model_fit, objective_data, values, valid) -> dict:
    fit_values, _ = tabulate_merl_grid(model_fit)
    e = objective_data.value(fit_values)
    rel = relative_error_from_values(fit_values, values, valid)["relative_error"]
    return {"objective": float(e.sum()),
            "normalised": float(e.sum() / objective_data.reference_energy().sum()),
            "cos_rel": float(rel)}


def _fresh(name: str):
    """The material loaded anew and tabulated on the MERL grid, so that its fit prepares its
    own objective (Eq. 8's weights) as a user's does, not the one this benchmark prepared for
    the measurements (prepared objectives are memoised per table). The tabulation itself,
    the Neural-BRDF network evaluated on the grid, is left out of the time: a raw MERL file,
    which this stands in for, is that table."""
    loaded = load(f"{NBRDF}:{name}")
    tabulate_merl_grid(loaded)
    return loaded


def run_material(name: str, models, done: set, only=()) -> list[dict]:
    """Every configuration of ``models`` (those named in ``only``, when given) not in
    ``done`` on material ``name``."""
    loaded = load(f"{NBRDF}:{name}")
    values, valid = tabulate_merl_grid(loaded)
    table = MERLBRDF(values, valid, name=name)
    data = prepare_objective(values, valid)
    rows = []
    for model in models:
        for config, options in CONFIGS[model]:
            if (name, model, config) in done or (only and config not in only):
                continue
            # the default from the loaded file (what users run), the others from its table
            source = _fresh(name) if config == "default" else table
            c0 = time.process_time()
            fitted = brdffit.fit(source, model=model, **options)
            cpu = time.process_time() - c0
            res = brdffit.fit_result(fitted)
            row = {"material": name, "model": model, "config": config, "cpu_s": cpu,
                   "converged": res.converged, "load": os.getloadavg()[0],
                   **_measure(fitted, data, values, valid)}
            rows.append(row)
            print(f"{name:24s} {model:14s} {config:18s} objective {row['normalised']:.6g} "
                  f"cos-rel {row['cos_rel']:.4f} CPU {cpu:6.1f} s", flush=True)
    return rows


def _read(path) -> list[dict]:
    """The rows of an earlier run (numbers as floats), or none."""
    if not os.path.isfile(path):
        return []
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        for k in ("objective", "normalised", "cos_rel", "cpu_s", "load"):
            r[k] = float(r[k])
    return rows


def summarise(rows: list[dict]) -> dict:
    """Per model: the defaults against the best-known objective (see the module docstring)."""
    out = {}
    for model in CONFIGS:
        by_material: dict[str, list[dict]] = {}
        for r in rows:
            if r["model"] == model:
                by_material.setdefault(r["material"], []).append(r)
        ratios, rel_ratios, spreads, basins, cpu, worst = [], [], [], [], [], []
        for material, rs in sorted(by_material.items()):
            default = next((r for r in rs if r["config"] == "default"), None)
            if default is None:
                continue
            best = min(rs, key=lambda r: float(r["objective"]))
            objs = np.array([float(r["objective"]) for r in rs])
            ratio = float(default["objective"]) / float(best["objective"])
            ratios.append(ratio)
            rel_ratios.append(float(default["cos_rel"]) / float(best["cos_rel"]))
            spreads.append(float(objs.max() / objs.min()))
            srt = np.sort(objs)
            basins.append(int(1 + np.sum(srt[1:] > srt[:-1] * 1.01)))
            cpu.append(float(default["cpu_s"]))
            worst.append((ratio, material, best["config"]))
        if not ratios:
            continue
        r = np.array(ratios)
        out[model] = {
            "materials": len(r),
            "default_within_1pc": int(np.sum(r <= 1.01)),
            "default_within_5pc": int(np.sum(r <= 1.05)),
            "objective_ratio_default_over_best": {"median": float(np.median(r)),
                                                  "max": float(r.max())},
            "worst": [{"material": m, "ratio": q, "best_config": c}
                      for q, m, c in sorted(worst, reverse=True)[:5]],
            "cos_rel_default_over_best_known_fit": {"median": float(np.median(rel_ratios)),
                                                    "max": float(np.max(rel_ratios)),
                                                    "above_1.05": int(np.sum(
                                                        np.array(rel_ratios) > 1.05))},
            "objective_spread_max_over_min": {"median": float(np.median(spreads)),
                                              "max": float(np.max(spreads))},
            "distinct_basins": {"mean": float(np.mean(basins)), "max": int(np.max(basins))},
            "default_cpu_s": {"mean": float(np.mean(cpu)), "max": float(np.max(cpu))},
        }
    return out


def merge(out: str, paths: list[str]) -> int:
    """Add to ``out`` the rows of ``paths`` it does not hold (by material, model and
    configuration), and write the summary of them all."""
    rows = _read(out)
    seen = {(r["material"], r["model"], r["config"]) for r in rows}
    for path in paths:
        for r in _read(path):
            key = (r["material"], r["model"], r["config"])
            if key not in seen:
                seen.add(key)
                rows.append(r)
    write_rows(out, FIELDS, rows, _summary(rows, merged=paths))
    return 0


def _summary(rows: list[dict], **extra) -> dict:
    """The JSON written next to the CSV: the run, the configurations and :func:`summarise`."""
    return {"benchmark": "best_known", "command": " ".join(sys.argv),
            "date": time.strftime("%Y-%m-%dT%H:%M:%S"), **extra,
            "configs": {m: [c for c, _ in CONFIGS[m]] for m in CONFIGS},
            "per_model": summarise(rows)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", default=",".join(CONFIGS),
                    help=f"comma-separated subset of {', '.join(CONFIGS)}")
    ap.add_argument("--materials", default=",".join(ISSUE_MATERIALS),
                    help="comma-separated MERL names, or 'all'")
    ap.add_argument("--configs", default="",
                    help="comma-separated subset of the configurations (default: all)")
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--retire-default", default="", metavar="LABEL",
                    help="rename the existing 'default' rows of --models to LABEL first "
                         "(after a change of the defaults; the rows stay as found objectives)")
    ap.add_argument("--merge", default="", metavar="A.csv,B.csv",
                    help="only add the rows of these CSVs (runs with their own --out, e.g. "
                         "two processes over disjoint materials) to --out and summarise")
    args = ap.parse_args(argv)
    if args.merge:
        return merge(args.out, [p for p in args.merge.split(",") if p])
    models = [m for m in args.models.split(",") if m]
    unknown = [m for m in models if m not in CONFIGS]
    if unknown:
        ap.error(f"unknown model(s) {unknown}; expected some of {', '.join(CONFIGS)}")
    if not NBRDF.is_file():
        print(f"{NBRDF} not found: nothing measured", file=sys.stderr)
        return 1
    names = merl_materials(NBRDF, None if args.materials == "all" else args.materials)
    rows = _read(args.out)
    if args.retire_default:          # once per (material, model): resuming keeps new rows
        retired = {(r["material"], r["model"]) for r in rows
                   if r["config"] == args.retire_default}
        for r in rows:
            if (r["model"] in models and r["config"] == "default"
                    and (r["material"], r["model"]) not in retired):
                r["config"] = args.retire_default
    done = {(r["material"], r["model"], r["config"]) for r in rows}
    load0 = os.getloadavg()
    for name in names:
        rows += run_material(name, models, done, [c for c in args.configs.split(",") if c])
        write_rows(args.out, FIELDS, rows, _summary(rows, load_average_start=load0,
                                                    load_average_now=os.getloadavg()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
