"""``brdffit fit``: summary output, JSON, fit file, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from brdffit.cli import main
from brdffit.cli.fit import parse_options
from brdffit.io.fitfile import load_fit, read_fit_header


def test_fit_json_and_output(tmp_path, capsys):
    out = tmp_path / "gold.npz"
    code = main(["fit", "synthetic:gold-ggx", "--model", "tabulated", "-o", str(out),
                 "--iterations", "6", "--option", "hotspot=\"G2\"", "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["iterations"] == 6
    assert summary["ggx_alpha"][0] == pytest.approx(0.12, rel=0.02)  # synthetic gold is GGX 0.12
    assert len(summary["fresnel_0"]) == 3 and summary["fresnel_0"][0] > summary["fresnel_0"][2]
    model = load_fit(out)
    header = read_fit_header(out)
    assert header["source"]["spec"] == "synthetic:gold-ggx"
    assert header["options"]["iterations"] == 6
    w = np.array([[0.3, 0.1, np.sqrt(0.9)]])
    assert np.all(np.isfinite(model.eval(w, w)))


def test_fit_text_summary_ggx(capsys):
    assert main(["fit", "synthetic:gold-ggx", "--model", "ggx"]) == 0
    text = capsys.readouterr().out
    assert "eigenvalue" in text and "alpha" in text and "fresnel_0" in text


def test_unknown_model_is_a_usage_error(capsys):
    code = main(["fit", "synthetic:gold-ggx", "--model", "no-such-model"])
    assert code == 2
    assert "no-such-model" in capsys.readouterr().err


def test_missing_input_is_an_error(tmp_path, capsys):
    code = main(["fit", str(tmp_path / "missing.binary"), "--model", "tabulated"])
    assert code == 1
    assert "missing.binary" in capsys.readouterr().err


def test_parse_options():
    assert parse_options(["tol=1e-6", "anisotropic=true", "rule=gauss"]) == {
        "tol": 1e-6, "anisotropic": True, "rule": "gauss"}
