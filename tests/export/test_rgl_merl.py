"""RGL-style and MERL exports: read back with the library's readers and Mitsuba's plugin."""

from __future__ import annotations

import os

import numpy as np
import pytest

import brdffit
from brdffit.errors import ExportError
from brdffit.export import export
from brdffit.export.mitsuba import LLVM_PATH
from brdffit.io.merl import read_merl
from brdffit.io.rgl import read_rgl

os.environ.setdefault("DRJIT_LIBLLVM_PATH", LLVM_PATH)


@pytest.fixture(scope="module")
def tab_fit():
    return brdffit.fit_tabulated(brdffit.synthetic("gold-ggx"), n=64)


def test_rgl_export_of_tabulated_fit_reads_back(tmp_path, tab_fit):
    info = export(tab_fit, "rgl", tmp_path / "gold.bsdf")
    assert info["error"]["cos_rel_error"] < 0.03
    back = read_rgl(tmp_path / "gold.bsdf")
    assert back.isotropic and back.jacobian
    # the stored NDF is the fit's NDF
    th = np.linspace(0, 1.2, 20)
    w = np.stack([np.sin(th), 0 * th, np.cos(th)], -1)
    np.testing.assert_allclose(back.ndf_table()(th), tab_fit.distribution.D(w), rtol=2e-2)


def test_rgl_with_diffuse_term(tmp_path):
    m = brdffit.synthetic("plastic-beckmann")
    assert export(m, "rgl", tmp_path / "p.bsdf")["error"]["cos_rel_error"] < 0.05


@pytest.mark.render
def test_rgl_export_loads_in_mitsuba_measured(tmp_path, tab_fit):
    from brdffit.evaluation.render import _mitsuba

    if not _mitsuba.available():
        pytest.skip("Mitsuba 3 with the LLVM back-end is unavailable")
    mi, dr = _mitsuba.load()
    path = tmp_path / "gold.bsdf"
    export(tab_fit, "rgl", path, check=False)
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    rng = np.random.default_rng(4)
    v = rng.normal(size=(400, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2]) + 0.1
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    a, b = v[:200], v[200:]
    si = dr.zeros(mi.SurfaceInteraction3f, 200)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.wi = mi.Vector3f(a[:, 0], a[:, 1], a[:, 2])
    got = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(b[:, 0], b[:, 1], b[:, 2])))
    got = got.T if got.shape[0] == 3 and got.shape[-1] != 3 else got
    ref = read_rgl(path).eval_mitsuba(a, b)
    np.testing.assert_allclose(got, ref, rtol=2e-3, atol=1e-4 * ref.max())


def test_merl_export_round_trip(tmp_path):
    m = brdffit.synthetic("plastic-beckmann")
    info = export(m, "merl", tmp_path / "p.binary")
    back = read_merl(tmp_path / "p.binary")
    assert info["n_invalid"] == back.n_invalid
    th = np.linspace(0.05, 1.2, 7)
    np.testing.assert_allclose(back.eval_hd(th, 0.3 + 0 * th, 1.0 + 0 * th),
                               m.eval_hd(th, 0.3 + 0 * th, 1.0 + 0 * th), rtol=0.05)


def test_anisotropic_to_merl_raises(tmp_path):
    """MERL has no φh axis; RGL files take anisotropic models (``phi_i`` slices, see
    ``test_rgl_aniso.py``)."""
    m = brdffit.synthetic("aniso-ggx")
    with pytest.raises(ExportError, match="isotropic"):
        export(m, "merl", tmp_path / "x.merl")
    assert not (tmp_path / "x.merl").exists()
