"""Does the coat help the *exported* materials? For each Neural-BRDF MERL material on which
ggx-diffuse keeps its coat (product defaults), the glTF and MaterialX equivalents of the
coated fit and of the same material fitted with ``coat="off"`` are rendered against the
measured reference, side by side with common random numbers (``compare()``, paper suite).

    nice .venv/bin/python bench/studies/coat_exports.py [--only a,b]

Writes ``bench/results/coat_exports.csv`` (PSNR ± se per material and column) and
``coat_exports.json`` (per target: mean PSNR with / without the coat, mean difference ± its
standard error over materials, wins / losses at two combined standard errors), atomically
after every material; re-running resumes.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "bench"))  # _common

from _common import resumable_merl_study, write_rows  # noqa: E402

ZIP = ROOT.parent / "shared" / "data" / "nbrdf" / "merl_nbrdf.zip"
COLUMNS = ("gltf-off", "gltf-on", "materialx-off", "materialx-on")


def summarise(rows: list[dict], load0) -> dict:
    out = {"benchmark": "coat: exported materials against the measured reference (rendered, CRN)",
           "command": " ".join(sys.argv), "n": len(rows), "load_average_start": load0,
           "load_average_now": list(os.getloadavg()), "per_target": {}}
    for t in ("gltf", "materialx"):
        on = np.array([r[f"{t}-on"] for r in rows], float)
        off = np.array([r[f"{t}-off"] for r in rows], float)
        se = np.hypot([r[f"{t}-on_se"] for r in rows], [r[f"{t}-off_se"] for r in rows])
        d = on - off
        out["per_target"][t] = {
            "psnr_on_mean": float(on.mean()) if len(d) else None,
            "psnr_off_mean": float(off.mean()) if len(d) else None,
            "difference_mean": float(d.mean()) if len(d) else None,
            "difference_se": float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else None,
            "wins": int((d > 2 * se).sum()), "losses": int((d < -2 * se).sum()),
            "worst": min(((float(x), r["material"]) for x, r in zip(d, rows)), default=None)}
    return out


def main(argv=None) -> int:
    todo, csv_path, rows = resumable_merl_study(__doc__, "coat_exports", ZIP,
                                               ROOT / "bench" / "results", argv)
    import brdffit
    from brdffit.evaluation.compare import compare
    from brdffit.export.gltf import gltf_equivalent
    from brdffit.export.materialx import openpbr_equivalent
    from brdffit.microfacet.coat import coat_parts

    fields = ["material"] + [c + s for c in COLUMNS for s in ("", "_se")]
    load0 = list(os.getloadavg())
    for name in todo:
        ref = brdffit.load(f"{ZIP}:{name}")
        on = brdffit.fit(ref, model="ggx-diffuse")
        if coat_parts(on) is None:
            continue
        off = brdffit.fit(ref, model="ggx-diffuse", coat="off")
        models = {"gltf-off": gltf_equivalent(off), "gltf-on": gltf_equivalent(on),
                  "materialx-off": openpbr_equivalent(off),
                  "materialx-on": openpbr_equivalent(on)}
        with tempfile.TemporaryDirectory() as tmp:
            res = compare(ref, models, tmp, name=name, save_fits=False, update_index=False,
                          brdf_metrics=(), write_exr=False)
        by = {m["name"]: m for m in res["models"]}
        row = {"material": name}
        for c in COLUMNS:
            row[c], row[c + "_se"] = by[c]["psnr"], by[c]["psnr_se"]
        rows.append(row)
        print(name, {c: round(row[c], 2) for c in COLUMNS}, flush=True)
        write_rows(csv_path, fields, rows, summarise(rows, load0))
    print(json.dumps(summarise(rows, load0)["per_target"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
