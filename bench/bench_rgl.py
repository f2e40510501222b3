"""Benchmark of the RGL ``.bsdf`` reader (target: 10⁶ evaluations under 3 s).

Prints and writes ``bench/results/rgl.json``:

* read time of each RGL file in ``../shared/data/rgl`` (parse + warp set-up),
* 10⁶ random (wi, wo) evaluations of ``eval`` (f_r, RGB) per material (target < 3 s),
  and 10⁶ importance samples (``sample``),
* when Mitsuba 3 (``llvm_ad_rgb``) is usable: the maximum / median relative difference
  between ``RGLBRDF.eval_mitsuba`` and Mitsuba's own ``measured`` plugin on ``--n-check``
  random direction pairs (float32-representable inputs), and Mitsuba's time for 10⁶ evals.

Each timing is the best of ``--repeat`` runs after one warm-up. Run:
``.venv/bin/python bench/bench_rgl.py`` (``--materials paper_white_rgb`` to restrict).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from _common import random_direction_pairs  # bench/ is on sys.path when run as a script

from brdffit._atomic import atomic_write
from brdffit.io.rgl import read_rgl

ROOT = Path(__file__).resolve().parent
RGL_DIR = ROOT.parent.parent / "shared" / "data" / "rgl"


def _best(fn, repeat):
    fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def _mitsuba():
    try:
        from brdffit.evaluation.render._mitsuba import load
        return load()[0]
    except Exception:  # noqa: BLE001 - fall back to a direct import
        pass
    os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")
    try:
        import mitsuba as mi
        mi.set_variant("llvm_ad_rgb")
        return mi
    except Exception as exc:  # noqa: BLE001
        print(f"Mitsuba cross-check skipped: {exc}", file=sys.stderr)
        return None


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="evaluations per timing")
    ap.add_argument("--n-check", type=int, default=100_000, help="pairs compared with Mitsuba")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--materials", nargs="*", default=None, help="file stems (default: all)")
    ap.add_argument("--no-mitsuba", action="store_true")
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "rgl.json")
    args = ap.parse_args()

    files = sorted(RGL_DIR.glob("*.bsdf"))
    if args.materials:
        files = [f for f in files if f.stem in args.materials]
    if not files:
        raise SystemExit(f"no RGL files found in {RGL_DIR}")
    mi = None if args.no_mitsuba else _mitsuba()
    wi, wo = random_direction_pairs(args.n)
    ci, co = (v.astype(np.float32).astype(np.float64) for v in random_direction_pairs(args.n_check, seed=1))

    result = {"n_evals": args.n, "repeat": args.repeat, "cpu_count": os.cpu_count(),
              "machine": platform.machine(), "python": platform.python_version(),
              "materials": {}}
    for path in files:
        read_s = _best(lambda: read_rgl(path), args.repeat)
        b = read_rgl(path)
        eval_s = _best(lambda: b.eval(wi, wo), args.repeat)
        u = np.random.default_rng(2).random((args.n, 2))
        sample_s = _best(lambda: b.sample(wi, u), args.repeat)
        row = {"read_s": read_s, "eval_1e6_s": eval_s * 1e6 / args.n,
               "sample_1e6_s": sample_s * 1e6 / args.n,
               "albedo_0_30_60_75deg": b.albedo(np.radians([0, 30, 60, 75]), 16384).round(4).tolist()}
        if mi is not None:
            bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(co.T.astype(np.float32))      # Mitsuba si.wi = our wo
            ref = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(ci.T.astype(np.float32)))).T
            ours = b.eval_mitsuba(co, ci)
            rel = np.abs(ours - ref) / np.maximum(np.abs(ref), 1e-3 * np.abs(ref).max())
            row.update(mitsuba_max_rel=float(rel.max()), mitsuba_median_rel=float(np.median(rel)))
            si_big = mi.SurfaceInteraction3f()
            si_big.wi = mi.Vector3f(wo.T.astype(np.float32))
            wo_big = mi.Vector3f(wi.T.astype(np.float32))

            def run_mi():
                v = bsdf.eval(mi.BSDFContext(), si_big, wo_big)
                np.array(v)   # forces evaluation of the JIT kernel
            row["mitsuba_eval_1e6_s"] = _best(run_mi, args.repeat) * 1e6 / args.n
        result["materials"][path.stem] = row
        print(f"{path.stem:28s} read {read_s * 1e3:6.1f} ms   eval 1e6 {row['eval_1e6_s']:.3f} s"
              f"   sample 1e6 {row['sample_1e6_s']:.3f} s"
              + (f"   vs Mitsuba: max rel {row['mitsuba_max_rel']:.2e}, median "
                 f"{row['mitsuba_median_rel']:.1e}, Mitsuba eval 1e6 {row['mitsuba_eval_1e6_s']:.3f} s"
                 if "mitsuba_max_rel" in row else ""))
    mats = result["materials"].values()
    result["eval_1e6_s_max"] = max(r["eval_1e6_s"] for r in mats)
    result["target_eval_1e6_s"] = 3.0
    if mi is not None:
        result["mitsuba_max_rel_all"] = max(r["mitsuba_max_rel"] for r in mats)
    print(f"worst eval of 1e6 pairs: {result['eval_1e6_s_max']:.3f} s (target < 3 s)"
          + (f"; worst relative difference to Mitsuba: {result['mitsuba_max_rel_all']:.2e}"
             if mi is not None else ""))
    with atomic_write(args.out, "w") as fh:
        json.dump(result, fh, indent=2)
    print(f"wrote {args.out}")
    return result


if __name__ == "__main__":
    main()
