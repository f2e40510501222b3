"""``brdffit compare INPUT[:MATERIAL] --models tabulated,ggx,... --out DIR``.

Fits the requested models (or loads saved fit files given as ``NAME=fit.npz`` or ``fit.npz``),
renders the reference and every model on the paper's scene suite (``--scenes paper``: a sphere
under three environment maps and the knot mesh, Bagher et al. 2016 §5) with common random
numbers in independent batches, measures rendered PSNR ± standard error per scene and its
mean over scenes, dE2000 and the BRDF-space metrics, and writes the static HTML
report (:mod:`brdffit.evaluation.report`): ``DIR/<material>/index.html`` and the index
``DIR/index.html``, rebuilt from every material already in ``DIR``. A Neural-BRDF collection
without ``:MATERIAL`` compares all its materials (``--limit`` keeps the first N).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

__all__ = ["register"]


def _materials(spec: str, limit: int | None) -> list[str]:
    if not spec.lower().endswith(".zip"):
        return [spec]
    from ..io import resolve_spec

    kind, path, member = resolve_spec(spec)
    if kind == "nbrdf-collection" and not member:
        from ..io.nbrdf import list_materials

        names = list_materials(path)
        names = names[:limit] if limit else names
        return [f"{path}:{n}" for n in names]
    return [spec]


def register(app: typer.Typer) -> None:
    from . import models_help

    @app.command("compare", epilog=models_help())
    def compare_cmd(
        spec: str = typer.Argument(..., metavar="INPUT[:MATERIAL]",
                                   help="Reference BRDF: a file, collection.zip[:material], "
                                        "synthetic:NAME or a fit file."),
        models: str = typer.Option("tabulated,ggx,beckmann", "--models", "-m", metavar="A,B",
                                   help="Comma-separated model names to fit (list below), "
                                        "and/or saved fits as NAME=fit.npz or fit.npz."),
        out: Path = typer.Option(Path("report"), "--out", "-o", metavar="DIR", help="Report directory."),
        scenes: str = typer.Option("paper", "--scenes", metavar="SCENES",
                                   help="Scene suite 'paper' (sphere-courtyard, sphere-studio, "
                                        "sphere-sunrise, knot-courtyard) or scene names, comma-"
                                        "separated: sphere-<map>, knot-<map>, sphere-env, knot, "
                                        "sphere-point, sphere-distant, sphere-svrough."),
        scene: str = typer.Option(None, "--scene", hidden=True,
                                  help="One scene (former option; same as --scenes NAME)."),
        spp: int = typer.Option(64, "--spp", min=1, metavar="N",
                                help="Samples per pixel per scene, all batches together."),
        batches: int = typer.Option(8, "--batches", min=1, metavar="N",
                                    help="Independent batches per scene (≥ 3 for standard "
                                         "errors)."),
        resolution: int = typer.Option(256, "--resolution", min=8, metavar="PX", help="Image side in pixels."),
        seed: int = typer.Option(0, "--seed", metavar="N", help="Seed of the sample streams (all models)."),
        exposure: str = typer.Option("scene", "--exposure", metavar="EV",
                                     help="Tone-mapping exposure: 'scene' (fixed per scene), "
                                          "'auto' (from each scene's reference) or a number."),
        gamma: float = typer.Option(None, "--gamma", metavar="G", help="Tone-mapping gamma (default: the "
                                                          "scene's, 2.2)."),
        noise_floor: bool = typer.Option(True, "--noise-floor/--no-noise-floor", hidden=True,
                                         help="Ignored: standard errors replace the noise floor."),
        envmap: str = typer.Option(None, "--envmap", metavar="MAP",
                                   help="Environment map of the plain sphere-env/knot scenes: a "
                                        "name of ../shared/data/envmaps or an EXR (default "
                                        "procedural)."),
        limit: int = typer.Option(None, "--limit", min=1, metavar="N",
                                  help="With a collection: only its first N materials."),
        fit_options: str = typer.Option(None, "--fit-options", metavar="JSON",
                                        help='Fitter keyword arguments as JSON per model, e.g. '
                                             '\'{"npf": {"max_iter": 100}}\'.'),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress messages."),
    ) -> None:
        """Fit, render and measure models against a reference (HTML report)."""
        from ..evaluation.compare import compare, compare_many
        from ..evaluation.report import write_index

        model_list = [m.strip() for m in models.split(",") if m.strip()]
        if not model_list:
            raise ValueError(f"--models: expected at least one model name, found {models!r}")
        from . import check_models  # model names (not saved fits) must be known: exit 2

        check_models([m for m in model_list if "=" not in m and not m.endswith(".npz")])
        exp = exposure if exposure in ("auto", "scene") else float(exposure)
        try:
            fopts = json.loads(fit_options) if fit_options else None
        except json.JSONDecodeError as exc:
            raise ValueError(f"--fit-options: expected JSON, found {fit_options!r} ({exc})")
        if fopts is not None and not (isinstance(fopts, dict)
                                      and all(isinstance(v, dict) for v in fopts.values())):
            raise ValueError(f"--fit-options: expected a JSON object {{model: {{option: value}}}}, "
                             f"found {fit_options!r}")
        ropts = {"envmap": envmap} if envmap else {}
        say = (lambda msg: None) if quiet else (lambda msg: typer.echo(msg, err=True))
        kw = dict(scenes=scene or scenes, spp=spp, batches=batches, resolution=resolution,
                  seed=seed, exposure=exp, gamma=gamma, render_options=ropts, progress=say,
                  fit_options=fopts)
        specs = _materials(spec, limit)
        if len(specs) == 1:
            res = compare(specs[0], model_list, out, **kw)
            results = [res]
        else:
            results = compare_many(specs, model_list, out, **kw)
        write_index(out)
        for r in results:
            if "error" in r and "models" not in r:
                typer.echo(f"{r['material']}: FAILED {r['error']}")
                continue
            cells = []
            for m in r["models"]:
                if m.get("status") == "ok":
                    se = m.get("psnr_se")
                    pm = (f"≥ {m['psnr']:.2f}" if m.get("psnr_bound") == "lower" else
                          f"{m['psnr']:.2f}" + (f" ± {se:.2f}" if se is not None and se == se else ""))
                    cells.append(f"{m['name']} {pm} dB / dE {m['mean_de2000']:.2f}")
                else:
                    cells.append(f"{m['name']} failed")
            typer.echo(f"{r['material']}: " + "; ".join(cells))
        typer.echo(f"report: {(Path(out) / 'index.html').resolve()}")
        if any(("error" in r and "models" not in r)
               or any(m.get("status") not in ("ok", "skipped") for m in r.get("models", []))
               for r in results):
            raise typer.Exit(3)  # some fits or renders failed; the report has the rest
