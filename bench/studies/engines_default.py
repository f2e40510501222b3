"""The cross-engine default question of issue 34: should the glTF export's default be the
rules (the specification), ``optimize="engines"`` (Blender's and three's models), or the same
optimiser over all three renderers (specification, Blender, three.js)? Per material (the 15
of ``bench_engines_params.py``, ggx-diffuse fits) each parameter set rendered in
``sphere-distant`` (96², noise-free) through the specification's BRDF and the models of
Blender and three.js against the fit converged, with the optimiser's CPU time, at its default
resolution (48²) and at 32².

    PYTHONPATH=src .venv/bin/python bench/studies/engines_default.py

Writes ``bench/results/engines_default.json`` (per material and variant: CPU, PSNR per
renderer; per variant the mean and lowest; load average).
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "bench"))  # _common
from _common import NBRDF, RGL_DIR, engine_render  # noqa: E402

MATERIALS = ("ss440,gold-metallic-paint,maroon-plastic,white-paint,chrome-steel,"
             "blue-metallic-paint,red-plastic,alum-bronze,acrylic_felt_green,cc_ibiza_sunset,"
             "cc_iris_purple_gem,chm_mint,colodur_napoli_4f,ilm_l3_37_matte,paper_white").split(",")
RENDERERS = ("specification", "blender", "threejs")
ALL3 = ("specification", "blender", "threejs")
VARIANTS = (("rule", None, None), ("engines48", ("blender", "threejs"), 48),
            ("all3_48", ALL3, 48), ("engines32", ("blender", "threejs"), 32),
            ("all3_32", ALL3, 32))
RES = 96


def _spec(name: str) -> str:
    rgl = RGL_DIR / f"{name}_rgb.bsdf"
    return str(rgl) if rgl.is_file() else f"{NBRDF}:{name}"


def bench_material(name: str) -> dict:
    import brdffit
    from brdffit.evaluation.engines import threejs_brdf as TB
    from brdffit.evaluation.metrics import rendered_psnr
    from brdffit.export.gltf import gltf_parameters, optimize_for_engines

    fit = brdffit.fit(brdffit.load(_spec(name)), model="ggx-diffuse")
    ref, ra = TB.shade_sphere(fit, resolution=RES, supersample=16, geometry_roughness=False)
    p0 = gltf_parameters(fit)
    row = {"material": name}
    for label, engines, res in VARIANTS:
        t = time.process_time()
        p = p0 if engines is None else optimize_for_engines(fit, p0, engines=engines,
                                                            resolution=res)
        cpu = time.process_time() - t
        psnr = []
        for e in RENDERERS:
            img, a = engine_render(p, e, RES)
            psnr.append(rendered_psnr(ref, img, (a >= 0.999) & (ra >= 0.999)))
        row[label] = {"cpu_seconds": cpu, "psnr": dict(zip(RENDERERS, psnr))}
    return row


def summarise(rows: list[dict]) -> dict:
    out = {}
    for label, _, _ in VARIANTS:
        P = np.array([[r[label]["psnr"][e] for e in RENDERERS] for r in rows])
        out[label] = {"cpu_seconds_mean": float(np.mean([r[label]["cpu_seconds"] for r in rows])),
                      "psnr_mean": dict(zip(RENDERERS, P.mean(0).tolist())),
                      "psnr_min": dict(zip(RENDERERS, P.min(0).tolist()))}
    return out


def main() -> int:
    from brdffit._atomic import atomic_write

    load0 = list(os.getloadavg())
    rows = []
    for name in MATERIALS:
        rows.append(bench_material(name))
        print(name, {k: (round(v["cpu_seconds"], 2), [round(x, 1) for x in v["psnr"].values()])
                     for k, v in rows[-1].items() if k != "material"}, flush=True)
    doc = {"benchmark": "engines_default", "resolution": RES, "variants": [v[0] for v in VARIANTS],
           "summary": summarise(rows), "results": rows,
           "load_average": [load0, list(os.getloadavg())]}
    with atomic_write(ROOT / "bench" / "results" / "engines_default.json", "w") as fh:
        json.dump(doc, fh, indent=1, default=float)
    print(json.dumps(doc["summary"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
