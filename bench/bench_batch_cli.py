"""One ``brdffit batch`` invocation over a sample of the MERL database with every model
(``--every 1``: the whole MERL-100 run with every model, as one invocation).

    nice .venv/bin/python bench/bench_batch_cli.py --every 5 --out runs/db20b

runs ``brdffit batch merl_nbrdf.zip --models <all 8> --only <every N-th material> --out OUT
--quiet`` (2 local workers, product defaults) as a child process; records its wall time,
the CPU time of the process tree (``RUSAGE_CHILDREN``), the load average, and per model the
fit times, convergence and status from ``OUT/records``. The projection to the whole database
is ``N ×`` the wall time (the sample is every N-th of the alphabetical list). With
``--reference DIR`` (an earlier run of the same command) the per-model fit times and the NPF
objectives are compared material by material. Writes ``bench/results/batch_cli.json`` (the
newest run without renders, whatever its ``--every``) or, with ``--render``,
``bench/results/batch_cli_render.json`` (with the render tasks' wall and CPU times: the CPU
of each comparison's renders, measured by the report, and of the whole task's process tree
is the batch's; see ``docs/design/batch.md``).

The child runs with an empty Dr.Jit kernel cache (``DRJIT_CACHE_DIR`` a fresh temporary
folder), as on a machine that never rendered these materials: Dr.Jit keeps compiled kernels
on disk (``~/.drjit``), and a kernel cache filled by earlier runs of the same command would
hide the compilations a first run pays. ``--warm-kernel-cache`` keeps the user's cache.
Numba's cache (``src/**/__pycache__/*.nbi``, written by the first process that compiles a
kernel) is taken as found, and a fresh checkout has none: both workers then compile every
fit kernel in their first tasks. ``--warm-numba-cache`` first runs the fits of one material
(no renders, untimed), as any earlier use of the installed package (``make demo``, a fit)
would have; the results record ``numba_cache_files_at_start``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from brdffit._atomic import atomic_write  # noqa: E402

MODELS = "tabulated,ggx,beckmann,sgd,npf,npf-g-from-d,npf-naive,npf-bivariate"


def _stats(xs):
    xs = [float(x) for x in xs if x is not None]
    return {"min": min(xs), "mean": float(np.mean(xs)), "max": max(xs), "n": len(xs)} if xs else {}


def _numba_cache_files() -> int:
    """Numba's on-disk cache entries of the package (0: every kernel compiles in the run)."""
    return sum(1 for _ in (ROOT / "src").rglob("*.nbi"))


def per_model(out: Path) -> dict:
    from brdffit import load_fit
    from brdffit.batch import read_records

    res: dict = {}
    for r in read_records(out):
        m = res.setdefault(r["model"], {"status": {}, "fit_time_s": [], "convergence": {},
                                        "objective": {}})
        m["status"][r.get("status")] = m["status"].get(r.get("status"), 0) + 1
        if r.get("status") != "ok":
            continue
        m["fit_time_s"].append(r.get("fit_time_s"))
        fi = load_fit(out / r["fit_file"]).fit_info or {}
        conv = fi.get("converged")
        key = "converged" if conv else ("capped" if fi.get("cap_reached") else str(conv))
        m["convergence"][key] = m["convergence"].get(key, 0) + 1
        if "objective" in fi:
            m["objective"][r["material"]] = fi["objective"]
    for m in res.values():
        m["n"] = len(m["fit_time_s"])
        m["fit_time_s"] = _stats(m["fit_time_s"])
    return res


def per_render(out: Path) -> dict:
    """Render tasks: status counts, task time, and the rendered PSNR per model."""
    recs = [json.loads(p.read_text()) for p in sorted((out / "renders").glob("*.json"))]
    status: dict = {}
    psnr: dict = {}
    for r in recs:
        status[r.get("status")] = status.get(r.get("status"), 0) + 1
        for model, m in (r.get("models") or {}).items():
            if m.get("psnr") is not None:
                psnr.setdefault(model, []).append(m["psnr"])
    render_cpu = []
    for r in recs:
        page = out / r.get("report_page", "")
        result = page.parent / "result.json" if r.get("report_page") else None
        if result is not None and result.is_file():
            render_cpu.append(json.loads(result.read_text()).get("timing", {})
                              .get("render_cpu_seconds"))
    return {"n": len(recs), "status": status,
            "task_wall_s": _stats(r.get("wall_time_s") for r in recs),
            "render_cpu_s": _stats(render_cpu),
            "psnr_db": {m: _stats(v) for m, v in sorted(psnr.items())}}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--every", type=int, default=5)
    ap.add_argument("--models", default=MODELS)
    ap.add_argument("--out", default="runs/db20b")
    ap.add_argument("--reference", default=None, help="output folder of an earlier run")
    ap.add_argument("--summarise", action="store_true", help="only summarise --out")
    ap.add_argument("--render", action="store_true",
                    help="pass --render (the four-scene paper suite, product defaults)")
    ap.add_argument("--warm-kernel-cache", action="store_true",
                    help="use the user's Dr.Jit kernel cache instead of an empty one")
    ap.add_argument("--warm-numba-cache", action="store_true",
                    help="first run the batch's fits (no renders) on one material in a scratch "
                         "folder, untimed, so that Numba's on-disk cache holds the kernels")
    args = ap.parse_args()
    from brdffit.batch import enumerate_materials

    names = [n for n, _ in enumerate_materials("merl_nbrdf.zip")][::args.every]
    cmd = [str(ROOT / ".venv" / "bin" / "brdffit"), "batch", "merl_nbrdf.zip",
           "--models", args.models, "--only", ",".join(names), "--out", args.out, "--quiet"]
    if args.render:
        cmd.append("--render")
    result = {"benchmark": "one brdffit batch invocation, every model",
              "command": " ".join(cmd[1:]), "every": args.every, "materials": names,
              "cpus": os.cpu_count()}
    if not args.summarise:
        if args.warm_numba_cache:
            with tempfile.TemporaryDirectory(prefix="numba-warm-") as scratch:
                warm = cmd[:cmd.index("--only")] + ["--only", names[0], "--out", scratch,
                                                    "--quiet"]
                subprocess.call(warm, cwd=ROOT)
        result["numba_cache_files_at_start"] = _numba_cache_files()
        load0 = list(os.getloadavg())
        t0 = time.perf_counter()
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        with tempfile.TemporaryDirectory(prefix="drjit-cache-") as cache:
            env = dict(os.environ)
            if not args.warm_kernel_cache:
                env["DRJIT_CACHE_DIR"] = cache
            rc = subprocess.call(cmd, cwd=ROOT, env=env)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        wall = time.perf_counter() - t0
        result.update(exit_code=rc, wall_s=wall,
                      cpu_s_user_sys=(r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime),
                      projected_all_materials_wall_h=wall * args.every / 3600.0,
                      drjit_kernel_cache="warm (the user's)" if args.warm_kernel_cache
                      else "empty at the start (fresh DRJIT_CACHE_DIR)",
                      load_average_start=load0, load_average_end=list(os.getloadavg()))
    out = ROOT / args.out
    pm = per_model(out)
    result["per_model"] = pm
    if args.render:
        result["renders"] = per_render(out)
    if args.reference:
        ref = per_model(ROOT / args.reference)
        cmp = {}
        for model, m in pm.items():
            if model not in ref:
                continue
            ratios = [m["objective"][k] / ref[model]["objective"][k]
                      for k in m["objective"] if k in ref[model]["objective"]
                      and ref[model]["objective"][k] > 0]
            cmp[model] = {"fit_time_mean_ratio": (m["fit_time_s"].get("mean", np.nan)
                                                  / ref[model]["fit_time_s"].get("mean", np.nan)),
                          "objective_ratio": _stats(ratios),
                          "objective_above_reference": sum(x > 1 for x in ratios)}
        result["versus_reference"] = {"reference": args.reference, "per_model": cmp}
    for m in pm.values():
        m.pop("objective", None)
    print(json.dumps(result, indent=1))
    name = "batch_cli_render.json" if args.render else "batch_cli.json"
    with atomic_write(ROOT / "bench" / "results" / name, "w") as fh:
        json.dump(result, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
