"""Engine-aware glTF parameters, measured on the engine models (no engine, no Monte Carlo).

Per material (MERL Neural-BRDF stand-ins and the RGL files, ``ggx-diffuse`` fits): the glTF
parameters of the rules (``optimize=False``), of :func:`brdffit.export.gltf.optimize_for_engines`
(``optimize="engines"``) and of the same for one engine alone (``"blender"``, ``"threejs"``: the
best the optimiser finds for that engine by its model, how far one glTF file can take it), each rendered in ``sphere-distant`` (128², noise-free,
:func:`brdffit.evaluation.engines.threejs_brdf.shade_sphere`) through the specification's BRDF,
the model of Blender (:class:`brdffit.export.gltf_cycles.CyclesPrincipledBRDF`, multiscatter GGX)
and the model of three.js (:class:`brdffit.evaluation.engines.threejs_brdf.ThreeJSBRDF` with
three's own DFG table and per-pixel geometry roughness, 8 × 8 samples per pixel), against the fit
converged (16 × 16): PSNR, per-channel mean ratio and rim ratio (r > 0.85 R). The real engines
are measured by ``bench_engines.py`` / ``bench_engines_threejs.py`` (``--optimize engines``).

Run: ``.venv/bin/python bench/bench_engines_params.py [--materials a,b]``; writes
``bench/results/engines_params.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from _common import NBRDF, RGL_DIR, ROOT, engine_render, use_project_sources  # bench/ is on sys.path

use_project_sources()
DEFAULT = ("ss440,gold-metallic-paint,maroon-plastic,white-paint,chrome-steel,blue-metallic-paint,"
           "red-plastic,alum-bronze,acrylic_felt_green,cc_ibiza_sunset,cc_iris_purple_gem,chm_mint,"
           "colodur_napoli_4f,ilm_l3_37_matte,paper_white")
#: the parameter sets compared: the rules, the exporter's option for both engines, and the
#: same for one engine alone (the best the optimiser finds for that engine: how far a single
#: glTF file can take it, by its model)
LABELS = (("rule", False), ("engines", "engines"), ("blender_only", "blender"),
          ("threejs_only", "threejs"))


def _spec(name: str) -> str:
    rgl = RGL_DIR / f"{name}_rgb.bsdf"
    return str(rgl) if rgl.is_file() else f"{NBRDF}:{name}"


def bench_material(name: str, res: int) -> dict:
    import brdffit
    from brdffit.evaluation.engines import threejs_brdf as TB
    from brdffit.evaluation.engines.threejs import sphere_geometry_px
    from brdffit.evaluation.metrics import rendered_psnr
    from brdffit.export.gltf import _refine, gltf_parameters

    fit = brdffit.fit(brdffit.load(_spec(name)), model="ggx-diffuse")
    ref, ra = TB.shade_sphere(fit, resolution=res, supersample=16, geometry_roughness=False)
    cx, cy, R = sphere_geometry_px(res)
    yy, xx = np.mgrid[0:res, 0:res] + 0.5
    out = {"material": name}
    for label, opt in LABELS:
        t = time.process_time()
        p = _refine(fit, gltf_parameters(fit), opt)
        row = {"cpu_seconds": time.process_time() - t, "baseColorFactor": p["baseColorFactor"][:3],
               "specular": p.get("specular"), "metallic": p["metallicFactor"],
               "roughness": p["roughnessFactor"], "notes": p["notes"][-1:]}
        for engine in ("specification", "blender", "threejs"):
            img, a = engine_render(p, engine, res)
            m = (a >= 0.999) & (ra >= 0.999)
            rim = m & (np.hypot(xx - cx, yy - cy) > 0.85 * R)
            row[engine] = {"psnr": rendered_psnr(ref, img, m),
                           "mean_ratio": (img[m].sum(0) / ref[m].sum(0)).tolist(),
                           "rim_ratio": (img[rim].sum(0) / ref[rim].sum(0)).tolist()}
        out[label] = row
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--materials", default=DEFAULT)
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "engines_params.json")
    args = ap.parse_args(argv)
    from brdffit._atomic import atomic_write

    rows, load0 = [], list(os.getloadavg())
    for name in args.materials.split(","):
        r = bench_material(name, args.res)
        rows.append(r)
        cells = " | ".join(label + " " + " ".join(f"{r[label][e]['psnr']:6.2f}" for e in
                                                  ("specification", "blender", "threejs"))
                           for label, _ in LABELS)
        print(f"{name:22s} spec/blender/three dB: {cells} | engines "
              f"{r['engines']['cpu_seconds']:.1f} s CPU", flush=True)
    summary = {}
    for label, _ in LABELS:
        summary[label] = {e: {"psnr_mean": float(np.mean([r[label][e]["psnr"] for r in rows])),
                              "psnr_min": float(np.min([r[label][e]["psnr"] for r in rows]))}
                          for e in ("specification", "blender", "threejs")}
    summary["engines"]["cpu_seconds_mean"] = float(np.mean([r["engines"]["cpu_seconds"]
                                                             for r in rows]))
    doc = {"command": "bench/bench_engines_params.py " + " ".join(argv or sys.argv[1:]),
           "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "resolution": args.res,
           "load_average_start": load0, "load_average_end": list(os.getloadavg()),
           "summary": summary, "materials": rows}
    with atomic_write(args.out, "w") as fh:
        fh.write(json.dumps(doc, indent=1, default=float) + "\n")
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
