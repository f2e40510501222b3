"""Export fidelity per target over the Neural-BRDF MERL materials.

For every material: the ``ggx-diffuse`` fit with the product's defaults is the reference;
each export target's *equivalent* BRDF — what the target's renderer evaluates for the
exported parameters — is compared with it:

* ``gltf``: :func:`brdffit.export.gltf.gltf_equivalent` (glTF 2.0 metal/rough + KHR
  extensions: Schlick with F0 = base colour, separable Smith G);
* ``materialx``: :func:`brdffit.export.materialx.openpbr_equivalent` (OpenPBR surface as
  MaterialX's GLSL evaluates it, energy compensation included);
* ``mitsuba-xml``: :func:`brdffit.export.mitsuba.mitsuba_equivalent` (``roughconductor`` +
  ``diffuse`` in a ``blendbsdf``, fitted conductor Fresnel, uncorrelated G1 G1).

Figures per target: the cosine-weighted relative error in BRDF space (2¹⁵ fixed direction
pairs, :func:`brdffit.evaluation.metrics.brdf_metrics`) and, rendered with common random
numbers against the fit (:func:`brdffit.evaluation.compare.compare`, one scene of the paper's
suite, default ``sphere-courtyard`` 128², 64 spp in 8 batches), the PSNR ± standard error and
the mean dE2000 of the tone-mapped images; mean / median / worst over the materials. The fit
time of each ``ggx-diffuse`` fit (CPU) is recorded too.

Writes ``bench/results/export_fidelity.csv`` (one row per material and target, appended as it
goes: a cut run resumes with ``--resume``) and ``export_fidelity.json`` (aggregates, the load
average before and after)::

    .venv/bin/python bench/studies/export_fidelity.py [--limit N] [--resume]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "src"))
os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")

RESULTS = ROOT / "bench" / "results"
TARGETS = ("gltf", "materialx", "mitsuba-xml")
FIELDS = ("material", "target", "cos_rel_error", "psnr_db", "psnr_se_db", "mean_de2000",
          "fit_cpu_s", "fit_fresnel", "fit_alpha")


def equivalents(fit, ablation: bool = False, optimized: bool = False) -> dict:
    """The equivalent BRDF of each target; with ``ablation`` also glTF and MaterialX with the
    dielectric base colour = ρd (``-uncompensated``: before the base was divided by the
    fraction the specular layer lets through); with ``optimized`` glTF with
    ``optimize=True`` (``gltf-optimized``)."""
    import copy

    from brdffit.export.gltf import _brdf_of, gltf_equivalent, gltf_parameters
    from brdffit.export.materialx import openpbr_equivalent
    from brdffit.export.mitsuba import mitsuba_equivalent

    eqs = {"gltf": gltf_equivalent(fit), "materialx": openpbr_equivalent(fit),
           "mitsuba-xml": mitsuba_equivalent(fit)}
    if optimized:
        eqs["gltf-optimized"] = gltf_equivalent(fit, optimize=True)
    if ablation:
        g = gltf_parameters(fit)
        if g["metallicFactor"] == 0.0:
            g = dict(g, baseColorFactor=np.clip(g["rho_d"], 0, 1).tolist() + [1.0])
        eqs["gltf-uncompensated"] = _brdf_of(g, name="gltf-uncompensated")
        m = copy.copy(eqs["materialx"])
        if m.base_metalness == 0.0:
            m.base_color = np.clip(np.zeros(3) if fit.diffuse is None else fit.diffuse, 0, 1)
        m.name = "materialx-uncompensated"
        eqs["materialx-uncompensated"] = m
    return eqs


def measure(name: str, spec: str, args) -> list[dict]:
    import brdffit
    from brdffit.evaluation.compare import compare
    from brdffit.evaluation.metrics import brdf_metrics

    ref = brdffit.load(spec)
    c0 = time.process_time()
    fit = brdffit.fit(ref, model="ggx-diffuse")
    fit_cpu = time.process_time() - c0
    eqs = equivalents(fit, args.ablation, args.optimized)
    if args.targets:
        eqs = {k: v for k, v in eqs.items() if k in set(args.targets.split(","))}
    with tempfile.TemporaryDirectory() as tmp:
        res = compare(fit, eqs, tmp, name=name, scenes=args.scenes, spp=args.spp,
                      batches=args.batches, resolution=args.res, save_fits=False,
                      update_index=False, brdf_metrics=())
    rendered = {m["name"]: m for m in res["models"]}
    rows = []
    for target, eq in eqs.items():
        cre = brdf_metrics(fit, eq, 1 << 15, metrics=("cos_rel_error",))["cos_rel_error"]
        r = rendered.get(target, {})
        rows.append({"material": name, "target": target, "cos_rel_error": cre,
                     "psnr_db": r.get("psnr"), "psnr_se_db": r.get("psnr_se"),
                     "mean_de2000": r.get("mean_de2000"), "fit_cpu_s": fit_cpu,
                     "fit_fresnel": fit.fit_info.get("fresnel"),
                     "fit_alpha": fit.fit_info.get("alpha_x")})
    return rows


def _stats(values) -> dict:
    v = np.array([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    if not v.size:
        return {"n": 0}
    return {"n": int(v.size), "mean": float(v.mean()), "median": float(np.median(v)),
            "min": float(v.min()), "max": float(v.max())}


def summarise(rows: list[dict]) -> dict:
    out = {}
    targets = list(dict.fromkeys(r["target"] for r in rows))
    for t in targets:
        sel = [r for r in rows if r["target"] == t]
        worst = max(sel, key=lambda r: float(r["cos_rel_error"]), default=None)
        out[t] = {"cos_rel_error": _stats(float(r["cos_rel_error"]) for r in sel),
                  "psnr_db": _stats(_num(r["psnr_db"]) for r in sel),
                  "psnr_se_db": _stats(_num(r["psnr_se_db"]) for r in sel),
                  "mean_de2000": _stats(_num(r["mean_de2000"]) for r in sel),
                  "worst_cos_rel_error_material": None if worst is None else worst["material"]}
    for t in TARGETS:           # paired (common random numbers): compensated − ρd base
        if f"{t}-uncompensated" not in targets:
            continue
        by = {(r["material"], r["target"]): _num(r["psnr_db"]) for r in rows}
        d = np.array([by[(m, t)] - by[(m, f"{t}-uncompensated")]
                      for m in {r["material"] for r in rows}
                      if by.get((m, t)) is not None
                      and by.get((m, f"{t}-uncompensated")) is not None])
        out[f"{t}_psnr_gain_of_compensation_db"] = {
            "n": int(d.size), "mean": float(d.mean()) if d.size else None,
            "se": float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 else None,
            "min": float(d.min()) if d.size else None, "max": float(d.max()) if d.size else None,
            "improved": int(np.sum(d > 0)), "unchanged": int(np.sum(d == 0))}
    fits = {r["material"]: _num(r["fit_cpu_s"]) for r in rows}
    out["ggx_diffuse_fit_cpu_s"] = _stats(fits.values())
    return out


def _num(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return None


def main(argv=None) -> int:
    from brdffit.batch import enumerate_materials

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--limit", type=int, default=0, help="first N materials (0: all 100)")
    ap.add_argument("--every", type=int, default=1, help="every k-th material")
    ap.add_argument("--scenes", default="sphere-courtyard")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--batches", type=int, default=8)
    ap.add_argument("--resume", action="store_true", help="keep the rows of the CSV")
    ap.add_argument("--name", default="export_fidelity", help="results file stem")
    ap.add_argument("--optimized", action="store_true",
                    help="also render glTF with --option optimize=true")
    ap.add_argument("--only", default="", help="comma-separated material names")
    ap.add_argument("--targets", default="", help="render only these (comma-separated)")
    ap.add_argument("--ablation", action="store_true",
                    help="also render glTF/MaterialX with base colour = ρd (uncompensated)")
    args = ap.parse_args(argv)

    mats = enumerate_materials("merl_nbrdf.zip")[::max(args.every, 1)]
    if args.only:
        mats = [m for m in mats if m[0] in set(args.only.split(","))]
    if args.limit:
        mats = mats[:args.limit]
    csv_path, json_path = RESULTS / f"{args.name}.csv", RESULTS / f"{args.name}.json"
    rows: list[dict] = []
    if args.resume and csv_path.is_file():
        with open(csv_path, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    done = {r["material"] for r in rows}
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    mode = "a" if args.resume and csv_path.is_file() else "w"
    with open(csv_path, mode, newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, FIELDS)
        if mode == "w":
            writer.writeheader()
        for i, (name, spec) in enumerate(mats):
            if name in done:
                continue
            try:
                new = measure(name, spec, args)
            except Exception as exc:  # noqa: BLE001 – reported, the run goes on
                print(f"{name}: failed: {type(exc).__name__}: {exc}", flush=True)
                continue
            for r in new:
                writer.writerow({k: r.get(k) for k in FIELDS})
            fh.flush()
            rows += new
            print(f"[{i + 1}/{len(mats)}] {name}: " + "; ".join(
                f"{r['target']} cre {r['cos_rel_error']:.4f} PSNR {r['psnr_db']:.1f}"
                f"±{r['psnr_se_db']:.2f} dE {r['mean_de2000']:.2f}" for r in new), flush=True)
    summary = {"benchmark": "export fidelity per target vs the ggx-diffuse fit",
               "protocol": f"ggx-diffuse product defaults; equivalents of gltf/materialx/"
                           f"mitsuba-xml; BRDF-space cos-weighted relative error (2^15 fixed "
                           f"pairs); CRN render {args.scenes} {args.res}² {args.spp} spp in "
                           f"{args.batches} batches, PSNR ± se, mean dE2000",
               "n_materials": len({r["material"] for r in rows}),
               "per_target": summarise(rows), "wall_s": time.perf_counter() - t0,
               "load_average_before": load_before, "load_average_after": os.getloadavg()}
    tmp = json_path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(summary, indent=1), encoding="utf-8")
    os.replace(tmp, json_path)
    print(json.dumps(summary["per_target"], indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
