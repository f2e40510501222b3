"""Rendering benchmark: Mitsuba 3 sphere renders per model, noise floor, and the
resampling error of the Dr.Jit evaluators.

Run: ``.venv/bin/python bench/bench_render.py`` (``--quick`` for a 64², 32 spp smoke run,
``--fits`` to also fit and render the registered models of ``brdffit.fit``). Writes
``bench/results/render.json`` (atomically) and prints a table.

Figures (per model, 256×256 sphere at 256 spp under an environment map, target ≤ 5 s):

* ``setup_s``: BRDF → Dr.Jit evaluator (tabulation for the generic path) + scene load;
* ``first_render_s``: first render (includes tracing the plugin and LLVM compilation);
* ``render_s``: second render (other seed, kernels cached) = steady-state cost;
* ``noise_floor_psnr``: PSNR (Bagher 2016 §5) between the two seeds;
* ``resampling``: :func:`brdffit.evaluation.render.translate.resampling_error` (cosine-
  weighted relative L1 / L2 / albedo error of the Dr.Jit evaluator vs ``brdf.eval``);
* for fits: ``psnr_vs_reference`` (same seed as the reference's first render).

``--crn`` measures instead, and writes ``bench/results/render_crn.json``:

* the dynamic range of the eight CC0 environment maps (:func:`envmap_stats`: max/median,
  decades between the max and the 1st percentile, energy share of the brightest 0.1 %), which
  justifies the paper suite's choice of courtyard / studio / sunrise;
* on ``synthetic:gold-ggx``, the tabulated and GGX fits (``brdffit.fit_tabulated`` /
  ``fit_ggx``, fit time excluded) compared on the paper's four scenes at 256² with common
  random numbers: PSNR ± standard error per scene and mean (target ≥ 55 dB, se ≤ 0.5 dB);
  and, for contrast, the former protocol (each model with its own sampler, same seed,
  sphere under the studio map, 256 spp).

Timings depend on machine load (shared 2-core machine during development): re-run to update.
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

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

SHARED = ROOT.parent / "shared" / "data"
NBRDF = SHARED / "nbrdf" / "merl_nbrdf.zip"
DEFAULT_MATERIALS = [f"{NBRDF}:{m}" for m in ("blue-metallic-paint", "chrome-steel",
                                               "white-paint", "gold-metallic-paint")] + [
    str(SHARED / "rgl" / "paper_white_rgb.bsdf")]
DEFAULT_SYNTHETIC = ["synthetic:gold-ggx", "synthetic:plastic-beckmann", "synthetic:aniso-ggx",
                     "synthetic:sgd-paint", "synthetic:two-lobe-ggx"]


def _bench_one(label, brdf, args, reference=None, mode="auto"):
    from brdffit.evaluation.render import Renderer, psnr
    from brdffit.evaluation.render.translate import resampling_error

    r = Renderer(brdf, scene=args.scene, envmap=args.envmap, spp=args.spp,
                 resolution=args.resolution, mode=mode)
    a = r.render(0)
    b = r.render(1)
    t0 = time.perf_counter()
    err = resampling_error(brdf, r.evaluator, n=1 << 16)
    t_err = time.perf_counter() - t0
    out = {
        "label": label, "model": type(brdf).__name__,
        "evaluator": a.info["evaluator"], "path": a.info["path"],
        "setup_s": round(r.setup_seconds, 3), "first_render_s": round(a.seconds, 3),
        "render_s": round(b.seconds, 3), "render_cpu_s": round(b.cpu_seconds, 3),
        "noise_floor_psnr": round(psnr(a.image, b.image, a.mask), 2),
        "resampling": {k: (round(v, 6) if isinstance(v, float) else v) for k, v in err.items()},
        "resampling_s": round(t_err, 3),
        "foreground_fraction": round(float(a.mask.mean()), 4),
    }
    if reference is not None:
        out["psnr_vs_reference"] = round(psnr(reference.image, a.image, reference.mask), 2)
    print(f"  {label:<34} {out['evaluator']:<11} {out['path']:<11} setup {out['setup_s']:6.2f} s  "
          f"first {out['first_render_s']:6.2f} s  render {out['render_s']:6.2f} s "
          f"(CPU {out['render_cpu_s']:6.2f} s)  "
          f"noise-floor {out['noise_floor_psnr']:6.2f} dB  resampling L1 {err['rel_cos']:.2e} "
          f"albedo {err['albedo_rel']:.2e}"
          + (f"  PSNR vs ref {out['psnr_vs_reference']:.2f} dB" if reference is not None else ""),
          flush=True)
    return out, a


def _scene_timings(args):
    """Render ``args.scene_timings`` in every scene (same resolution/spp) and time it."""
    from brdffit.evaluation.render import SCENES, Renderer, psnr
    from brdffit.io import load

    brdf = load(args.scene_timings)
    print(f"scenes ({args.scene_timings}):")
    out = {"brdf": args.scene_timings, "load_avg": os.getloadavg(), "scenes": []}
    for scene in SCENES:
        r = Renderer(brdf, scene=scene, envmap=args.envmap, spp=args.spp,
                     resolution=args.resolution)
        a, b = r.render(0), r.render(1)
        rec = {"scene": scene, "setup_s": round(r.setup_seconds, 3),
               "first_render_s": round(a.seconds, 3), "render_s": round(b.seconds, 3),
               "render_cpu_s": round(b.cpu_seconds, 3),
               "noise_floor_psnr": round(psnr(a.image, b.image, a.mask), 2),
               "foreground_fraction": round(float(a.mask.mean()), 4)}
        print(f"  {scene:<16} render {rec['render_s']:6.2f} s (CPU {rec['render_cpu_s']:6.2f} s)  "
              f"noise-floor {rec['noise_floor_psnr']:6.2f} dB", flush=True)
        out["scenes"].append(rec)
    return out


def _crn_figures(args) -> dict:
    """Issue 13 figures: envmap dynamic range; gold-ggx tabulated / GGX fits, PSNR ± se."""
    import tempfile

    import brdffit
    from brdffit.evaluation.compare import compare
    from brdffit.evaluation.render import Renderer, envmap_names, envmap_stats, psnr

    out = {"machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                       "load_avg_start": os.getloadavg()},
           "settings": {"resolution": args.resolution, "spp": args.crn_spp,
                        "batches": args.crn_batches, "scenes": "paper"}}
    out["envmaps"] = {n: envmap_stats(n) for n in envmap_names()}
    for n, st in out["envmaps"].items():
        print(f"  {n:<10} max {st['max']:9.1f}  max/median {st['max_over_median']:9.0f}  "
              f"decades {st['decades']:.2f}  top-0.1% energy {st['top_energy']:.2f}")
    ref = brdffit.load("synthetic:gold-ggx")
    fits = {}
    for name, fn in (("tabulated", brdffit.fit_tabulated), ("ggx", brdffit.fit_ggx)):
        t0 = time.perf_counter()
        fits[name] = fn(ref)
        out.setdefault("fit_seconds", {})[name] = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        t0, c0 = time.perf_counter(), time.process_time()
        res = compare(ref, fits, tmp, spp=args.crn_spp, batches=args.crn_batches,
                      resolution=args.resolution, brdf_metrics=("cos_rel_error",),
                      progress=lambda m: print(f"  [{time.perf_counter() - t0:6.1f} s] {m}",
                                               flush=True))
        out["compare_seconds"], out["compare_cpu_seconds"] = (time.perf_counter() - t0,
                                                              time.process_time() - c0)
    out["scenes"] = [{k: s.get(k) for k in ("name", "envmap", "exposure", "render_seconds",
                                            "render_cpu_seconds")}
                     | {"peak": s["reference"]["peak"],
                        "peak_psnr_se": s["reference"].get("peak_psnr_se"),
                        "peak_batches_only": s["reference"].get("peak_batches_only")}
                     for s in res["scenes"]]
    out["gold_ggx"] = {}
    for m in res["models"]:
        rec = {k: m.get(k) for k in ("psnr", "psnr_se", "psnr_se_mse", "mean_de2000")}
        rec["cos_rel_error"] = (m.get("brdf") or {}).get("cos_rel_error")
        rec["scenes"] = [{k: e.get(k) for k in ("scene", "psnr", "psnr_se", "psnr_se_mse",
                                                "noise_mse", "mse", "resolved")}
                         for e in m["scenes"]]
        rec["meets_target"] = bool(m["psnr"] >= 55.0 and m["psnr_se"] <= 0.5)
        out["gold_ggx"][m["name"]] = rec
        print(f"  gold-ggx {m['name']:<10} PSNR {m['psnr']:7.2f} ± {m['psnr_se']:.3f} dB  ("
              + ", ".join(f"{e['scene']} {e['psnr']:.2f} ± {e['psnr_se']:.3f}" for e in m["scenes"])
              + ")")
    # the former protocol: own sampling, same seed, one scene
    env = "studio" if "studio" in envmap_names() else None
    a = Renderer(ref, scene="sphere-env", envmap=env, spp=256, resolution=args.resolution).render(0)
    out["former_protocol"] = {"scene": "sphere-env", "envmap": env, "spp": 256,
                              "note": "each model with its own importance sampling, same seed "
                                      "(PSNR limited by the Monte Carlo noise unless the "
                                      "samplers coincide)"}
    for name, model in fits.items():
        b = Renderer(model, scene="sphere-env", envmap=env, spp=256,
                     resolution=args.resolution).render(0)
        out["former_protocol"][name] = psnr(a.image, b.image, a.mask)
        print(f"  former protocol {name:<10} {out['former_protocol'][name]:.2f} dB")
    out["validation"] = _crn_validation()
    out["machine"]["load_avg_end"] = os.getloadavg()
    return out


def _crn_validation(resolution: int = 96, batches: int = 8, spp: int = 32) -> list:
    """Unbiasedness check of the CRN estimate: the same U-statistic MSE computed from the
    models rendered with *independent* seeds (no common random numbers: unbiased too, only
    much noisier) must agree within the combined standard error. Fits of a Neural-BRDF
    material made here (GGX, NPF bivariate), sphere-studio and knot-courtyard."""
    import brdffit
    from brdffit.evaluation.metrics import crn_psnr
    from brdffit.evaluation.render import MultiRenderer, envmap_names
    from brdffit.fit.registry import fit_model

    if not NBRDF.exists() or "studio" not in envmap_names():
        return []
    ref = brdffit.load(f"{NBRDF}:gold-metallic-paint")
    models = {"ref": ref}
    for name in ("ggx", "npf-bivariate"):
        models[name], _ = fit_model(name, ref, None)
    rows = []
    for scene in ("sphere-studio", "knot-courtyard"):
        mr = MultiRenderer(models, scene=scene, resolution=resolution, reference=ref)
        A = [mr.render(1000 + k, spp) for k in range(batches)]
        B = [mr.render(5000 + k, spp) for k in range(batches)]
        mask = np.mean([r.alpha for r in A], 0) >= 0.999
        R = np.stack([r.images["ref"] for r in A])
        peak = float(R.mean(0)[mask].max())
        for k in models:
            if k == "ref":
                continue
            crn = crn_psnr(R, np.stack([r.images[k] for r in A]), mask, peak=peak)
            ind = crn_psnr(R, np.stack([r.images[k] for r in B]), mask, peak=peak)
            z = (crn["psnr"] - ind["psnr"]) / np.hypot(crn["psnr_se"], ind["psnr_se"])
            rows.append({"scene": scene, "model": k, "crn": [crn["psnr"], crn["psnr_se"]],
                         "independent": [ind["psnr"], ind["psnr_se"]],
                         "independent_plain": ind["psnr_plain"], "z": z})
            print(f"  validation {scene:<15} {k:<14} CRN {crn['psnr']:.2f} ± {crn['psnr_se']:.3f}"
                  f" | independent seeds {ind['psnr']:.2f} ± {ind['psnr_se']:.3f} (noise-biased "
                  f"{ind['psnr_plain']:.2f}) z {z:+.2f}", flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--materials", nargs="*", default=None)
    ap.add_argument("--synthetic", nargs="*", default=DEFAULT_SYNTHETIC)
    ap.add_argument("--scene", default="sphere-env")
    ap.add_argument("--envmap", default="studio")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--fits", nargs="*", default=None,
                    help="fit and render these registered models (no value: all registered)")
    ap.add_argument("--quick", action="store_true", help="64², 32 spp, one material")
    ap.add_argument("--scene-timings", default="synthetic:gold-ggx",
                    help="time every scene of SCENES with this BRDF ('' to skip)")
    ap.add_argument("--only-scenes", action="store_true",
                    help="only the per-scene timings (merged into an existing --out file)")
    ap.add_argument("--out", default=None)
    ap.add_argument("--crn", action="store_true",
                    help="CRN figures (envmaps, gold-ggx PSNR ± se) → render_crn.json")
    ap.add_argument("--crn-spp", type=int, default=64)
    ap.add_argument("--crn-batches", type=int, default=8)
    args = ap.parse_args(argv)
    if args.out is None:
        args.out = str(ROOT / "bench" / "results" / ("render_crn.json" if args.crn else "render.json"))
    if args.quick:
        args.spp, args.resolution = 32, 64
    from brdffit.evaluation.render import available, envmap_names

    if not available():
        print("Mitsuba 3 LLVM back-end unavailable: nothing to benchmark", file=sys.stderr)
        return 1
    if args.crn:
        results = _crn_figures(args)
        from brdffit._atomic import atomic_write
        from brdffit._json import standard_json

        with atomic_write(args.out, "w") as fh:
            json.dump(standard_json(results), fh, indent=1, default=float)
        print(f"wrote {args.out}")
        return 0
    if args.envmap not in envmap_names() and not Path(args.envmap).is_file():
        print(f"envmap {args.envmap!r} not found; using the procedural environment")
        args.envmap = None
    if args.only_scenes:
        out = Path(args.out)
        results = json.loads(out.read_text()) if out.is_file() else {}
        results["scenes"] = _scene_timings(args)
        from brdffit._atomic import atomic_write

        with atomic_write(out, "w") as fh:
            json.dump(results, fh, indent=1, default=float)
        print(f"wrote {out}")
        return 0
    materials = args.materials
    if materials is None:
        materials = [m for m in DEFAULT_MATERIALS if Path(m.split(".zip:")[0] + (".zip" if ".zip:" in m else "")).exists()]
        if args.quick:
            materials = materials[:1]
    from brdffit import load

    results = {"settings": {"scene": args.scene, "envmap": args.envmap, "spp": args.spp,
                            "resolution": args.resolution},
               "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                           "load_avg_start": os.getloadavg()},
               "measured": [], "synthetic": [], "fits": []}
    print(f"{args.resolution}² sphere, {args.spp} spp, scene {args.scene}, envmap "
          f"{args.envmap or 'procedural'}")
    print("measured materials (generic MERL-grid table path):")
    refs = {}
    for spec in materials:
        brdf = load(spec)
        rec, img = _bench_one(brdf.name, brdf, args)
        rec["spec"] = spec
        results["measured"].append(rec)
        refs[spec] = (brdf, img)
    print("analytic models (closed-form path; and the table path for comparison):")
    for spec in (args.synthetic if not args.quick else args.synthetic[:1]):
        brdf = load(spec)
        rec, img = _bench_one(spec.split(":", 1)[1], brdf, args)
        rec["spec"] = spec
        trec, _ = _bench_one(spec.split(":", 1)[1] + " [table]", brdf, args, reference=img,
                             mode="table")
        rec["table_path"] = trec
        results["synthetic"].append(rec)
    if args.fits is not None:
        from brdffit.fit.registry import fit as run_fit, list_fitters

        names = args.fits or [f if isinstance(f, str) else f.name for f in list_fitters()]
        print(f"fits ({', '.join(names)}) of each measured material:")
        for spec, (brdf, ref_img) in refs.items():
            for name in names:
                t0 = time.perf_counter()
                try:
                    model = run_fit(name, brdf)
                except Exception as exc:  # a fit that fails is recorded, not fatal
                    print(f"  {brdf.name}/{name}: fit failed: {exc}")
                    results["fits"].append({"material": brdf.name, "fit": name, "error": str(exc)})
                    continue
                t_fit = time.perf_counter() - t0
                rec, _ = _bench_one(f"{brdf.name}/{name}", model, args, reference=ref_img)
                rec.update({"material": brdf.name, "fit": name, "fit_s": round(t_fit, 2)})
                results["fits"].append(rec)
    if args.scene_timings:
        results["scenes"] = _scene_timings(args)
    results["machine"]["load_avg_end"] = os.getloadavg()
    all_recs = (results["measured"] + results["synthetic"]
                + [r["table_path"] for r in results["synthetic"] if "table_path" in r]
                + [r for r in results["fits"] if "render_s" in r])
    rt = [r["render_s"] for r in all_recs if "render_s" in r]
    ct = [r["render_cpu_s"] for r in all_recs if "render_cpu_s" in r]
    results["summary"] = {
        "render_cpu_s_max": max(ct) if ct else None,
        "render_cpu_s_median": float(np.median(ct)) if ct else None,
        "note": "render_s is wall-clock time and depends on machine load; render_cpu_s is the "
                "process CPU time (all threads): wall time on an idle machine with N cores is "
                "about render_cpu_s / N",
        "render_s_max": max(rt) if rt else None, "render_s_median": float(np.median(rt)) if rt else None,
        "target_s": 5.0, "within_target": bool(rt) and max(rt) <= 5.0,
        "noise_floor_psnr_min": min(r["noise_floor_psnr"] for r in all_recs) if all_recs else None,
    }
    from brdffit._atomic import atomic_write

    with atomic_write(args.out, "w") as fh:
        json.dump(results, fh, indent=1, default=float)
    print(f"summary: {results['summary']}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
