"""One validation path for every way a model enters an export (issue 32.2): parameter JSON,
fit files and Python objects all meet the fit-file schema, with the same caps."""

from __future__ import annotations

import json
import os

import pytest

from brdffit.cli import main
from brdffit.errors import BRDFFormatError, ExportError
from brdffit.export import export, load_json
from brdffit.microfacet import GGX, ConductorFresnel, MicrofacetBRDF

BASE = {"format": "brdffit-params", "version": 1, "model": "microfacet",
        "parameters": {"distribution": {"kind": "ggx", "alpha_x": 0.2}, "rho_d": 0.1}}


def _doc(**changes) -> dict:
    doc = json.loads(json.dumps(BASE))
    for key, value in changes.items():
        node = doc
        *parents, last = key.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[last] = value
    return doc


@pytest.mark.parametrize("doc, message", [
    (_doc(**{"parameters.distribution.alpha_x": 1e300}), "alpha_x: expected a finite number >= 1e-06"),
    (_doc(**{"parameters.distribution.alpha_x": 5e-324}), "alpha_x: expected a finite number >= 1e-06"),
    (_doc(**{"parameters.fresnel": {"kind": "conductor", "eta": 1e300, "k": 1e300}}),
     "eta[0]: expected a finite number > 0 and <= 100"),
    (_doc(version="2"), 'expected format version an integer in 0..1, found "2"'),
    (_doc(version=2), "expected format version an integer in 0..1, found 2"),
    (_doc(model=["microfacet"]), "expected a model kind (a string)"),
    ("[" * 100_000 + "]" * 100_000, "expected JSON nested at most 32 levels"),
    (_doc(model="microfacet", state={"params": {}, "arrays": {"x": {
        "dtype": "object", "shape": [1], "data": [1]}}}), "is not numeric"),
])
def test_hostile_parameter_files_are_one_line_naming_the_file(doc, message, tmp_path, capsys):
    path = tmp_path / "p.json"
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    with pytest.raises(BRDFFormatError) as info:
        load_json(path)
    assert str(info.value).startswith(f"{path}: ") and message in str(info.value)
    assert main(["export", str(path), "--to", "glsl", "-o", str(tmp_path / "o.glsl")]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and str(path) in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.json"]


def test_a_parameter_file_is_size_capped_before_reading_and_must_be_a_regular_file(
        tmp_path, monkeypatch):
    from brdffit.export import json_params

    big = tmp_path / "big.json"
    big.write_text(json.dumps(BASE) + " " * 2048)
    monkeypatch.setattr(json_params, "MAX_JSON_BYTES", 1024)
    with pytest.raises(BRDFFormatError, match="expected at most 1024 bytes of JSON"):
        load_json(big)
    fifo = tmp_path / "p.json.fifo"
    os.mkfifo(fifo)
    with pytest.raises(BRDFFormatError, match="expected a regular file"):
        load_json(fifo)  # never opened: would block


def test_a_valid_hand_written_file_still_exports(tmp_path):
    path = tmp_path / "ok.json"
    path.write_text(json.dumps(BASE))
    assert main(["export", str(path), "--to", "gltf", "-o", str(tmp_path / "ok.gltf")]) == 0


def test_models_from_python_and_from_fit_files_meet_the_same_schema(tmp_path):
    from brdffit.io.fitfile import save_fit

    denormal = MicrofacetBRDF(GGX(5e-324), ConductorFresnel([0.2] * 3, [3.0] * 3))
    for to, name in (("mitsuba-xml", "x.xml"), ("materialx", "x.mtlx"), ("glsl", "x.glsl"),
                     ("gltf", "x.gltf")):
        with pytest.raises(ExportError, match="alpha_x: expected a finite number >= 1e-06"):
            export(denormal, to, tmp_path / name)
    with pytest.raises(BRDFFormatError, match="refusing to write .*alpha_x"):
        save_fit(denormal, tmp_path / "d.npz")
    assert list(tmp_path.iterdir()) == []
