"""GLSL export: compiles with glslangValidator; its NumPy twin matches the library's eval."""

from __future__ import annotations

import json

import numpy as np
import pytest

import brdffit
from brdffit.errors import ExportError
from brdffit.export import glsl as GL
from tests.support import glsl_cpu as C
from brdffit.microfacet import GeneralizedSchlickFresnel, MicrofacetBRDF
from brdffit.microfacet.npf_model import NPFMicrofacetBRDF, smith_g_from_d
from brdffit.microfacet.sgd import SGD, SGDApproxG1


def _pairs(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2 * n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    return v[:n], v[n:]


def _npf(seed=0, name="npf"):
    rng = np.random.default_rng(seed)
    th = (np.arange(90) / 90) ** 2 * np.pi / 2
    a = rng.uniform(0.05, 0.3, 3)
    D = 1.0 / (1.0 + (np.tan(th)[:, None] / a) ** 2) ** 2
    F = 0.5 + 0.5 * rng.random((90, 3)) * np.linspace(0, 1, 90)[:, None]
    G = smith_g_from_d(D)
    return NPFMicrofacetBRDF(D, F, G, rng.uniform(0, 0.1, 3), rng.uniform(0.01, 0.2, 3), name=name)


def _sgd_approx():
    a = SGD(0.15, 1.2).g1_approximation()
    return MicrofacetBRDF(SGDApproxG1(0.15, 1.2, a["lambda"], a["c"], a["k"]),
                          GeneralizedSchlickFresnel(0.06, 0.02), diffuse=(0.04, 0.07, 0.3))


def _npf_naive():
    from brdffit.microfacet.npf_model import NPFNaiveBRDF

    rng = np.random.default_rng(5)
    m = _npf(5)
    H = 0.5 + rng.random((180, 3))
    return NPFNaiveBRDF(m.D.astype(np.float32), m.F.astype(np.float32), H.astype(np.float32),
                        m.rho_d.astype(np.float32), m.rho_s.astype(np.float32))


def _npf_bivariate():
    from brdffit.microfacet.npf_model import NPFBivariateBRDF

    rng = np.random.default_rng(6)
    return NPFBivariateBRDF((0.1 + rng.random((90, 90, 3))).astype(np.float32))


MODELS = {
    "gold-ggx": lambda: brdffit.synthetic("gold-ggx"),
    "aniso-ggx": lambda: brdffit.synthetic("aniso-ggx"),
    "plastic-beckmann": lambda: brdffit.synthetic("plastic-beckmann"),
    "two-lobe-ggx": lambda: brdffit.synthetic("two-lobe-ggx"),
    "sgd-eq9": _sgd_approx,
    "npf": _npf,
    "npf-naive": _npf_naive,
    "npf-bivariate": _npf_bivariate,
}


@pytest.mark.parametrize("name", list(MODELS))
def test_cpu_translation_matches_library(name):
    model = MODELS[name]()
    spec = GL.model_spec(model)
    wi, wo = _pairs()
    ref = model.eval(wi, wo)
    got = C.eval_spec(spec, wi, wo)
    defined = ref > 1e-6 * ref.max()
    rel = np.abs(got - ref)[defined] / ref[defined]
    assert rel.max() < 1e-4, (name, rel.max())
    assert np.all(got[~defined] < 1e-5 * ref.max())


def test_tabulated_fit_resampling_error_small():
    model = brdffit.fit_tabulated(brdffit.synthetic("gold-ggx"), n=64)
    spec = GL.model_spec(model)
    assert any("resampled" in n for n in spec["notes"])
    wi, wo = _pairs(2000, 3)
    ref = model.eval(wi, wo)
    rel = np.abs(C.eval_spec(spec, wi, wo) - ref)[ref > 1e-4] / ref[ref > 1e-4]
    assert np.median(rel) < 1e-4 and rel.max() < 5e-3     # linear resampling of a cubic table


@pytest.mark.skipif(not GL.glslang_available(), reason="glslangValidator (glslang-tools) absent")
@pytest.mark.parametrize("name", ["aniso-ggx", "plastic-beckmann", "two-lobe-ggx", "sgd-eq9", "npf",
                                  "npf-naive"])
def test_glsl_compiles(name):
    src = GL.glsl_source(GL.model_spec(MODELS[name]()), main=True)
    ok, log = GL.compile_glsl(src)
    assert ok, log
    # and a broken shader is reported as such (the check can fail)
    ok2, _ = GL.compile_glsl(src.replace("bf_microfacet(wi, wo, D, G", "bf_microfacet(wi, D, G"))
    assert name.startswith("npf") or not ok2


def test_write_glsl_and_uber_texture(tmp_path):
    m = _npf(1, "mat-a")
    info = GL.write_glsl(m, tmp_path / "npf.glsl")
    idx = json.loads((tmp_path / "npf.glsl.json").read_text())
    from brdffit.evaluation.imageio import read_exr

    entry = idx["textures"]["bf_tex_uber"]
    tex = read_exr(tmp_path / entry["file"])             # float32 EXR, what engines load
    assert entry["file"].endswith(".exr") and entry["shape"] == [1, GL.UBER_WIDTH, 3]
    assert tex.shape == (1, GL.UBER_WIDTH, 3) and len(info["files"]) == 3
    np.testing.assert_array_equal(tex, np.asarray(GL.model_spec(m)["textures"]["uber"],
                                                  np.float32))        # lossless
    assert "uber" in entry["meaning"] and "texelFetch" in entry["lookup"]
    models = [_npf(s, f"mat-{s}") for s in range(4)]
    GL.pack_npf_uber_texture(models, tmp_path / "uber.npy")
    uber = np.load(tmp_path / "uber.npy")
    index = json.loads((tmp_path / "uber.json").read_text())
    assert uber.shape == (4, 272, 3) and index["rows"] == [f"mat-{s}" for s in range(4)]
    wi, wo = _pairs(500, 2)
    for r, mm in enumerate(models):                 # each row evaluates its own material
        spec = {"lobes": [{"type": "npf", "tex": "uber", "row": r}], "textures": {"uber": uber}}
        np.testing.assert_allclose(C.eval_spec(spec, wi, wo), mm.eval(wi, wo), rtol=2e-6, atol=1e-9)


def test_unsupported_raises_and_per_channel_works():
    from brdffit.export.gltf import GLTFBRDF
    from brdffit.microfacet.per_channel import PerChannelBRDF

    with pytest.raises(ExportError, match="GLSL"):
        GL.model_spec(GLTFBRDF([0.5, 0.5, 0.5], 0.0, 0.5))
    pc = PerChannelBRDF([brdffit.synthetic(n) for n in ("gold-ggx", "aniso-ggx", "plastic-beckmann")])
    wi, wo = _pairs(1000, 7)
    ref = pc.eval(wi, wo)
    got = C.eval_spec(GL.model_spec(pc), wi, wo)
    ok = ref > 1e-6 * ref.max()
    assert (np.abs(got - ref)[ok] / ref[ok]).max() < 1e-4


def test_anisotropic_tabulated_fit_glsl():
    from brdffit.evaluation.metrics import brdf_metrics

    model = brdffit.fit_tabulated(brdffit.synthetic("aniso-ggx"), n=32, n_phi=32)
    spec = GL.model_spec(model)
    assert spec["lobes"][0]["dist"]["kind"] == "table2"

    class Twin:
        isotropic = False

        def eval(self, wi, wo):
            return C.eval_spec(spec, wi, wo)

    err = brdf_metrics(model, Twin(), 1 << 13, metrics=("cos_rel_error",))["cos_rel_error"]
    assert err < 0.02                                  # bilinear resampling of the 2D table
    if GL.glslang_available():
        ok, log = GL.compile_glsl(GL.glsl_source(spec, main=True))
        assert ok, log


def test_npf_uber_is_an_export_target(tmp_path):
    from brdffit.export import TARGETS, export

    assert "npf-uber" in TARGETS
    info = export(_npf(2, "one"), "npf-uber", tmp_path / "one.npy")   # a single fit too
    index = json.loads((tmp_path / "one.json").read_text())
    assert index["rows"] == ["one"] and len(info["files"]) == 3
