"""Benchmark of the measured-data readers.

Prints and writes ``bench/results/io.json``:

* read of a MERL ``.binary`` (target < 0.3 s),
* 10⁶ (wi, wo) evaluations of the MERL table, trilinear (target < 0.5 s) and nearest,
* 10⁶ evaluations of a Neural-BRDF network (target < 1 s),
* 10⁶ evaluations of a UTIA table.

The MERL file is the Neural-BRDF ``gold-metallic-paint`` resampled on the MERL grid when
``../shared/data`` is present (a random table otherwise); the UTIA file is that BRDF on
the UTIA grid. Each figure is the best of ``--repeat`` runs after one warm-up (first-call
compilation of the lookup kernels excluded). Run: ``.venv/bin/python bench/bench_io.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import random_direction_pairs  # bench/ is on sys.path when run as a script

from brdffit._atomic import atomic_write
from brdffit.io import load, read_merl, read_utia, write_merl, write_utia
from brdffit.io.merl import resample_to_merl

ROOT = Path(__file__).resolve().parent
SHARED = ROOT.parent.parent / "shared" / "data"


def _best(fn, repeat):
    fn()  # warm-up (numba compilation, page cache)
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times), times


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="evaluations per figure")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "io.json")
    args = ap.parse_args()

    zspec = SHARED / "nbrdf" / "merl_nbrdf.zip"
    results: dict = {"n_evals": args.n, "repeat": args.repeat, "cpu_count": os.cpu_count(),
                     "machine": platform.machine(), "python": platform.python_version(),
                     "loadavg_1min_before": os.getloadavg()[0]}
    wi, wo = random_direction_pairs(args.n)
    with tempfile.TemporaryDirectory() as tmp:
        merl_path = Path(tmp) / "bench.binary"
        if zspec.is_file():
            net = load(f"{zspec}:gold-metallic-paint")
            results["material"] = "merl_nbrdf.zip:gold-metallic-paint"
            resample_to_merl(net, merl_path)
        else:
            net = None
            results["material"] = "random table (shared data absent)"
            write_merl(np.random.default_rng(0).random((90, 90, 180, 3)), merl_path)

        t, all_t = _best(lambda: read_merl(merl_path), args.repeat)
        results["merl_read_s"] = t
        print(f"MERL read ({merl_path.stat().st_size / 1e6:.1f} MB):     {t:.3f} s  "
              f"(runs {', '.join(f'{x:.3f}' for x in all_t)}; target < 0.3 s)")

        merl = read_merl(merl_path)
        for mode in ("trilinear", "nearest"):
            m = merl.with_interpolation(mode)
            t, all_t = _best(lambda: m.eval(wi, wo), args.repeat)
            results[f"merl_eval_{mode}_s"] = t
            print(f"MERL eval {mode:<9} {args.n:.0e} pairs: {t:.3f} s  "
                  f"(runs {', '.join(f'{x:.3f}' for x in all_t)})")

        if net is not None:
            t, all_t = _best(lambda: net.eval(wi, wo), args.repeat)
            results["nbrdf_eval_s"] = t
            print(f"NBRDF eval {args.n:.0e} pairs:          {t:.3f} s  "
                  f"(runs {', '.join(f'{x:.3f}' for x in all_t)}; target < 1 s)")
            net64 = load(f"{zspec}:gold-metallic-paint", precision="float64")
            f32, f64 = net.eval(wi[:200000], wo[:200000]), net64.eval(wi[:200000], wo[:200000])
            big = f64 > 1e-3
            results["nbrdf_float32_max_rel_err"] = float(np.max(np.abs(f32 - f64)[big] / f64[big]))
            print(f"NBRDF float32 vs float64 max rel. error (values > 1e-3): "
                  f"{results['nbrdf_float32_max_rel_err']:.2e}")
            t, _ = _best(lambda: net64.eval(wi, wo), 1)
            results["nbrdf_eval_float64_s"] = t

        utia_path = Path(tmp) / "bench.bin"
        write_utia(merl, utia_path)
        t, _ = _best(lambda: read_utia(utia_path), args.repeat)
        results["utia_read_s"] = t
        utia = read_utia(utia_path)
        t, all_t = _best(lambda: utia.eval(wi, wo), args.repeat)
        results["utia_eval_s"] = t
        print(f"UTIA eval {args.n:.0e} pairs:           {t:.3f} s  "
              f"(runs {', '.join(f'{x:.3f}' for x in all_t)})")

    results["loadavg_1min_after"] = os.getloadavg()[0]
    print(f"load average (1 min) before/after: {results['loadavg_1min_before']:.1f} / "
          f"{results['loadavg_1min_after']:.1f} on {os.cpu_count()} CPUs")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, "w") as fh:
        json.dump(results, fh, indent=2)
    print(f"wrote {args.out}")
    return results


if __name__ == "__main__":
    main()
