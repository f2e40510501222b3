"""``brdffit batch``: fit whole databases on Dask, resumably.

Exit status: 0 every task done, 1 error (data, cluster), 2 usage (unknown model, bad value,
output folder locked by another batch), 3 some tasks failed — now or in an earlier run of
the same output folder (their records say why; ``--retry-failed`` redoes them).
"""

from __future__ import annotations

import sys

from . import (DEFAULT_MODELS, EXIT_ERROR, EXIT_FAILED_TASKS, EXIT_USAGE, add_command,
               add_render_options, at_least, between, check_models, check_render_settings,
               models_help, usage_error)
from ..errors import printable


def register(commands) -> None:
    cmd = add_command(commands, "batch", batch_cmd, epilog=models_help())
    cmd.add_argument("source", metavar="SOURCE",
                     help="Folder of measured files, a Neural-BRDF .zip collection, a list "
                          "file, or synthetic:[a,b].")
    cmd.add_argument("-m", "--models", default=DEFAULT_MODELS, metavar="A,B",
                     help="Comma-separated model names (list below).")
    cmd.add_argument("-o", "--out", required=True, metavar="DIR",
                     help="Output folder (created; re-runs resume).")
    cmd.add_argument("--only", default="", metavar="A,B",
                     help="Comma-separated material names to keep.")
    cmd.add_argument("--limit", type=at_least(0), default=0, metavar="N",
                     help="Keep only the first N materials (0: all).")
    cmd.add_argument("--scheduler", default="", metavar="ADDRESS",
                     help="Address of an existing Dask scheduler, e.g. tcp://host:8786 "
                          "(default: a local cluster). Its workers must share OUT and the data "
                          "at the same paths and run the same brdffit version.")
    cmd.add_argument("--workers", type=between(1, 256), default=2, metavar="N",
                     help="Local cluster: worker processes.")
    cmd.add_argument("--memory-limit", default="", metavar="SIZE",
                     help="Local cluster: memory per worker, e.g. 8GiB.")
    cmd.add_argument("--retries", type=between(0, 100), default=2, metavar="N",
                     help="Local cluster: how many more times a task that kills its worker "
                          "(out of memory...) is tried before it is recorded as failed.")
    cmd.add_argument("--no-metrics", action="store_true", help="Skip BRDF-space metrics.")
    cmd.add_argument("--render", action="store_true",
                     help="Also render every material and its fits (Mitsuba 3) and write the "
                          "HTML report to OUT/report/.")
    add_render_options(cmd, when="--render: ")
    cmd.add_argument("--retry-failed", action="store_true",
                     help="Redo tasks recorded as failed.")
    cmd.add_argument("--wait-lock", action="store_true",
                     help="If another batch is writing to OUT, wait for it (default: exit with "
                          "status 2).")
    cmd.add_argument("-q", "--quiet", action="store_true", help="No progress bar.")


def batch_cmd(source: str, out: str, models: str = DEFAULT_MODELS, only: str = "",
              limit: int = 0, scheduler: str = "", workers: int = 2, memory_limit: str = "",
              retries: int = 2, no_metrics: bool = False, render: bool = False,
              scenes: str = "paper", spp: int = 64, batches: int = 8, resolution: int = 256,
              retry_failed: bool = False, wait_lock: bool = False,
              quiet: bool = False) -> int | None:
    """Fit every material of SOURCE with every model (Dask, resumable).

            Writes OUT/fits/, OUT/records/ and OUT/summary.csv (one row per material and
            model: α and glTF roughness, F0, ρd, errors, PSNR ± se and dE2000 when rendered,
            time, status, fit file, and the recommended model of each material).

            \b
            Example:
              brdffit batch merl_nbrdf.zip -m tabulated,ggx --limit 10 --out runs/merl

            With --render, each material is also rendered once its fits are done, and
            OUT/report/index.html compares every model over the database. Exit status: 0 all
            done, 1 error, 2 usage or OUT locked by another batch, 3 some tasks failed.
            """
    from ..batch import (OutputLocked, RenderSettings, enumerate_materials, make_tasks,
                         run_batch)
    model_list = check_models([m.strip() for m in models.split(",") if m.strip()])
    if not model_list:
        raise usage_error("--models", f"expected at least one model name, found {models!r}")
    if memory_limit:
        from dask.utils import parse_bytes

        try:
            parse_bytes(memory_limit)
        except (ValueError, TypeError):
            raise usage_error("--memory-limit", f"expected a size such as 8GiB, found "
                                                f"{memory_limit!r}") from None
    if render:
        from ..evaluation.render.scenes import scene_suite
        check_render_settings(spp, batches, resolution)
        try:
            scene_suite(scenes)
        except (ValueError, KeyError) as exc:
            raise usage_error("--scenes", str(exc).strip("'\"")) from None
    materials = enumerate_materials(source, only=[s for s in only.split(",") if s] or None,
                                    limit=limit or None)
    tasks = make_tasks(materials, model_list)
    try:
        result = run_batch(tasks, out, scheduler=scheduler or None, workers=workers,
                           memory_limit=memory_limit or None, metrics=not no_metrics,
                           render=RenderSettings(scenes, spp, resolution, 0, batches)
                           if render else None, retry_failed=retry_failed,
                           progress=not quiet, retries=retries, wait_lock=wait_lock)
    except OutputLocked as exc:
        print(f"brdffit: {printable(str(exc))}", file=sys.stderr)
        return EXIT_USAGE
    n_render = f" + {result['render_tasks']} render" if render else ""
    print(f"{len(tasks)} fit{n_render} tasks: {result['ran']} run ({result['failed']} failed), "
          f"{result['skipped']} already done; summary in {out}/summary.csv")
    if render:
        print(f"report: {out}/report/index.html")
    if result["lost"]:
        print(f"brdffit: error: {result['lost']} task result(s) were lost (not "
              f"recorded); run the same command again to redo them", file=sys.stderr)
        return EXIT_ERROR
    earlier = result["failed_total"] - result["failed"]
    if earlier > 0:
        print(f"{earlier} task(s) failed in an earlier run (--retry-failed redoes them)")
    if result["failed_total"]:
        return EXIT_FAILED_TASKS
