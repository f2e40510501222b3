"""Real engines: glTF exports rendered by Blender (Cycles) vs our render of the fit.

Per material (a MERL Neural-BRDF stand-in of ``../shared/data/nbrdf/merl_nbrdf.zip`` or an
RGL file of ``../shared/data/rgl``): the fit of ``--model`` (default ``ggx-diffuse``) is
exported to glTF (preview sphere, default options) and

* ``blender``: Blender's own importer (default options) and Cycles on the CPU render the file
  in each scene rebuilt in Blender (:mod:`brdffit.evaluation.engines.blender`):
  ``sphere-distant`` and the paper suite's spheres (``sphere-courtyard``, ``sphere-studio``,
  ``sphere-sunrise``: the map as Blender's world; ``--scenes``);
* in ``sphere-distant`` only: ``blender_ggx``: the same with the Principled BSDF's distribution set to single-scatter
  GGX after the import (what the importer's multiscatter GGX costs);
* ``blender_usd``: the fit's USD export (``brdffit export --to usd``: UsdPreviewSurface on the
  same preview sphere) imported by Blender's USD importer (default options), same render;
* ``equivalent``: our Mitsuba render of :func:`brdffit.export.gltf.gltf_equivalent` (the
  specification's BRDF); ``equivalent_blender`` / ``equivalent_blender_ggx`` (the latter in
  ``sphere-distant`` only): the same with
  ``engine="blender"`` / ``"blender-ggx"`` (Cycles' Principled BSDF as the importer sets it
  up, :mod:`brdffit.export.gltf_cycles`): the predictions of ``blender`` / ``blender_ggx``
  (``*_prediction_gap_db`` in the summary: predicted − measured PSNR);

each compared with our Mitsuba render of the fit, K batches (seeds) on both sides: PSNR ±
its standard error (:func:`brdffit.evaluation.metrics.crn_psnr`; the batches of the two
renderers are independent), per-channel mean ratio, rim ratio (r > 0.85 R), HDR-FLIP and the
alignment (coverage, peak pixel). The glTF parameters written (ior, specular factors,
metallic) and what Blender's importer made of them are kept. The summary has each scene and,
over the paper suite's spheres, the per-material mean PSNR's mean and minimum.

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
#: the scenes rebuilt in Blender: the directional light and the paper suite's spheres
SCENES = ("sphere-distant", "sphere-courtyard", "sphere-studio", "sphere-sunrise")
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


def _render_variants(fit, scene: str, files: dict, args) -> dict:
    """One scene of one material: our render of the fit, of its glTF equivalents and
    Blender's renders of the exported files, each compared with the fit's."""
    from brdffit.evaluation.engines import blender
    from brdffit.export.gltf import gltf_equivalent

    seeds = tuple(range(args.batches))
    full = scene == "sphere-distant"          # every variant there; the main ones elsewhere
    out: dict = {}
    t = time.perf_counter()
    ref, alpha = blender.render_fit(fit, scene, args.res, args.spp, seeds)
    out["fit_render_seconds"] = time.perf_counter() - t
    equivalents = (("equivalent", "specification"), ("equivalent_blender", "blender"))
    if full:
        equivalents += (("equivalent_blender_ggx", "blender-ggx"),)
    for key, engine in equivalents:
        try:
            model = gltf_equivalent(fit, engine=engine, optimize=args.optimize)
        except ValueError as exc:                # e.g. anisotropy, not modelled
            out[key] = {"error": str(exc)}
            continue
        eq, eq_alpha = blender.render_fit(model, scene, args.res, args.spp, seeds)
        out[key] = _brief(blender.compare_renders(ref, alpha, eq, eq_alpha))
    variants = [("blender", None, files["gltf"])]
    if full:
        variants += [("blender_ggx", "GGX", files["gltf"]), ("blender_usd", None, files["usd"])]
    for key, dist, file in variants:
        b = blender.render_file(file, scene, args.res, args.spp, seeds, dist)
        out[key] = _brief(blender.compare_renders(ref, alpha, b.images, b.alpha))
        out[key]["seconds"] = b.seconds
        out[key]["principled"] = b.report["materials"][0]["principled"]
        out["blender_version"] = b.report["blender"]
    return out


def bench_material(name: str, spec: str, args) -> dict:
    import brdffit
    from brdffit.export import export
    from brdffit.io import load

    out: dict = {"material": name, "source": spec, "load_average_before": os.getloadavg()}
    t = time.perf_counter()
    fit = brdffit.fit(load(spec), args.model)
    out["fit_seconds"] = time.perf_counter() - t
    with tempfile.TemporaryDirectory() as tmp:
        files = {"gltf": Path(tmp) / f"{name}.gltf", "usd": Path(tmp) / f"{name}.usda"}
        info = export(fit, "gltf", files["gltf"], fidelity=False, optimize=args.optimize)
        out["usd_notes"] = export(fit, "usd", files["usd"])["notes"]
        mat = json.loads(files["gltf"].read_text())["materials"][0]
        out["gltf"] = {"pbrMetallicRoughness": mat["pbrMetallicRoughness"],
                       "extensions": mat.get("extensions", {}), "notes": info["notes"]}
        out["scenes"] = {scene: _render_variants(fit, scene, files, args)
                         for scene in args.scenes}
    out["load_average_after"] = os.getloadavg()
    return out


def _scene_summary(rows: list[dict], scene: str) -> dict:
    s = {}
    for key in ("blender", "blender_ggx", "blender_usd", "equivalent"):
        got = [r for r in rows if "psnr" in r["scenes"][scene].get(key, {})]
        if not got:
            continue
        ps = np.array([r["scenes"][scene][key]["psnr"] for r in got])
        ratios = np.array([r["scenes"][scene][key]["mean_ratio"] for r in got])
        rims = np.array([r["scenes"][scene][key]["rim_ratio"] for r in got])
        s[key] = {"psnr_mean": float(ps.mean()), "psnr_min": float(ps.min()),
                  "worst": got[int(ps.argmin())]["material"],
                  "max_mean_ratio_deviation": float(np.max(np.abs(ratios - 1))),
                  "max_rim_ratio_deviation": float(np.max(np.abs(rims - 1)))}
    for name, eq, measured in (("prediction_gap_db", "equivalent", "blender"),
                               ("blender_prediction_gap_db", "equivalent_blender", "blender"),
                               ("blender_ggx_prediction_gap_db", "equivalent_blender_ggx",
                                "blender_ggx")):
        pairs = [(r["scenes"][scene][eq]["psnr"], r["scenes"][scene][measured]["psnr"],
                  r["scenes"][scene][measured]["resolved"]) for r in rows
                 if "psnr" in r["scenes"][scene].get(eq, {})
                 and measured in r["scenes"][scene]]
        if not pairs:
            continue
        gap = np.array([p - m for p, m, _ in pairs])
        resolved = np.array([p - m for p, m, ok in pairs if ok])
        s[name] = {"mean": float(gap.mean()), "max_abs": float(np.abs(gap).max()),
                   "max_abs_resolved": float(np.abs(resolved).max()) if resolved.size else None,
                   "within_2db": int(np.sum(np.abs(gap) <= 2.0)), "materials": len(pairs)}
    return s


def _summary(rows: list[dict], scenes) -> dict:
    """Per scene, and over the paper suite's spheres (per material the mean PSNR of those
    scenes, as the paper averages its scenes)."""
    out = {scene: _scene_summary(rows, scene) for scene in scenes}
    suite = [sc for sc in scenes if sc != "sphere-distant"]
    if suite:
        per = np.array([np.mean([r["scenes"][sc]["blender"]["psnr"] for sc in suite])
                        for r in rows])
        out["paper_suite_spheres"] = {"scenes": suite, "blender_psnr_mean": float(per.mean()),
                                      "blender_psnr_min": float(per.min()),
                                      "worst": rows[int(per.argmin())]["material"]}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--materials", help="comma-separated subset of the material names")
    ap.add_argument("--model", default="ggx-diffuse")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--optimize", default="engines",
                    help="the exporter's refinement (brdffit.export.gltf.OPTIMIZE; default: "
                         "the exporter's, engines), false: the rules alone")
    ap.add_argument("--spp", type=int, default=64, help="per batch")
    ap.add_argument("--batches", type=int, default=4)
    ap.add_argument("--scenes", default=",".join(SCENES),
                    help="comma-separated: sphere-distant and sphere-<map> scenes")
    ap.add_argument("--label", default="current", help="key of this run in the JSON")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "engines_blender.json")
    args = ap.parse_args(argv)
    if str(args.optimize).lower() in ("false", "none", "0", ""):
        args.optimize = False
    args.scenes = [x for x in args.scenes.split(",") if x]

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
    for name, spec in mats:
        r = bench_material(name, spec, args)
        rows.append(r)
        for scene, v in r["scenes"].items():
            b, e = v["blender"], v["equivalent"]
            extra = "".join(f" {k.removeprefix('blender_')} {v[k]['psnr']:6.2f}"
                            for k in ("blender_ggx", "blender_usd") if k in v)
            print(f"{name:22s} {scene:17s} Blender {b['psnr']:6.2f} ± {b['psnr_se']:4.2f}"
                  f"{extra} spec eq. {e.get('psnr', np.nan):6.2f} Blender eq. "
                  f"{v['equivalent_blender'].get('psnr', np.nan):6.2f} ratio "
                  f"{' '.join(f'{x:.3f}' for x in b['mean_ratio'])} rim "
                  f"{' '.join(f'{x:.3f}' for x in b['rim_ratio'])} FLIP {b['flip']:.4f}",
                  flush=True)
    run = {"commit": commit, "model": args.model, "optimize": args.optimize,
           "scenes": args.scenes,
           "resolution": args.res, "spp_per_batch": args.spp, "batches": args.batches,
           "cpus": os.cpu_count(), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
           "command": "bench/bench_engines.py " + " ".join(argv if argv is not None
                                                            else sys.argv[1:]),
           "summary": _summary(rows, args.scenes), "materials": rows}
    old = json.loads(args.out.read_text()) if args.out.is_file() else {}
    old[args.label] = run
    with atomic_write(args.out, "w") as fh:
        fh.write(json.dumps(old, indent=1, default=float) + "\n")
    print(json.dumps(run["summary"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
