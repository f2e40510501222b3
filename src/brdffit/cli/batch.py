"""``brdffit batch``: fit whole databases on Dask, resumably."""

from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    @app.command("batch")
    def batch(
        source: str = typer.Argument(..., help="Folder of measured files, a Neural-BRDF .zip "
                                               "collection, a list file, or synthetic:[a,b]."),
        models: str = typer.Option("tabulated,ggx,beckmann", "--models", "-m",
                                   help="Comma-separated model names (see `brdffit fit --help`)."),
        out: str = typer.Option(..., "--out", "-o", help="Output folder (created; re-runs resume)."),
        only: str = typer.Option("", "--only", help="Comma-separated material names to keep."),
        limit: int = typer.Option(0, "--limit", help="Keep only the first N materials (0: all)."),
        scheduler: str = typer.Option("", "--scheduler",
                                      help="Address of an existing Dask scheduler, e.g. "
                                           "tcp://host:8786 (default: a local cluster)."),
        workers: int = typer.Option(2, "--workers", help="Local cluster: worker processes."),
        memory_limit: str = typer.Option("", "--memory-limit",
                                         help="Local cluster: memory per worker, e.g. 8GiB."),
        no_metrics: bool = typer.Option(False, "--no-metrics", help="Skip BRDF-space metrics."),
        render: bool = typer.Option(False, "--render",
                                    help="Also render every material and its fits (Mitsuba 3) "
                                         "and write the HTML report to OUT/report/."),
        scene: str = typer.Option("sphere-env", "--scene", help="--render: scene."),
        spp: int = typer.Option(64, "--spp", help="--render: samples per pixel."),
        resolution: int = typer.Option(128, "--resolution", help="--render: image size."),
        noise_floor: bool = typer.Option(True, "--noise-floor/--no-noise-floor",
                                         help="--render: render the reference twice to "
                                              "measure the Monte Carlo noise floor."),
        retry_failed: bool = typer.Option(False, "--retry-failed",
                                          help="Redo tasks recorded as failed."),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
    ):
        """Fit every material of SOURCE with every model; write fits, records and a summary.

        Example: brdffit batch merl_nbrdf.zip --models tabulated,ggx --limit 10 --out runs/merl

        With --render, each material is also rendered once its fits are done, and
        OUT/report/index.html compares every model over the database.
        """
        from ..batch import RenderSettings, enumerate_materials, make_tasks, run_batch

        model_list = [m.strip() for m in models.split(",") if m.strip()]
        materials = enumerate_materials(source, only=[s for s in only.split(",") if s] or None,
                                        limit=limit or None)
        tasks = make_tasks(materials, model_list)
        result = run_batch(tasks, out, scheduler=scheduler or None, workers=workers,
                           memory_limit=memory_limit or None, metrics=not no_metrics,
                           render=RenderSettings(scene, spp, resolution, 0, noise_floor)
                           if render else None, retry_failed=retry_failed, progress=not quiet)
        n_render = f" + {result['render_tasks']} render" if render else ""
        typer.echo(f"{len(tasks)} fit{n_render} tasks: {result['ran']} run ({result['failed']} failed), "
                   f"{result['skipped']} already done; summary in {out}/summary.csv")
        if render:
            typer.echo(f"report: {out}/report/index.html")
        if result["failed"]:
            raise typer.Exit(3)
