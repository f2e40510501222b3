"""UTIA .bin anisotropic tables: layout and view/illumination convention, lookup, validation."""

from __future__ import annotations

import os

import numpy as np
import pytest

from brdffit.brdf import BRDF
from brdffit.errors import BRDFFormatError
from brdffit.geometry import spherical_to_cartesian
from brdffit.io import utia as utia_mod
from brdffit.io.utia import UTIABRDF, read_utia, utia_phi, utia_theta, write_utia

D = np.pi / 180


class AnisoLobe(BRDF):
    """An anisotropic test BRDF: elliptic lobe around the mirror direction, not symmetric
    under wi <-> wo swaps (so the illumination/view convention is observable)."""

    name = "aniso-lobe"

    def eval(self, wi, wo):
        wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
        h = wi + wo
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        lobe = np.exp(-(h[..., 0] / 0.35) ** 2 - (h[..., 1] / 0.7) ** 2)
        v = 0.2 + lobe + 0.15 * wi[..., 0] + 0.05 * wo[..., 1]
        out = np.stack([v, 0.5 * v, 0.25 * v], axis=-1)
        return np.where(((wi[..., 2] > 0) & (wo[..., 2] > 0))[..., None], out, 0.0)


def _grid_dirs():
    t, p = utia_theta(), utia_phi()
    ti, pi, tv, pv = np.meshgrid(t, p, t, p, indexing="ij")
    return spherical_to_cartesian(ti, pi), spherical_to_cartesian(tv, pv)


@pytest.fixture(scope="module")
def utia_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("utia") / "aniso.bin"
    write_utia(AnisoLobe(), path)
    return path


def test_file_layout_and_convention(tmp_path):
    # Fortran order (48 φv, 6 θv, 48 φi, 6 θi, 3): a single spike, written by hand
    arr = np.zeros((48, 6, 48, 6, 3))
    arr[3, 2, 10, 4, 1] = 7.0  # φv = 22.5°, θv = 30°, φi = 75°, θi = 60°, green
    path = tmp_path / "spike.bin"
    path.write_bytes(arr.ravel(order="F").astype("<f8").tobytes())
    b = read_utia(path)
    wi = spherical_to_cartesian(60 * D, 75 * D)    # illumination
    wo = spherical_to_cartesian(30 * D, 22.5 * D)  # view
    np.testing.assert_allclose(b.eval(wi, wo), [0.0, 7.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(b.eval(wo, wi), [0.0, 0.0, 0.0], atol=1e-12)  # swapped: other sample
    assert b.utia_table()[0][4, 10, 2, 3, 1] == 7.0
    # and write_utia puts it back at the same place
    write_utia(b, tmp_path / "copy.bin")
    assert (tmp_path / "copy.bin").read_bytes() == path.read_bytes()
    write_utia(b.utia_table(), tmp_path / "copy2.bin")
    assert (tmp_path / "copy2.bin").read_bytes() == path.read_bytes()


def test_round_trip_reproduces_grid(utia_file):
    b = read_utia(utia_file)
    assert not b.isotropic and b.n_invalid == 0 and b.n_samples == 6 * 48 * 6 * 48
    wi, wo = _grid_dirs()
    np.testing.assert_allclose(b.eval(wi, wo), AnisoLobe().eval(wi, wo), rtol=1e-12, atol=1e-14)


def test_interpolation(utia_file):
    b = read_utia(utia_file)
    values = b.utia_table()[0]
    # half-way in φv between samples 47 and 0 (periodic)
    f = b.eval_angles(30 * D, 15 * D, 45 * D, (352.5 + 3.75) * D)
    np.testing.assert_allclose(f, 0.5 * (values[2, 2, 3, 47] + values[2, 2, 3, 0]), rtol=1e-12)
    # half-way in θi
    f = b.eval_angles(37.5 * D, 15 * D, 45 * D, 90 * D)
    np.testing.assert_allclose(f, 0.5 * (values[2, 2, 3, 12] + values[3, 2, 3, 12]), rtol=1e-12)
    # above 75°: held at the 75° value; at/below the horizon: 0
    np.testing.assert_allclose(b.eval_angles(85 * D, 15 * D, 45 * D, 90 * D),
                               values[5, 2, 3, 12], rtol=1e-12)
    assert np.all(b.eval_angles(90 * D, 0, 45 * D, 0) == 0)
    wi = spherical_to_cartesian(100 * D, 0.0)
    assert np.all(b.eval(wi, spherical_to_cartesian(0.3, 0.2)) == 0)
    # interpolation error of a smooth BRDF is small off the grid
    rng = np.random.default_rng(0)
    ti, tv = rng.uniform(0, 75 * D, (2, 5000))
    pi, pv = rng.uniform(0, 2 * np.pi, (2, 5000))
    got = b.eval_angles(ti, pi, tv, pv)
    ref = AnisoLobe().eval(spherical_to_cartesian(ti, pi), spherical_to_cartesian(tv, pv))
    assert np.median(np.abs(got - ref) / ref) < 0.05


def test_continuity_and_kernel_matches_numpy():
    rng = np.random.default_rng(4)
    values = rng.random((6, 48, 6, 48, 3))
    valid = rng.random((6, 48, 6, 48)) > 0.1
    b = UTIABRDF(values, valid)
    a = rng.random((4, 20000)) * np.array([[80 * D], [2 * np.pi], [80 * D], [2 * np.pi]])
    f0 = b.eval_angles(*a)
    f1 = b.eval_angles(*(a + 1e-8))
    assert np.max(np.abs(f1 - f0)) < 1e-3 and np.all(f0 >= 0)
    if utia_mod._numba is not None:
        idx = (np.minimum(a[0], 75 * D) / (15 * D), np.mod(a[1], 2 * np.pi) / (7.5 * D),
               np.minimum(a[2], 75 * D) / (15 * D), np.mod(a[3], 2 * np.pi) / (7.5 * D))
        np.testing.assert_allclose(f0, utia_mod._utia_lookup_numpy(b._packed, *idx), rtol=1e-12)


def test_negative_samples_are_invalid(tmp_path):
    arr = np.full((48, 6, 48, 6, 3), 0.5)
    arr[:, :, :, 2, :] = -1.0  # every θi = 30° sample unmeasured
    path = tmp_path / "neg.bin"
    path.write_bytes(arr.ravel(order="F").tobytes())
    b = read_utia(path)
    assert b.n_invalid == 48 * 6 * 48
    f = b.eval_angles(np.linspace(0, 89 * D, 200), 0.3, 40 * D, 1.0)
    assert np.all(f >= 0)
    np.testing.assert_allclose(f[f[:, 0] > 0], 0.5)
    assert np.all(b.eval_angles(30 * D, 0.3, 40 * D, 1.0) == 0)


@pytest.mark.parametrize("case", ["truncated", "trailing", "nan", "empty", "missing"])
def test_validation_errors(tmp_path, case):
    path = tmp_path / f"{case}.bin"
    good = np.zeros(48 * 6 * 48 * 6 * 3)
    if case == "truncated":
        path.write_bytes(good[:-1].tobytes())
    elif case == "trailing":
        path.write_bytes(good.tobytes() + b"\0")
    elif case == "nan":
        good[100] = np.nan
        path.write_bytes(good.tobytes())
    elif case == "empty":
        path.write_bytes(b"")
    with pytest.raises(BRDFFormatError) as err:
        read_utia(path)
    assert str(path) in str(err.value) and "expected" in str(err.value)


def test_failed_write_leaves_no_output(tmp_path):
    class Broken(BRDF):
        def eval(self, wi, wo):
            raise RuntimeError("boom")

    with pytest.raises(RuntimeError):
        write_utia(Broken(), tmp_path / "a.bin")
    values = np.ones((6, 48, 6, 48, 3))
    values[0, 0, 0, 0, 0] = np.nan
    with pytest.raises(BRDFFormatError):
        write_utia((values, np.ones(values.shape[:-1], bool)), tmp_path / "b.bin")
    assert os.listdir(tmp_path) == []


def test_measured_domain_is_the_grid(utia_file):
    """Beyond θ = 75° the UTIA value is held, not measured: the domain is θi, θo ≤ 75°."""
    b = read_utia(utia_file)
    assert b.measured_domain.startswith("θi, θo ≤ 75°")

    def d(deg, phi=0.0):
        t, p = np.radians(deg), np.radians(phi)
        return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])

    assert b.measured(d(75.0), d(0.0)) and b.measured(d(40.0), d(75.0, 120.0))
    assert not b.measured(d(75.5), d(10.0)) and not b.measured(d(10.0), d(80.0, 30.0))
    assert not b.measured(d(10.0), np.array([0.0, 0.0, -1.0]))
