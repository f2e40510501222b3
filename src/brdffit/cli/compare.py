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
import sys
from pathlib import Path

from . import EXIT_FAILED_TASKS
from ..errors import printable
from ..batch import compare_with_exports
from ..evaluation.compare import compare_many
from ..evaluation.report import write_index
from ..fit.options import OptionError
from ..fit.registry import check_options
from ..io import resolve_spec
from ..io.nbrdf import list_materials
from ._checks import check_models, check_render_settings
from ._parsing import DEFAULT_MODELS, usage_error

__all__ = ["compare_cmd"]


def _materials(spec: str, limit: int | None) -> list[str]:
    if not spec.lower().endswith(".zip"):
        return [spec]
    kind, path, member = resolve_spec(spec)
    if kind == "nbrdf-collection" and not member:
        names = list_materials(path)
        names = names[:limit] if limit else names
        return [f"{path}:{n}" for n in names]
    return [spec]


def compare_cmd(spec: str, models: str = DEFAULT_MODELS, out: Path = Path("report"),
                scenes: str = "paper", scene: str | None = None, spp: int = 64,
                batches: int = 8, resolution: int = 256, seed: int = 0,
                exposure: str = "scene", gamma: float | None = None, noise_floor: bool = True,
                envmap: str | None = None, limit: int | None = None,
                fit_options: str | None = None, quiet: bool = False) -> int | None:
    """Run ``brdffit compare`` (its options: :func:`brdffit.cli._commands.compare`)."""
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
