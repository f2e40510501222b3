"""Mitsuba tensor files: format against an independent byte-level packing, round trips,
the real RGL files, and one clear BRDFFormatError for every kind of damage."""

from __future__ import annotations

import importlib.util
import struct
import sys
from pathlib import Path

import numpy as np
import pytest

from brdffit.errors import BRDFFormatError
from brdffit.io.tensorfile import (is_tensor_file, read_tensor_file, read_tensor_header,
                                   write_tensor_file)
from tests.conftest import shared_data_path


def _pack_by_hand(fields: list[tuple[str, int, np.ndarray]], pad_to: int = 8) -> bytes:
    """Independent packing straight from the spec (magic, version, count, entries, data)."""
    head = b"tensor_file\x00" + bytes([1, 0]) + struct.pack("<I", len(fields))
    entries_len = sum(2 + len(n.encode()) + 2 + 1 + 8 + 8 * a.ndim for n, _, a in fields)
    pos = len(head) + entries_len
    offsets, blobs = [], []
    for _, _, a in fields:
        pos = -(-pos // pad_to) * pad_to
        offsets.append(pos)
        blobs.append(a.tobytes())
        pos += a.nbytes
    body = bytearray(pos)
    entries = b""
    for (name, code, a), off in zip(fields, offsets):
        nb = name.encode()
        entries += struct.pack("<H", len(nb)) + nb + struct.pack("<HBQ", a.ndim, code, off)
        entries += b"".join(struct.pack("<Q", s) for s in a.shape)
    body[:len(head) + len(entries)] = head + entries
    for off, blob in zip(offsets, blobs):
        body[off:off + len(blob)] = blob
    return bytes(body)


SAMPLE = [
    ("theta_i", 10, np.linspace(0, 1.5, 5, dtype="<f4")),
    ("grid", 11, np.arange(24, dtype="<f8").reshape(2, 3, 4) * 0.5),
    ("flags", 1, np.array([1, 0, 255], dtype="u1")),
    ("counts", 5, np.array([[7, 8], [9, 10]], dtype="<u4")),
    ("deltas", 8, np.array([-3, 2**40], dtype="<i8")),
    ("half", 9, np.array([0.5, -2.0], dtype="<f2")),
    ("description", 1, np.frombuffer("Wei\u00df paper".encode(), dtype="u1")),
]


def test_reader_decodes_hand_packed_file(tmp_path):
    p = tmp_path / "hand.bsdf"
    p.write_bytes(_pack_by_hand(SAMPLE))
    got = read_tensor_file(p)
    assert list(got) == [n for n, _, _ in SAMPLE]
    for name, _, arr in SAMPLE:
        if name == "description":
            assert got[name] == "Wei\u00df paper"
        else:
            assert got[name].dtype == arr.dtype.newbyteorder("=")
            np.testing.assert_array_equal(got[name], arr)
    hdr = read_tensor_header(p)
    assert hdr["grid"].shape == (2, 3, 4) and hdr["grid"].dtype_code == 11
    assert is_tensor_file(p) and not is_tensor_file(tmp_path / "missing")


def test_writer_matches_hand_packing_and_round_trips(tmp_path):
    p = tmp_path / "ours.bsdf"
    write_tensor_file(p, {n: (a.tobytes().decode() if n == "description" else a)
                          for n, _, a in SAMPLE})
    assert p.read_bytes() == _pack_by_hand(SAMPLE)
    # bool -> uint8, big-endian input -> little-endian output, 0-d arrays
    q = tmp_path / "misc.bsdf"
    write_tensor_file(q, {"mask": np.array([True, False]), "be": np.array([1.5, 2.5], ">f8"),
                          "scalar": np.float32(3.0)})
    got = read_tensor_file(q)
    np.testing.assert_array_equal(got["mask"], [1, 0])
    assert got["mask"].dtype == np.uint8
    np.testing.assert_array_equal(got["be"], [1.5, 2.5])
    assert got["scalar"].shape == () and got["scalar"] == 3.0


def test_writer_is_readable_by_mitsubas_own_python_reader(tmp_path):
    # located on sys.path without importing mitsuba (which may already be imported as a variant)
    hits = [Path(d) / "mitsuba" / "python" / "tensor_io.py" for d in sys.path if d]
    hits = [h for h in hits if h.is_file()]
    if not hits:
        pytest.skip("mitsuba (and its python/tensor_io.py) not installed")
    mod_path = hits[0]
    s = importlib.util.spec_from_file_location("_mi_tensor_io", mod_path)
    tio = importlib.util.module_from_spec(s)
    s.loader.exec_module(tio)  # plain-Python module (struct, os, numpy)
    p = tmp_path / "t.bsdf"
    data = {"a": np.arange(6, dtype=np.float32).reshape(2, 3), "b": np.array([3], np.uint8)}
    write_tensor_file(p, data)
    theirs = tio.read(str(p))
    for k, v in data.items():
        np.testing.assert_array_equal(theirs[k], v)
    q = tmp_path / "mi.bsdf"
    tio.write(str(q), **data)
    assert q.read_bytes() == p.read_bytes()


def test_real_rgl_file_rewrites_byte_identically(tmp_path):
    src = shared_data_path("rgl", "paper_white_rgb.bsdf")
    fields = read_tensor_file(src)
    assert isinstance(fields["description"], str) and fields["description"]
    assert fields["vndf"].dtype == np.float32 and fields["vndf"].ndim == 4
    out = write_tensor_file(tmp_path / "copy.bsdf", fields)
    assert out.read_bytes() == src.read_bytes()


def test_atomic_write_leaves_no_partial_file(tmp_path):
    p = tmp_path / "x.bsdf"
    write_tensor_file(p, {"a": np.ones(3, np.float32)})
    before = p.read_bytes()
    with pytest.raises(BRDFFormatError, match="finite"):
        write_tensor_file(p, {"a": np.array([1.0, np.nan], np.float32)})
    with pytest.raises(BRDFFormatError, match="dtype"):
        write_tensor_file(p, {"a": np.array([1 + 2j])})
    assert p.read_bytes() == before
    assert sorted(x.name for x in tmp_path.iterdir()) == ["x.bsdf"]


# ----------------------------------------------------------------------------- damage
def _good() -> bytes:
    return _pack_by_hand([("a", 10, np.arange(6, dtype="<f4").reshape(2, 3)),
                          ("description", 1, np.frombuffer(b"ok", "u1"))])


def _expect(tmp_path, data: bytes, match: str):
    p = tmp_path / "bad.bsdf"
    p.write_bytes(data)
    with pytest.raises(BRDFFormatError, match=match) as exc:
        read_tensor_file(p)
    assert str(p) in str(exc.value)
    return exc.value


def test_every_truncation_is_a_format_error(tmp_path):
    good = _good()
    p = tmp_path / "cut.bsdf"
    for n in range(len(good)):
        p.write_bytes(good[:n])
        with pytest.raises(BRDFFormatError):
            read_tensor_file(p)


def test_specific_damage_messages(tmp_path):
    good = bytearray(_good())
    _expect(tmp_path, b"", "at least 18 bytes")
    _expect(tmp_path, b"TENSOR_FILE\x00" + bytes(good[12:]), "magic")
    bad = good.copy(); bad[12] = 2
    _expect(tmp_path, bytes(bad), r"version \(1, 0\), found \(2, 0\)")
    bad = good.copy(); struct.pack_into("<I", bad, 14, 10**9)
    _expect(tmp_path, bytes(bad), "field count")
    bad = good.copy(); struct.pack_into("<I", bad, 14, 0)
    _expect(tmp_path, bytes(bad), "at least one field")
    # entry of field "a": name length at 18, name at 20, ndim at 21, dtype at 23, offset at 24
    bad = good.copy(); bad[23] = 0
    _expect(tmp_path, bytes(bad), "dtype code.*found 0")
    bad = good.copy(); bad[23] = 12
    _expect(tmp_path, bytes(bad), "dtype code.*found 12")
    bad = good.copy(); struct.pack_into("<Q", bad, 24, len(good) - 4)
    _expect(tmp_path, bytes(bad), "data of field 'a'")
    bad = good.copy(); struct.pack_into("<Q", bad, 24, 2**64 - 8)
    _expect(tmp_path, bytes(bad), "data of field 'a'")
    bad = good.copy(); struct.pack_into("<Q", bad, 32, 2**62)  # shape[0] absurd
    _expect(tmp_path, bytes(bad), "data of field 'a'")
    bad = good.copy(); struct.pack_into("<H", bad, 21, 40000)
    _expect(tmp_path, bytes(bad), "dimensions")
    bad = good.copy(); bad[20:21] = b"\xff"
    _expect(tmp_path, bytes(bad), "UTF-8 name")


def test_nan_duplicate_and_text_errors(tmp_path):
    e = _expect(tmp_path, _pack_by_hand([("v", 10, np.array([0, np.nan, np.inf], "<f4"))]),
                "finite.*'v'.*2 NaN/inf")
    assert e.path.endswith("bad.bsdf")
    _expect(tmp_path, _pack_by_hand([("v", 1, np.zeros(2, "u1")), ("v", 1, np.zeros(1, "u1"))]),
            "unique")
    _expect(tmp_path, _pack_by_hand([("description", 1, np.frombuffer(b"\xff\xfe", "u1"))]),
            "UTF-8 text")
    # NaN allowed when asked
    p = tmp_path / "nan.bsdf"
    p.write_bytes(_pack_by_hand([("v", 11, np.array([np.nan], "<f8"))]))
    assert np.isnan(read_tensor_file(p, check_finite=False)["v"][0])


def test_random_garbage_never_escapes_as_another_exception(tmp_path):
    rng = np.random.default_rng(7)
    good = np.frombuffer(_good(), np.uint8)
    p = tmp_path / "fuzz.bsdf"
    for k in range(300):
        data = good.copy()
        if k % 3 == 0:   # garbage after a valid magic/version
            data[14:] = rng.integers(0, 256, data.size - 14, dtype=np.uint8)
        else:            # a few flipped header bytes
            idx = rng.integers(12, 60, size=rng.integers(1, 4))
            data[idx] = rng.integers(0, 256, idx.size, dtype=np.uint8)
        p.write_bytes(data.tobytes())
        try:
            out = read_tensor_file(p)
        except BRDFFormatError:
            continue
        assert isinstance(out, dict) and out
    with pytest.raises(BRDFFormatError, match="does-not-exist.bsdf: expected a tensor file, found no such"):
        read_tensor_file(tmp_path / "does-not-exist.bsdf")
