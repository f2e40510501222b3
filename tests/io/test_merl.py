"""MERL .binary reader/writer: layout, lookups, invalid samples, validation, resampling."""

from __future__ import annotations

import os

import numpy as np
import pytest

from brdffit.brdf import BRDF, IsotropicBRDF
from brdffit.errors import BRDFFormatError
from brdffit.geometry import half_diff_to_io
from brdffit.grid import merl_phi_d, merl_theta_d, merl_theta_h, tabulate_merl_grid
from brdffit.io import merl as merl_mod
from brdffit.io.merl import MERLBRDF, read_merl, resample_to_merl, write_merl

SCALE = np.array([1.0, 1.15, 1.66]) / 1500.0
N = 90 * 90 * 180


def _write_raw(path, raw_channel_major, header=(90, 90, 180)):
    """Write a MERL file by hand (independently of write_merl)."""
    with open(path, "wb") as fh:
        fh.write(np.asarray(header, dtype="<i4").tobytes())
        fh.write(np.asarray(raw_channel_major, dtype="<f8").tobytes())
    return path


@pytest.fixture(scope="module")
def raw_table():
    rng = np.random.default_rng(7)
    raw = rng.uniform(0.0, 3000.0, size=(3, N))
    invalid = rng.random(N) < 0.03
    raw[:, invalid] = -1.0
    return raw, invalid


@pytest.fixture(scope="module")
def merl_file(tmp_path_factory, raw_table):
    path = tmp_path_factory.mktemp("merl") / "random.binary"
    return _write_raw(path, raw_table[0])


def _grid():
    return np.meshgrid(merl_theta_h(), merl_theta_d(), merl_phi_d(), indexing="ij")


def test_layout_scaling_and_mask(merl_file, raw_table):
    raw, invalid = raw_table
    b = read_merl(merl_file)
    values, valid = b.merl_table()
    assert values.shape == (90, 90, 180, 3) and valid.shape == (90, 90, 180)
    # sample (i_θh, i_θd, i_φd) sits at φd + 180 (θd + 90 θh) in each channel block
    i, j, k = 37, 81, 123
    flat = k + 180 * (j + 90 * i)
    if invalid[flat]:
        flat += 1
        k += 1
    np.testing.assert_array_equal(values[i, j, k], raw[:, flat] * SCALE)
    np.testing.assert_array_equal(valid.ravel(), ~invalid)
    assert b.n_invalid == int(invalid.sum())
    assert np.all(values[~valid] == 0.0)
    assert b.name == "random" and b.source == str(merl_file)
    # every channel is one contiguous block, as in the file (no transposed copy is made)
    for c in range(3):
        assert values[..., c].flags["C_CONTIGUOUS"]
        np.testing.assert_array_equal(values[..., c].ravel(), np.where(invalid, 0.0,
                                                                       raw[c] * SCALE[c]))
    assert not values.flags.writeable and not valid.flags.writeable


def test_file_round_trip_is_bit_exact(merl_file, tmp_path):
    b = read_merl(merl_file)
    out = write_merl(b, tmp_path / "copy.binary")
    assert out.read_bytes() == merl_file.read_bytes()


def test_round_trip_after_the_source_changed_writes_the_table_read(merl_file, tmp_path):
    """The table is scaled in its read buffer (the file's numbers are not kept): when the
    source no longer holds it, the written file is the table itself (values / scales)."""
    b = read_merl(merl_file)
    values, valid = (a.copy() for a in b.merl_table())
    original = merl_file.read_bytes()
    changed = bytearray(original)
    changed[12:20] = np.float64(0.123).tobytes()   # R of the first sample
    merl_file.write_bytes(bytes(changed))
    try:
        out = write_merl(b, tmp_path / "copy.binary")
        assert out.read_bytes() != bytes(changed)
        back = read_merl(out)
        np.testing.assert_array_equal(back.merl_table()[1], valid)
        np.testing.assert_allclose(back.merl_table()[0], values, rtol=4e-16, atol=0)
        merl_file.unlink()                            # gone: the same
        assert write_merl(b, tmp_path / "again.binary").read_bytes() == out.read_bytes()
    finally:
        merl_file.write_bytes(original)


def test_table_round_trip(tmp_path, raw_table):
    rng = np.random.default_rng(3)
    values = rng.random((90, 90, 180, 3))
    valid = ~raw_table[1].reshape(90, 90, 180)
    write_merl((values, valid), tmp_path / "t.binary")
    back = read_merl(tmp_path / "t.binary")
    v2, m2 = back.merl_table()
    np.testing.assert_array_equal(m2, valid)
    np.testing.assert_allclose(v2[valid], values[valid], rtol=1e-15, atol=0)
    # invalid samples are written as -1 in every channel
    raw = np.fromfile(tmp_path / "t.binary", dtype="<f8", offset=12).reshape(3, -1)
    assert np.all(raw[:, ~valid.ravel()] == -1.0)


def test_nearest_reproduces_stored_values_at_grid_points(merl_file):
    b = read_merl(merl_file, interpolation="nearest")
    values, _ = b.merl_table()
    th, td, pd = _grid()
    np.testing.assert_array_equal(b.eval_hd(th, td, pd), values)
    # MERL's lookup truncates the index (not rounding): 70% into a cell gives its first sample
    eps_h = np.diff(merl_theta_h())[:, None, None] * 0.7
    got = b.eval_hd(th[:-1] + eps_h, td[:-1] + 0.7 * np.pi / 180, pd[:-1] + 0.7 * np.pi / 180)
    np.testing.assert_array_equal(got, values[:-1])


def test_trilinear_matches_grid_and_interpolates_linearly(tmp_path):
    rng = np.random.default_rng(11)
    values = rng.random((90, 90, 180, 3)) + 0.1
    b = MERLBRDF(values)
    th, td, pd = _grid()
    np.testing.assert_allclose(b.eval_hd(th, td, pd), values, rtol=1e-12)
    # half-way in φd between samples k and k+1 (θh, θd on the grid): the mean
    i, j, k = 20, 40, 179  # k = 179 wraps to 0 (φd periodic with period π)
    mid = b.eval_hd(merl_theta_h()[i], merl_theta_d()[j], (k + 0.5) * np.pi / 180)
    np.testing.assert_allclose(mid, 0.5 * (values[i, j, k] + values[i, j, 0]), rtol=1e-12)
    # half-way in the sqrt-θh index
    u = (i + 0.5) / 90
    mid = b.eval_hd(u * u * np.pi / 2, merl_theta_d()[j], merl_phi_d()[7])
    np.testing.assert_allclose(mid, 0.5 * (values[i, j, 7] + values[i + 1, j, 7]), rtol=1e-12)
    # reciprocity: φd and φd + π are the same configuration
    x = rng.random((1000, 3)) * [np.pi / 2, np.pi / 2, np.pi]
    np.testing.assert_allclose(b.eval_hd(x[:, 0], x[:, 1], x[:, 2]),
                               b.eval_hd(x[:, 0], x[:, 1], x[:, 2] + np.pi), rtol=1e-12)
    # clamped beyond the last samples (θh, θd -> π/2)
    np.testing.assert_allclose(b.eval_hd(np.pi / 2, np.pi / 2, 0.0), values[89, 89, 0], rtol=1e-12)


def test_trilinear_is_continuous():
    rng = np.random.default_rng(5)
    values = rng.random((90, 90, 180, 3))
    b = MERLBRDF(values)
    x = rng.random((20000, 3)) * [np.pi / 2, np.pi / 2, 2 * np.pi]
    x[:100, 2] = np.pi - 1e-9  # across the φd wrap
    d = 1e-7
    f0 = b.eval_hd(x[:, 0], x[:, 1], x[:, 2])
    f1 = b.eval_hd(x[:, 0] + d, x[:, 1] + d, x[:, 2] + d)
    # index-space slopes are ≤ 1 per sample; the steepest index map is sqrt near θh = 0
    assert np.max(np.abs(f1 - f0)) < 1e-2
    nb = b.with_interpolation("nearest")
    assert np.max(np.abs(nb.eval_hd(x[:, 0], x[:, 1], x[:, 2])
                         - nb.eval_hd(x[:, 0] + 0.02, x[:, 1] + 0.02, x[:, 2] + 0.02))) > 0.1


def test_invalid_samples_never_leak(merl_file, rng):
    for mode in ("nearest", "trilinear"):
        b = read_merl(merl_file, interpolation=mode)
        wi = rng.normal(size=(100000, 3))
        wo = rng.normal(size=(100000, 3))
        wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
        wi /= np.linalg.norm(wi, axis=1, keepdims=True)
        wo /= np.linalg.norm(wo, axis=1, keepdims=True)
        f = b.eval(wi, wo)
        assert np.all(f >= 0) and np.all(np.isfinite(f))
    # a valid sample next to an invalid one: trilinear uses only the valid one
    values = np.ones((90, 90, 180, 3))
    valid = np.zeros((90, 90, 180), bool)
    valid[10, 10, 10] = True
    values[10, 10, 10] = [0.5, 0.25, 0.125]
    b = MERLBRDF(values, valid)
    th, td = merl_theta_h()[10], merl_theta_d()[10]
    np.testing.assert_allclose(b.eval_hd(th, td, 10.4 * np.pi / 180), [0.5, 0.25, 0.125])
    assert np.all(b.eval_hd(th, td, 12.5 * np.pi / 180) == 0)  # all 8 corners invalid
    assert np.all(b.with_interpolation("nearest").eval_hd(th, td, 11 * np.pi / 180) == 0)


def test_compiled_kernel_matches_numpy_reference(monkeypatch):
    if merl_mod._numba is None:
        pytest.skip("numba not installed: only the NumPy path exists")
    import brdffit._jit

    monkeypatch.setattr(brdffit._jit, "COMPILE_AFTER", -1)  # compiled from the first call
    rng = np.random.default_rng(2)
    values = rng.random((90, 90, 180, 3))
    valid = rng.random((90, 90, 180)) > 0.2
    table = merl_mod._pack(values, valid)
    u, v, w = rng.random(5000) * 92, rng.random(5000) * 92, rng.random(5000) * 180
    np.testing.assert_allclose(merl_mod._merl_trilinear(table, u, v, w),
                               merl_mod._merl_trilinear_numpy(table, u, v, w), rtol=1e-12)


@pytest.mark.parametrize("case", ["empty", "short_header", "bad_header", "absurd_header",
                                  "truncated", "trailing", "nan", "inf"])
def test_validation_errors(tmp_path, case):
    path = tmp_path / f"{case}.binary"
    good = np.zeros(3 * N)
    if case == "empty":
        path.write_bytes(b"")
    elif case == "short_header":
        path.write_bytes(b"\x5a\x00\x00\x00\x5a")
    elif case == "bad_header":
        _write_raw(path, good, header=(90, 90, 90))
    elif case == "absurd_header":
        _write_raw(path, good[:10], header=(-3, 1 << 30, 7))
    elif case == "truncated":
        _write_raw(path, good[:-5])
    elif case == "trailing":
        _write_raw(path, np.concatenate([good, [1.0]]))
    else:
        bad = good.copy()
        bad[12345] = np.nan if case == "nan" else np.inf
        _write_raw(path, bad)
    with pytest.raises(BRDFFormatError) as err:
        read_merl(path)
    msg = str(err.value)
    assert str(path) in msg and "expected" in msg
    assert err.value.path == str(path)


def test_missing_file_and_bad_interpolation(tmp_path):
    with pytest.raises(BRDFFormatError, match="no such file"):
        read_merl(tmp_path / "nope.binary")
    with pytest.raises(ValueError, match="interpolation"):
        MERLBRDF(np.zeros((90, 90, 180, 3)), interpolation="cubic")


def test_failed_write_leaves_no_output(tmp_path):
    values = np.ones((90, 90, 180, 3))
    values[1, 2, 3, 0] = np.nan
    valid = np.ones((90, 90, 180), bool)
    target = tmp_path / "out.binary"
    with pytest.raises(BRDFFormatError):
        write_merl((values, valid), target)
    with pytest.raises(BRDFFormatError):
        write_merl(np.ones((90, 90, 3)), target)
    assert os.listdir(tmp_path) == []
    # an existing file is left untouched by a failing write
    target.write_bytes(b"old")
    with pytest.raises(BRDFFormatError):
        write_merl((values, valid), target)
    assert target.read_bytes() == b"old" and os.listdir(tmp_path) == ["out.binary"]


class _Analytic(IsotropicBRDF):
    """A smooth isotropic test BRDF, with a negative patch that must come out invalid."""

    name = "analytic"

    def eval_hd(self, theta_h, theta_d, phi_d):
        th, td, pd = np.broadcast_arrays(theta_h, theta_d, phi_d)
        base = 0.1 + np.exp(-(th / 0.2) ** 2) * (1 + 0.3 * np.cos(td)) + 0.01 * np.cos(2 * pd)
        out = np.stack([base, 0.5 * base, 0.25 * base], axis=-1)
        return np.where((th > 1.5)[..., None], -1.0, out)


class _Aniso(BRDF):
    name = "aniso"

    def eval(self, wi, wo):
        return np.ones(np.broadcast_shapes(np.shape(wi), np.shape(wo)))


def test_resample_to_merl(tmp_path):
    brdf = _Analytic()
    target = tmp_path / "res.binary"
    m = resample_to_merl(brdf, target)
    th, td, pd = _grid()
    expected = brdf.eval_hd(th, td, pd)
    values, valid = m.merl_table()
    np.testing.assert_array_equal(valid, ~(th > 1.5))
    np.testing.assert_allclose(values[valid], expected[valid], rtol=1e-15)
    back = read_merl(target)
    np.testing.assert_array_equal(back.merl_table()[1], valid)
    np.testing.assert_allclose(back.merl_table()[0], values, rtol=1e-14)
    # grid.tabulate_merl_grid returns the stored table (mask included) of a MERLBRDF
    tv, tm = tabulate_merl_grid(back)
    np.testing.assert_array_equal(tm, valid)
    assert resample_to_merl(back) is not back
    with pytest.raises(BRDFFormatError, match="isotropic"):
        resample_to_merl(_Aniso(), tmp_path / "x.binary")
    assert not (tmp_path / "x.binary").exists()


@pytest.mark.parametrize("compiled", [True, False])
def test_fast_half_diff_matches_geometry_and_base_eval(rng, compiled, monkeypatch):
    import brdffit._jit
    from brdffit.geometry import io_to_half_diff
    from brdffit.io.merl import fast_half_diff

    if compiled and merl_mod._numba is None:
        pytest.skip("numba not installed: only the NumPy path exists")
    monkeypatch.setattr(brdffit._jit, "COMPILE_AFTER", -1 if compiled else 1 << 40)

    wi = rng.normal(size=(20000, 3))
    wo = rng.normal(size=(20000, 3))
    wo[:10] = wi[:10]   # θd = 0
    wo[10:20] = -wi[10:20]  # degenerate half vector
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    th, td, pd, above = fast_half_diff(wi, wo)
    rth, _, rtd, rpd = io_to_half_diff(wi, wo)
    np.testing.assert_allclose(th, rth, atol=1e-12)
    np.testing.assert_allclose(td, rtd, atol=1e-9)
    dphi = np.abs(pd - rpd)
    dphi = np.minimum(dphi, 2 * np.pi - dphi)
    assert np.all(dphi[rtd > 1e-6] < 1e-9)  # φd is undefined at θd = 0
    np.testing.assert_array_equal(above, (wi[:, 2] > 0) & (wo[:, 2] > 0))
    b = MERLBRDF(rng.random((90, 90, 180, 3)))
    np.testing.assert_allclose(b.eval(wi[20:], wo[20:]), IsotropicBRDF.eval(b, wi[20:], wo[20:]),
                               rtol=1e-9, atol=1e-12)
    assert b.eval(wi[0], wo[0]).shape == (3,)


def test_measured_domain_is_the_valid_mask(merl_file, raw_table, rng):
    """A MERL table's measured domain is its valid samples: ``measured`` at the nodes is the
    mask, and a direction pair is measured when its nearest sample is."""
    _, invalid = raw_table
    b = read_merl(merl_file)
    assert b.measured_domain == f"the {N - invalid.sum()} of {N} table samples not marked invalid"
    th, td, pd = _grid()
    np.testing.assert_array_equal(b.measured_hd(th, td, pd), ~invalid.reshape(th.shape))
    sub = (slice(1, None, 7), slice(1, None, 5), slice(None, None, 11))  # θh, θd > 0: φd defined
    wi, wo = half_diff_to_io(th[sub], 0.0, td[sub], pd[sub])
    above = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    expect = ~invalid.reshape(th.shape)[sub] & above
    np.testing.assert_array_equal(b.measured(wi, wo), expect)
    full = MERLBRDF(np.ones(th.shape + (3,)))
    assert full.measured_domain is None
