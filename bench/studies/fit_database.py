"""Fit every model to every material of the database once, for the database comparison:
``runs/db/fits/<slug>/<model>.npz`` + ``<model>.json`` (fit time, status).

Resumable: a fit whose ``.json`` says ``ok`` and whose ``.npz`` loads is not redone. One process
walks the materials in order (``--reverse`` for a second process from the end); each fit runs in
this process with its CPU time recorded (the machine is shared). Defaults are the product's::

    nice -n 19 .venv/bin/python bench/studies/fit_database.py --models tabulated,ggx,beckmann,sgd,\\
        npf-g-from-d,npf-naive,npf-bivariate
    nice -n 19 .venv/bin/python bench/studies/fit_database.py --models npf --reverse

Materials: the 100 Neural-BRDF MERL networks (``merl_nbrdf.zip``) and the 7 RGL materials.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "src"))

from brdffit._atomic import atomic_write  # noqa: E402
from brdffit.batch import enumerate_materials  # noqa: E402
from brdffit.fit.registry import fit_model, is_isotropic_only  # noqa: E402
from brdffit.io import load  # noqa: E402
from brdffit.io.fitfile import load_fit, save_fit  # noqa: E402

SOURCES = ("merl_nbrdf.zip", str(ROOT.parent / "shared" / "data" / "rgl"))


def slug(name: str) -> str:
    from brdffit.evaluation.report import slugify

    return slugify(name)


def done(npz: Path, rec: Path) -> bool:
    try:
        status = json.loads(rec.read_text()).get("status")
    except (OSError, ValueError):
        return False
    if status == "skipped":
        return True
    if status != "ok":
        return False
    try:
        load_fit(npz)
        return True
    except Exception:  # noqa: BLE001
        return False


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", required=True)
    ap.add_argument("--out", default=str(ROOT / "runs" / "db"))
    ap.add_argument("--reverse", action="store_true")
    ap.add_argument("--limit", type=int, default=0)
    ap.add_argument("--only", default="", help="comma-separated material names to keep")
    args = ap.parse_args(argv)
    models = [m for m in args.models.split(",") if m]
    materials = []
    for src in SOURCES:
        materials += enumerate_materials(src)
    if args.only:
        keep = set(args.only.split(","))
        materials = [m for m in materials if m[0] in keep]
    if args.limit:
        materials = materials[:args.limit]
    if args.reverse:
        materials = materials[::-1]
    out = Path(args.out) / "fits"
    for name, spec in materials:
        ref = None
        for model in models:
            d = out / slug(name)
            npz, rec = d / f"{model}.npz", d / f"{model}.json"
            if done(npz, rec):
                continue
            if ref is None:
                ref = load(spec)
            record = {"material": name, "spec": spec, "model": model, "pid": os.getpid(),
                      "load": os.getloadavg()[0]}
            try:
                if is_isotropic_only(model) and not getattr(ref, "isotropic", False):
                    record["status"] = "skipped"
                else:
                    c0 = time.process_time()
                    fitted, record["fit_time_s"] = fit_model(model, ref)
                    record["fit_cpu_s"] = time.process_time() - c0
                    save_fit(fitted, npz, source=spec)
                    record["status"] = "ok"
            except Exception as exc:  # noqa: BLE001 - recorded, the run goes on
                record.update(status="failed", error=f"{type(exc).__name__}: {exc}",
                              traceback=traceback.format_exc(limit=6))
            record["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S")
            with atomic_write(rec, "w") as fh:
                json.dump(record, fh, indent=1)
            print(f"{name:32s} {model:14s} {record['status']:7s} "
                  f"{record.get('fit_time_s', 0):7.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
