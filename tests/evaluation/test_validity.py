"""brdffit.evaluation.validity: the physical checks of a fit (issue 31.2)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from brdffit.brdf import BRDF
from brdffit.cli import main
from brdffit.evaluation.validity import check_validity
from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel, SumBRDF
from brdffit.synthetic import list_synthetic, synthetic


@pytest.mark.parametrize("name", list_synthetic())
def test_the_synthetic_materials_are_valid(name):
    assert check_validity(synthetic(name)) == []


def test_a_fresnel_above_one_is_named_with_its_channel_and_the_advice():
    model = MicrofacetBRDF(GGX(0.3), SchlickFresnel([0.9, 0.5, 0.4]), specular=[1.5, 1.0, 1.0])
    (v,) = [v for v in check_validity(model) if v.check == "fresnel"]
    assert v.figure == pytest.approx(1.5) and "in red" in v.message
    assert "--model ggx-diffuse" in v.advice   # no diffuse term: it absorbed one
    coated = SumBRDF([MicrofacetBRDF(GGX(0.3), SchlickFresnel(0.04), diffuse=0.5),
                      MicrofacetBRDF(GGX(0.05), SchlickFresnel(0.04), specular=30.0)])
    (v,) = [v for v in check_validity(coated) if v.check == "fresnel"]
    assert v.figure > 1 and "clamps" in v.advice


def test_an_albedo_above_one_fails_the_furnace_and_a_tiny_excess_does_not():
    bright = MicrofacetBRDF(GGX(0.2), SchlickFresnel(0.04), diffuse=[1.3, 0.5, 0.5])
    (v,) = [v for v in check_validity(bright) if v.check == "albedo"]
    assert 1.3 < v.figure < 1.6 and "in red" in v.message  # + the specular lobe
    white = MicrofacetBRDF(GGX(0.2), SchlickFresnel(0.0), diffuse=1.0, specular=0.0)
    assert [v for v in check_validity(white) if v.check == "albedo"] == []


class _Odd(BRDF):
    """Negative where wi.x > 0.9, and not reciprocal (depends on wi.z only)."""

    def eval(self, wi, wo):
        wi, wo = np.asarray(wi, float), np.asarray(wo, float)
        v = 0.1 * wi[..., 2] * (wo[..., 2] > 0) - 0.2 * (wi[..., 0] > 0.9)
        return np.repeat(v[..., None], 3, -1)


def test_negative_values_and_a_broken_reciprocity_are_found():
    found = {v.check: v for v in check_validity(_Odd())}
    assert found["non_negative"].figure < 0 and found["reciprocity"].figure > 0.01


@pytest.fixture
def quick_alternatives(monkeypatch):
    """The quality warning's other candidates cut to the fast one (these tests are about the
    physical checks; tests/evaluation/test_validity.py::test_a_large_error_names_a_better_model
    covers the candidates)."""
    from brdffit.cli import fit as F

    monkeypatch.setattr(F, "ALTERNATIVES", ("ggx-diffuse",))


def test_fit_prints_the_warnings_and_json_carries_them(capsys, quick_alternatives):
    assert main(["fit", "synthetic:plastic-beckmann", "-m", "tabulated", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert isinstance(doc["warnings"], list)
    assert main(["fit", "synthetic:gold-ggx"]) == 0
    out = capsys.readouterr()
    assert "physical checks     F ≤ 1, albedo ≤ 1, f ≥ 0, reciprocal: all passed" in out.out
    assert "warning" not in out.err


def test_the_tabulated_fit_is_valid_and_the_papers_lobe_alone_warns(capsys, quick_alternatives):
    """A diffuse material: the default tabulated fit carries the base in its Lambertian term
    (F ≤ 1, all checks pass); the paper's lobe alone with an unbounded F absorbs it (F0 > 1)."""
    assert main(["fit", "synthetic:plastic-beckmann", "-m", "tabulated"]) == 0
    out = capsys.readouterr()
    assert "F ≤ 1, albedo ≤ 1, f ≥ 0, reciprocal: all passed" in out.out
    assert not [ln for ln in out.err.splitlines() if "fresnel" in ln or "albedo" in ln]
    assert main(["fit", "synthetic:plastic-beckmann", "-m", "tabulated",
                 "-O", "diffuse=false", "-O", "fresnel_max=100"]) == 0
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("brdffit: warning:")]
    assert lines and all("(tabulated fit): " in ln for ln in lines)


def test_the_report_shows_a_badge_and_the_summary_a_column(tmp_path):
    from brdffit.batch_summary import summary_rows
    from brdffit.evaluation.report import write_index, write_material_page, write_result

    model = MicrofacetBRDF(GGX(0.3), SchlickFresnel(0.9), specular=1.5)
    checks = [v.as_dict() for v in check_validity(model)]
    fig = {"params": {"figures": {"alpha": [0.3, 0.3, 0.0], "f0": [1.35] * 3, "rho_d": [0.0] * 3,
                                  "table_bytes": 0}}}
    result = {"material": "m", "slug": "m", "models": [
        {"name": "bad", "status": "ok", "psnr": 30.0, "validity": checks, **fig},
        {"name": "good", "status": "ok", "psnr": 40.0, "validity": [], **fig}]}
    write_result(tmp_path / "m", result)
    page = write_material_page(tmp_path, result).read_text()
    index = write_index(tmp_path).read_text()
    assert "⚠ fresnel 1.5" in page and '<span class="badge ok"' in page
    assert "⚠ fresnel 1.5" in index and index.count('class="badge') == 1
    rows, _ = summary_rows([{"material": "m", "model": "bad", "status": "ok",
                             "warnings": checks},
                            {"material": "m", "model": "good", "status": "ok", "warnings": []}],
                           tmp_path)
    assert rows[0]["warnings"].startswith("fresnel 1.5") and rows[1]["warnings"] == ""


def test_a_large_error_names_a_better_model(monkeypatch, capsys):
    from brdffit.cli import fit as F

    monkeypatch.setattr(F, "LARGE_ERROR", 1e-9)      # every fit's error is "large" here
    monkeypatch.setattr(F, "ALTERNATIVES", ("ggx-diffuse", "sgd"))
    assert main(["fit", "synthetic:plastic-beckmann", "-m", "ggx", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    (q,) = [w for w in doc["warnings"] if w["check"] == "quality"]
    assert q["message"].startswith("the error ") and "is large (above 1e-07 %)" in q["message"]
    # the synthetic material is a Beckmann + Lambert: GGX + Lambert fits it far better
    assert q["advice"].startswith("ggx-diffuse does better on this material") or \
        q["advice"].startswith("sgd does better on this material"), q["advice"]
    assert "--model " in q["advice"] and "tried ggx-diffuse" in q["advice"]
