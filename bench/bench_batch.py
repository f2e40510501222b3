"""Batch throughput with 1 and 2 local Dask workers (issue 7 scaling figure), and the
whole-database run time.

Runs ``brdffit.batch.run_batch`` on the first ``--limit`` materials of a database with each
worker count into a fresh folder, and reports tasks per second and the speed-up (target:
2 workers ≥ 1.8× one). ``--full`` instead runs the whole database once with every model of
``--models`` (resumable: re-running continues) and reports the wall time.

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
from brdffit.batch import enumerate_materials, make_tasks, run_batch

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--source", default=str(DEFAULT_SOURCE))
    ap.add_argument("--models", default="tabulated,ggx")
    ap.add_argument("--limit", type=int, default=8)
    ap.add_argument("--full", action="store_true")
    ap.add_argument("--out", default="runs/merl-full")
    args = ap.parse_args()
    models = args.models.split(",")
    if args.full:
        tasks = make_tasks(enumerate_materials(args.source, limit=args.limit or None), models)
        t0 = time.perf_counter()
        res = run_batch(tasks, args.out, workers=2)
        result = {"machine": machine(), "source": args.source, "models": models,
                  "tasks": len(tasks), "ran": res["ran"], "skipped": res["skipped"],
                  "failed": res["failed"], "wall_s": time.perf_counter() - t0}
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
