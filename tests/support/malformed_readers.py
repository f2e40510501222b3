"""Generators of malformed measured-data files, one :class:`Case` per way a file can be bad.

For every reader of :mod:`brdffit.io` (MERL ``.binary``, Neural-BRDF ``.h5`` and ``.zip``
collections, RGL ``.bsdf``, UTIA ``.bin``) and for hostile load specs, :func:`cases` returns
cases of truncated, empty, wrong-magic, absurd/negative/overflowing dimensions, NaN/inf,
wrong endianness, compression bombs, lying headers, external storage and links, and hostile
names. Nothing is shipped: each case *writes* its bad file(s) into a folder on demand.

A :class:`Case` has

``name``
    unique id, ``<reader>-<problem>`` (e.g. ``"nbrdf-h5-external-storage"``);
``reader``
    ``"merl"``, ``"nbrdf-h5"``, ``"nbrdf-zip"``, ``"rgl"``, ``"utia"`` or ``"spec"``;
``make(folder) -> spec``
    writes the bad file(s) into ``folder`` (an existing, preferably empty directory) and
    returns the load spec to pass to :func:`brdffit.io.load` or to the CLI (an absolute path,
    ``/abs/collection.zip:material`` or ``synthetic:NAME``);
``file_name``
    what the one-line error must name (the file's name as printed: control characters are
    escaped as ``\\n``, ``\\x1b``...);
``mentions``
    lower-case substrings the error must also contain (what was expected / found);
``cli``
    ``True`` for the representative subset the test suite runs through the CLI.

Use (tests, ``bench/bench_robustness.py``)::

    from tests.support.hostile import run_limited
    from tests.support.malformed_readers import cases

    for case in cases():
        folder = Path(tempfile.mkdtemp())
        spec = case.make(folder)
        # in process: brdffit.io.load(spec) raises BRDFFormatError; case.check_message(str(err))
        out = folder / "out"
        outcome = run_limited(["fit", spec, "--model", "ggx", "-o", out / "x.npz"], cwd=folder)
        problems = outcome.problems(names=case.file_name, out_dir=out)   # [] when clean

``CASES`` is the same list as ``cases()``. Valid base files come from the project's own
writers (:func:`brdffit.io.write_merl`, :func:`brdffit.io.write_utia`,
:func:`brdffit.export.rgl.rgl_fields` + :func:`brdffit.io.tensorfile.write_tensor_file`) and,
for Neural-BRDF, from h5py writing the Keras 2 layout (:func:`write_network_h5`); they are
also used by the property-based tests (random byte flips and truncations).
"""

from __future__ import annotations

import dataclasses
import functools
import io
import json
import os
import struct
import zipfile
import zlib
from pathlib import Path
from typing import Callable

import numpy as np
from brdffit.export.rgl import rgl_fields
from brdffit.io import write_merl, write_utia
from brdffit.io.tensorfile import write_tensor_file
from brdffit.synthetic import synthetic

__all__ = ["Case", "cases", "CASES", "case_by_name", "valid_merl_bytes", "valid_utia_bytes",
           "valid_rgl_bytes", "write_network_h5", "network_h5_bytes", "keras_json",
           "write_collection", "random_weights", "deflate_bomb", "crashing_h5_bytes", "LAYER_SIZES"]

#: Layer sizes of the published Neural-BRDF networks (data README).
LAYER_SIZES = [(6, 21), (21, 21), (21, 3)]


@dataclasses.dataclass(frozen=True)
class Case:
    """One malformed input (see the module docstring)."""

    name: str
    reader: str
    make: Callable[[Path], str]
    file_name: str
    mentions: tuple[str, ...] = ()
    cli: bool = False
    doc: str = ""

    def check_message(self, message: str) -> list[str]:
        """What the error message lacks ([] when it names the file and every mention)."""
        missing = []
        if "\n" in message.strip():
            missing.append("message spans several lines")
        if self.file_name not in message:
            missing.append(f"does not name {self.file_name!r}")
        low = message.lower()
        missing += [f"does not mention {m!r}" for m in self.mentions if m not in low]
        return missing


_CASES: list[Case] = []


def _case(name: str, reader: str, file_name: str, *mentions: str, cli: bool = False):
    def register(fn):
        _CASES.append(Case(name, reader, fn, file_name, tuple(m.lower() for m in mentions),
                           cli, (fn.__doc__ or "").strip()))
        return fn
    return register


# -- valid base files -----------------------------------------------------------------------
@functools.lru_cache(maxsize=1)
def valid_merl_bytes() -> bytes:
    """A valid MERL ``.binary`` file (random positive table, 5 % invalid samples), written by
    :func:`brdffit.io.write_merl`."""
    import tempfile

    rng = np.random.default_rng(12)
    values = rng.random((90, 90, 180, 3)) * np.array([0.5, 0.4, 0.3])
    valid = rng.random((90, 90, 180)) > 0.05
    with tempfile.TemporaryDirectory() as d:
        return write_merl((values, valid), Path(d) / "v.binary").read_bytes()


@functools.lru_cache(maxsize=1)
def valid_utia_bytes() -> bytes:
    """A valid UTIA ``.bin`` file (random positive table), written by :func:`brdffit.io.write_utia`."""
    import tempfile

    rng = np.random.default_rng(13)
    values = rng.random((6, 48, 6, 48, 3))
    with tempfile.TemporaryDirectory() as d:
        return write_utia((values, np.ones(values.shape[:-1], bool)),
                          Path(d) / "v.bin").read_bytes()


@functools.lru_cache(maxsize=1)
def _rgl_fields() -> dict:
    return rgl_fields(synthetic("gold-ggx"), n_theta=4, n_ndf=16, vndf_res=8, rgb_res=8)


def _tensor_bytes(fields: dict) -> bytes:
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        return write_tensor_file(Path(d) / "v.bsdf", fields).read_bytes()


@functools.lru_cache(maxsize=1)
def valid_rgl_bytes() -> bytes:
    """A small valid RGL ``.bsdf`` file (5.9 kB): the RGL export of ``synthetic:gold-ggx`` at a
    low resolution (:func:`brdffit.export.rgl.rgl_fields`)."""
    return _tensor_bytes(_rgl_fields())


def random_weights(seed: int = 0, sizes=LAYER_SIZES, dtype=np.float32) -> list:
    """``[(kernel, bias), ...]`` of a random network with the published architecture."""
    rng = np.random.default_rng(seed)
    return [(rng.normal(0, 0.6, s).astype(dtype), rng.normal(0, 0.3, s[1]).astype(dtype))
            for s in sizes]


def write_network_h5(target, weights=None, *, dataset=None, layer_names=None) -> None:
    """Write a Neural-BRDF network in the Keras 2.2 layout (``dense_k/dense_k/kernel:0``...).

    ``target`` is a path or a binary file object. ``dataset(group, name, data)``, when given,
    creates each weight dataset instead of ``group.create_dataset(name, data=data)`` (to
    plant a hostile one); ``layer_names`` overrides the root attribute.
    """
    import h5py

    weights = random_weights() if weights is None else weights
    names = [f"dense_{k + 1}" for k in range(len(weights))]
    with h5py.File(target, "w") as f:
        f.attrs["backend"] = b"tensorflow"
        f.attrs["keras_version"] = b"2.2.4"
        f.attrs["layer_names"] = np.array([n.encode() for n in
                                           (layer_names or names + ["lambda_1"])])
        for name, (kern, bias) in zip(names, weights):
            g = f.create_group(name)
            g.attrs["weight_names"] = np.array([f"{name}/kernel:0".encode(),
                                                f"{name}/bias:0".encode()])
            for wname, data in ((f"{name}/kernel:0", kern), (f"{name}/bias:0", bias)):
                if dataset is None:
                    g.create_dataset(wname, data=data)
                else:
                    dataset(g, wname, data)
        f.create_group("lambda_1").attrs["weight_names"] = np.array([], dtype=np.float64)


def network_h5_bytes(weights=None, **kwargs) -> bytes:
    """The bytes of :func:`write_network_h5`."""
    buf = io.BytesIO()
    write_network_h5(buf, weights, **kwargs)
    return buf.getvalue()


def keras_json(acts=("relu", "relu", "linear")) -> str:
    """A Keras ``Sequential`` model description (the ``.json`` sidecar)."""
    layers = [{"class_name": "Dense", "config": {"name": f"dense_{k + 1}", "units": u,
                                                 "activation": a}}
              for k, (a, u) in enumerate(zip(acts, (21, 21, 3)))]
    layers.append({"class_name": "Lambda", "config": {"name": "lambda_1"}})
    return json.dumps({"class_name": "Sequential", "config": {"layers": layers}})


def write_collection(path, members, *, compression=zipfile.ZIP_DEFLATED) -> Path:
    """Write a zip of ``members`` (``[(name, bytes), ...]``, duplicates allowed)."""
    import warnings

    path = Path(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "Duplicate name" is what some cases want
        with zipfile.ZipFile(path, "w", compression) as zf:
            for name, data in members:
                zf.writestr(zipfile.ZipInfo(name, (2020, 1, 1, 0, 0, 0)), data,
                            compress_type=compression)
    return path


def _good_members(prefix="coll", names=("gold", "blue")) -> list:
    out = []
    for k, n in enumerate(names):
        out += [(f"{prefix}/{n}.h5", network_h5_bytes(random_weights(k))),
                (f"{prefix}/{n}.json", keras_json().encode())]
    return out


def deflate_bomb(n_bytes: int, *, zlib_wrapper: bool = False) -> bytes:
    """A valid deflate stream inflating to ``n_bytes`` zeros (~1/1000 of that compressed),
    built in milliseconds by repeating a fully flushed 1 MiB segment. With ``zlib_wrapper``
    it has the zlib header and Adler-32 trailer (HDF5's gzip filter), else it is raw (zip)."""
    co = zlib.compressobj(9, zlib.DEFLATED, -15)
    seg = co.compress(bytes(1 << 20)) + co.flush(zlib.Z_FULL_FLUSH)
    n_seg, rest = divmod(n_bytes, 1 << 20)
    tail = zlib.compressobj(9, zlib.DEFLATED, -15)
    body = seg * n_seg + tail.compress(bytes(rest)) + tail.flush()
    if not zlib_wrapper:
        return body
    adler = ((n_bytes % 65521) << 16) | 1  # Adler-32 of n zero bytes
    return b"\x78\xda" + body + struct.pack(">I", adler)


def _patch_central_sizes(path: Path, member: str, *, file_size=None, crc=None,
                         compress_size=None) -> None:
    """Rewrite the central-directory sizes/CRC of ``member`` (a lying header)."""
    data = bytearray(path.read_bytes())
    key = member.encode()
    pos = 0
    while True:
        pos = data.find(b"PK\x01\x02", pos)
        if pos < 0:
            raise ValueError(f"member {member!r} not found")
        n = struct.unpack_from("<H", data, pos + 28)[0]
        if bytes(data[pos + 46:pos + 46 + n]) == key:
            break
        pos += 4
    if crc is not None:
        struct.pack_into("<I", data, pos + 16, crc)
    if compress_size is not None:
        struct.pack_into("<I", data, pos + 20, compress_size)
    if file_size is not None:
        struct.pack_into("<I", data, pos + 24, file_size)
    path.write_bytes(bytes(data))


def _raw_member_zip(path: Path, members: list, raw: dict) -> Path:
    """A zip whose members in ``raw`` (``name -> (deflate bytes, declared size, crc)``) hold
    the given compressed stream verbatim (written with :mod:`zipfile`, then patched)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        for name, data in members:
            if name in raw:
                stream, _, _ = raw[name]
                zf.writestr(zipfile.ZipInfo(name, (2020, 1, 1, 0, 0, 0)), stream)
            else:
                zf.writestr(zipfile.ZipInfo(name, (2020, 1, 1, 0, 0, 0)), data,
                            compress_type=zipfile.ZIP_DEFLATED)
    data = bytearray(buf.getvalue())
    for name, (stream, size, crc) in raw.items():
        key = name.encode()
        for sig, off_method, off_crc, off_usize, off_name, off_nlen in (
                (b"PK\x03\x04", 8, 14, 22, 30, 26), (b"PK\x01\x02", 10, 16, 24, 46, 28)):
            pos = 0
            while True:
                pos = data.find(sig, pos)
                if pos < 0:
                    break
                n = struct.unpack_from("<H", data, pos + off_nlen)[0]
                if bytes(data[pos + off_name:pos + off_name + n]) == key:
                    struct.pack_into("<H", data, pos + off_method, zipfile.ZIP_DEFLATED)
                    struct.pack_into("<I", data, pos + off_crc, crc)
                    struct.pack_into("<I", data, pos + off_usize, size)
                    break
                pos += 4
    path.write_bytes(bytes(data))
    return path


def _flip_h5_dataset(make_dataset) -> Callable:
    """A ``dataset`` hook planting ``make_dataset(group, name, data)`` for dense_1's kernel."""
    def hook(group, name, data):
        if name == "dense_1/kernel:0":
            make_dataset(group, name, data)
        else:
            group.create_dataset(name, data=data)
    return hook


def _host_file(folder: Path) -> Path:
    """A stand-in for a host file an attacker wants to read (outside the BRDF file)."""
    p = folder / "host-secret.txt"
    p.write_bytes(b"SECRET " * 200)
    return p


# == MERL .binary ===========================================================================
_M = "bad.binary"


def _merl_with(folder: Path, data: bytes, name: str = _M) -> str:
    p = folder / name
    p.write_bytes(data)
    return str(p)


@_case("merl-empty", "merl", _M, "header", "0 bytes")
def _(folder):
    """An empty file."""
    return _merl_with(folder, b"")


@_case("merl-truncated-header", "merl", _M, "header", "truncated")
def _(folder):
    return _merl_with(folder, valid_merl_bytes()[:7])


@_case("merl-truncated-data", "merl", _M, "truncated")
def _(folder):
    """A valid file cut in the middle of the table."""
    return _merl_with(folder, valid_merl_bytes()[:5_000_000])


@_case("merl-trailing-bytes", "merl", _M, "trailing")
def _(folder):
    return _merl_with(folder, valid_merl_bytes() + b"\0" * 8)


@_case("merl-wrong-magic", "merl", _M, "expected header")
def _(folder):
    """A text file with the .binary extension."""
    return _merl_with(folder, b"this is not a MERL table at all\n" * 10)


@_case("merl-negative-dims", "merl", _M, "expected header", "absurd")
def _(folder):
    return _merl_with(folder, struct.pack("<3i", -90, 90, 180) + valid_merl_bytes()[12:])


@_case("merl-overflowing-dims", "merl", _M, "expected header", "absurd")
def _(folder):
    """Dimensions whose product overflows 64 bits (2^31-1 cubed times 3 channels)."""
    return _merl_with(folder, struct.pack("<3i", 2**31 - 1, 2**31 - 1, 2**31 - 1) + b"\0" * 64)


@_case("merl-zero-dims", "merl", _M, "expected header")
def _(folder):
    return _merl_with(folder, struct.pack("<3i", 0, 90, 180))


@_case("merl-other-dims", "merl", _M, "expected header", "unsupported")
def _(folder):
    """A plausible but unsupported grid with a matching amount of data."""
    return _merl_with(folder, struct.pack("<3i", 45, 90, 180) + bytes(45 * 90 * 180 * 24))


@_case("merl-big-endian", "merl", _M, "byte", cli=True)
def _(folder):
    """The whole file byte-swapped (header and values big-endian)."""
    raw = valid_merl_bytes()
    head = np.frombuffer(raw[:12], "<i4").byteswap().tobytes()
    body = np.frombuffer(raw[12:], "<f8").byteswap().tobytes()
    return _merl_with(folder, head + body)


@_case("merl-big-endian-values", "merl", _M, "byte")
def _(folder):
    """A little-endian header followed by big-endian values."""
    raw = valid_merl_bytes()
    return _merl_with(folder, raw[:12] + np.frombuffer(raw[12:], "<f8").byteswap().tobytes())


@_case("merl-nan", "merl", _M, "nan")
def _(folder):
    raw = bytearray(valid_merl_bytes())
    struct.pack_into("<d", raw, 12 + 8 * 1234, float("nan"))
    return _merl_with(folder, bytes(raw))


@_case("merl-inf", "merl", _M, "inf")
def _(folder):
    raw = bytearray(valid_merl_bytes())
    struct.pack_into("<d", raw, len(raw) - 8, float("-inf"))
    return _merl_with(folder, bytes(raw))


@_case("merl-huge-values", "merl", _M, "magnitude")
def _(folder):
    raw = bytearray(valid_merl_bytes())
    struct.pack_into("<d", raw, 12 + 8 * 99, 1e300)
    return _merl_with(folder, bytes(raw))


@_case("merl-directory", "merl", _M, "directory")
def _(folder):
    (folder / _M).mkdir()
    return str(folder / _M)


@_case("merl-fifo", "merl", "pipe.binary", "fifo", cli=True)
def _(folder):
    """A named pipe: opening it would block forever."""
    os.mkfifo(folder / "pipe.binary")
    return str(folder / "pipe.binary")


@_case("merl-symlink-to-device", "merl", _M, "character device")
def _(folder):
    """``bad.binary`` is a symbolic link to ``/dev/zero`` (endless zeros)."""
    os.symlink("/dev/zero", folder / _M)
    return str(folder / _M)


@_case("merl-newline-name", "merl", "bad\\nname.binary", "header", cli=True)
def _(folder):
    """A file name with a newline and an escape sequence must not break the one-line error."""
    return _merl_with(folder, b"", name="bad\nname.binary")


@_case("merl-escape-name", "merl", "\\x1b[2Jx.binary", "header")
def _(folder):
    return _merl_with(folder, b"xx", name="\x1b[2Jx.binary")


# == UTIA .bin ==============================================================================
_U = "bad.bin"


def _utia_with(folder: Path, data: bytes) -> str:
    p = folder / _U
    p.write_bytes(data)
    return str(p)


@_case("utia-empty", "utia", _U, "expected", "found 0")
def _(folder):
    return _utia_with(folder, b"")


@_case("utia-truncated", "utia", _U, "truncated")
def _(folder):
    return _utia_with(folder, valid_utia_bytes()[:-1])


@_case("utia-trailing-bytes", "utia", _U, "trailing")
def _(folder):
    return _utia_with(folder, valid_utia_bytes() + b"\0")


@_case("utia-nan", "utia", _U, "nan")
def _(folder):
    raw = bytearray(valid_utia_bytes())
    struct.pack_into("<d", raw, 8 * 777, float("nan"))
    return _utia_with(folder, bytes(raw))


@_case("utia-inf", "utia", _U, "inf")
def _(folder):
    raw = bytearray(valid_utia_bytes())
    struct.pack_into("<d", raw, 0, float("inf"))
    return _utia_with(folder, bytes(raw))


@_case("utia-big-endian", "utia", _U, "byte", cli=True)
def _(folder):
    """The whole table byte-swapped (UTIA files have no header to tell)."""
    return _utia_with(folder, np.frombuffer(valid_utia_bytes(), "<f8").byteswap().tobytes())


@_case("utia-subnormal", "utia", _U, "subnormal")
def _(folder):
    raw = np.frombuffer(valid_utia_bytes(), "<f8").copy()
    raw[5] = 5e-324
    return _utia_with(folder, raw.tobytes())


@_case("utia-directory", "utia", _U, "directory")
def _(folder):
    (folder / _U).mkdir()
    return str(folder / _U)


# == RGL .bsdf ==============================================================================
_R = "bad.bsdf"


def _rgl_with(folder: Path, data: bytes) -> str:
    p = folder / _R
    p.write_bytes(data)
    return str(p)


def _header_entries(data: bytes) -> dict:
    """``name -> (position of ndim, ndim)`` of a tensor-file header."""
    (count,) = struct.unpack_from("<I", data, 14)
    pos, out = 18, {}
    for _ in range(count):
        (n,) = struct.unpack_from("<H", data, pos)
        name = data[pos + 2:pos + 2 + n].decode()
        pos += 2 + n
        (ndim,) = struct.unpack_from("<H", data, pos)
        out[name] = (pos, ndim)
        pos += 11 + 8 * ndim
    return out


def _rgl_patched(field: str, *, shape=None, offset=None, code=None, ndim=None) -> bytes:
    """The valid RGL file with one header entry rewritten in place."""
    data = bytearray(valid_rgl_bytes())
    pos, nd = _header_entries(bytes(data))[field]
    if ndim is not None:
        struct.pack_into("<H", data, pos, ndim)
    if code is not None:
        struct.pack_into("<B", data, pos + 2, code)
    if offset is not None:
        struct.pack_into("<Q", data, pos + 3, offset)
    if shape is not None:
        assert len(shape) == nd
        struct.pack_into(f"<{nd}Q", data, pos + 11, *shape)
    return bytes(data)


@_case("rgl-empty", "rgl", _R, "expected", "0 bytes")
def _(folder):
    return _rgl_with(folder, b"")


@_case("rgl-truncated", "rgl", _R, "expected")
def _(folder):
    return _rgl_with(folder, valid_rgl_bytes()[:3000])


@_case("rgl-truncated-header", "rgl", _R, "truncated")
def _(folder):
    return _rgl_with(folder, valid_rgl_bytes()[:60])


@_case("rgl-wrong-magic", "rgl", _R, "magic")
def _(folder):
    return _rgl_with(folder, b"tensor_fiLe\0" + valid_rgl_bytes()[12:])


@_case("rgl-wrong-version", "rgl", _R, "version")
def _(folder):
    data = bytearray(valid_rgl_bytes())
    data[12] = 7
    return _rgl_with(folder, bytes(data))


@_case("rgl-huge-field-count", "rgl", _R, "field count")
def _(folder):
    data = bytearray(valid_rgl_bytes())
    struct.pack_into("<I", data, 14, 0xFFFFFFFF)
    return _rgl_with(folder, bytes(data))


@_case("rgl-big-endian-header", "rgl", _R, "field count")
def _(folder):
    """Header integers written big-endian (the field count becomes absurd)."""
    data = bytearray(valid_rgl_bytes())
    (count,) = struct.unpack_from("<I", data, 14)
    struct.pack_into(">I", data, 14, count)
    return _rgl_with(folder, bytes(data))


@_case("rgl-zero-dimension", "rgl", _R, "vndf", "shape", cli=True)
def _(folder):
    """A zero-size vndf whose other dimensions are absurd (used to say "array is too big")."""
    return _rgl_with(folder, _rgl_patched("vndf", shape=(0, 2**62, 2**62, 8)))


@_case("rgl-zero-size-table", "rgl", _R, "vndf")
def _(folder):
    return _rgl_with(folder, _rgl_patched("vndf", shape=(1, 4, 0, 8)))


@_case("rgl-24tib-field", "rgl", _R, "rgb", "inside the file")
def _(folder):
    """A field declaring 24 TiB of float32."""
    return _rgl_with(folder, _rgl_patched("rgb", shape=(1, 4, 3, 2**20, 2**19)))


@_case("rgl-overflowing-shape", "rgl", _R, "ndf", "inside the file")
def _(folder):
    """Dimensions whose product overflows 64 bits."""
    return _rgl_with(folder, _rgl_patched("ndf", shape=(2**63, 2**63)))


@_case("rgl-offset-beyond-eof", "rgl", _R, "luminance", "inside the file")
def _(folder):
    return _rgl_with(folder, _rgl_patched("luminance", offset=2**64 - 8))


@_case("rgl-overlapping-fields", "rgl", _R, "overlap")
def _(folder):
    """Two fields sharing the same bytes (memory amplification)."""
    h = _header_entries(valid_rgl_bytes())
    data = bytearray(valid_rgl_bytes())
    (rgb_offset,) = struct.unpack_from("<Q", data, h["rgb"][0] + 3)
    pos = h["luminance"][0]
    struct.pack_into("<Q", data, pos + 3, rgb_offset)
    return _rgl_with(folder, bytes(data))


@_case("rgl-bad-dtype-code", "rgl", _R, "dtype")
def _(folder):
    return _rgl_with(folder, _rgl_patched("ndf", code=200))


@_case("rgl-wrong-dtype", "rgl", _R, "ndf", "float32")
def _(folder):
    """ndf declared as int32 (same size, wrong type)."""
    return _rgl_with(folder, _rgl_patched("ndf", code=6))


@_case("rgl-huge-ndim", "rgl", _R, "dimensions")
def _(folder):
    return _rgl_with(folder, _rgl_patched("ndf", ndim=65535))


@_case("rgl-nan", "rgl", _R, "nan")
def _(folder):
    data = bytearray(valid_rgl_bytes())  # write_tensor_file refuses NaN: plant it afterwards
    h = _header_entries(bytes(data))
    (off,) = struct.unpack_from("<Q", data, h["sigma"][0] + 3)
    struct.pack_into("<f", data, off + 4 * 5, float("nan"))
    return _rgl_with(folder, bytes(data))


@_case("rgl-missing-field", "rgl", _R, "vndf")
def _(folder):
    return _rgl_with(folder, _tensor_bytes({k: v for k, v in _rgl_fields().items()
                                            if k != "vndf"}))


@_case("rgl-inconsistent-shapes", "rgl", _R, "rgb")
def _(folder):
    fields = dict(_rgl_fields())
    fields["rgb"] = fields["rgb"][:, :, :, :4]
    return _rgl_with(folder, _tensor_bytes(fields))


@_case("rgl-bad-angles", "rgl", _R, "theta_i")
def _(folder):
    fields = dict(_rgl_fields())
    fields["theta_i"] = np.array([0.0, 10.0, 20.0, 1e30], np.float32)  # degrees, and absurd
    return _rgl_with(folder, _tensor_bytes(fields))


@_case("rgl-huge-file", "rgl", _R, "at most", cli=True)
def _(folder):
    """A sparse 8 GiB file (no disk used) with a valid header: never read whole."""
    p = Path(_rgl_with(folder, valid_rgl_bytes()))
    with open(p, "r+b") as fh:
        fh.truncate(8 << 30)
    return str(p)


# == Neural-BRDF .h5 ========================================================================
_H = "bad.h5"


def _h5_with(folder: Path, **kwargs) -> str:
    p = folder / _H
    write_network_h5(p, **kwargs)
    return str(p)


@_case("nbrdf-h5-empty", "nbrdf-h5", _H, "expected")
def _(folder):
    (folder / _H).write_bytes(b"")
    return str(folder / _H)


@_case("nbrdf-h5-truncated", "nbrdf-h5", _H, "expected")
def _(folder):
    (folder / _H).write_bytes(network_h5_bytes()[:3000])
    return str(folder / _H)


@_case("nbrdf-h5-wrong-magic", "nbrdf-h5", _H, "expected")
def _(folder):
    (folder / _H).write_bytes(b"\x89HDF\r\n\x1a\x0b" + b"\0" * 2000)
    return str(folder / _H)


@_case("nbrdf-h5-huge-dataset", "nbrdf-h5", _H, "kernel", "at most", cli=True)
def _(folder):
    """An 8 kB file declaring a 6 x 2e8 float32 kernel (4.8 GB of fill values)."""
    return _h5_with(folder, dataset=_flip_h5_dataset(
        lambda g, n, d: g.create_dataset(n, shape=(6, 200_000_000), dtype="f4",
                                         chunks=(6, 1 << 14), compression="gzip")))


@_case("nbrdf-h5-24tib-dataset", "nbrdf-h5", _H, "kernel", "at most", cli=True)
def _(folder):
    """A kernel declaring 6 x 2^40 float32 = 24 TiB."""
    return _h5_with(folder, dataset=_flip_h5_dataset(
        lambda g, n, d: g.create_dataset(n, shape=(6, 2**40), dtype="f4", chunks=(6, 1 << 14))))


@_case("nbrdf-h5-deflate-bomb", "nbrdf-h5", _H, "bomb", cli=True)
def _(folder):
    """A (6, 21) gzip-chunked kernel whose one chunk inflates to 1.5 GB (1.5 MB file)."""
    def make(g, n, d):
        ds = g.create_dataset(n, shape=d.shape, dtype=d.dtype, chunks=d.shape, compression="gzip")
        ds.id.write_direct_chunk((0, 0), deflate_bomb(1_500_000_000, zlib_wrapper=True))
    return _h5_with(folder, dataset=_flip_h5_dataset(make))


def crashing_h5_bytes() -> bytes:
    """A network whose first filtered dataset's object-header *filter pipeline* message
    (type 11) is retyped to the unknown message type 207: one changed byte that makes
    libhdf5 2.0 segfault when the dataset is opened (found by fuzzing)."""
    data = bytearray(network_h5_bytes(dataset=lambda g, n, d: g.create_dataset(
        n, data=d, chunks=d.shape, compression="gzip", shuffle=True, fletcher32=True)))
    pos = data.find(b"shuffle\x00") - 24   # v1 message header: type, size, flags, reserved
    if pos < 0 or data[pos:pos + 2] != b"\x0b\x00":
        raise RuntimeError("unexpected HDF5 layout: filter pipeline message not found")
    data[pos] = 207
    return bytes(data)


@_case("nbrdf-h5-crashes-libhdf5", "nbrdf-h5", _H, "expected", cli=True)
def _(folder):
    """One byte that crashes libhdf5 (SIGSEGV): must become one error line, not a dead
    process."""
    (folder / _H).write_bytes(crashing_h5_bytes())
    return str(folder / _H)


@_case("nbrdf-h5-external-storage", "nbrdf-h5", _H, "external", cli=True)
def _(folder):
    """The kernel's bytes stored in a host file (HDF5 external storage, absolute path)."""
    host = _host_file(folder)
    return _h5_with(folder, dataset=_flip_h5_dataset(
        lambda g, n, d: g.create_dataset(n, shape=d.shape, dtype=d.dtype,
                                         external=[(str(host), 0, d.nbytes)])))


@_case("nbrdf-h5-external-link", "nbrdf-h5", _H, "external link")
def _(folder):
    """The kernel is an external link to a dataset of another HDF5 file."""
    import h5py

    other = folder / "other.h5"
    with h5py.File(other, "w") as f:
        f["k"] = np.full((6, 21), 0.25, np.float32)

    def make(g, n, d):
        g[n] = h5py.ExternalLink(str(other), "/k")
    return _h5_with(folder, dataset=_flip_h5_dataset(make))


@_case("nbrdf-h5-external-link-group", "nbrdf-h5", _H, "external link")
def _(folder):
    """A whole layer group is an external link."""
    import h5py

    p = Path(_h5_with(folder))
    other = folder / "other.h5"
    write_network_h5(other)
    with h5py.File(p, "a") as f:
        del f["dense_2"]
        f["dense_2"] = h5py.ExternalLink(str(other), "/dense_2")
    return str(p)


@_case("nbrdf-h5-soft-link", "nbrdf-h5", _H, "soft link")
def _(folder):
    """The kernel is a soft link (to a path that is not there: a dangling link)."""
    import h5py

    def make(g, n, d):
        g[n] = h5py.SoftLink("/nowhere/kernel:0")
    return _h5_with(folder, dataset=_flip_h5_dataset(make))


@_case("nbrdf-h5-virtual-dataset", "nbrdf-h5", _H, "virtual")
def _(folder):
    """The kernel is a virtual dataset (VDS) mapping another file by absolute path."""
    return _h5_with(folder, dataset=_flip_h5_dataset(_virtual_kernel(folder)))


def _virtual_kernel(folder: Path):
    """A dataset maker whose kernel is a VDS mapping ``folder/other.h5`` by absolute path."""
    import h5py

    other = folder / "other.h5"
    with h5py.File(other, "w") as f:
        f["k"] = np.full((6, 21), 0.25, np.float32)

    def make(g, n, d):
        layout = h5py.VirtualLayout(shape=d.shape, dtype=d.dtype)
        layout[:] = h5py.VirtualSource(str(other), "k", shape=d.shape)
        g.create_virtual_dataset(n, layout)
    return make


@_case("nbrdf-h5-unknown-filter", "nbrdf-h5", _H, "filter")
def _(folder):
    """A chunked kernel with the LZF filter (only gzip/shuffle/fletcher32 are decoded)."""
    return _h5_with(folder, dataset=_flip_h5_dataset(
        lambda g, n, d: g.create_dataset(n, data=d, chunks=d.shape, compression="lzf")))


@_case("nbrdf-h5-int-weights", "nbrdf-h5", _H, "float")
def _(folder):
    return _h5_with(folder, dataset=_flip_h5_dataset(
        lambda g, n, d: g.create_dataset(n, data=(d * 100).astype(np.int32))))


@_case("nbrdf-h5-string-weights", "nbrdf-h5", _H, "float")
def _(folder):
    return _h5_with(folder, dataset=_flip_h5_dataset(
        lambda g, n, d: g.create_dataset(n, data=np.full(d.shape, b"x" * 16))))


@_case("nbrdf-h5-scalar-weights", "nbrdf-h5", _H, "scalar")
def _(folder):
    return _h5_with(folder, dataset=_flip_h5_dataset(
        lambda g, n, d: g.create_dataset(n, data=np.float32(1.0))))


@_case("nbrdf-h5-zero-dimension", "nbrdf-h5", _H, "kernel", "shape")
def _(folder):
    return _h5_with(folder, dataset=_flip_h5_dataset(
        lambda g, n, d: g.create_dataset(n, shape=(6, 0), dtype="f4")))


@_case("nbrdf-h5-wrong-shape", "nbrdf-h5", _H, "expected kernel")
def _(folder):
    w = random_weights()
    w[0] = (np.ones((7, 21), np.float32), w[0][1])
    return _h5_with(folder, weights=w)


@_case("nbrdf-h5-nan", "nbrdf-h5", _H, "finite")
def _(folder):
    w = random_weights()
    w[1][0][2, 3] = np.nan
    return _h5_with(folder, weights=w)


@_case("nbrdf-h5-inf", "nbrdf-h5", _H, "finite")
def _(folder):
    w = random_weights()
    w[2] = (w[2][0], np.array([np.inf, 0, 0], np.float32))
    return _h5_with(folder, weights=w)


@_case("nbrdf-h5-group-not-dataset", "nbrdf-h5", _H, "dataset")
def _(folder):
    return _h5_with(folder, dataset=_flip_h5_dataset(lambda g, n, d: g.create_group(n)))


@_case("nbrdf-h5-missing-weights", "nbrdf-h5", _H, "bias")
def _(folder):
    def make(g, n, d):
        if not n.endswith("bias:0"):
            g.create_dataset(n, data=d)
    return _h5_with(folder, dataset=make)


@_case("nbrdf-h5-too-many-layers", "nbrdf-h5", _H, "at most")
def _(folder):
    return _h5_with(folder, layer_names=[f"dense_{k}" for k in range(5000)])


@_case("nbrdf-h5-too-many-weights", "nbrdf-h5", _H, "at most")
def _(folder):
    """A 6 -> 1024 -> 1024 -> 3 network (1.06 M weights, zeros, gzip: a 30 kB file that would
    take minutes to evaluate)."""
    w = [(np.zeros((6, 1024), np.float32), np.zeros(1024, np.float32)),
         (np.zeros((1024, 1024), np.float32), np.zeros(1024, np.float32)),
         (np.zeros((1024, 3), np.float32), np.zeros(3, np.float32))]
    return _h5_with(folder, weights=w, dataset=lambda g, n, d: g.create_dataset(
        n, data=d, chunks=d.shape, compression="gzip"))


@_case("nbrdf-h5-sidecar-bomb", "nbrdf-h5", "bad.json", "json", "at most")
def _(folder):
    """A 4 GiB sparse JSON sidecar next to a valid network."""
    p = _h5_with(folder)
    with open(folder / "bad.json", "wb") as fh:
        fh.truncate(4 << 30)
    return p


@_case("nbrdf-h5-sidecar-deep-json", "nbrdf-h5", "bad.json", "json")
def _(folder):
    """A sidecar nested 100 000 levels deep (RecursionError in the JSON parser)."""
    p = _h5_with(folder)
    (folder / "bad.json").write_text("[" * 100_000 + "]" * 100_000)
    return p


@_case("nbrdf-h5-sidecar-wrong-types", "nbrdf-h5", "bad.json", "keras")
def _(folder):
    p = _h5_with(folder)
    (folder / "bad.json").write_text(json.dumps({"config": {"layers": [1, "two", None]}}))
    return p


# == Neural-BRDF .zip collection ============================================================
_Z = "bad.zip"


def _zip_spec(folder: Path, member: str = "gold") -> str:
    return f"{folder / _Z}:{member}"


@_case("nbrdf-zip-empty", "nbrdf-zip", _Z, "expected")
def _(folder):
    (folder / _Z).write_bytes(b"")
    return _zip_spec(folder)


@_case("nbrdf-zip-not-a-zip", "nbrdf-zip", _Z, "expected")
def _(folder):
    (folder / _Z).write_bytes(b"PK\x03\x04" + b"\x01" * 500)
    return _zip_spec(folder)


@_case("nbrdf-zip-truncated", "nbrdf-zip", _Z, "expected")
def _(folder):
    p = write_collection(folder / _Z, _good_members())
    p.write_bytes(p.read_bytes()[:-300])
    return _zip_spec(folder)


@_case("nbrdf-zip-json-bomb", "nbrdf-zip", _Z, "gold.json", "at most", cli=True)
def _(folder):
    """A 1.5 MB zip whose JSON sidecar inflates to 1.5 GB (declared honestly)."""
    n = 1_500_000_000
    members = _good_members()
    _raw_member_zip(folder / _Z, members, {"coll/gold.json": (deflate_bomb(n), n, 0)})
    return _zip_spec(folder)


@_case("nbrdf-zip-json-bomb-lying", "nbrdf-zip", _Z, "gold.json")
def _(folder):
    """The same bomb declaring 1844 bytes: the read must stop at the cap anyway."""
    members = _good_members()
    _raw_member_zip(folder / _Z, members,
                    {"coll/gold.json": (deflate_bomb(1_500_000_000), 1844, 0)})
    return _zip_spec(folder)


@_case("nbrdf-zip-h5-bomb", "nbrdf-zip", _Z, "gold.h5", "at most")
def _(folder):
    n = 2_000_000_000
    _raw_member_zip(folder / _Z, _good_members(), {"coll/gold.h5": (deflate_bomb(n), n, 0)})
    return _zip_spec(folder)


@_case("nbrdf-zip-corrupt-deflate", "nbrdf-zip", _Z, "corrupt", cli=True)
def _(folder):
    """The network member's deflate stream is invalid (zlib.error)."""
    members = _good_members()
    size = len(members[0][1])
    _raw_member_zip(folder / _Z, members, {"coll/gold.h5": (b"\xff" * 300, size, 0)})
    return _zip_spec(folder)


@_case("nbrdf-zip-bad-crc", "nbrdf-zip", _Z, "corrupt")
def _(folder):
    p = write_collection(folder / _Z, _good_members())
    _patch_central_sizes(p, "coll/gold.h5", crc=0x12345678)
    return _zip_spec(folder)


@_case("nbrdf-zip-unsupported-method", "nbrdf-zip", _Z, "compression method")
def _(folder):
    p = write_collection(folder / _Z, _good_members(), compression=zipfile.ZIP_BZIP2)
    return str(p) + ":gold"


@_case("nbrdf-zip-encrypted", "nbrdf-zip", _Z, "encrypted")
def _(folder):
    p = write_collection(folder / _Z, _good_members(), compression=zipfile.ZIP_STORED)
    data = bytearray(p.read_bytes())
    for sig, off in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):
        pos = data.find(sig)
        while pos >= 0:
            data[pos + off] |= 1
            pos = data.find(sig, pos + 4)
    p.write_bytes(bytes(data))
    return _zip_spec(folder)


@_case("nbrdf-zip-dotdot-member", "nbrdf-zip", _Z, "unsafe", cli=True)
def _(folder):
    """The only member for the material is named ``../../evil.h5``."""
    write_collection(folder / _Z, [("../../evil.h5", network_h5_bytes())])
    return _zip_spec(folder, "evil")


@_case("nbrdf-zip-absolute-member", "nbrdf-zip", _Z, "unsafe")
def _(folder):
    write_collection(folder / _Z, [("/etc/evil.h5", network_h5_bytes())])
    return _zip_spec(folder, "evil")


@_case("nbrdf-zip-dotdot-material", "nbrdf-zip", _Z, "'..'")
def _(folder):
    """A member ``coll/...h5`` whose material name would be ``..``."""
    write_collection(folder / _Z, [("coll/...h5", network_h5_bytes())])
    return _zip_spec(folder, "..")


@_case("nbrdf-zip-newline-member", "nbrdf-zip", _Z, "unsafe", "control character")
def _(folder):
    """A member name with a newline and an escape sequence (never listed, never used)."""
    write_collection(folder / _Z, [("coll/evil\n\x1b[2J.h5", network_h5_bytes())]
                     + _good_members())
    return _zip_spec(folder, "evil\n\x1b[2J")


@_case("nbrdf-zip-duplicate-members", "nbrdf-zip", _Z, "one member")
def _(folder):
    """Two members with the same name and different networks (which one is read?)."""
    write_collection(folder / _Z, [("coll/gold.h5", network_h5_bytes(random_weights(1))),
                                   ("coll/gold.h5", network_h5_bytes(random_weights(2)))])
    return _zip_spec(folder)


@_case("nbrdf-zip-external-storage", "nbrdf-zip", _Z, "external")
def _(folder):
    """A network inside the zip whose kernel is external storage in a host file."""
    host = _host_file(folder)
    blob = network_h5_bytes(dataset=_flip_h5_dataset(
        lambda g, n, d: g.create_dataset(n, shape=d.shape, dtype=d.dtype,
                                         external=[(str(host), 0, d.nbytes)])))
    write_collection(folder / _Z, [("coll/gold.h5", blob)])
    return _zip_spec(folder)


@_case("nbrdf-zip-virtual-dataset", "nbrdf-zip", _Z, "virtual")
def _(folder):
    write_collection(folder / _Z, [("coll/gold.h5", network_h5_bytes(
        dataset=_flip_h5_dataset(_virtual_kernel(folder))))])
    return _zip_spec(folder)


@_case("nbrdf-zip-huge-dataset", "nbrdf-zip", _Z, "at most")
def _(folder):
    blob = network_h5_bytes(dataset=_flip_h5_dataset(
        lambda g, n, d: g.create_dataset(n, shape=(6, 200_000_000), dtype="f4",
                                         chunks=(6, 1 << 14), compression="gzip")))
    write_collection(folder / _Z, [("coll/gold.h5", blob)])
    return _zip_spec(folder)


@_case("nbrdf-zip-crashes-libhdf5", "nbrdf-zip", _Z, "expected")
def _(folder):
    write_collection(folder / _Z, [("coll/gold.h5", crashing_h5_bytes())])
    return _zip_spec(folder)


@_case("nbrdf-zip-garbage-member", "nbrdf-zip", _Z, "expected keras hdf5")
def _(folder):
    write_collection(folder / _Z, [("coll/gold.h5", b"\x89HDF\r\n\x1a\n" + b"\0" * 100)])
    return _zip_spec(folder)


# == load specs ==============================================================================
@_case("spec-zip-dotdot-path", "spec", "coll.zip", "no 'passwd'")
def _(folder):
    """``coll.zip:../../../../etc/passwd`` must not read anything outside the archive."""
    write_collection(folder / "coll.zip", _good_members())
    return f"{folder / 'coll.zip'}:../../../../etc/passwd"


@_case("spec-zip-absolute-member", "spec", "coll.zip", "no 'hostname'")
def _(folder):
    write_collection(folder / "coll.zip", _good_members())
    return f"{folder / 'coll.zip'}:/etc/hostname"


@_case("spec-zip-dotdot-member", "spec", "coll.zip", "no '..'")
def _(folder):
    write_collection(folder / "coll.zip", _good_members())
    return f"{folder / 'coll.zip'}:.."


@_case("spec-synthetic-path", "spec", "synthetic:../../../etc/passwd", "synthetic")
def _(folder):
    return "synthetic:../../../etc/passwd"


@_case("spec-synthetic-control", "spec", "synthetic:\\x1b[2J\\n", "synthetic", cli=True)
def _(folder):
    return "synthetic:\x1b[2J\n"


@_case("spec-synthetic-empty", "spec", "synthetic:", "synthetic")
def _(folder):
    return "synthetic:"


@_case("spec-name-too-long", "spec", "xxxxxxxxxx", "expected")
def _(folder):
    return str(folder / ("x" * 5000 + ".binary"))


@_case("spec-unknown-content", "spec", "bad.data", "unrecognised")
def _(folder):
    (folder / "bad.data").write_bytes(b"\x00\x01garbage" * 50)
    return str(folder / "bad.data")


@_case("spec-fifo-unknown-extension", "spec", "pipe.data", "fifo")
def _(folder):
    """A named pipe without a known extension: sniffing its content would block forever."""
    os.mkfifo(folder / "pipe.data")
    return str(folder / "pipe.data")


@_case("spec-zip-sniffed", "spec", "bad.data", "expected")
def _(folder):
    """A corrupt zip without the .zip extension, recognised by content."""
    p = write_collection(folder / "x.zip", _good_members())
    (folder / "bad.data").write_bytes(p.read_bytes()[:200])
    (folder / "x.zip").unlink()
    return str(folder / "bad.data")


def cases() -> list[Case]:
    """Every malformed-input case (a new list; see the module docstring)."""
    return list(_CASES)


def case_by_name(name: str) -> Case:
    for c in _CASES:
        if c.name == name:
            return c
    raise KeyError(name)


CASES: tuple[Case, ...] = tuple(_CASES)

assert len({c.name for c in _CASES}) == len(_CASES), "case names must be unique"
