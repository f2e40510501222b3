"""`brdffit info` and `brdffit convert` through brdffit.cli.main (and once via a subprocess)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from brdffit.cli import main
from brdffit.grid import merl_phi_d, merl_theta_d, merl_theta_h
from brdffit.io import load, read_merl, read_utia, write_merl
from tests.conftest import shared_data_path


@pytest.fixture(scope="module")
def merl_with_holes(tmp_path_factory):
    rng = np.random.default_rng(3)
    values = rng.random((90, 90, 180, 3)) * [1.0, 2.0, 3.0]
    valid = rng.random((90, 90, 180)) > 0.01
    path = tmp_path_factory.mktemp("cli") / "holes.binary"
    write_merl((values, valid), path)
    return path, values, valid


def test_info_json(merl_with_holes, capsys):
    path, values, valid = merl_with_holes
    assert main(["info", str(path), "--json", "--albedo-samples", "1024"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["format"] == "merl" and out["isotropic"] is True
    assert out["samples"]["n_samples"] == valid.size
    assert out["samples"]["n_invalid"] == int((~valid).sum())
    v = values[valid]
    np.testing.assert_allclose(out["value_range"]["min"], v.min(axis=0), rtol=1e-12)
    np.testing.assert_allclose(out["value_range"]["max"], v.max(axis=0), rtol=1e-12)
    assert set(out["albedo"]) == {"0", "30", "60", "75"}
    # a table of uniform random values: albedo ≈ π · mean value (≈ 0.5, 1, 1.5 · π)
    alb = np.array(out["albedo"]["30"])
    np.testing.assert_allclose(alb, np.pi * np.array([0.5, 1.0, 1.5]), rtol=0.1)


def test_info_text(merl_with_holes, capsys):
    path, _, valid = merl_with_holes
    assert main(["info", str(path), "--albedo-samples", "1024"]) == 0
    text = capsys.readouterr().out
    assert "merl" in text and f"invalid: {int((~valid).sum())}" in text and "75°" in text
    assert all(len(line) <= 80 for line in text.splitlines()), text


def test_convert_merl_to_utia_and_back_errors(merl_with_holes, tmp_path, capsys):
    path, _, _ = merl_with_holes
    out = tmp_path / "u.bin"
    assert main(["convert", str(path), str(out)]) == 0
    u = read_utia(out)
    m = read_merl(path)
    # the UTIA file holds the MERL BRDF evaluated at its grid points: check one grid point
    t30, p180 = np.radians(30), np.pi
    wi = np.array([np.sin(t30), 0, np.cos(t30)])
    wo = np.array([np.sin(t30) * np.cos(p180), np.sin(t30) * np.sin(p180), np.cos(t30)])
    np.testing.assert_allclose(u.eval(wi, wo), m.eval(wi, wo), rtol=1e-12)
    capsys.readouterr()
    # anisotropic input cannot go to MERL: one line on stderr, exit 1, no output file
    assert main(["convert", str(out), str(tmp_path / "x.binary")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("brdffit: error:") and "isotropic" in err and err.count("\n") == 1
    assert not (tmp_path / "x.binary").exists()
    assert main(["convert", str(path), str(tmp_path / "x.png")]) == 2  # usage: bad OUT
    assert ".png" in capsys.readouterr().err and not (tmp_path / "x.png").exists()
    assert main(["info", str(tmp_path / "absent.binary")]) == 1
    assert "absent.binary" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["u.bin"]


def test_convert_nbrdf_collection_to_merl(tmp_path, capsys, monkeypatch):
    shared_data_path("nbrdf", "merl_nbrdf.zip")
    monkeypatch.chdir(tmp_path)
    assert main(["convert", "merl_nbrdf.zip:gold-metallic-paint", "out.binary"]) == 0
    assert "out.binary" in capsys.readouterr().out
    m = read_merl(tmp_path / "out.binary")
    net = load("merl_nbrdf.zip:gold-metallic-paint")
    values, valid = m.merl_table()
    assert valid.all()
    rng = np.random.default_rng(0)
    i, j, k = rng.integers(0, 90, 200), rng.integers(0, 90, 200), rng.integers(0, 180, 200)
    ref = net.eval_hd(merl_theta_h()[i], merl_theta_d()[j], merl_phi_d()[k])
    np.testing.assert_allclose(values[i, j, k], ref, rtol=1e-12, atol=1e-15)
    # info on the collection itself lists the materials
    assert main(["info", "merl_nbrdf.zip", "--json"]) == 0
    listing = json.loads(capsys.readouterr().out)
    assert len(listing["materials"]) == 100 and "gold-metallic-paint" in listing["materials"]


def test_subprocess_entry_point(tmp_path):
    """The real entry point: a failing command prints one line, no traceback, exit 1."""
    res = subprocess.run([sys.executable, "-m", "brdffit.cli", "info", str(tmp_path / "no.bin")],
                         capture_output=True, text=True, env=dict(os.environ), timeout=120)
    assert res.returncode == 1 and "Traceback" not in res.stderr
    assert res.stderr.startswith("brdffit: error:") and res.stderr.strip().count("\n") == 0
    assert "no.bin" in res.stderr and res.stdout == ""


def test_info_rgl_and_nbrdf(capsys):
    rgl = shared_data_path("rgl", "paper_white_rgb.bsdf")
    assert main(["info", str(rgl), "--json", "--albedo-samples", "1024"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["isotropic"] is True and "rgb" in out["samples"]["field_shapes"]
    alb = np.array(list(out["albedo"].values()))
    assert np.all((alb > 0.3) & (alb < 1.05))  # white paper
    z = shared_data_path("nbrdf", "merl_nbrdf.zip")
    assert main(["info", f"{z}:gold-metallic-paint", "--json", "--albedo-samples", "1024"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["format"] == "nbrdf" and out["samples"]["n_parameters"] == 675
    assert out["value_range"]["min"][0] >= 0 and out["value_range"]["max"][0] > 1.0
