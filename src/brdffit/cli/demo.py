"""``brdffit demo``: the main job on built-in synthetic materials (or real data)."""

from __future__ import annotations

import time
from pathlib import Path

from . import (EXIT_FAILED_TASKS, MAX_RESOLUTION, MAX_SPP, add_command, at_least, between,
               check_models, check_render_settings, models_help, usage_error)
from ..errors import printable as safe

# the paper's models and the engine-ready GGX + Lambert (+ coat)
DEMO_MODELS = "tabulated,ggx,beckmann,ggx-diffuse,sgd,npf-g-from-d,npf"
# The demo's independent-G NPF runs one start (from the G-from-D fit) for a bounded number of
# AWLS iterations, to stay within a few minutes; `brdffit fit/compare` run all starts.
DEMO_FIT_OPTIONS = {"npf": {"starts": ("g-from-d",), "max_iter": 60, "start_max_iter": 60}}
# what the demo suggests next (brdffit arguments; tests/cli/test_demo.py runs them)
NEXT_STEP = ("fit synthetic:plastic-beckmann -m ggx-diffuse -o plastic.npz",
             "export plastic.npz --to gltf -o plastic.gltf")


def register(commands) -> None:
    cmd = add_command(commands, "demo", demo_cmd, epilog=models_help())
    cmd.add_argument("-o", "--out", default="demo-out", metavar="DIR", help="Report folder.")
    cmd.add_argument("--data", default="", metavar="SOURCE",
                     help="Run on real data instead: a folder, a Neural-BRDF .zip collection "
                          "or a list file.")
    cmd.add_argument("--limit", type=at_least(0), default=0, metavar="N",
                     help="With --data: first N materials only.")
    cmd.add_argument("-m", "--models", default=DEMO_MODELS, metavar="A,B",
                     help="Models to fit (list below).")
    cmd.add_argument("--spp", type=between(1, MAX_SPP), default=64, metavar="N",
                     help="Samples per pixel of the renderings (in up to 8 batches: a "
                          "multiple of 8, or fewer than 8).")
    cmd.add_argument("--resolution", type=between(8, MAX_RESOLUTION), default=128,
                     metavar="PX", help="Image size in pixels.")
    cmd.add_argument("-j", "--jobs", type=between(0, 64), default=0, metavar="N",
                     help="Materials at a time, each in its own process (0: one per CPU).")


def _one_material(name: str, spec: str, model_list: list[str], out: str, spp: int,
                  resolution: int) -> tuple[float, list[str], int]:
    """Fit, render and compare one material (in a worker process): ``(seconds, per-model
    and per-scene texts, failures)``; what it is doing goes out as progress stages (a crash
    message names the last one)."""
    from ..batch import compare_with_exports
    from ..progress import report

    t = time.perf_counter()
    result = compare_with_exports(
        spec, model_list, out, name=name, spp=spp, resolution=resolution,
        fit_options=DEMO_FIT_OPTIONS, update_index=False,
        progress=lambda msg: report(stage=msg.removeprefix(f"{name}: "), final=True))
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
    for s in result.get("scenes", []):
        if s.get("error") and not result.get("render_error"):
            failures += 1
            rows.append(f"{s.get('name', 'a scene')}: FAILED ({s['error']})")
    return time.perf_counter() - t, rows, failures


def _record_crash(out: str, name: str, model_list: list[str], error: str) -> None:
    """The material's result and page when its worker died: every model failed with
    ``error``, so that the index shows the row."""
    from ..evaluation import report as R

    slug = R.slugify(name)
    result = {"material": name, "slug": slug, "error": error,
              "models": [{"name": m, "status": "failed", "error": error} for m in model_list],
              "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    R.write_result(Path(out) / slug, result)
    R.write_material_page(out, result)


def demo_cmd(out: str = "demo-out", data: str = "", limit: int = 0, models: str = DEMO_MODELS,
             spp: int = 64, resolution: int = 128, jobs: int = 0) -> int | None:
    """Fit and render built-in synthetic materials; write a report.

    No external data or network is needed. Example: brdffit demo --out demo-out
    Exit status: 0 all done, 1 error, 2 usage, 3 some fits failed (the rest is written).
    """
    import os
    import queue
    from concurrent.futures import ThreadPoolExecutor, as_completed

    from .._isolation import ChildCrashed, IsolatedProcess
    from ..batch import enumerate_materials
    from ..evaluation.report import write_index
    model_list = check_models([m.strip() for m in models.split(",") if m.strip()])
    if not model_list:
        raise usage_error("--models", f"expected at least one model name, found {models!r}")
    from ..evaluation.compare import DEFAULT_BATCHES
    check_render_settings(spp, DEFAULT_BATCHES, resolution, batches_option=None)
    source = data or "synthetic:"
    materials = enumerate_materials(source, limit=limit or None)
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(materials)))
    print(f"brdffit demo: {len(materials)} materials × {len(model_list)} models "
          f"({', '.join(model_list)}) → {out}/ ({jobs} at a time)")
    t0 = time.perf_counter()
    failures = 0
    # one worker process per job slot (the fits are single-threaded), each running materials
    # one after the other; a worker that dies (a signal in native code) fails its material
    # only, and the slot starts a new worker for the next one
    workers: queue.SimpleQueue = queue.SimpleQueue()
    for _ in range(jobs):
        workers.put(IsolatedProcess())

    def run(name: str, spec: str):
        child = workers.get()
        child.what, child.stage = f"the worker of {name}", None
        try:
            return child.call(_one_material, name, spec, model_list, out, spp, resolution)
        finally:
            workers.put(child)

    try:
        with ThreadPoolExecutor(jobs) as pool:
            tasks = {pool.submit(run, name, spec): name for name, spec in materials}
            for done, task in enumerate(as_completed(tasks), 1):
                name = tasks[task]
                try:
                    seconds, rows, failed = task.result()
                except ChildCrashed as exc:
                    _record_crash(out, name, model_list, str(exc))
                    failures += 1
                    print(f"  [{done}/{len(materials)}] {safe(name)}: FAILED: {safe(str(exc))}",
                          flush=True)
                    continue
                failures += failed
                print(f"  [{done}/{len(materials)}] {safe(name)} ({seconds:.1f} s): "
                      + "; ".join(safe(r) for r in rows), flush=True)
    finally:
        while not workers.empty():
            workers.get().close()
    write_index(out)
    index = Path(out).resolve() / "index.html"
    print(f"done in {time.perf_counter() - t0:.0f} s; report: {index}")
    print("next, a material for an engine: "
          + " && ".join(f"brdffit {step}" for step in NEXT_STEP) + " (docs/tutorial.md)")
    if failures:
        return EXIT_FAILED_TASKS
