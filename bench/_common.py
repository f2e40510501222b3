"""Helpers shared by the benchmark scripts (run as ``python bench/bench_X.py``)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

#: the project's root, the shared data beside it, and its Neural-BRDF MERL and RGL folders
ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
NBRDF = DATA / "nbrdf" / "merl_nbrdf.zip"
RGL_DIR = DATA / "rgl"


def use_project_sources() -> None:
    """Import brdffit from ``src/`` and load Mitsuba with Debian's LLVM 19 (the README)."""
    sys.path.insert(0, str(ROOT / "src"))
    os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")


def random_direction_pairs(n: int, seed: int = 0) -> list[np.ndarray]:
    """``[wi, wo]``: two arrays of ``n`` random unit vectors on the upper hemisphere."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(2):
        v = rng.normal(size=(n, 3))
        v[:, 2] = np.abs(v[:, 2])
        out.append(v / np.linalg.norm(v, axis=1, keepdims=True))
    return out


def merl_materials(zip_path, only: str | None = None) -> list[str]:
    """The Neural-BRDF MERL material names of ``zip_path``, sorted; ``only``: a comma-separated
    subset."""
    from brdffit.io.nbrdf import list_materials

    names = sorted(list_materials(str(zip_path)))
    if only:
        keep = set(only.split(","))
        names = [n for n in names if n in keep]
    return names


def read_rows(csv_path) -> list[dict]:
    """The rows of a resumable per-material CSV (``material`` text, every other field float)."""
    import csv
    from pathlib import Path

    if not Path(csv_path).is_file():
        return []
    with open(csv_path, newline="") as fh:
        return [{k: (v if k == "material" else float(v)) for k, v in r.items()}
                for r in csv.DictReader(fh)]


def write_rows(csv_path, fields, rows, summary: dict) -> None:
    """Write ``rows`` as CSV and ``summary`` as JSON next to it, both atomically."""
    import csv
    import io
    import json
    from pathlib import Path

    from brdffit._atomic import atomic_write

    buf = io.StringIO()
    w = csv.DictWriter(buf, fields)
    w.writeheader()
    w.writerows(rows)
    with atomic_write(csv_path, "w") as fh:
        fh.write(buf.getvalue())
    with atomic_write(Path(csv_path).with_suffix(".json"), "w") as fh:
        fh.write(json.dumps(summary, indent=1) + "\n")


def write_csv_and_summary(csv_path, json_path, fields, rows, summarise) -> list[dict]:
    """Write ``rows`` (missing fields empty) as CSV and ``summarise(rows)`` as JSON, both
    atomically; returns the rows as read back (all fields text), as a resumed run sees them."""
    import csv
    import io
    import json

    from brdffit._atomic import atomic_write

    buf = io.StringIO()
    w = csv.DictWriter(buf, fields)
    w.writeheader()
    for r in rows:
        w.writerow({k: r.get(k, "") for k in fields})
    with atomic_write(csv_path, "w") as fh:
        fh.write(buf.getvalue())
    rows = list(csv.DictReader(io.StringIO(buf.getvalue())))
    with atomic_write(json_path, "w") as fh:
        json.dump(summarise(rows), fh, indent=1, default=float)
    return rows


def resumable_merl_study(doc: str, default_name: str, zip_path, results_dir, argv=None):
    """The command line of a resumable per-material study over the Neural-BRDF MERL
    materials (``--only``, ``--name``): ``(todo, csv_path, rows)`` — the materials still to
    run, the CSV of ``--name`` in ``results_dir`` and the rows it already holds."""
    import argparse
    import sys
    from pathlib import Path

    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("--only", default=None, help="comma-separated material names")
    ap.add_argument("--name", default=default_name, help="results file stem")
    args = ap.parse_args(argv)
    if not Path(zip_path).is_file():
        sys.exit(f"needs {zip_path} (../shared/data)")
    csv_path = Path(results_dir) / f"{args.name}.csv"
    rows = read_rows(csv_path)
    done = {r["material"] for r in rows}
    return [n for n in merl_materials(zip_path, args.only) if n not in done], csv_path, rows


def engine_render(p: dict, engine: str, resolution: int):
    """``(image, alpha)`` of the glTF parameters ``p`` through ``engine``'s model
    (:func:`brdffit.export.gltf.engine_brdf`) in ``sphere-distant``, noise-free, 8 × 8
    samples per pixel: three.js with its own DFG table and per-pixel geometry roughness."""
    from brdffit.evaluation.engines import threejs_brdf as TB
    from brdffit.export.gltf import engine_brdf

    model = engine_brdf(p, engine)
    if engine == "threejs":
        model.lut = TB.dfg_lut()                    # three's own table
        return TB.shade_sphere(model, resolution=resolution, supersample=8)
    return TB.shade_sphere(model, resolution=resolution, supersample=8, geometry_roughness=False)
