"""Benchmark of the analytic fits with a diffuse lobe.

Run: ``.venv/bin/python bench/bench_analytic.py`` (``--materials a,b,...`` to choose the
Neural-BRDF MERL materials, ``--no-validator`` to skip the Khronos glTF-Validator). Writes
``bench/results/analytic.json`` (atomically) and prints a table.

* ``synthetic``: parameter recovery of ``beckmann-diffuse`` on ``synthetic:plastic-beckmann``
  (truth Beckmann α 0.18, dielectric η 1.5, ρd (0.45, 0.06, 0.04)) and of ``ggx-diffuse`` on
  ``gold-ggx`` / ``aniso-ggx``; cosine-weighted relative error (BRDF space,
  :func:`brdffit.evaluation.metrics.brdf_metrics`) against the truth, and that of the
  moment-conversion fits (``beckmann`` / ``ggx``, Dupuy 2015 App. C).
* ``real``: per Neural-BRDF MERL material, for ``ggx`` (moment conversion + tabulated
  Fresnel) and ``ggx-diffuse``: the compressive objective of Bagher 2016 (Eq. 7-12, full
  MERL grid, normalised by the all-zero model's), the cosine-weighted relative error vs the
  reference, the fit time (wall and CPU); for the ``ggx-diffuse`` fit its glTF and MaterialX
  exports: the error of the engine-equivalent BRDF (:class:`~brdffit.export.gltf.GLTFBRDF`,
  :class:`~brdffit.export.materialx.OpenPBRBRDF`) against the reference and against the fit,
  the glTF-Validator's error/warning counts and MaterialX ``validate()``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

import brdffit  # noqa: E402
from brdffit._atomic import atomic_write  # noqa: E402
from brdffit.evaluation.metrics import brdf_metrics  # noqa: E402
from brdffit.export import export  # noqa: E402
from brdffit.export.gltf import gltf_equivalent  # noqa: E402
from brdffit.export.materialx import openpbr_equivalent, validate_document  # noqa: E402
from brdffit.fit.analytic import fit_beckmann_diffuse, fit_ggx_diffuse  # noqa: E402
from brdffit.losses.objective import compressive_objective  # noqa: E402

MATERIALS = ("white-paint", "red-specular-plastic", "specular-black-phenolic", "blue-rubber",
             "gold-metallic-paint", "brass", "chrome-steel", "aluminium", "blue-fabric",
             "violet-acrylic")
N = 1 << 15
VALIDATE_JS = r"""
const fs = require('fs');
const validator = require(process.argv[2]);
validator.validateBytes(new Uint8Array(fs.readFileSync(process.argv[3])), {maxIssues: 1000})
  .then((r) => process.stdout.write(JSON.stringify(r)))
  .catch((e) => { process.stderr.write(String(e)); process.exit(2); });
"""


def err(ref, test):
    return float(brdf_metrics(ref, test, N, metrics=("cos_rel_error",))["cos_rel_error"])


def timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def validator():
    pkg = ROOT / ".npm" / "node_modules" / "gltf-validator"
    node = shutil.which("node")
    if node is None or not (pkg / "package.json").is_file():
        return None
    script = Path(tempfile.mkdtemp()) / "v.js"
    script.write_text(VALIDATE_JS)

    def run(path):
        r = subprocess.run([node, str(script), str(pkg), str(path)], capture_output=True,
                           text=True, timeout=120)
        rep = json.loads(r.stdout)["issues"]
        return {"errors": rep["numErrors"], "warnings": rep["numWarnings"],
                "infos": rep["numInfos"]}
    return run


def exports(fit, ref, tmp: Path, validate_gltf) -> dict:
    out = {}
    g, gw, gc = timed(lambda: export(fit, "gltf", tmp / "m.gltf", fidelity=False))
    eq = gltf_equivalent(fit)
    out["gltf"] = {"material": g["material"], "extensions": g["extensions"],
                   "cos_rel_error_vs_reference": err(ref, eq), "cos_rel_error_vs_fit": err(fit, eq),
                   "cos_rel_error_core_only_vs_fit": err(fit, gltf_equivalent(fit, specular=False)),
                   "time_s": gw, "cpu_s": gc}
    if validate_gltf is not None:
        out["gltf"]["validator"] = validate_gltf(tmp / "m.gltf")
    m, mw, mc = timed(lambda: export(fit, "materialx", tmp / "m.mtlx", fidelity=False))
    import MaterialX as mx

    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(tmp / "m.mtlx"))
    ok, msg = validate_document(doc)
    eqx = openpbr_equivalent(fit)
    out["materialx"] = {"parameters": m["parameters"], "validate": bool(ok),
                        "validate_message": msg.strip()[:200],
                        "cos_rel_error_vs_reference": err(ref, eqx),
                        "cos_rel_error_vs_fit": err(fit, eqx), "time_s": mw, "cpu_s": mc}
    return out


def synthetic_section(tmp, validate_gltf) -> dict:
    out = {}
    cases = (("plastic-beckmann", fit_beckmann_diffuse, brdffit.fit_beckmann, "beckmann"),
             ("gold-ggx", fit_ggx_diffuse, brdffit.fit_ggx, "ggx"),
             ("aniso-ggx", fit_ggx_diffuse, brdffit.fit_ggx, "ggx"))
    for name, fn, moments_fn, mname in cases:
        ref = brdffit.synthetic(name)
        fit, w, c = timed(lambda: fn(ref))
        mom, mw, mc = timed(lambda: moments_fn(ref))
        d = fit.distribution
        info = fit.fit_info
        out[name] = {"truth": ref.describe() if hasattr(ref, "describe") else None,
                     "fit": {"alpha": [d.alpha_x, d.alpha_y, d.rho], "fresnel": info["fresnel"],
                             "eta": info["eta"], "rho_d": info["rho_d"], "F0": info["F0"],
                             "ks": info["ks"], "time_s": w, "cpu_s": c,
                             "cos_rel_error": err(ref, fit)},
                     mname: {"alpha": [mom.distribution.alpha_x, mom.distribution.alpha_y,
                                       mom.distribution.rho], "time_s": mw, "cpu_s": mc,
                             "cos_rel_error": err(ref, mom)},
                     "exports": exports(fit, ref, tmp, validate_gltf)}
        print(f"{name:18s} {fn.__name__}: alpha={np.round([d.alpha_x, d.alpha_y, d.rho], 5).tolist()} "
              f"{info['fresnel']} eta={info['eta']} rho_d={np.round(info['rho_d'], 4).tolist()} "
              f"F0={np.round(info['F0'], 4).tolist()} err={out[name]['fit']['cos_rel_error']:.3g} "
              f"(moments {mname}: {out[name][mname]['cos_rel_error']:.3g}) cpu={c:.2f}s", flush=True)
    return out


def real_section(materials, tmp, validate_gltf) -> dict:
    out = {}
    for name in materials:
        ref = brdffit.load(f"merl_nbrdf.zip:{name}")
        row = {}
        for label, fn in (("ggx", brdffit.fit_ggx), ("ggx-diffuse", fit_ggx_diffuse)):
            fit, w, c = timed(lambda: fn(ref))
            row[label] = {"objective_normalised": compressive_objective(fit, ref)["normalised"],
                          "cos_rel_error": err(ref, fit), "time_s": w, "cpu_s": c}
            if label == "ggx-diffuse":
                i = fit.fit_info
                row[label].update({k: i[k] for k in ("fresnel", "eta", "rho_d", "F0", "ks")},
                                  alpha=i["alpha_x"])
                row["exports"] = exports(fit, ref, tmp, validate_gltf)
        out[name] = row
        g, d, e = row["ggx"], row["ggx-diffuse"], row["exports"]
        print(f"{name:24s} objective ggx {g['objective_normalised']:8.4g} -> {d['objective_normalised']:8.4g}"
              f" | cos-rel ggx {g['cos_rel_error']:.3f} -> {d['cos_rel_error']:.3f}"
              f" | glTF {e['gltf']['cos_rel_error_vs_reference']:.3f} (vs fit {e['gltf']['cos_rel_error_vs_fit']:.3f})"
              f" | mtlx {e['materialx']['cos_rel_error_vs_reference']:.3f} (vs fit {e['materialx']['cos_rel_error_vs_fit']:.3f})"
              f" | t {d['time_s']:.2f}s cpu {d['cpu_s']:.2f}s", flush=True)
    return out


def summary(real) -> dict:
    def col(f):
        return np.array([f(r) for r in real.values()], float)

    s = {}
    for label in ("ggx", "ggx-diffuse"):
        s[label] = {k: {"mean": float(col(lambda r: r[label][k]).mean()),
                        "median": float(np.median(col(lambda r: r[label][k])))}
                    for k in ("objective_normalised", "cos_rel_error", "time_s", "cpu_s")}
    for tgt in ("gltf", "materialx"):
        s[tgt] = {k: {"mean": float(col(lambda r: r["exports"][tgt][k]).mean()),
                      "worst": float(col(lambda r: r["exports"][tgt][k]).max())}
                  for k in ("cos_rel_error_vs_reference", "cos_rel_error_vs_fit")}
    s["gltf"]["validator_errors_total"] = int(sum(
        r["exports"]["gltf"].get("validator", {}).get("errors", 0) for r in real.values()))
    s["materialx"]["validate_all"] = all(r["exports"]["materialx"]["validate"] for r in real.values())
    s["wins_objective"] = int(sum(r["ggx-diffuse"]["objective_normalised"]
                                  < r["ggx"]["objective_normalised"] for r in real.values()))
    s["wins_cos_rel_error"] = int(sum(r["ggx-diffuse"]["cos_rel_error"] < r["ggx"]["cos_rel_error"]
                                      for r in real.values()))
    return s


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--materials", default=",".join(MATERIALS))
    ap.add_argument("--no-validator", action="store_true")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "analytic.json"))
    a = ap.parse_args(argv)
    validate_gltf = None if a.no_validator else validator()
    tmp = Path(tempfile.mkdtemp())
    t0 = time.perf_counter()
    res = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                       "load_average_start": list(os.getloadavg())},
           "n_direction_pairs": N, "gltf_validator": validate_gltf is not None}
    res["synthetic"] = synthetic_section(tmp, validate_gltf)
    materials = [m for m in a.materials.split(",") if m]
    res["real"] = real_section(materials, tmp, validate_gltf) if materials else {}
    if res["real"]:
        res["summary"] = summary(res["real"])
        print(json.dumps(res["summary"], indent=1))
    res["machine"]["load_average_end"] = list(os.getloadavg())
    res["wall_s"] = time.perf_counter() - t0
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(a.out, "w") as fh:
        json.dump(res, fh, indent=1, default=float)
    print(f"wrote {a.out} ({res['wall_s']:.0f} s)")


if __name__ == "__main__":
    main()
