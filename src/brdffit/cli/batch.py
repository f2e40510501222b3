"""``brdffit batch``: fit whole databases on Dask, resumably.

Exit status: 0 every task done, 1 error (data, cluster), 2 usage (unknown model, bad value,
output folder locked by another batch), 3 some tasks failed — now or in an earlier run of
the same output folder (their records say why; ``--retry-failed`` redoes them).
"""

from __future__ import annotations

import sys

from . import EXIT_ERROR, EXIT_FAILED_TASKS, EXIT_USAGE
from ..batch import OutputLocked, RenderSettings, enumerate_materials, make_tasks, run_batch
from ..errors import printable
from ..evaluation.render.scenes import scene_suite
from ._checks import check_models, check_render_settings
from ._parsing import DEFAULT_MODELS, usage_error


def batch_cmd(source: str, out: str, models: str = DEFAULT_MODELS, only: str = "",
              limit: int = 0, scheduler: str = "", workers: int = 2, memory_limit: str = "",
              retries: int = 2, no_metrics: bool = False, render: bool = False,
              scenes: str = "paper", spp: int = 64, batches: int = 8, resolution: int = 256,
              retry_failed: bool = False, wait_lock: bool = False,
              quiet: bool = False) -> int | None:
    """Run ``brdffit batch`` (its options: :func:`brdffit.cli._commands.batch`)."""
    model_list = check_models([m.strip() for m in models.split(",") if m.strip()])
    if not model_list:
        raise usage_error("--models", f"expected at least one model name, found {models!r}")
    if memory_limit:
        from dask.utils import parse_bytes  # Dask only when a size is given

        try:
            parse_bytes(memory_limit)
        except (ValueError, TypeError):
            raise usage_error("--memory-limit", f"expected a size such as 8GiB, found "
                                                f"{memory_limit!r}") from None
    if render:
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
