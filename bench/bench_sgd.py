"""Benchmark of the SGD fit (Bagher, Soler, Holzschuch 2012) → bench/results/sgd.json.

Usage::

    .venv/bin/python bench/bench_sgd.py                 # synthetic recovery + speed
    .venv/bin/python bench/bench_sgd.py --real          # + all 100 Neural-BRDF MERL materials
    .venv/bin/python bench/bench_sgd.py --real --limit 10 --phi-stride 4
    .venv/bin/python bench/bench_sgd.py --skip-synthetic --modes 16   # paper vs default fit
    .venv/bin/python bench/bench_sgd.py --skip-synthetic --modes 16 --psnr   # + renderings

Speed (``--speed [N]``): CPU time (``time.process_time``) of ``fit_sgd`` on the first N (10)
Neural-BRDF MERL materials, median of ``--repeats`` fits per material, timed cold (memoised
grid tables cleared before each fit, as a fresh ``brdffit fit`` process) and warm (as the later
materials of a batch), side by side; the compressive objective (brdffit.losses.objective,
Bagher et al. 2016 Eq. 7) of the fit against the network tabulated on the MERL grid, and the
fit's convergence report. ``--merl-grid`` fits the tabulated table (a MERL file) instead of the
network. Written to the ``speed`` section of bench/results/sgd.json (``network`` or
``merl_grid``)::

    .venv/bin/python bench/bench_sgd.py --speed 10 --skip-synthetic

Synthetic part: SGD materials with known per-channel (α, p, ρd, ρs, F0, F1) are fitted with
``fit_sgd``; relative errors on α and p, absolute on F0/F1, time per material (full fit,
including the Eq. 6 G1 tables and the Eq. 9 approximation).

Real part (``--real``): every material of ``../shared/data/nbrdf/merl_nbrdf.zip`` is fitted
with the SGD and the two-slice Beckmann (and GGX) procedures, and the normalised L2 error of
§6.3 (brdffit.losses.l2, MERL-grid quadrature) is computed over the full domain and over
θi, θo ≤ 80°. Counts: materials where SGD beats two-slice Beckmann, NaN, failures. The
materials the seed papers single out (two-layer-gold, color-changing-paint1, white-paint)
are reported in detail, with the full-data Cook-Torrance fits for reference.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import traceback
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from brdffit._atomic import atomic_write  # noqa: E402
from brdffit.fit.sgd import (fit_beckmann_two_slice, fit_cook_torrance,  # noqa: E402
                             fit_ggx_two_slice, fit_sgd)
from brdffit.microfacet.sgd import SGD  # noqa: E402
from brdffit.microfacet.sgd_model import PerChannelMicrofacetBRDF  # noqa: E402

NBRDF = ROOT.parent / "shared" / "data" / "nbrdf" / "merl_nbrdf.zip"
SHOWCASE = ("two-layer-gold", "color-changing-paint1", "white-paint")
OUT = ROOT / "bench" / "results" / "sgd.json"


def synthetic_materials(seed: int = 2012) -> dict[str, list[dict]]:
    """Hand-picked plus random SGD materials (per channel α, p, ρd, ρs, F0, F1)."""
    mats = {
        "sharp-metal": [dict(alpha=0.004, p=2.3, rho_d=0.01, rho_s=0.05, F0=0.9, F1=0.2),
                        dict(alpha=0.005, p=2.1, rho_d=0.02, rho_s=0.06, F0=0.7, F1=0.1),
                        dict(alpha=0.004, p=2.4, rho_d=0.015, rho_s=0.04, F0=0.5, F1=0.0)],
        "glossy-paint": [dict(alpha=0.06, p=1.3, rho_d=0.25, rho_s=0.4, F0=0.08, F1=0.03),
                         dict(alpha=0.07, p=1.1, rho_d=0.12, rho_s=0.5, F0=0.05, F1=0.0),
                         dict(alpha=0.05, p=1.5, rho_d=0.05, rho_s=0.3, F0=0.12, F1=0.06)],
        "rough": [dict(alpha=0.4, p=0.3, rho_d=0.3, rho_s=0.8, F0=0.3, F1=0.1),
                  dict(alpha=0.35, p=0.6, rho_d=0.2, rho_s=0.9, F0=0.2, F1=0.0),
                  dict(alpha=0.45, p=-0.5, rho_d=0.1, rho_s=0.7, F0=0.4, F1=0.2)],
    }
    rng = np.random.default_rng(seed)
    for k in range(5):
        rows = []
        la = rng.uniform(np.log(0.002), np.log(0.3))
        p = rng.uniform(0.2, 2.6)
        for _ in range(3):
            f0 = rng.uniform(0.02, 0.95)
            rows.append(dict(alpha=float(np.exp(la + rng.normal(0, 0.1))),
                             p=float(p + rng.normal(0, 0.1)),
                             rho_d=float(rng.uniform(0.0, 0.4)),
                             rho_s=float(rng.uniform(0.05, 1.0)),
                             F0=float(f0), F1=float(rng.uniform(0.0, 0.5 * f0))))
        mats[f"random-{k}"] = rows
    return mats


def truth_model(rows) -> PerChannelMicrofacetBRDF:
    return PerChannelMicrofacetBRDF(
        [{"distribution": SGD(r["alpha"], r["p"]),
          **{k: r[k] for k in ("rho_d", "rho_s", "F0", "F1")}} for r in rows], name="truth")


def truth_max_albedo(row) -> float:
    """Largest directional albedo of one truth channel (quadrature of brdffit.fit.sgd)."""
    from brdffit.fit.sgd import _albedo_rows

    rows = _albedo_rows("sgd", row["alpha"], row["p"])
    rs, f0, f1 = row["rho_s"], row["F0"], row["F1"]
    return float(np.max(rows @ np.array([row["rho_d"], rs * f0, rs * (1 - f0), rs * (f0 - f1)])))


def run_synthetic() -> dict:
    """Parameter recovery; ``worst`` over the physically valid truths only (the default fit
    bounds the albedo by 1, so a truth above 1 cannot be recovered: ``worst_all``)."""
    fit_sgd(truth_model(synthetic_materials()["glossy-paint"]))      # warm-up (imports)
    out, worst = {}, {"alpha_rel": 0.0, "p_rel": 0.0, "F0_abs": 0.0, "F1_abs": 0.0}
    worst_all = dict(worst)
    times = []
    for name, rows in synthetic_materials().items():
        t0 = time.perf_counter()
        model = fit_sgd(truth_model(rows))
        dt = time.perf_counter() - t0
        times.append(dt)
        chans = []
        for got, want in zip(model.channel_params(), rows):
            e = {"alpha_rel": abs(got["alpha"] / want["alpha"] - 1),
                 "p_rel": abs(got["p"] - want["p"]) / max(abs(want["p"]), 1e-12),
                 "F0_abs": abs(got["F0"] - want["F0"]), "F1_abs": abs(got["F1"] - want["F1"])}
            alb = truth_max_albedo(want)
            for k in worst:
                worst_all[k] = max(worst_all[k], e[k])
                if alb <= 1.0:
                    worst[k] = max(worst[k], e[k])
            chans.append({"truth": want, "fit": {k: got[k] for k in want}, "errors": e,
                          "truth_max_albedo": alb, "g1_approx": got.get("g1_approx")})
        out[name] = {"time_s": dt, "fit_info": {k: v for k, v in model.fit_info.items()
                                                if k.startswith("time")}, "channels": chans}
        print(f"  {name:14s} {dt:6.2f} s  max α rel {max(c['errors']['alpha_rel'] for c in chans):.2e}"
              f"  p rel {max(c['errors']['p_rel'] for c in chans):.2e}"
              f"  F0 abs {max(c['errors']['F0_abs'] for c in chans):.2e}", flush=True)
    return {"materials": out, "worst": worst, "worst_all": worst_all,
            "time_median_s": float(np.median(times)),
            "time_max_s": float(np.max(times)),
            "targets_met": bool(worst["alpha_rel"] <= 0.01 and worst["p_rel"] <= 0.01
                                and worst["F0_abs"] <= 0.01)}


def _params(model):
    return [{k: v for k, v in r.items() if k != "g1_approx"} for r in model.channel_params()]


def run_real(limit: int | None, phi_stride: int, prev: dict | None) -> dict:
    import brdffit
    from brdffit.losses.l2 import L2Reference
    from brdffit.io.nbrdf import list_materials

    names = list_materials(NBRDF)
    if limit:
        names = [n for n in SHOWCASE if n in names] + [n for n in names if n not in SHOWCASE]
        names = names[:limit]
    results = dict((prev or {}).get("materials", {}))
    for i, name in enumerate(names):
        if name in results and "error" not in results[name]:
            continue
        rec: dict = {}
        try:
            brdf = brdffit.load(f"{NBRDF}:{name}")
            ref = L2Reference(brdf, phi_stride=phi_stride, albedo_samples=4096)
            fits = {"sgd": fit_sgd, "beckmann-2s": fit_beckmann_two_slice,
                    "ggx-2s": fit_ggx_two_slice}
            if name in SHOWCASE:
                fits["beckmann-ct"] = lambda b: fit_cook_torrance(b, "beckmann")
                fits["ggx-ct"] = lambda b: fit_cook_torrance(b, "ggx")
            for key, fn in fits.items():
                t0 = time.perf_counter()
                try:
                    model = fn(brdf)
                except Exception as exc:            # a failed fit is a result, not a crash
                    rec[key] = {"error": f"{type(exc).__name__}: {exc}"}
                    continue
                dt = time.perf_counter() - t0
                e, e80 = ref.errors(model, theta_max=(np.radians(80.0),))
                rec[key] = {"time_s": dt, "l2": e.value, "l2_80": e80.value,
                            "l2_per_channel": e.per_channel.tolist(),
                            "nan": bool(not np.isfinite(e.value)), "params": _params(model)}
        except Exception as exc:
            rec["error"] = f"{type(exc).__name__}: {exc}"
            traceback.print_exc()
        results[name] = rec
        s, b = rec.get("sgd", {}), rec.get("beckmann-2s", {})
        print(f"  [{i + 1:3d}/{len(names)}] {name:28s} SGD {s.get('l2', np.nan):9.4g} "
              f"({s.get('l2_80', np.nan):8.4g})  Beckmann-2s {b.get('l2', np.nan):9.4g} "
              f"({b.get('l2_80', np.nan):8.4g})  t_sgd {s.get('time_s', np.nan):5.2f} s", flush=True)
        yield results


def summarize_real(results: dict) -> dict:
    def get(rec, key, field):
        v = rec.get(key, {}).get(field)
        return np.nan if v is None else v

    names = sorted(results)
    sgd = np.array([get(results[n], "sgd", "l2") for n in names])
    bec = np.array([get(results[n], "beckmann-2s", "l2") for n in names])
    ggx = np.array([get(results[n], "ggx-2s", "l2") for n in names])
    sgd80 = np.array([get(results[n], "sgd", "l2_80") for n in names])
    bec80 = np.array([get(results[n], "beckmann-2s", "l2_80") for n in names])
    t = np.array([get(results[n], "sgd", "time_s") for n in names])
    failures = {n: {k: v["error"] for k, v in results[n].items()
                    if isinstance(v, dict) and "error" in v} for n in names}
    failures = {n: v for n, v in failures.items() if v}
    return {
        "n_materials": len(names),
        "sgd_better_than_beckmann_2s": int(np.sum(sgd < bec)),
        "sgd_better_than_beckmann_2s_theta80": int(np.sum(sgd80 < bec80)),
        "sgd_better_than_ggx_2s": int(np.sum(sgd < ggx)),
        "materials_where_beckmann_2s_wins": [n for n, a, b in zip(names, sgd, bec) if not a < b],
        "sgd_nan": int(np.sum(~np.isfinite(sgd))), "failures": failures,
        "median_l2": {"sgd": float(np.nanmedian(sgd)), "beckmann-2s": float(np.nanmedian(bec)),
                      "ggx-2s": float(np.nanmedian(ggx))},
        "median_l2_theta80": {"sgd": float(np.nanmedian(sgd80)),
                              "beckmann-2s": float(np.nanmedian(bec80))},
        "sgd_time_s": {"median": float(np.nanmedian(t)), "max": float(np.nanmax(t)),
                       "under_1s": int(np.sum(t < 1.0))},
        "showcase": {n: results[n] for n in SHOWCASE if n in results},
    }


def g1_approximation_stats(results: dict) -> dict:
    """Eq. 9 approximation error over every fitted SGD channel of the real materials."""
    l2, rms, mse = [], [], []
    for rec in results.values():
        for row in rec.get("sgd", {}).get("params", []):
            ap = SGD(row["alpha"], row["p"]).g1_approximation()
            l2.append(ap["l2"]), rms.append(ap["rms"]), mse.append(ap["mse"])
    l2, rms, mse = map(np.asarray, (l2, rms, mse))
    return {"n_channels": int(l2.size),
            "l2": {"median": float(np.median(l2)), "max": float(np.max(l2)),
                   "fraction_below_1e-5": float(np.mean(l2 < 1e-5))},
            "rms": {"median": float(np.median(rms)), "max": float(np.max(rms))},
            "mse": {"median": float(np.median(mse)), "max": float(np.max(mse)),
                    "fraction_below_1e-5": float(np.mean(mse < 1e-5))},
            "definitions": "l2 = sqrt(∫(G1 − G1≈)² dθ) on 512 uniform θ; rms/mse over the nodes"}


PAPER_MODE = {"selection": "slice", "linear": "slice", "bounded": False}


def run_modes(names: list[str], prev: dict | None = None, psnr: bool = False):
    """Paper's two-slice procedure vs the default (safeguarded) fit, per material.

    For SGD, two-slice GGX and two-slice Beckmann: the compressive objective of Bagher et al.
    2016 (normalised, ``brdf_metrics``) and the §6.3 normalised L2, fit time; with ``psnr``
    also the rendered PSNR (Bagher 2016 §5) of the SGD fits against the reference (Mitsuba,
    sphere under the procedural environment, 128², 64 spp). Yields the growing result dict
    (resumable: materials already in ``prev`` are skipped).
    """
    import brdffit
    from brdffit.evaluation.metrics import BRDFMetrics

    fits = {"sgd": fit_sgd, "ggx-2s": fit_ggx_two_slice, "beckmann-2s": fit_beckmann_two_slice}
    results = dict(prev or {})
    for i, name in enumerate(names):
        if name in results:
            continue
        brdf = brdffit.load(f"{NBRDF}:{name}")
        bm = BRDFMetrics(brdf, metrics=("compressive_objective", "normalized_l2"))
        rec = {}
        ref_img = None
        if psnr:
            from brdffit.evaluation.render import render

            ref_img, mask = render(brdf, resolution=128, spp=64, return_mask=True)
        for key, fn in fits.items():
            for mode, opts in (("paper", PAPER_MODE), ("default", {})):
                t0 = time.perf_counter()
                try:
                    model = fn(brdf, **opts)
                except Exception as exc:            # a failed fit is a result
                    rec[f"{key}/{mode}"] = {"error": f"{type(exc).__name__}: {exc}"}
                    continue
                dt = time.perf_counter() - t0
                m = bm.evaluate(model)
                rec[f"{key}/{mode}"] = {"compressive_objective": m["compressive_objective"],
                                        "normalized_l2": m["normalized_l2"], "time_s": dt,
                                        "params": _params(model)}
                if ref_img is not None and key == "sgd":
                    from brdffit.evaluation.metrics import rendered_psnr

                    img = render(model, resolution=128, spp=64)
                    rec[f"{key}/{mode}"]["psnr_db"] = rendered_psnr(ref_img, img, mask)
        results[name] = rec
        print(f"  [{i + 1:3d}/{len(names)}] {name:24s} " + "  ".join(
            f"{k} {rec[k + '/paper'].get('compressive_objective', np.nan):8.4g} → "
            f"{rec[k + '/default'].get('compressive_objective', np.nan):8.4g}" for k in fits)
            + ("" if ref_img is None else "  PSNR sgd {:.1f} → {:.1f} dB".format(
                rec["sgd/paper"].get("psnr_db", np.nan), rec["sgd/default"].get("psnr_db", np.nan))),
            flush=True)
        yield results


class _MerlGrid:
    """A network tabulated once on the MERL grid (what a MERL .binary file gives)."""

    isotropic = True

    def __init__(self, brdf, table):
        self._brdf, self._table = brdf, table
        self.name, self.source = brdf.name, None

    def merl_table(self):
        return self._table

    def eval(self, wi, wo):
        return self._brdf.eval(wi, wo)

    def eval_hd(self, th, td, pd):
        return self._brdf.eval_hd(th, td, pd)


def run_speed(n: int, repeats: int, merl_grid: bool) -> dict:
    """CPU time per material, cold and warm, and the fit's objective."""
    import statistics

    import brdffit
    import brdffit.fit.sgd as new
    from brdffit.grid import tabulate_merl_grid
    from brdffit.io.nbrdf import list_materials
    from brdffit.losses.objective import objective_from_values

    names = list_materials(NBRDF)[:n]
    load0 = os.getloadavg()
    rows = []
    warm_input = brdffit.load(f"{NBRDF}:{names[0]}")
    new.fit_sgd(warm_input)                   # imports, numba compilation of the network
    for name in names:
        net = brdffit.load(f"{NBRDF}:{name}")
        ref_values, ref_valid = tabulate_merl_grid(net)
        brdf = _MerlGrid(net, (ref_values, ref_valid)) if merl_grid else net
        times = {"new_cold": [], "new_warm": []}
        models = {}
        for _ in range(repeats):             # interleaved: the machine's load hits both alike
            new.clear_caches()
            t0 = time.process_time()
            models["new"] = new.fit_sgd(brdf)
            times["new_cold"].append(time.process_time() - t0)
            t0 = time.process_time()
            new.fit_sgd(brdf)
            times["new_warm"].append(time.process_time() - t0)
        row = {"material": name,
               **{f"cpu_s_{k}": statistics.median(v) for k, v in times.items() if v},
               "cpu_s_all": times}
        for key, model in models.items():
            o = objective_from_values(tabulate_merl_grid(model)[0], ref_values, ref_valid)
            row[f"objective_{key}"] = o["objective"]
            row[f"objective_normalised_{key}"] = o["normalised"]
            row[f"params_{key}"] = _params(model)
        info = models["new"].fit_info
        row["convergence_new"] = {k: info.get(k) for k in (
            "converged", "success", "message", "iterations", "cap_reached", "n_local_runs")}
        rows.append(row)
        print(f"  {name:28s} CPU {row['cpu_s_new_cold']:.3f} s cold, "
              f"{row['cpu_s_new_warm']:.3f} s warm, objective {row['objective_new']:.5g}",
              flush=True)

    def stats(key):
        v = [r[key] for r in rows if key in r]
        return {"mean": float(np.mean(v)), "median": float(np.median(v)), "max": float(np.max(v)),
                "min": float(np.min(v))} if v else None

    out = {"materials": rows, "n_materials": len(rows), "input": "MERL-grid table" if merl_grid
           else "Neural-BRDF network (brdffit.load)", "repeats": repeats,
           "cpu_s_new_cold": stats("cpu_s_new_cold"), "cpu_s_new_warm": stats("cpu_s_new_warm"),
           "all_converged": all(r["convergence_new"]["converged"] for r in rows),
           "targets": {"cpu": "median <= 0.5 s, max <= 1 s"},
           "load_average_start": load0, "load_average_end": os.getloadavg(),
           "openblas_num_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
           "timer": "time.process_time (CPU time of this process, all threads)"}
    return out


def write(doc: dict) -> None:
    OUT.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(OUT, "w") as fh:
        json.dump(doc, fh, indent=1, default=float)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--real", action="store_true", help="also run all Neural-BRDF MERL materials")
    ap.add_argument("--limit", type=int, default=None, help="only the first N materials")
    ap.add_argument("--phi-stride", type=int, default=6, help="φd subsampling of the L2 grid")
    ap.add_argument("--skip-synthetic", action="store_true")
    ap.add_argument("--resume", action="store_true", help="reuse materials already in the JSON")
    ap.add_argument("--modes", type=int, default=None, metavar="N",
                    help="paper two-slice vs default fit (compressive objective) on the first "
                         "N Neural-BRDF materials")
    ap.add_argument("--psnr", action="store_true",
                    help="with --modes: also render the SGD fits (Mitsuba) and report PSNR")
    ap.add_argument("--speed", type=int, nargs="?", const=10, default=None, metavar="N",
                    help="CPU time (cold and warm) and objective on the first N (10) "
                         "materials (the 'speed' section of bench/results/sgd.json)")
    ap.add_argument("--repeats", type=int, default=3, help="fits per material for --speed")
    ap.add_argument("--merl-grid", action="store_true",
                    help="--speed on the network tabulated on the MERL grid (a MERL file)")
    args = ap.parse_args(argv)
    if args.psnr:
        os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")

    doc: dict = {}
    if OUT.exists():
        try:
            doc = json.loads(OUT.read_text())
        except json.JSONDecodeError:
            doc = {}
    doc["command"] = " ".join(["bench/bench_sgd.py"] + (argv if argv is not None else sys.argv[1:]))
    doc["date"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    if args.speed:
        if not NBRDF.exists():
            print(f"skipping --speed: {NBRDF} not found")
        else:
            res = run_speed(args.speed, args.repeats, args.merl_grid)
            res["command"] = doc["command"]
            res["date"] = doc["date"]
            doc.setdefault("speed", {})["merl_grid" if args.merl_grid else "network"] = res
            write(doc)
            print(json.dumps({k: v for k, v in res.items() if k != "materials"}, indent=1,
                             default=float))
        if args.skip_synthetic and not (args.modes or args.real):
            print(f"wrote {OUT}")
            return 0
    if not args.skip_synthetic:
        print("synthetic SGD materials:")
        doc["synthetic"] = run_synthetic()
        w = doc["synthetic"]["worst"]
        print(f"worst: α rel {w['alpha_rel']:.2e}, p rel {w['p_rel']:.2e}, F0 abs "
              f"{w['F0_abs']:.2e}, F1 abs {w['F1_abs']:.2e}; time median "
              f"{doc['synthetic']['time_median_s']:.2f} s, max {doc['synthetic']['time_max_s']:.2f} s")
        write(doc)
    if args.modes:
        if not NBRDF.exists():
            print(f"skipping --modes: {NBRDF} not found")
        else:
            from brdffit.io.nbrdf import list_materials

            names = list_materials(NBRDF)[:args.modes]
            print(f"paper vs default fit, compressive objective ({len(names)} materials):")
            prev = (doc.get("modes") or {}).get("materials") if args.resume else None
            for results in run_modes(names, prev, psnr=args.psnr):
                cols = {}
                for rec in results.values():
                    for k, v in rec.items():
                        cols.setdefault(k, []).append(v.get("compressive_objective", np.nan))
                ps = {k: [r[k]["psnr_db"] for r in results.values() if "psnr_db" in r.get(k, {})]
                      for k in ("sgd/paper", "sgd/default")}
                doc["modes"] = {"materials": results, "paper_options": PAPER_MODE,
                                "median_psnr_db": {k: float(np.median(v)) for k, v in ps.items()
                                                   if v},
                                "median_compressive_objective":
                                    {k: float(np.nanmedian(v)) for k, v in cols.items()},
                                "max_compressive_objective":
                                    {k: float(np.nanmax(v)) for k, v in cols.items()}}
                write(doc)
    if args.real:
        if not NBRDF.exists():
            print(f"skipping --real: {NBRDF} not found")
        else:
            print(f"Neural-BRDF MERL materials ({NBRDF}):")
            prev = doc.get("real") if args.resume else None
            if prev:
                doc["real"] = prev
            for results in run_real(args.limit, args.phi_stride, prev):
                doc["real"] = {"materials": results, "phi_stride": args.phi_stride,
                               "summary": summarize_real(results)}
                write(doc)
            doc["real"]["g1_approximation"] = g1_approximation_stats(doc["real"]["materials"])
            print("Eq. 9 G1 approximation over the fitted channels:",
                  json.dumps(doc["real"]["g1_approximation"], default=float))
            s = doc["real"]["summary"]
            print(json.dumps({k: v for k, v in s.items() if k != "showcase"}, indent=1,
                             default=float))
    write(doc)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
