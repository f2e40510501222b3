"""``brdffit export`` command line."""

from __future__ import annotations

import json

from brdffit.cli import main


def test_cli_export_json_gltf_glsl(tmp_path, capsys):
    assert main(["export", "synthetic:gold-ggx", "--to", "json", "-o", str(tmp_path / "g.json")]) == 0
    # the JSON written can be exported again (FIT may be a parameter JSON)
    assert main(["export", str(tmp_path / "g.json"), "--to", "gltf", "-o",
                 str(tmp_path / "g.gltf"), "--json", "--option", "fidelity=false"]) == 0
    out = capsys.readouterr().out.strip().splitlines()[-1]
    summary = json.loads(out)
    assert summary["material"]["metallicFactor"] == 1.0
    assert main(["export", "synthetic:aniso-ggx", "--to", "glsl", "-o", str(tmp_path / "a.glsl")]) == 0
    assert "brdffit_eval" in (tmp_path / "a.glsl").read_text()


def test_cli_export_errors(tmp_path, capsys):
    assert main(["export", "synthetic:sgd-paint", "--to", "gltf", "-o", str(tmp_path / "x.gltf")]) == 1
    err = capsys.readouterr().err
    assert "glTF" in err and "sgd-paint" in err
    assert not (tmp_path / "x.gltf").exists()
    assert main(["export", "synthetic:gold-ggx", "--to", "nope", "-o", str(tmp_path / "x")]) != 0


def test_cli_npf_uber_from_fit_files(tmp_path):
    import numpy as np

    from brdffit.export.tables import load_npf_table
    from brdffit.io.fitfile import save_fit
    from tests.export.test_glsl import _npf

    paths = []
    for s in range(2):
        save_fit(_npf(s, f"m{s}"), tmp_path / f"m{s}.npz")
        paths.append(str(tmp_path / f"m{s}.npz"))
    assert main(["export", *paths, "--to", "npf-uber", "-o", str(tmp_path / "u.npy")]) == 0
    back = load_npf_table(tmp_path / "u.npy")
    assert list(back) == ["m0", "m1"]
    np.testing.assert_allclose(back["m1"].D, _npf(1).D.astype(np.float32), rtol=1e-6)
    assert main(["export", *paths, "--to", "json", "-o", str(tmp_path / "x.json")]) == 1
