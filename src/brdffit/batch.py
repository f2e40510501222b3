"""Batch fitting of whole databases on Dask (local cluster or an existing scheduler).

One task per (material, model). A task loads the material *on the worker* (only its load spec
travels through the scheduler), fits the model, saves the fit and computes BRDF-space metrics,
then writes its record; everything is written atomically, the record last, so a record on disk
means the task's outputs are complete. Output layout::

    OUT/fits/<material>/<model>.npz       the fitted model (brdffit fit file)
    OUT/records/<material>/<model>.json   status, metrics, parameters, timings, task key
    OUT/summary.csv, OUT/summary.json     one row per material × model

**Rendering (optional).** With :class:`RenderSettings`, each material also gets one render
task that waits for its fits, renders the reference and every fitted model with Mitsuba 3
(:func:`brdffit.evaluation.compare.compare` on the saved fit files, no refitting) and writes
its report page; the run ends by rebuilding the report index over the whole database::

    OUT/report/<material>/index.html      renderings, dE2000 maps, plots, metrics
    OUT/report/index.html, summary.json   every material; per-model PSNR/dE2000, wins/ties
    OUT/renders/<material>.json           render record (status, PSNR/dE2000, task key)

**Resuming.** Each task has a key: a hash of the load spec, the checksum of the file behind
it, the model name, the options and the fit-file format version. A re-run skips a task whose
record exists with the same key (``ok``, or ``failed`` unless ``retry_failed``) and redoes it
when the key changed. Killing a run loses at most the tasks in flight. A render task's key
covers the keys of the fits it renders and the render settings.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
import traceback
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from ._atomic import atomic_write
from ._json import json_default
from .errors import BRDFError

__all__ = ["Task", "RenderSettings", "RenderTask", "enumerate_materials", "make_tasks",
           "make_render_tasks", "run_task", "run_render_task", "run_batch", "read_records",
           "write_summary", "TIMING_FIELDS"]

#: Record fields that legitimately differ between two runs of the same task.
TIMING_FIELDS = ("fit_time_s", "metrics_time_s", "metrics_seconds", "wall_time_s", "finished",
                 "worker")

#: Statuses of finished work (not redone on resume, not counted as failures).
DONE = ("ok", "skipped")

_MEASURED_SUFFIXES = (".binary", ".bsdf", ".bin", ".h5")


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
        from .io.fitfile import FORMAT_VERSION, source_checksum

        payload = {"spec": self.spec, "source_sha256": source_checksum(self.spec),
                   "model": self.model, "options": self.options_dict(),
                   "fit_format": FORMAT_VERSION}
        return _hash(payload)

    def fit_path(self, out: Path) -> Path:
        return out / "fits" / _safe(self.material) / f"{_safe(self.model)}.npz"

    def record_path(self, out: Path) -> Path:
        return out / "records" / _safe(self.material) / f"{_safe(self.model)}.json"


@dataclasses.dataclass(frozen=True)
class RenderSettings:
    """The render stage of a batch: scene, samples per pixel, image size, seed, and whether
    to render the reference twice to measure the Monte Carlo noise floor (as
    :func:`brdffit.evaluation.compare.compare`, whose defaults are the report's settings)."""

    scene: str = "sphere-env"
    spp: int = 64
    resolution: int = 128
    seed: int = 0
    noise_floor: bool = True

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
        from .io.fitfile import source_checksum

        payload = {"spec": self.spec, "source_sha256": source_checksum(self.spec),
                   "fits": list(self.fits), "render": self.settings.as_dict()}
        return _hash(payload)

    def record_path(self, out: Path) -> Path:
        return out / "renders" / f"{_safe(self.material)}.json"


def _hash(payload: dict) -> str:
    """A task key: 16 hex digits of the SHA-256 of the canonical JSON of ``payload``."""
    blob = json.dumps(payload, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def enumerate_materials(source, only: Sequence[str] | None = None,
                        limit: int | None = None) -> list[tuple[str, str]]:
    """``(material name, load spec)`` pairs of a database.

    ``source`` is a folder of measured files (MERL ``.binary``, RGL ``.bsdf``, UTIA ``.bin``,
    Neural-BRDF ``.h5``), a Neural-BRDF ``.zip`` collection, a list file (one load spec per
    line, ``#`` comments), or ``synthetic:`` / ``synthetic:a,b`` for the built-in materials.
    ``only`` keeps the named materials (an unknown name is an error); ``limit`` keeps the first N.
    """
    src = str(source)
    if src.startswith("synthetic:"):
        from .synthetic import list_synthetic

        names = [n for n in src.split(":", 1)[1].split(",") if n] or list(list_synthetic())
        pairs = [(n, f"synthetic:{n}") for n in names]
    else:
        from .io import find_data_file  # the same data search path as load()

        path = find_data_file(Path(src))
        if path is None:
            raise BRDFError(f"{src}: no such file or folder")
        if path.is_dir():
            files = sorted(p for p in path.iterdir() if p.suffix in _MEASURED_SUFFIXES)
            if not files:
                raise BRDFError(f"{path}: expected measured BRDF files "
                                f"({', '.join(_MEASURED_SUFFIXES)}), found none")
            pairs = [(p.stem, str(p)) for p in files]
        elif path.suffix == ".zip":
            from .io.nbrdf import list_materials

            pairs = [(m, f"{path}:{m}") for m in list_materials(path)]
        else:
            pairs = []
            for line in path.read_text().splitlines():
                line = line.split("#", 1)[0].strip()
                if line:
                    name = line.rsplit(":", 1)[-1] if ":" in line else Path(line).stem
                    pairs.append((Path(name).stem, line))
            if not pairs:
                raise BRDFError(f"{path}: expected a list of load specs, found no entries")
    if only:
        known = {n for n, _ in pairs}
        missing = [n for n in only if n not in known]
        if missing:
            raise BRDFError(f"{src}: unknown material(s) {missing}; "
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


def _write_json(path: Path, obj: dict) -> None:
    with atomic_write(path, "w") as fh:
        json.dump(obj, fh, indent=1, sort_keys=True, default=json_default)


def run_task(task: Task, out_dir, metrics: bool = True) -> dict:
    """Run one task in this process and return its record (also written to disk).

    A failure of loading, fitting or measuring is caught and recorded (``status: failed``
    with the error), so one bad material never stops a batch.
    """
    import os
    import socket

    from .fit.registry import fit_model, is_isotropic_only, model_params
    from .io import load
    from .io.fitfile import save_fit

    out = Path(out_dir)
    record: dict[str, Any] = {"material": task.material, "spec": task.spec, "model": task.model,
                              "options": task.options_dict(), "key": task.key(),
                              "worker": f"{socket.gethostname()}:{os.getpid()}"}
    t0 = time.perf_counter()
    try:
        reference = load(task.spec)
        if is_isotropic_only(task.model) and not getattr(reference, "isotropic", False):
            record["status"] = "skipped"
            record["error"] = f"{task.model} fits isotropic BRDFs only; {task.material} is anisotropic"
            raise _Skip
        model, record["fit_time_s"] = fit_model(task.model, reference, task.options_dict())
        save_fit(model, task.fit_path(out), source=task.spec, options=task.options_dict())
        record["fit_file"] = str(task.fit_path(out).relative_to(out))
        record["params"] = model_params(model)
        if metrics:
            from .evaluation.metrics import brdf_metrics

            t_m = time.perf_counter()
            record["metrics"] = brdf_metrics(reference, model)
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


def run_render_task(task: RenderTask, out_dir, *after) -> dict:
    """Render one material's reference and saved fits and write its report page.

    ``after`` are ignored: Dask passes the results of the fit tasks there, so this task starts
    when they are done. Fits whose record is missing, failed or out of date are left out of
    the page (and listed in the record's ``missing_fits``); a failure is recorded, not raised.
    """
    import os
    import socket

    from .evaluation.compare import compare
    from .evaluation.metrics import BRDFMetrics
    from .evaluation.report import write_material_page, write_result
    from .io import load

    out = Path(out_dir)
    record: dict[str, Any] = {"material": task.material, "spec": task.spec, "model": "render",
                              "settings": task.settings.as_dict(), "key": task.key(),
                              "worker": f"{socket.gethostname()}:{os.getpid()}"}
    t0 = time.perf_counter()
    try:
        models, missing, fit_metrics = {}, [], {}
        for model, key in task.fits:
            fit_task = Task(task.material, task.spec, model)
            try:
                rec = json.loads(fit_task.record_path(out).read_text())
            except (FileNotFoundError, json.JSONDecodeError):
                rec = {}
            if rec.get("status") == "ok" and rec.get("key") == key:
                models[model] = str(out / rec["fit_file"])
                if rec.get("metrics"):
                    fit_metrics[model] = rec["metrics"]
            else:
                missing.append(model)
        record["missing_fits"] = missing
        st = task.settings
        result = compare(load(task.spec), models, out / "report", name=task.material,
                         scene=st.scene, spp=st.spp, resolution=st.resolution, seed=st.seed,
                         noise_floor=st.noise_floor, save_fits=False, update_index=False,
                         brdf_metrics=() if len(fit_metrics) == len(models) else BRDFMetrics.ALL)
        if len(fit_metrics) == len(models):  # the fit tasks measured them already: reuse
            for m in result["models"]:
                m["brdf"] = fit_metrics.get(m["name"], m.get("brdf"))
            write_result(out / "report" / result["slug"], result)
            write_material_page(out / "report", result)
        record["report_page"] = f"report/{result['slug']}/index.html"
        record["noise_floor_psnr"] = result.get("noise_floor_psnr")
        record["models"] = {m["name"]: {k: m.get(k) for k in ("status", "error", "psnr",
                                                                "mean_de2000", "render_time")}
                            for m in result["models"]}
        failed = [n for n, m in record["models"].items() if m["status"] != "ok"]
        record["status"] = "failed" if failed else "ok"
        if failed:
            record["error"] = "; ".join(f"{n}: {record['models'][n]['error']}" for n in failed)
    except Exception as exc:  # noqa: BLE001 – recorded, the batch goes on
        _record_failure(record, exc)
    return _finish(record, t0, task.record_path(out))


def _existing(task: Task | RenderTask, out: Path) -> dict | None:
    path = task.record_path(out)
    try:
        rec = json.loads(path.read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None
    return rec if rec.get("key") == task.key() else None


def read_records(out_dir) -> list[dict]:
    """Every record under ``OUT/records`` (sorted by material, then model)."""
    out = Path(out_dir)
    recs = []
    for p in sorted((out / "records").glob("*/*.json")):
        if p.name.startswith("."):  # a temporary file left by a killed writer
            continue
        try:
            recs.append(json.loads(p.read_text()))
        except json.JSONDecodeError:
            continue
    return recs


def write_summary(out_dir, records: list[dict] | None = None) -> tuple[Path, Path]:
    """Write ``summary.json`` and ``summary.csv`` (one row per material × model)."""
    import csv
    import io

    out = Path(out_dir)
    records = read_records(out) if records is None else records
    rows = []
    for r in records:
        row = {"material": r["material"], "model": r["model"], "status": r.get("status"),
               "fit_time_s": r.get("fit_time_s"), "error": r.get("error", "")}
        for k, v in (r.get("metrics") or {}).items():
            if not isinstance(v, dict):
                row[f"metric_{k}"] = v
        for k, v in (r.get("params") or {}).items():
            if isinstance(v, (int, float, str, bool)) or v is None:
                row[f"param_{k}"] = v
        rows.append(row)
    _write_json(out / "summary.json", {"rows": rows})
    fields: list[str] = []
    for row in rows:
        fields += [k for k in row if k not in fields]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=fields)
    writer.writeheader()
    writer.writerows(rows)
    with atomic_write(out / "summary.csv", "w") as fh:
        fh.write(buf.getvalue())
    return out / "summary.json", out / "summary.csv"


#: glibc malloc settings of the local workers. Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_``
#: to 64 KiB, which also switches off glibc's dynamic mmap threshold: every NumPy temporary
#: above 128 KiB is then mmap'd and unmapped again, and the page faults cost the AWLS fits
#: 25-35 % of their time (bench: G-from-D 9.0 s vs 6.5 s). Temporaries up to 64 MiB come
#: from the heap instead, and up to 128 MiB of free heap is kept before trimming.
WORKER_MALLOC_ENV = {"MALLOC_MMAP_THRESHOLD_": 64 << 20, "MALLOC_TRIM_THRESHOLD_": 128 << 20}


def _client(scheduler: str | None, workers: int, memory_limit: str | None):
    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler), None
    environ = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **WORKER_MALLOC_ENV}
    with dask.config.set({"distributed.nanny.pre-spawn-environ": environ}):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=":0",
                               memory_limit=memory_limit or "auto", silence_logs=40)
    return Client(cluster), cluster


def run_batch(tasks: Sequence[Task], out_dir, *, scheduler: str | None = None,
              workers: int = 2, memory_limit: str | None = None, metrics: bool = True,
              render: RenderSettings | None = None, retry_failed: bool = False,
              progress: Callable | bool = True) -> dict:
    """Run ``tasks`` on Dask, skipping finished ones; return counts and the records.

    ``scheduler``: address of an existing Dask scheduler (``tcp://host:port``); by default a
    local cluster of ``workers`` processes with one thread each. ``render``: also render
    every material once its fits are done and write the report (module docstring).
    ``progress``: ``True`` for a Rich progress bar, ``False`` for none, or a callable
    ``(record) -> None``.
    """
    from dask.distributed import as_completed

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    render_tasks = make_render_tasks(tasks, render) if render is not None else []
    todo, skipped = [], []
    for t in [*tasks, *render_tasks]:
        rec = _existing(t, out)
        if rec is not None and (rec.get("status") in DONE or not retry_failed):
            skipped.append(rec)
        else:
            todo.append(t)
    done: list[dict] = []
    t0 = time.perf_counter()
    if todo:
        client, cluster = _client(scheduler, workers, memory_limit)
        try:
            futures, by_material = [], {}
            for t in todo:
                if isinstance(t, Task):
                    fut = client.submit(run_task, t, str(out), metrics, pure=False,
                                        key=f"brdffit-{_safe(t.material)}-{_safe(t.model)}-{t.key()}")
                    by_material.setdefault(t.material, []).append(fut)
                else:
                    fut = client.submit(run_render_task, t, str(out),
                                        *by_material.get(t.material, []), pure=False,
                                        key=f"brdffit-{_safe(t.material)}-render-{t.key()}")
                futures.append(fut)
            with _Progress(todo, enabled=progress is True) as bar:
                for fut in as_completed(futures):
                    rec = fut.result()
                    done.append(rec)
                    bar.advance(rec)
                    if callable(progress):
                        progress(rec)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    records = read_records(out)
    write_summary(out, records)
    if render_tasks:
        from .evaluation.report import write_index

        write_index(out / "report", title=f"brdffit batch report – {out.name}")
    return {"ran": len(done), "skipped": len(skipped), "render_tasks": len(render_tasks),
            "failed": sum(r.get("status") not in DONE for r in done),
            "wall_time_s": time.perf_counter() - t0, "records": records}


class _Progress:
    """Rich progress bar with per-model counts and ETA (no-op when disabled)."""

    def __init__(self, tasks: Sequence[Task], enabled: bool):
        self.enabled = enabled
        kinds = [getattr(t, "model", "render") for t in tasks]
        self.models = sorted(set(kinds))
        self.total = {m: kinds.count(m) for m in self.models}

    def __enter__(self):
        if self.enabled:
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                       TimeElapsedColumn, TimeRemainingColumn)

            self._p = Progress(TextColumn("{task.description:>14}"), BarColumn(),
                               MofNCompleteColumn(), TextColumn("{task.fields[failed]} failed"),
                               TimeElapsedColumn(), TimeRemainingColumn())
            self._p.__enter__()
            self._ids = {m: self._p.add_task(m, total=self.total[m], failed=0) for m in self.models}
            self._failed = dict.fromkeys(self.models, 0)
        return self

    def advance(self, rec: dict) -> None:
        if self.enabled:
            m = rec["model"]
            self._failed[m] += rec.get("status") not in DONE
            self._p.update(self._ids[m], advance=1, failed=self._failed[m])

    def __exit__(self, *exc):
        if self.enabled:
            self._p.__exit__(*exc)
