"""Benchmark of the comparison report.

Single-material mode (default): time of a complete one-material report — fitting every model,
rendering the reference, the noise floor and every fit, metrics, plots, HTML — with the
reference and six fits. Target: ≤ 2 minutes on the project machine. Writes
``bench/results/report.json``.

    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 \\
        .venv/bin/python bench/bench_report.py [--material merl_nbrdf.zip:gold-metallic-paint]
        [--models tabulated,ggx,beckmann,sgd,npf,...] [--spp 64] [--resolution 128]

Database mode (``--database``): the database-wide figure — for the 100 Neural-BRDF MERL
materials and the RGL materials, one fixed scene set (``--scenes``), mean and median
rendered PSNR and dE2000 per model and pairwise wins / ties within 2 dB (Bagher et al. 2016
§5). Each (scene, material) report lands in ``OUT/<scene>/<material>/``; materials already
done are skipped (``--resume``, default on), so the run can be interrupted and continued.
``--limit N`` keeps the first N materials of each collection. Writes
``bench/results/report_database.json``.

    .venv/bin/python bench/bench_report.py --database --limit 3 --out /tmp/brdffit-db

``--from-batch DIR,...`` summarises the reports that ``brdffit batch --render`` wrote
(``DIR/report/``, fits loaded, not refitted) instead of running anything, and checks the
papers' ranking claims pair by pair (materials where the claimed order is reversed by more
than the 2 dB tie margin are listed):

    .venv/bin/python bench/bench_report.py --from-batch runs/merl-full,runs/rgl-full

``--crn-speed``: time of the four-scene comparison (the paper suite, 256², common
random numbers, default spp and batches) of one material with all eight models, *fits
excluded*: the fits are loaded from ``--fits-dir`` (made there first, untimed, when missing).
Wall and CPU time (the machine is shared) and the load average; per-phase timings; the PSNR
± standard error of every model. Writes ``bench/results/report_crn.json``.

    .venv/bin/python bench/bench_report.py --crn-speed [--material merl_nbrdf.zip:gold-metallic-paint]

Timings on a shared machine are pessimistic; re-run to update the figures.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
RESULTS = ROOT / "bench" / "results"
SHARED = ROOT.parent / "shared" / "data"

FALLBACK_MODELS = ["tabulated", "ggx", "beckmann", "sgd", "npf", "npf-g-from-d"]
# Preference order of the six fits (the ranking claims of the issue involve these).
PREFERRED = ["tabulated", "ggx", "beckmann", "sgd", "npf", "npf-g-from-d", "npf-naive",
             "npf-bivariate"]


def default_models(n: int = 6) -> list[str]:
    """The first ``n`` of :data:`PREFERRED` that the fit registry knows (all of
    :data:`FALLBACK_MODELS` when there is no registry)."""
    try:
        from brdffit.fit.registry import list_fitters
    except ImportError:
        return FALLBACK_MODELS
    known = set(list_fitters())
    pick = [m for m in PREFERRED if m in known]
    pick += sorted(known - set(pick))
    return pick[:n]


def database_specs(collections: list[str], limit: int | None) -> list[str]:
    """Material specs of the database: every member of the given Neural-BRDF zips and every
    RGL ``*_rgb.bsdf`` matching the given globs."""
    from brdffit.io.nbrdf import list_materials

    specs = []
    for c in collections:
        if c.endswith(".zip"):
            path = Path(c) if Path(c).exists() else SHARED / "nbrdf" / c
            names = list_materials(path)
            specs += [f"{path}:{n}" for n in (names[:limit] if limit else names)]
        else:
            files = sorted(glob.glob(c if os.path.isabs(c) else str(SHARED / c)))
            specs += files[:limit] if limit else files
    return specs


def machine() -> dict:
    return {"python": platform.python_version(), "cpus": os.cpu_count(),
            "load_avg": os.getloadavg() if hasattr(os, "getloadavg") else None,
            "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def write_json(path: Path, obj) -> None:
    from brdffit._atomic import atomic_write
    from brdffit._json import standard_json

    with atomic_write(path, "w") as fh:
        json.dump(standard_json(obj), fh, indent=1, default=str, allow_nan=False)


def bench_single(args) -> dict:
    from brdffit.evaluation.compare import compare

    models = args.models.split(",") if args.models else default_models()
    out = Path(args.out or "/tmp/brdffit-bench-report")
    t0 = time.perf_counter()
    res = compare(args.material, models, out, scene=args.scene, spp=args.spp,
                  fit_options=json.loads(args.fit_options) if args.fit_options else None,
                  resolution=args.resolution, seed=0,
                  render_options={"envmap": args.envmap} if args.envmap else None,
                  progress=lambda m: print(f"  [{time.perf_counter() - t0:6.1f} s] {m}", flush=True))
    total = time.perf_counter() - t0
    rows = []
    for m in res["models"]:
        rows.append({k: m.get(k) for k in ("name", "status", "error", "fit_time", "render_time",
                                            "psnr", "mean_de2000")}
                    | {"cos_rel_error": (m.get("brdf") or {}).get("cos_rel_error")})
    fig = {"benchmark": "one-material report (reference + fits)", "material": args.material,
           "fit_options": args.fit_options, "command": " ".join(sys.argv),
           "models": models, "scene": res["scene"], "total_seconds": total,
           "target_seconds": 120.0, "meets_target": total <= 120.0,
           "reference_render_seconds": res["reference"]["render_time"],
           "noise_floor_psnr": res.get("noise_floor_psnr"), "per_model": rows,
           "report": str(out / "index.html"), "machine": machine()}
    print(f"total {total:.1f} s for {len(models)} models (target 120 s); report {out}/index.html")
    for r in rows:
        print(f"  {r['name']:>14}: {r['status']:6} fit {r['fit_time'] or 0:6.1f} s  render "
              f"{r['render_time'] or 0:5.1f} s  PSNR {r['psnr'] if r['psnr'] is not None else float('nan'):6.2f}"
              f"  dE {r['mean_de2000'] if r['mean_de2000'] is not None else float('nan'):5.2f}"
              + (f"  ({r['error']})" if r.get("error") else ""))
    write_json(RESULTS / "report.json", fig)
    return fig


ALL_MODELS = ["tabulated", "ggx", "beckmann", "sgd", "npf", "npf-g-from-d", "npf-naive",
              "npf-bivariate"]


def bench_crn_speed(args) -> dict:
    from brdffit.evaluation.compare import compare, resolve_reference
    from brdffit.evaluation.report import slugify
    from brdffit.fit.registry import fit_model
    from brdffit.io.fitfile import save_fit

    models = args.models.split(",") if args.models else ALL_MODELS
    spec = args.material if Path(args.material.split(":")[0]).exists() else \
        str(SHARED / "nbrdf" / args.material)
    ref = resolve_reference(spec)
    fdir = Path(args.fits_dir) / slugify(ref.name)
    fdir.mkdir(parents=True, exist_ok=True)
    fit_seconds = {}
    for m in models:
        path = fdir / f"{m}.npz"
        if not path.is_file():
            print(f"  fitting {m} (not timed)", flush=True)
            t0 = time.perf_counter()
            model, _ = fit_model(m, ref, None)
            save_fit(model, path)
            fit_seconds[m] = time.perf_counter() - t0
    out = Path(args.out or "/tmp/brdffit-bench-crn")
    spp = args.spp
    runs = []
    for rep in range(args.repeats):
        ref = resolve_reference(spec)   # a fresh object: nothing cached from the last run
        la0 = os.getloadavg()
        t0, c0 = time.perf_counter(), time.process_time()
        res = compare(ref, {m: str(fdir / f"{m}.npz") for m in models}, out,
                      resolution=args.resolution, spp=spp, batches=args.batches,
                      progress=lambda msg: print(f"  [{time.perf_counter() - t0:6.1f} s] {msg}",
                                                 flush=True))
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        runs.append({"wall_seconds": wall, "cpu_seconds": cpu, "load_avg_before": la0,
                     "load_avg_after": os.getloadavg(), "timing": res["timing"],
                     "scenes": [{k: s.get(k) for k in ("name", "render_seconds",
                                                       "render_cpu_seconds", "peak_seconds",
                                                       "peak_cpu_seconds")}
                                for s in res["scenes"]]})
        print(f"run {rep + 1}: {wall:.1f} s wall, {cpu:.1f} s CPU (load {la0[0]:.1f} → "
              f"{os.getloadavg()[0]:.1f}); renders {res['timing']['render_seconds']:.1f} s wall, "
              f"{res['timing']['render_cpu_seconds']:.1f} s CPU", flush=True)
    rows = []
    for m in res["models"]:
        rows.append({"name": m["name"], "status": m["status"], "psnr": m.get("psnr"),
                     "psnr_se": m.get("psnr_se"), "psnr_se_mse": m.get("psnr_se_mse"),
                     "mean_de2000": m.get("mean_de2000"),
                     "scenes": [{k: e.get(k) for k in ("scene", "psnr", "psnr_se")}
                                for e in m.get("scenes", [])]})
        if m["status"] == "ok":
            print(f"  {m['name']:>14}: {m['psnr']:6.2f} ± {m['psnr_se']:.3f} dB  "
                  + "  ".join(f"{e['scene']} {e['psnr']:.2f}" for e in m["scenes"]))
    best = min(runs, key=lambda r: r["wall_seconds"])
    fig = {"benchmark": "four-scene CRN comparison, 8 models, fits loaded (excluded)",
           "material": spec, "models": models, "resolution": args.resolution, "spp": spp,
           "batches": args.batches, "scenes": [s["name"] for s in res["scenes"]],
           "runs": runs, "target_seconds": 120.0,
           "meets_target_wall": best["wall_seconds"] <= 120.0,
           "cpu_seconds_best": min(r["cpu_seconds"] for r in runs),
           "note": "cpu_seconds is the process CPU time of all threads (the machine is shared "
                   "by several sessions: wall time depends on the load average recorded)",
           "fit_seconds_untimed": fit_seconds, "per_model": rows,
           "report": str(out / "index.html"), "machine": machine()}
    write_json(RESULTS / "report_crn.json", fig)
    return fig


def bench_database(args) -> dict:
    from brdffit.evaluation.compare import compare, resolve_reference
    from brdffit.evaluation.report import read_results, slugify, summarize, write_index

    models = args.models.split(",") if args.models else default_models()
    out = Path(args.out or "/tmp/brdffit-bench-database")
    specs = database_specs(args.collections.split(","), args.limit)
    scenes = args.scenes.split(",")
    t0 = time.perf_counter()
    failures = []
    slugs: dict[str, set] = {}
    for scene in scenes:
        sdir = out / scene
        slugs[scene] = set()
        for k, spec in enumerate(specs):
            try:
                ref = resolve_reference(spec)
            except Exception as exc:  # noqa: BLE001
                failures.append({"spec": spec, "scene": scene, "error": f"load: {exc}"})
                continue
            slugs[scene].add(slugify(ref.name))
            if args.resume and (sdir / slugify(ref.name) / "result.json").is_file():
                continue
            print(f"[{time.perf_counter() - t0:7.1f} s] {scene} {k + 1}/{len(specs)} {spec}",
                  flush=True)
            try:
                compare(ref, models, sdir, scene=scene, spp=args.spp, resolution=args.resolution,
                        fit_options=json.loads(args.fit_options) if args.fit_options else None,
                        seed=0, noise_floor=args.noise_floor, update_index=False,
                        render_options={"envmap": args.envmap} if args.envmap else None)
            except Exception as exc:  # noqa: BLE001
                failures.append({"spec": spec, "scene": scene, "error": f"{type(exc).__name__}: {exc}"})
        write_index(sdir, title=f"brdffit database comparison – {scene}")
    # one summary over every (scene, material) rendering (Bagher 2016 count 4 per material)
    all_results = []
    for scene in scenes:
        for r in read_results(out / scene):
            if r["slug"] in slugs[scene]:
                r["scene_name"] = scene
                all_results.append(r)
    summ = summarize(all_results)
    total = time.perf_counter() - t0
    ranking = sorted(((n, s["mean_psnr"]) for n, s in summ["per_model"].items()
                      if s["mean_psnr"] is not None), key=lambda x: -x[1])
    fig = {"benchmark": "database comparison", "collections": args.collections,
           "fit_options": args.fit_options, "command": " ".join(sys.argv),
           "limit": args.limit, "n_specs": len(specs), "scenes": scenes, "spp": args.spp,
           "resolution": args.resolution, "models": models, "n_renderings": len(all_results),
           "summary": summ, "ranking_by_mean_psnr": ranking, "failures": failures,
           "seconds": total, "reports": [str(out / s / "index.html") for s in scenes],
           "machine": machine()}
    print(f"{len(all_results)} renderings of {len(specs)} materials x {len(scenes)} scenes in "
          f"{total:.0f} s")
    for n, s in summ["per_model"].items():
        print(f"  {n:>14}: n={s['n']:3d} PSNR mean {s['mean_psnr'] if s['mean_psnr'] is not None else float('nan'):6.2f}"
              f" median {s['median_psnr'] if s['median_psnr'] is not None else float('nan'):6.2f}"
              f" | dE2000 mean {s['mean_de2000'] if s['mean_de2000'] is not None else float('nan'):5.2f}"
              f" median {s['median_de2000'] if s['median_de2000'] is not None else float('nan'):5.2f}")
    names = summ["models"]
    for a in names:
        print(f"  {a:>14} vs " + ", ".join(
            f"{b}: {w['wins']}/{w['ties']}/{w['losses']}" for b, w in summ["wins"][a].items()))
    write_json(RESULTS / "report_database.json", fig)
    return fig


#: Ranking claims of the papers (Bagher 2016 §5 and Table II; Bagher 2012 §6): (better, worse).
PAPER_CLAIMS = [("npf", "npf-g-from-d"), ("npf", "npf-naive"), ("npf-g-from-d", "sgd"),
                ("npf-naive", "sgd"), ("sgd", "ggx"), ("ggx", "beckmann"), ("sgd", "tabulated")]
#: MERL materials that are bare metals (Matusik et al. 2003's classification, paints excluded).
MERL_METALS = {"alum-bronze", "aluminium", "black-oxidized-steel", "brass", "chrome",
               "chrome-steel", "grease-covered-steel", "hematite", "nickel", "ss440", "steel",
               "tungsten-carbide"}


def _claims(results: list[dict], tie_db: float) -> list[dict]:
    """For each claim (a better than b): wins/ties/losses of a over b and the losing materials."""
    from brdffit.evaluation.report import _models, _num, _ok

    table = {}
    for r in results:
        table[r.get("material")] = {m["name"]: _num(m.get("psnr")) for m in _models(r) if _ok(m)}
    out = []
    for a, b in PAPER_CLAIMS:
        for subset, names in (("all", None), ("metals", MERL_METALS)):
            if subset == "metals" and (a, b) != ("sgd", "tabulated"):
                continue
            w = t = l = 0
            losses = []
            for mat, ps in table.items():
                if names is not None and mat not in names:
                    continue
                if ps.get(a) is None or ps.get(b) is None:
                    continue
                d = ps[a] - ps[b]
                if abs(d) <= tie_db:
                    t += 1
                elif d > 0:
                    w += 1
                else:
                    l += 1
                    losses.append((mat, round(d, 2)))
            if w + t + l:
                out.append({"claim": f"{a} > {b}", "subset": subset, "wins": w, "ties": t,
                            "losses": l, "holds": w + t >= l,
                            "reversed_on": sorted(losses, key=lambda x: x[1])})
    return out


def bench_from_batch(args) -> dict:
    from brdffit.evaluation.report import read_results, summarize

    results, dirs = [], [Path(d) for d in args.from_batch.split(",") if d]
    for d in dirs:
        results += read_results(d / "report")
    summ = summarize(results)
    ranking = sorted(((n, s["mean_psnr"]) for n, s in summ["per_model"].items()
                      if s["mean_psnr"] is not None), key=lambda x: -x[1])
    renders = []
    for d in dirs:
        renders += [json.loads(p.read_text()) for p in sorted((d / "renders").glob("*.json"))]
    fig = {"benchmark": "database comparison (from brdffit batch --render)",
           "batch_dirs": [str(d) for d in dirs], "n_materials": len(results),
           "scene": results[0].get("scene") if results else None, "summary": summ,
           "ranking_by_mean_psnr": ranking, "paper_claims": _claims(results, summ["tie_db"]),
           "render_task_seconds": {"n": len(renders),
                                   "sum": sum(r.get("wall_time_s", 0) for r in renders)},
           "failures": [{"material": r["material"], "error": r.get("error")}
                        for r in renders if r.get("status") != "ok"],
           "reports": [str(d / "report" / "index.html") for d in dirs], "machine": machine()}
    print(f"{len(results)} materials from {', '.join(map(str, dirs))}")
    for n, s in summ["per_model"].items():
        print(f"  {n:>14}: n={s['n']:3d} PSNR mean {s['mean_psnr'] or float('nan'):6.2f} median "
              f"{s['median_psnr'] or float('nan'):6.2f} | dE2000 mean "
              f"{s['mean_de2000'] or float('nan'):5.2f} median {s['median_de2000'] or float('nan'):5.2f}")
    for c in fig["paper_claims"]:
        print(f"  {c['claim']:>26} ({c['subset']}): {c['wins']}/{c['ties']}/{c['losses']} "
              f"{'holds' if c['holds'] else 'does NOT hold'}; reversed on "
              f"{', '.join(m for m, _ in c['reversed_on'][:8])}")
    write_json(RESULTS / "report_database.json", fig)
    return fig


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--material", default="merl_nbrdf.zip:gold-metallic-paint")
    ap.add_argument("--models", default=None, help="comma-separated (default: registry, 6)")
    ap.add_argument("--scene", default="sphere-env")
    ap.add_argument("--envmap", default=None)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--out", default=None)
    ap.add_argument("--fit-options", default=None,
                    help='JSON {model: {option: value}}, e.g. \'{"npf": {"max_iter": 200}}\'')
    ap.add_argument("--database", action="store_true")
    ap.add_argument("--from-batch", default=None, help="comma-separated brdffit batch --render dirs")
    ap.add_argument("--collections", default="merl_nbrdf.zip,rgl/*_rgb.bsdf")
    ap.add_argument("--scenes", default="sphere-env")
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--noise-floor", action=argparse.BooleanOptionalAction, default=False)
    ap.add_argument("--resume", action=argparse.BooleanOptionalAction, default=True)
    ap.add_argument("--crn-speed", action="store_true",
                    help="time the 8-model four-scene comparison with fits loaded")
    ap.add_argument("--fits-dir", default="/tmp/brdffit-bench-fits")
    ap.add_argument("--batches", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args(argv)
    RESULTS.mkdir(parents=True, exist_ok=True)
    if args.crn_speed:
        if args.resolution == 128:
            args.resolution = 256
        bench_crn_speed(args)
    elif args.from_batch:
        bench_from_batch(args)
    else:
        (bench_database if args.database else bench_single)(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
