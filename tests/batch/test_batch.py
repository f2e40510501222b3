"""Batch processing on a local Dask cluster: enumeration, keys, rendering, resume."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from brdffit._cpus import usable_cpus
from brdffit.batch import enumerate_materials, make_tasks
from brdffit.errors import BRDFError

def test_enumerate_list_file_and_folder(tmp_path):
    (tmp_path / "a.binary").write_bytes(b"")
    (tmp_path / "b.bsdf").write_bytes(b"")
    (tmp_path / "notes.txt").write_text("x")
    assert [n for n, _ in enumerate_materials(tmp_path)] == ["a", "b"]
    lst = tmp_path / "list.txt"
    lst.write_text("# two specs\nsynthetic:gold-ggx\nsome.zip:red-paint  # comment\n")
    assert enumerate_materials(lst) == [("gold-ggx", "synthetic:gold-ggx"),
                                        ("red-paint", "some.zip:red-paint")]
    assert len(enumerate_materials(lst, limit=1)) == 1
    with pytest.raises(BRDFError, match="unknown material"):
        enumerate_materials(lst, only=["nope"])
    with pytest.raises(BRDFError, match="no such file"):
        enumerate_materials(tmp_path / "missing")


def test_enumerate_nbrdf_collection(shared_data):
    z = shared_data("nbrdf", "merl_nbrdf.zip")
    pairs = enumerate_materials(z)
    assert len(pairs) == 100
    assert ("gold-metallic-paint", f"{z}:gold-metallic-paint") in pairs


def test_task_key_changes_with_options():
    a, = make_tasks([("m", "synthetic:gold-ggx")], ["tabulated"])
    b, = make_tasks([("m", "synthetic:gold-ggx")], ["tabulated"], {"tabulated": {"n": 64}})
    assert a.key() != b.key() and a.key() == make_tasks([("m", "synthetic:gold-ggx")],
                                                        ["tabulated"])[0].key()


# Kill-and-resume of the whole run: tests/batch/test_faults.py


@pytest.mark.slow
def test_render_stage_writes_a_report_and_resumes(tmp_path):
    """``--render``: one render task per material after its fits, a report page per material,
    an index over the database; a re-run renders nothing, a new model re-renders."""
    pytest.importorskip("mitsuba")
    from brdffit.evaluation.report import missing_links

    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "brdffit", "batch", "synthetic:gold-ggx,plastic-beckmann",
           "--out", str(out), "--workers", "2", "--quiet", "--render", "--spp", "4",
           "--batches", "4", "--resolution", "24", "--scenes", "sphere-env,knot", "--no-metrics"]
    log = subprocess.run(cmd + ["--models", "ggx"], check=True, timeout=300,
                         capture_output=True, text=True)
    assert "2 fit + 2 render tasks: 4 run (0 failed)" in log.stdout
    renders = {p.stem: json.loads(p.read_text()) for p in (out / "renders").glob("*.json")}
    assert set(renders) == {"gold-ggx", "plastic-beckmann"}
    for rec in renders.values():
        assert rec["status"] == "ok" and rec["missing_fits"] == []
        assert np.isfinite(rec["models"]["ggx"]["psnr"])
        assert rec["models"]["ggx"]["psnr_se"] >= 0 and rec["scenes"] == ["sphere-env", "knot"]
    # the GGX fit of a GGX material renders like its reference (common random numbers)
    assert renders["gold-ggx"]["models"]["ggx"]["psnr"] > 40
    index = out / "report" / "index.html"
    assert index.is_file() and missing_links(index) == []
    assert json.loads((out / "report" / "summary.json").read_text())["n_materials"] == 2
    for m in renders:
        assert missing_links(out / "report" / m / "index.html") == []

    log = subprocess.run(cmd + ["--models", "ggx"], check=True, timeout=300,
                         capture_output=True, text=True)
    assert "0 run (0 failed), 4 already done" in log.stdout
    log = subprocess.run(cmd + ["--models", "ggx,beckmann"], check=True, timeout=300,
                         capture_output=True, text=True)
    assert "4 fit + 2 render tasks: 4 run (0 failed), 2 already done" in log.stdout
    rec = json.loads((out / "renders" / "gold-ggx.json").read_text())
    assert set(rec["models"]) == {"ggx", "beckmann"}


def test_isotropic_only_model_is_skipped_on_anisotropic_material(tmp_path):
    from brdffit.batch import run_task

    task, = make_tasks([("aniso", "synthetic:aniso-ggx")], ["sgd"])
    rec = run_task(task, tmp_path)
    assert rec["status"] == "skipped" and "isotropic" in rec["error"]
    assert not task.fit_path(tmp_path).exists()
    assert json.loads(task.record_path(tmp_path).read_text())["status"] == "skipped"


def test_record_says_when_its_task_started_to_the_millisecond(tmp_path):
    """``started`` (ISO, milliseconds) and ``finished`` (ISO, seconds) bound the task's
    ``wall_time_s``: a timeline of a batch's workers can be drawn from the records."""
    import datetime

    from brdffit.batch import TIMING_FIELDS, run_task

    task, = make_tasks([("gold", "synthetic:gold-ggx")], ["ggx"])
    rec = run_task(task, tmp_path, metrics=False)
    started = datetime.datetime.fromisoformat(rec["started"])
    finished = datetime.datetime.fromisoformat(rec["finished"])
    assert len(rec["started"].rsplit(".", 1)[-1]) == 3          # milliseconds
    assert started.replace(microsecond=0) <= finished
    assert (finished - started).total_seconds() <= rec["wall_time_s"] + 1.0
    assert "started" in TIMING_FIELDS      # differs between two runs of the same task


def _worker_env(dask_worker):
    env = {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_",
                                          "BRDFFIT_RENDER_THREADS")}
    return env, {k: pc.callback_time for k, pc in dask_worker.periodic_callbacks.items()}


@pytest.mark.slow
def test_local_workers_keep_numpy_temporaries_on_the_heap_and_share_the_cores(monkeypatch):
    """Dask's nanny default (trim threshold 64 KiB) turns every NumPy temporary into an mmap;
    the local cluster overrides it (brdffit.batch.WORKER_MALLOC_ENV). Its workers' renders
    share the cores (BRDFFIT_RENDER_THREADS = cores // workers). They run no profiler, and
    their housekeeping runs at brdffit.batch.LOCAL_HOUSEKEEPING's intervals."""
    from brdffit.batch import WORKER_MALLOC_ENV, _client

    monkeypatch.delenv("BRDFFIT_RENDER_THREADS", raising=False)
    client, cluster = _client(None, 2, None)
    try:
        found = list(client.run(_worker_env).values())
    finally:
        client.close()
        cluster.close()
    threads = str(max(1, usable_cpus() // 2))
    assert [env for env, _ in found] == 2 * [{**{k: str(v) for k, v in WORKER_MALLOC_ENV.items()},
                                              "BRDFFIT_RENDER_THREADS": threads}]
    for _, callbacks in found:           # {name: interval in ms}
        assert "heartbeat" in callbacks and "profile" not in callbacks, callbacks
        assert (callbacks["tick"], callbacks["monitor"], callbacks["memory_monitor"]) == \
            (1000, 2000, 500), callbacks


def test_progress_inside_running_tasks_reaches_caller_and_log(tmp_path, dask_client):
    """A long fit's iterations travel from the worker to ``on_event`` and OUT/batch.log."""
    from brdffit.batch import LOG_NAME, run_batch

    tasks = make_tasks([("gold", "synthetic:gold-ggx")], ["npf-g-from-d", "ggx"],
                       {"npf-g-from-d": {"max_iter": 3, "polish": 0}})
    events = []
    res = run_batch(tasks, tmp_path, client=dask_client, metrics=False, progress=False,
                    on_event=events.append)
    assert res["failed"] == 0 and res["ran"] == 2
    npf = [e for e in events if e["model"] == "npf-g-from-d"]
    assert npf, events                    # the first event of a task is never throttled
    e = npf[0]
    assert e["material"] == "gold" and e["stage"] == "G-from-D AWLS"
    assert 1 <= e["iteration"] <= 3 and e["max_iterations"] == 3 and e["objective"] > 0
    assert not [e for e in events if e["model"] == "ggx"]   # closed forms report nothing
    log = (tmp_path / LOG_NAME).read_text(encoding="utf-8").splitlines()
    assert any("gold npf-g-from-d: G-from-D AWLS: iteration" in line for line in log)
    assert any(line.endswith(" s") and "gold ggx: ok in" in line for line in log)
    assert "run: 2 task(s) to do, 0 already done" in log[0] and log[-1].endswith("end of run")


def test_progress_display_shows_running_tasks_within_80_columns(monkeypatch):
    import io
    import re

    import rich.live
    from rich.console import Console

    from brdffit.batch import Task, _Progress

    buf = io.StringIO()
    init = rich.live.Live.__init__

    def at_80_columns(self, *a, **k):
        k["console"] = Console(file=buf, width=80, force_terminal=True, color_system=None)
        init(self, *a, **k)

    monkeypatch.setattr(rich.live.Live, "__init__", at_80_columns)
    tasks = [Task("alum-bronze", "x", "npf"), Task("alum-bronze", "x", "ggx")]
    with _Progress(tasks, enabled=True) as bar:
        bar.activity({"material": "alum-bronze", "model": "npf", "stage": "start ones",
                      "iteration": 41, "max_iterations": 100, "objective": 3.06e-4,
                      "elapsed_s": 54, "note": "x" * 200})
        bar._live.refresh()
        shown = buf.getvalue()
        bar.advance({"material": "alum-bronze", "model": "npf", "status": "ok"})
        assert bar._status.plain == ""                     # finished: its line goes away
    lines = re.split(r"\x1b\[[0-9;?]*[A-Za-z]|\n|\r", shown)   # frames, rows
    assert any("npf alum-bronze: start ones: iteration 41/100" in x for x in lines)
    assert all(len(x) <= 80 for x in lines)
    assert any("0/1 0 failed" in x for x in lines)        # the bars keep their columns


def test_tasks_of_one_material_share_its_prepared_metrics(tmp_path, monkeypatch):
    """The reference side of the BRDF metrics is prepared once per material and worker, not
    once per model; the numbers are those of a fresh :func:`brdf_metrics`."""
    from brdffit import batch
    from brdffit.evaluation import metrics as M
    from brdffit.io.fitfile import load_fit

    made = []
    real = M.BRDFMetrics.__init__

    def counting(self, *args, **kwargs):
        made.append(args[0])
        real(self, *args, **kwargs)

    monkeypatch.setattr(M.BRDFMetrics, "__init__", counting)
    batch._reference_metrics.cache_clear()
    tasks = make_tasks([("plastic", "synthetic:plastic-beckmann")], ["ggx", "beckmann"])
    recs = [batch.run_task(t, tmp_path) for t in tasks]
    assert [r["status"] for r in recs] == ["ok", "ok"] and len(made) == 1
    for task, rec in zip(tasks, recs):
        fresh = M.brdf_metrics(batch._load_reference(task.spec), load_fit(task.fit_path(tmp_path)))
        for key in M.BRDFMetrics.ALL:
            if isinstance(fresh[key], dict):        # error_regions: same pairs, same figures
                assert rec["metrics"][key] == fresh[key], key
            else:
                assert rec["metrics"][key] == pytest.approx(fresh[key], rel=1e-12), key
    batch._reference_metrics.cache_clear()


def test_feeder_sends_a_material_after_itself_and_shares_only_the_last():
    """After a task of a material, the next task of that material; then the first material
    not begun; when none is left, the material with the most tasks left."""
    from brdffit.batch import _Feeder

    tasks = make_tasks([("a", "synthetic:a"), ("b", "synthetic:b"), ("c", "synthetic:c")],
                       ["ggx", "beckmann", "tabulated"])
    feeder = _Feeder(tasks)
    sent = [feeder.next(), feeder.next()]                # two threads: two materials
    assert [(t.material, t.model) for t in sent] == [("a", "ggx"), ("b", "ggx")]
    got = []
    for after in ("a", "b", "a", "a", "a", "b", "b"):     # a's thread is the faster
        t = feeder.next(after)
        got.append((after, t.material, t.model))
    assert got == [("a", "a", "beckmann"), ("b", "b", "beckmann"), ("a", "a", "tabulated"),
                   ("a", "c", "ggx"), ("a", "c", "beckmann"), ("b", "b", "tabulated"),
                   ("b", "c", "tabulated")]
    assert feeder.next("c") is None and feeder.next() is None


def test_feeder_sends_a_render_to_the_thread_that_ended_its_material():
    """A material's render is sent when its last fit is over (not before), to the thread that
    ran that fit, ahead of a new material; a thread whose material has fits left goes on
    with them; a render whose fits were done before the run is sent first."""
    from brdffit.batch import RenderSettings, RenderTask, _Feeder, make_render_tasks

    fits = make_tasks([("a", "synthetic:a"), ("b", "synthetic:b"), ("c", "synthetic:c")],
                      ["ggx", "beckmann"])
    renders = make_render_tasks(fits, RenderSettings())
    feeder = _Feeder([t for t in fits if t.material != "c"], renders)
    rc = feeder.next()
    assert isinstance(rc, RenderTask) and rc.material == "c"
    a1, b1 = feeder.next(), feeder.next()
    assert (a1.material, a1.model, b1.material, b1.model) == ("a", "ggx", "b", "ggx")
    feeder.done(a1)
    a2 = feeder.next("a")
    assert (a2.material, a2.model) == ("a", "beckmann")
    feeder.done(b1)
    b2 = feeder.next("b")
    assert (b2.material, b2.model, list(feeder.ready)) == ("b", "beckmann", [])
    feeder.done(a2)                                      # a's fits are over: its render
    ra = feeder.next("a")
    assert isinstance(ra, RenderTask) and ra.material == "a"
    feeder.done(ra)
    assert feeder.next("a") is None                      # nothing left but b's running fit


class _SimulatedCluster:
    """A client of a cluster of ``threads`` one-thread workers, in simulated time: a
    submitted task runs at once on a free thread (submitting with every thread busy fails
    the test: Dask would queue it behind a running task on some worker), and
    :meth:`as_completed` yields the tasks in the order they end."""

    def __init__(self, threads: int, seconds):
        self.free, self.seconds, self.now = list(range(threads)), seconds, 0.0
        self.threads = threads
        self.ran: list[tuple] = []                     # (thread, material, kind) in start order

    def scheduler_info(self):
        return {"workers": {f"w{i}": {"nthreads": 1} for i in range(self.threads)}}

    def subscribe_topic(self, *args):
        pass

    def unsubscribe_topic(self, *args):
        pass

    def submit(self, fn, task, out, *args, key, **kwargs):
        assert self.free, f"{key} submitted while every thread is busy"
        kind = getattr(task, "model", "render")
        thread = self.free.pop(0)
        self.ran.append((thread, task.material, kind))
        record = {"material": task.material, "model": kind, "status": "ok"}
        return _SimulatedFuture(key, thread, self.now + self.seconds[kind], record)

    def as_completed(self, futures):
        cluster, pending = self, list(futures)

        class _Queue:
            def add(self, fut):
                pending.append(fut)

            def __iter__(self):
                while pending:
                    fut = min(pending, key=lambda f: f.end)
                    pending.remove(fut)
                    cluster.now = fut.end
                    cluster.free.append(fut.thread)
                    yield fut

        return _Queue()


class _SimulatedFuture:
    def __init__(self, key, thread, end, record):
        self.key, self.thread, self.end, self.record = key, thread, end, record

    def result(self):
        return self.record

    def release(self):
        pass


def test_run_todo_sends_one_task_per_free_thread_and_a_render_after_its_fits(tmp_path):
    """Renders count among the tasks in flight (a render sent beside two running fits would
    wait on a busy worker while the other may run dry), a render starts after its
    material's fits, on the thread of its last fit, and a material's fits stay on one
    thread except at the end."""
    from brdffit.batch import RenderSettings, _run_todo, make_render_tasks

    names = [(n, f"synthetic:{n}") for n in "abcdef"]
    fits = make_tasks(names, ["ggx", "npf", "sgd"])
    todo = fits + make_render_tasks(fits, RenderSettings())
    cluster = _SimulatedCluster(2, {"ggx": 1.0, "npf": 7.0, "sgd": 0.5, "render": 6.0})
    done = _run_todo(cluster, todo, tmp_path, True, False, cluster.as_completed)

    assert sorted((r["material"], r["model"]) for r in done) == sorted(
        (t.material, getattr(t, "model", "render")) for t in todo)
    for name, _ in names[:-1]:                          # the last material may be shared
        runs = [(i, th, kind) for i, (th, m, kind) in enumerate(cluster.ran) if m == name]
        assert len({th for _, th, _ in runs}) == 1, runs
        assert runs[-1][2] == "render", runs
