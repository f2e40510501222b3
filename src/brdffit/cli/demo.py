"""``brdffit demo``: the main job on built-in synthetic materials (or real data)."""

from __future__ import annotations

import time
from pathlib import Path

from . import EXIT_FAILED_TASKS

# the paper's models and the engine-ready GGX + Lambert (+ coat) of issue 14
DEMO_MODELS = "tabulated,ggx,beckmann,ggx-diffuse,sgd,npf-g-from-d,npf"
# The demo's independent-G NPF runs one start (from the G-from-D fit) for a bounded number of
# AWLS iterations, to stay within a few minutes; `brdffit fit/compare` run all starts.
DEMO_FIT_OPTIONS = {"npf": {"starts": ("g-from-d",), "max_iter": 60, "start_max_iter": 60}}
# what the demo suggests next (brdffit arguments; tests/cli/test_demo.py runs them)
NEXT_STEP = ("fit synthetic:plastic-beckmann -m ggx-diffuse -o plastic.npz",
             "export plastic.npz --to gltf -o plastic.gltf")


def register(commands) -> None:
    from . import add_command, at_least, integer, models_help

    cmd = add_command(commands, "demo", demo_cmd, epilog=models_help())
    cmd.add_argument("-o", "--out", default="demo-out", metavar="DIR", help="Report folder.")
    cmd.add_argument("--data", default="", metavar="SOURCE",
                     help="Run on real data instead: a folder, a Neural-BRDF .zip collection "
                          "or a list file.")
    cmd.add_argument("--limit", type=integer, default=0, metavar="N",
                     help="With --data: first N materials only.")
    cmd.add_argument("-m", "--models", default=DEMO_MODELS, metavar="A,B",
                     help="Models to fit (list below).")
    cmd.add_argument("--spp", type=integer, default=64, metavar="N",
                     help="Samples per pixel of the renderings.")
    cmd.add_argument("--resolution", type=integer, default=128, metavar="PX",
                     help="Image size in pixels.")
    cmd.add_argument("-j", "--jobs", type=at_least(0), default=0, metavar="N",
                     help="Materials at a time, each in its own process (0: one per CPU).")


def _one_material(k: int, name: str, spec: str, model_list: list[str], out: str, spp: int,
                  resolution: int) -> tuple[int, str, float, list[str], int]:
    """Fit, render and compare one material (in a worker process): ``(k, name, seconds,
    per-model texts, failed models)``."""
    from ..evaluation.compare import compare

    t = time.perf_counter()
    result = compare(spec, model_list, out, name=name, spp=spp, resolution=resolution,
                     fit_options=DEMO_FIT_OPTIONS, update_index=False)
    rows, failures = [], 0
    for m in result.get("models", []):
        psnr = m.get("psnr")
        if m.get("status") == "skipped":
            rows.append(f"{m['name']}: skipped ({m.get('error')})")
        elif m.get("status") != "ok":
            failures += 1
            rows.append(f"{m['name']}: FAILED ({m.get('error', '?')})")
        else:
            rows.append(f"{m['name']} {psnr:.1f} dB" if psnr is not None else m["name"])
    return k, name, time.perf_counter() - t, rows, failures


def demo_cmd(out: str = "demo-out", data: str = "", limit: int = 0, models: str = DEMO_MODELS,
             spp: int = 64, resolution: int = 128, jobs: int = 0) -> int | None:
    """Fit and render built-in synthetic materials; write a report.

    No external data or network is needed. Example: brdffit demo --out demo-out
    Exit status: 0 all done, 1 error, 2 usage, 3 some fits failed (the rest is written).
    """
    import os
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from multiprocessing import get_context

    from ..batch import enumerate_materials
    from ..evaluation.report import write_index
    from . import check_models, usage_error

    model_list = check_models([m.strip() for m in models.split(",") if m.strip()])
    if not model_list:
        raise usage_error("--models", f"expected at least one model name, found {models!r}")
    source = data or "synthetic:"
    materials = enumerate_materials(source, limit=limit or None)
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(materials)))
    print(f"brdffit demo: {len(materials)} materials × {len(model_list)} models "
          f"({', '.join(model_list)}) → {out}/ ({jobs} at a time)")
    t0 = time.perf_counter()
    failures = 0
    # materials in worker processes (the fits are single-threaded); "spawn": the renderer's
    # threads must not be forked
    with ProcessPoolExecutor(jobs, mp_context=get_context("spawn")) as pool:
        tasks = [pool.submit(_one_material, k, name, spec, model_list, out, spp, resolution)
                 for k, (name, spec) in enumerate(materials)]
        for done, task in enumerate(as_completed(tasks), 1):
            k, name, seconds, rows, failed = task.result()
            failures += failed
            print(f"  [{done}/{len(materials)}] {name} ({seconds:.1f} s): " + "; ".join(rows),
                  flush=True)
    write_index(out)
    index = Path(out).resolve() / "index.html"
    print(f"done in {time.perf_counter() - t0:.0f} s; report: {index}")
    print("next, a material for an engine: "
          + " && ".join(f"brdffit {step}" for step in NEXT_STEP) + " (docs/tutorial.md)")
    if failures:
        return EXIT_FAILED_TASKS
