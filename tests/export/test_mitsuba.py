"""Mitsuba export: built-in mapping checked against Mitsuba's own BSDF evaluation, XML/dict
scenes load and render, the project's plugin for SGD models, errors."""

from __future__ import annotations

import os

import numpy as np
import pytest

import brdffit
from brdffit.errors import ExportError
from brdffit.export import mitsuba as M
from brdffit.export._common import principal_axes, rotate_z
from brdffit.microfacet import GGX

os.environ.setdefault("DRJIT_LIBLLVM_PATH", M.LLVM_PATH)


def _mi():
    from brdffit.evaluation.render import _mitsuba

    if not _mitsuba.available():
        pytest.skip("Mitsuba 3 with the LLVM back-end is unavailable")
    return _mitsuba.load()


def _dirs(n, seed):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2]) + 0.05
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_principal_axes_rotation_is_exact():
    d = GGX(0.06, 0.3, 0.45)
    au, av, phi = principal_axes(d.alpha_x, d.alpha_y, d.rho)
    m = _dirs(500, 1)
    # D of the correlated distribution = D of the axis-aligned one in the rotated frame
    np.testing.assert_allclose(d.D(m), GGX(au, av, 0.0).D(rotate_z(m, phi)), rtol=1e-10)
    assert phi != 0.0 and au != av


def test_conductor_fresnel_fit_recovers_conductor_curve():
    from brdffit.microfacet.fresnel import ConductorFresnel, TabulatedFresnel

    c = ConductorFresnel([0.2, 0.4, 1.4], [3.9, 2.4, 1.6])
    t = np.linspace(0, np.pi / 2, 91)
    fit = M.fit_conductor_fresnel(TabulatedFresnel(t, c.eval(np.cos(t))))
    assert not fit["exact"] and fit["max_abs"] < 2e-3


def test_non_mappable_model_raises_export_error():
    sgd = brdffit.synthetic("sgd-paint")
    with pytest.raises(ExportError, match="SGD"):
        M.builtin_bsdf(sgd)


@pytest.mark.render
@pytest.mark.parametrize("name", ["gold-ggx", "aniso-ggx", "two-lobe-ggx", "plastic-beckmann"])
def test_builtin_mapping_matches_mitsuba_eval(name):
    mi, dr = _mi()
    model = brdffit.synthetic(name)
    bsdf = mi.load_dict(M.builtin_bsdf(model)[0])
    eq = M.mitsuba_equivalent(model)
    wi, wo = _dirs(256, 2), _dirs(256, 3)
    si = dr.zeros(mi.SurfaceInteraction3f, 256)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.wi = mi.Vector3f(wo[:, 0], wo[:, 1], wo[:, 2])          # Mitsuba's wi = viewer
    val = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wi[:, 0], wi[:, 1], wi[:, 2]))
    got = np.array(val).reshape(3, -1).T if np.array(val).shape[0] == 3 else np.array(val)
    ref = eq.eval(wi, wo) * wi[:, 2:3]
    # Mitsuba's Beckmann G1 is Walter 2007's rational approximation (≈0.35 % max error)
    rtol = 5e-3 if "beckmann" in name else 2e-3
    np.testing.assert_allclose(got, ref, rtol=rtol, atol=1e-5 * ref.max())
    # and the equivalent is close to the model itself (only documented approximations)
    err = M.mitsuba_error(model, n_samples=4096)
    assert err["cos_rel_error"] < 0.5


@pytest.mark.render
@pytest.mark.parametrize("name", ["gold-ggx", "plastic-beckmann"])
def test_xml_and_python_scenes_render(tmp_path, name):
    mi, _ = _mi()
    model = brdffit.synthetic(name)
    info = M.write_mitsuba_xml(model, tmp_path / "gold.xml")
    scene = mi.load_file(str(tmp_path / "gold.xml"), res=16, spp=4)
    if name == "plastic-beckmann":       # blendbsdf of diffuse + roughconductor, from XML
        xml_bsdf = [s.bsdf() for s in scene.shapes()][0]
        assert "BlendBSDF" in str(xml_bsdf)
    img = np.array(mi.render(scene))
    assert img.shape[:2] == (16, 16) and np.isfinite(img).all() and img[..., :3].max() > 0
    assert info["error"]["cos_rel_error"] >= 0
    M.write_mitsuba_python(model, tmp_path / "gold.py")
    ns: dict = {"__file__": str(tmp_path / "gold.py"), "__name__": "scene"}
    exec(compile((tmp_path / "gold.py").read_text(), "gold.py", "exec"), ns)
    img2 = np.array(mi.render(mi.load_dict(ns["scene_dict"](16, 4))))
    assert np.isfinite(img2).all() and img2[..., :3].max() > 0


@pytest.mark.render
def test_plugin_scene_for_sgd(tmp_path):
    mi, _ = _mi()
    model = brdffit.synthetic("sgd-paint")
    with pytest.raises(ExportError):          # no built-in plugin for SGD
        M.write_mitsuba_xml(model, tmp_path / "x.xml", style="conductor")
    assert not (tmp_path / "x.xml").exists()
    info = M.write_mitsuba_python(model, tmp_path / "paint.py")
    assert info["plugin"] == "brdffit" and (tmp_path / "paint.fit.npz").exists()
    ns: dict = {"__file__": str(tmp_path / "paint.py"), "__name__": "scene"}
    exec(compile((tmp_path / "paint.py").read_text(), "paint.py", "exec"), ns)
    img = np.array(mi.render(mi.load_dict(ns["scene_dict"](16, 4))))
    assert np.isfinite(img).all() and img[..., :3].max() > 0
    # the live dict from the Python API renders too
    d = M.example_scene_dict(M.mitsuba_bsdf(model), resolution=8, spp=2)
    assert np.isfinite(np.array(mi.render(mi.load_dict(d)))).all()


@pytest.mark.render
def test_roughplastic_style_measured_in_mitsuba(tmp_path):
    mi, _ = _mi()
    model = brdffit.synthetic("plastic-beckmann")
    bsdf, info = M.plastic_bsdf(model, n=1024)
    assert bsdf["type"] == "roughplastic" and bsdf["int_ior"] == pytest.approx(1.5)
    assert 0 < info["error"]["cos_rel_error"] < 0.3          # approximate, and measured
    # the exact blend mapping is much closer, measured the same way (inside Mitsuba)
    exact = M.mitsuba_eval_error(model, M.builtin_bsdf(model)[0], n=2048)["cos_rel_error"]
    assert exact < 0.01 < info["error"]["cos_rel_error"]
    out = M.write_mitsuba_xml(model, tmp_path / "p.xml", style="plastic")
    assert out["error"]["cos_rel_error"] > 0
    scene = mi.load_file(str(tmp_path / "p.xml"), res=8, spp=2)
    assert np.isfinite(np.array(mi.render(scene))).all()
    with pytest.raises(ExportError, match="roughplastic"):
        M.plastic_bsdf(brdffit.synthetic("aniso-ggx"))


@pytest.mark.render
def test_plugin_scene_for_npf(tmp_path):
    mi, _ = _mi()
    from tests.export.test_glsl import _npf

    model = _npf(3, "npf-test")
    info = M.write_mitsuba_python(model, tmp_path / "npf.py")
    assert info["plugin"] == "brdffit" and "builtin_unavailable" in info
    ns: dict = {"__file__": str(tmp_path / "npf.py"), "__name__": "scene"}
    exec(compile((tmp_path / "npf.py").read_text(), "npf.py", "exec"), ns)
    img = np.array(mi.render(mi.load_dict(ns["scene_dict"](12, 4))))
    assert np.isfinite(img).all() and img[..., :3].max() > 0


_PLAIN_MITSUBA = r"""
import os, sys
import numpy as np
import mitsuba as mi
mi.set_variant("llvm_ad_rgb")
scene = mi.load_file(sys.argv[1], res=16, spp=4)
kind = str(scene.shapes()[0].bsdf()).split("[")[0].strip()
img = np.array(mi.render(scene))
assert not any(m.startswith("brdffit") for m in sys.modules), "brdffit was imported"
print(kind, bool(np.isfinite(img).all()), float(img[..., :3].max()))
"""


def run_plain_mitsuba(script: str, *args, cwd):
    """Run ``script`` (e.g. :data:`_PLAIN_MITSUBA`, which refuses to have imported brdffit) in
    a fresh interpreter without ``PYTHONPATH``: a Mitsuba install that never sees brdffit.
    Returns the ``CompletedProcess`` (text output)."""
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run([sys.executable, "-c", script, *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, env=env, timeout=300)


@pytest.mark.render
@pytest.mark.parametrize("model", ["tabulated", "ggx-diffuse", "sgd", "npf-g-from-d",
                                   "npf-naive", "npf-bivariate"])
def test_mitsuba_xml_of_every_model_loads_in_plain_mitsuba(tmp_path, model):
    """Issue 14.4: a scene that a Mitsuba install without brdffit loads and renders; models
    with no built-in plugin go through an RGL tensor file and the stock ``measured`` plugin."""
    from brdffit.fit.registry import fit_model

    _mi()
    options = {"max_iter": 3, "polish": 0} if model in ("npf-g-from-d", "npf-naive") else {}
    fitted, _ = fit_model(model, brdffit.synthetic("gold-ggx"), options)
    info = M.write_mitsuba_xml(fitted, tmp_path / "my scene.xml")
    assert all(os.path.isfile(f) for f in info["files"])
    # the resampling error of the tensor file, read back by brdffit's own RGL reader
    assert info["error"]["cos_rel_error"] < 0.02
    run = run_plain_mitsuba(_PLAIN_MITSUBA, tmp_path / "my scene.xml", cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-2000:]
    kind, finite, peak = run.stdout.split()
    assert finite == "True" and float(peak) > 0
    assert ("Measured" in kind) == (model != "ggx-diffuse"), kind


def test_mitsuba_xml_failure_leaves_no_tensor_file(tmp_path, monkeypatch):
    from brdffit.export import rgl

    def boom(*a, **k):
        raise ExportError("simulated failure")

    monkeypatch.setattr(rgl, "rgl_error", boom)
    with pytest.raises(ExportError):
        M.write_mitsuba_xml(brdffit.synthetic("sgd-paint"), tmp_path / "s.xml")
    assert list(tmp_path.iterdir()) == []
