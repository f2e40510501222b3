"""Batch throughput with 1 and 2 local Dask workers, and the
whole-database run time.

Runs ``brdffit.batch.run_batch`` on the first ``--limit`` materials of a database with each
worker count into a fresh folder, and reports tasks per second and the speed-up (target:
2 workers ≥ 1.8× one). ``--full`` instead runs the whole database once with every model of
``--models`` (resumable: re-running continues; the wall time is summed over the
invocations) and reports the wall time and per-model fit times; ``--render`` adds the render
stage at the report's settings (``brdffit batch --render``) to the same folder.

    .venv/bin/python bench/bench_batch.py --limit 8 --models tabulated,ggx
    .venv/bin/python bench/bench_batch.py --full --out runs/merl-full \
        --models tabulated,ggx,beckmann,sgd,npf-g-from-d,npf
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import tempfile
import time
from pathlib import Path

from brdffit._atomic import atomic_write
from brdffit.batch import RenderSettings, enumerate_materials, make_tasks, run_batch

RESULTS = Path(__file__).resolve().parent / "results"
DEFAULT_SOURCE = Path(__file__).resolve().parents[2] / "shared" / "data" / "nbrdf" / "merl_nbrdf.zip"


def machine() -> dict:
    return {"platform": platform.platform(), "python": platform.python_version(),
            "cpus": os.cpu_count(), "processor": platform.processor()}


def throughput(source, models, limit, workers) -> dict:
    tasks = make_tasks(enumerate_materials(source, limit=limit), models)
    out = Path(tempfile.mkdtemp(prefix=f"bench-batch-{workers}w-"))
    try:
        t0 = time.perf_counter()
        res = run_batch(tasks, out, workers=workers, progress=False)
        wall = time.perf_counter() - t0
    finally:
        shutil.rmtree(out, ignore_errors=True)
    return {"workers": workers, "tasks": len(tasks), "failed": res["failed"],
            "wall_s": wall, "tasks_per_s": len(tasks) / wall}


def _stats(xs) -> dict | None:
    xs = [float(x) for x in xs if x is not None]
    return {"min": min(xs), "avg": sum(xs) / len(xs), "max": max(xs), "n": len(xs)} if xs else None


def full_run_summary(out: Path, models, source, n_tasks: int, invocation: dict | None) -> dict:
    """Whole-database figure: the wall time summed over every invocation that worked on
    ``out`` (a resumed run is several invocations; each appends itself to
    ``out/bench_invocations.json``) and per-model fit time and metrics over the records."""
    from brdffit.batch import read_records

    inv_path = out / "bench_invocations.json"
    invocations = json.loads(inv_path.read_text()) if inv_path.exists() else []
    if invocation is not None:
        invocations.append(invocation)
        with atomic_write(inv_path, "w") as fh:
            json.dump(invocations, fh, indent=1)
    records = read_records(out)
    per_model = {}
    for m in models:
        rs = [r for r in records if r["model"] == m]
        ok = [r for r in rs if r.get("status") == "ok"]
        metrics = sorted({k for r in ok for k in (r.get("metrics") or {})})
        per_model[m] = {"ok": len(ok), "failed": sum(r.get("status") == "failed" for r in rs),
                        "skipped": sum(r.get("status") == "skipped" for r in rs),
                        "fit_time_s": _stats(r.get("fit_time_s") for r in ok),
                        "task_wall_s": _stats(r.get("wall_time_s") for r in ok),
                        "metrics_mean": {k: _stats((r.get("metrics") or {}).get(k) for r in ok)["avg"]
                                         for k in metrics}}
    return {"machine": machine(), "source": source, "models": models, "tasks": n_tasks,
            "records": len(records), "materials": len({r["material"] for r in records}),
            "wall_s": sum(i["wall_s"] for i in invocations),
            "wall_s_without_render": sum(i["wall_s"] for i in invocations if not i.get("render")),
            "wall_s_render_invocations": sum(i["wall_s"] for i in invocations if i.get("render")),
            "invocations": invocations,
            "task_seconds_sum": sum(r.get("wall_time_s", 0) for r in records),
            "per_model": per_model,
            "note": "fit times measured inside the 2-worker run (pessimistic: both cores busy)"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--source", default=str(DEFAULT_SOURCE))
    ap.add_argument("--models", default="tabulated,ggx")
    ap.add_argument("--limit", type=int, default=8)
    ap.add_argument("--full", action="store_true")
    ap.add_argument("--out", default="runs/merl-full")
    ap.add_argument("--render", action="store_true", help="with --full: also render")
    ap.add_argument("--summarise", action="store_true",
                    help="with --full: only (re)write the summary of the records in --out")
    args = ap.parse_args()
    models = args.models.split(",")
    if args.full and args.summarise:
        n = len(make_tasks(enumerate_materials(args.source, limit=args.limit or None), models))
        result = full_run_summary(Path(args.out), models, args.source, n, None)
        name = "batch_full.json"
    elif args.full:
        tasks = make_tasks(enumerate_materials(args.source, limit=args.limit or None), models)
        t0 = time.perf_counter()
        res = run_batch(tasks, args.out, workers=2,
                        render=RenderSettings() if args.render else None)
        wall = time.perf_counter() - t0
        result = full_run_summary(Path(args.out), models, args.source, len(tasks),
                                  {"wall_s": wall, "render": args.render, "ran": res["ran"], "skipped": res["skipped"],
                                   "failed": res["failed"],
                                   "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())})
        name = "batch_full.json"
    else:
        runs = [throughput(args.source, models, args.limit, w) for w in (1, 2)]
        result = {"machine": machine(), "source": args.source, "models": models,
                  "runs": runs, "speedup_2_over_1": runs[1]["tasks_per_s"] / runs[0]["tasks_per_s"],
                  "note": "includes local-cluster start-up (a few seconds) in each wall time"}
        name = "batch.json"
    print(json.dumps(result, indent=1))
    RESULTS.mkdir(exist_ok=True)
    with atomic_write(RESULTS / name, "w") as fh:
        json.dump(result, fh, indent=1)


if __name__ == "__main__":
    main()
