"""``brdffit fit``: labelled summary, JSON, fit file, quick error, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from brdffit.cli import main
from brdffit.cli.fit import parse_options, quick_error
from brdffit.io.fitfile import load_fit, read_fit_header


def test_fit_json_and_output(tmp_path, capsys):
    out = tmp_path / "gold.npz"
    code = main(["fit", "synthetic:gold-ggx", "--model", "tabulated", "-o", str(out),
                 "--iterations", "6", "--option", "hotspot=\"G2\"", "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["details"]["iterations"] == 6
    assert summary["output"] == str(out)
    # synthetic gold is GGX α = 0.12 with gold's conductor Fresnel: the labelled figures
    assert summary["alpha_kind"] == "ggx-equivalent"
    assert summary["alpha"]["x"] == pytest.approx(0.12, rel=0.02)
    assert summary["gltf_roughness"][0] == pytest.approx(np.sqrt(summary["alpha"]["x"]))
    assert len(summary["f0"]) == 3 and summary["f0"][0] > summary["f0"][2]
    assert summary["rho_d"] == [0.0, 0.0, 0.0]
    assert summary["error"]["cos_rel_error"] < 0.02
    assert summary["table_bytes"] > 0
    assert set(summary["timings_s"]) >= {"load", "fit", "save", "error"}
    model = load_fit(out)
    header = read_fit_header(out)
    assert header["source"]["spec"] == "synthetic:gold-ggx"
    assert header["options"]["iterations"] == 6
    w = np.array([[0.3, 0.1, np.sqrt(0.9)]])
    assert np.all(np.isfinite(model.eval(w, w)))


def test_fit_text_summary_is_labelled_and_says_it_was_not_saved(capsys):
    assert main(["fit", "synthetic:gold-ggx", "--model", "ggx"]) == 0
    lines = capsys.readouterr().out.splitlines()
    text = "\n".join(lines)
    assert "αx 0.12" in text and "αy 0.12" in text           # exact: the input is GGX 0.12
    assert "glTF roughness √α" in text and "0.3464" in text   # √0.12
    for label in ("F0", "ρd", "error vs input", "NOT saved"):
        assert label in text, label
    assert "eigenvalue" in text  # the model's own figures follow
    assert all(len(line) <= 80 for line in lines), [ln for ln in lines if len(ln) > 80]


def test_fit_says_where_it_saved(tmp_path, capsys):
    out = tmp_path / "f.npz"
    assert main(["fit", "synthetic:plastic-beckmann", "--model", "ggx", "-o", str(out),
                 "--no-error"]) == 0
    text = capsys.readouterr().out
    assert f"saved to            {out}" in text and "NOT saved" not in text
    assert out.is_file()


def test_fit_json_without_output_is_null(capsys):
    assert main(["fit", "synthetic:gold-ggx", "--model", "ggx", "--json", "--no-error"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["output"] is None and summary["error"] is None


def test_per_channel_and_diffuse_figures(capsys):
    """plastic-beckmann: Beckmann α = 0.18, dielectric η = 1.5 (F0 = 0.04), red Lambertian
    ρd = (0.45, 0.06, 0.04); a per-channel Cook-Torrance fit recovers them."""
    assert main(["fit", "synthetic:plastic-beckmann", "--model", "beckmann-ct", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["alpha"] is None and s["alpha_rgb"] == pytest.approx([0.18] * 3, rel=0.1)
    assert s["rho_d"] == pytest.approx([0.45, 0.06, 0.04], abs=0.01)
    assert s["f0"] == pytest.approx([0.04] * 3, abs=0.015)


def test_quick_error_matches_the_metric():
    """The quick error of the summary estimates the same quantity as the batch metric
    (cos_rel_error, 2^17 Sobol pairs): on an analytic input (quasi-random pairs) and on a
    MERL table (its own grid nodes)."""
    from brdffit import synthetic
    from brdffit.evaluation.metrics import cosine_weighted_relative_error
    from brdffit.fit import registry
    from brdffit.grid import tabulate_merl_grid
    from brdffit.io.merl import MERLBRDF

    ref = synthetic("plastic-beckmann")
    fits = [registry.get("ggx").fit(ref), registry.get("sgd").fit(ref)]
    table = MERLBRDF(*tabulate_merl_grid(ref))
    for fitted in fits:
        full = cosine_weighted_relative_error(ref, fitted)
        q = quick_error(ref, fitted)
        assert "pairs" in q["method"] and q["cos_rel_error"] == pytest.approx(full, rel=0.1)
        qt = quick_error(table, fitted)
        assert "MERL nodes" in qt["method"]
        assert qt["cos_rel_error"] == pytest.approx(cosine_weighted_relative_error(
            table, fitted), rel=0.1, abs=0.003)
    assert quick_error(ref, ref)["cos_rel_error"] == 0.0


def test_grid_error_directions_are_the_nodes_half_diff_directions():
    """The quick error's closed-form (wi, wo) of the MERL nodes equal half_diff_to_io at
    φh = 0, node for node, and weigh exactly the valid nodes above the horizon (of non-zero
    measure: θh, θd > 0)."""
    from brdffit.cli.fit import QUICK_ERROR_GRID_STRIDE, _grid_error
    from brdffit.geometry import half_diff_to_io
    from brdffit.grid import merl_phi_d, merl_theta_d, merl_theta_h

    si, sj, sk = QUICK_ERROR_GRID_STRIDE
    th, td, pd = np.meshgrid(merl_theta_h()[::si], merl_theta_d()[::sj], merl_phi_d()[::sk],
                             indexing="ij")
    valid = np.random.default_rng(5).random((90, 90, 180)) > 0.2
    seen = {"wi": [], "wo": []}

    class Probe:
        def eval(self, wi, wo):
            seen["wi"].append(wi)
            seen["wo"].append(wo)
            return np.zeros(wi.shape[:-1] + (3,))

    _, n = _grid_error(np.ones((90, 90, 180, 3)), valid, Probe())
    seen = {k: np.concatenate(v) for k, v in seen.items()}
    wi, wo = half_diff_to_io(th, 0.0, td, pd)
    keep = (valid[::si, ::sj, ::sk] & (wi[..., 2] > 0) & (wo[..., 2] > 0) & (th > 0)
            & (td > 0))
    assert n == keep.sum() == len(seen["wi"])
    np.testing.assert_allclose(seen["wi"], wi[keep], atol=1e-15)
    np.testing.assert_allclose(seen["wo"], wo[keep], atol=1e-15)


def test_unknown_model_is_a_usage_error(capsys):
    code = main(["fit", "synthetic:gold-ggx", "--model", "no-such-model"])
    assert code == 2
    err = capsys.readouterr().err
    assert "no-such-model" in err and "tabulated" in err


def test_missing_input_is_an_error(tmp_path, capsys):
    code = main(["fit", str(tmp_path / "missing.binary"), "--model", "tabulated"])
    assert code == 1
    assert "missing.binary" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["--iterations", "0"], ["--iterations", "many"],
                                  ["--option", "novalue"], ["-o", "a\x00b.npz"]])
def test_bad_values_are_usage_errors(argv, capsys):
    assert main(["fit", "synthetic:gold-ggx", "--model", "ggx", *argv]) == 2
    assert "Traceback" not in capsys.readouterr().err


def test_parse_options():
    assert parse_options(["tol=1e-6", "anisotropic=true", "rule=gauss"]) == {
        "tol": 1e-6, "anisotropic": True, "rule": "gauss"}
