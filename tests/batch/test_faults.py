"""Fault tests of the batch (issue 12): killed workers and runs, a poisonous material, corrupt
records and fits, two batches on one folder, and a real external cluster.

Misbehaving fitters live in ``_faults_plugin.py`` and are loaded into the *workers* only, with
Dask's worker preload (see that file)."""

from __future__ import annotations

import csv
import json
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import distributed  # noqa: F401 – its config defaults must be loaded before dask.config.set
import dask
import numpy as np
import pytest

from brdffit.batch import TIMING_FIELDS, make_tasks, read_records, run_batch, write_summary
from brdffit.cli import main

PLUGIN = str(Path(__file__).with_name("_faults_plugin.py"))
VENV_BIN = Path(sys.executable).parent


def _rows(out):
    return list(csv.DictReader((Path(out) / "summary.csv").open(encoding="utf-8")))


# -- a worker dies -------------------------------------------------------------------------
@pytest.mark.slow
def test_poisonous_material_is_recorded_failed_and_the_batch_goes_on(tmp_path):
    tasks = make_tasks([("gold", "synthetic:gold-ggx")], ["test-copy", "test-poison"])
    out = tmp_path / "out"
    with dask.config.set({"distributed.worker.preload": [PLUGIN]}):
        res = run_batch(tasks, out, workers=1, retries=1, metrics=False, progress=False)
    by_model = {r["model"]: r for r in res["records"]}
    assert by_model["test-copy"]["status"] == "ok"
    poison = by_model["test-poison"]
    assert poison["status"] == "failed"
    assert "worker died (out of memory or killed) 2 times" in poison["error"]
    assert res["failed"] == 1 and res["failed_total"] == 1
    assert json.loads(tasks[1].record_path(out).read_text())["status"] == "failed"
    assert {r["model"] for r in _rows(out)} == {"test-copy", "test-poison"}
    # the resume neither crashes nor redoes anything (failed is kept unless --retry-failed)
    again = run_batch(tasks, out, workers=1, progress=False)
    assert again["ran"] == 0 and again["failed_total"] == 1


@pytest.mark.slow
def test_worker_killed_mid_task_is_retried(tmp_path):
    markers = tmp_path / "markers"
    markers.mkdir()
    tasks = make_tasks([("gold", "synthetic:gold-ggx"), ("plastic", "synthetic:plastic-beckmann")],
                       ["test-slow-copy"], {"test-slow-copy": {"marker_dir": str(markers),
                                                               "delay": 2.0}})
    killed = []

    def killer():
        deadline = time.time() + 60
        while time.time() < deadline and not killed:
            for m in markers.iterdir():
                pid = int(m.name.split(".")[0])
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
                return
            time.sleep(0.02)

    thread = threading.Thread(target=killer)
    thread.start()
    with dask.config.set({"distributed.worker.preload": [PLUGIN]}):
        res = run_batch(tasks, tmp_path / "out", workers=2, metrics=False, progress=False)
    thread.join()
    assert len(killed) == 1
    assert res["ran"] == 2 and res["failed"] == 0
    assert all(r["status"] == "ok" for r in res["records"])
    assert all(int(r["worker"].rsplit(":", 1)[1]) != killed[0] for r in res["records"])
    assert len(list(markers.iterdir())) == 3  # the killed attempt, its retry, the other task


# -- the whole run dies ----------------------------------------------------------------------
MATERIALS = "synthetic:gold-ggx,plastic-beckmann,sgd-paint,two-lobe-ggx"


def _batch_cmd(out, models="ggx"):
    return [sys.executable, "-m", "brdffit", "batch", MATERIALS, "--models", models,
            "--out", str(out), "--workers", "2", "--quiet", "--no-metrics"]


def _comparable(rec):
    return {k: v for k, v in rec.items() if k not in TIMING_FIELDS}


@pytest.mark.slow
def test_kill_and_resume_loses_nothing_and_redoes_nothing(tmp_path):
    """SIGKILL of the whole run (client, scheduler, workers); the resume finishes the rest,
    leaves every record written before the kill untouched and matches an uninterrupted run."""
    n_tasks = len(MATERIALS.split(":")[1].split(","))
    ref_out, out = tmp_path / "ref", tmp_path / "run"
    subprocess.run(_batch_cmd(ref_out), check=True, timeout=300)
    reference = {(r["material"], r["model"]): r for r in read_records(ref_out)}
    assert len(reference) == n_tasks and all(r["status"] == "ok" for r in reference.values())

    proc = subprocess.Popen(_batch_cmd(out), start_new_session=True)
    deadline = time.time() + 240
    while time.time() < deadline and not list((out / "records").glob("*/[!.]*.json")):
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)  # the client, the scheduler and both workers
    proc.wait()
    before = {p: (p.stat().st_mtime_ns, p.read_bytes())
              for p in (out / "records").glob("*/[!.]*.json")}
    assert 1 <= len(before) < n_tasks, f"kill landed after {len(before)} of {n_tasks} tasks"

    log = subprocess.run(_batch_cmd(out), timeout=300, capture_output=True, text=True)
    assert log.returncode == 0, log.stderr
    assert f"{len(before)} already done" in log.stdout
    for p, (mtime, blob) in before.items():  # finished work is not done twice
        assert p.stat().st_mtime_ns == mtime and p.read_bytes() == blob
    files = sorted((out / "records").glob("*/[!.]*.json"))
    assert len(files) == n_tasks  # each result exactly once
    from brdffit.io.fitfile import load_fit

    rng = np.random.default_rng(0)
    wi, wo = (v / np.linalg.norm(v, axis=-1, keepdims=True)
              for v in np.abs(rng.normal(size=(2, 500, 3))))
    for f in files:
        rec = json.loads(f.read_text())
        ref = reference[(rec["material"], rec["model"])]
        assert _comparable(rec) == _comparable(ref)
        np.testing.assert_array_equal(load_fit(out / rec["fit_file"]).eval(wi, wo),
                                      load_fit(ref_out / ref["fit_file"]).eval(wi, wo))
    assert len(_rows(out)) == n_tasks
    log = subprocess.run(_batch_cmd(out), check=True, timeout=300, capture_output=True, text=True)
    assert f"0 run (0 failed), {n_tasks} already done" in log.stdout


# -- corrupt outputs -------------------------------------------------------------------------
def test_corrupt_or_missing_fit_file_is_redone(tmp_path, dask_client):
    from brdffit.io.fitfile import load_fit

    tasks = make_tasks([("gold", "synthetic:gold-ggx"), ("plastic", "synthetic:plastic-beckmann")],
                       ["test-copy"])
    out = tmp_path / "out"
    kw = dict(client=dask_client, metrics=False, progress=False)
    assert run_batch(tasks, out, **kw)["ran"] == 2
    fit = tasks[0].fit_path(out)
    blob = fit.read_bytes()
    fit.write_bytes(blob[: len(blob) // 2])  # truncated
    tasks[1].fit_path(out).unlink()           # missing
    res = run_batch(tasks, out, **kw)
    assert res["ran"] == 2 and res["skipped"] == 0 and res["failed"] == 0
    for t in tasks:
        load_fit(t.fit_path(out))  # loadable again
        rec = json.loads(t.record_path(out).read_text())
        import hashlib

        assert rec["fit_sha256"] == hashlib.sha256(t.fit_path(out).read_bytes()).hexdigest()
    # any change to the file is caught by the checksum
    data = bytearray(fit.read_bytes())
    data[-30] ^= 0xFF
    fit.write_bytes(bytes(data))
    assert run_batch(tasks, out, **kw)["ran"] == 1


def test_corrupt_records_are_redone_with_a_warning(tmp_path, dask_client, caplog):
    tasks = make_tasks([(m, f"synthetic:{m}") for m in ("gold-ggx", "plastic-beckmann",
                                                         "sgd-paint", "two-lobe-ggx")],
                       ["test-copy"])
    out = tmp_path / "out"
    kw = dict(client=dask_client, metrics=False, progress=False)
    run_batch(tasks, out, **kw)
    junk = ["[]", '"a string"', '{"status": "ok"}', "{not json"]
    for t, text in zip(tasks, junk):
        t.record_path(out).write_text(text)
    (out / "records" / "stray").mkdir()
    (out / "records" / "stray" / "x.json").write_text('{"model": "test-copy"}')
    caplog.set_level(logging.WARNING, logger="brdffit.batch")
    res = run_batch(tasks, out, **kw)
    assert res["ran"] == 4 and res["failed"] == 0
    assert sum("redoing" in r.message for r in caplog.records) == 4
    assert any("stray" in r.message for r in caplog.records)  # ignored, said so
    assert sorted(r["material"] for r in read_records(out)) == sorted(t.material for t in tasks)
    write_summary(out)  # no KeyError on the stray record
    assert len(_rows(out)) == 4


# -- two batches on one folder ---------------------------------------------------------------
HOLDER = """
import sys, time
from brdffit.batch import lock_output
with lock_output(sys.argv[1]):
    print("locked", flush=True)
    time.sleep(float(sys.argv[2]))
"""


def _hold_lock(out, seconds):
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(out), str(seconds)],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_second_batch_on_the_same_out_exits_2(tmp_path, capsys):
    out = tmp_path / "out"
    holder = _hold_lock(out, 60)
    try:
        t0 = time.perf_counter()
        rc = main(["batch", "synthetic:gold-ggx", "--models", "ggx", "--out", str(out), "-q"])
        err = capsys.readouterr().err
        assert rc == 2 and time.perf_counter() - t0 < 10
        assert f"pid {holder.pid}" in err and socket.gethostname() in err and "--wait-lock" in err
        assert not (out / "records").exists()
    finally:
        holder.kill()
        holder.wait()


def test_stale_lock_of_a_killed_batch_does_not_block(tmp_path):
    from brdffit.batch import lock_output

    out = tmp_path / "out"
    holder = _hold_lock(out, 60)
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    with lock_output(out) as info:  # immediately, without waiting
        assert info["pid"] == os.getpid()
        assert json.loads((out / ".lock").read_text())["pid"] == os.getpid()


@pytest.mark.slow
def test_wait_lock_waits_for_the_other_batch(tmp_path, capsys):
    out = tmp_path / "out"
    holder = _hold_lock(out, 1.0)
    rc = main(["batch", "synthetic:gold-ggx", "--models", "ggx", "--out", str(out), "-q",
               "--workers", "1", "--no-metrics", "--wait-lock"])
    holder.wait()
    assert rc == 0, capsys.readouterr().err
    assert [r["status"] for r in read_records(out)] == ["ok"]


# -- an external cluster ---------------------------------------------------------------------
def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_external_cluster_with_relative_out_writes_on_the_client(tmp_path, monkeypatch, capsys):
    """``dask scheduler`` + ``dask worker`` processes, the worker in another working directory:
    a relative --out lands in the client's folder, not the worker's."""
    client_dir, worker_dir = tmp_path / "client", tmp_path / "worker"
    client_dir.mkdir()
    worker_dir.mkdir()
    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    procs = [subprocess.Popen([str(VENV_BIN / "dask"), "scheduler", "--host", "127.0.0.1",
                               "--port", str(port), "--no-dashboard"], cwd=worker_dir,
                              start_new_session=True, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)]
    try:
        procs.append(subprocess.Popen([str(VENV_BIN / "dask"), "worker", addr, "--nworkers", "1",
                                       "--nthreads", "1", "--no-dashboard"], cwd=worker_dir,
                                      start_new_session=True, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL))
        monkeypatch.chdir(client_dir)
        rc = main(["batch", "synthetic:[gold-ggx,plastic-beckmann]", "--models", "ggx",
                   "--out", "rel", "--scheduler", addr, "-q", "--no-metrics"])
        captured = capsys.readouterr()
        assert rc == 0, captured.err
        assert sorted(r["material"] for r in read_records(client_dir / "rel")) == [
            "gold-ggx", "plastic-beckmann"]
        assert len(_rows(client_dir / "rel")) == 2
        assert list(worker_dir.iterdir()) == [] or not (worker_dir / "rel").exists()
    finally:
        for p in procs:
            os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)


@pytest.mark.slow
def test_workers_with_another_brdffit_version_are_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("BRDFFIT_TEST_WORKER_VERSION", "0.0.0-other")
    with dask.config.set({"distributed.worker.preload": [PLUGIN]}):
        rc = main(["batch", "synthetic:gold-ggx", "--models", "ggx", "--out",
                   str(tmp_path / "out"), "-q", "--workers", "1"])
    err = capsys.readouterr().err
    assert rc == 1 and "0.0.0-other" in err and "version" in err and "Traceback" not in err
    assert not (tmp_path / "out" / "records").exists()


def test_a_record_of_another_material_in_the_folder_is_not_trusted(tmp_path, dask_client, caplog):
    """Folders of older versions could hold another material's record (``mat a`` and ``mat_a``
    shared ``mat_a/``); with the same spec and model its key even matches."""
    a, b = make_tasks([("mat a", "synthetic:gold-ggx"), ("mat_a", "synthetic:gold-ggx")],
                      ["test-copy"])
    out = tmp_path / "out"
    kw = dict(client=dask_client, metrics=False, progress=False)
    run_batch([a], out, **kw)
    b.record_path(out).parent.mkdir(parents=True)
    rec = json.loads(a.record_path(out).read_text())
    rec["fit_file"] = b.fit_path(out).relative_to(out).as_posix()  # consistent otherwise
    b.record_path(out).write_text(json.dumps(rec))
    b.fit_path(out).parent.mkdir(parents=True)
    b.fit_path(out).write_bytes(a.fit_path(out).read_bytes())
    caplog.set_level(logging.WARNING, logger="brdffit.batch")
    assert run_batch([a, b], out, **kw)["ran"] == 1
    assert any("expected 'mat_a'" in r.message for r in caplog.records)
    assert json.loads(b.record_path(out).read_text())["material"] == "mat_a"
