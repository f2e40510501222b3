"""``brdffit batch``: fit whole databases on Dask, resumably.

Exit status: 0 every task done, 1 error (data, cluster), 2 usage (unknown model, bad value,
output folder locked by another batch), 3 some tasks failed — now or in an earlier run of
the same output folder (their records say why; ``--retry-failed`` redoes them).
"""

from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    from . import models_help

    @app.command("batch", epilog=models_help())
    def batch(
        source: str = typer.Argument(..., metavar="SOURCE", help="Folder of measured files, a Neural-BRDF .zip "
                                               "collection, a list file, or synthetic:[a,b]."),
        models: str = typer.Option("tabulated,ggx,beckmann", "--models", "-m", metavar="A,B",
                                   help="Comma-separated model names (list below)."),
        out: str = typer.Option(..., "--out", "-o", metavar="DIR",
                                help="Output folder (created; re-runs resume)."),
        only: str = typer.Option("", "--only", metavar="A,B", help="Comma-separated material names to keep."),
        limit: int = typer.Option(0, "--limit", min=0, metavar="N",
                                  help="Keep only the first N materials (0: all)."),
        scheduler: str = typer.Option("", "--scheduler", metavar="ADDRESS",
                                      help="Address of an existing Dask scheduler, e.g. "
                                           "tcp://host:8786 (default: a local cluster). Its "
                                           "workers must share OUT and the data at the same "
                                           "paths and run the same brdffit version."),
        workers: int = typer.Option(2, "--workers", min=1, metavar="N",
                                    help="Local cluster: worker processes."),
        memory_limit: str = typer.Option("", "--memory-limit", metavar="SIZE",
                                         help="Local cluster: memory per worker, e.g. 8GiB."),
        retries: int = typer.Option(2, "--retries", min=0, metavar="N",
                                    help="Local cluster: how many more times a task that kills "
                                         "its worker (out of memory...) is tried before it is "
                                         "recorded as failed."),
        no_metrics: bool = typer.Option(False, "--no-metrics", help="Skip BRDF-space metrics."),
        render: bool = typer.Option(False, "--render",
                                    help="Also render every material and its fits (Mitsuba 3) "
                                         "and write the HTML report to OUT/report/."),
        scenes: str = typer.Option("paper", "--scenes", metavar="SCENES",
                                   help="--render: the scene suite 'paper' (Bagher 2016 §5: a "
                                        "sphere under three environment maps and a knot), one "
                                        "scene or a comma-separated list."),
        spp: int = typer.Option(64, "--spp", min=1, metavar="N",
                                help="--render: samples per pixel per scene, all batches."),
        batches: int = typer.Option(8, "--batches", min=1, metavar="N",
                                    help="--render: independent batches per scene (the PSNR "
                                         "standard error needs ≥ 3)."),
        resolution: int = typer.Option(256, "--resolution", min=8, metavar="PX", help="--render: image size."),
        retry_failed: bool = typer.Option(False, "--retry-failed",
                                          help="Redo tasks recorded as failed."),
        wait_lock: bool = typer.Option(False, "--wait-lock",
                                       help="If another batch is writing to OUT, wait for it "
                                            "(default: exit with status 2)."),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
    ):
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
        from . import check_models, usage_error

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
            typer.echo(f"brdffit: {exc}", err=True)
            raise typer.Exit(2)
        n_render = f" + {result['render_tasks']} render" if render else ""
        typer.echo(f"{len(tasks)} fit{n_render} tasks: {result['ran']} run ({result['failed']} failed), "
                   f"{result['skipped']} already done; summary in {out}/summary.csv")
        if render:
            typer.echo(f"report: {out}/report/index.html")
        if result["lost"]:
            typer.echo(f"brdffit: error: {result['lost']} task result(s) were lost (not "
                       f"recorded); run the same command again to redo them", err=True)
            raise typer.Exit(1)
        earlier = result["failed_total"] - result["failed"]
        if earlier > 0:
            typer.echo(f"{earlier} task(s) failed in an earlier run (--retry-failed redoes them)")
        if result["failed_total"]:
            raise typer.Exit(3)
