"""Real engines: glTF exports rendered by Blender (Cycles) vs our render of the fit.

Per material (a MERL Neural-BRDF stand-in of ``../shared/data/nbrdf/merl_nbrdf.zip`` or an
RGL file of ``../shared/data/rgl``): the fit of ``--model`` (default ``ggx-diffuse``) is
exported to glTF (preview sphere, default options) and

* ``blender``: Blender's own importer (default options) and Cycles on the CPU render the file
  in ``sphere-distant`` rebuilt in Blender (:mod:`brdffit.evaluation.engines.blender`);
* ``blender_ggx``: the same with the Principled BSDF's distribution set to single-scatter
  GGX after the import (what the importer's multiscatter GGX costs);
* ``blender_usd``: the fit's USD export (``brdffit export --to usd``: UsdPreviewSurface on the
  same preview sphere) imported by Blender's USD importer (default options), same render;
* ``equivalent``: our Mitsuba render of :func:`brdffit.export.gltf.gltf_equivalent` (the
  specification's BRDF); ``equivalent_blender`` / ``equivalent_blender_ggx``: the same with
  ``engine="blender"`` / ``"blender-ggx"`` (Cycles' Principled BSDF as the importer sets it
  up, :mod:`brdffit.export.gltf_cycles`): the predictions of ``blender`` / ``blender_ggx``
  (``*_prediction_gap_db`` in the summary: predicted − measured PSNR);

each compared with our Mitsuba render of the fit, K batches (seeds) on both sides: PSNR ±
its standard error (:func:`brdffit.evaluation.metrics.crn_psnr`; the batches of the two
renderers are independent), per-channel mean ratio, rim ratio (r > 0.85 R), HDR-FLIP and the
alignment (coverage, peak pixel). The glTF parameters written (ior, specular factors,
metallic) and what Blender's importer made of them are kept.

Run: ``.venv/bin/python bench/bench_engines.py`` (``--materials a,b`` to restrict,
``--label after`` to store the run under that label next to others in the same JSON).
Writes ``bench/results/engines_blender.json`` atomically; the machine's load average before
and after each material is recorded (2 shared cores: timings vary, the images do not).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _common import DATA, NBRDF, RGL_DIR, ROOT, use_project_sources  # bench/ is on sys.path

use_project_sources()
MERL = ["ss440", "gold-metallic-paint", "maroon-plastic", "white-paint", "chrome-steel",
        "blue-metallic-paint", "red-plastic", "alum-bronze"]


def _materials(only: str | None) -> list[tuple[str, str]]:
    out = [(n, f"{NBRDF}:{n}") for n in MERL] if NBRDF.is_file() else []
    if RGL_DIR.is_dir():
        out += [(p.stem.removesuffix("_rgb"), str(p)) for p in sorted(RGL_DIR.glob("*.bsdf"))]
    if only:
        keep = set(only.split(","))
        out = [m for m in out if m[0] in keep]
    return out


def _brief(r: dict) -> dict:
    keys = ("psnr", "psnr_se", "resolved", "mean_ratio", "rim_ratio", "flip", "coverage",
            "peak_pixel", "pixels", "rim_pixels")
    return {k: r[k] for k in keys if k in r}


def bench_material(name: str, spec: str, args) -> dict:
    import brdffit
    from brdffit.evaluation.engines import blender
    from brdffit.export import export
    from brdffit.export.gltf import gltf_equivalent
    from brdffit.io import load

    seeds = tuple(range(args.batches))
    out: dict = {"material": name, "source": spec, "load_average_before": os.getloadavg()}
    t = time.perf_counter()
    fit = brdffit.fit(load(spec), args.model)
    out["fit_seconds"] = time.perf_counter() - t
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{name}.gltf"
        info = export(fit, "gltf", path, fidelity=False, optimize=args.optimize)
        doc = json.loads(path.read_text())
        mat = doc["materials"][0]
        out["gltf"] = {"pbrMetallicRoughness": mat["pbrMetallicRoughness"],
                       "extensions": mat.get("extensions", {}), "notes": info["notes"]}
        t = time.perf_counter()
        ref, alpha = blender.render_fit(fit, "sphere-distant", args.res, args.spp, seeds)
        out["fit_render_seconds"] = time.perf_counter() - t
        for key, engine in (("equivalent", "specification"),
                            ("equivalent_blender", "blender"),
                            ("equivalent_blender_ggx", "blender-ggx")):
            try:
                model = gltf_equivalent(fit, engine=engine, optimize=args.optimize)
            except ValueError as exc:                # e.g. anisotropy, not modelled
                out[key] = {"error": str(exc)}
                continue
            eq, eq_alpha = blender.render_fit(model, "sphere-distant", args.res, args.spp,
                                              seeds)
            out[key] = _brief(blender.compare_renders(ref, alpha, eq, eq_alpha))
        usd = Path(tmp) / f"{name}.usda"
        out["usd_notes"] = export(fit, "usd", usd)["notes"]
        for key, dist, file in (("blender", None, path), ("blender_ggx", "GGX", path),
                                ("blender_usd", None, usd)):
            b = blender.render_file(file, "sphere-distant", args.res, args.spp, seeds, dist)
            out[key] = _brief(blender.compare_renders(ref, alpha, b.images, b.alpha))
            out[key]["seconds"] = b.seconds
            out[key]["principled"] = b.report["materials"][0]["principled"]
            out["blender_version"] = b.report["blender"]
    out["load_average_after"] = os.getloadavg()
    return out


def _summary(rows: list[dict]) -> dict:
    s = {}
    for key in ("blender", "blender_ggx", "blender_usd", "equivalent"):
        ps = np.array([r[key]["psnr"] for r in rows])
        ratios = np.array([r[key]["mean_ratio"] for r in rows])
        rims = np.array([r[key]["rim_ratio"] for r in rows])
        s[key] = {"psnr_mean": float(ps.mean()), "psnr_min": float(ps.min()),
                  "worst": rows[int(ps.argmin())]["material"],
                  "max_mean_ratio_deviation": float(np.max(np.abs(ratios - 1))),
                  "max_rim_ratio_deviation": float(np.max(np.abs(rims - 1)))}
    for name, eq, measured in (("prediction_gap_db", "equivalent", "blender"),
                               ("blender_prediction_gap_db", "equivalent_blender", "blender"),
                               ("blender_ggx_prediction_gap_db", "equivalent_blender_ggx",
                                "blender_ggx")):
        pairs = [(r[eq]["psnr"], r[measured]["psnr"], r[measured]["resolved"]) for r in rows
                 if "psnr" in r.get(eq, {})]
        gap = np.array([p - m for p, m, _ in pairs])
        resolved = np.array([p - m for p, m, ok in pairs if ok])
        s[name] = {"mean": float(gap.mean()), "max_abs": float(np.abs(gap).max()),
                   "max_abs_resolved": float(np.abs(resolved).max()) if resolved.size else None,
                   "within_2db": int(np.sum(np.abs(gap) <= 2.0)), "materials": len(pairs)}
    return s


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--materials", help="comma-separated subset of the material names")
    ap.add_argument("--model", default="ggx-diffuse")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--optimize", default=False,
                    help="the exporter's refinement (brdffit.export.gltf.OPTIMIZE), e.g. engines")
    ap.add_argument("--spp", type=int, default=64, help="per batch")
    ap.add_argument("--batches", type=int, default=4)
    ap.add_argument("--label", default="current", help="key of this run in the JSON")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "engines_blender.json")
    args = ap.parse_args(argv)
    if str(args.optimize).lower() in ("false", "none", "0", ""):
        args.optimize = False

    from brdffit._atomic import atomic_write
    from brdffit.evaluation.engines import blender

    if not blender.available():
        print("bpy not found (make blender): nothing measured", file=sys.stderr)
        return 1
    mats = _materials(args.materials)
    if not mats:
        print(f"no materials found under {DATA}", file=sys.stderr)
        return 1
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip()
    rows = []
    print(f"{'material':24s} {'Blender dB':>14s} {'GGX forced':>14s} {'USD':>6s} {'spec/Bl. eq.':>13s} "
          f"{'mean ratio R,G,B':>20s} {'rim ratio R,G,B':>20s} {'FLIP':>6s}")
    for name, spec in mats:
        r = bench_material(name, spec, args)
        rows.append(r)
        b, g, e = r["blender"], r["blender_ggx"], r["equivalent"]
        print(f"{name:24s} {b['psnr']:7.2f} ± {b['psnr_se']:4.2f} {g['psnr']:7.2f} ± "
              f"{g['psnr_se']:4.2f} {r['blender_usd']['psnr']:6.2f} {e['psnr']:6.2f}/{r['equivalent_blender'].get('psnr', np.nan):6.2f} "
              f"{' '.join(f'{x:.3f}' for x in b['mean_ratio']):>20s} "
              f"{' '.join(f'{x:.3f}' for x in b['rim_ratio']):>20s} {b['flip']:6.4f}",
              flush=True)
    run = {"commit": commit, "model": args.model, "optimize": args.optimize,
           "scene": "sphere-distant",
           "resolution": args.res, "spp_per_batch": args.spp, "batches": args.batches,
           "cpus": os.cpu_count(), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
           "command": "bench/bench_engines.py " + " ".join(argv if argv is not None
                                                            else sys.argv[1:]),
           "summary": _summary(rows), "materials": rows}
    old = json.loads(args.out.read_text()) if args.out.is_file() else {}
    old[args.label] = run
    with atomic_write(args.out, "w") as fh:
        fh.write(json.dumps(old, indent=1, default=float) + "\n")
    print(json.dumps(run["summary"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
