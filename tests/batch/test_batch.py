"""Batch processing on a two-worker local Dask cluster: enumeration, kill and resume."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from brdffit.batch import TIMING_FIELDS, enumerate_materials, make_tasks, read_records
from brdffit.errors import BRDFError

MATERIALS = "synthetic:gold-ggx,plastic-beckmann,sgd-paint,two-lobe-ggx"
MODELS = "ggx"


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


def _batch_cmd(out):
    return [sys.executable, "-m", "brdffit", "batch", MATERIALS, "--models", MODELS,
            "--out", str(out), "--workers", "2", "--quiet"]


def _comparable(rec):
    return {k: v for k, v in rec.items() if k not in TIMING_FIELDS}


@pytest.mark.slow
def test_kill_and_resume_matches_uninterrupted_run(tmp_path):
    n_tasks = len(MATERIALS.split(":")[1].split(",")) * len(MODELS.split(","))
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
    partial = len(list((out / "records").glob("*/[!.]*.json")))
    assert 1 <= partial < n_tasks, f"kill landed after {partial} of {n_tasks} tasks"

    log = subprocess.run(_batch_cmd(out), check=True, timeout=300, capture_output=True, text=True)
    assert f"{partial} already done" in log.stdout
    files = sorted((out / "records").glob("*/[!.]*.json"))
    assert len(files) == n_tasks  # each result exactly once
    for f in files:
        rec = json.loads(f.read_text())
        assert _comparable(rec) == _comparable(reference[(rec["material"], rec["model"])])
    # the saved fits evaluate identically to the uninterrupted run's
    from brdffit.io.fitfile import load_fit

    rng = np.random.default_rng(0)
    wi, wo = (v / np.linalg.norm(v, axis=-1, keepdims=True) * [1, 1, 1]
              for v in np.abs(rng.normal(size=(2, 500, 3))))
    for key, rec in reference.items():
        a = load_fit(ref_out / rec["fit_file"]).eval(wi, wo)
        b = load_fit(out / rec["fit_file"]).eval(wi, wo)
        np.testing.assert_array_equal(a, b)
    summary = (out / "summary.csv").read_text().splitlines()
    assert len(summary) == n_tasks + 1

    # a second re-run does nothing
    log = subprocess.run(_batch_cmd(out), check=True, timeout=300, capture_output=True, text=True)
    assert f"0 run (0 failed), {n_tasks} already done" in log.stdout


@pytest.mark.slow
def test_render_stage_writes_a_report_and_resumes(tmp_path):
    """``--render``: one render task per material after its fits, a report page per material,
    an index over the database; a re-run renders nothing, a new model re-renders."""
    pytest.importorskip("mitsuba")
    from brdffit.evaluation.report import missing_links

    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "brdffit", "batch", "synthetic:gold-ggx,plastic-beckmann",
           "--out", str(out), "--workers", "2", "--quiet", "--render", "--spp", "4",
           "--resolution", "24", "--no-noise-floor"]
    log = subprocess.run(cmd + ["--models", "ggx"], check=True, timeout=300,
                         capture_output=True, text=True)
    assert "2 fit + 2 render tasks: 4 run (0 failed)" in log.stdout
    renders = {p.stem: json.loads(p.read_text()) for p in (out / "renders").glob("*.json")}
    assert set(renders) == {"gold-ggx", "plastic-beckmann"}
    for rec in renders.values():
        assert rec["status"] == "ok" and rec["missing_fits"] == []
        assert np.isfinite(rec["models"]["ggx"]["psnr"])
    # the GGX fit of a GGX material renders like its reference (same sample streams)
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


def _malloc_env():
    return {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_")}


@pytest.mark.slow
def test_local_workers_keep_numpy_temporaries_on_the_heap():
    """Dask's nanny default (trim threshold 64 KiB) turns every NumPy temporary into an mmap;
    the local cluster overrides it (brdffit.batch.WORKER_MALLOC_ENV)."""
    from brdffit.batch import WORKER_MALLOC_ENV, _client

    client, cluster = _client(None, 1, None)
    try:
        (env,) = client.run(_malloc_env).values()
    finally:
        client.close()
        cluster.close()
    assert env == {k: str(v) for k, v in WORKER_MALLOC_ENV.items()}
