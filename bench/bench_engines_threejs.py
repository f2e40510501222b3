"""three.js and MaterialX round trip (issue 34): glTF exports of ggx-diffuse fits rendered by
three.js (``MeshPhysicalMaterial``, WebGL 2 on SwiftShader, headless Chromium) and their
MaterialX exports rendered by MaterialX's own ESSL shaders in the same browser, in
``sphere-distant`` and the paper suite's spheres (``sphere-courtyard``, ``sphere-studio``,
``sphere-sunrise``: the map alone, three's PMREM image-based lighting and MaterialX's FIS
environment lighting), against our Mitsuba render of the fit in the same scene.

Run: ``.venv/bin/python bench/bench_engines_threejs.py`` (the issue's four MERL stand-ins and
the 7 RGL files, the default scenes); ``--scenes a,b`` (sphere-distant, sphere-point: three.js
only, sphere-env, sphere-<map>); ``--merl all`` for the 100 Neural-BRDF MERL materials
(``--every 5``: 20 of them; give such runs their own ``--out`` outside ``bench/results``),
``--merl a,b`` for a subset, ``--no-rgl``; ``--res``, ``--ss`` (samples per pixel side in
three.js), ``--mx-ss`` (in MaterialX: its FIS loop is what SwiftShader spends the time on),
``--env-samples`` (MaterialX's FIS samples per lobe), ``--spp`` and ``--batches`` (Mitsuba).
Needs ``make npmdeps`` (three), Chromium and ``../shared/data``. Writes
``bench/results/engines_threejs.json`` (atomically, after every material) and
``engines_threejs.csv`` (one row per material and scene); ``--optimize false --label
rules`` stores a run of the rule-based parameters under ``labelled["rules"]`` of the same JSON.

Per material (``fit`` = ``brdffit.fit(material, model="ggx-diffuse")``, the files =
``write_gltf(fit)`` and ``write_materialx(fit)``, as ``brdffit fit`` + ``brdffit export``
make them), ``scenes[scene]``:

* ``three``: :func:`brdffit.evaluation.engines.threejs.compare_render` of the three.js image
  against K Mitsuba renders of the fit: ``psnr`` ± ``psnr_se``, ``mean_ratio`` and
  ``rim_ratio`` (RGB, r > 0.85 R), ``flip`` (HDR-FLIP over the foreground), coverage and
  peak pixel;
* ``materialx``: the same figures for the MaterialX export
  (:mod:`brdffit.evaluation.engines.materialx_web`; ``--no-materialx`` skips it); in the
  environment scenes with ``estimate`` (:func:`brdffit.export.materialx_fis.estimate_fis`:
  MaterialX's FIS of the exporter's :class:`OpenPBRBRDF` in NumPy) and its error, and
  ``model_vs_engine`` (that image against MaterialX's);
* in ``sphere-distant``, the noise-free diagnostics: ``model_vs_three`` (:class:`ThreeJSBRDF`,
  our model of three's shader, through :func:`shade_sphere`, against the three.js image),
  ``shader_vs_mitsuba_fit``, ``three_vs_converged_fit``, ``three_grid_vs_converged``,
  ``estimate`` (the cheap estimate of the engine's PSNR: model vs fit, no browser, no Monte
  Carlo) and its error, ``gltf_spec_vs_fit``, ``ablations`` (three's departures from the
  specification switched off one at a time); for MaterialX ``model_vs_engine``,
  ``vs_converged_fit`` and ``estimate`` from :class:`OpenPBRBRDF`;
* in the environment scenes ``estimate``: the cheap estimate of three's PSNR there
  (:func:`brdffit.evaluation.engines.threejs_ibl.estimate_env`: three's PMREM and split-sum
  shading in NumPy, against the same Mitsuba renders of the fit) and its error; also
  ``model_vs_three`` (the estimate's image against three's) and ``three_model_mitsuba`` and
  ``materialx.model_mitsuba``: the engine's model (:class:`ThreeJSBRDF` of the file,
  :class:`OpenPBRBRDF` of the fit) rendered by Mitsuba in the scene against the fit (same
  seeds, :func:`crn_psnr`): what the engine would score if it integrated the map exactly, so
  that the gap to the measured PSNR is what its environment lighting costs;
* timings (fit, export, three.js, MaterialX, Mitsuba).

``summary``: per scene and engine the PSNR mean and lowest (and which material), the
ratio ranges, FLIP; over the paper suite's three spheres per engine each material's mean,
their mean and lowest, the lowest single PSNR and the issue's goals (three.js: mean ≥ 45 dB,
none below 30 dB; MaterialX: mean ≥ 40 dB); ``sphere-distant``: the detailed summary of the
diagnostics. Also the load average before and after, wall and CPU time (this process and
its reaped children: a lower bound, as Chromium's own child processes may be reaped by init
when Chromium is stopped).
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
FIELDS = ["material", "scene", "psnr", "psnr_se", "psnr_vs_converged", "mx_psnr", "mx_psnr_se",
          "mx_mean_r", "mx_mean_g", "mx_mean_b", "mx_rim_r", "mx_flip", "mx_model_vs_engine",
          "mx_model_mitsuba", "mx_estimate", "mx_estimate_error", "mean_r", "mean_g", "mean_b", "rim_r", "rim_g", "rim_b",
          "flip", "model_vs_three", "model_mitsuba", "estimate", "estimate_error",
          "gltf_spec_vs_fit", "no_multiscatter", "pow5_fresnel", "no_geometry_roughness",
          "three_s", "mx_s"]
PAPER_SPHERES = ("sphere-courtyard", "sphere-studio", "sphere-sunrise")
DEFAULT_SCENES = ("sphere-distant",) + PAPER_SPHERES
#: the issue's goals over the paper suite's spheres: (mean ≥, none below) in dB
GOALS = {"three": (45.0, 30.0), "materialx": (40.0, None)}


def _export(fit, tmp: Path, args) -> dict:
    """The fit's glTF and MaterialX files in ``tmp`` and their timings."""
    from brdffit.export.gltf import write_gltf

    out = {"gltf": tmp / "m.gltf", "timings": {}}
    t = time.perf_counter()
    write_gltf(fit, out["gltf"], fidelity=False, optimize=args.optimize)
    out["timings"]["export_s"] = time.perf_counter() - t
    if args.materialx:
        from brdffit.export.materialx import write_materialx

        out["mtlx"] = tmp / "m.mtlx"
        write_materialx(fit, out["mtlx"], fidelity=False)
    return out


def _compare(T, image, alpha, refs, ra) -> dict:
    c = T.compare_render(image, alpha, refs, ra)
    crn = c.pop("crn")
    return c | {"crn": {k: crn[k] for k in ("mse", "mse_se", "noise_mse", "resolved", "bound",
                                            "psnr_plain", "batches")}}


def _model_in_mitsuba(T, model, scene, refs, mask, args) -> dict:
    """An engine's model (its shading of a light, as a BRDF) integrated by Mitsuba in an
    environment scene, against the fit's render with the same seeds: what the engine would
    score if it integrated the map exactly."""
    from brdffit.evaluation.metrics import crn_psnr

    stack, _ = T.reference_renders(model, scene, args.res, args.spp, args.batches)
    c = crn_psnr(refs, stack, mask)
    ref = refs.mean(0)
    return {"psnr": c["psnr"], "psnr_se": c.get("psnr_se"),
            "mean_ratio": (stack.mean(0)[mask].sum(0) / ref[mask].sum(0)).tolist()}


def bench_scene(fit, files: dict, scene: str, args) -> dict:
    """One scene: three.js (and MaterialX) against K Mitsuba renders of the fit; in
    sphere-distant also the noise-free diagnostics of :func:`_distant_diagnostics`, in the
    environment scenes the estimate of three's image-based lighting
    (:func:`~brdffit.evaluation.engines.threejs_ibl.estimate_env`) and the engines' models
    integrated by Mitsuba."""
    from brdffit.evaluation.engines import threejs as T
    from brdffit.evaluation.engines import threejs_brdf as TB
    from brdffit.evaluation.engines import threejs_ibl as TI
    from brdffit.evaluation.metrics import rendered_psnr

    out = {"scene": scene, "timings": {}}
    t = time.perf_counter()
    r = T.render_gltf(files["gltf"], scene, resolution=args.res, supersample=args.ss)
    out["timings"]["three_s"] = time.perf_counter() - t
    t = time.perf_counter()
    refs, ra = T.reference_renders(fit, scene, args.res, args.spp, args.batches)
    out["timings"]["mitsuba_s"] = time.perf_counter() - t
    out["three"] = _compare(T, r.image, r.alpha, refs, ra)
    out["three_info"] = r.info
    mask = r.mask & (ra >= 0.999)
    if scene == "sphere-distant":
        out |= _distant_diagnostics(fit, files["gltf"], r, refs, mask, args)
    else:
        e = TI.estimate_env(files["gltf"], refs, ra, scene, args.ss)
        out["estimate"] = {k: e[k] for k in ("psnr", "psnr_se", "mean_ratio")} | {"error_db": None}
        out["model_vs_three"] = rendered_psnr(r.image, e["image"], mask & (e["alpha"] >= 0.999))
        out["three_model_mitsuba"] = _model_in_mitsuba(T, TB.from_gltf(files["gltf"]), scene,
                                                       refs, mask, args)
    if args.materialx:
        try:
            out["materialx"] = _bench_materialx(fit, files["mtlx"], scene, refs, ra, args,
                                                out["timings"])
        except Exception as exc:  # noqa: BLE001 - keep three's figures of the scene
            out["materialx_error"] = f"{type(exc).__name__}: {exc}"
    return out


def _bench_materialx(fit, mtlx: Path, scene: str, refs, ra, args, timings: dict) -> dict:
    from brdffit.evaluation.engines import materialx_web as MX
    from brdffit.evaluation.engines import threejs as T
    from brdffit.evaluation.engines import threejs_brdf as TB
    from brdffit.evaluation.metrics import rendered_psnr
    from brdffit.export import materialx_fis as FIS
    from brdffit.export.materialx import openpbr_equivalent

    t = time.perf_counter()
    rm = MX.render_mtlx(mtlx, scene, resolution=args.res, supersample=args.mx_ss,
                        env_samples=args.env_samples)
    timings["materialx_s"] = time.perf_counter() - t
    cm = T.compare_render(rm.image, rm.alpha, refs, ra)
    cm.pop("crn")
    mmask = rm.mask & (ra >= 0.999)
    out = cm | {"info": rm.info}
    if scene != "sphere-distant":
        e = FIS.estimate_fis(openpbr_equivalent(fit), refs, ra, scene, args.mx_ss,
                             args.env_samples)
        return out | {"estimate": {"psnr": e["psnr"], "psnr_se": e["psnr_se"],
                                   "mean_ratio": e["mean_ratio"],
                                   "error_db": e["psnr"] - cm["psnr"]},
                      "model_vs_engine": rendered_psnr(rm.image, e["image"],
                                                       mmask & (e["alpha"] >= 0.999)),
                      "model_mitsuba": _model_in_mitsuba(T, openpbr_equivalent(fit), scene,
                                                         refs, mmask, args)}
    kw = {"resolution": args.res, "supersample": args.mx_ss}
    fit_img, _ = TB.shade_sphere(fit, geometry_roughness=False, resolution=args.res,
                                 supersample=max(16, args.mx_ss))
    eq, _ = TB.shade_sphere(openpbr_equivalent(fit), geometry_roughness=False, **kw)
    e = rendered_psnr(fit_img, eq, mmask)
    return out | {"vs_converged_fit": rendered_psnr(fit_img, rm.image, mmask),
                  "model_vs_engine": rendered_psnr(rm.image, eq, mmask),
                  "estimate": {"psnr": e, "error_db": e - cm["psnr"]}}


def _distant_diagnostics(fit, path: Path, r, refs, mask, args) -> dict:
    """sphere-distant only: :class:`ThreeJSBRDF` and the glTF specification's BRDF through the
    noise-free shader (module docstring: model_vs_three, shader_vs_mitsuba_fit,
    three_vs_converged_fit, three_grid_vs_converged, estimate, gltf_spec_vs_fit, ablations)."""
    from brdffit.evaluation.engines import threejs_brdf as TB
    from brdffit.evaluation.metrics import rendered_psnr
    from brdffit.export.gltf import gltf_equivalent

    out = {}
    doc = json.loads(path.read_text())
    out["gltf_material"] = {k: v for k, v in doc["materials"][0].items() if k != "extras"}
    model = TB.from_gltf(path)
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
    out["estimate"] = {"psnr": e, "error_db": None}
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
    return out


def bench_material(name, spec, args) -> dict:
    """Fit ``spec`` (ggx-diffuse), export it, and measure every scene of ``args.scenes``."""
    import brdffit

    out = {"material": name, "spec": spec, "timings": {}, "scenes": {}}
    t = time.perf_counter()
    fit = brdffit.fit(brdffit.load(spec), model="ggx-diffuse")
    out["timings"]["fit_s"] = time.perf_counter() - t
    with tempfile.TemporaryDirectory() as tmp:
        files = _export(fit, Path(tmp), args)
        out["timings"] |= files.pop("timings")
        for scene in args.scenes:
            try:
                sc = bench_scene(fit, files, scene, args)
            except Exception as exc:  # noqa: BLE001 - keep measuring the other scenes
                sc = {"scene": scene, "error": f"{type(exc).__name__}: {exc}"}
            if sc.get("estimate") is not None and "three" in sc:
                sc["estimate"]["error_db"] = sc["estimate"]["psnr"] - sc["three"]["psnr"]
            out["scenes"][scene] = sc
    return out


def _rows(r: dict) -> list[dict]:
    """The CSV rows of one material: one per scene measured."""
    return [_row(r["material"], sc) for sc in r.get("scenes", {}).values() if "three" in sc]


def _row(material: str, r: dict) -> dict:
    c = r["three"]
    row = {"material": material, "scene": r["scene"], "psnr": c["psnr"], "psnr_se": c["psnr_se"],
           "mean_r": c["mean_ratio"][0], "mean_g": c["mean_ratio"][1],
           "mean_b": c["mean_ratio"][2], "rim_r": c["rim_ratio"][0], "rim_g": c["rim_ratio"][1],
           "rim_b": c["rim_ratio"][2], "flip": c["flip"], "three_s": r["timings"]["three_s"]}
    if "three_model_mitsuba" in r:
        row["model_mitsuba"] = r["three_model_mitsuba"]["psnr"]
    if r.get("estimate") is not None:
        row |= {"estimate": r["estimate"]["psnr"], "estimate_error": r["estimate"]["error_db"]}
    if "model_vs_three" in r:
        row["model_vs_three"] = r["model_vs_three"]
    if "three_vs_converged_fit" in r:
        row |= {"psnr_vs_converged": r["three_vs_converged_fit"],
                "gltf_spec_vs_fit": r["gltf_spec_vs_fit"],
                "no_multiscatter": r["ablations"]["no_multiscatter"]["psnr_vs_fit"],
                "pow5_fresnel": r["ablations"]["pow5_fresnel"]["psnr_vs_fit"],
                "no_geometry_roughness": r["ablations"]["no_geometry_roughness"]["psnr_vs_fit"]}
    m = r.get("materialx")
    if m:
        row |= {"mx_psnr": m["psnr"], "mx_psnr_se": m["psnr_se"],
                "mx_mean_r": m["mean_ratio"][0], "mx_mean_g": m["mean_ratio"][1],
                "mx_mean_b": m["mean_ratio"][2], "mx_rim_r": m["rim_ratio"][0],
                "mx_flip": m["flip"], "mx_s": r["timings"].get("materialx_s")}
        if "model_vs_engine" in m:
            row["mx_model_vs_engine"] = m["model_vs_engine"]
        if m.get("estimate"):
            row |= {"mx_estimate": m["estimate"]["psnr"],
                    "mx_estimate_error": m["estimate"]["error_db"]}
        if m.get("model_mitsuba"):
            row["mx_model_mitsuba"] = m["model_mitsuba"]["psnr"]
    return row


def summarise(results: list[dict]) -> dict:
    """Per scene: PSNR (mean, lowest and where), ratio ranges and FLIP per engine; over the
    paper suite's spheres: per material the mean of its three PSNRs, their mean and lowest,
    the lowest single PSNR, and the issue's goals; sphere-distant: :func:`summarise_distant`."""
    scenes = list(dict.fromkeys(s for r in results for s in r.get("scenes", {})))
    out = {"materials": len(results), "scenes": {}}
    for scene in scenes:
        views = [{"material": r["material"]} | r["scenes"][scene] for r in results
                 if "three" in r.get("scenes", {}).get(scene, {})]
        out["scenes"][scene] = {"measured": len(views),
                                "errors": sum(1 for r in results
                                              if "error" in r.get("scenes", {}).get(scene, {})),
                                "three": _scene_engine(views, "three"),
                                "materialx": _scene_engine(views, "materialx")}
        if scene == "sphere-distant" and views:
            out["sphere-distant"] = summarise_distant(views)
    out["paper_suite"] = {e: _paper_suite(results, e) for e in ("three", "materialx")}
    return out


def _scene_engine(views: list[dict], engine: str) -> dict | None:
    """PSNR mean / lowest (and which material), mean and rim ratio ranges and FLIP of one
    engine in one scene; the engine's model integrated by Mitsuba, where measured."""
    rs = [(v["material"], v[engine]) for v in views if v.get(engine)]
    if not rs:
        return None
    p = np.array([c["psnr"] for _, c in rs])
    mr = np.array([c["mean_ratio"] for _, c in rs])
    rim = np.array([c["rim_ratio"] for _, c in rs])
    flip = [c["flip"] for _, c in rs if c.get("flip") is not None]
    model = [c.get("model_mitsuba") or v.get("three_model_mitsuba") if engine == "three"
             else c.get("model_mitsuba") for v, (_, c) in zip(views, rs)]
    model = [m["psnr"] for m in model if m]
    # sphere-distant's estimate is judged against the converged fit (summarise_distant)
    est = [e["error_db"] for e in ((v if engine == "three" else v[engine]).get("estimate")
                                   for v in views
                                   if v.get(engine) and v.get("scene") != "sphere-distant")
           if e and e.get("error_db") is not None]
    return {"estimate_error_db": ({"mean": float(np.mean(est)),
                                   "max_abs": float(np.max(np.abs(est))),
                                   "within_2db": int(np.sum(np.abs(est) <= 2)),
                                   "of": len(est)} if est else None),
            "materials": len(rs), "psnr_mean": float(p.mean()), "psnr_min": float(p.min()),
            "lowest": rs[int(np.argmin(p))][0],
            "mean_ratio_range": [float(mr.min()), float(mr.max())],
            "rim_ratio_range": [float(rim.min()), float(rim.max())],
            "flip_mean": float(np.mean(flip)) if flip else None,
            "model_mitsuba_psnr_mean": float(np.mean(model)) if model else None}


def _paper_suite(results: list[dict], engine: str) -> dict | None:
    """Over the materials measured in all three paper-suite spheres: each material's mean
    PSNR over them, the mean and lowest of those, the lowest single PSNR, and the goal."""
    per = {}
    for r in results:
        cs = [r.get("scenes", {}).get(s, {}).get(engine) for s in PAPER_SPHERES]
        if all(cs):
            per[r["material"]] = {"mean": float(np.mean([c["psnr"] for c in cs])),
                                  "min": float(min(c["psnr"] for c in cs)),
                                  "psnr": {s: float(c["psnr"]) for s, c in zip(PAPER_SPHERES, cs)}}
    if not per:
        return None
    means = {m: v["mean"] for m, v in per.items()}
    low = min(per, key=lambda m: per[m]["min"])
    mean_goal, floor = GOALS[engine]
    mean = float(np.mean(list(means.values())))
    return {"scenes": list(PAPER_SPHERES), "materials": len(per), "mean": mean,
            "lowest_material_mean": min(means.values()),
            "lowest_material": min(means, key=means.get),
            "lowest_single": per[low]["min"], "lowest_single_at": low,
            "per_material": per,
            "goal": {"mean_at_least": mean_goal, "none_below": floor,
                     "met": bool(mean >= mean_goal and (floor is None
                                                        or per[low]["min"] >= floor))}}


def summarise_distant(results: list[dict]) -> dict:
    """sphere-distant in detail (the noise-free model, the estimate and its error, the
    ablations), over the per-material views of that scene."""
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


def _arguments(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--merl", default=",".join(ISSUE_MERL),
                    help="comma-separated Neural-BRDF MERL names, or 'all' (default: the issue's 4)")
    ap.add_argument("--every", type=int, default=1,
                    help="with --merl all: every N-th material in name order (5: 20 of 100)")
    ap.add_argument("--no-rgl", action="store_true", help="skip the 7 RGL files")
    ap.add_argument("--no-materialx", dest="materialx", action="store_false",
                    help="skip the MaterialX round trip")
    ap.add_argument("--scenes", default=",".join(DEFAULT_SCENES),
                    help="comma-separated scenes: sphere-distant, sphere-point (three.js only), "
                         "sphere-env, sphere-<map> (default: sphere-distant and the paper "
                         "suite's spheres)")
    ap.add_argument("--res", type=int, default=96)
    ap.add_argument("--optimize", default="engines",
                    help="the exporter's refinement (brdffit.export.gltf.OPTIMIZE; default: "
                         "the exporter's, engines), false: the rules alone")
    ap.add_argument("--ss", type=int, default=4, help="three.js samples per pixel side")
    ap.add_argument("--mx-ss", type=int, default=2,
                    help="MaterialX samples per pixel side (its FIS loop is SwiftShader's cost)")
    ap.add_argument("--env-samples", type=int, default=256,
                    help="MaterialX FIS samples per specular lobe (u_envRadianceSamples)")
    ap.add_argument("--spp", type=int, default=256, help="Mitsuba samples per pixel per batch")
    ap.add_argument("--batches", type=int, default=8, help="Mitsuba batches (independent seeds)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "engines_threejs.json")
    ap.add_argument("--label", default=None,
                    help="store this run under labelled[LABEL] of --out, next to the main run "
                         "(which is kept, as is the CSV); e.g. --optimize engines --label engines")
    ap.add_argument("--summarise-only", action="store_true",
                    help="recompute the summary of the results already in --out (no rendering)")
    args = ap.parse_args(argv)
    args.scenes = [x.strip() for x in args.scenes.split(",") if x.strip()]
    if str(args.optimize).lower() in ("false", "none", "0", ""):
        args.optimize = False
    return args


def _materials(args) -> list[tuple[str, str]]:
    mats = []
    if args.merl:
        from _common import merl_materials

        names = (merl_materials(NBRDF)[::max(1, args.every)] if args.merl == "all"
                 else args.merl.split(","))
        mats += [(n, f"{NBRDF}:{n}") for n in names]
    if not args.no_rgl:
        mats += [(p.name.removesuffix("_rgb.bsdf") + " (RGL)", str(p))
                 for p in sorted(RGL.glob("*_rgb.bsdf"))]
    return mats


def _report(r: dict) -> None:
    """One line per scene and engine."""
    if "error" in r:
        print(f"{r['material']:28s} ERROR {r['error']}", flush=True)
        return
    for scene, sc in r["scenes"].items():
        if "error" in sc:
            print(f"{r['material']:28s} {scene:17s} ERROR {sc['error']}", flush=True)
            continue
        for label, c in (("three", sc["three"]), ("MaterialX", sc.get("materialx"))):
            if not c:
                continue
            print(f"{r['material']:28s} {scene:17s} {label:9s} {c['psnr']:6.2f} ± "
                  f"{c['psnr_se'] or 0:.2f} dB | mean {'/'.join(f'{x:.3f}' for x in c['mean_ratio'])}"
                  f" | rim {'/'.join(f'{x:.3f}' for x in c['rim_ratio'])} | FLIP "
                  f"{c['flip'] if c['flip'] is not None else float('nan'):.4f}", flush=True)
        if "materialx_error" in sc:
            print(f"{'':28s} {scene:17s} MaterialX ERROR {sc['materialx_error']}", flush=True)


def _settings(args, T) -> dict:
    from brdffit.evaluation.engines import materialx_web as MX

    return {"scenes": args.scenes, "resolution": args.res, "three_supersample": args.ss,
            "materialx_supersample": args.mx_ss, "materialx_env_samples": args.env_samples,
            "materialx_specular_environment": "FIS",
            "materialx_irradiance": f"brute-force E/π, {MX.IRRADIANCE_WIDTH}×"
                                    f"{MX.IRRADIANCE_WIDTH // 2} from the map at 256×128",
            "environment_texture": "the map's own resolution, half floats",
            "mitsuba_spp": args.spp, "mitsuba_batches": args.batches, "model": "ggx-diffuse",
            "optimize": args.optimize, "three": T.three_version()}


def _cpu_seconds() -> float:
    """CPU time of this process and of its finished children (Chromium and its processes)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _store(args, run: dict) -> None:
    """Write ``run`` to ``args.out`` atomically: as the file, or with ``--label`` under
    ``labelled[label]`` of the file's current content (the main run kept)."""
    from brdffit._atomic import atomic_write

    doc = run
    if args.label:
        doc = json.loads(args.out.read_text()) if args.out.is_file() else {}
        doc.setdefault("labelled", {})[args.label] = run
    elif args.out.is_file():
        old = json.loads(args.out.read_text()).get("labelled")
        if old:
            doc = dict(run, labelled=old)
    with atomic_write(args.out, "w") as fh:
        json.dump(doc, fh, indent=1, default=float)


def main(argv=None) -> int:
    args = _arguments(argv)
    from brdffit._atomic import atomic_write

    if args.summarise_only:
        doc = json.loads(args.out.read_text())
        doc["summary"] = summarise(doc["results"])
        with atomic_write(args.out, "w") as fh:
            json.dump(doc, fh, indent=1, default=float)
        print(json.dumps(doc["summary"], indent=1, default=float))
        return 0
    from brdffit.evaluation.engines import threejs as T

    for scene in args.scenes:
        T.resolve_scene(scene)                 # a clear error before any work
    ok, why = T.available()
    if not ok:
        print(f"three.js round trip unavailable: {why}")
        return 1
    load0, cpu0, t0 = list(os.getloadavg()), _cpu_seconds(), time.perf_counter()
    results, doc = [], {}
    for name, spec in _materials(args):
        t = time.perf_counter()
        try:
            r = bench_material(name, spec, args)
        except Exception as exc:  # noqa: BLE001 - keep benchmarking the others
            r = {"material": name, "spec": spec, "error": f"{type(exc).__name__}: {exc}"}
        r["wall_s"] = time.perf_counter() - t
        results.append(r)
        _report(r)
        doc = {"benchmark": "engines_threejs",
               "command": " ".join([Path(sys.executable).name] + sys.argv),
               "settings": _settings(args, T),
               "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                           "load_average_start": load0, "load_average_end": list(os.getloadavg()),
                           "nice": os.nice(0)},
               "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
               "wall_s": time.perf_counter() - t0, "cpu_s": _cpu_seconds() - cpu0,
               "summary": summarise(results), "results": results}
        _store(args, doc)
    if args.label:
        print(json.dumps(doc.get("summary", {}), indent=1, default=float))
        print(f"wrote labelled[{args.label!r}] of {args.out}")
        return 0
    buf = io.StringIO()
    w = csv.DictWriter(buf, FIELDS)
    w.writeheader()
    w.writerows(row for r in results for row in _rows(r))
    with atomic_write(args.out.with_suffix(".csv"), "w") as fh:
        fh.write(buf.getvalue())
    print(json.dumps(doc.get("summary", {}), indent=1, default=float))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
