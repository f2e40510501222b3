"""Export benchmark: loss of fidelity of the glTF material of GGX fits, error of the
Mitsuba built-in mapping, GLSL/RGL resampling errors and export timings.

Run: ``.venv/bin/python bench/bench_export.py`` (synthetic materials), ``--real`` to add a few
Neural-BRDF MERL materials (``../shared/data/nbrdf/merl_nbrdf.zip``), ``--render`` to add the
rendered PSNR (Bagher 2016 §5) of the glTF-equivalent vs the fit (Mitsuba, sphere under the
procedural environment; ``--spp``/``--res``). Writes ``bench/results/export.json``
(atomically) and prints a table.

Per material (the GGX fit ``fit_ggx`` of the material is the reference of the export):

* ``gltf``: glTF parameters and BRDF-space metrics of :class:`GLTFBRDF` vs the fit
  (``cos_rel_error``, ``normalized_l2``) and vs the original material, for the rule-based
  parameters and the BRDF-space optimised ones (``optimize=True``); with ``--render`` the
  rendered PSNR vs the fit (same seed) and the fit's noise floor (two seeds);
* ``mitsuba``: cosine-weighted relative error of the built-in mapping (roughconductor +
  diffuse, conductor Fresnel fit, uncorrelated G) vs the fit;
* ``glsl``: max / median relative error of the GLSL NumPy twin vs the fit's eval (and the
  max with both directions below 89°: the tabulated path's linear σ is least accurate at
  grazing);
* ``rgl``: read-back error of the RGL-style file of the *tabulated* fit;
* timings of every step (wall and CPU; shared 2-core machine: re-run to update).
"""

from __future__ import annotations

import argparse
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
sys.path.insert(0, str(ROOT))  # tests.support: the test kit
os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")

NBRDF = ROOT.parent / "shared" / "data" / "nbrdf" / "merl_nbrdf.zip"
REAL = ["gold-metallic-paint", "chrome-steel", "blue-metallic-paint", "white-paint",
        "red-plastic"]


class Timer:
    def __init__(self):
        self.t, self.c = time.perf_counter(), time.process_time()

    def done(self) -> dict:
        return {"wall_s": round(time.perf_counter() - self.t, 3),
                "cpu_s": round(time.process_time() - self.c, 3)}


def _pairs(n=20000, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2 * n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    return v[:n], v[n:]


def bench_material(name, brdf, args) -> dict:
    import brdffit
    from brdffit.evaluation.metrics import brdf_metrics
    from brdffit.export import glsl, gltf, mitsuba, rgl
    from tests.support import glsl_cpu
    from brdffit.microfacet.conversions import to_ggx

    out: dict = {"material": name, "timings": {}}
    t = Timer()
    tab = brdffit.fit_tabulated(brdf)
    out["timings"]["fit_tabulated"] = t.done()
    fit = to_ggx(tab)
    d = fit.distribution
    out["ggx_fit"] = {"alpha_x": d.alpha_x, "alpha_y": d.alpha_y, "rho": d.rho,
                      "F0": np.asarray(fit.fresnel.eval(1.0)).tolist()}
    # glTF
    t = Timer()
    p = gltf.gltf_parameters(fit)
    eq = gltf.gltf_equivalent(fit)
    out["gltf"] = {"params": {k: p[k] for k in ("baseColorFactor", "metallicFactor",
                                                 "roughnessFactor", "alpha")},
                   "notes": p["notes"],
                   "vs_fit": brdf_metrics(fit, eq, 1 << 15, metrics=("cos_rel_error",
                                                                      "normalized_l2")),
                   "fit_vs_material": brdf_metrics(brdf, fit, 1 << 15,
                                                   metrics=("cos_rel_error", "normalized_l2")),
                   "gltf_vs_material": brdf_metrics(brdf, eq, 1 << 15,
                                                    metrics=("cos_rel_error", "normalized_l2"))}
    eq_opt = gltf.gltf_equivalent(fit, optimize=True)
    out["gltf"]["optimized_vs_fit"] = brdf_metrics(fit, eq_opt, 1 << 15,
                                                   metrics=("cos_rel_error", "normalized_l2"))
    out["gltf"]["optimized_params"] = {"baseColor": eq_opt.base_color.tolist(),
                                       "metallic": eq_opt.metallic,
                                       "roughness": eq_opt.roughness}
    for k in ("vs_fit", "fit_vs_material", "gltf_vs_material", "optimized_vs_fit"):
        out["gltf"][k] = {m: out["gltf"][k].get(m) for m in ("cos_rel_error", "normalized_l2")}
    out["timings"]["gltf"] = t.done()
    if args.render:
        from brdffit.evaluation.render import psnr, render_ex

        t = Timer()
        target = eq.as_microfacet() or eq
        a = render_ex(fit, spp=args.spp, resolution=args.res, seed=0)
        b = render_ex(target, spp=args.spp, resolution=args.res, seed=0)
        c = render_ex(fit, spp=args.spp, resolution=args.res, seed=1)
        o = render_ex(eq_opt.as_microfacet() or eq_opt, spp=args.spp, resolution=args.res, seed=0)
        out["gltf"]["render"] = {"psnr_gltf_vs_fit": psnr(a.image, b.image, a.mask),
                                 "psnr_gltf_optimized_vs_fit": psnr(a.image, o.image, a.mask),
                                 "noise_floor_psnr": psnr(a.image, c.image, a.mask),
                                 "spp": args.spp, "resolution": args.res}
        out["timings"]["render"] = t.done()
    # Mitsuba built-in mapping
    t = Timer()
    bsdf, info = mitsuba.builtin_bsdf(fit)
    out["mitsuba"] = {"error": mitsuba.mitsuba_error(fit), "notes": info["notes"],
                      "fresnel_max_abs": [f["max_abs"] for f in info["fresnel_fits"]]}
    out["timings"]["mitsuba"] = t.done()
    # GLSL twin
    t = Timer()
    wi, wo = _pairs()
    for label, model in (("ggx", fit), ("tabulated", tab)):
        try:
            spec = glsl.model_spec(model)
        except Exception as exc:  # noqa: BLE001 - e.g. anisotropic tables have no GLSL path
            out.setdefault("glsl", {})[label] = {"unsupported": str(exc)}
            continue
        ref = model.eval(wi, wo)
        got = glsl_cpu.eval_spec(spec, wi, wo)
        ok = ref > 1e-6 * ref.max()
        rel = np.abs(got - ref)[ok] / ref[ok]
        below = ok & (np.minimum(wi[:, 2], wo[:, 2]) > np.cos(np.radians(89.0)))[:, None]
        out.setdefault("glsl", {})[label] = {
            "max_rel": float(rel.max()), "median_rel": float(np.median(rel)),
            "max_rel_below_89deg": float((np.abs(got - ref)[below] / ref[below]).max())}
    out["timings"]["glsl"] = t.done()
    # RGL of the tabulated fit
    if getattr(tab, "isotropic", False):
        t = Timer()
        with tempfile.TemporaryDirectory() as tmp:
            out["rgl"] = rgl.export_rgl(tab, Path(tmp) / "x.bsdf")["error"]
        out["timings"]["rgl"] = t.done()
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real", action="store_true", help="add Neural-BRDF MERL materials")
    ap.add_argument("--render", action="store_true", help="add rendered PSNR (Mitsuba)")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "export.json")
    args = ap.parse_args(argv)

    import brdffit
    from brdffit._atomic import atomic_write

    mats = [(n, brdffit.synthetic(n)) for n in ("gold-ggx", "aniso-ggx", "plastic-beckmann",
                                                "sgd-paint", "two-lobe-ggx")]
    if args.real:
        if NBRDF.is_file():
            from brdffit.io import load

            mats += [(n, load(f"{NBRDF}:{n}")) for n in REAL]
        else:
            print(f"--real: {NBRDF} absent, skipped")
    results = []
    for name, brdf in mats:
        t = Timer()
        try:
            r = bench_material(name, brdf, args)
        except Exception as exc:  # noqa: BLE001 - keep benchmarking the others
            r = {"material": name, "error": f"{type(exc).__name__}: {exc}"}
        r["total"] = t.done()
        results.append(r)
        g = r.get("gltf", {})
        print(f"{name:22s} glTF vs fit cos_rel={g.get('vs_fit', {}).get('cos_rel_error', float('nan')):.4f} "
              f"(opt {g.get('optimized_vs_fit', {}).get('cos_rel_error', float('nan')):.4f}) "
              f"L2={g.get('vs_fit', {}).get('normalized_l2', float('nan')) or float('nan'):.4f} "
              f"| fit vs mat cos_rel={g.get('fit_vs_material', {}).get('cos_rel_error', float('nan')):.4f} "
              f"| mitsuba cos_rel={r.get('mitsuba', {}).get('error', {}).get('cos_rel_error', float('nan')):.4f} "
              f"| glsl max_rel ggx={r.get('glsl', {}).get('ggx', {}).get('max_rel', float('nan')):.2e} "
              f"tab={r.get('glsl', {}).get('tabulated', {}).get('max_rel', float('nan')):.2e} "
              f"| rgl={r.get('rgl', {}).get('cos_rel_error', float('nan')):.4f} "
              f"| psnr={g.get('render', {}).get('psnr_gltf_vs_fit', float('nan')):.2f} "
              f"opt={g.get('render', {}).get('psnr_gltf_optimized_vs_fit', float('nan')):.2f} "
              f"(floor {g.get('render', {}).get('noise_floor_psnr', float('nan')):.2f}) "
              f"| {r['total']['wall_s']:.1f}s" + (f" ERROR {r['error']}" if "error" in r else ""))
    doc = {"benchmark": "export", "command": " ".join([sys.executable] + sys.argv),
           "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                       "load_average": list(os.getloadavg())},
           "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "results": results}
    with atomic_write(args.out, "w") as fh:
        json.dump(doc, fh, indent=1, default=float)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
