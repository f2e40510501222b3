"""The report's index calls ties ties, and the parameters table shows the coat (issue 31.5)."""

from __future__ import annotations

from brdffit.evaluation.report import write_index, write_material_page, write_result


def _result(models):
    return {"material": "m", "slug": "m", "models": models}


def test_a_winner_tied_with_the_runner_up_is_not_highlighted_alone(tmp_path):
    models = [{"name": "a", "status": "ok", "psnr": 40.0, "psnr_se": 0.1},
              {"name": "b", "status": "ok", "psnr": 39.9, "psnr_se": 0.1},
              {"name": "c", "status": "ok", "psnr": 30.0, "psnr_se": 0.1}]
    write_result(tmp_path / "m", _result(models))
    index = write_index(tmp_path).read_text()
    assert index.count('class="best"') == 2 and index.count(">tie</span>") == 2
    models[1]["psnr"] = 38.0                               # 2 dB apart, se 0.1: a clear win
    write_result(tmp_path / "m", _result(models))
    index = write_index(tmp_path).read_text()
    assert index.count('class="best"') == 1 and ">tie</span>" not in index


def test_the_parameters_table_shows_the_coat(tmp_path):
    fig = {"alpha": [0.2, 0.2, 0.0], "f0": [0.04] * 3, "rho_d": [0.3] * 3, "table_bytes": 0,
           "coat": {"alpha": 0.0025, "weight": 0.8, "f0": 0.04}}
    page = write_material_page(tmp_path, _result([
        {"name": "ggx-diffuse", "status": "ok", "params": {"figures": fig}}])).read_text()
    assert "α 0.0025 (roughness 0.0500), weight 0.800, F0 0.040" in page


def test_the_index_says_which_file_to_use(tmp_path):
    models = [{"name": "tabulated", "status": "ok", "psnr": 40.0, "psnr_se": 0.1,
               "table_bytes": 1800, "fit_time": 0.02, "fit_file": "fits/tabulated.npz",
               "exports": ["exports/tabulated.json"]},
              {"name": "ggx-diffuse", "status": "ok", "psnr": 39.9, "psnr_se": 0.1,
               "table_bytes": 0, "fit_time": 1.1, "fit_file": "fits/ggx-diffuse.npz",
               "exports": ["exports/ggx-diffuse.json", "exports/ggx-diffuse.gltf"],
               "validity": []},
              {"name": "npf", "status": "ok", "psnr": 30.0, "psnr_se": 0.1, "table_bytes": 3264}]
    write_result(tmp_path / "m", _result(models))
    index = write_index(tmp_path).read_text()
    assert '<a href="m/exports/ggx-diffuse.gltf">ggx-diffuse (glTF)</a>' in index
    assert ('most faithful: <a href="m/fits/tabulated.npz">tabulated</a> (1,800 B of tables, '
            "fit 0.02 s) – tied with ggx-diffuse") in index
    assert ('smallest of those: <a href="m/fits/ggx-diffuse.npz">ggx-diffuse</a> (parameters '
            "only, fit 1.10 s)") in index
