"""RGL .bsdf materials: loading, physical sanity, the warp port, and the proof of
correctness: agreement with Mitsuba 3's own ``measured`` plugin (marked ``render``)."""

from __future__ import annotations

import glob
import os

import numpy as np
import pytest

from brdffit.brdf import IsotropicBRDF
from brdffit.errors import BRDFFormatError
from brdffit.geometry import half_diff_to_io, io_to_half_diff
from brdffit.io.rgl import (IsotropicRGLBRDF, RGLBRDF, _Marginal2D, elevation, phi_to_u,
                            read_rgl, theta_to_u, u_to_phi, u_to_theta)
from brdffit.io.tensorfile import read_tensor_file, write_tensor_file
from tests.conftest import random_hemisphere, shared_data_path

NAMES = ["acrylic_felt_green", "cc_ibiza_sunset", "cc_iris_purple_gem", "chm_mint",
         "colodur_napoli_4f", "ilm_l3_37_matte", "paper_white"]
MATTE = ["acrylic_felt_green", "colodur_napoli_4f", "ilm_l3_37_matte", "paper_white"]
_cache: dict = {}


def rgl(name) -> RGLBRDF:
    p = shared_data_path("rgl", f"{name}_rgb.bsdf")
    if name not in _cache:
        _cache[name] = read_rgl(p)
    return _cache[name]


def make_anisotropic(src, dst, phi_lo, phi_hi, n_phi=4):
    """An anisotropic file built from an isotropic one (for the code paths only: the
    absolute-azimuth vndf is the isotropic one shifted by φi and modulated by cos 2φm)."""
    f = read_tensor_file(src)
    phi_i = np.linspace(phi_lo, phi_hi, n_phi).astype(np.float32)
    vn = f["vndf"][0]
    n_t, h, w = vn.shape
    phm = np.linspace(-np.pi, np.pi, h)
    rel = np.angle(np.exp(1j * (phm[None, :] - phi_i[:, None].astype(np.float64))))
    x = (rel + np.pi) / (2 * np.pi) * (h - 1)
    i0 = np.clip(np.floor(x).astype(int), 0, h - 2)
    fr = (x - i0)[:, None, :, None]
    vndf = (vn[:, i0, :].transpose(1, 0, 2, 3) * (1 - fr) + vn[:, i0 + 1, :].transpose(1, 0, 2, 3) * fr)
    vndf = vndf * (1 + 0.5 * np.cos(2 * phm))[None, None, :, None]
    mod = (1 + 0.3 * np.sin(np.arange(n_phi) + 1.0)).astype(np.float32)
    phj = np.linspace(-np.pi, np.pi, 9)
    g = dict(f)
    g.update(phi_i=phi_i, vndf=vndf.astype(np.float32),
             luminance=(np.repeat(f["luminance"], n_phi, 0) * mod[:, None, None, None]).astype(np.float32),
             rgb=(np.repeat(f["rgb"], n_phi, 0) * mod[:, None, None, None, None]).astype(np.float32),
             ndf=(f["ndf"][:1] * (1 + 0.2 * np.cos(phj))[:, None]).astype(np.float32),
             sigma=(f["sigma"][:1] * (1 + 0.1 * np.sin(phj))[:, None]).astype(np.float32),
             description="synthetic anisotropic test material")
    write_tensor_file(dst, g)
    return dst


ANISO = {1: (-np.pi, np.pi), 2: (-np.pi, 0.0), 4: (-np.pi, -np.pi / 2)}


@pytest.fixture(scope="module")
def aniso_files(tmp_path_factory):
    src = shared_data_path("rgl", "cc_ibiza_sunset_rgb.bsdf")
    d = tmp_path_factory.mktemp("aniso")
    return {r: make_anisotropic(src, d / f"aniso_r{r}.bsdf", *ANISO[r]) for r in ANISO}


# ----------------------------------------------------------------------------- loading
def test_the_seven_files_are_there():
    found = sorted(glob.glob(str(shared_data_path("rgl") / "*_rgb.bsdf")))
    assert [os.path.basename(p)[:-9] for p in found] == NAMES


@pytest.mark.parametrize("name", NAMES)
def test_load_exposes_fields(name):
    b = rgl(name)
    assert isinstance(b, IsotropicRGLBRDF) and isinstance(b, IsotropicBRDF) and b.isotropic
    n_phi, n_th = b.phi_i.size, b.theta_i.size
    assert n_phi == 1 and n_th >= 2 and b.reduction == 0
    assert np.all(np.diff(b.theta_i) > 0) and 0 <= b.theta_i[0] and b.theta_i[-1] <= np.pi / 2 + 1e-6
    assert b.vndf.shape[:2] == (n_phi, n_th)
    assert b.rgb.shape == (n_phi, n_th, 3) + b.luminance.shape[2:]
    assert isinstance(b.description, str) and b.description
    assert b.jacobian in (True, False) and b.name == f"{name}_rgb"
    assert set(b.fields) >= {"theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance", "rgb",
                             "jacobian", "description"}
    mask = b.valid_mask()
    assert mask is None or (mask.shape == b.luminance.shape and mask.any())
    d = b.describe()
    assert d["format"] == "rgl-bsdf" and d["resolution"] == list(b.luminance.shape[2:])


def test_angle_maps_are_mitsubas():
    u = np.linspace(0, 1, 11)
    np.testing.assert_allclose(theta_to_u(u_to_theta(u)), u, atol=1e-15)
    np.testing.assert_allclose(phi_to_u(u_to_phi(u)), u, atol=1e-15)
    assert u_to_theta(1.0) == pytest.approx(np.pi / 2) and u_to_phi(0.0) == pytest.approx(-np.pi)
    rng = np.random.default_rng(3)
    d = random_hemisphere(rng, 1000)
    np.testing.assert_allclose(elevation(d), np.arccos(d[:, 2]), atol=1e-7)


# ----------------------------------------------------------------------------- warps
def test_marginal2d_invert_is_the_cdf_of_its_interpolant():
    """Independent of Mitsuba: invert(u) equals the conditional/marginal CDFs of the
    bilinear interpolant, computed by dense quadrature."""
    rng = np.random.default_rng(5)
    data = rng.random((5, 7)) + 0.05           # H=5 rows (y), W=7 columns (x)
    warp = _Marginal2D(data[None], [np.array([0.3])])   # one (ignored) parameter
    u = rng.random((200, 2))
    got, pdf = warp.invert(u, warp.corners([np.full(200, 0.7)]))
    n = 2401
    xs = np.linspace(0, 1, n)

    def interp(x, y):
        gx, gy = x * 6, y * 4
        ix, iy = np.minimum(gx.astype(int), 5), np.minimum(gy.astype(int), 3)
        fx, fy = gx - ix, gy - iy
        return ((1 - fy) * ((1 - fx) * data[iy, ix] + fx * data[iy, ix + 1])
                + fy * ((1 - fx) * data[iy + 1, ix] + fx * data[iy + 1, ix + 1]))

    marg = np.trapezoid(interp(xs[None, :], xs[:, None]), xs, axis=1)
    total = np.trapezoid(marg, xs)
    for (ux, uy), (gx, gy), p in zip(u[:25], got[:25], pdf[:25]):
        row = interp(xs, np.full(n, uy))
        cdf_x = np.trapezoid(row[xs <= ux], xs[xs <= ux]) / np.trapezoid(row, xs)
        cdf_y = np.trapezoid(marg[xs <= uy], xs[xs <= uy]) / total
        assert gx == pytest.approx(cdf_x, abs=2e-3) and gy == pytest.approx(cdf_y, abs=2e-3)
        assert p == pytest.approx(interp(np.array([ux]), np.array([uy]))[0] / total, rel=1e-6)
    assert np.all((got >= 0) & (got <= 1 + 1e-12))


def test_parameter_interpolation_is_linear_and_clamped():
    a, b = np.ones((3, 4)), np.full((3, 4), 3.0)
    warp = _Marginal2D(np.stack([a, b]), [np.array([0.0, 1.0])], normalize=False,
                       enable_sampling=False)
    pos = np.full((4, 2), 0.4)
    vals = warp.eval(pos, warp.corners([np.array([-1.0, 0.0, 0.25, 2.0])]))
    np.testing.assert_allclose(vals, [1.0, 1.0, 1.5, 3.0])


# ----------------------------------------------------------------------------- physics
@pytest.mark.parametrize("name", NAMES)
def test_eval_finite_nonnegative_zero_below_horizon(name, rng):
    b = rgl(name)
    wi, wo = random_hemisphere(rng, 3000), random_hemisphere(rng, 3000)
    f = b.eval(wi, wo)
    assert f.shape == (3000, 3) and np.all(np.isfinite(f)) and np.all(f >= 0)
    assert f.max() > 0
    below = wo * np.array([1, 1, -1])
    assert np.all(b.eval(wi, below) == 0) and np.all(b.eval(below, wi) == 0)
    one = b.eval(wi[0], wo[:5])                 # broadcasting a single wi
    assert one.shape == (5, 3)
    np.testing.assert_allclose(one[0], f[0])
    np.testing.assert_allclose(one, b.eval(np.tile(wi[0], (5, 1)), wo[:5]))
    edge = np.array([[1, 0, 1e-12], [0, 1, 1e-7], [0, 0, 1], [1e-9, 0, 1], [-1, 0, 1e-5]])
    edge /= np.linalg.norm(edge, axis=1, keepdims=True)
    fe = b.eval(np.repeat(edge, 5, 0), np.tile(edge, (5, 1)))     # grazing / normal pairs
    assert np.all(np.isfinite(fe)) and np.all(fe >= 0)
    th, _, td, pd = io_to_half_diff(wi[:50], wo[:50])
    np.testing.assert_allclose(b.eval_hd(th, td, pd), f[:50], rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("name", MATTE)
def test_reciprocity_and_the_cosine_division(name, rng):
    """f(a, b) ≈ f(b, a); dividing by the other cosine would break it by (cos ratio)²."""
    b = rgl(name)
    wi, wo = random_hemisphere(rng, 4000), random_hemisphere(rng, 4000)
    ok = (wi[:, 2] > 0.2) & (wo[:, 2] > 0.2)
    f1, f2 = b.eval(wi[ok], wo[ok]).sum(-1), b.eval(wo[ok], wi[ok]).sum(-1)
    err = np.median(np.abs(np.log(f1 / f2)))
    wrong = np.median(np.abs(np.log(f1 / f2 * (wi[ok, 2] / wo[ok, 2]) ** 2)))
    assert err < 0.1 and wrong > 3 * err


@pytest.mark.parametrize("name", NAMES)
def test_directional_albedo_at_most_one(name):
    a = rgl(name).albedo(np.radians([0.0, 30.0, 60.0, 75.0]), n_samples=16384)
    assert np.all(a.sum(-1) > 0.05) and np.all(a >= 0) and np.all(a <= 1.0)


@pytest.mark.parametrize("name", NAMES)
def test_ndf_and_sigma_tables(name):
    b = rgl(name)
    nt, st = b.ndf_table(), b.sigma_table()
    j, k = b.ndf.shape
    assert nt.values.shape == (j, k) and nt.theta.shape == (k,) and nt.phi.shape == (j,)
    np.testing.assert_allclose(nt.theta, (np.arange(k) / (k - 1)) ** 2 * np.pi / 2)
    np.testing.assert_allclose(nt.phi, -np.pi + 2 * np.pi * np.arange(j) / (j - 1))
    np.testing.assert_allclose(nt(nt.theta[None, :], nt.phi[:, None]), nt.values, rtol=1e-12)
    assert st(0.0) == pytest.approx(1.0, abs=1e-4)
    # D normalised (∫ D cos θm dωm = 1) and σ(ω) = ∫ D max(0, ω·m) dm: quadrature in u space
    nu, nphi = 600, 128
    u = (np.arange(nu) + 0.5) / nu
    ph = -np.pi + (np.arange(nphi) + 0.5) * 2 * np.pi / nphi
    T, P = np.meshgrid(u_to_theta(u), ph, indexing="ij")
    D = nt(T, P)
    dw = np.sin(T) * np.pi * u[:, None] / nu * (2 * np.pi / nphi)   # dθ = π u du
    assert (D * np.cos(T) * dw).sum() == pytest.approx(1.0, abs=0.03)
    m = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    for t in (0.4, 0.9, 1.3):
        w = np.array([np.sin(t), 0.0, np.cos(t)])
        assert (D * np.maximum(m @ w, 0) * dw).sum() == pytest.approx(float(st(t)), rel=0.03)


# ----------------------------------------------------------------------------- anisotropic
def test_anisotropic_files_fold_by_symmetry(aniso_files, rng):
    wi, wo = random_hemisphere(rng, 2000), random_hemisphere(rng, 2000)
    mirror_x, rot_pi = np.array([-1, 1, 1]), np.array([-1, -1, 1])
    b4, b2, b1 = (read_rgl(aniso_files[r]) for r in (4, 2, 1))
    assert type(b4) is RGLBRDF and not b4.isotropic
    assert (b4.reduction, b2.reduction, b1.reduction) == (4, 2, 1)
    f4 = b4.eval(wi, wo)
    assert np.all(np.isfinite(f4)) and np.all(f4 >= 0) and f4.max() > 0
    np.testing.assert_allclose(b4.eval(wi * mirror_x, wo * mirror_x), f4, rtol=1e-9, atol=1e-12)
    f2 = b2.eval(wi, wo)
    np.testing.assert_allclose(b2.eval(wi * rot_pi, wo * rot_pi), f2, rtol=1e-9, atol=1e-12)
    f1 = b1.eval(wi, wo)   # no folding: a rotation by π changes the value
    assert np.median(np.abs(b1.eval(wi * rot_pi, wo * rot_pi) - f1) / (f1 + 1e-9)) > 1e-3
    with pytest.raises(AttributeError):
        b4.eval_hd  # noqa: B018  (anisotropic: no Rusinkiewicz evaluation)


def test_importance_sampling_passes_chi2(tmp_path):
    """sample() draws wo with the density pdf() reports (Pearson χ², Šidák-corrected)."""
    from brdffit.testing.chi2 import check_sampling
    ok, res = check_sampling(rgl("paper_white"), [[0.0, 0.0, 1.0], [0.9, 0.1, 0.4243]],
                             sample_count=60_000, res_theta=16, res_phi=32)
    assert ok, "\n".join(map(str, res))
    aniso = make_anisotropic(shared_data_path("rgl", "paper_white_rgb.bsdf"),
                             tmp_path / "a4.bsdf", *ANISO[4])   # matte: cheap quadrature
    ok, res = check_sampling(read_rgl(aniso), [[-0.5, 0.6, 0.6245]],
                             sample_count=60_000, res_theta=16, res_phi=32)
    assert ok, "\n".join(map(str, res))
    r = res[0]
    assert r.pdf_integral == pytest.approx(r.valid_fraction, abs=0.01)


def test_sampling_is_useful_and_pdf_positive_where_f_is(rng):
    b = rgl("cc_ibiza_sunset")
    wi = np.tile([0.5, 0.0, np.sqrt(0.75)], (20000, 1))
    wo, pdf = b.sample(wi, rng.random((20000, 2)))
    ok = pdf > 0
    assert ok.mean() > 0.9 and np.allclose(np.linalg.norm(wo[ok], axis=1), 1.0)
    np.testing.assert_allclose(b.pdf(wi[ok], wo[ok]), pdf[ok], rtol=1e-4)
    # importance sampling: the estimator f cos / pdf of the albedo has a low variance
    est = (b.eval(wi[ok], wo[ok]).sum(-1) * wo[ok, 2] / pdf[ok])
    wc = random_hemisphere(rng, 20000)
    uni = b.eval(wi, wc).sum(-1) * wc[:, 2] * 2 * np.pi
    assert est.std() < 0.5 * uni.std()
    assert est.mean() == pytest.approx(uni.mean(), rel=0.1)


# ----------------------------------------------------------------------------- spectral
LAMBDAS = np.array([380, 430, 480, 530, 580, 630, 680, 730], np.float32)


def make_spectral(src, dst, mix):
    """A spectral file whose spectrum at LAMBDAS[k] is mix[k] · (R, G, B) of an RGB file."""
    f = read_tensor_file(src)
    rgb = f.pop("rgb")
    f["spectra"] = np.einsum("lc,ptcyx->ptlyx", mix, rgb).astype(np.float32)
    f["wavelengths"] = LAMBDAS
    return write_tensor_file(dst, f)


@pytest.fixture(scope="module")
def spectral_file(tmp_path_factory):
    mix = np.abs(np.random.default_rng(0).normal(size=(LAMBDAS.size, 3))).astype(np.float32)
    src = shared_data_path("rgl", "cc_iris_purple_gem_rgb.bsdf")
    return make_spectral(src, tmp_path_factory.mktemp("spec") / "spec.bsdf", mix), mix


def test_spectral_files_evaluate_consistently(spectral_file, rng):
    from brdffit.io.rgl import spectral_to_srgb_weights
    path, mix = spectral_file
    b, ref = read_rgl(path), rgl("cc_iris_purple_gem")
    assert b.rgb is None and b.spectra.shape[2] == LAMBDAS.size
    wi, wo = random_hemisphere(rng, 2000), random_hemisphere(rng, 2000)
    # the evaluation is linear in the table: at a stored wavelength, mix · RGB value
    spec = b.eval_spectral_mitsuba(wo, wi, LAMBDAS.astype(np.float64))
    tol = dict(rtol=2e-5, atol=1e-7 * spec.max())    # spectra are stored as float32
    np.testing.assert_allclose(spec, ref.eval_mitsuba(wo, wi) @ mix.T.astype(np.float64), **tol)
    # halfway between two samples: the average (linear in wavelength); clamped outside
    mid = b.eval_spectral_mitsuba(wo, wi, [405.0, 300.0, 900.0])
    np.testing.assert_allclose(mid[:, 0], 0.5 * (spec[:, 0] + spec[:, 1]), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(mid[:, 1], spec[:, 0], rtol=1e-9)
    np.testing.assert_allclose(mid[:, 2], spec[:, -1], rtol=1e-9)
    # RGB of a spectral file = sRGB weights applied to the spectral table
    w = spectral_to_srgb_weights(LAMBDAS)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=2e-3)     # flat spectrum -> grey
    rgbv = b.eval_mitsuba(wo, wi)
    np.testing.assert_allclose(rgbv, ref.eval_mitsuba(wo, wi) @ (w @ mix.astype(np.float64)).T,
                               rtol=2e-5, atol=1e-7 * np.abs(rgbv).max())
    with pytest.raises(BRDFFormatError, match="spectral file"):
        ref.eval_spectral_mitsuba(wo, wi, [500.0])


@pytest.mark.render
def test_spectral_matches_mitsuba_spectral_variant(spectral_file, mitsuba):
    """Mitsuba's spectral variant, in a subprocess (the session's variant stays llvm_ad_rgb)."""
    import json
    import subprocess
    import sys
    path, _ = spectral_file
    script = f"""
import json, numpy as np, mitsuba as mi
mi.set_variant('llvm_ad_spectral')
from brdffit.io.rgl import read_rgl
rng = np.random.default_rng(1); n = 3000
def rh(n):
    v = rng.normal(size=(n, 3)); v /= np.linalg.norm(v, axis=1, keepdims=True); v[:, 2] = abs(v[:, 2])
    return v.astype(np.float32).astype(np.float64)
wi, wo = rh(n), rh(n)
wl = rng.uniform(360, 830, size=(n, 4)).astype(np.float32).astype(np.float64)
bs = mi.load_dict({{'type': 'measured', 'filename': {str(path)!r}}})
si = mi.SurfaceInteraction3f(); si.wi = mi.Vector3f(wo.T); si.wavelengths = mi.Spectrum(wl.T)
ref = np.array(bs.eval(mi.BSDFContext(), si, mi.Vector3f(wi.T))).T
ours = read_rgl({str(path)!r}).eval_spectral_mitsuba(wo, wi, wl)
rel = np.abs(ours - ref) / np.maximum(np.abs(ref), 1e-3 * np.abs(ref).max())
print(json.dumps({{"max": float(rel.max()), "median": float(np.median(rel))}}))
"""
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env=dict(os.environ), timeout=300)
    if out.returncode != 0 and "llvm_ad_spectral" in out.stderr:
        pytest.skip(f"Mitsuba llvm_ad_spectral unavailable: {out.stderr[-300:]}")
    assert out.returncode == 0, out.stderr[-2000:]
    rel = json.loads(out.stdout.strip().splitlines()[-1])
    assert rel["max"] < 1e-3 and rel["median"] < 1e-5, rel


# ----------------------------------------------------------------------------- errors
def _rewrite(tmp_path, **changes):
    f = read_tensor_file(shared_data_path("rgl", "paper_white_rgb.bsdf"))
    for k, v in changes.items():
        if v is None:
            f.pop(k)
        else:
            f[k] = v
    return write_tensor_file(tmp_path / "broken.bsdf", f)


def test_rgl_structure_errors(tmp_path):
    f = read_tensor_file(shared_data_path("rgl", "paper_white_rgb.bsdf"))
    cases = [
        (dict(vndf=None), "field 'vndf'"),
        (dict(rgb=f["rgb"][:, :, :2]), "rgb of shape"),
        (dict(rgb=None), "'rgb' or a 'spectra'"),
        (dict(vndf=f["vndf"].astype(np.float64)), "float32"),
        (dict(theta_i=f["theta_i"][::-1].copy()), "increasing"),
        (dict(vndf=-f["vndf"]), "non-negative"),
        (dict(vndf=np.zeros_like(f["vndf"])), "positive integral"),
        (dict(luminance=f["luminance"][:, :, :, :5]), "luminance of shape"),
        (dict(luminance=np.zeros_like(f["luminance"])), "luminance slice"),
        (dict(jacobian=np.zeros(0, np.uint8)), "jacobian flag"),
        (dict(spectra=f["rgb"], wavelengths=np.array([500, 400, 600], np.float32), rgb=None),
         "increasing wavelengths"),
    ]
    for change, match in cases:
        p = _rewrite(tmp_path, **change)
        with pytest.raises(BRDFFormatError, match=match) as exc:
            read_rgl(p)
        assert str(p) in str(exc.value)
    p = tmp_path / "trunc.bsdf"
    p.write_bytes(shared_data_path("rgl", "paper_white_rgb.bsdf").read_bytes()[:5000])
    with pytest.raises(BRDFFormatError, match="data of field"):
        read_rgl(p)


# ----------------------------------------------------------------------------- Mitsuba
@pytest.fixture(scope="module")
def mitsuba():
    try:
        from brdffit.evaluation.render._mitsuba import MitsubaUnavailable, load
    except ImportError:
        load = None
    if load is not None:
        try:
            return load()[0]
        except MitsubaUnavailable as exc:
            pytest.skip(str(exc))
    lib = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"
    if not os.environ.get("DRJIT_LIBLLVM_PATH"):
        if not os.path.exists(lib):
            pytest.skip(f"Mitsuba's LLVM back-end needs {lib} (absent)")
        os.environ["DRJIT_LIBLLVM_PATH"] = lib
    try:
        import mitsuba as mi
        mi.set_variant("llvm_ad_rgb")
    except Exception as exc:  # noqa: BLE001 - any failure means: cannot cross-check here
        pytest.skip(f"Mitsuba 3 llvm_ad_rgb unavailable: {exc}")
    return mi


def _mitsuba_eval(mi, path, wi_m, wo_m):
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(wi_m.T.astype(np.float32))
    return np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wo_m.T.astype(np.float32)))).T


def _cross_check(mi, b, path, seed, n=3000):
    rng = np.random.default_rng(seed)
    # float32-representable directions: both sides see identical inputs
    wi = random_hemisphere(rng, n).astype(np.float32).astype(np.float64)
    wo = random_hemisphere(rng, n).astype(np.float32).astype(np.float64)
    ref = _mitsuba_eval(mi, path, wo, wi)          # Mitsuba si.wi = our wo (towards viewer)
    ours = b.eval_mitsuba(wo, wi)
    scale = np.abs(ref).max()
    rel = np.abs(ours - ref) / np.maximum(np.abs(ref), 1e-3 * scale)
    assert scale > 0
    assert rel.max() < 1e-3 and np.median(rel) < 1e-5, (rel.max(), np.median(rel))
    f = b.eval(wi, wo)                             # f_r = Mitsuba value / cos θ(light)
    expect = np.maximum(ref / wi[:, 2:3], 0.0)
    assert np.allclose(f, expect, rtol=1e-3, atol=1e-6 * expect.max())
    # pdf and sample: Mitsuba's Measured::pdf / Measured::sample with the same inputs
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(wi.T.astype(np.float32))
    ctx = mi.BSDFContext()
    ref_pdf = np.array(bsdf.pdf(ctx, si, mi.Vector3f(wo.T.astype(np.float32))))
    pdf = b.pdf(wi, wo)
    prel = np.abs(pdf - ref_pdf) / np.maximum(ref_pdf, 1e-3 * ref_pdf.max())
    assert prel.max() < 1e-3, prel.max()
    u = rng.random((n, 2)).astype(np.float32).astype(np.float64)
    bs, _ = bsdf.sample(ctx, si, 0.5, mi.Point2f(u.T.astype(np.float32)))
    ref_wo, ref_spdf = np.array(bs.wo).T, np.array(bs.pdf)
    wo_s, spdf = b.sample(wi, u)
    valid = ref_wo[:, 2] > 0
    assert valid.mean() > 0.9 and np.all(spdf[~valid] == 0)
    assert np.abs(wo_s - ref_wo)[valid].max() < 1e-3
    srel = np.abs(spdf - ref_spdf) / np.maximum(ref_spdf, 1e-3 * ref_spdf.max())
    assert srel[valid].max() < 1e-2 and np.median(srel[valid]) < 1e-5
    return rel.max()


@pytest.mark.render
@pytest.mark.parametrize("name", NAMES)
def test_matches_mitsuba_measured_plugin(mitsuba, name):
    path = shared_data_path("rgl", f"{name}_rgb.bsdf")
    _cross_check(mitsuba, rgl(name), path, seed=NAMES.index(name))


@pytest.mark.render
@pytest.mark.parametrize("reduction", [1, 2, 4])
def test_matches_mitsuba_on_anisotropic_files(mitsuba, aniso_files, reduction):
    path = aniso_files[reduction]
    _cross_check(mitsuba, read_rgl(path), path, seed=10 + reduction)


# ----------------------------------------------------------------------------- measured domain
@pytest.mark.parametrize("name", NAMES)
def test_measured_domain_ends_at_the_last_measured_incidence(name):
    """The 90° row of an RGL file cannot be measured: the domain ends at the node before it,
    and ``measured`` is exactly θi ≤ that node (wo anywhere above the horizon)."""
    b = rgl(name)
    assert np.degrees(b.theta_i[-1]) == pytest.approx(90.0, abs=0.01)
    t = b.theta_i_measured
    assert t == pytest.approx(float(b.theta_i[-2])) and 70.0 < np.degrees(t) < 85.0
    assert b.measured_domain == f"θi ≤ {np.degrees(t):.1f}° (the file's measured incidences)"
    wo = np.array([0.3, 0.1, np.sqrt(1 - 0.1)])

    def at(deg):
        r = np.radians(deg)
        return np.array([np.sin(r), 0.0, np.cos(r)])

    assert b.measured(at(np.degrees(t) - 0.01), wo) and not b.measured(at(np.degrees(t) + 0.05), wo)
    assert not b.measured(at(30.0), np.array([0.0, 0.6, -0.8]))   # wo below the horizon
    th, td, pd = np.radians([10.0, 30.0]), np.radians([5.0, 80.0]), np.radians([20.0, 90.0])
    wi, wo2 = half_diff_to_io(th, 0.0, td, pd)
    np.testing.assert_array_equal(b.measured_hd(th, td, pd), b.measured(wi, wo2))


@pytest.mark.parametrize("name", NAMES)
def test_valid_field_marks_the_horizon_or_its_complement(name):
    """What ``valid_mask`` documents: read MSB first, the file's bit mask is set exactly on
    the texels whose outgoing direction lies above the horizon, or exactly on the others —
    so it carries no measured domain (the 90° rows of the last θi excepted, ≤ 0.2 %)."""
    b = rgl(name)
    bits = b.valid_mask()
    n = bits.shape[-1]
    y, x = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    s = np.stack([x.ravel() / (n - 1), y.ravel() / (n - 1)], -1)
    agree = []
    for k, th in enumerate(b.theta_i):
        corners = b._vndf.corners([np.zeros(len(s)), np.full(len(s), th)])
        u_m, _ = b._vndf.sample(s, corners)
        phi_m, theta_m = u_to_phi(u_m[:, 1]), u_to_theta(u_m[:, 0])
        m = np.stack([np.cos(phi_m) * np.sin(theta_m), np.sin(phi_m) * np.sin(theta_m),
                      np.cos(theta_m)], -1)
        wi = np.array([np.sin(th), 0.0, np.cos(th)])
        wo_z = 2 * (m @ wi) * m[:, 2] - wi[2]
        agree.append(np.mean(bits[0, k].ravel() == (wo_z > 0)))
    agree = np.array(agree)
    assert np.all(agree >= 0.998) or np.all(agree <= 0.002), agree
