"""Renderer safety: repeated user commands on a chosen LLVM target, and stray
memory accesses counted in Dr.Jit's debug mode.

Run: ``.venv/bin/python bench/bench_render_safety.py`` (defaults below; ``--help``). Writes
``bench/results/render_safety.json`` and prints one line per figure:

* ``compare``: ``brdffit compare synthetic:gold-ggx --models tabulated,ggx`` with the default
  scene suite, spp, batches and resolution, ``--compare-runs`` times on each ``--targets``
  (``native``, ``avx2``: ``BRDFFIT_LLVM_TARGET``): exit statuses, crashes (a negative status
  or 139), wall time min/median/max;
* ``demo``: ``brdffit demo`` (defaults) ``--demo-runs`` times on each target, the same;
* ``out_of_bounds``: ``brdffit compare`` of ``--oob-materials`` (default models, default
  suite) in debug mode (``BRDFFIT_DRJIT_DEBUG=1``): the count of ``out-of-bounds`` reports on
  stderr per material (goal 0).

Every command is a whole process, as a user runs it. The load average is recorded before and
after each group (the machine may be shared).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BRDFFIT = [sys.executable, "-m", "brdffit"]
RESULTS = ROOT / "bench" / "results" / "render_safety.json"


def _run(args, env: dict, cwd: str) -> dict:
    t0 = time.perf_counter()
    res = subprocess.run(BRDFFIT + args, cwd=cwd, env={**os.environ, **env},
                         capture_output=True, text=True)
    return {"status": res.returncode, "seconds": round(time.perf_counter() - t0, 2),
            "out_of_bounds": sum("out-of-bounds" in ln for ln in res.stderr.splitlines()),
            "tail": res.stderr.strip().splitlines()[-1:] if res.returncode else []}


def _repeat(name: str, args, runs: int, target: str) -> dict:
    env = {"BRDFFIT_LLVM_TARGET": target, "BRDFFIT_DRJIT_DEBUG": "0"}
    load0 = os.getloadavg()
    rows = []
    for k in range(runs):
        with tempfile.TemporaryDirectory() as tmp:
            rows.append(_run(args + ["--out", "out"], env, tmp))
        print(f"{name} [{target}] run {k + 1}/{runs}: exit {rows[-1]['status']}, "
              f"{rows[-1]['seconds']} s", flush=True)
    secs = [r["seconds"] for r in rows]
    crashes = sum(r["status"] < 0 or r["status"] >= 128 for r in rows)
    return {"command": "brdffit " + " ".join(args), "target": target, "runs": runs,
            "exit_statuses": [r["status"] for r in rows], "crashes": crashes,
            "failures": sum(r["status"] != 0 for r in rows),
            "seconds_min_median_max": [min(secs), statistics.median(secs), max(secs)],
            "load_before": load0, "load_after": os.getloadavg(),
            "errors": [r["tail"] for r in rows if r["tail"]]}


def _out_of_bounds(materials: list[str]) -> dict:
    out = {}
    for m in materials:
        with tempfile.TemporaryDirectory() as tmp:
            r = _run(["compare", m, "--out", "out"], {"BRDFFIT_DRJIT_DEBUG": "1"}, tmp)
        out[m] = {"out_of_bounds": r["out_of_bounds"], "status": r["status"],
                  "seconds": r["seconds"]}
        print(f"debug mode: compare {m}: {r['out_of_bounds']} out-of-bounds report(s), "
              f"exit {r['status']}", flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--targets", default="native,avx2")
    ap.add_argument("--compare-runs", type=int, default=20)
    ap.add_argument("--demo-runs", type=int, default=10)
    ap.add_argument("--oob-materials", default="synthetic:gold-ggx,"
                    "merl_nbrdf.zip:gold-metallic-paint,rgl/cc_ibiza_sunset_rgb.bsdf")
    args = ap.parse_args()
    result = {"machine": {"cpu": platform.processor() or platform.machine(),
                          "cpus": os.cpu_count()},
              "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
              "compare": [], "demo": []}
    for target in args.targets.split(","):
        if args.compare_runs:
            result["compare"].append(_repeat("compare", ["compare", "synthetic:gold-ggx",
                                                         "--models", "tabulated,ggx"],
                                             args.compare_runs, target))
        if args.demo_runs:
            result["demo"].append(_repeat("demo", ["demo"], args.demo_runs, target))
    if args.oob_materials:
        result["out_of_bounds"] = _out_of_bounds(args.oob_materials.split(","))
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
