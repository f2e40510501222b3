"""Mitsuba "tensor files": the container of the RGL material database (``.bsdf``).

Layout (Mitsuba 2/3 ``TensorFile``, ``src/core/tensor.cpp``; also written by Mitsuba's
``mitsuba/python/tensor_io.py``), all integers little-endian::

    12 bytes   magic  b"tensor_file\\0"
    2  bytes   version (major, minor) = (1, 0)
    uint32     field count
    per field: uint16 name length, name (UTF-8), uint16 ndim, uint8 dtype code,
               uint64 byte offset of the data, uint64 shape[ndim]
    data       each field stored contiguously (C order) at its offset

The dtype code is Mitsuba's ``Struct::Type`` enumeration (``include/mitsuba/core/struct.h``
of Mitsuba 2, kept by Mitsuba 3's tensor reader): ``Invalid = 0, UInt8, Int8, UInt16, Int16,
UInt32, Int32, UInt64, Int64, Float16, Float32, Float64``, i.e. 1 = uint8 ... 10 = float32,
11 = float64.

:func:`read_tensor_file` validates everything it reads (file size at most
:data:`~brdffit.io._limits.MAX_TENSOR_FILE_BYTES`, magic, version, field count, header bounds,
dtype codes, data offsets and sizes inside the file, no overlapping fields, no absurd
dimensions even for empty fields, duplicate names, NaN/inf in float fields) before allocating
anything and raises :class:`~brdffit.errors.BRDFFormatError` naming the file, what was expected
and what was found. :func:`write_tensor_file` writes the same format atomically.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from .._atomic import atomic_write
from ..errors import BRDFFormatError
from ._limits import MAX_TENSOR_FILE_BYTES, read_file_capped

__all__ = ["MAGIC", "VERSION", "DTYPE_CODES", "TensorField", "read_tensor_header",
           "read_tensor_file", "write_tensor_file", "is_tensor_file"]

MAGIC = b"tensor_file\x00"
VERSION = (1, 0)
#: Mitsuba ``Struct::Type`` code -> little-endian NumPy dtype.
DTYPE_CODES: dict[int, np.dtype] = {
    1: np.dtype("<u1"), 2: np.dtype("<i1"), 3: np.dtype("<u2"), 4: np.dtype("<i2"),
    5: np.dtype("<u4"), 6: np.dtype("<i4"), 7: np.dtype("<u8"), 8: np.dtype("<i8"),
    9: np.dtype("<f2"), 10: np.dtype("<f4"), 11: np.dtype("<f8"),
}
_CODE_OF = {(dt.kind, dt.itemsize): code for code, dt in DTYPE_CODES.items()}
_PREAMBLE = 12 + 2 + 4
_MAX_NDIM = 32          # Mitsuba allows uint16; anything beyond this is a corrupt header
_MIN_ENTRY = 2 + 2 + 1 + 8   # name length, ndim, dtype, offset (empty name, 0-d)
#: fields decoded to ``str`` by default (uint8 byte strings).
STRING_FIELDS = ("description",)


@dataclass(frozen=True)
class TensorField:
    """One header entry: ``name``, Mitsuba ``dtype_code``, NumPy ``dtype``, ``offset``, ``shape``."""

    name: str
    dtype_code: int
    dtype: np.dtype
    offset: int
    shape: tuple[int, ...]

    @property
    def nbytes(self) -> int:
        n = 1
        for s in self.shape:
            n *= s
        return n * self.dtype.itemsize


def is_tensor_file(path) -> bool:
    """True when ``path`` is a regular file starting with the tensor-file magic (cheap check,
    no validation; a FIFO or device is never opened)."""
    try:
        if not Path(path).is_file():
            return False
        with open(path, "rb") as fh:
            return fh.read(12) == MAGIC
    except OSError:
        return False


def _parse_header(buf: bytes | memoryview, path) -> tuple[dict[str, TensorField], int]:
    size = len(buf)
    if size < _PREAMBLE:
        raise BRDFFormatError(path, f"expected a tensor file of at least {_PREAMBLE} bytes "
                                    f"(magic, version, field count), found {size} bytes")
    magic = bytes(buf[:12])
    if magic != MAGIC:
        raise BRDFFormatError(path, f"expected the tensor-file magic {MAGIC!r}, found {magic!r}")
    version = (buf[12], buf[13])
    if version != VERSION:
        raise BRDFFormatError(path, f"expected tensor-file version {VERSION}, found {version}")
    (count,) = struct.unpack_from("<I", buf, 14)
    if count == 0:
        raise BRDFFormatError(path, "expected at least one field, found a field count of 0")
    if count * _MIN_ENTRY > size - _PREAMBLE:
        raise BRDFFormatError(path, f"expected a field count that fits in the file ({size} "
                                    f"bytes), found {count} fields (corrupt or truncated header)")
    pos = _PREAMBLE
    fields: dict[str, TensorField] = {}

    def need(n: int, what: str) -> None:
        if pos + n > size:
            raise BRDFFormatError(path, f"expected {n} more header bytes for {what} at byte "
                                        f"{pos}, found end of file at {size} (truncated)")

    for k in range(count):
        need(2, f"the name length of field #{k}")
        (name_len,) = struct.unpack_from("<H", buf, pos)
        pos += 2
        need(name_len, f"the name of field #{k}")
        raw = bytes(buf[pos:pos + name_len])
        pos += name_len
        try:
            name = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise BRDFFormatError(path, f"expected a UTF-8 name for field #{k}, found {raw!r}") from None
        if not name:
            raise BRDFFormatError(path, f"expected a non-empty name for field #{k}, found ''")
        if name in fields:
            raise BRDFFormatError(path, f"expected unique field names, found {name!r} twice")
        need(2 + 1 + 8, f"the ndim/dtype/offset of field {name!r}")
        ndim, code, offset = struct.unpack_from("<HBQ", buf, pos)
        pos += 11
        if ndim > _MAX_NDIM:
            raise BRDFFormatError(path, f"expected at most {_MAX_NDIM} dimensions for field "
                                        f"{name!r}, found {ndim}")
        if code not in DTYPE_CODES:
            raise BRDFFormatError(path, f"expected a dtype code in 1..11 (Mitsuba Struct::Type) "
                                        f"for field {name!r}, found {code}")
        need(8 * ndim, f"the shape of field {name!r}")
        shape = struct.unpack_from(f"<{ndim}Q", buf, pos)
        pos += 8 * ndim
        fields[name] = TensorField(name, code, DTYPE_CODES[code], int(offset),
                                   tuple(int(s) for s in shape))
    header_end = pos
    for f in fields.values():
        if f.nbytes == 0 and any(s > size for s in f.shape):
            # an empty field may still declare absurd dimensions (NumPy: "array is too big")
            raise BRDFFormatError(path, f"expected the dimensions of the empty field {f.name!r} "
                                        f"to be at most the file size ({size}), found shape "
                                        f"{f.shape}")
        if f.offset < header_end or f.offset + f.nbytes > size:
            raise BRDFFormatError(
                path, f"expected the data of field {f.name!r} ({f.nbytes} bytes, shape "
                      f"{f.shape}, {f.dtype}) inside the file between the header end "
                      f"({header_end}) and the file size ({size}), found offset {f.offset}")
    placed = sorted((f for f in fields.values() if f.nbytes), key=lambda f: f.offset)
    for a, b in zip(placed, placed[1:]):
        if a.offset + a.nbytes > b.offset:
            raise BRDFFormatError(path, f"expected fields stored without overlap, found "
                                        f"{a.name!r} (bytes {a.offset}..{a.offset + a.nbytes}) "
                                        f"overlapping {b.name!r} (from byte {b.offset})")
    return fields, header_end


def read_tensor_header(path) -> dict[str, TensorField]:
    """Parse and validate the header of a tensor file (field name -> :class:`TensorField`)."""
    path = Path(path)
    buf = _read_bytes(path)
    return _parse_header(buf, path)[0]


def _read_bytes(path: Path) -> bytes:
    return read_file_capped(path, "a tensor file", MAX_TENSOR_FILE_BYTES)


def read_tensor_file(path, *, string_fields=STRING_FIELDS, check_finite: bool = True
                     ) -> dict[str, np.ndarray | str]:
    """Read a Mitsuba tensor file: ``{name: array}`` in file order.

    Arrays are native-endian copies with the stored shape and dtype. Fields named in
    ``string_fields`` (default ``description``) that are 1-D uint8 are decoded as UTF-8 ``str``.
    With ``check_finite`` (default) a float field holding NaN or inf is an error.
    """
    path = Path(path)
    buf = _read_bytes(path)
    fields, _ = _parse_header(buf, path)
    out: dict[str, np.ndarray | str] = {}
    for f in fields.values():
        count = f.nbytes // f.dtype.itemsize
        arr = np.frombuffer(buf, dtype=f.dtype, count=count, offset=f.offset)
        arr = arr.astype(f.dtype.newbyteorder("="), copy=True).reshape(f.shape)
        if f.name in string_fields and f.dtype_code == 1 and arr.ndim == 1:
            try:
                out[f.name] = arr.tobytes().decode("utf-8").rstrip("\x00")
            except UnicodeDecodeError:
                raise BRDFFormatError(path, f"expected UTF-8 text in field {f.name!r}, found "
                                            f"undecodable bytes") from None
            continue
        if check_finite and arr.dtype.kind == "f":
            bad = ~np.isfinite(arr)
            if bad.any():
                raise BRDFFormatError(path, f"expected finite values in float field {f.name!r} "
                                            f"{f.shape}, found {int(bad.sum())} NaN/inf "
                                            f"(first at index {np.unravel_index(int(np.argmax(bad)), arr.shape)})")
        out[f.name] = arr
    return out


def write_tensor_file(path, fields: Mapping[str, np.ndarray | str], *, align: int = 8) -> Path:
    """Write ``fields`` as a Mitsuba tensor file, atomically (readable by Mitsuba 3).

    Values are arrays of a supported dtype (bool is stored as uint8) or ``str`` (stored as
    1-D uint8 UTF-8). Each field's data is aligned to ``align`` bytes. Float fields must be
    finite (the reader rejects NaN/inf).
    """
    path = Path(path)
    if not fields:
        raise BRDFFormatError(path, "expected at least one field to write, found none")
    if align < 1:
        raise ValueError(f"align must be >= 1, got {align}")
    arrays: dict[str, tuple[bytes, int, np.ndarray]] = {}
    for name, value in fields.items():
        label = str(name).encode("utf-8")
        if not label or len(label) > 0xFFFF:
            raise BRDFFormatError(path, f"expected a field name of 1..65535 UTF-8 bytes, found {name!r}")
        if isinstance(value, str):
            arr = np.frombuffer(value.encode("utf-8"), dtype=np.uint8)
        else:
            arr = np.asarray(value)
            if arr.dtype == np.bool_:
                arr = arr.astype(np.uint8)
        code = _CODE_OF.get((arr.dtype.kind, arr.dtype.itemsize))
        if code is None or arr.dtype.kind not in "uif":
            raise BRDFFormatError(path, f"expected a (u)int8-64 or float16/32/64 array for field "
                                        f"{name!r}, found dtype {arr.dtype}")
        if arr.ndim > _MAX_NDIM:
            raise BRDFFormatError(path, f"expected at most {_MAX_NDIM} dimensions for field "
                                        f"{name!r}, found {arr.ndim}")
        if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
            raise BRDFFormatError(path, f"expected finite values in float field {name!r}, found NaN/inf")
        arr = np.asarray(arr, dtype=DTYPE_CODES[code], order="C")  # keeps 0-d arrays 0-d
        arrays[str(name)] = (label, code, arr)

    header_size = _PREAMBLE + sum(2 + len(lb) + 2 + 1 + 8 + 8 * a.ndim
                                  for lb, _, a in arrays.values())
    offsets = {}
    pos = header_size
    for name, (_, _, arr) in arrays.items():
        pos = (pos + align - 1) // align * align
        offsets[name] = pos
        pos += arr.nbytes
    out = bytearray(pos)
    out[:12] = MAGIC
    out[12:14] = bytes(VERSION)
    struct.pack_into("<I", out, 14, len(arrays))
    h = _PREAMBLE
    for name, (label, code, arr) in arrays.items():
        struct.pack_into("<H", out, h, len(label))
        h += 2
        out[h:h + len(label)] = label
        h += len(label)
        struct.pack_into(f"<HBQ{arr.ndim}Q", out, h, arr.ndim, code, offsets[name], *arr.shape)
        h += 11 + 8 * arr.ndim
        out[offsets[name]:offsets[name] + arr.nbytes] = arr.tobytes()
    assert h == header_size
    with atomic_write(path) as fh:
        fh.write(bytes(out))
    return path
