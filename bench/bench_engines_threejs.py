"""three.js round trip (issue 34): glTF exports of ggx-diffuse fits rendered by three.js
(``MeshPhysicalMaterial``, WebGL 2 on SwiftShader, headless Chromium) in ``sphere-distant``,
against our Mitsuba render of the fit; and their MaterialX exports rendered by MaterialX's own
ESSL shaders in the same browser.

Run: ``.venv/bin/python bench/bench_engines_threejs.py`` (the issue's four MERL stand-ins and
the 7 RGL files); ``--merl all`` for the 100 Neural-BRDF MERL materials (``--every 5``: 20 of
them, written with ``--out bench/results/engines_threejs_merl.json``), ``--merl a,b`` for a
subset, ``--no-rgl``; ``--res``, ``--ss`` (samples per pixel side in three.js), ``--spp`` and
``--batches`` (Mitsuba). Needs ``make npmdeps`` (three), Chromium and ``../shared/data``.
Writes ``bench/results/engines_threejs.json`` (atomically, after every material) and
``engines_threejs.csv``.

Per material (``fit`` = ``brdffit.fit(material, model="ggx-diffuse")``, the file =
``write_gltf(fit)``, as ``brdffit fit`` + ``brdffit export --to gltf`` make them):

* ``three``: :func:`brdffit.evaluation.engines.threejs.compare_render` of the three.js image
  against K Mitsuba renders of the fit: ``psnr`` ± ``psnr_se``, ``mean_ratio`` and
  ``rim_ratio`` (RGB, r > 0.85 R), ``flip`` (HDR-FLIP over the foreground), coverage and
  peak pixel;
* ``model_vs_three``: PSNR of :class:`ThreeJSBRDF` (our model of three's shader, noise-free
  shader :func:`shade_sphere`) against the three.js image: how well the model explains it;
* ``shader_vs_mitsuba_fit``: the noise-free shader of the fit (16 × 16 samples per pixel)
  against Mitsuba's render of it (a check of the shader; limited by Mitsuba's noise on sharp
  highlights), ``three_vs_converged_fit``: three.js against that converged image, and
  ``three_grid_vs_converged``: the model on three's sample grid against it on the 16 × 16 one
  (what the engine's pixel sampling alone costs);
* ``estimate``: the cheap estimate of the engine's PSNR vs the fit (model vs the fit, both
  through :func:`shade_sphere`, no browser, no Monte Carlo) and its error to the measured one;
* ``gltf_spec_vs_fit``: the glTF specification's BRDF (:class:`GLTFBRDF`, what the exporter
  optimises) vs the fit, same shader;
* ``ablations``: the model vs the fit with one of three's departures from the specification
  switched off (``no_multiscatter``, ``pow5_fresnel``, ``no_geometry_roughness``,
  ``no_min_roughness``): which departure costs what;
* ``materialx`` (``--materialx``, default on): the same figures for the MaterialX export
  (``write_materialx``) rendered by MaterialX's own ESSL shaders in the browser
  (:mod:`brdffit.evaluation.engines.materialx_web`), with ``model_vs_engine`` and
  ``estimate`` from :class:`OpenPBRBRDF` (the exporter's model of MaterialX's GLSL);
* timings (fit, export, three.js, MaterialX, Mitsuba) and the load average before and after.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "bench"))
os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")

DATA = ROOT.parent / "shared" / "data"
if not DATA.is_dir():
    DATA = Path("/work/shared/data")
NBRDF = DATA / "nbrdf" / "merl_nbrdf.zip"
RGL = DATA / "rgl"
ISSUE_MERL = ["ss440", "gold-metallic-paint", "maroon-plastic", "white-paint"]
FIELDS = ["material", "psnr", "psnr_se", "psnr_vs_converged", "mx_psnr", "mx_psnr_se",
          "mx_mean_r", "mx_mean_g", "mx_mean_b", "mx_rim_r", "mx_flip", "mx_model_vs_engine",
          "mean_r", "mean_g", "mean_b", "rim_r", "rim_g", "rim_b",
          "flip", "model_vs_three", "estimate", "estimate_error", "gltf_spec_vs_fit",
          "no_multiscatter", "pow5_fresnel", "no_geometry_roughness", "three_s"]


def bench_material(name, spec, args) -> dict:
    import brdffit
    from brdffit.evaluation.engines import threejs as T
    from brdffit.evaluation.engines import threejs_brdf as TB
    from brdffit.evaluation.metrics import rendered_psnr
    from brdffit.export.gltf import gltf_equivalent, write_gltf

    out = {"material": name, "spec": spec, "timings": {}}
    t = time.perf_counter()
    fit = brdffit.fit(brdffit.load(spec), model="ggx-diffuse")
    out["timings"]["fit_s"] = time.perf_counter() - t
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.gltf"
        t = time.perf_counter()
        write_gltf(fit, path, fidelity=False, optimize=args.optimize)
        out["timings"]["export_s"] = time.perf_counter() - t
        doc = json.loads(path.read_text())
        out["gltf_material"] = {k: v for k, v in doc["materials"][0].items() if k != "extras"}
        t = time.perf_counter()
        r = T.render_gltf(path, "sphere-distant", resolution=args.res, supersample=args.ss)
        out["timings"]["three_s"] = time.perf_counter() - t
        model = TB.from_gltf(path)
    t = time.perf_counter()
    refs, ra = T.reference_renders(fit, "sphere-distant", args.res, args.spp, args.batches)
    out["timings"]["mitsuba_s"] = time.perf_counter() - t
    c = T.compare_render(r.image, r.alpha, refs, ra)
    crn = c.pop("crn")
    out["three"] = c | {"crn": {k: crn[k] for k in ("mse", "mse_se", "noise_mse", "resolved",
                                                       "bound", "psnr_plain", "batches")}}
    out["three_info"] = r.info
    mask = r.mask & (ra >= 0.999)
    kw = {"resolution": args.res, "supersample": args.ss}
    # the fit's pixel integrals converged (a 16 × 16 grid at least), as Mitsuba's estimate
    fit_img, _ = TB.shade_sphere(fit, geometry_roughness=False, resolution=args.res,
                                 supersample=max(16, args.ss))
    est, _ = TB.shade_sphere(model, **kw)
    out["model_vs_three"] = rendered_psnr(r.image, est, mask)
    out["shader_vs_mitsuba_fit"] = rendered_psnr(refs.mean(0), fit_img, mask)
    # three vs the converged fit (no Monte Carlo noise), and what three's sample grid alone
    # costs (the model on three's grid vs on the 16 × 16 one)
    out["three_vs_converged_fit"] = rendered_psnr(fit_img, r.image, mask)
    fine, _ = TB.shade_sphere(model, resolution=args.res, supersample=max(16, args.ss))
    out["three_grid_vs_converged"] = rendered_psnr(fine, est, mask)
    e = rendered_psnr(fit_img, est, mask)
    out["estimate"] = {"psnr": e, "error_db": e - c["psnr"]}
    spec_img, _ = TB.shade_sphere(gltf_equivalent(fit, optimize=args.optimize),
                                  geometry_roughness=False, **kw)
    out["gltf_spec_vs_fit"] = rendered_psnr(fit_img, spec_img, mask)
    abl = {}
    for key, opts, g in (("no_multiscatter", {"multiscatter": False}, True),
                         ("pow5_fresnel", {"sg_fresnel": False}, True),
                         ("no_geometry_roughness", {}, False),
                         ("no_min_roughness", {"min_roughness": False}, True),
                         ("spec_like", {"multiscatter": False, "sg_fresnel": False,
                                        "min_roughness": False}, False)):
        img, _ = TB.shade_sphere(TB.from_gltf(doc, **opts), geometry_roughness=g, **kw)
        abl[key] = {"psnr_vs_fit": rendered_psnr(fit_img, img, mask),
                    "mean_ratio": (img[mask].sum(0) / fit_img[mask].sum(0)).tolist()}
    out["ablations"] = abl
    if args.materialx:
        from brdffit.evaluation.engines import materialx_web as MX
        from brdffit.export.materialx import openpbr_equivalent, write_materialx

        with tempfile.TemporaryDirectory() as tmp:
            mpath = Path(tmp) / "m.mtlx"
            write_materialx(fit, mpath, fidelity=False)
            t = time.perf_counter()
            rm = MX.render_mtlx(mpath, "sphere-distant", resolution=args.res, supersample=args.ss)
            out["timings"]["materialx_s"] = time.perf_counter() - t
        cm = T.compare_render(rm.image, rm.alpha, refs, ra)
        cm.pop("crn")
        eq, _ = TB.shade_sphere(openpbr_equivalent(fit), geometry_roughness=False, **kw)
        mmask = rm.mask & (ra >= 0.999)
        e = rendered_psnr(fit_img, eq, mmask)
        out["materialx"] = cm | {"vs_converged_fit": rendered_psnr(fit_img, rm.image, mmask),
                                 "model_vs_engine": rendered_psnr(rm.image, eq, mmask),
                                 "estimate": {"psnr": e, "error_db": e - cm["psnr"]},
                                 "info": rm.info}
    return out


def _row(r: dict) -> dict:
    c = r["three"]
    return {"material": r["material"], "psnr": c["psnr"], "psnr_se": c["psnr_se"],
            "psnr_vs_converged": r["three_vs_converged_fit"],
            "mean_r": c["mean_ratio"][0], "mean_g": c["mean_ratio"][1],
            "mean_b": c["mean_ratio"][2], "rim_r": c["rim_ratio"][0], "rim_g": c["rim_ratio"][1],
            "rim_b": c["rim_ratio"][2], "flip": c["flip"], "model_vs_three": r["model_vs_three"],
            "estimate": r["estimate"]["psnr"], "estimate_error": r["estimate"]["error_db"],
            "gltf_spec_vs_fit": r["gltf_spec_vs_fit"],
            "no_multiscatter": r["ablations"]["no_multiscatter"]["psnr_vs_fit"],
            "pow5_fresnel": r["ablations"]["pow5_fresnel"]["psnr_vs_fit"],
            "no_geometry_roughness": r["ablations"]["no_geometry_roughness"]["psnr_vs_fit"],
            "three_s": r["timings"]["three_s"]} | ({
                "mx_psnr": r["materialx"]["psnr"], "mx_psnr_se": r["materialx"]["psnr_se"],
                "mx_mean_r": r["materialx"]["mean_ratio"][0],
                "mx_mean_g": r["materialx"]["mean_ratio"][1],
                "mx_mean_b": r["materialx"]["mean_ratio"][2],
                "mx_rim_r": r["materialx"]["rim_ratio"][0], "mx_flip": r["materialx"]["flip"],
                "mx_model_vs_engine": r["materialx"]["model_vs_engine"]}
                if "materialx" in r else {})


def summarise(results: list[dict]) -> dict:
    ok = [r for r in results if "three" in r]
    if not ok:
        return {"materials": 0}
    p = np.array([r["three"]["psnr"] for r in ok])
    mr = np.array([r["three"]["mean_ratio"] for r in ok])
    rim = np.array([r["three"]["rim_ratio"] for r in ok])
    flip = np.array([r["three"]["flip"] for r in ok if r["three"]["flip"] is not None])
    est = np.array([r["estimate"]["error_db"] for r in ok])
    est_c = np.array([r["estimate"]["psnr"] - r["three_vs_converged_fit"] for r in ok])
    n = len(ok)

    def ms(x):
        return {"mean": float(np.mean(x)), "se": float(np.std(x, ddof=1) / np.sqrt(n)) if n > 1
                else None, "min": float(np.min(x)), "max": float(np.max(x))}

    return {"materials": n, "errors": len(results) - n, "psnr": ms(p),
            "lowest": ok[int(np.argmin(p))]["material"],
            "psnr_vs_converged_fit": ms([r["three_vs_converged_fit"] for r in ok]),
            "shader_vs_mitsuba_fit": ms([r["shader_vs_mitsuba_fit"] for r in ok]),
            "three_grid_vs_converged": ms([r["three_grid_vs_converged"] for r in ok]),
            "mean_ratio_range": [float(mr.min()), float(mr.max())],
            "materials_mean_ratio_within_3pct": int(np.sum(np.all(np.abs(mr - 1) <= 0.03, 1))),
            "rim_ratio_range": [float(rim.min()), float(rim.max())],
            "materials_rim_within_5pct": int(np.sum(np.all(np.abs(rim - 1) <= 0.05, 1))),
            "flip": ms(flip) if flip.size else None,
            "model_vs_three": ms([r["model_vs_three"] for r in ok]),
            "estimate_error_db": ms(est), "estimate_within_2db": int(np.sum(np.abs(est) <= 2)),
            # against the converged fit (no Mitsuba noise: sharp highlights are noise-limited)
            "estimate_error_vs_converged_db": ms(est_c),
            "estimate_within_2db_vs_converged": int(np.sum(np.abs(est_c) <= 2)),
            "gltf_spec_vs_fit": ms([r["gltf_spec_vs_fit"] for r in ok]),
            "ablations_psnr_vs_fit": {k: ms([r["ablations"][k]["psnr_vs_fit"] for r in ok])
                                      for k in ok[0]["ablations"]},
            "materialx": _summarise_engine([r["materialx"] for r in ok if "materialx" in r])}


def _summarise_engine(rs: list[dict]) -> dict | None:
    """PSNR, ratios, rim, FLIP and the estimate's error over materials of one engine."""
    if not rs:
        return None
    n = len(rs)

    def ms(x):
        x = np.asarray(x, float)
        return {"mean": float(x.mean()), "se": float(x.std(ddof=1) / np.sqrt(n)) if n > 1
                else None, "min": float(x.min()), "max": float(x.max())}

    mr = np.array([r["mean_ratio"] for r in rs])
    rim = np.array([r["rim_ratio"] for r in rs])
    est = [r["estimate"]["error_db"] for r in rs]
    est_c = [r["estimate"]["psnr"] - r["vs_converged_fit"] for r in rs]
    return {"materials": n, "psnr": ms([r["psnr"] for r in rs]),
            "psnr_vs_converged_fit": ms([r["vs_converged_fit"] for r in rs]),
            "mean_ratio_range": [float(mr.min()), float(mr.max())],
            "rim_ratio_range": [float(rim.min()), float(rim.max())],
            "flip": ms([r["flip"] for r in rs if r["flip"] is not None]),
            "model_vs_engine": ms([r["model_vs_engine"] for r in rs]),
            "estimate_error_db": ms(est),
            "estimate_within_2db": int(np.sum(np.abs(est) <= 2)),
            "estimate_error_vs_converged_db": ms(est_c),
            "estimate_within_2db_vs_converged": int(np.sum(np.abs(np.array(est_c)) <= 2))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--merl", default=",".join(ISSUE_MERL),
                    help="comma-separated Neural-BRDF MERL names, or 'all' (default: the issue's 4)")
    ap.add_argument("--every", type=int, default=1,
                    help="with --merl all: every N-th material in name order (5: 20 of 100)")
    ap.add_argument("--no-rgl", action="store_true", help="skip the 7 RGL files")
    ap.add_argument("--no-materialx", dest="materialx", action="store_false",
                    help="skip the MaterialX round trip")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--optimize", default=False,
                    help="the exporter's refinement (brdffit.export.gltf.OPTIMIZE), e.g. engines")
    ap.add_argument("--ss", type=int, default=8, help="three.js samples per pixel side")
    ap.add_argument("--spp", type=int, default=256, help="Mitsuba samples per pixel per batch")
    ap.add_argument("--batches", type=int, default=8, help="Mitsuba batches (independent seeds)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "engines_threejs.json")
    ap.add_argument("--summarise-only", action="store_true",
                    help="recompute the summary of the results already in --out (no rendering)")
    args = ap.parse_args(argv)

    from brdffit._atomic import atomic_write

    if args.summarise_only:
        doc = json.loads(args.out.read_text())
        doc["summary"] = summarise(doc["results"])
        with atomic_write(args.out, "w") as fh:
            json.dump(doc, fh, indent=1, default=float)
        print(json.dumps(doc["summary"], indent=1, default=float))
        return 0
    from brdffit.evaluation.engines import threejs as T

    ok, why = T.available()
    if not ok:
        print(f"three.js round trip unavailable: {why}")
        return 1
    mats = []
    if args.merl:
        from _common import merl_materials

        names = (merl_materials(NBRDF)[::max(1, args.every)] if args.merl == "all"
                 else args.merl.split(","))
        mats += [(n, f"{NBRDF}:{n}") for n in names]
    if not args.no_rgl:
        mats += [(p.name.removesuffix("_rgb.bsdf") + " (RGL)", str(p))
                 for p in sorted(RGL.glob("*_rgb.bsdf"))]
    load0 = list(os.getloadavg())
    t0 = time.perf_counter()
    results = []
    doc = {}
    for name, spec in mats:
        t = time.perf_counter()
        try:
            r = bench_material(name, spec, args)
        except Exception as exc:  # noqa: BLE001 - keep benchmarking the others
            r = {"material": name, "spec": spec, "error": f"{type(exc).__name__}: {exc}"}
        r["wall_s"] = time.perf_counter() - t
        results.append(r)
        if "three" in r:
            c = r["three"]
            print(f"{name:28s} three vs fit {c['psnr']:6.2f} ± {c['psnr_se'] or 0:.2f} dB | mean "
                  f"{'/'.join(f'{x:.3f}' for x in c['mean_ratio'])} | rim "
                  f"{'/'.join(f'{x:.3f}' for x in c['rim_ratio'])} | FLIP {c['flip'] or float('nan'):.4f}"
                  f" | model vs three {r['model_vs_three']:6.2f} | estimate {r['estimate']['psnr']:6.2f}"
                  f" | spec vs fit {r['gltf_spec_vs_fit']:6.2f} | vs converged fit "
                  f"{r['three_vs_converged_fit']:6.2f} | {r['wall_s']:.1f}s", flush=True)
            if "materialx" in r:
                m = r["materialx"]
                print(f"{'':28s} MaterialX vs fit {m['psnr']:6.2f} ± {m['psnr_se'] or 0:.2f} dB | mean "
                      f"{'/'.join(f'{x:.3f}' for x in m['mean_ratio'])} | rim "
                      f"{'/'.join(f'{x:.3f}' for x in m['rim_ratio'])} | FLIP "
                      f"{m['flip'] or float('nan'):.4f} | model vs engine {m['model_vs_engine']:6.2f}"
                      f" | estimate {m['estimate']['psnr']:6.2f} | vs converged fit "
                      f"{m['vs_converged_fit']:6.2f}", flush=True)
        else:
            print(f"{name:28s} ERROR {r['error']}", flush=True)
        doc = {"benchmark": "engines_threejs",
               "command": " ".join([Path(sys.executable).name] + sys.argv),
               "settings": {"scene": "sphere-distant", "resolution": args.res,
                            "three_supersample": args.ss, "mitsuba_spp": args.spp,
                            "mitsuba_batches": args.batches, "model": "ggx-diffuse",
                            "optimize": args.optimize,
                            "three": T.three_version()},
               "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                           "load_average_start": load0, "load_average_end": list(os.getloadavg())},
               "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
               "wall_s": time.perf_counter() - t0, "summary": summarise(results),
               "results": results}
        with atomic_write(args.out, "w") as fh:
            json.dump(doc, fh, indent=1, default=float)
    buf = io.StringIO()
    w = csv.DictWriter(buf, FIELDS)
    w.writeheader()
    w.writerows(_row(r) for r in results if "three" in r)
    with atomic_write(args.out.with_suffix(".csv"), "w") as fh:
        fh.write(buf.getvalue())
    print(json.dumps(doc.get("summary", {}), indent=1, default=float))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
