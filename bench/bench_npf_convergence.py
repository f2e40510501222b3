"""NPF convergence study (issue 15 item 2): objective against CPU time of fit_npf on real
materials (Neural-BRDF MERL networks), per variant, with the product defaults.

    nice -n 5 .venv/bin/python bench/bench_npf_convergence.py --n 5 --variants g-from-d independent-g

Materials are evenly spaced over the alphabetical list of ``merl_nbrdf.zip``. Records per
iteration (callback) the summed objective and ``time.process_time()`` since the fit started,
the load average before/after, and fit_info's convergence fields. Writes
bench/results/npf_convergence.json and bench/results/npf_convergence_<variant>.png.
"""
from __future__ import annotations

import argparse
import json
import os
import time
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ZIP = ROOT.parent / "shared" / "data" / "nbrdf" / "merl_nbrdf.zip"
OUT = ROOT / "bench" / "results"


def materials(n: int) -> list[str]:
    with zipfile.ZipFile(ZIP) as z:
        names = sorted({Path(f).stem for f in z.namelist() if f.endswith(".h5")})
    idx = np.linspace(0, len(names) - 1, n).round().astype(int)
    return [names[i] for i in dict.fromkeys(idx)]


def run_one(name: str, variant: str, **kw) -> dict:
    import brdffit
    from brdffit.fit.npf import fit_npf
    brdf = brdffit.load(f"{ZIP}:{name}")
    trace: list[tuple[int, float, float]] = []
    t0 = time.process_time()

    def cb(it, e):
        trace.append((int(it), float(e), time.process_time() - t0))

    fit = fit_npf(brdf, variant=variant, callback=cb, **kw)
    cpu = time.process_time() - t0
    info = fit.fit_info
    keep = ("objective", "normalised_objective", "converged", "cap_reached", "nit",
            "final_relative_change", "message", "criterion", "stop_reason", "time_s")
    return {"material": name, "variant": variant, "cpu_s": cpu,
            **{k: info.get(k) for k in keep}, "trace": trace}


def plot(rows: list[dict], variant: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in rows:
        tr = np.array(r["trace"])
        if len(tr) == 0:
            continue
        best = r["objective"]
        ax.semilogy(tr[:, 2], np.maximum(tr[:, 1] / best - 1, 1e-12), label=r["material"])
    ax.set_xlabel("CPU time (s, process_time)")
    ax.set_ylabel("objective / final − 1")
    ax.set_title(f"NPF {variant}: objective vs CPU time (product defaults)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / f"npf_convergence_{variant}.png", dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=5, help="materials, evenly spaced alphabetically")
    ap.add_argument("--variants", nargs="+", default=["g-from-d", "independent-g"])
    ap.add_argument("--out", default=str(OUT / "npf_convergence.json"))
    a = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    mats = materials(a.n)
    result = {"command": "bench/bench_npf_convergence.py " + " ".join(
        [f"--n {a.n}", "--variants", *a.variants]), "materials": mats,
        "loadavg_start": os.getloadavg(), "runs": []}
    for v in a.variants:
        rows = []
        for m in mats:
            r = run_one(m, v)
            r["loadavg"] = os.getloadavg()
            print(f"{v:14s} {m:28s} cpu={r['cpu_s']:7.1f}s E={r['objective']:.6g} "
                  f"nit={r['nit']} converged={r['converged']} cap={r['cap_reached']} "
                  f"rel={r['final_relative_change']:.2e}", flush=True)
            rows.append(r)
            result["runs"].append(r)
            Path(a.out).write_text(json.dumps(result, indent=1))
        plot(rows, v)
    result["loadavg_end"] = os.getloadavg()
    Path(a.out).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
