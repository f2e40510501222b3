"""Tests of the comparison report (compare + report) with a tiny NumPy stand-in renderer."""

from __future__ import annotations

import json

import numpy as np
import pytest

from brdffit.evaluation import compare as C
from brdffit.evaluation import report as R
from tests.evaluation.test_metrics import Lambert, Phongish
from tests.evaluation.test_plots import FakeMicrofacet


def standin_render(brdf, scene="sphere", spp=4, resolution=24, seed=0, **_):
    """Orthographic sphere under one distant light + a constant sky term, evaluated with
    ``brdf.eval`` per pixel; seed-dependent noise of relative size 1/sqrt(spp) mimics MC."""
    n = int(resolution)
    y, x = np.mgrid[0:n, 0:n]
    px = (x + 0.5) / n * 2 - 1
    py = 1 - (y + 0.5) / n * 2
    r2 = px**2 + py**2
    mask = r2 < 1
    nz = np.sqrt(np.clip(1 - r2, 0, 1))
    nrm = np.stack([px, py, nz], -1)
    # local frame around the normal
    t = np.cross(nrm, [0.0, 1.0, 0.0])
    t /= np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-9)
    b = np.cross(nrm, t)

    def local(w):
        return np.stack([np.sum(w * t, -1), np.sum(w * b, -1), np.sum(w * nrm, -1)], -1)

    v = np.broadcast_to([0.0, 0.0, 1.0], nrm.shape)
    light = np.array([0.5, 0.5, 0.707])
    light = np.broadcast_to(light / np.linalg.norm(light), nrm.shape)
    wi, wo = local(light), local(v)
    f = np.asarray(brdf.eval(wi, wo))
    img = f * np.clip(wi[..., 2:3], 0, None) * 5.0 + 0.05
    rng = np.random.default_rng(seed)
    img = img * (1 + rng.normal(0, 0.3 / np.sqrt(spp), img.shape))
    return np.where(mask[..., None], np.maximum(img, 0), 0.0), mask


def _ref():
    ref = Phongish(30)
    ref.name = "glossy test/material"  # slash: must be made a safe directory name
    return ref


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    models = {"lambert": Lambert([0.3, 0.25, 0.2]), "microfacet": FakeMicrofacet(),
              "exact": Phongish(30), "broken": "no-such-model"}
    res = C.compare(_ref(), models, out, renderer=standin_render, spp=16, resolution=24,
                    brdf_metric_samples=1 << 10)
    return out, res


def test_compare_result_and_metrics(report_dir):
    out, res = report_dir
    by = {m["name"]: m for m in res["models"]}
    assert set(by) == {"lambert", "microfacet", "exact", "broken"}
    assert by["broken"]["status"] == "failed" and "no-such-model" in by["broken"]["error"]
    # same scene and seed: the reference itself renders identically
    assert by["exact"]["psnr"] == np.inf and by["exact"]["mean_de2000"] == 0.0
    assert by["exact"]["brdf"]["cos_rel_error"] == 0.0
    assert by["exact"]["psnr_se"] == 0.0
    assert by["microfacet"]["psnr"] > by["lambert"]["psnr"]
    assert by["lambert"]["mean_de2000"] > 0
    assert "noise_floor_psnr" not in res  # replaced by the standard errors
    saved = json.loads((out / res["slug"] / "result.json").read_text())
    assert saved["models"][2]["psnr"] == "inf"  # non-finite floats stay valid JSON


def test_result_json_has_psnr_se_and_scenes(report_dir):
    """Public interface (issue 13): per model psnr (mean over scenes), psnr_se and per-scene
    PSNR ± se; a top-level scenes list (the paper suite, or its procedural fallback)."""
    from brdffit.evaluation.render.scenes import scene_suite

    out, res = report_dir
    saved = json.loads((out / res["slug"] / "result.json").read_text())
    names = [s.name for s in scene_suite("paper")[0]]
    assert [s["name"] for s in saved["scenes"]] == names and len(names) in (2, 4)
    for s in saved["scenes"]:
        assert s["reference"]["png"] and s["reference"]["peak"] > 0 and len(s["seeds"]) == 8
        assert (out / res["slug"] / s["reference"]["png"]).is_file()
    lam = next(m for m in saved["models"] if m["name"] == "lambert")
    assert [e["scene"] for e in lam["scenes"]] == names
    per = [e["psnr"] for e in lam["scenes"]]
    assert lam["psnr"] == pytest.approx(np.mean(per))
    ses = np.array([e["psnr_se"] for e in lam["scenes"]])
    assert np.all(ses > 0) and lam["psnr_se"] == pytest.approx(np.sqrt(np.sum(ses**2)) / len(ses))
    assert 0 < lam["psnr_se"] < 1.0
    for e in lam["scenes"]:
        assert (out / res["slug"] / e["png"]).is_file() and (out / res["slug"] / e["de_png"]).is_file()


def test_pages_contain_every_model_and_links_resolve(report_dir):
    out, res = report_dir
    page = out / res["slug"] / "index.html"
    idx = out / "index.html"
    text = page.read_text()
    for name in ("lambert", "microfacet", "exact", "broken", "glossy test/material"):
        assert name in text
    assert R.missing_links(page) == [] and R.missing_links(idx) == []
    links = R.local_links(page)
    for sc in res["scenes"]:   # every scene's reference, renderings and dE maps
        assert sc["reference"]["png"] in links and f"Scene {sc['name']}" in text
        assert f"{sc['name']}-lambert.png" in links and f"{sc['name']}-lambert_de2000.png" in links
    assert "lobes.png" in links
    lam = next(m for m in res["models"] if m["name"] == "lambert")
    shown = R._pm(lam["psnr"], lam["psnr_se"])
    assert " ± " in shown and shown in text and shown in idx.read_text()  # PSNR ± se
    assert "factors.png" in links and "slices.png" in links
    assert "http" not in idx.read_text() and "<script src" not in idx.read_text()
    assert "microfacet" in idx.read_text()


def test_index_rebuilt_when_a_material_is_added(report_dir, tmp_path):
    out, _ = report_dir
    other = Lambert([0.6, 0.5, 0.4])
    other.name = "second"
    C.compare(other, {"lambert": Lambert([0.5, 0.5, 0.5])}, out, renderer=standin_render, spp=4,
              resolution=16, noise_floor=False, brdf_metric_samples=1 << 8)
    text = (out / "index.html").read_text()
    assert "second/index.html" in text and f"{R.slugify('glossy test/material')}/index.html" in text
    summ = json.loads((out / "summary.json").read_text())
    assert summ["n_materials"] == 2 and summ["per_model"]["lambert"]["n"] == 2
    assert R.missing_links(out / "index.html") == []


def test_index_reads_old_results_with_a_noise_floor(tmp_path):
    """result.json files of earlier versions (one scene, noise floor, no psnr_se) still make
    the index and their page; the noise-floor column only appears for them."""
    old = {"material": "old", "slug": "old", "scene": {"scene": "sphere-env", "spp": 64},
           "noise_floor_psnr": 35.5, "reference": {},
           "models": [{"name": "ggx", "status": "ok", "psnr": 30.25, "mean_de2000": 1.5}]}
    R.write_result(tmp_path / "old", old)
    R.write_material_page(tmp_path, old)
    text = R.write_index(tmp_path).read_text()
    assert "noise floor PSNR" in text and "35.50" in text and "30.25" in text
    assert "30.25" in (tmp_path / "old" / "index.html").read_text()
    new = {"material": "new", "slug": "new", "scenes": [{"name": "sphere-env"}], "reference": {},
           "models": [{"name": "ggx", "status": "ok", "psnr": 31.0, "psnr_se": 0.125,
                       "scenes": [{"scene": "sphere-env", "psnr": 31.0, "psnr_se": 0.125}]}]}
    R.write_result(tmp_path / "new", new)
    R.write_material_page(tmp_path, new)
    assert "31.00 ± 0.12" in (tmp_path / "new" / "index.html").read_text()
    assert "31.00 ± 0.12" in R.write_index(tmp_path).read_text()
    assert R.summarize(R.read_results(tmp_path))["per_model"]["ggx"]["median_psnr_se"] == 0.125


def test_missing_links_detects_problems(tmp_path):
    p = tmp_path / "x.html"
    (tmp_path / "a.png").write_bytes(b"x")
    p.write_text('<img src="a.png"><img src="b.png"><a href="https://cdn.example/x.js">'
                 '<img src="/abs.png">')
    assert R.missing_links(p) == ["b.png", "https://cdn.example/x.js", "/abs.png"]


def test_summarize_counts_wins():
    results = [{"models": [{"name": "a", "psnr": 30}, {"name": "b", "psnr": 25}]},
               {"models": [{"name": "a", "psnr": 30}, {"name": "b", "psnr": 31}]},
               {"models": [{"name": "a", "status": "failed"}, {"name": "b", "psnr": 20}]}]
    s = R.summarize(results)
    assert s["per_model"]["a"]["n"] == 2 and s["per_model"]["b"]["mean_psnr"] == pytest.approx(76 / 3)
    assert s["wins"]["a"]["b"] == {"wins": 1, "ties": 1, "losses": 0, "n": 2}


def test_cli_compare(tmp_path, monkeypatch, capsys):
    from brdffit.cli import main

    monkeypatch.setattr(C, "_default_renderer", lambda: standin_render)
    monkeypatch.setattr(C, "resolve_reference", lambda src, material=None: _ref())
    seen = []
    fitters = {"lam": lambda brdf, albedo=0.3: seen.append(albedo) or Lambert([albedo] * 3),
               "mf": lambda brdf: FakeMicrofacet()}
    from brdffit.fit import registry

    for name, fn in fitters.items():
        monkeypatch.setitem(registry.FITTERS, name, registry.Fitter(name, fn))
    rc = main(["compare", "whatever.h5", "--models", "lam,mf", "--out", str(tmp_path),
               "--spp", "4", "--resolution", "16", "--no-noise-floor", "-q",
               "--scenes", "sphere-env", "--fit-options", '{"lam": {"albedo": 0.7}}'])
    assert rc == 0
    out = capsys.readouterr().out
    assert "lam" in out and "mf" in out and "index.html" in out and " ± " in out
    page = tmp_path / R.slugify("glossy test/material") / "index.html"
    assert page.is_file() and R.missing_links(page) == []
    res = json.loads((tmp_path / R.slugify("glossy test/material") / "result.json").read_text())
    assert res["scene"]["spp"] == 4 and res["scene"]["resolution"] == 16
    assert res["scene"]["batches"] == 4 and [s["name"] for s in res["scenes"]] == ["sphere-env"]
    assert [m["fit_time"] is not None for m in res["models"]] == [True, True]
    assert seen == [0.7]  # --fit-options reached the fitter
    assert main(["compare", "x.h5", "--models", "lam", "--out", str(tmp_path),
                 "--fit-options", "[1]", "-q"]) == 1  # one-line error, not a traceback
    assert "--fit-options" in capsys.readouterr().err


def test_compare_loads_saved_fit_files(tmp_path):
    """Models given as fit files are loaded (not refitted) and end up in the report."""
    synth = pytest.importorskip("brdffit.synthetic")
    from brdffit.io.fitfile import save_fit

    ref = synth.synthetic("gold-ggx")
    fp = save_fit(ref, tmp_path / "same.npz")
    res = C.compare(ref, [f"copy={fp}", str(fp)], tmp_path / "rep", renderer=standin_render,
                    spp=4, resolution=16, noise_floor=False, brdf_metric_samples=1 << 8,
                    brdf_metrics=("cos_rel_error",))
    names = [m["name"] for m in res["models"]]
    assert names == ["copy", "same"]
    for m in res["models"]:
        assert m["status"] == "ok" and m["origin"].startswith("loaded")
        assert m["psnr"] == np.inf and m["brdf"]["cos_rel_error"] == pytest.approx(0.0, abs=1e-6)


def test_material_page_says_where_the_error_lies(report_dir):
    """The section of the most faithful fit by BRDF-space error (here "exact" or the equal
    "microfacet", error 0: no region stands out), with its regions table; a finding reaches
    the page escaped."""
    out, res = report_dir
    text = (out / res["slug"] / "index.html").read_text()
    assert "(0.0 %, the most faithful fit)" in text and "No region stands out." in text
    for region in ("specular peak", "retro-reflection", "grazing", "body"):
        assert f'<td class="l">{region}</td>' in text
    lam = next(m for m in res["models"] if m["name"] == "lambert")
    hostile = dict(lam, name="<b>x</b>", brdf=dict(lam["brdf"], cos_rel_error=0.0,
                   error_regions=dict(lam["brdf"]["error_regions"], findings=["a <i>b</i>"])))
    section = R._error_regions_section([hostile])
    assert "&lt;i&gt;b&lt;/i&gt;" in section and "<i>" not in section and "<b>x</b>" not in section
