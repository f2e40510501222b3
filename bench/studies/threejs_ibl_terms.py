"""Which term of three.js's image-based lighting makes diffuse materials too bright under the
paper suite's maps (issue 34): the NumPy model of three's shading
(:mod:`brdffit.evaluation.engines.threejs_ibl`, 55-86 dB against three's own images) with one
term at a time replaced (the irradiance by the exact cosine convolution, the multiple
scattering off, the diffuse factor by the punctual-light BRDF's), against our Mitsuba render of the fit (4 × 256 spp, 64², 4 × 4
samples per pixel); then the diffuse factor of three's IBL, ``1 − ss − ms`` (the specular
lobe's directional albedo from the DFG table), beside its punctual-light BRDF's, the mean
of ``1 − F(V·H)`` over cosine-distributed light directions.

    PYTHONPATH=src .venv/bin/python bench/studies/threejs_ibl_terms.py [--material SPEC]

Prints a table and writes ``bench/results/threejs_ibl_terms.json`` (PSNR ± se and mean ratio
per map and variant, the diffuse factors, the load average). Default material: RGL
paper_white (the lowest in three.js over the paper suite).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "src"))
os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")
DATA = ROOT.parent / "shared" / "data"
MAPS = ("courtyard", "studio", "sunrise")
RES, SS = 64, 4


def _variant(model, env, cam, irradiance, exact_irradiance: bool, multiscatter: bool):
    """The model's image with three's irradiance (PMREM's roughest level) or the exact
    cosine convolution, and with or without the multiple-scattering term."""
    from brdffit.evaluation.engines import threejs_ibl as TI

    hit = cam.hit
    N = cam.N[hit]
    read = env.read

    def patched(d, lod):
        return irradiance if exact_irradiance and np.ndim(lod) == 0 and lod == env.max_lod \
            else read(d, lod)

    keep = TI._multiscatter
    env.read = patched
    if not multiscatter:
        TI._multiscatter = lambda fab, f0, f90: (keep(fab, f0, f90)[0], 0.0)
    try:
        values = TI.shade_ibl(model, env, N, cam.V[hit], cam.geometry_roughness()[hit])
    finally:
        env.read, TI._multiscatter = read, keep
    return cam.average(values)[0]


def _punctual_diffuse(model, env, cam, image):
    """``image`` with the diffuse term's IBL factor ``1 − ss − ms`` replaced by the
    punctual-light BRDF's cosine-averaged ``1 − F(V·H)`` (per N·V, interpolated from 32)."""
    hit = cam.hit
    N, V = cam.N[hit], cam.V[hit]
    nv = np.clip(np.sum(N * V, -1), 0.0, 1.0)
    grid = np.linspace(0.02, 1.0, 32)
    rows = diffuse_factors(model, grid, n=100_000)
    d = np.array([np.array(r["punctual"]) - np.array(r["ibl"]) for r in rows])
    delta = np.stack([np.interp(nv, grid, d[:, c]) for c in range(3)], -1)
    return image + cam.average(model.base_color * (1 - model.metallic) * delta
                               * env.read(N, env.max_lod))[0]


def diffuse_factors(model, cos_v=(0.9, 0.6, 0.3), n: int = 400_000) -> list[dict]:
    """``1 − F(V·H)`` averaged over cosine-distributed L (three's punctual-light diffuse
    factor) and ``1 − ss − ms`` (its IBL's), per view cosine."""
    from brdffit.evaluation.engines import threejs_brdf as TB
    from brdffit.evaluation.engines import threejs_ibl as TI

    rng = np.random.default_rng(0)
    u1, u2 = rng.random(n), rng.random(n)
    L = np.stack([np.sqrt(u1) * np.cos(2 * np.pi * u2), np.sqrt(u1) * np.sin(2 * np.pi * u2),
                  np.sqrt(1 - u1)], -1)
    f0, f90 = model.dielectric_f0_f90()
    rows = []
    for nv in cos_v:
        V = np.array([np.sqrt(1 - nv * nv), 0.0, nv])
        H = L + V
        H /= np.linalg.norm(H, axis=-1, keepdims=True)
        F = TB._f_schlick_sg(f0[None, :], f90, np.clip(H @ V, 0, 1)[:, None])
        fab = TB._lut_bilinear(model.lut, np.array([max(model.roughness, 0.045)]), np.array([nv]))
        ss, ms = TI._multiscatter(fab, f0, f90)
        rows.append({"cos_v": nv, "punctual": (1 - F.mean(0)).tolist(),
                     "ibl": (1 - ss - ms)[0].tolist()})
    return rows


def main(argv=None) -> int:
    import brdffit
    from brdffit.evaluation.engines import threejs as T
    from brdffit.evaluation.engines import threejs_brdf as TB
    from brdffit.evaluation.engines import threejs_ibl as TI
    from brdffit.evaluation.engines.materialx_web import irradiance_map
    from brdffit.export.gltf import write_gltf

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--material", default=str(DATA / "rgl" / "paper_white_rgb.bsdf"))
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "threejs_ibl_terms.json")
    args = ap.parse_args(argv)
    load0 = list(os.getloadavg())
    doc = {"benchmark": "threejs_ibl_terms", "material": args.material, "maps": {},
           "resolution": RES, "supersample": SS, "mitsuba": "4 × 256 spp"}
    fit = brdffit.fit(brdffit.load(args.material), model="ggx-diffuse")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.gltf"
        write_gltf(fit, path, fidelity=False)
        model = TB.from_gltf(path)
    print(model.describe())
    cam = TB.CameraSphere(RES, SS)
    N = cam.N[cam.hit]
    alpha = cam.average(np.zeros((int(cam.hit.sum()), 3)))[1]
    for envmap in MAPS:
        refs, ra = T.reference_renders(fit, "sphere-" + envmap, RES, 256, 4)
        irr = TI.latlong_bilinear(irradiance_map(envmap).astype(float), *TI.latlong_uv(N))
        for name, exact, ms in (("three", False, True), ("exact irradiance", True, True),
                                ("no multiscatter", False, False), ("both", True, False)):
            c = T.compare_render(_variant(model, TI.pmrem(envmap), cam, irr, exact, ms), alpha,
                                 refs, ra)
            _row(doc, envmap, name, c)
        img = _punctual_diffuse(model, TI.pmrem(envmap), cam,
                                _variant(model, TI.pmrem(envmap), cam, irr, False, True))
        _row(doc, envmap, "punctual diffuse", T.compare_render(img, alpha, refs, ra))
    doc["diffuse_factors"] = diffuse_factors(model)
    for row in doc["diffuse_factors"]:
        print(f"N·V {row['cos_v']}: punctual 1 − F(V·H) {np.round(row['punctual'], 3).tolist()}"
              f", IBL 1 − ss − ms {np.round(row['ibl'], 3).tolist()}")
    doc["load_average"] = [load0, list(os.getloadavg())]
    from brdffit._atomic import atomic_write

    with atomic_write(args.out, "w") as fh:
        json.dump(doc, fh, indent=1, default=float)
    return 0


def _row(doc: dict, envmap: str, name: str, c: dict) -> None:
    doc["maps"].setdefault(envmap, {})[name] = {k: c[k] for k in ("psnr", "psnr_se",
                                                                  "mean_ratio")}
    print(f"{envmap:10s} {name:17s} {c['psnr']:6.2f} dB  mean ratio "
          f"{np.round(c['mean_ratio'], 3).tolist()}")


if __name__ == "__main__":
    sys.exit(main())
