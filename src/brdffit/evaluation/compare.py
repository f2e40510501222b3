"""Orchestration of a comparison: fit (or load) models, render them and the reference with
common random numbers on a suite of scenes, measure, plot, and write the HTML report.

:func:`compare` handles one material and updates the report index; :func:`compare_many`
loops over several. A comparison is a :class:`Comparison` passed through five stages:

1. :func:`resolve_comparison`: the reference, the material's name and folder, the scenes and
   the options;
2. :func:`fit_models`: fit, load or take each model and describe it (``result.json``'s
   ``models``), saving the fits;
3. :func:`render_scenes`: render every scene and measure each model in it;
4. :func:`measure_models`: each model's summary over the scenes and its BRDF-space metrics;
5. :func:`write_report`: plots, ``result.json``, the material page and the index.

:func:`prepare` runs the first two and :func:`finish` the last three: between them a caller
can write engine files of the fitted models (:meth:`Comparison.fit_files`,
:meth:`Comparison.add_exports`; :func:`brdffit.batch.compare_with_exports`), which the page
links.

The measurement protocol:

* **scenes**: by default the paper's suite (Bagher et al. 2016 §5; :data:`SUITES` ``paper``
  in :mod:`.render.scenes`): a sphere under three environment maps of different dynamic range
  and the torus-knot mesh under one of them (the procedural environment, with a note, when
  ``../shared/data/envmaps`` is absent); any list of scene names otherwise;
* **common random numbers**: per scene, the reference and every model are rendered *in one
  pass* along the same paths, whose directions come from one proposal fitted to the
  reference (:mod:`.render.proposal`, MIS with the environment's importance sampling;
  :class:`.render.core.MultiRenderer`): the difference of two images is estimated with noise
  proportional to the difference itself, and the reference's own noise cancels;
* **standard errors**: ``spp`` samples per pixel per scene are split into ``batches``
  independent batches (different seeds; within a batch, the same seed for every model); the
  PSNR of a scene (Bagher 2016 §5: linear values, foreground pixels, peak = max RGB of the
  reference's foreground) is estimated from the batches without the noise bias and with its
  standard error (:func:`.metrics.crn_psnr`: U-statistic MSE, jackknife, delta method);
  a model's ``psnr`` is the mean over scenes with ``psnr_se`` propagated
  (:func:`.metrics.combine_psnr`). No noise floor (reference against itself with another
  seed) is computed: ``noise_floor`` is accepted and ignored, and ``result.json`` files that
  carry a ``noise_floor_psnr`` are still shown by the index (docs/design/render-comparisons.md);
* pictures: the paper's fixed tone map with one exposure per *scene*
  (:func:`.render.scenes.scene_exposure`; ``exposure="auto"`` picks one per scene from the
  reference instead, a number fixes it), dE2000 on the tone-mapped mean images (:mod:`.metrics`);
* BRDF-space metrics (:func:`.metrics.brdf_metrics`) independent of rendering.

The scenes are rendered by an engine of :mod:`.scene_engines`. A custom ``renderer``
(``renderer(brdf, scene=..., spp=..., resolution=..., seed=...)``, e.g. a NumPy stand-in in
tests) is called once per model, scene and batch with the batch's seed; it must itself make
equal seeds mean common random numbers.

A model that fails to fit, load or render is recorded with its error message; the others
still make it into the report.
"""

from __future__ import annotations

import dataclasses
import os
import time
import traceback
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from .._isolation import ChildCrashed
from ..errors import BRDFError, printable
from ..fit.registry import fit_model, is_isotropic_only, model_params, small_json
from . import imageio, metrics as M, plots as P, report as R
from .imageio import write_png
from .tonemap import auto_exposure, tonemap
from ..fit.result import fit_result
from ..loading import load
from .render.scenes import SceneSpec, scene_suite
from .scene_engines import (CallbackEngine, IsolatedCRNEngine, cpu_seconds, make_engine,
                            peak_from_batches)
from ..io.fitfile import SerializableModel, load_fit, save_fit, table_bytes
from .validity import check_validity

__all__ = ["compare", "compare_many", "resolve_reference", "DEFAULT_MODELS", "Comparison",
           "CompareOptions", "resolve_comparison", "fit_models", "render_scenes",
           "measure_models", "write_report", "prepare", "finish"]

DEFAULT_MODELS = ("tabulated", "ggx", "beckmann", "sgd", "npf")
#: Samples per pixel per scene (all batches), batches, image size of :func:`compare`.
DEFAULT_SPP = 64
DEFAULT_BATCHES = 8
DEFAULT_RESOLUTION = 256

# ------------------------------------------------------------------------------------------
# inputs
# ------------------------------------------------------------------------------------------
def resolve_reference(source, material: str | None = None):
    """A reference BRDF: a BRDF object as is, else :func:`brdffit.load` of the spec (a file,
    a fit file, ``archive.zip:member``, ``synthetic:NAME``; ``material`` is appended as
    ``:material``)."""
    if hasattr(source, "eval"):
        return source
    spec = str(source)
    if material:
        spec = f"{spec}:{material}"
    return load(spec)


def _default_renderer():
    """The renderer of :func:`compare` when none is given: ``None`` means the Mitsuba 3
    common-random-numbers engine (:class:`.render.core.MultiRenderer`); tests replace this
    hook with a per-BRDF stand-in ``renderer(brdf, scene=, spp=, resolution=, seed=)``."""
    return None


def _tonemapper():
    return auto_exposure, tonemap


def _write_png(path, img):
    return write_png(path, img)


def _write_exr(path, img):
    return imageio.write_exr(path, np.asarray(img, np.float32))  # looked up at call time


def _safe_name(name: str) -> str:
    return R.slugify(name)


def _model_entries(models: Sequence | Mapping) -> list[tuple[str, Any]]:
    """``(label, what)`` of each model: a mapping's items; in a sequence ``"label=what"``,
    ``"path.npz"`` (labelled by its stem) or a model name (labelled by itself)."""
    if isinstance(models, Mapping):
        return list(models.items())
    entries: list[tuple[str, Any]] = []
    for m in models:
        if isinstance(m, str) and "=" in m:
            label, what = m.split("=", 1)
            entries.append((label, what))
        elif isinstance(m, str) and m.endswith(".npz"):
            entries.append((Path(m).stem, m))
        else:
            entries.append((str(m), m))
    return entries


# ------------------------------------------------------------------------------------------
# the comparison and its options
# ------------------------------------------------------------------------------------------
@dataclasses.dataclass
class CompareOptions:
    """How a comparison renders and measures: the keyword arguments of :func:`compare`.

    Attributes
    ----------
    scenes : str or sequence of str
        ``"paper"`` (the four scenes of Bagher 2016 §5, see :mod:`.render.scenes`), one scene
        name or several (list or comma-separated: ``sphere-studio``, ``knot-courtyard``,
        ``sphere-env`` with ``render_options={"envmap": ...}``, ...).
    scene : str, optional
        One scene name; wins over ``scenes`` when given.
    spp, batches, resolution, seed : int
        ``spp`` samples per pixel per scene in total, rendered as ``batches`` independent
        batches of ``ceil(spp / batches)`` (``batches ≥ 3`` gives standard errors); scene
        ``i``'s batch ``k`` uses seed ``seed + i·batches + k`` for the reference and every
        model.
    exposure : {"scene", "auto"} or float
        Tone mapping of the PNGs and of the dE2000 conversion (Bagher et al. 2016 §5):
        ``"scene"`` each scene's fixed exposure (:func:`.render.scenes.scene_exposure`),
        ``"auto"`` one exposure per scene from its reference, a number the same everywhere.
    gamma : float, optional
        The tone map's γ; ``None`` is the scene's (2.2).
    noise_floor : bool, optional
        Ignored: the standard error replaces the noise floor.
    brdf_metric_samples : int
        Sample pairs of the cosine-weighted relative error.
    brdf_metrics : sequence of str
        Which BRDF-space metrics to compute (:class:`.metrics.BRDFMetrics`; the reference is
        prepared once).
    fit_options : mapping, optional
        Per-model keyword arguments of the fitters.
    measured : mapping, optional
        Per model label, figures of that model measured elsewhere (a batch's fit tasks),
        taken as they are instead of being measured again: ``"brdf"`` (its BRDF-space
        metrics, as :meth:`.metrics.BRDFMetrics.evaluate` returns them) and ``"validity"``
        (its :func:`.validity.check_validity` list, as dictionaries).
    save_fits : bool
        Save each fitted model to ``<slug>/fits/<label>.npz``, linked from the page.
    write_exr : bool or "reference"
        Linear EXRs of the mean images: ``"reference"`` the references only, ``True`` every
        model too, ``False`` none.
    renderer : callable, optional
        Replaces the Mitsuba CRN renderer (see the module docstring).
    render_options : mapping, optional
        Go to the scenes (e.g. ``{"envmap": "studio"}`` for ``sphere-env``/``knot``) or to a
        custom ``renderer``.
    update_index : bool
        Rebuild ``out_dir/index.html`` from every material present.
    progress : callable, optional
        Receives one line per step (``"<material>: fitting ggx"``).
    isolate_renders : bool
        Render in a child process: a renderer that dies from a signal fails the scene it was
        rendering (``scenes[i]["error"]``, one line through ``progress``) and the other scenes
        go on in a new child. BRDFs that cannot be pickled are rendered in this process, with
        a note.
    """

    scenes: str | Sequence[str] = "paper"
    scene: str | None = None
    spp: int = DEFAULT_SPP
    batches: int = DEFAULT_BATCHES
    resolution: int = DEFAULT_RESOLUTION
    seed: int = 0
    exposure: str | float = "scene"
    gamma: float | None = None
    noise_floor: bool | None = None
    brdf_metric_samples: int = 1 << 16
    brdf_metrics: Sequence[str] = M.BRDFMetrics.ALL
    fit_options: Mapping[str, Mapping] | None = None
    measured: Mapping[str, Mapping] | None = None
    save_fits: bool = True
    write_exr: bool | str = "reference"
    renderer: Callable | None = None
    render_options: Mapping | None = None
    update_index: bool = True
    progress: Callable[[str], None] | None = None
    isolate_renders: bool = True

    @property
    def batch_count(self) -> int:
        """Batches rendered per scene: ``batches`` clipped to ``[1, spp]``."""
        return max(1, min(int(self.batches), int(self.spp)))

    @property
    def spp_batch(self) -> int:
        """Samples per pixel of one batch: ``ceil(spp / batch_count)``."""
        return max(1, -(-int(self.spp) // self.batch_count))


@dataclasses.dataclass
class Comparison:
    """One material compared with its models: what the stages of :func:`compare` read and
    fill.

    Attributes
    ----------
    source : object
        The reference as given (a BRDF or a load spec).
    reference : BRDF
        The reference BRDF.
    material : str
        Its name in the report; :attr:`slug` names its folder.
    out_dir : Path
        The report directory; the material's files go to :attr:`folder`.
    models : list of (str, object)
        ``(label, what)`` per model: a BRDF, a fit-file path or a model name.
    scenes : list of SceneSpec
        The scenes rendered.
    options : CompareOptions
        The settings.
    notes : list of str
        Notes on the settings (scene substitutions, rounded sample counts).
    records : list of dict
        Per model, what ``result.json`` says of it (``result["models"]``).
    fitted : dict
        Label → BRDF of each model fitted, loaded or given.
    scene_entries : dict
        Label → the model's per-scene measures (``records[i]["scenes"]``) of each model
        rendered.
    result : dict
        ``result.json``.
    """

    source: Any
    reference: Any
    material: str
    out_dir: Path
    models: list[tuple[str, Any]]
    scenes: list[SceneSpec]
    options: CompareOptions
    notes: list[str] = dataclasses.field(default_factory=list)
    records: list[dict] = dataclasses.field(default_factory=list)
    fitted: dict[str, Any] = dataclasses.field(default_factory=dict)
    scene_entries: dict[str, list[dict]] = dataclasses.field(default_factory=dict)
    result: dict[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def slug(self) -> str:
        """The material's folder name under :attr:`out_dir`."""
        return _safe_name(self.material)

    @property
    def folder(self) -> Path:
        """``out_dir/<slug>``: the material's page, pictures, fits and exports."""
        return self.out_dir / self.slug

    def say(self, message: str) -> None:
        """One line of progress (``options.progress``)."""
        if self.options.progress:
            self.options.progress(message)

    def record(self, label: str) -> dict:
        """The record of the model ``label``."""
        return next(r for r in self.records if r["name"] == label)

    def stem(self, label: str) -> str:
        """The file-name stem of model ``label``'s fit file and engine files."""
        return _safe_name(label)

    def fit_files(self) -> dict[str, Any]:
        """Label → BRDF of each model that has a fit file: saved by :func:`fit_models`
        (``fit_file``) or loaded from one (``loaded_from``), in the order of the models;
        the models whose engine files the page can link (:meth:`add_exports`)."""
        return {r["name"]: self.fitted[r["name"]] for r in self.records
                if r["status"] == "ok" and (r.get("loaded_from") or r.get("fit_file"))}

    def add_exports(self, label: str, paths: Sequence[str]) -> None:
        """Record the engine files written for model ``label`` under ``folder/exports``
        (paths relative to :attr:`folder`; ``result.json``'s ``exports``). A loaded fit is
        linked where it is, relative to the page (``fit_file``, ``table_bytes``)."""
        self._link_loaded_fit(label)["exports"] = list(paths)

    def exports_failed(self, label: str, exc: BaseException) -> None:
        """Writing the engine files of model ``label`` raised ``exc`` (call it while handling
        ``exc``): a model fitted here keeps its fit file, with a warning; a loaded fit fails
        like a fit file that cannot be read."""
        rec = self._link_loaded_fit(label)
        if rec.get("loaded_from"):
            rec.update(status="failed", error=f"fit/load failed: {type(exc).__name__}: {exc}")
            rec["traceback"] = traceback.format_exc(limit=4)
        else:
            rec.setdefault("warnings", []).append(f"could not save fit: {exc}")

    def _link_loaded_fit(self, label: str) -> dict:
        """The record of ``label``, with a loaded fit's file linked relative to the page."""
        rec = self.record(label)
        if rec.get("loaded_from"):
            rel = Path(os.path.relpath(Path(rec["loaded_from"]).resolve(), self.folder.resolve()))
            rec["fit_file"] = rel.as_posix()
            rec["table_bytes"] = table_bytes(self.fitted[label])
        return rec


@dataclasses.dataclass
class _Scene:
    """One rendered scene while its models are measured: its record in ``result["scenes"]``,
    the reference's batches, their mean, the foreground and the scene's tone map."""

    spec: SceneSpec
    record: dict
    ref_stack: np.ndarray
    ref_mean: np.ndarray
    mask: np.ndarray
    exposure: float
    gamma: float

    def tonemap(self, img):
        """The scene's tone map of a linear image."""
        return _tonemapper()[1](img, exposure=self.exposure, gamma=self.gamma)


# ------------------------------------------------------------------------------------------
# the stages
# ------------------------------------------------------------------------------------------
def resolve_comparison(source, models: Sequence | Mapping = DEFAULT_MODELS, out_dir="report",
                       *, material: str | None = None, name: str | None = None,
                       **options) -> Comparison:
    """The comparison of one reference with ``models``, nothing fitted yet.

    Parameters
    ----------
    source : BRDF or str
        The reference: a BRDF object, a fit file, ``synthetic:NAME`` or a load spec
        (``INPUT`` with ``material`` → ``INPUT:MATERIAL``, :func:`resolve_reference`).
    models : sequence or mapping
        Model names to fit (``"tabulated"``, ``"ggx"``, … resolved by
        :func:`brdffit.fit.registry.get`), paths to saved fit files (``.npz``),
        ``"label=path.npz"``, or a mapping label → (BRDF object | fit-file path | model name).
    out_dir : path
        Report directory; the material goes to ``out_dir/<slug>/`` (created here).
    material, name : str, optional
        The member of ``source`` and the material's name in the report (default: the
        reference's ``name``, else ``material``, else ``source``).
    **options
        :class:`CompareOptions`.
    """
    opts = CompareOptions(**options)
    reference = resolve_reference(source, material)
    mat_name = name or getattr(reference, "name", None) or (material or str(source))
    opts.render_options = dict(opts.render_options or {})
    opts.fit_options = dict(opts.fit_options or {})
    opts.measured = dict(opts.measured or {})
    specs, notes = scene_suite(opts.scene if opts.scene is not None else opts.scenes,
                               opts.render_options.get("envmap"))
    rendered = opts.spp_batch * opts.batch_count
    if rendered != int(opts.spp):
        notes = [*notes, f"{int(opts.spp)} samples per pixel asked, {rendered} rendered: "
                         f"{opts.batch_count} batches of {opts.spp_batch}"]
    c = Comparison(source, reference, mat_name, Path(out_dir), _model_entries(models),
                   list(specs), opts, list(notes))
    c.folder.mkdir(parents=True, exist_ok=True)
    return c


def _convergence(model) -> dict | None:
    """How the fit went (:func:`brdffit.fit.result.fit_result`) and its history, thinned to
    at most 120 points, for the report's convergence plot: the objective per iteration
    (NPF AWLS) or the relative change of the power iteration (tabulated)."""
    try:
        res = fit_result(model)
    except ValueError:
        return None
    info = res.fit_info
    hist, what = None, None
    if isinstance(info.get("history"), list) and len(info["history"]) > 1:
        hist, what = info["history"], "objective"
    elif isinstance(info.get("relative_change"), list) and info["relative_change"]:
        hist, what = info["relative_change"], "relative change"
    out = {"success": res.success, "converged": res.converged, "message": res.message,
           "nit": res.nit, "fun": res.fun, "time": res.time}
    if hist is not None:
        h = np.asarray([x for x in hist if isinstance(x, (int, float))], float)
        if h.size > 1:
            idx = np.unique(np.linspace(0, h.size - 1, min(120, h.size)).round().astype(int))
            out["history"] = {"quantity": what, "iteration": idx.tolist(),
                              "value": h[idx].tolist()}
    return out


def _obtain_model(c: Comparison, label: str, what, rec: dict):
    """The BRDF of one model entry: ``what`` itself (a BRDF), loaded (a fit file) or fitted
    to the reference (a model name); ``None`` when the model is skipped (an isotropic-only
    model of an anisotropic reference). Fills ``rec``'s ``origin`` and ``fit_time``."""
    if hasattr(what, "eval"):
        rec["fit_time"], rec["origin"] = None, "given"
        return what
    if isinstance(what, (str, Path)) and str(what).endswith(".npz"):
        model = load_fit(what)
        rec["origin"] = f"loaded {what}"
        rec["loaded_from"] = str(what)
        info = getattr(model, "fit_info", None) or {}
        rec["fit_time"] = _num(info.get("time", info.get("time_s")))  # NPF: time_s
        return model
    if is_isotropic_only(str(what)) and not getattr(c.reference, "isotropic", False):
        rec.update(status="skipped", error=f"{what} fits isotropic BRDFs only")
        return None
    c.say(f"{c.material}: fitting {label}")
    model, rec["fit_time"] = fit_model(str(what), c.reference, c.options.fit_options.get(label))
    rec["origin"] = "fitted"
    return model


def _describe_model(rec: dict, model, measured: Mapping) -> None:
    """The model's class, parameters, validity checks (``measured["validity"]`` when given)
    and, for a fit, how it went."""
    rec["model_class"] = type(model).__name__
    rec["params"] = model_params(model)
    rec["validity"] = (list(measured["validity"]) if "validity" in measured
                       else [v.as_dict() for v in check_validity(model)])
    info = getattr(model, "fit_info", None)
    if info:
        rec["fit_info"] = small_json(dict(info))
        rec["convergence"] = _convergence(model)


def _save_model(c: Comparison, label: str, model, rec: dict) -> None:
    """Save a fitted model to ``fits/<label>.npz`` (fit files only; a failure is a warning)."""
    try:
        if isinstance(model, SerializableModel) and model.fit_kind:
            fp = save_fit(model, c.folder / "fits" / f"{_safe_name(label)}.npz",
                          source=getattr(c.reference, "source", None))
            rec["fit_file"] = f"fits/{fp.name}"
            rec["table_bytes"] = table_bytes(model)
    except Exception as exc:  # noqa: BLE001 – saving is a convenience
        rec.setdefault("warnings", []).append(f"could not save fit: {exc}")


def fit_models(c: Comparison) -> Comparison:
    """Fit, load or take each model of ``c`` (:attr:`Comparison.fitted`) and describe it
    (:attr:`Comparison.records`: origin, fit time, parameters, validity, convergence, fit
    file); fits are saved unless ``options.save_fits`` is false. A model that fails is
    recorded with its error and traceback (``status="failed"``); one that does not apply to
    the reference is ``"skipped"``."""
    for label, what in c.models:
        rec: dict[str, Any] = {"name": label, "status": "ok"}
        c.records.append(rec)
        try:
            model = _obtain_model(c, label, what, rec)
            if model is None:
                continue
            c.fitted[label] = model
            _describe_model(rec, model, c.options.measured.get(label, {}))
            if c.options.save_fits and rec["origin"] == "fitted":
                _save_model(c, label, model, rec)
        except Exception as exc:  # noqa: BLE001 – one failing model must not sink the report
            rec.update(status="failed", error=f"fit/load failed: {type(exc).__name__}: {exc}")
            rec["traceback"] = traceback.format_exc(limit=4)
    return c


def _start_result(c: Comparison) -> None:
    """``result.json``'s head: the material, its source, the render settings, the models'
    records and the notes."""
    o = c.options
    settings = {"scenes": [sp.name for sp in c.scenes], "spp": int(o.spp_batch * o.batch_count),
                "batches": int(o.batch_count), "spp_per_batch": int(o.spp_batch),
                "resolution": int(o.resolution), "seed": int(o.seed),
                **{k: (v if isinstance(v, (int, float, str, bool)) else str(v))
                   for k, v in o.render_options.items()}}
    c.result = {"material": c.material, "slug": c.slug,
                "source": getattr(c.reference, "source", None) or (
                    str(c.source) if not hasattr(c.source, "eval") else None),
                "scene": settings, "models": c.records,
                "measured_domain": getattr(c.reference, "measured_domain", None),
                "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    if c.notes:
        c.result["notes"] = list(c.notes)


def _make_scene_engine(c: Comparison):
    """The engine that renders the scenes (Mitsuba CRN, or ``options.renderer`` per model);
    ``None`` when the renderer died while being prepared: every scene and model then fails
    with that error."""
    ok = {r["name"]: c.fitted[r["name"]] for r in c.records if r["status"] == "ok"}
    renderer = c.options.renderer or _default_renderer()
    try:
        if renderer is None:
            engine, note = make_engine(c.reference, ok, c.records, c.say, c.material,
                                        c.options.isolate_renders)
            if note:
                c.result.setdefault("notes", []).append(note)
            c.result["proposal"] = engine.proposal_dict
            return engine
        return CallbackEngine(renderer, c.reference, ok, c.options.render_options)
    except ChildCrashed as exc:  # the renderer died while being prepared: nothing renders
        c.result["render_error"] = str(exc)
        c.say(f"{c.material}: {exc}")
        for spec in c.scenes:
            c.result["scenes"].append(spec.as_dict() | {"error": str(exc)})
        for rec in c.records:
            if rec["status"] == "ok":
                rec.update(status="failed", error=f"render failed: {exc}")
        return None


def _scene_failed(c: Comparison, srec: dict, error: str) -> None:
    """Scene ``srec`` could not be measured: its ``error``, and every model's entry says so."""
    srec["error"] = error
    for entries in c.scene_entries.values():
        entries.append({"scene": srec["name"], "error": error})


def _tone(c: Comparison, spec: SceneSpec, ref_mean, mask) -> tuple[float, float]:
    """The scene's exposure and γ (``options.exposure``, ``options.gamma``)."""
    exposure, gamma = c.options.exposure, c.options.gamma
    if exposure == "scene":
        exp_s = float(spec.exposure)
    elif exposure == "auto":
        exp_s = float(_tonemapper()[0](ref_mean, mask))
    else:
        exp_s = float(exposure)
    return exp_s, float(spec.gamma if gamma is None else gamma)


def _render_scene(c: Comparison, engine, i: int, spec: SceneSpec):
    """Render scene ``i`` (``batches`` seeds, the reference and every model): a
    :class:`_Scene` and the models' stacks and render failures, or ``None`` when the scene
    failed (its record and the models' entries say why)."""
    o = c.options
    seeds = [int(o.seed) + i * o.batch_count + k for k in range(o.batch_count)]
    c.say(f"{c.material}: rendering {spec.name} ({o.batch_count} × {o.spp_batch} spp, "
          f"{len(engine.labels)} models)")
    srec: dict[str, Any] = spec.as_dict() | {"seeds": seeds}
    c.result["scenes"].append(srec)
    t0, c0 = time.perf_counter(), cpu_seconds(engine)
    try:
        stacks, alpha, failures = engine.render_scene(spec, seeds, o.spp_batch, o.resolution)
    except Exception as exc:  # noqa: BLE001 – the reference of this scene cannot be rendered
        _scene_failed(c, srec, str(exc) if isinstance(exc, ChildCrashed)
                      else f"{type(exc).__name__}: {exc}")
        return None
    srec["render_seconds"] = time.perf_counter() - t0
    srec["render_cpu_seconds"] = cpu_seconds(engine) - c0
    ref_stack = stacks.pop(None)
    mask = alpha >= 0.999
    ref_mean = ref_stack.mean(0)
    if not mask.any():
        _scene_failed(c, srec, "the reference has no foreground pixel in this scene")
        return None
    exp_s, gam = _tone(c, spec, ref_mean, mask)
    srec["exposure"], srec["gamma"] = exp_s, gam
    return _Scene(spec, srec, ref_stack, ref_mean, mask, exp_s, gam), stacks, failures


def _measure_reference(c: Comparison, engine, i: int, sc: _Scene) -> None:
    """The scene's reference picture (PNG, EXR) and converged peak (the PSNR numerator,
    ``engine.peak``; the batches' own maximum, with a warning, when that fails)."""
    srec, o = sc.record, c.options
    ref_png = f"{_safe_name(sc.spec.name)}-reference.png"
    _write_png(c.folder / ref_png, sc.tonemap(sc.ref_mean))
    srec["reference"] = {"png": ref_png, "foreground_pixels": int(sc.mask.sum())}
    t1, c1 = time.perf_counter(), cpu_seconds(engine)
    try:
        srec["reference"] |= engine.peak(sc.spec, sc.ref_stack, sc.mask, o.resolution,
                                         seed=int(o.seed) + 100000 + 16 * i)
    except Exception as exc:  # noqa: BLE001 – the batches' own peak is the fallback
        srec["reference"] |= peak_from_batches(sc.ref_stack, sc.mask)
        srec.setdefault("warnings", []).append(
            f"the peak was not converged ({type(exc).__name__}: {exc}); the batches' "
            "maximum is used")
    srec["peak_seconds"] = time.perf_counter() - t1
    srec["peak_cpu_seconds"] = cpu_seconds(engine) - c1
    exr = ref_png.replace(".png", ".exr")
    if o.write_exr in (True, "reference") and _write_exr(c.folder / exr, sc.ref_mean) is not None:
        srec["reference"]["exr"] = exr


def _measure_model(c: Comparison, sc: _Scene, refs: tuple, label: str, stack,
                   entry: dict) -> None:
    """One model in one scene: PSNR with standard errors (:func:`.metrics.crn_psnr`; the
    total ``psnr_se`` adds the peak's residual uncertainty, ``psnr_se_mse`` is the part that
    separates two models of the comparison), mean dE2000, and its pictures. ``refs``: the
    scene's :class:`.metrics.CRNReference` and :class:`.metrics.DeltaE2000`."""
    crn_ref, de_ref = refs
    peak_se = float(sc.record["reference"].get("peak_psnr_se", 0.0))
    est = crn_ref.psnr(stack, peak=sc.record["reference"]["peak"])
    entry.update({k: est[k] for k in ("psnr", "mse", "mse_se", "noise_mse",
                                      "resolved", "bound", "psnr_plain")})
    entry["psnr_se_mse"] = est["psnr_se"]
    entry["psnr_se"] = float(np.hypot(est["psnr_se"], peak_se)) if np.isfinite(
        est["psnr"]) else est["psnr_se"]
    img = stack.mean(0)
    de = de_ref.image(img)
    entry["mean_de2000"] = float(np.nanmean(de))
    fn = f"{_safe_name(sc.spec.name)}-{_safe_name(label)}"
    _write_png(c.folder / f"{fn}.png", sc.tonemap(img))
    _write_png(c.folder / f"{fn}_de2000.png", M.colorize_delta_e(de))
    entry["png"], entry["de_png"] = f"{fn}.png", f"{fn}_de2000.png"
    if c.options.write_exr is True and _write_exr(c.folder / f"{fn}.exr", img) is not None:
        entry["exr"] = f"{fn}.exr"


def _measure_scene(c: Comparison, sc: _Scene, stacks, failures: Mapping[str, str]) -> None:
    """Every model's entry of one rendered scene (:func:`_measure_model`; a model that failed
    to render or to be measured gets an ``error``)."""
    refs = (M.CRNReference(sc.ref_stack, sc.mask),
            M.DeltaE2000(sc.ref_mean, sc.mask, tonemap=sc.tonemap))
    for label, entries in c.scene_entries.items():
        entry: dict[str, Any] = {"scene": sc.spec.name}
        entries.append(entry)
        if label in failures:
            entry["error"] = failures[label]
            continue
        try:
            _measure_model(c, sc, refs, label, stacks[label], entry)
        except Exception as exc:  # noqa: BLE001
            entry["error"] = f"{type(exc).__name__}: {exc}"


_ESTIMATOR = ("crn-u-statistic-jackknife: per scene, MSE of (model − reference) "
              "from batches rendered with common random numbers, unbiased "
              "U-statistic over pairs of batches, jackknife standard error, delta "
              "method to dB, plus the converged reference peak's residual "
              "uncertainty (psnr_se_mse: without it, the part that separates two "
              "models of this comparison); psnr = mean over scenes, "
              "psnr_se = sqrt(Σ se²)/S")


def _render_summary(c: Comparison, engine, seconds: float, cpu: float) -> None:
    """``result.json``'s timing, reference picture, tone map and estimator."""
    c.result["timing"] = {"render_seconds": seconds, "render_cpu_seconds": cpu,
                          "setup_seconds": getattr(engine, "setup_seconds", None),
                          "renders_isolated": isinstance(engine, IsolatedCRNEngine)}
    first = next((s for s in c.result["scenes"] if "reference" in s), None)
    c.result["reference"] = {
        "png": first["reference"]["png"] if first else None, "render_time": seconds,
        "foreground_pixels": first["reference"]["foreground_pixels"] if first else 0}
    if first:
        c.result["exposure"], c.result["gamma"] = first["exposure"], first["gamma"]
    c.result["estimator"] = _ESTIMATOR


def render_scenes(c: Comparison) -> Comparison:
    """Render every scene of ``c`` with the reference and every model that is ``ok``, and
    measure them per scene (``result["scenes"]``, :attr:`Comparison.scene_entries`): the
    batches of a scene are measured as soon as they are rendered and then dropped. Starts
    ``result.json`` (:attr:`Comparison.result`)."""
    _start_result(c)
    c.result["scenes"] = []
    t_all, c_all = time.perf_counter(), time.process_time()  # the child's CPU starts at 0
    engine = _make_scene_engine(c)
    c.scene_entries = {k: [] for k in (engine.labels if engine is not None else ())}
    for i, spec in enumerate(c.scenes if engine is not None else ()):
        rendered = _render_scene(c, engine, i, spec)
        if rendered is None:
            continue
        sc, stacks, failures = rendered
        _measure_reference(c, engine, i, sc)
        _measure_scene(c, sc, stacks, failures)
    t_render, c_render = time.perf_counter() - t_all, cpu_seconds(engine) - c_all
    if engine is not None and hasattr(engine, "close"):
        engine.close()
    _render_summary(c, engine, t_render, c_render)
    return c


def _summarize_model(rec: dict, entries: list[dict]) -> bool:
    """A rendered model's summary over its scenes (``psnr`` ± ``psnr_se``, mean dE2000, the
    first scene's pictures); ``False`` (and the record failed) when no scene measured it."""
    rec["scenes"] = entries
    rec["render_time"] = None  # all models are rendered in the same passes
    good = [e for e in entries if "error" not in e]
    bad = [e for e in entries if "error" in e]
    if not good:
        rec.update(status="failed", error="render failed: " + "; ".join(
            f"{e['scene']}: {e['error']}" for e in bad))
        return False
    comb = M.combine_psnr(good)
    rec["psnr"], rec["psnr_se"] = comb["psnr"], comb["psnr_se"]
    rec["psnr_se_mse"] = M.combine_psnr(
        [e | {"psnr_se": e["psnr_se_mse"]} for e in good])["psnr_se"]
    if comb["bound"]:
        rec["psnr_bound"] = comb["bound"]
    rec["mean_de2000"] = float(np.mean([e["mean_de2000"] for e in good]))
    rec["png"], rec["de_png"] = good[0]["png"], good[0]["de_png"]
    if bad:
        rec.setdefault("warnings", []).append(
            "not rendered in " + ", ".join(f"{e['scene']} ({e['error']})" for e in bad)
            + "; psnr is the mean over the other scenes")
    return True


def measure_models(c: Comparison) -> Comparison:
    """Each rendered model's summary over the scenes (:func:`_summarize_model`) and its
    BRDF-space metrics (those of ``options.measured``, or :class:`.metrics.BRDFMetrics` with
    the reference prepared once; an error is recorded in ``brdf["errors"]``)."""
    bm = None
    for rec in c.records:
        if rec["status"] != "ok" or not _summarize_model(rec, c.scene_entries[rec["name"]]):
            continue
        known = c.options.measured.get(rec["name"], {})
        if "brdf" in known:
            rec["brdf"] = known["brdf"]
            continue
        try:
            if bm is None:
                c.say(f"{c.material}: preparing BRDF-space metrics")
                bm = M.BRDFMetrics(c.reference, c.options.brdf_metric_samples, c.options.seed,
                                   c.options.brdf_metrics)
                c.result["brdf_metrics_setup"] = bm.timings
            rec["brdf"] = bm.evaluate(c.fitted[rec["name"]])
        except Exception as exc:  # noqa: BLE001
            rec["brdf"] = {"errors": {"all": f"{type(exc).__name__}: {exc}"}}
    return c


def _write_plots(c: Comparison) -> dict[str, str]:
    """The lobes, factors and slices plots of the models that are ``ok`` (name → file); a
    plot that fails is a note."""
    ok = {r["name"]: c.fitted[r["name"]] for r in c.records if r["status"] == "ok"}
    plots: dict[str, str] = {}
    title = printable(c.material)
    for key, fn in (("lobes", lambda p: P.plot_lobes(c.reference, ok, p, title=title)),
                    ("factors", lambda p: P.plot_factors(ok, p, title=title)),
                    ("slices", lambda p: P.plot_slices(c.reference, ok, p, title=title))):
        if not ok:
            break
        try:
            if fn(c.folder / f"{key}.png") is not None:
                plots[key] = f"{key}.png"
        except Exception as exc:  # noqa: BLE001
            c.result.setdefault("notes", []).append(
                f"{key} plot failed: {type(exc).__name__}: {exc}")
    return plots


def write_report(c: Comparison) -> dict:
    """Write the plots, ``<slug>/result.json``, the material page and (``update_index``) the
    report index; returns the result."""
    c.result["plots"] = _write_plots(c)
    R.write_result(c.folder, c.result)
    P.plot_colorbar(c.out_dir / "assets" / "de_colorbar.png")
    R.write_material_page(c.out_dir, c.result)
    if c.options.update_index:
        R.write_index(c.out_dir)
    return c.result


def prepare(source, models: Sequence | Mapping = DEFAULT_MODELS, out_dir="report",
            **options) -> Comparison:
    """:func:`resolve_comparison` then :func:`fit_models`: the comparison with its models
    fitted, loaded or taken, ready for exports (:meth:`Comparison.fit_files`) and
    :func:`finish`."""
    return fit_models(resolve_comparison(source, models, out_dir, **options))


def finish(c: Comparison) -> dict:
    """:func:`render_scenes`, :func:`measure_models` and :func:`write_report`: the result."""
    return write_report(measure_models(render_scenes(c)))


def compare(source, models: Sequence | Mapping = DEFAULT_MODELS, out_dir="report",
            **options) -> dict:
    """Compare models against one reference BRDF and write its report page.

    Parameters
    ----------
    source, models, out_dir, material, name
        As :func:`resolve_comparison`.
    **options
        :class:`CompareOptions`.

    Returns
    -------
    dict
        The result that is also written to ``out_dir/<slug>/result.json``: per model
        ``psnr`` (mean over scenes, dB), ``psnr_se`` (its standard error, dB, including the
        reference peak's residual uncertainty; ``psnr_se_mse`` without it), ``scenes`` (per
        scene: ``psnr``, ``psnr_se``, ``mse``, ``mse_se``, … of :func:`.metrics.crn_psnr`,
        mean dE2000 and the pictures), and a top-level ``scenes`` list (name, map, exposure,
        reference picture and converged peak, render times); ``proposal`` (the sampling
        mixture fitted to the reference) and ``timing``.

    Notes
    -----
    No engine files are written: :func:`brdffit.batch.compare_with_exports` writes them
    between :func:`prepare` and :func:`finish`.
    """
    return finish(prepare(source, models, out_dir, **options))


def compare_many(sources: Iterable, models=DEFAULT_MODELS, out_dir="report", *,
                 run: Callable[..., dict] | None = None, **kw) -> list[dict]:
    """:func:`compare` for several inputs (each a BRDF or spec), then one index rebuild.

    ``run`` compares one material, with :func:`compare`'s arguments (default
    :func:`compare`; :func:`brdffit.batch.compare_with_exports` adds the engine files). A
    material that fails entirely (cannot be loaded or the reference cannot be rendered) is
    reported in the returned list as ``{"material": ..., "error": ...}`` and skipped.
    """
    run = run or compare
    results = []
    for src in sources:
        try:
            results.append(run(src, models, out_dir, update_index=False, **kw))
        except (BRDFError, OSError, ValueError, RuntimeError, KeyError) as exc:
            results.append({"material": str(getattr(src, "name", src)),
                            "error": f"{type(exc).__name__}: {exc}"})
    R.write_index(out_dir)
    return results


def _num(x):
    try:
        return None if x is None else float(x)
    except (TypeError, ValueError):
        return None
