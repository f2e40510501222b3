"""Report pages of fitted models: parameter table, convergence, files and exports; the index
with a thumbnail per model, a filter, the batch tables and the recommended model (issue 16.3)."""

from __future__ import annotations

import json
import math

import pytest

import brdffit
from brdffit.evaluation import report as R
from brdffit.batch import compare_with_exports

from .test_report import standin_render


@pytest.fixture(scope="module")
def fitted_report(tmp_path_factory):
    root = tmp_path_factory.mktemp("batch")
    out = root / "report"
    res = compare_with_exports(brdffit.synthetic("gold-ggx"), ["tabulated", "ggx", "npf-g-from-d"],
                               out, renderer=standin_render, spp=8, resolution=16,
                               brdf_metric_samples=1 << 9,
                               fit_options={"npf-g-from-d": {"max_iter": 5, "polish": 0}})
    return root, out, res


def test_material_page_tables_files_and_exports(fitted_report):
    _, out, res = fitted_report
    page = out / res["slug"] / "index.html"
    text = page.read_text(encoding="utf-8")
    ggx = next(m for m in res["models"] if m["name"] == "ggx")
    alpha = ggx["params"]["figures"]["alpha"][0]
    assert "glTF roughness √α" in text and R._fmt(math.sqrt(alpha), 4) in text
    # convergence: the tabulated fit reports its power iterations; NPF its AWLS history
    assert '<table class="sortable" id="convergence">' in text
    tab = next(m for m in res["models"] if m["name"] == "tabulated")
    assert tab["convergence"]["converged"] is True and tab["convergence"]["nit"] > 0
    npf = next(m for m in res["models"] if m["name"] == "npf-g-from-d")
    assert npf["convergence"]["history"]["quantity"] == "objective"
    assert text.count("<svg") >= 2                          # tabulated + NPF histories
    # files: fit files and engine exports, every link resolves
    links = R.local_links(page)
    for f in ("fits/ggx.npz", "exports/ggx.json", "exports/ggx.gltf", "exports/ggx.mtlx",
              "exports/npf-g-from-d.json"):
        assert f in links, f
    assert "exports/npf-g-from-d.gltf" not in links         # NPF has no glTF form
    assert R.missing_links(page) == []
    # the full JSON is folded away and readable (no \\u escapes)
    assert "<details>" in text and "\\u03b8" not in text


def test_index_thumbnails_filter_summary_links_and_recommendation(fitted_report):
    root, out, res = fitted_report
    (root / "summary.csv").write_text("material,model\n")
    (root / "summary.json").write_text(json.dumps(
        {"rows": [], "recommended": {res["material"]: {"model": "ggx"}}}))
    idx = R.write_index(out)
    text = idx.read_text(encoding="utf-8")
    for name in ("tabulated", "ggx", "npf-g-from-d"):
        assert f'alt="{name} rendering"' in text                 # a thumbnail per model
    assert 'id="filter"' in text and "filterRows" in text
    assert 'href="../summary.csv"' in text and 'href="../summary.json"' in text
    assert "recommended model" in text and "<td class=\"l\">ggx</td>" in text
    assert "cos-weighted rel. error" in text
    assert R.missing_links(idx) == []


def test_loaded_fit_files_are_linked_where_they_are(tmp_path):
    """A batch renders fits it saved in OUT/fits/: the page links them there (relative)."""
    from brdffit.fit.registry import fit_model
    from brdffit.io.fitfile import save_fit

    ref = brdffit.synthetic("gold-ggx")
    fp = save_fit(fit_model("ggx", ref)[0], tmp_path / "fits" / "gold" / "ggx.npz")
    res = compare_with_exports(ref, {"ggx": str(fp)}, tmp_path / "report",
                               renderer=standin_render, spp=4, resolution=16,
                               brdf_metric_samples=1 << 9)
    page = tmp_path / "report" / res["slug"] / "index.html"
    links = R.local_links(page)
    assert "../../fits/gold/ggx.npz" in links and "exports/ggx.gltf" in links
    assert R.missing_links(page) == []
