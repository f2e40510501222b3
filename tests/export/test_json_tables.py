"""JSON parameters round trip, hand-written JSON, SGD/NPF table import."""

from __future__ import annotations

import json

import numpy as np
import pytest

import brdffit
from brdffit.errors import BRDFFormatError, ExportError
from brdffit.export import export, load_json
from brdffit.export.json_params import to_json_dict
from brdffit.export.tables import load_npf_table, load_sgd_table, write_sgd_table
from brdffit.microfacet.sgd_model import PerChannelMicrofacetBRDF
from brdffit.microfacet.sgd import SGD


def _pairs(n=1500, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2 * n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    return v[:n], v[n:]


def _per_channel_sgd(name="paint", g1=True):
    chans = [{"distribution": SGD(0.1 + 0.05 * c, 1.0 + 0.3 * c), "rho_d": 0.02 * (c + 1),
              "rho_s": 0.1 + 0.01 * c, "F0": 0.05, "F1": 0.01} for c in range(3)]
    g = [{"lambda": 0.1 + c, "c": 1.5, "k": 3.0} for c in range(3)] if g1 else None
    return PerChannelMicrofacetBRDF(chans, g1_approx=g, name=name)


@pytest.mark.parametrize("name", ["gold-ggx", "aniso-ggx", "two-lobe-ggx", "sgd-paint",
                                  "plastic-beckmann"])
def test_json_round_trip_identical_eval(tmp_path, name):
    m = brdffit.synthetic(name)
    export(m, "json", tmp_path / "m.json")
    back = load_json(tmp_path / "m.json")
    wi, wo = _pairs()
    np.testing.assert_array_equal(back.eval(wi, wo), m.eval(wi, wo))
    doc = json.loads((tmp_path / "m.json").read_text())
    assert "alpha" in doc["conventions"] and doc["parameters"]


def test_json_round_trip_fitted_tables(tmp_path):
    m = brdffit.fit_ggx(brdffit.synthetic("gold-ggx"), n=48)     # FittedFresnel float32 table
    export(m, "json", tmp_path / "f.json")
    wi, wo = _pairs(500, 1)
    np.testing.assert_array_equal(load_json(tmp_path / "f.json").eval(wi, wo), m.eval(wi, wo))
    pc = _per_channel_sgd()
    export(pc, "json", tmp_path / "pc.json")
    np.testing.assert_array_equal(load_json(tmp_path / "pc.json").eval(wi, wo), pc.eval(wi, wo))


def test_hand_written_parameters(tmp_path):
    m = brdffit.synthetic("gold-ggx")
    doc = to_json_dict(m)
    del doc["state"]
    (tmp_path / "h.json").write_text(json.dumps(doc))
    wi, wo = _pairs(500, 2)
    np.testing.assert_allclose(load_json(tmp_path / "h.json").eval(wi, wo), m.eval(wi, wo),
                               rtol=1e-12)
    (tmp_path / "bad.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(BRDFFormatError, match="format"):
        load_json(tmp_path / "bad.json")


def test_json_unserialisable_raises(tmp_path):
    from brdffit.export.gltf import GLTFBRDF

    with pytest.raises(ExportError, match="json"):
        export(GLTFBRDF([0.5, 0.5, 0.5], 0.0, 0.5), "json", tmp_path / "x.json")
    assert not (tmp_path / "x.json").exists()


def test_json_per_channel_tabulated(tmp_path):
    from brdffit.microfacet.per_channel import PerChannelBRDF

    pc = PerChannelBRDF([brdffit.synthetic(n) for n in ("gold-ggx", "aniso-ggx", "sgd-paint")])
    export(pc, "json", tmp_path / "pc.json")
    wi, wo = _pairs(400, 5)
    np.testing.assert_array_equal(load_json(tmp_path / "pc.json").eval(wi, wo), pc.eval(wi, wo))


def test_sgd_table_round_trip(tmp_path):
    models = [_per_channel_sgd("a"), _per_channel_sgd("b")]
    write_sgd_table(models, tmp_path / "t.csv")
    back = load_sgd_table(tmp_path / "t.csv")
    assert list(back) == ["a", "b"]
    wi, wo = _pairs(500, 3)
    np.testing.assert_array_equal(back["a"].eval(wi, wo), models[0].eval(wi, wo))
    assert back["b"].with_g1("approx").g1 == "approx"


def test_sgd_table_hand_written_and_errors(tmp_path):
    p = tmp_path / "paper.csv"
    p.write_text("# transcribed\nmaterial,channel,rho_d,rho_s,alpha,p,F0,F1\n"
                 "m,R,0.1,0.2,0.05,1.1,0.04,0\nm,G,0.1,0.2,0.05,1.1,0.04,0\n"
                 "m,B,0.1,0.2,0.05,1.1,0.04,0\n")
    m = load_sgd_table(p)["m"]
    assert m.channels[2]["distribution"].p == 1.1 and m.g1_approx is None
    p.write_text("material,channel,rho_d\nm,R,0.1\n")
    with pytest.raises(BRDFFormatError, match="missing"):
        load_sgd_table(p)
    p.write_text("material,channel,rho_d,rho_s,alpha,p,F0,F1\nm,R,0.1,0.2,0.05,1.1,0.04,0\n")
    with pytest.raises(BRDFFormatError, match="three channel"):
        load_sgd_table(p)


def test_npf_table_round_trip(tmp_path):
    from brdffit.export.glsl import pack_npf_uber_texture
    from tests.export.test_glsl import _npf

    models = [_npf(s, f"n{s}") for s in range(3)]
    pack_npf_uber_texture(models, tmp_path / "u.npy")
    wi, wo = _pairs(500, 4)
    for spec in (tmp_path / "u.npy", tmp_path / "u.json", tmp_path / "u.exr"):
        back = load_npf_table(spec)
        assert list(back) == ["n0", "n1", "n2"]
        np.testing.assert_allclose(back["n1"].eval(wi, wo), models[1].eval(wi, wo), rtol=1e-6)


# every model the registry fits goes to JSON and back (a tabulated fit once crashed:
# "could not convert string to float: 'tabulated'")
@pytest.mark.parametrize("model", ["tabulated", "ggx", "beckmann", "ggx-diffuse", "sgd",
                                   "npf-g-from-d", "npf-naive", "npf-bivariate"])
def test_every_registered_model_exports_to_json(tmp_path, model):
    from brdffit.fit.registry import fit_model

    options = {"max_iter": 3, "polish": 0} if model in ("npf-g-from-d", "npf-naive") else {}
    fitted, _ = fit_model(model, brdffit.synthetic("gold-ggx"), options)
    export(fitted, "json", tmp_path / "m.json")
    doc = json.loads((tmp_path / "m.json").read_text())
    assert doc["parameters"] and "state" in doc
    back = load_json(tmp_path / "m.json")
    wi, wo = _pairs(400)
    np.testing.assert_allclose(back.eval(wi, wo), fitted.eval(wi, wo), rtol=1e-6, atol=1e-9)
