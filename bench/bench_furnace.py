"""Furnace benchmark: is every importance sampler of brdffit unbiased?

For every render translator (Dr.Jit evaluators: closed-form GGX/Beckmann with Schlick or
tabulated Fresnel, radial-table distributions for SGD and tabulated fits, sums of lobes,
per-channel lobes of very different widths, the three NPF variants, the generic MERL-grid
and 4D tables) and every Python ``sample``/``pdf`` pair of the library's models
(:func:`brdffit.testing.furnace.model_zoo`), over roughness α (0.001 … 1) × incidence θi
(0 … 80°), the importance-sampled directional albedo ``mean(f cos θo / pdf)`` (per RGB
channel) is compared with the deterministic quadrature of the same ``f``
(:func:`brdffit.furnace.albedo_quadrature`, half-vector, log-θh Gauss-Legendre).

Uniforms are stratified (16 independent batches of jittered-grid points; the standard error
is that of the batch means) unless ``--iid``.

Figures: ``max_rel_error`` (target ≤ 1 %) with the worst case and its standard error, the
largest relative standard error (the test's resolution), and for the translated (non-table)
evaluators ``max_fidelity``: the relative difference between the quadratures of the Dr.Jit
``eval`` and of the library model's ``eval`` (the albedo the renderer sees vs the model's).

Run: ``.venv/bin/python bench/bench_furnace.py`` (``--quick``: 3 α × 3 θi, fewer samples).
Writes ``bench/results/furnace.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

ALPHAS = (0.001, 0.002, 0.005, 0.01, 0.03, 0.1, 0.3, 1.0)
THETAS = (0.0, 20.0, 40.0, 60.0, 70.0, 80.0)


def _evaluators(zoo):
    """(translator label, model name, evaluator) for every Dr.Jit path."""
    from brdffit.evaluation.render.translate import to_evaluator

    out = []
    for name, brdf in zoo.items():
        mode = "auto" if name == "tabulated-aniso" else "closed"   # no closed form: 4D table
        ev = to_evaluator(brdf, mode=mode, cache=False)
        out.append((f"{ev.kind}:{name}", name, ev))
    for name in ("ggx", "sgd"):
        ev = to_evaluator(zoo[name], mode="table", cache=False)
        out.append((f"{ev.kind}:{name}", name, ev))
    return out


def run(alphas, thetas, n_drjit, n_python, python_side=True, stratified=True, log=print):
    from brdffit.evaluation.render.translate import albedo_drjit, evaluate_drjit
    from brdffit.furnace import FurnaceResult, albedo_quadrature, albedo_sampled
    from brdffit.testing.furnace import model_zoo

    rows = []
    for a in alphas:
        zoo = model_zoo(a)
        quad_py = {}
        for label, name, ev in _evaluators(zoo):
            t0 = time.time()
            for j, deg in enumerate(thetas):
                t = np.radians(deg)
                est, se = albedo_drjit(ev, t, n=n_drjit, seed=1000 + j, stratified=stratified)
                q = albedo_quadrature(lambda x, y: evaluate_drjit(ev, x, y), t)
                if (name, deg) not in quad_py:
                    quad_py[name, deg] = albedo_quadrature(zoo[name].eval, t)
                r = FurnaceResult(t, est, se, q)
                qp = quad_py[name, deg]
                rows.append({"side": "drjit", "translator": label, "kind": ev.kind,
                             "model": name, "path": getattr(ev, "path", None), "alpha": a,
                             "theta_i": deg, "estimate": est.tolist(), "se": se.tolist(),
                             "quadrature": q.tolist(), "model_quadrature": qp.tolist(),
                             "rel_error": float(r.rel_error.max()),
                             "rel_se": float(r.rel_se.max()), "passed": r.passed,
                             "fidelity": float(np.max(np.abs(q - qp) / np.maximum(qp, 1e-300)))})
            worst = max(rows[-len(thetas):], key=lambda d: d["rel_error"])
            log(f"α={a:<6g} {label:34s} max err {worst['rel_error']:.4f} "
                f"(θi={worst['theta_i']:g}°, rel.se {worst['rel_se']:.4f}) "
                f"fidelity {max(d['fidelity'] for d in rows[-len(thetas):]):.4f} "
                f"{time.time() - t0:5.1f}s")
        if not python_side:
            continue
        for name, brdf in zoo.items():
            t0 = time.time()
            for j, deg in enumerate(thetas):
                t = np.radians(deg)
                est, se = albedo_sampled(brdf, t, n=n_python, seed=2000 + j,
                                         stratified=stratified)
                q = quad_py.get((name, deg))
                if q is None:
                    q = albedo_quadrature(brdf.eval, t)
                r = FurnaceResult(t, est, se, q)
                rows.append({"side": "python", "translator": f"python:{name}",
                             "class": type(brdf).__name__,
                             "model": name, "alpha": a, "theta_i": deg,
                             "estimate": est.tolist(), "se": se.tolist(),
                             "quadrature": q.tolist(), "rel_error": float(r.rel_error.max()),
                             "rel_se": float(r.rel_se.max()), "passed": r.passed})
            worst = max(rows[-len(thetas):], key=lambda d: d["rel_error"])
            log(f"α={a:<6g} {'python:' + name:34s} max err {worst['rel_error']:.4f} "
                f"(θi={worst['theta_i']:g}°, rel.se {worst['rel_se']:.4f}) "
                f"{time.time() - t0:5.1f}s")
    return rows


def summarise(rows):
    out = {}
    for side in ("drjit", "python"):
        sel = [r for r in rows if r["side"] == side]
        if not sel:
            continue
        worst = max(sel, key=lambda r: r["rel_error"])
        per = {}
        for r in sel:
            d = per.setdefault(r["translator"], {"max_rel_error": 0.0, "max_rel_se": 0.0,
                                                 "failed": 0, "cases": 0})
            d["max_rel_error"] = max(d["max_rel_error"], r["rel_error"])
            d["max_rel_se"] = max(d["max_rel_se"], r["rel_se"])
            d["failed"] += int(not r["passed"])
            d["cases"] += 1
        s = {"cases": len(sel), "failed": sum(not r["passed"] for r in sel),
             "max_rel_error": worst["rel_error"],
             "worst": {k: worst[k] for k in ("translator", "alpha", "theta_i", "rel_error",
                                             "rel_se", "estimate", "se", "quadrature")},
             "max_rel_se": max(r["rel_se"] for r in sel),
             "median_rel_se": float(np.median([r["rel_se"] for r in sel])),
             "per_translator": per}
        if side == "drjit":
            closed = [r for r in sel if r["kind"] not in ("merl-table", "table4d")]
            fw = max(closed, key=lambda r: r["fidelity"])
            s["max_fidelity"] = fw["fidelity"]
            s["worst_fidelity"] = {k: fw[k] for k in ("translator", "alpha", "theta_i",
                                                      "quadrature", "model_quadrature")}
            tables = [r for r in sel if r["kind"] in ("merl-table", "table4d")]
            if tables:
                s["max_table_fidelity"] = max(r["fidelity"] for r in tables)
        out[side] = s
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 α × 3 θi, 2^18 / 2^16 samples")
    ap.add_argument("--alphas", type=str, default=None, help="comma-separated α list")
    ap.add_argument("--thetas", type=str, default=None, help="comma-separated θi (degrees)")
    ap.add_argument("--n-drjit", type=int, default=1 << 20)
    ap.add_argument("--n-python", type=int, default=1 << 18)
    ap.add_argument("--no-python", action="store_true", help="Dr.Jit translators only")
    ap.add_argument("--iid", action="store_true",
                    help="i.i.d. uniforms (default: 16 batches of jittered-grid uniforms)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "furnace.json")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    alphas, thetas = ALPHAS, THETAS
    n_dj, n_py = args.n_drjit, args.n_python
    if args.quick:
        alphas, thetas, n_dj, n_py = (0.001, 0.03, 1.0), (0.0, 60.0, 80.0), 1 << 18, 1 << 16
    if args.alphas:
        alphas = tuple(float(x) for x in args.alphas.split(","))
    if args.thetas:
        thetas = tuple(float(x) for x in args.thetas.split(","))
    t0 = time.time()
    rows = run(alphas, thetas, n_dj, n_py, python_side=not args.no_python,
               stratified=not args.iid)
    summary = summarise(rows)
    result = {"benchmark": "furnace", "issue": 13, "alphas": list(alphas),
              "thetas_deg": list(thetas), "n_drjit": n_dj, "n_python": n_py,
              "sampling": "iid" if args.iid else "stratified, 16 independent batches (se of "
                                                 "the batch means)",
              "criterion": "|estimate - quadrature| <= max(1 % quadrature, 4 se) per channel",
              "target_max_rel_error": 0.01, "summary": summary,
              "wall_s": round(time.time() - t0, 1), "machine": platform.platform(),
              "rows": rows}
    from brdffit._atomic import atomic_write

    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, "w") as fh:
        json.dump(result, fh, indent=1)
    for side, s in summary.items():
        w = s["worst"]
        print(f"{side}: {s['cases']} cases, {s['failed']} failed; max rel. error "
              f"{s['max_rel_error']:.4f} ({w['translator']}, α={w['alpha']:g}, "
              f"θi={w['theta_i']:g}°, rel.se {w['rel_se']:.4f}); max rel.se {s['max_rel_se']:.4f}"
              + (f"; max fidelity {s['max_fidelity']:.4f}" if "max_fidelity" in s else ""))
    print(f"wrote {args.out} ({result['wall_s']} s)")


if __name__ == "__main__":
    main()
