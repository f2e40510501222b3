"""brdffit.io.load: dispatch on extension and content, zip:material specs, errors, exports."""

from __future__ import annotations

import importlib
import io
import shutil

import h5py
import numpy as np
import pytest

import brdffit
import brdffit.io as bio
import brdffit.loading
from brdffit.brdf import IsotropicBRDF
from brdffit.errors import BRDFFormatError
from brdffit.io.fitfile import SerializableModel, save_fit
from tests.conftest import shared_data_path


class _ConstModel(SerializableModel, IsotropicBRDF):
    """A minimal saveable model (only for the .npz dispatch test)."""

    fit_kind = "test-io-load-constant"

    def __init__(self, rgb):
        self.rgb = np.asarray(rgb, float)
        self.name = "const"

    def eval_hd(self, theta_h, theta_d, phi_d):
        shape = np.broadcast_shapes(np.shape(theta_h), np.shape(theta_d), np.shape(phi_d))
        return np.broadcast_to(self.rgb, shape + (3,)).copy()

    def to_state(self):
        return {}, {"rgb": self.rgb}

    @classmethod
    def from_state(cls, params, arrays):
        return cls(arrays["rgb"])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("load")
    rng = np.random.default_rng(0)
    values = rng.random((90, 90, 180, 3))
    bio.write_merl(values, d / "m.binary")
    utia = rng.random((6, 48, 6, 48, 3))
    bio.write_utia((utia, np.ones(utia.shape[:-1], bool)), d / "u.bin")
    with h5py.File(d / "n.h5", "w") as f:
        for k, (a, b) in enumerate([(6, 21), (21, 21), (21, 3)]):
            name = f"dense_{k + 1}"
            f.create_dataset(f"{name}/{name}/kernel:0", data=rng.normal(0, 0.3, (a, b)))
            f.create_dataset(f"{name}/{name}/bias:0", data=np.zeros(b))
    save_fit(_ConstModel([0.1, 0.2, 0.3]), d / "f.npz")
    return d, values


def test_dispatch_by_extension(files):
    d, values = files
    m = bio.load(d / "m.binary")
    assert type(m).__name__ == "MERLBRDF"
    np.testing.assert_allclose(m.merl_table()[0], values, rtol=1e-15)
    assert bio.load(str(d / "m.binary"), interpolation="nearest").interpolation == "nearest"
    assert type(bio.load(d / "u.bin")).__name__ == "UTIABRDF"
    assert type(bio.load(d / "n.h5")).__name__ == "NBRDF"
    fit = bio.load(d / "f.npz")
    assert isinstance(fit, _ConstModel)
    np.testing.assert_array_equal(fit.eval_hd(0.1, 0.2, 0.3), [0.1, 0.2, 0.3])


def test_dispatch_by_content(files, tmp_path):
    d, _ = files
    for src, kind in (("m.binary", "MERLBRDF"), ("u.bin", "UTIABRDF"), ("n.h5", "NBRDF")):
        target = tmp_path / (src.split(".")[0] + ".data")
        shutil.copy(d / src, target)
        assert type(bio.load(target)).__name__ == kind
    (tmp_path / "junk.data").write_bytes(b"hello world, not a BRDF")
    with pytest.raises(BRDFFormatError, match="junk.data.*unrecognised"):
        bio.load(tmp_path / "junk.data")


def test_errors_name_the_spec(tmp_path):
    with pytest.raises(BRDFFormatError, match="nowhere.binary.*no such file"):
        bio.load(tmp_path / "nowhere.binary")
    with pytest.raises(BRDFFormatError, match="missing.zip"):
        bio.load(str(tmp_path / "missing.zip") + ":gold")
    with pytest.raises(BRDFFormatError, match="directory"):
        bio.load(tmp_path)


def _make_zip(path):
    import zipfile

    rng = np.random.default_rng(1)
    buf = io.BytesIO()
    with h5py.File(buf, "w") as f:
        for k, (a, b) in enumerate([(6, 21), (21, 21), (21, 3)]):
            name = f"dense_{k + 1}"
            f.create_dataset(f"{name}/{name}/kernel:0", data=rng.normal(0, 0.3, (a, b)))
            f.create_dataset(f"{name}/{name}/bias:0", data=np.zeros(b))
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("mine/red-paint.h5", buf.getvalue())


def test_zip_specs_relative_and_absolute(tmp_path, monkeypatch):
    _make_zip(tmp_path / "coll.zip")
    a = bio.load(f"{tmp_path / 'coll.zip'}:red-paint")
    monkeypatch.chdir(tmp_path)
    b = bio.load("coll.zip:red-paint")
    assert a.name == b.name == "red-paint"
    np.testing.assert_array_equal(a.eval_hd(0.2, 0.3, 0.4), b.eval_hd(0.2, 0.3, 0.4))
    with pytest.raises(BRDFFormatError, match="1 materials: red-paint"):
        bio.load("coll.zip")
    with pytest.raises(BRDFFormatError, match="close matches: red-paint"):
        bio.load("coll.zip:red-pain")
    # BRDFFIT_DATA makes bare archive names resolvable from anywhere
    other = tmp_path / "elsewhere"
    other.mkdir()
    monkeypatch.chdir(other)
    monkeypatch.setenv("BRDFFIT_DATA", str(tmp_path))
    assert bio.load("coll.zip:red-paint").name == "red-paint"


def test_shared_collection_by_bare_name(tmp_path, monkeypatch):
    zpath = shared_data_path("nbrdf", "merl_nbrdf.zip")
    monkeypatch.chdir(tmp_path)
    b = bio.load("merl_nbrdf.zip:gold-metallic-paint")
    assert b.name == "gold-metallic-paint"
    monkeypatch.chdir(zpath.parent.parent)
    assert bio.load("nbrdf/merl_nbrdf.zip:gold-metallic-paint").name == "gold-metallic-paint"


def test_rgl_and_synthetic():
    path = shared_data_path("rgl", "paper_white_rgb.bsdf")
    try:
        import brdffit.io.rgl  # noqa: F401
    except ImportError:
        pytest.skip("brdffit.io.rgl not available yet")
    b = bio.load(path)
    assert b.isotropic and np.all(b.eval([0, 0, 1.0], [0.3, 0, 0.95393920141]) > 0)
    try:  # import_module: `brdffit.synthetic` the attribute may be the function, not the module
        syn = importlib.import_module("brdffit.synthetic")
    except ImportError:
        pytest.skip("brdffit.synthetic not available yet")
    for name in syn.list_synthetic()[:2]:
        b = brdffit.load(f"synthetic:{name}")
        assert b.eval([0, 0, 1.0], [0, 0, 1.0]).shape == (3,)
    with pytest.raises(Exception, match="no-such-material"):
        brdffit.load("synthetic:no-such-material")
    # the readers read files; the synthetic materials (a layer above them) go by brdffit.load
    with pytest.raises(BRDFFormatError, match="brdffit.load"):
        bio.load(f"synthetic:{syn.list_synthetic()[0]}")


def test_public_exports():
    for name in ("load", "read_merl", "write_merl", "resample_to_merl", "read_nbrdf",
                 "read_utia", "write_utia"):
        assert callable(getattr(bio, name))
    assert brdffit.load is brdffit.loading.load
    assert brdffit.write_merl is bio.write_merl
    with pytest.raises(AttributeError):
        bio.not_a_reader  # noqa: B018
