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

import argparse
import json
import sys
from pathlib import Path

from . import (DEFAULT_MODELS, EXIT_FAILED_TASKS, MAX_SEED, add_command, add_render_options,
               at_least, between, check_models, check_render_settings, models_help, path, positive,
               positive_or, usage_error)
from ..errors import printable
from ..fit.registry import check_options

__all__ = ["register", "compare_cmd"]


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


def register(commands) -> None:
    cmd = add_command(commands, "compare", compare_cmd, epilog=models_help())
    cmd.add_argument("spec", metavar="INPUT[:MATERIAL]",
                     help="Reference BRDF: a file, collection.zip[:material], synthetic:NAME "
                          "or a fit file.")
    cmd.add_argument("-m", "--models", default=DEFAULT_MODELS, metavar="A,B",
                     help="Comma-separated model names to fit (list below), and/or saved fits "
                          "as NAME=fit.npz or fit.npz.")
    cmd.add_argument("-o", "--out", type=path, default=Path("report"), metavar="DIR",
                     help="Report directory.")
    add_render_options(cmd)
    cmd.add_argument("--scene", help=argparse.SUPPRESS)  # hidden: the single-scene form of --scenes NAME
    cmd.add_argument("--seed", type=between(0, MAX_SEED - (1 << 20)), default=0, metavar="N",
                     help="Seed of the sample streams (all models).")
    cmd.add_argument("--exposure", type=positive_or("scene", "auto"), default="scene",
                     metavar="EV",
                     help="Tone-mapping exposure: 'scene' (fixed per scene), 'auto' (from "
                          "each scene's reference) or a positive number.")
    cmd.add_argument("--gamma", type=positive(10.0), metavar="G",
                     help="Tone-mapping gamma (default: the scene's, 2.2).")
    # ignored (standard errors replaced the noise floor); accepted for old command lines
    cmd.add_argument("--noise-floor", action=argparse.BooleanOptionalAction, default=True,
                     help=argparse.SUPPRESS)
    cmd.add_argument("--envmap", metavar="MAP",
                     help="Environment map of the plain sphere-env/knot scenes: a name of "
                          "../shared/data/envmaps or an EXR (default procedural).")
    cmd.add_argument("--limit", type=at_least(1), metavar="N",
                     help="With a collection: only its first N materials.")
    cmd.add_argument("--fit-options", metavar="JSON",
                     help='Fitter keyword arguments as JSON per model, e.g. '
                          '\'{"npf": {"max_iter": 100}}\'.')
    cmd.add_argument("-q", "--quiet", action="store_true", help="No progress messages.")


def compare_cmd(spec: str, models: str = DEFAULT_MODELS, out: Path = Path("report"),
                scenes: str = "paper", scene: str | None = None, spp: int = 64,
                batches: int = 8, resolution: int = 256, seed: int = 0,
                exposure: str = "scene", gamma: float | None = None, noise_floor: bool = True,
                envmap: str | None = None, limit: int | None = None,
                fit_options: str | None = None, quiet: bool = False) -> int | None:
    """Fit, render and measure models against a reference (HTML report)."""
    from ..batch import compare_with_exports
    from ..evaluation.compare import compare_many
    from ..evaluation.report import write_index

    model_list = [m.strip() for m in models.split(",") if m.strip()]
    if not model_list:
        raise ValueError(f"--models: expected at least one model name, found {models!r}")
    check_models([m for m in model_list if "=" not in m and not m.endswith(".npz")])
    batches = check_render_settings(spp, batches, resolution)
    exp = exposure
    try:
        fopts = json.loads(fit_options) if fit_options else None
    except json.JSONDecodeError as exc:
        raise ValueError(f"--fit-options: expected JSON, found {fit_options!r} ({exc})")
    if fopts is not None and not (isinstance(fopts, dict)
                                  and all(isinstance(v, dict) for v in fopts.values())):
        raise ValueError(f"--fit-options: expected a JSON object {{model: {{option: value}}}}, "
                         f"found {fit_options!r}")
    if fopts:
        from ..fit.options import OptionError
        labels = [m.split("=", 1)[0] if "=" in m else Path(m).stem if m.endswith(".npz")
                  else m for m in model_list]
        for label, opts in fopts.items():
            if label not in labels:
                raise usage_error("--fit-options", f"{label!r} is not one of --models "
                                                   f"({', '.join(model_list)})")
            try:
                fopts[label] = check_options(label, opts, command_line=True)
            except OptionError as exc:
                raise usage_error("--fit-options", f"{label}: {exc}") from None
            except KeyError:  # a saved fit (label=path.npz) takes no fitting options
                raise usage_error("--fit-options", f"{label!r} is not a model name") from None
    ropts = {"envmap": envmap} if envmap else {}
    say = (lambda msg: None) if quiet else (lambda msg: print(printable(msg), file=sys.stderr))
    kw = dict(scenes=scene or scenes, spp=spp, batches=batches, resolution=resolution,
              seed=seed, exposure=exp, gamma=gamma, render_options=ropts, progress=say,
              fit_options=fopts)
    specs = _materials(spec, limit)
    if len(specs) == 1:
        res = compare_with_exports(specs[0], model_list, out, **kw)
        results = [res]
    else:
        results = compare_many(specs, model_list, out, run=compare_with_exports, **kw)
    write_index(out)
    for r in results:
        if "error" in r and "models" not in r:
            print(printable(f"{r['material']}: FAILED {r['error']}"))
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
        failed_scenes = [s for s in r.get("scenes", []) if s.get("error")]
        if failed_scenes:
            cells.append("not rendered: " + ", ".join(f"{s.get('name')} ({s['error']})"
                                                      for s in failed_scenes))
        print(printable(f"{r['material']}: " + "; ".join(cells)))
    print(f"report: {(Path(out) / 'index.html').resolve()}")
    if any(("error" in r and "models" not in r)
           or any(m.get("status") not in ("ok", "skipped") for m in r.get("models", []))
           or any(s.get("error") for s in r.get("scenes", []))
           for r in results):
        return EXIT_FAILED_TASKS  # some fits or renders failed; the report has the rest
