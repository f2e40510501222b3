"""Anisotropic models in RGL tensor files (``phi_i`` slices) and in ``--to mitsuba-xml``
scenes that a plain Mitsuba 3 loads (issue 14 item 4).

Fidelity is the cosine-weighted relative error of :func:`_fidelity` on 4096 cosine-weighted
pairs rotated about the normal to eight azimuths and to those plus 90°. Measured for the
anisotropic tabulated fit of ``aniso-ggx`` (reduction 2, 9 slices): 0.49 % with brdffit's
reader and with Mitsuba's ``measured`` plugin (the two agree to 6.5e-7), and 0.53 % on the
change between φ and φ + 90° (which is 150 % of the values in the model); the axis-aligned
fit (reduction 4, 5 slices): 0.47 % and 0.53 %. The read-back metric of the export summary is
0.50 % (the isotropic ``gold-ggx`` tabulated fit: 0.25 %, which the isotropic tests bound by
2-3 %). The bound :data:`BOUND` = 1 % is about twice the measured error and 7-9 times below
that of a file whose ``phi_i`` slices all hold the first one (φi ignored: 7.3 % and 8.8 %),
which the tests check fails it.
"""

from __future__ import annotations

import functools
import os

import numpy as np
import pytest

import brdffit
from brdffit.brdf import BRDF, _as_dirs, cosine_hemisphere_sample
from brdffit.export import export
from brdffit.export.mitsuba import LLVM_PATH
from brdffit.export.rgl import default_n_phi, rgl_fields, rgl_reduction
from brdffit.io.rgl import read_rgl
from brdffit.io.tensorfile import write_tensor_file
from brdffit.microfacet import GGX, ConductorFresnel, MicrofacetBRDF
from brdffit.synthetic import ALUMINIUM_ETA, ALUMINIUM_K

os.environ.setdefault("DRJIT_LIBLLVM_PATH", LLVM_PATH)

#: bound on the cos-weighted relative error and on the error of the φ → φ + 90° change
BOUND = 0.01
#: azimuths (degrees) the test configurations are rotated to
PHIS = (0, 30, 45, 60, 90, 135, 200, 290)


@pytest.fixture(scope="module")
def aniso_tab():
    """The anisotropic tabulated fit of ``aniso-ggx`` (correlated ρ = 0.45: reduction 2)."""
    return brdffit.fit_tabulated(brdffit.synthetic("aniso-ggx"))


@functools.cache
def _axis_aligned_tab():
    """An anisotropic tabulated fit symmetric under both mirrors (reduction 4)."""
    return brdffit.fit_tabulated(MicrofacetBRDF(GGX(0.06, 0.3),
                                                ConductorFresnel(ALUMINIUM_ETA, ALUMINIUM_K)))


class _Tilted(BRDF):
    """``aniso-ggx`` times ``1 + h_x / 2`` (h the half vector): reciprocal, positive, but not
    symmetric under the rotation by π (reduction 1), and not a microfacet model (the export
    warps with its tabulated fit's NDF)."""

    isotropic = False
    name = "tilted"

    def __init__(self):
        self.base = brdffit.synthetic("aniso-ggx")

    def eval(self, wi, wo):
        wi, wo = _as_dirs(wi, wo)
        h = wi + wo
        h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-12)
        return self.base.eval(wi, wo) * (1.0 + 0.5 * h[..., :1])


def _rot(v, deg):
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1], v[..., 2]], -1)


def _configs(n=4096, seed=7):
    """``(wi, wo)`` of shape (2 · len(PHIS), n, 3): cosine-weighted pairs rotated to each φ
    of :data:`PHIS` (first half) and to φ + 90° (second half)."""
    rng = np.random.default_rng(seed)
    wi, wo = cosine_hemisphere_sample(rng.random((n, 2))), cosine_hemisphere_sample(rng.random((n, 2)))
    angles = list(PHIS) + [p + 90 for p in PHIS]
    return (np.stack([_rot(wi, a) for a in angles]), np.stack([_rot(wo, a) for a in angles]))


def _fidelity(got, ref):
    """``(error, anisotropy, change_error)`` of values ``got`` against ``ref`` (f_r, shape
    (2·P, n, 3), from :func:`_configs`): the cos-weighted relative error over all pairs, the
    model's own change between φ and φ + 90° (relative to its values) and the relative error
    of that change in ``got``."""
    p = len(PHIS)
    err = np.abs(got - ref).sum() / np.abs(ref).sum()
    d_ref, d_got = ref[p:] - ref[:p], got[p:] - got[:p]
    return (float(err), float(np.abs(d_ref).sum() / np.abs(ref[:p]).sum()),
            float(np.abs(d_got - d_ref).sum() / np.abs(d_ref).sum()))


def test_reduction_follows_the_model_symmetry(aniso_tab):
    assert rgl_reduction(brdffit.synthetic("gold-ggx")) == 1          # isotropic: one slice
    assert rgl_reduction(brdffit.synthetic("aniso-ggx")) == 2         # ρ ≠ 0: rotation only
    assert rgl_reduction(aniso_tab) == 2
    assert rgl_reduction(_axis_aligned_tab()) == 4                   # both mirrors too
    assert rgl_reduction(_Tilted()) == 1                             # no symmetry
    assert [default_n_phi(r) for r in (1, 2, 4)] == [17, 9, 5]


def test_anisotropic_tabulated_fit_to_rgl_keeps_phi(tmp_path, aniso_tab):
    info = export(aniso_tab, "rgl", tmp_path / "a.bsdf")
    assert info["reduction"] == 2 and info["shapes"]["phi_i"] == [9]
    assert info["shapes"]["vndf"] == [9, 32, 64, 64] and info["shapes"]["ndf"] == [256, 256]
    assert info["error"]["cos_rel_error"] < BOUND                    # measured 0.50 %
    back = read_rgl(tmp_path / "a.bsdf")
    assert not back.isotropic and back.reduction == 2 and back.jacobian
    np.testing.assert_allclose(back.phi_i[[0, -1]], [-np.pi, 0.0], atol=1e-6)
    # the stored NDF is the fit's anisotropic NDF at every azimuth
    th, ph = np.meshgrid(np.linspace(0.0, 1.2, 13), np.radians([-170, -90, -30, 0, 45, 120]))
    w = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    np.testing.assert_allclose(back.ndf_table()(th, ph), aniso_tab.distribution.D(w),
                               rtol=0.03, atol=1e-3 * float(aniso_tab.distribution.D(w).max()))
    wi, wo = _configs()
    err, aniso, change = _fidelity(back.eval(wi, wo), aniso_tab.eval(wi, wo))
    assert aniso > 0.5                   # the model changes a lot between φ and φ + 90°
    assert err < BOUND and change < BOUND, (err, change)             # measured 0.49 %, 0.53 %
    # control: a file whose phi_i slices all hold the first slice (φi ignored) fails the check
    fields = rgl_fields(aniso_tab)
    for k in ("vndf", "rgb", "luminance"):
        fields[k] = np.repeat(fields[k][:1], fields[k].shape[0], axis=0)
    write_tensor_file(tmp_path / "flat.bsdf", fields)
    err, _, change = _fidelity(read_rgl(tmp_path / "flat.bsdf").eval(wi, wo), aniso_tab.eval(wi, wo))
    assert err > 5 * BOUND and change > 5 * BOUND, (err, change)


@pytest.mark.parametrize("make, reduction, n_phi, bound", [
    (_axis_aligned_tab, 4, 5, BOUND),          # measured 0.47 %, mirrors folded
    # measured 2.5 %: the proxy warp (tabulated NDF + 25 % uniform) of non-microfacet models
    # (aniso-ggx itself through the proxy: 2.6 %, with its own NDF: 0.4 %)
    (_Tilted, 1, 17, 0.04),
])
def test_other_symmetries_read_back(tmp_path, make, reduction, n_phi, bound):
    model = make()
    info = export(model, "rgl", tmp_path / "m.bsdf")
    assert info["reduction"] == reduction and info["shapes"]["phi_i"] == [n_phi]
    assert info["error"]["cos_rel_error"] < bound
    back = read_rgl(tmp_path / "m.bsdf")
    span = float(back.phi_i[-1] - back.phi_i[0])
    assert back.reduction == reduction and span == pytest.approx(2 * np.pi / reduction, abs=1e-5)
    wi, wo = _configs(2048)
    err, aniso, change = _fidelity(back.eval(wi, wo), model.eval(wi, wo))
    assert aniso > 0.5 and err < bound and change < 2 * bound, (err, change)


def test_rgl_size_options_are_checked(tmp_path, aniso_tab):
    from brdffit.errors import ExportError

    for opts, msg in [({"n_phi": 2}, "n_phi"), ({"n_phi": 1.5}, "n_phi"),
                      ({"vndf_res": 1}, "vndf_res"), ({"n_phi": 40, "vndf_res": 128}, "MiB")]:
        with pytest.raises(ExportError, match=msg):
            export(aniso_tab, "rgl", tmp_path / "x.bsdf", **opts)
    assert list(tmp_path.iterdir()) == []
    # an explicit n_phi is honoured
    info = export(aniso_tab, "rgl", tmp_path / "x.bsdf", n_phi=3, n_theta=8, rgb_res=16, check=False)
    assert info["shapes"]["phi_i"] == [3] and info["shapes"]["rgb"] == [3, 8, 3, 16, 16]


_EVAL = r"""
import drjit as dr
d = np.load(sys.argv[2])
a, b = d["si_wi"].reshape(-1, 3), d["wo"].reshape(-1, 3)
bsdf = scene.shapes()[0].bsdf()
si = dr.zeros(mi.SurfaceInteraction3f, a.shape[0])
si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
si.wi = mi.Vector3f(a[:, 0], a[:, 1], a[:, 2])
val = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(b[:, 0], b[:, 1], b[:, 2])))
val = val.T if val.shape[0] == 3 and val.shape[-1] != 3 else val
np.save(sys.argv[3], val)
assert not any(m.startswith("brdffit") for m in sys.modules), "brdffit was imported"
"""


@pytest.mark.render
@pytest.mark.parametrize("case", ["aniso-ggx", "axis-aligned"])
def test_anisotropic_tabulated_fit_in_plain_mitsuba(tmp_path, case):
    """``brdffit fit ... --model tabulated`` of an anisotropic material, then ``brdffit export
    --to mitsuba-xml``: the scene loads and renders in a Mitsuba that never imports brdffit,
    and its ``measured`` BSDF evaluates to the fit (φ-dependence included)."""
    from brdffit.cli import main
    from brdffit.io.fitfile import load_fit, save_fit
    from tests.export.test_mitsuba import _PLAIN_MITSUBA, _mi, run_plain_mitsuba

    _mi()
    fit = tmp_path / "fit.npz"
    if case == "aniso-ggx":
        assert main(["fit", "synthetic:aniso-ggx", "--model", "tabulated", "-o", str(fit)]) == 0
    else:
        save_fit(_axis_aligned_tab(), fit)
    assert main(["export", str(fit), "--to", "mitsuba-xml", "-o", str(tmp_path / "aniso scene.xml")]) == 0
    model = load_fit(fit)
    assert not model.isotropic
    (tensor,) = tmp_path.glob("*.bsdf")
    back = read_rgl(tensor)
    assert back.reduction == (2 if case == "aniso-ggx" else 4) and back.phi_i.size >= 3
    wi, wo = _configs()
    np.savez(tmp_path / "dirs.npz", si_wi=wo, wo=wi)      # Mitsuba's si.wi = our viewer wo
    run = run_plain_mitsuba(_PLAIN_MITSUBA + _EVAL, tmp_path / "aniso scene.xml",
                            tmp_path / "dirs.npz", tmp_path / "val.npy", cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-2000:]
    kind, finite, peak = run.stdout.split()
    assert "Measured" in kind and finite == "True" and float(peak) > 0
    # Mitsuba returns f_r · cos θ(light); the light is our wi
    got = np.load(tmp_path / "val.npy").reshape(wi.shape) / wi[..., 2:3]
    err, aniso, change = _fidelity(got, model.eval(wi, wo))
    assert aniso > 0.5
    assert err < BOUND and change < BOUND, (err, change)         # measured 0.49 / 0.47 %
