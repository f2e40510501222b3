"""``brdffit demo``: the main job on built-in synthetic materials (or real data)."""

from __future__ import annotations

import os
import queue
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

from . import EXIT_FAILED_TASKS
from .._isolation import ChildCrashed, IsolatedProcess
from ..batch import compare_with_exports, enumerate_materials
from ..errors import printable as safe
from ..evaluation import report as R
from ..evaluation.compare import DEFAULT_BATCHES
from ..evaluation.report import write_index
from ..progress import report
from ._checks import check_models, check_render_settings
from ._commands import DEMO_MODELS
from ._parsing import usage_error

# The demo's independent-G NPF runs one start (from the G-from-D fit) for a bounded number of
# AWLS iterations, to stay within a few minutes; `brdffit fit/compare` run the default starts.
DEMO_FIT_OPTIONS = {"npf": {"starts": ("g-from-d",), "max_iter": 60, "start_max_iter": 60}}
# what the demo suggests next (brdffit arguments; tests/cli/test_demo.py runs them)
NEXT_STEP = ("fit synthetic:plastic-beckmann -m ggx-diffuse -o plastic.npz",
             "export plastic.npz --to gltf -o plastic.gltf")


def _one_material(name: str, spec: str, model_list: list[str], out: str, spp: int,
                  resolution: int) -> tuple[float, list[str], int]:
    """Fit, render and compare one material (in a worker process): ``(seconds, per-model
    and per-scene texts, failures)``; what it is doing goes out as progress stages (a crash
    message names the last one)."""
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
    slug = R.slugify(name)
    result = {"material": name, "slug": slug, "error": error,
              "models": [{"name": m, "status": "failed", "error": error} for m in model_list],
              "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    R.write_result(Path(out) / slug, result)
    R.write_material_page(out, result)


def demo_cmd(out: str = "demo-out", data: str = "", limit: int = 0, models: str = DEMO_MODELS,
             spp: int = 64, resolution: int = 128, jobs: int = 0) -> int | None:
    """Run ``brdffit demo`` (its options: :func:`brdffit.cli._commands.demo`)."""
    model_list = check_models([m.strip() for m in models.split(",") if m.strip()])
    if not model_list:
        raise usage_error("--models", f"expected at least one model name, found {models!r}")
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
