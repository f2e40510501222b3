"""The evidence for the coat margin of the diffuse fits (``COAT_MARGIN``): for each
Neural-BRDF MERL material, ggx-diffuse with ``coat="off"`` and with ``coat="on"`` (the coat
kept whenever it lowers the objective at all), rendered side by side on the paper suite with
common random numbers (``compare()`` defaults), against the objective ratio coated /
uncoated. The product keeps the coat when that ratio is below ``1 − COAT_MARGIN``.

    nice .venv/bin/python bench/studies/coat_margin.py                 # all 100 (≈ 20 s each)
    .venv/bin/python bench/studies/coat_margin.py --only delrin,nylon  # some

Writes ``bench/results/coat_margin.csv`` (material, objective ratio, PSNR ± se of both,
ΔPSNR, coat α and weight; NaN and Δ = 0 where no coat lowers the objective, not rendered) and ``coat_margin.json`` (ΔPSNR summed / counted per ratio bucket,
and per candidate margin the mean change over all materials and the losses), atomically after
every material; re-running resumes.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "bench"))  # _common

from _common import resumable_merl_study, write_rows  # noqa: E402

ZIP = ROOT.parent / "shared" / "data" / "nbrdf" / "merl_nbrdf.zip"
FIELDS = ["material", "objective_ratio", "psnr_off", "se_off", "psnr_on", "se_on", "delta_db",
          "coat_alpha", "coat_weight", "cpu_off_s", "cpu_on_s"]
BUCKETS = ((0.0, 0.9), (0.9, 0.95), (0.95, 1.0), (1.0, np.inf))
MARGINS = (0.0, 0.05, 0.1, 0.15)


def summarise(rows: list[dict], load0) -> dict:
    ratio = np.array([r["objective_ratio"] for r in rows], float)   # NaN: no coat lowers it
    delta = np.array([r["delta_db"] for r in rows], float)
    out = {"benchmark": "coat margin (ggx-diffuse coat='on' vs 'off', rendered, CRN)",
           "command": " ".join(sys.argv), "n": len(rows), "load_average_start": load0,
           "load_average_now": list(os.getloadavg()), "buckets": [], "margins": []}
    for lo, hi in BUCKETS:
        sel = (ratio >= lo) & (ratio < hi)
        out["buckets"].append({"ratio": [lo, None if np.isinf(hi) else hi],
                               "n": int(sel.sum()), "sum_db": float(delta[sel].sum()),
                               "losses": int((delta[sel] < 0).sum())})
    for m in MARGINS:
        sel = ratio < 1.0 - m
        out["margins"].append({"margin": m, "coated": int(sel.sum()),
                               "mean_change_db_over_all": float(delta[sel].sum() / max(len(rows), 1)),
                               "losses": int((delta[sel] < 0).sum()),
                               "worst_db": float(delta[sel].min()) if sel.any() else None})
    return out


def main(argv=None) -> int:
    todo, csv_path, rows = resumable_merl_study(__doc__, "coat_margin", ZIP,
                                               ROOT / "bench" / "results", argv)
    import brdffit
    from brdffit.evaluation.compare import compare

    load0 = list(os.getloadavg())
    for name in todo:
        ref = brdffit.load(f"{ZIP}:{name}")
        fits, cpu = {}, {}
        for mode in ("off", "on"):
            c0 = time.process_time()
            fits[mode] = brdffit.fit(ref, model="ggx-diffuse", coat=mode)
            cpu[mode] = time.process_time() - c0
        coat = fits["on"].fit_info["coat"] or {}
        if not coat.get("kept"):        # no coat lowers the objective: both fits are the same
            rows.append(dict({k: float("nan") for k in FIELDS}, material=name, delta_db=0.0,
                             cpu_off_s=cpu["off"], cpu_on_s=cpu["on"]))
            _write(csv_path, rows, load0)
            continue
        with tempfile.TemporaryDirectory() as tmp:
            res = compare(ref, {"off": fits["off"], "on": fits["on"]}, tmp, name=name,
                          save_fits=False, update_index=False, brdf_metrics=(), write_exr=False)
        by = {m["name"]: m for m in res["models"]}
        rows.append({"material": name,
                     "objective_ratio": coat["objective"] / coat["objective_without"],
                     "psnr_off": by["off"]["psnr"], "se_off": by["off"]["psnr_se"],
                     "psnr_on": by["on"]["psnr"], "se_on": by["on"]["psnr_se"],
                     "delta_db": by["on"]["psnr"] - by["off"]["psnr"],
                     "coat_alpha": coat["alpha"], "coat_weight": coat["weight"],
                     "cpu_off_s": cpu["off"], "cpu_on_s": cpu["on"]})
        print(f"{name:28s} ratio {rows[-1]['objective_ratio']:.3f} "
              f"Δ {rows[-1]['delta_db']:+.2f} dB", flush=True)
        _write(csv_path, rows, load0)
    print(json.dumps(summarise(rows, load0)["margins"], indent=1))
    return 0


def _write(csv_path: Path, rows: list[dict], load0) -> None:
    write_rows(csv_path, FIELDS, rows, summarise(rows, load0))

if __name__ == "__main__":
    sys.exit(main())
