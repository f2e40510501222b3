"""Batch outputs people can use (issue 16.2): flat named columns in summary.csv, rendered
figures from the render records, and the per-material recommended model."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from brdffit.batch import Task, run_task, write_summary
from brdffit.batch_summary import COLUMNS, RECOMMENDATION_RULE, recommend
from brdffit.paths import slug


def _csv(out: Path) -> list[dict]:
    return list(csv.DictReader((out / "summary.csv").open(encoding="utf-8")))


def _f(v: str) -> float:
    return float(v)


@pytest.fixture(scope="module")
def batch_dir(tmp_path_factory):
    """plastic-beckmann (Beckmann α = 0.18, η = 1.5, ρd = (0.45, 0.06, 0.04)) fitted with a
    single-lobe and a per-channel model, and a failed task."""
    out = tmp_path_factory.mktemp("batch")
    for model in ("ggx", "beckmann-ct"):
        rec = run_task(Task("plastic", "synthetic:plastic-beckmann", model), out)
        assert rec["status"] == "ok", rec.get("error")
    rec = run_task(Task("missing", str(out / "missing.binary"), "ggx"), out)
    assert rec["status"] == "failed"
    return out


def test_summary_csv_has_flat_named_columns(batch_dir):
    write_summary(batch_dir)
    rows = {(r["material"], r["model"]): r for r in _csv(batch_dir)}
    header = list(_csv(batch_dir)[0])
    assert header[:len(COLUMNS)] == list(COLUMNS)
    assert not any(h.startswith(("param_", "metric_")) for h in header)

    ggx = rows[("plastic", "ggx")]
    assert ggx["status"] == "ok" and ggx["alpha_kind"] == "ggx"
    assert _f(ggx["gltf_roughness_x"]) == pytest.approx(math.sqrt(_f(ggx["alpha_x"])))
    assert 0 < _f(ggx["cos_rel_error"]) < 1 and _f(ggx["fit_time_s"]) > 0
    assert (batch_dir / ggx["fit_file"]).is_file()
    assert ggx["psnr"] == "" and ggx["alpha_r"] == ""  # not rendered; not per channel
    assert ggx["error_domain"] == "everywhere"          # a synthetic model: no smaller domain

    ct = rows[("plastic", "beckmann-ct")]
    assert ct["alpha_x"] == "" and _f(ct["alpha_r"]) == pytest.approx(0.18, rel=0.1)
    assert _f(ct["gltf_roughness_g"]) == pytest.approx(math.sqrt(_f(ct["alpha_g"])))
    assert [_f(ct[f"rho_d_{c}"]) for c in "rgb"] == pytest.approx([0.45, 0.06, 0.04], abs=0.01)
    assert [_f(ct[f"f0_{c}"]) for c in "rgb"] == pytest.approx([0.04] * 3, abs=0.015)
    assert int(ct["table_bytes"]) >= 0

    bad = rows[("missing", "ggx")]
    assert bad["error_domain"] == ""
    assert bad["status"] == "failed" and "missing.binary" in bad["error"]
    assert bad["fit_file"] == "" and bad["recommended"] == "" and bad["alpha_x"] == ""


def test_recommended_model_is_in_the_summary(batch_dir):
    write_summary(batch_dir)
    rows = [r for r in _csv(batch_dir) if r["material"] == "plastic"]
    data = json.loads((batch_dir / "summary.json").read_text())
    choice = data["recommended"]["plastic"]
    assert data["recommendation_rule"] == RECOMMENDATION_RULE
    assert {r["recommended"] for r in rows} == {choice["model"]}
    assert [r["model"] for r in rows if r["is_recommended"] == "True"] == [choice["model"]]
    assert choice["by"] == "cos_rel_error"  # no renders
    best = min(rows, key=lambda r: _f(r["cos_rel_error"]))
    assert choice["best_model"] == best["model"]
    assert "missing" not in data["recommended"]  # nothing fitted there


def test_render_records_add_psnr_and_decide(batch_dir):
    renders = batch_dir / "renders"
    renders.mkdir(exist_ok=True)
    record = {"material": "plastic", "model": "render", "status": "ok",
              "finished": "9999-01-01T00:00:00",
              "models": {"ggx": {"status": "ok", "psnr": 30.0, "psnr_se": 0.1,
                                 "mean_de2000": 2.5},
                         "beckmann-ct": {"status": "ok", "psnr": 41.0, "psnr_se": 0.1,
                                         "mean_de2000": 0.4}}}
    (renders / f"{slug('plastic')}.json").write_text(json.dumps(record))
    try:
        write_summary(batch_dir)
        rows = {r["model"]: r for r in _csv(batch_dir) if r["material"] == "plastic"}
        assert _f(rows["ggx"]["psnr"]) == 30.0 and _f(rows["ggx"]["psnr_se"]) == 0.1
        assert _f(rows["beckmann-ct"]["mean_de2000"]) == 0.4
        choice = json.loads((batch_dir / "summary.json").read_text())["recommended"]["plastic"]
        assert choice["by"] == "psnr" and choice["model"] == "beckmann-ct"  # ggx is 11 dB worse
        record["finished"] = "2000-01-01T00:00:00"  # renders of fits redone since: not used
        (renders / f"{slug('plastic')}.json").write_text(json.dumps(record))
        write_summary(batch_dir)
        assert {r["psnr"] for r in _csv(batch_dir)} == {""}
    finally:
        (renders / f"{slug('plastic')}.json").unlink()


def test_records_without_figures_read_the_fit_file(batch_dir, tmp_path):
    rec = json.loads(Task("plastic", "synthetic:plastic-beckmann", "ggx")
                     .record_path(batch_dir).read_text())
    expected = rec["params"]["figures"]
    del rec["params"]["figures"]  # a record of an older version
    write_summary(batch_dir, [rec])
    (row,) = _csv(batch_dir)
    assert _f(row["alpha_x"]) == pytest.approx(expected["alpha"][0])
    assert int(row["table_bytes"]) == expected["table_bytes"]
    write_summary(batch_dir)  # leave the folder's summary whole


def _row(model, table_bytes, err=None, psnr=None, se=None, status="ok"):
    return {"material": "m", "model": model, "status": status, "table_bytes": table_bytes,
            "cos_rel_error": err, "psnr": psnr, "psnr_se": se}


def test_recommend_rule_without_renders():
    rows = [_row("tab", 1800, 0.100), _row("ggx", 1080, 0.108), _row("lambert", 0, 0.30)]
    assert recommend(rows)["m"]["model"] == "ggx"  # 8 % worse: within 10 %, smaller
    rows[1]["cos_rel_error"] = 0.115
    assert recommend(rows)["m"]["model"] == "tab"  # 15 % worse: out
    rows = [_row("tab", 1800, 0.010), _row("ggx", 1080, 0.0145)]
    assert recommend(rows)["m"]["model"] == "ggx"  # the absolute floor (0.005) applies
    rows = [_row("a", 0, 0.2), _row("b", 0, 0.1)]
    assert recommend(rows)["m"]["model"] == "b"  # same size: the lower error
    rows = [_row("tab", 1800, 0.1), _row("ggx", 1080, 0.01, status="failed")]
    assert recommend(rows)["m"]["model"] == "tab"  # failed fits are never recommended
    assert recommend([_row("x", 10, status="failed")]) == {}


def test_recommend_rule_with_renders():
    rows = [_row("npf", 3264, 0.05, 40.0, 0.1), _row("ggx", 1080, 0.2, 39.3, 0.1)]
    assert recommend(rows)["m"]["model"] == "ggx"  # 0.7 dB: within 1 dB
    rows[1]["psnr"] = 38.0
    assert recommend(rows)["m"]["model"] == "npf"  # 2 dB: out
    rows[0]["psnr_se"] = rows[1]["psnr_se"] = 1.0  # 2 se of the difference = 2.8 dB
    assert recommend(rows)["m"]["model"] == "ggx"
    rows[1]["psnr"] = None  # one fit not rendered: decide on the BRDF-space error
    assert recommend(rows)["m"]["by"] == "cos_rel_error"


def test_error_domain_names_the_measured_domain(tmp_path, shared_data):
    """A measurement with a smaller measured domain (RGL: θi up to its last measured
    incidence) says so in the row of every fit whose errors were computed over it."""
    out = tmp_path / "rgl"
    spec = str(shared_data("rgl", "paper_white_rgb.bsdf"))
    assert run_task(Task("paper", spec, "ggx-diffuse"), out)["status"] == "ok"
    write_summary(out)
    row = _csv(out)[0]
    assert row["error_domain"] == "θi ≤ 78.5° (the file's measured incidences)"
    assert 0 < _f(row["cos_rel_error"]) < 0.1 and row["warnings"] == ""
