"""Neural-BRDF networks: evaluation against a direct float64 forward pass, files, collections."""

from __future__ import annotations

import io
import json
import zipfile

import h5py
import numpy as np
import pytest

from brdffit.errors import BRDFFormatError
from brdffit.geometry import half_diff_to_io
from brdffit.io.nbrdf import NBRDF, list_materials, read_nbrdf, read_nbrdf_collection
from tests.conftest import shared_data_path

SIZES = [(6, 21), (21, 21), (21, 3)]


def _random_weights(seed=0):
    rng = np.random.default_rng(seed)
    return [(rng.normal(0, 0.6, s).astype(np.float32), rng.normal(0, 0.3, s[1]).astype(np.float32))
            for s in SIZES]


def _write_h5(target, weights):
    """Keras 2.2 layout: group dense_k/dense_k with kernel:0 and bias:0 (+ attrs)."""
    with h5py.File(target, "w") as f:
        names = [f"dense_{k + 1}" for k in range(len(weights))] + ["lambda_1"]
        f.attrs["layer_names"] = np.array([n.encode() for n in names])
        for name, (kern, bias) in zip(names, weights):
            g = f.create_group(name)
            g.attrs["weight_names"] = np.array([f"{name}/kernel:0".encode(),
                                                f"{name}/bias:0".encode()])
            g.create_dataset(f"{name}/kernel:0", data=kern)
            g.create_dataset(f"{name}/bias:0", data=bias)
        f.create_group("lambda_1").attrs["weight_names"] = np.array([], dtype=np.float64)


def _keras_json(acts=("relu", "relu", "linear")):
    layers = [{"class_name": "Dense", "config": {"name": f"dense_{k + 1}", "units": u,
                                                 "activation": a}}
              for k, (a, u) in enumerate(zip(acts, (21, 21, 3)))]
    layers.append({"class_name": "Lambda", "config": {"name": "lambda_1"}})
    return json.dumps({"class_name": "Sequential", "config": {"layers": layers}})


def _reference(weights, th, td, pd):
    """Direct float64 forward pass from the format description (data README)."""
    x = np.stack([np.sin(th), np.zeros_like(th), np.cos(th),
                  np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)], axis=-1)
    h = x
    for k, (kern, bias) in enumerate(weights):
        h = h @ kern.astype(np.float64) + bias.astype(np.float64)
        if k < len(weights) - 1:
            h = np.maximum(h, 0.0)
    return np.maximum(np.exp(h) - 1.0, 0.0)


def _angles(n, seed=1):
    rng = np.random.default_rng(seed)
    return rng.random(n) * np.pi / 2, rng.random(n) * np.pi / 2, rng.random(n) * 2 * np.pi


def test_matches_float64_reference(tmp_path):
    w = _random_weights()
    _write_h5(tmp_path / "m.h5", w)
    (tmp_path / "m.json").write_text(_keras_json())
    th, td, pd = _angles(20000)
    ref = _reference(w, th, td, pd)
    assert (ref == 0).mean() > 0.05 and (ref > 0).mean() > 0.05  # the clamp is exercised
    b64 = read_nbrdf(tmp_path / "m.h5", precision="float64")
    np.testing.assert_allclose(b64.eval_hd(th, td, pd), ref, rtol=1e-12, atol=1e-14)
    b32 = read_nbrdf(tmp_path / "m.h5")
    f32 = b32.eval_hd(th, td, pd)
    assert np.all(f32 >= 0)
    np.testing.assert_allclose(f32, ref, rtol=2e-5, atol=2e-6)
    # eval(wi, wo) goes through the Rusinkiewicz conversion
    wi, wo = half_diff_to_io(th, 0.7, td, pd)
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    assert 0.2 < above.mean() < 0.9
    got = b64.eval(wi, wo)
    np.testing.assert_allclose(got[above], ref[above], rtol=1e-8, atol=1e-10)
    assert np.all(got[~above] == 0)
    assert b32.name == "m" and b32.isotropic and b32.n_parameters == 6 * 21 + 21 + 21 * 21 + 21 + 66


def test_sidecar_activations_are_used(tmp_path):
    w = _random_weights(3)
    _write_h5(tmp_path / "lin.h5", w)
    (tmp_path / "lin.json").write_text(_keras_json(("linear", "relu", "linear")))
    th, td, pd = _angles(2000)
    b = read_nbrdf(tmp_path / "lin.h5", precision="float64")
    x = np.stack([np.sin(th), 0 * th, np.cos(th), np.sin(td) * np.cos(pd),
                  np.sin(td) * np.sin(pd), np.cos(td)], -1)
    h = x @ w[0][0] + w[0][1]
    h = np.maximum(h @ w[1][0] + w[1][1], 0) @ w[2][0] + w[2][1]
    np.testing.assert_allclose(b.eval_hd(th, td, pd), np.maximum(np.expm1(h), 0), rtol=1e-10)


@pytest.mark.parametrize("case", ["garbage", "activation", "layer_count", "nan", "shape",
                                  "bad_json", "missing"])
def test_validation_errors(tmp_path, case):
    path = tmp_path / f"{case}.h5"
    w = _random_weights()
    if case == "garbage":
        path.write_bytes(b"\x89HDF not really" * 10)
    elif case == "missing":
        path = tmp_path / "absent.h5"
    else:
        if case == "nan":
            w[1][0][3, 4] = np.nan
        if case == "shape":
            w[1] = (w[1][0][:, :5], w[1][1][:5])
        _write_h5(path, w)
        js = {"activation": _keras_json(("relu", "tanh", "linear")),
              "layer_count": _keras_json(("relu", "linear")).replace('"units": 21, "activation": '
                                                                    '"linear"', '"units": 3, "a'
                                                                    'ctivation": "linear"'),
              "bad_json": "{not json"}.get(case)
        if js is not None:
            path.with_suffix(".json").write_text(js)
    with pytest.raises(BRDFFormatError) as err:
        read_nbrdf(path)
    assert str(path.with_suffix(".json") if case in ("bad_json",) else path) in str(err.value)


def test_collection_in_memory(tmp_path):
    zpath = tmp_path / "coll.zip"
    weights = {"alpha-paint": _random_weights(1), "beta-metal": _random_weights(2)}
    with zipfile.ZipFile(zpath, "w") as zf:
        for name, w in weights.items():
            buf = io.BytesIO()
            _write_h5(buf, w)
            zf.writestr(f"coll/{name}.h5", buf.getvalue())
            zf.writestr(f"coll/{name}.json", _keras_json())
    assert list_materials(zpath) == ["alpha-paint", "beta-metal"]
    th, td, pd = _angles(500)
    for spec in ("beta-metal", "coll/beta-metal.h5", "beta-metal.h5"):
        b = read_nbrdf_collection(zpath, spec, precision="float64")
        np.testing.assert_allclose(b.eval_hd(th, td, pd), _reference(weights["beta-metal"], th, td, pd),
                                   rtol=1e-12, atol=1e-14)
    assert b.source == f"{zpath}:beta-metal"
    with pytest.raises(BRDFFormatError, match="close matches: beta-metal"):
        read_nbrdf_collection(zpath, "beta-metl")
    (tmp_path / "bad.zip").write_bytes(b"PK not a zip")
    with pytest.raises(BRDFFormatError, match="bad.zip"):
        list_materials(tmp_path / "bad.zip")


def test_constructor_checks_architecture():
    w = _random_weights()
    with pytest.raises(BRDFFormatError, match="3 outputs"):
        NBRDF([(w[0][0], w[0][1], "relu"), (w[1][0], w[1][1], "relu")])
    with pytest.raises(ValueError, match="precision"):
        NBRDF([(k, b, a) for (k, b), a in zip(w, ("relu", "relu", "linear"))], precision="half")


# -- real networks (../shared/data) -------------------------------------------------------
def test_real_collection_against_independent_weights():
    zpath = shared_data_path("nbrdf", "merl_nbrdf.zip")
    names = list_materials(zpath)
    assert len(names) == 100 and "gold-metallic-paint" in names
    # the zip also ships blue-acrylic's weights as .npy files: an independent weight source
    with zipfile.ZipFile(zpath) as zf:
        npy = {k: np.load(io.BytesIO(zf.read(f"merl_nbrdf/npy/blue-acrylic_{k}.npy")))
               for k in ("fc1", "b1", "fc2", "b2", "fc3", "b3")}
    w = [(npy["fc1"], npy["b1"]), (npy["fc2"], npy["b2"]), (npy["fc3"], npy["b3"])]
    th, td, pd = _angles(50000, seed=9)
    ref = _reference(w, th, td, pd)
    got = read_nbrdf_collection(zpath, "blue-acrylic").eval_hd(th, td, pd)
    big = ref > 1e-3
    assert np.max(np.abs(got - ref)[big] / ref[big]) < 1e-3  # float32 vs float64
    assert np.max(np.abs(got - ref)[~big]) < 1e-6


def test_real_gold_metallic_paint_is_plausible():
    zpath = shared_data_path("nbrdf", "merl_nbrdf.zip")
    b = read_nbrdf_collection(zpath, "gold-metallic-paint")
    with pytest.raises(BRDFFormatError, match="gold-metallic-paint"):
        read_nbrdf_collection(zpath, "gold-metalic-paint")
    th = np.linspace(0, 1.2, 50)
    f = b.eval_hd(th, 0.2, np.pi / 2)
    assert np.all(f >= 0)
    assert f[0, 0] > 5 * f[-1, 0]  # specular peak at θh = 0
    assert f[0, 0] > f[0, 2]       # gold: red above blue
    alb = b.albedo(np.radians([0.0, 45.0]), n_samples=16384)
    assert np.all((alb > 0.01) & (alb < 1.0))


# -- chunked/filtered weights: decoded by brdffit (capped), must equal what h5py reads -------
def test_filtered_chunked_weights_decode_like_hdf5(tmp_path):
    """gzip + shuffle + fletcher32, chunks with partial edges, big-endian / float16 / float64
    types and never-written chunks (fill value): the capped chunk decoder of
    ``brdffit.io._limits`` must give exactly h5py's values."""
    w = _random_weights(7)
    path = tmp_path / "chunked.h5"
    specs = {
        "dense_1/kernel:0": dict(dtype=">f4", chunks=(4, 8), compression="gzip", shuffle=True,
                                 fletcher32=True),
        "dense_1/bias:0": dict(dtype="<f2", chunks=(5,), compression="gzip"),
        "dense_2/kernel:0": dict(dtype="<f8", chunks=(8, 8), shuffle=True, fillvalue=0.25),
        "dense_2/bias:0": dict(dtype=">f8", chunks=(21,), fletcher32=True),
        "dense_3/kernel:0": dict(dtype="<f4", chunks=(21, 3), compression="gzip",
                                 compression_opts=9),
    }
    with h5py.File(path, "w") as f:
        for k, (kern, bias) in enumerate(w):
            name = f"dense_{k + 1}"
            for wname, data in ((f"{name}/kernel:0", kern), (f"{name}/bias:0", bias)):
                opts = specs.get(wname, {})
                ds = f.create_dataset(f"{name}/{wname}", shape=data.shape,
                                      dtype=opts.pop("dtype", data.dtype), **opts)
                if wname == "dense_2/kernel:0":
                    ds[:16, :8] = data[:16, :8]  # the other chunks are never written
                else:
                    ds[...] = data
        expected = [(f[f"dense_{k}/dense_{k}/kernel:0"][()].astype(np.float64),
                     f[f"dense_{k}/dense_{k}/bias:0"][()].astype(np.float64)) for k in (1, 2, 3)]
    assert np.count_nonzero(expected[1][0] == 0.25) == 21 * 21 - 16 * 8
    got = read_nbrdf(path, precision="float64")
    for (k, b, _), (ek, eb) in zip(got.layers, expected):
        np.testing.assert_array_equal(k, ek)
        np.testing.assert_array_equal(b, eb)


def test_collection_member_names_windows_separators_and_unsafe_ones(tmp_path):
    """Backslashes separate folders (zips written on Windows); absolute, ``..`` and
    control-character names are never listed nor read."""
    from tests.support.malformed_readers import network_h5_bytes, write_collection

    w = _random_weights(5)
    net = network_h5_bytes(w)
    z = write_collection(tmp_path / "c.zip", [
        ("coll\\gold.h5", net), ("coll\\gold.json", _keras_json().encode()),
        ("../../evil.h5", net), ("/abs/root.h5", net), ("coll/bad\nname.h5", net),
        ("coll/...h5", net)])
    assert list_materials(z) == ["gold"]
    th, td, pd = _angles(300)
    got = read_nbrdf_collection(z, "gold", precision="float64").eval_hd(th, td, pd)
    np.testing.assert_allclose(got, _reference(w, th, td, pd), rtol=1e-12, atol=1e-14)
    for name in ("evil", "root", ".."):
        with pytest.raises(BRDFFormatError, match="unsafe member"):
            read_nbrdf_collection(z, name)
