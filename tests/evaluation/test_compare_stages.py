"""The stages of a comparison (resolve → fit → render → measure → write around a
:class:`Comparison`) and the engine files written by the caller between them."""

from __future__ import annotations

import json
import re

import pytest

import brdffit
from brdffit import batch
from brdffit.evaluation import compare as C
from brdffit.io.fitfile import save_fit
from tests.evaluation.test_metrics import Lambert, Phongish

from .test_report import _ref, standin_render

_TIMES = re.compile(r"time|seconds|created|timing|setup", re.I)
_FAST = dict(renderer=standin_render, spp=4, resolution=16, brdf_metric_samples=1 << 8,
             brdf_metrics=("cos_rel_error",))


def _untimed(obj):
    """``obj`` without its timings and timestamps."""
    if isinstance(obj, dict):
        return {k: _untimed(v) for k, v in obj.items() if not _TIMES.search(k)}
    if isinstance(obj, list):
        return [_untimed(v) for v in obj]
    return obj


def _models():
    return {"lambert": Lambert([0.3, 0.25, 0.2]), "exact": Phongish(30),
            "broken": "no-such-model"}


def test_the_stages_write_what_compare_writes(tmp_path):
    """compare() is resolve_comparison → fit_models → render_scenes → measure_models →
    write_report: the same result.json (timings aside), files and key order."""
    whole = C.compare(_ref(), _models(), tmp_path / "whole", **_FAST)
    c = C.resolve_comparison(_ref(), _models(), tmp_path / "staged", **_FAST)
    assert c.folder == tmp_path / "staged" / c.slug and c.folder.is_dir() and not c.records
    C.fit_models(c)
    assert [r["status"] for r in c.records] == ["ok", "ok", "failed"]
    assert set(c.fitted) == {"lambert", "exact"}
    staged = C.write_report(C.measure_models(C.render_scenes(c)))
    assert staged is c.result
    assert _untimed(staged) == _untimed(whole)
    files = {p.relative_to(tmp_path / "whole") for p in (tmp_path / "whole").rglob("*")}
    assert files == {p.relative_to(tmp_path / "staged")
                     for p in (tmp_path / "staged").rglob("*")}
    written = json.loads((c.folder / "result.json").read_text())
    assert list(written) == list(json.loads(
        (tmp_path / "whole" / c.slug / "result.json").read_text()))


def test_compare_writes_no_engine_files(tmp_path):
    """Exports are the caller's: compare() has no exports option and writes none."""
    with pytest.raises(TypeError, match="exports"):
        C.compare(_ref(), {"lambert": Lambert([0.3] * 3)}, tmp_path, exports=None)
    ref = brdffit.synthetic("gold-ggx")
    fp = save_fit(ref, tmp_path / "fits" / "gold.npz")
    res = C.compare(ref, {"gold": str(fp)}, tmp_path / "report", **_FAST)
    rec = res["models"][0]
    assert rec["status"] == "ok" and "exports" not in rec and "fit_file" not in rec
    assert not (tmp_path / "report" / res["slug"] / "exports").exists()


def test_compare_with_exports_links_saved_and_loaded_fits(tmp_path):
    """The caller's exports: a fit saved by the comparison and a loaded fit file both get
    their engine files, listed in result.json; the loaded fit is linked where it is."""
    ref = brdffit.synthetic("gold-ggx")
    fp = save_fit(ref, tmp_path / "fits" / "gold.npz")
    res = batch.compare_with_exports(ref, {"loaded": str(fp), "given": Lambert([0.3] * 3)},
                                     tmp_path / "report", **_FAST)
    by = {m["name"]: m for m in res["models"]}
    assert by["loaded"]["fit_file"] == "../../fits/gold.npz"
    assert by["loaded"]["exports"] and all(p.startswith("exports/loaded.")
                                           for p in by["loaded"]["exports"])
    for p in by["loaded"]["exports"]:
        assert (tmp_path / "report" / res["slug"] / p).is_file()
    assert "exports" not in by["given"]  # no fit file: nothing to export
    written = json.loads((tmp_path / "report" / res["slug"] / "result.json").read_text())
    assert written["models"][0]["exports"] == by["loaded"]["exports"]


def test_an_export_that_raises_is_recorded_on_its_model(tmp_path, monkeypatch):
    """A loaded fit whose engine files cannot be written fails (its record says why); the
    other models are still rendered."""
    def broken(model, folder, stem):
        raise OSError("disk full")

    monkeypatch.setattr(batch, "report_exports", broken)
    ref = brdffit.synthetic("gold-ggx")
    fp = save_fit(ref, tmp_path / "gold.npz")
    res = batch.compare_with_exports(ref, {"loaded": str(fp), "given": Lambert([0.3] * 3)},
                                     tmp_path / "report", **_FAST)
    by = {m["name"]: m for m in res["models"]}
    assert by["loaded"]["status"] == "failed" and "disk full" in by["loaded"]["error"]
    assert by["given"]["status"] == "ok" and "psnr" in by["given"]


def test_compare_many_runs_the_given_function(tmp_path):
    """compare_many calls ``run`` per material and records a material that fails."""
    seen = []

    def run(src, models, out_dir, **kw):
        seen.append(kw["update_index"])
        return C.compare(src, models, out_dir, **kw)

    out = C.compare_many([_ref(), "synthetic:no-such-material"],
                         {"lambert": Lambert([0.3] * 3)}, tmp_path, run=run, **_FAST)
    assert seen == [False, False]
    assert out[0]["models"][0]["status"] == "ok" and "error" in out[1]
    assert (tmp_path / "index.html").is_file()


def test_figures_measured_elsewhere_are_taken_as_they_are(tmp_path, monkeypatch):
    """``measured``: a model's given BRDF metrics and validity list are the result's; the
    model without given figures is measured (the reference prepared for it only)."""
    given = {"brdf": {"cos_rel_error": 0.125}, "validity": [{"check": "albedo", "value": 1.5}]}
    prepared = []
    real = C.M.BRDFMetrics

    def counting(*args, **kwargs):
        prepared.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(C.M, "BRDFMetrics", counting)
    res = C.compare(_ref(), {"lambert": Lambert([0.3, 0.25, 0.2]), "exact": Phongish(30)},
                    tmp_path, measured={"lambert": given}, **_FAST)
    by = {m["name"]: m for m in res["models"]}
    assert by["lambert"]["brdf"] == given["brdf"]
    assert by["lambert"]["validity"] == given["validity"]
    assert by["exact"]["validity"] == [] and "cos_rel_error" in by["exact"]["brdf"]
    assert len(prepared) == 1
    prepared.clear()
    C.compare(_ref(), {"lambert": Lambert([0.3, 0.25, 0.2])}, tmp_path / "b",
              measured={"lambert": given}, **_FAST)
    assert prepared == []
