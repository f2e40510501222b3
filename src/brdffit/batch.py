"""Batch fitting of whole databases on Dask (local cluster or an existing scheduler).

One task per (material, model). A task loads the material *on the worker* (only its load spec
travels through the scheduler), fits the model, saves the fit and computes BRDF-space metrics,
then writes its record; everything is written atomically, the record last, so a record on disk
means the task's outputs are complete. The tasks are fed to the workers one per thread at a
time, the next task of a material to the thread that ran its previous one, so that a worker
loads and prepares a material once (:class:`_Feeder`). Output layout (``<material>`` and
``<model>`` are :func:`brdffit.paths.slug` of the names; records and the report keep the
readable names)::

    OUT/fits/<material>/<model>.npz       the fitted model (brdffit fit file)
    OUT/records/<material>/<model>.json   status, metrics, parameters, timings, task key,
                                          SHA-256 of the fit file
    OUT/summary.csv, OUT/summary.json     one row per material × model
    OUT/.lock                             who runs a batch on OUT (see *Locking*)

**Rendering (optional).** With :class:`RenderSettings`, each material also gets one render
task, submitted once its fits are done, that renders the reference and every fitted model
with Mitsuba 3 (:func:`compare_with_exports` on the saved fit files, no refitting) and
writes its report page with the fits' engine files; the run ends by rebuilding the report
index over the whole database::

    OUT/report/<material>/index.html      renderings, dE2000 maps, plots, metrics
    OUT/report/index.html, summary.json   every material; per-model PSNR/dE2000, wins/ties
    OUT/renders/<material>.json           render record (status, PSNR/dE2000, task key)

**Names.** Material names are unique within a batch: :func:`enumerate_materials` names a
file by its stem, and by its file name (then its spec) when stems collide (``nan.bin`` and
``nan.binary``); :func:`run_batch` refuses two different specs under one name up front.

**Resuming.** Each task has a key: a hash of the load spec, the checksum of the file behind
it, the model name, the options and the fit-file format version. A re-run skips a task whose
record exists with the same key (``ok``, or ``failed`` unless ``retry_failed``) and redoes it
when the key changed, when the record is unreadable or malformed (with a warning), and — for
``ok`` fits — when the fit file is missing or its SHA-256 differs from the record's (records
of older versions without a checksum: when the file does not load). Killing a run loses at
most the tasks in flight. A render task's key covers the keys of the fits it renders and the
render settings; its report page must exist.

**Faults.** A task that kills its worker (out of memory, SIGKILL) is retried on another
worker by Dask, up to ``retries`` more times on the local cluster (the scheduler's
``distributed.scheduler.allowed-failures`` on an external one), then recorded ``failed``
with "worker died (out of memory or killed) N times"; the batch goes on. A task whose
result is lost for another reason (e.g. the connection to the scheduler) is reported as
lost and not recorded, so the next run redoes it.

**Locking.** :func:`run_batch` holds an exclusive ``flock`` on ``OUT/.lock`` (holder's pid,
host, start time and command inside) for the whole run: a second batch on the same folder is
refused with :class:`OutputLocked` naming the holder (``brdffit batch`` exits 2), or waits
with ``wait_lock=True``. The kernel releases the lock when the holder dies, so a killed
batch never leaves a stale lock. (Over NFS this relies on the server's lock manager.)

**Clusters.** Every path is made absolute on the client (the output folder and the files of
the load specs), then a probe runs on every worker before anything is submitted: the worker
must see a file the client just wrote to ``OUT`` (a shared filesystem), be able to write
there, read every data file, and run the same brdffit and fit-file format versions;
otherwise :class:`BatchError` says which worker and why (``brdffit batch`` exits 1).
Workers that join after the probe are not checked.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import datetime
import functools
import hashlib
import json
import logging
import math
import os
import time
import traceback
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from ._atomic import atomic_write
from ._cpus import usable_cpus
from ._json import json_default
from ._malloc import WORKER_MALLOC_ENV  # the local workers' malloc settings
from .errors import BRDFError, csv_cell, printable
from .paths import check_unique, slug
from .progress import describe, listening
from .batch_summary import COLUMNS, RECOMMENDATION_RULE, summary_rows
from .evaluation.compare import Comparison, finish, prepare
from .evaluation.metrics import BRDFMetrics
from .evaluation.report import write_index
from .export import report_exports
from .fit.registry import fit_model, is_isotropic_only, model_params
from .io import find_data_file, resolve_spec
from .io.fitfile import FORMAT_VERSION, FORMAT_VERSION as fmt, load_fit, save_fit, source_checksum
from .io.nbrdf import list_materials
from .loading import load
from .synthetic import list_synthetic
from . import __version__
from .evaluation.validity import check_validity
import brdffit

__all__ = ["Task", "RenderSettings", "RenderTask", "enumerate_materials", "make_tasks",
           "make_render_tasks", "run_task", "run_render_task", "run_batch", "read_records",
           "write_summary", "lock_output", "BatchError", "OutputLocked", "TIMING_FIELDS",
           "DEFAULT_RETRIES", "PROGRESS_TOPIC"]

_log = logging.getLogger("brdffit.batch")

#: Record fields that legitimately differ between two runs of the same task (the fit file
#: holds its creation time, hence its checksum).
TIMING_FIELDS = ("fit_time_s", "metrics_time_s", "metrics_seconds", "wall_time_s", "started",
                 "finished", "worker", "fit_sha256")

#: Statuses of finished work (not redone on resume, not counted as failures).
DONE = ("ok", "skipped")

#: Local cluster: how many more times a task that killed its worker is tried.
DEFAULT_RETRIES = 2

_MEASURED_SUFFIXES = (".binary", ".bsdf", ".bin", ".h5")

#: Dask event topic of the progress inside running tasks (:mod:`brdffit.progress`)
PROGRESS_TOPIC = "brdffit-progress"
#: a running task sends at most one progress event per this many seconds
PROGRESS_INTERVAL_S = 1.0
#: ``OUT/batch.log`` gets at most one progress line per task per this many seconds
LOG_INTERVAL_S = 10.0
LOG_NAME = "batch.log"


class BatchError(BRDFError):
    """The batch cannot run as asked (names, cluster, output folder)."""


class OutputLocked(BatchError):
    """Another batch holds the lock of the output folder."""


def _warn(message: str) -> None:
    _log.warning("brdffit: warning: %s", message)


@contextlib.contextmanager
def _forward_progress(material: str, kind: str):
    """Inside a Dask worker, send the task's progress events (:mod:`brdffit.progress`) to
    the client under :data:`PROGRESS_TOPIC`; elsewhere, do nothing."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):
        yield
        return
    def send(event: dict) -> None:
        worker.log_event(PROGRESS_TOPIC, {**{k: v for k, v in event.items()
                                             if isinstance(v, (str, int, float, bool, type(None)))},
                                          "material": material, "model": kind})

    with listening(send, min_interval=PROGRESS_INTERVAL_S):
        yield




@dataclasses.dataclass(frozen=True)
class Task:
    """One unit of work: fit ``model`` to the material loaded from ``spec``."""

    material: str
    spec: str
    model: str
    options: tuple = ()  # sorted (key, value) pairs, hashable and JSON-able

    def options_dict(self) -> dict:
        return dict(self.options)

    def key(self) -> str:
        payload = {"spec": self.spec, "source_sha256": source_checksum(self.spec),
                   "model": self.model, "options": self.options_dict(),
                   "fit_format": FORMAT_VERSION}
        return _hash(payload)

    def fit_path(self, out: Path) -> Path:
        return Path(out) / "fits" / slug(self.material) / f"{slug(self.model)}.npz"

    def record_path(self, out: Path) -> Path:
        return Path(out) / "records" / slug(self.material) / f"{slug(self.model)}.json"


@dataclasses.dataclass(frozen=True)
class RenderSettings:
    """The render stage of a batch: the scenes (a suite name such as ``"paper"``, one scene
    name or a comma-separated list), samples per pixel per scene (all batches together), the
    number of independent batches (for the standard error), image size and seed — as
    :func:`brdffit.evaluation.compare.compare`, whose defaults these are."""

    scenes: str = "paper"
    spp: int = 64
    resolution: int = 256
    seed: int = 0
    batches: int = 8

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class RenderTask:
    """Render the reference and the fits of one material and write its report page."""

    material: str
    spec: str
    fits: tuple  # (model, fit-task key) pairs, in the batch's model order
    settings: RenderSettings = RenderSettings()

    def key(self) -> str:
        payload = {"spec": self.spec, "source_sha256": source_checksum(self.spec),
                   "fits": list(self.fits), "render": self.settings.as_dict()}
        return _hash(payload)

    def record_path(self, out: Path) -> Path:
        return Path(out) / "renders" / f"{slug(self.material)}.json"


def _hash(payload: dict) -> str:
    """A task key: 16 hex digits of the SHA-256 of the canonical JSON of ``payload``."""
    blob = json.dumps(payload, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def _file_sha256(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


# -- materials ------------------------------------------------------------------------------
def _absolute_spec(spec: str, base: Path | None = None) -> str:
    """``spec`` with its file made absolute (as the client finds it: working directory, data
    search path, then ``base``), so that workers elsewhere load the same file; unchanged when
    it is ``synthetic:`` or names no existing file (the task then fails with that error)."""
    if spec.startswith("synthetic:"):
        return spec
    for candidate in (spec, str(base / spec) if base is not None else None):
        if candidate is None:
            continue
        try:
            _, path, member = resolve_spec(candidate)
        except BRDFError:
            continue
        path = os.path.abspath(path)
        return f"{path}:{member}" if member is not None else path
    return spec


def _unique_names(entries: list[tuple[list[str], str]], where: str) -> list[tuple[str, str]]:
    """``(name, spec)`` pairs from ``(candidate names, spec)``: identical specs are kept once,
    and materials whose names collide move on to their next, more specific candidate (stem →
    file name → spec) until every name is unique."""
    items, seen = [], set()
    for cands, spec in entries:
        if spec in seen:
            _warn(f"{where}: {spec} listed twice; fitting it once")
            continue
        seen.add(spec)
        items.append([cands, spec, 0])
    while True:
        groups: dict[str, list] = {}
        for it in items:
            groups.setdefault(it[0][it[2]], []).append(it)
        bumped = False
        for grp in groups.values():
            if len(grp) > 1:
                for it in grp:
                    if it[2] < len(it[0]) - 1:
                        it[2] += 1
                        bumped = True
        if not bumped:
            break
    pairs = [(it[0][it[2]], it[1]) for it in items]
    _check_materials(pairs, where)
    return pairs


def _check_materials(pairs: Iterable[tuple[str, str]], where: str = "batch") -> None:
    """Refuse two specs under one material name, or two names sharing a folder."""
    specs: dict[str, str] = {}
    for name, spec in pairs:
        if specs.setdefault(name, spec) != spec:
            raise BatchError(f"{where}: two materials are named {name!r} "
                             f"({specs[name]} and {spec}); material names must be unique")
    try:
        check_unique(specs, "materials")
    except ValueError as exc:
        raise BatchError(f"{where}: {exc}") from None


def _synthetic_names(body: str) -> list[str]:
    body = body.strip()
    if body.startswith("[") and body.endswith("]"):  # synthetic:[a,b] as in the help text
        body = body[1:-1]
    names = [n.strip() for n in body.split(",") if n.strip()]
    known = list(list_synthetic())
    unknown = [n for n in names if n not in known]
    if unknown:
        raise BatchError(f"synthetic:{body}: unknown synthetic material(s) "
                         f"{', '.join(map(repr, unknown))}; available: {', '.join(known)}")
    return names or known


def enumerate_materials(source, only: Sequence[str] | None = None,
                        limit: int | None = None) -> list[tuple[str, str]]:
    """``(material name, load spec)`` pairs of a database.

    ``source`` is a folder of measured files (MERL ``.binary``, RGL ``.bsdf``, UTIA ``.bin``,
    Neural-BRDF ``.h5``), a Neural-BRDF ``.zip`` collection, a list file (one load spec per
    line, ``#`` comments; relative paths as :func:`brdffit.io.load` finds them, else relative
    to the list file), or ``synthetic:`` / ``synthetic:a,b`` / ``synthetic:[a,b]`` for the
    built-in materials. File specs are made absolute. Names are unique: a file is named by its
    stem, or by its file name when stems collide (then by its spec). ``only`` keeps the named
    materials (an unknown name is an error); ``limit`` keeps the first N.
    """
    src = str(source)
    if src.startswith("synthetic:"):
        pairs = [(n, f"synthetic:{n}") for n in dict.fromkeys(_synthetic_names(src[10:]))]
    else:
        path = find_data_file(Path(src))
        if path is None:
            raise BatchError(f"{src}: no such file or folder")
        path = Path(os.path.abspath(path))
        if path.is_dir():
            files = sorted(p for p in path.iterdir()
                           if p.suffix in _MEASURED_SUFFIXES and p.is_file())
            if not files:
                raise BatchError(f"{path}: expected measured BRDF files "
                                 f"({', '.join(_MEASURED_SUFFIXES)}), found none")
            pairs = _unique_names([([p.stem, p.name, str(p)], str(p)) for p in files], str(path))
        elif path.suffix == ".zip":
            pairs = _unique_names([([m], f"{path}:{m}") for m in list_materials(path)], str(path))
        else:
            entries = []
            try:
                text = path.read_text(encoding="utf-8")
            except UnicodeDecodeError:
                raise BatchError(f"{path}: expected a text list of load specs, found binary "
                                 f"data") from None
            for line in text.splitlines():
                line = line.split("#", 1)[0].strip()
                if line:
                    last = line.rsplit(":", 1)[-1] if ":" in line else Path(line).name
                    spec = _absolute_spec(line, path.parent)
                    entries.append(([Path(last).stem, Path(last).name, line, spec], spec))
            if not entries:
                raise BatchError(f"{path}: expected a list of load specs, found no entries")
            pairs = _unique_names(entries, str(path))
    if only:
        known = {n for n, _ in pairs}
        missing = [n for n in only if n not in known]
        if missing:
            raise BatchError(f"{src}: unknown material(s) {missing}; "
                             f"{len(known)} available, e.g. {sorted(known)[:5]}")
        pairs = [p for p in pairs if p[0] in set(only)]
    return pairs[:limit] if limit else pairs


def make_tasks(materials: Iterable[tuple[str, str]], models: Sequence[str],
               options: dict[str, dict] | None = None) -> list[Task]:
    """The cross product of materials and models (``options`` per model name)."""
    options = options or {}
    return [Task(name, spec, model, tuple(sorted((options.get(model) or {}).items())))
            for name, spec in materials for model in models]


def make_render_tasks(tasks: Sequence[Task], settings: RenderSettings) -> list[RenderTask]:
    """One :class:`RenderTask` per material of ``tasks`` (covering all its models)."""
    fits: dict[tuple[str, str], list] = {}
    for t in tasks:
        fits.setdefault((t.material, t.spec), []).append((t.model, t.key()))
    return [RenderTask(m, spec, tuple(f), settings) for (m, spec), f in fits.items()]


# -- records --------------------------------------------------------------------------------
def _write_json(path: Path, obj: dict) -> None:
    with atomic_write(path, "w") as fh:
        json.dump(obj, fh, indent=1, sort_keys=True, default=json_default)


def _base_record(task: Task | RenderTask) -> dict[str, Any]:
    import socket

    record: dict[str, Any] = {"material": task.material, "spec": task.spec,
                              "key": task.key(),
                              "worker": f"{socket.gethostname()}:{os.getpid()}",
                              "started": datetime.datetime.now().isoformat(timespec="milliseconds")}
    if isinstance(task, Task):
        record.update(model=task.model, options=task.options_dict())
    else:
        record.update(model="render", settings=task.settings.as_dict())
    return record


@functools.lru_cache(maxsize=2)
def _load_reference(spec: str):
    """The measured BRDF of ``spec``, loaded once per worker process for the consecutive
    tasks of one material (its models are submitted one after the other); with its MERL-grid
    tabulation memoised (:func:`brdffit.grid.tabulate_merl_grid`) the fits and metrics of a
    material share both. Two entries: the material of each of two interleaved task streams."""
    return load(spec)


@functools.lru_cache(maxsize=2)
def _reference_metrics(spec: str):
    """The BRDF metrics of ``spec``'s reference, prepared once per worker process (its
    evaluation at the Sobol pairs, the MERL-grid L2 quadrature and the compressive objective's
    samples and weights: ~1 s per model otherwise) and shared by the consecutive tasks of one
    material, like :func:`_load_reference`."""
    return BRDFMetrics(_load_reference(spec))


def run_task(task: Task, out_dir, metrics: bool = True) -> dict:
    """Run one task in this process and return its record (also written to disk).

    A failure of loading, fitting or measuring is caught and recorded (``status: failed``
    with the error), so one bad material never stops a batch.
    """
    out = Path(out_dir)
    record = _base_record(task)
    t0 = time.perf_counter()
    try:
        reference = _load_reference(task.spec)
        if is_isotropic_only(task.model) and not getattr(reference, "isotropic", False):
            record["status"] = "skipped"
            record["error"] = f"{task.model} fits isotropic BRDFs only; {task.material} is anisotropic"
            raise _Skip
        with _forward_progress(task.material, task.model):
            model, record["fit_time_s"] = fit_model(task.model, reference, task.options_dict())
        fit_path = task.fit_path(out)
        save_fit(model, fit_path, source=task.spec, options=task.options_dict())
        record["fit_file"] = fit_path.relative_to(out).as_posix()
        record["fit_sha256"] = _file_sha256(fit_path)
        record["params"] = model_params(model)
        record["warnings"] = [v.as_dict() for v in check_validity(model)]
        if metrics:
            t_m = time.perf_counter()
            bm = _reference_metrics(task.spec)
            record["metrics"] = bm.evaluate(model)
            record["error_domain"] = getattr(bm.reference, "measured_domain", None)
            record["metrics_seconds"] = record["metrics"].pop("seconds", None)
            record["metrics_time_s"] = time.perf_counter() - t_m
        record["status"] = "ok"
    except _Skip:
        pass
    except Exception as exc:  # noqa: BLE001 – recorded, the batch goes on
        _record_failure(record, exc)
    return _finish(record, t0, task.record_path(out))


def _record_failure(record: dict, exc: Exception) -> None:
    record["status"] = "failed"
    record["error"] = f"{type(exc).__name__}: {exc}"
    record["traceback"] = traceback.format_exc(limit=8)


def _finish(record: dict, t0: float, path: Path) -> dict:
    """Time-stamp ``record`` and write it atomically (the last output of a task)."""
    record["wall_time_s"] = time.perf_counter() - t0
    record["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    _write_json(path, record)
    return record


class _Skip(Exception):
    """The task does not apply to this material (recorded as ``skipped``, not failed)."""


def _read_record(path: Path, quiet_missing: bool = True) -> tuple[dict | None, str | None]:
    """``(record, None)``, or ``(None, why)`` when the file is missing (why ``None``),
    unreadable, not JSON, or not a record (a JSON object with string ``material``, ``model``
    and ``status``)."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return None, None
    except (OSError, UnicodeDecodeError) as exc:
        return None, f"unreadable ({exc})"
    try:
        rec = json.loads(text)
    except ValueError as exc:
        return None, f"not JSON ({exc})"
    if not isinstance(rec, dict):
        return None, f"expected a JSON object, found {type(rec).__name__}"
    missing = [k for k in ("material", "model", "status") if not isinstance(rec.get(k), str)]
    if missing:
        return None, f"expected the fields {', '.join(missing)}, found none"
    return rec, None


def export_fits(comparison: Comparison) -> None:
    """Write the engine files (:func:`brdffit.export.report_exports`: JSON, glTF, MaterialX)
    of every model of ``comparison`` that has a fit file, under ``<slug>/exports/``, and
    record them for its page (:meth:`~brdffit.evaluation.compare.Comparison.add_exports`;
    one that raises is recorded by
    :meth:`~brdffit.evaluation.compare.Comparison.exports_failed`)."""
    for label, model in comparison.fit_files().items():
        try:
            paths = report_exports(model, comparison.folder / "exports", comparison.stem(label))
        except Exception as exc:  # noqa: BLE001 – recorded on the model, the others go on
            comparison.exports_failed(label, exc)
        else:
            comparison.add_exports(label, paths)


def compare_with_exports(source, models, out_dir, **options) -> dict:
    """:func:`brdffit.evaluation.compare.compare` with the engine files of the fits
    (:func:`export_fits`, between :func:`~brdffit.evaluation.compare.prepare` and
    :func:`~brdffit.evaluation.compare.finish`) linked from the material page and listed in
    each model's ``exports`` of ``result.json``."""
    comparison = prepare(source, models, out_dir, **options)
    export_fits(comparison)
    return finish(comparison)


def _measured_by_fit_task(rec: dict) -> dict:
    """What a fit task's record measured of its fit, as a comparison's ``measured`` entry:
    the BRDF-space metrics and the validity checks (its ``warnings``)."""
    out = {}
    if isinstance(rec.get("metrics"), dict):
        out["brdf"] = rec["metrics"]
    if isinstance(rec.get("warnings"), list):
        out["validity"] = rec["warnings"]
    return out


def run_render_task(task: RenderTask, out_dir, *after) -> dict:
    """Render one material's reference and saved fits and write its report page.

    ``after`` are ignored (kept for callers that pass the fit tasks' results). Fits whose
    record is missing, failed or out of date are left out of the page (and listed in the
    record's ``missing_fits``); a failure is recorded, not raised.
    """
    out = Path(out_dir)
    record = _base_record(task)
    t0 = time.perf_counter()
    try:
        models, missing, measured = {}, [], {}
        for model, key in task.fits:
            fit_task = Task(task.material, task.spec, model)
            rec, _ = _read_record(fit_task.record_path(out))
            if rec is not None and rec["status"] == "ok" and rec.get("key") == key:
                models[model] = str(fit_task.fit_path(out))
                measured[model] = _measured_by_fit_task(rec)
            else:
                missing.append(model)
        record["missing_fits"] = missing
        st = task.settings
        with _forward_progress(task.material, "render"):
            result = compare_with_exports(
                load(task.spec), models, out / "report", name=task.material,
                scenes=st.scenes, spp=st.spp, batches=st.batches, resolution=st.resolution,
                seed=st.seed, save_fits=False, update_index=False, measured=measured)
        record["report_page"] = f"report/{result['slug']}/index.html"
        record["scenes"] = [sc.get("name", sc) if isinstance(sc, dict) else sc
                            for sc in result.get("scenes", [])]
        record["models"] = {m["name"]: {k: m.get(k) for k in ("status", "error", "psnr",
                                                                "psnr_se", "mean_de2000",
                                                                "render_time")}
                            for m in result["models"]}
        failed = [f"{n}: {m['error']}" for n, m in record["models"].items()
                  if m["status"] != "ok"]
        failed += [f"{sc.get('name')}: {sc['error']}" for sc in result.get("scenes", [])
                   if isinstance(sc, dict) and sc.get("error")]
        record["status"] = "failed" if failed else "ok"
        if failed:
            record["error"] = "; ".join(failed)
    except Exception as exc:  # noqa: BLE001 – recorded, the batch goes on
        _record_failure(record, exc)
    return _finish(record, t0, task.record_path(out))


def _outputs_problem(task: Task | RenderTask, rec: dict, out: Path) -> str | None:
    """Why the outputs an ``ok`` record describes cannot be trusted (``None`` if they can)."""
    if isinstance(task, RenderTask):
        page = rec.get("report_page")
        if not isinstance(page, str) or not (out / page).is_file():
            return f"its report page {page!r} is missing"
        return None
    fit = task.fit_path(out)
    if rec.get("fit_file") != fit.relative_to(out).as_posix():
        return f"it describes the fit file {rec.get('fit_file')!r}, expected " \
               f"{fit.relative_to(out).as_posix()!r}"
    expected = rec.get("fit_sha256")
    try:
        if expected is not None:
            actual = _file_sha256(fit)
            if actual != expected:
                return f"{fit} has SHA-256 {actual[:12]}…, the record says {str(expected)[:12]}…"
        else:  # a record of an older version: the file must at least load
            load_fit(fit)
    except FileNotFoundError:
        return f"{fit} is missing"
    except Exception as exc:  # noqa: BLE001 – any unreadable file means: redo the task
        return f"{fit} cannot be read ({type(exc).__name__}: {exc})"
    return None


def _existing(task: Task | RenderTask, out: Path) -> dict | None:
    """The record of ``task`` if it is current and its outputs are intact, else ``None``
    (a malformed record or damaged output is reported with a warning)."""
    path = task.record_path(out)
    rec, why = _read_record(path)
    if rec is None:
        if why is not None:
            _warn(f"{path}: {why}; redoing the task")
        return None
    if rec.get("key") != task.key():
        return None
    model = task.model if isinstance(task, Task) else "render"
    if (rec["material"], rec["model"]) != (task.material, model):
        _warn(f"{path}: it is the record of {rec['material']!r}/{rec['model']!r}, expected "
              f"{task.material!r}/{model!r}; redoing the task")
        return None
    if rec["status"] == "ok":
        problem = _outputs_problem(task, rec, out)
        if problem is not None:
            _warn(f"{path}: {problem}; redoing the task")
            return None
    return rec


def read_records(out_dir) -> list[dict]:
    """Every fit record under ``OUT/records`` (sorted by folder, then model); files that are
    not records are skipped with a warning."""
    out = Path(out_dir)
    recs = []
    for p in sorted((out / "records").glob("*/*.json")):
        if p.name.startswith("."):  # a temporary file left by a killed writer
            continue
        rec, why = _read_record(p)
        if rec is None:
            _warn(f"{p}: {why or 'vanished'}; ignored")
            continue
        recs.append(rec)
    return recs


def write_summary(out_dir, records: list[dict] | None = None) -> tuple[Path, Path]:
    """Write ``summary.json`` and ``summary.csv``: one row per material × model with flat,
    named columns (α and glTF roughness √α, F0 and ρd per channel, table bytes, BRDF-space
    errors, PSNR ± se and dE2000 from the render records when the batch rendered, fit time,
    status, fit file) and each material's recommended model — the smallest fit within a
    stated tolerance of the best (:mod:`brdffit.batch_summary`, whose rule
    ``summary.json`` repeats). Entries of ``records`` that are not records are skipped."""
    import csv
    import io

    out = Path(out_dir)
    records = read_records(out) if records is None else records
    rows, recommended = summary_rows(records, out)
    _write_json(out / "summary.json", {"rows": rows, "recommended": recommended,
                                       "recommendation_rule": RECOMMENDATION_RULE})
    fields = list(COLUMNS)
    for row in rows:
        fields += [k for k in row if k not in fields]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=fields)
    writer.writeheader()
    writer.writerows({k: csv_cell(v) for k, v in row.items()} for row in rows)
    with atomic_write(out / "summary.csv", "w") as fh:
        fh.write(buf.getvalue())
    return out / "summary.json", out / "summary.csv"


# -- the lock -------------------------------------------------------------------------------
def _describe_holder(path: Path) -> str:
    try:
        info = json.loads(path.read_text())
        return (f"pid {info['pid']} on {info['host']}, started {info['started']}: "
                f"{info.get('command', '?')}")
    except Exception:  # noqa: BLE001 – being written, or not ours
        return "holder unknown"


@contextlib.contextmanager
def lock_output(out_dir, wait: bool = False):
    """Hold an exclusive lock on ``OUT/.lock`` (created) for the ``with`` block; yields the
    holder information written into it (pid, host, start time, command).

    Raises :class:`OutputLocked` naming the holder when another process has it, unless
    ``wait`` (then blocks until it is released). ``flock`` locks belong to the open file:
    the kernel drops them when the holder exits or is killed, so no lock is ever stale.
    """
    import socket
    import sys

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / ".lock"
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX: no locking
        yield {"pid": os.getpid(), "host": socket.gethostname(), "locked": False}
        return
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _describe_holder(path)
            if not wait:
                raise OutputLocked(f"{out}: another batch is writing there ({holder}); wait for "
                                   f"it to finish, or pass --wait-lock") from None
            _warn(f"{out}: waiting for the batch holding its lock ({holder})")
            fcntl.flock(fd, fcntl.LOCK_EX)
        info = {"pid": os.getpid(), "host": socket.gethostname(),
                "started": time.strftime("%Y-%m-%dT%H:%M:%S"),
                "command": " ".join(sys.argv) or "?", "locked": True}
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(info).encode(), 0)
        yield info
    finally:
        os.close(fd)  # releases the lock


# -- the cluster ----------------------------------------------------------------------------
#: Dask's periodic housekeeping in the local cluster's processes (workers, and the nannies
#: and scheduler in the calling process). Dask's defaults serve its dashboard: a statistical
#: profiler that walks the running task's stack every 10 ms on each worker's event loop, an
#: event-loop "tick" every 20 ms in every server, system metrics every 500 ms and memory
#: every 100 ms. The batch has no dashboard user (it reports each task itself), and these
#: took 3.6-5.0 % of a busy worker's CPU on its event-loop thread, 0.4 % with the values
#: below (docs/design/batch.md, session 32). The memory limits are still enforced, twice a
#: second instead of ten times; an event loop blocked for ``tick.limit`` (3 s) is still
#: reported.
LOCAL_HOUSEKEEPING = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.memory.monitor-interval": "500ms",
}


def _client(scheduler: str | None, workers: int, memory_limit: str | None,
            retries: int = DEFAULT_RETRIES):
    """A client of ``scheduler``, or of a new local cluster (returned too, to be closed).

    The local workers render with ``cores // workers`` threads each
    (:func:`_render_threads_env`). The local scheduler gives up on a task after
    ``retries + 1`` worker deaths (``allowed-failures``). The batch sends one task per
    free thread (:func:`_run_todo`), so that a worker killed by one task does not take
    queued innocent tasks with it (``worker-saturation`` 1.0 does the same for tasks that
    Dask queues itself); with nothing queued, work stealing has nothing to move and is off.
    The local cluster's housekeeping is set by :data:`LOCAL_HOUSEKEEPING`.
    Dask's own log lines below CRITICAL are silenced: the batch reports every task's
    failure itself, and on a loaded machine a worker's heartbeat can race the local
    cluster's shutdown and log a traceback that means nothing to the user.
    """
    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler, timeout="30s"), None
    environ = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **WORKER_MALLOC_ENV,
               **_render_threads_env(workers)}
    with dask.config.set({"distributed.nanny.pre-spawn-environ": environ,
                          "distributed.scheduler.allowed-failures": int(retries),
                          "distributed.scheduler.worker-saturation": 1.0,
                          "distributed.scheduler.work-stealing": False,
                          **LOCAL_HOUSEKEEPING}):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=":0",
                               memory_limit=memory_limit or "auto",
                               silence_logs=logging.CRITICAL)
    return Client(cluster), cluster


def _render_threads_env(workers: int) -> dict:
    """``BRDFFIT_RENDER_THREADS`` of local workers that share this machine's cores: each
    worker's renders get ``cores // workers`` threads (at least 1; the cores this process
    may run on), unless the user set it (:mod:`brdffit.evaluation.render._mitsuba`)."""
    if os.environ.get("BRDFFIT_RENDER_THREADS", "").strip():
        return {}
    cores = usable_cpus()
    return {"BRDFFIT_RENDER_THREADS": str(max(1, cores // max(1, workers)))}


def _data_files(tasks: Iterable[Task | RenderTask]) -> list[str]:
    """The distinct existing files behind the tasks' load specs (what workers must read)."""
    files = []
    for spec in dict.fromkeys(t.spec for t in tasks):
        if spec.startswith("synthetic:"):
            continue
        path = spec.split(":", 1)[0] if ":" in spec and not os.path.exists(spec) else spec
        if os.path.isfile(path):
            files.append(path)
    return list(dict.fromkeys(files))


def _probe_workers(client, out: Path, tasks: Sequence[Task | RenderTask],
                   wait_s: float = 60.0) -> dict:
    """Check every worker before submitting anything (module docstring, *Clusters*);
    returns ``{worker address: probe result}`` or raises :class:`BatchError`."""
    import secrets

    def probe(out: str, token: str, files: list) -> dict:  # runs on the workers; by value
        import os
        import socket

        res = {"where": f"{socket.gethostname()}:{os.getpid()}", "cwd": os.getcwd(),
               "problems": [], "version": None, "fit_format": None}
        try:
            res["version"], res["fit_format"] = brdffit.__version__, fmt
        except Exception as exc:  # noqa: BLE001
            res["problems"].append(f"cannot import brdffit ({type(exc).__name__}: {exc})")
        marker = os.path.join(out, f".probe-{token}")
        try:
            with open(marker, encoding="ascii") as fh:
                seen = fh.read() == token
        except OSError:
            seen = False
        if not seen:
            res["problems"].append(f"does not see the file {marker} the client wrote (the "
                                   f"output folder must be on a filesystem shared with the "
                                   f"client, at the same path)")
        else:
            mine = f"{marker}-{socket.gethostname()}-{os.getpid()}"
            try:
                with open(mine, "w", encoding="ascii") as fh:
                    fh.write(token)
                os.unlink(mine)
            except OSError as exc:
                res["problems"].append(f"cannot write to {out} ({exc.strerror})")
        unreadable = [f for f in files if not os.access(f, os.R_OK)]
        if unreadable:
            res["problems"].append(f"cannot read {len(unreadable)} data file(s), e.g. "
                                   f"{unreadable[0]}")
        return res

    try:
        client.wait_for_workers(1, timeout=wait_s)
    except Exception:  # noqa: BLE001 – dask raises TimeoutError (or its own) here
        where = getattr(client.scheduler, "address", None) or "the scheduler"
        raise BatchError(f"no Dask worker connected to {where} within {wait_s:.0f} s") from None
    token = secrets.token_hex(8)
    marker = out / f".probe-{token}"
    marker.write_text(token, encoding="ascii")
    try:
        results = client.run(probe, str(out), token, _data_files(tasks))
    except Exception as exc:  # noqa: BLE001
        raise BatchError(f"the workers could not run brdffit's probe ({type(exc).__name__}: "
                         f"{exc})") from None
    finally:
        marker.unlink(missing_ok=True)
    problems = []
    for addr, res in sorted(results.items()):
        mine = list(res["problems"])
        if res["version"] is not None and (res["version"], res["fit_format"]) != (
                __version__, FORMAT_VERSION):
            mine.append(f"runs brdffit version {res['version']} (fit format "
                        f"{res['fit_format']}), the client {__version__} (fit format "
                        f"{FORMAT_VERSION}); install the same version on every machine")
        problems += [f"worker {addr} ({res['where']}, cwd {res['cwd']}): {p}" for p in mine]
    if problems:
        raise BatchError("refusing to start the batch:\n  " + "\n  ".join(problems))
    return results


def _lost_record(task: Task | RenderTask, exc: BaseException, out: Path, t0: float) -> dict:
    """The record of a task whose result never came back. A task that killed its workers
    is recorded ``failed`` on disk; any other loss only in memory (the next run redoes it)."""
    from distributed import KilledWorker

    record = _base_record(task)
    record.update(status="failed", worker="client")
    if isinstance(exc, KilledWorker):
        deaths = getattr(exc, "allowed_failures", 0) + 1
        record["error"] = (f"worker died (out of memory or killed) {deaths} times while "
                           f"running this task")
        record["worker_deaths"] = deaths
        try:
            return _finish(record, t0, task.record_path(out))
        except OSError as err:
            _warn(f"cannot record the failure of {task.material}/{record['model']}: {err}")
            record["lost"] = True
            return record
    record["error"] = f"result lost ({type(exc).__name__}: {exc}); the next run redoes it"
    record["lost"] = True
    return record


def run_batch(tasks: Sequence[Task], out_dir, *, scheduler: str | None = None,
              workers: int = 2, memory_limit: str | None = None, metrics: bool = True,
              render: RenderSettings | None = None, retry_failed: bool = False,
              progress: Callable | bool = True, client=None, retries: int = DEFAULT_RETRIES,
              wait_lock: bool = False, on_event: Callable[[dict], None] | None = None) -> dict:
    """Run ``tasks`` on Dask, skipping finished ones; return counts and the records.

    ``scheduler``: address of an existing Dask scheduler (``tcp://host:port``); ``client``:
    an existing :class:`distributed.Client` (left open); by default a local cluster of
    ``workers`` processes with one thread each, where a task that kills its worker is tried
    ``retries`` more times. ``render``: also render every material once its fits are done
    and write the report (module docstring). ``wait_lock``: wait for another batch on the
    same folder instead of raising :class:`OutputLocked`. ``progress``: ``True`` for a Rich
    progress bar, ``False`` for none, or a callable ``(record) -> None``. ``on_event``: called
    with the progress events of running tasks (:mod:`brdffit.progress`: ``stage``,
    ``iteration``, ``max_iterations``, ``objective``, ``elapsed_s``, plus ``material`` and
    ``model``), at most one per task per :data:`PROGRESS_INTERVAL_S`; they also reach the
    progress bar (its last column) and ``OUT/batch.log`` (a line per finished task and at
    most one progress line per task per :data:`LOG_INTERVAL_S`).

    Returns ``ran`` (tasks run now), ``failed`` (of those), ``lost`` (results that never
    came back, not recorded), ``skipped`` (already done), ``failed_total`` (tasks of this
    batch whose record says failed, now or from an earlier run), ``render_tasks``,
    ``wall_time_s`` and ``records`` (every fit record in the folder).
    """
    from dask.distributed import as_completed

    out = Path(os.path.abspath(out_dir))  # workers may run in another working directory
    _check_materials(((t.material, t.spec) for t in tasks), "batch")
    with lock_output(out, wait=wait_lock):
        render_tasks = make_render_tasks(tasks, render) if render is not None else []
        todo, skipped = [], []
        for t in [*tasks, *render_tasks]:
            rec = _existing(t, out)
            if rec is not None and (rec["status"] in DONE or not retry_failed):
                skipped.append(rec)
            else:
                todo.append(t)
        done: list[dict] = []
        t0 = time.perf_counter()
        if todo:
            own = client is None
            if own:
                client, cluster = _client(scheduler, workers, memory_limit, retries)
            try:
                _probe_workers(client, out, todo)
                with _BatchLog(out / LOG_NAME, len(todo), len(skipped)) as log:
                    done = _run_todo(client, todo, out, metrics, progress, as_completed,
                                     log, on_event)
            finally:
                if own:
                    client.close()
                    if cluster is not None:
                        cluster.close()
        records = read_records(out)
        write_summary(out, records)
        if render_tasks:
            write_index(out / "report", title=f"brdffit batch report – {out.name}")
    final = {(r["material"], r["model"]): r for r in [*skipped, *done] if not r.get("lost")}
    return {"ran": len(done), "skipped": len(skipped), "render_tasks": len(render_tasks),
            "failed": sum(r.get("status") not in DONE for r in done),
            "lost": sum(bool(r.get("lost")) for r in done),
            "failed_total": sum(r.get("status") not in DONE for r in final.values()),
            "wall_time_s": time.perf_counter() - t0, "records": records}


class _Feeder:
    """The task to send to a thread that became free: the next fit of the material whose task
    just ended there, else a render task whose material's fits are over, else the first fit
    of the next material not begun, else (at the end) one of the material with the most fits
    left. With one task in flight per worker thread (:func:`_run_todo`), a material's fits
    run one after the other on one worker, which loads, tabulates and prepares it once
    (≈ 1.5 s of CPU for a Neural-BRDF material that two workers would both prepare), and its
    render follows them there; only the last materials are shared."""

    def __init__(self, fits: Sequence[Task], renders: Sequence[RenderTask] = ()):
        self.left: dict[str, collections.deque] = {}     # material → fits not yet sent
        for t in fits:
            self.left.setdefault(t.material, collections.deque()).append(t)
        self.begun: set[str] = set()
        self.renders = {t.material: t for t in renders}
        self.fits_running = {m: 0 for m in self.renders}  # sent and not over
        self.ready = collections.deque(r for m, r in self.renders.items() if m not in self.left)

    def done(self, task: Task | RenderTask) -> None:
        """``task`` is over (whatever its outcome): its material's render may be ready."""
        m = task.material
        if isinstance(task, Task) and m in self.fits_running:
            self.fits_running[m] -= 1
            if not self.fits_running[m] and m not in self.left:
                self.ready.append(self.renders[m])

    def next(self, after: str | None = None) -> Task | RenderTask | None:
        if after not in self.left and self.ready:
            return self.ready.popleft()
        m = after if after in self.left else next(
            (k for k in self.left if k not in self.begun),
            max(self.left, key=lambda k: len(self.left[k]), default=None))
        if m is None:
            return None
        self.begun.add(m)
        t = self.left[m].popleft()
        if not self.left[m]:
            del self.left[m]
        if m in self.fits_running:
            self.fits_running[m] += 1
        return t


def _threads(client) -> int:
    """Worker threads of the cluster (at least 1)."""
    workers = client.scheduler_info().get("workers", {})
    return max(1, sum(int(w.get("nthreads", 1)) for w in workers.values()))


def _run_todo(client, todo, out: Path, metrics: bool, progress, as_completed, log=None,
              on_event=None) -> list[dict]:
    """Send the tasks one per worker thread at a time, in :class:`_Feeder`'s order: a task is
    submitted only when a thread is free, so Dask places it on that thread's worker (Dask
    assigns a task without dependencies to a worker when it is submitted, behind the task
    that worker is running if all are busy; docs/design/batch.md, session 31)."""
    feeder = _Feeder([t for t in todo if isinstance(t, Task)],
                     [t for t in todo if isinstance(t, RenderTask)])
    running: dict = {}          # future key → (task, perf_counter at submission)

    def submit(t):
        kind, fn, args = ((t.model, run_task, (metrics,)) if isinstance(t, Task)
                          else ("render", run_render_task, ()))
        fut = client.submit(fn, t, str(out), *args, pure=False,
                            key=f"brdffit-{slug(t.material)}-{slug(kind)}-{t.key()}")
        running[fut.key] = (t, time.perf_counter())
        return fut

    def feed(after: str | None = None) -> list:
        """Tasks for the threads without one (``after``: the material of the task that just
        ended, whose thread is free)."""
        sent, threads = [], _threads(client)       # (one call to the scheduler)
        while len(running) < threads:
            t = feeder.next(after)
            if t is None:
                break
            after = None
            sent.append(submit(t))
        return sent

    futures = feed()
    done: list[dict] = []
    with _Progress(todo, enabled=progress is True) as bar, \
            _subscribed(client, bar, log, on_event):
        queue = as_completed(futures)
        for fut in queue:
            t, t0 = running.pop(fut.key)
            try:
                rec = fut.result()
            except Exception as exc:  # noqa: BLE001 – KilledWorker, lost connection, ...
                rec = _lost_record(t, exc, out, t0)
            fut.release()
            feeder.done(t)
            for nxt in feed(t.material):
                queue.add(nxt)
            done.append(rec)
            bar.advance(rec)
            if log is not None:
                log.finished(rec)
            if callable(progress):
                progress(rec)
    return done


@contextlib.contextmanager
def _subscribed(client, bar: "_Progress", log: "_BatchLog | None", on_event):
    """Route the workers' progress events to the bar, the log and ``on_event``."""
    def handle(event) -> None:
        msg = event[1] if isinstance(event, tuple) and len(event) == 2 else event
        if not isinstance(msg, dict):
            return
        bar.activity(msg)
        if log is not None:
            log.progress(msg)
        _log.debug("%s %s %s", msg.get("material"), msg.get("model"), describe(msg))
        if on_event is not None:
            on_event(msg)

    try:
        client.subscribe_topic(PROGRESS_TOPIC, handle)
    except Exception as exc:  # noqa: BLE001 – progress is optional, the batch is not
        _warn(f"no progress from the workers: {type(exc).__name__}: {exc}")
        yield
        return
    try:
        yield
    finally:
        try:
            client.unsubscribe_topic(PROGRESS_TOPIC)
        except Exception:  # noqa: BLE001 – the client may be closing
            pass


class _BatchLog:
    """``OUT/batch.log``: one line per run, per finished task and, at most every
    :data:`LOG_INTERVAL_S` per task, per progress event (appended; the batch holds the
    output lock, so it is the only writer)."""

    def __init__(self, path: Path, n_todo: int, n_skipped: int):
        import threading

        self.path, self._lock, self._last = path, threading.Lock(), {}
        self._head = f"run: {n_todo} task(s) to do, {n_skipped} already done"

    def __enter__(self):
        try:
            self._f = open(self.path, "a", encoding="utf-8", buffering=1)
        except OSError as exc:
            _warn(f"{self.path}: cannot write the batch log: {exc}")
            self._f = None
        self._write(self._head)
        return self

    def _write(self, line: str) -> None:
        if self._f is None:
            return
        stamp = time.strftime("%Y-%m-%dT%H:%M:%S")
        with self._lock:
            try:  # names and errors come from files and users: one escaped line each
                self._f.write(f"{stamp} {printable(line)}\n")
            except (OSError, ValueError):
                pass

    def progress(self, msg: dict) -> None:
        key = (msg.get("material"), msg.get("model"))
        now = time.monotonic()
        if now - self._last.get(key, -math.inf) >= LOG_INTERVAL_S:
            self._last[key] = now
            self._write(f"{msg.get('material')} {msg.get('model')}: {describe(msg)}")

    def finished(self, rec: dict) -> None:
        self._last.pop((rec.get("material"), rec.get("model")), None)
        what = rec.get("status")
        if rec.get("error"):
            what += f" ({str(rec['error']).splitlines()[0][:200]})"
        wall = rec.get("wall_time_s")
        self._write(f"{rec.get('material')} {rec.get('model')}: {what}"
                    + (f" in {wall:.1f} s" if isinstance(wall, (int, float)) else ""))

    def __exit__(self, *exc):
        if self._f is not None:
            self._write("end of run" if exc[0] is None else f"run stopped: {exc[0].__name__}")
            self._f.close()


class _Progress:
    """Rich progress bar with per-model counts and ETA, and below it one line per running
    task with its last progress event (no-op when disabled). The lines are cropped to the
    terminal width, so the bars keep their room at 80 columns."""

    def __init__(self, tasks: Sequence[Task], enabled: bool):
        self.enabled = enabled
        kinds = [getattr(t, "model", "render") for t in tasks]
        self.models = sorted(set(kinds))
        self.total = {m: kinds.count(m) for m in self.models}
        self._running: dict[tuple, str] = {}

    def __enter__(self):
        if self.enabled:
            import threading

            from rich.console import Group
            from rich.live import Live
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                       TimeElapsedColumn, TimeRemainingColumn)
            from rich.text import Text

            self._p = Progress(TextColumn("{task.description:>14}"), BarColumn(),
                               MofNCompleteColumn(), TextColumn("{task.fields[failed]} failed"),
                               TimeElapsedColumn(), TimeRemainingColumn())
            self._status = Text("", no_wrap=True, overflow="ellipsis")
            self._lock = threading.Lock()
            self._live = Live(Group(self._p, self._status), refresh_per_second=4)
            self._live.__enter__()
            self._ids = {m: self._p.add_task(m, total=self.total[m], failed=0)
                         for m in self.models}
            self._failed = dict.fromkeys(self.models, 0)
        return self

    def _show(self) -> None:
        with self._lock:
            self._status.plain = "\n".join(self._running.values())

    def advance(self, rec: dict) -> None:
        if self.enabled:
            m = rec["model"]
            self._failed[m] += rec.get("status") not in DONE
            self._p.update(self._ids[m], advance=1, failed=self._failed[m])
            self._running.pop((rec.get("material"), m), None)
            self._show()

    def activity(self, event: dict) -> None:
        """Show a running task's last progress event on its own line."""
        if self.enabled and event.get("model") in getattr(self, "_ids", {}):
            key = (event.get("material"), event["model"])
            self._running[key] = f"  {event['model']} {event.get('material', '')}: {describe(event)}"
            self._show()

    def __exit__(self, *exc):
        if self.enabled:
            self._live.__exit__(*exc)
