"""Limits and validators shared by the readers of measured data (files brdffit did not write).

What every reader of :mod:`brdffit.io` promises on a hostile or damaged file (MERL
``.binary``, Neural-BRDF ``.h5`` and ``.zip`` collections, RGL ``.bsdf``, UTIA ``.bin``):

* it raises :class:`~brdffit.errors.BRDFFormatError` naming the file, what was expected and
  what was found, and nothing else (no ``MemoryError``, ``zlib.error``, ``KeyError``...);
* sizes, shapes, dtypes, offsets and counts declared by the file are checked against what the
  format allows and against the file's own size *before* anything is allocated or read;
* nothing is decompressed without a hard cap on the output (declared sizes are checked first,
  and the read stops at the cap even when the declaration lies);
* nothing outside the file is ever read: HDF5 external storage, virtual datasets, external
  and soft links are refused, zip members are read in memory (never extracted) and members
  with absolute, ``..`` or control-character names are never used.

The caps below are generous for the real formats (a Neural-BRDF network is 675 weights in a
19 kB file, its JSON sidecar 1.8 kB, an RGL file 0.7 MB) and small enough that a rejected file
costs well under a second and a few MiB.
"""

from __future__ import annotations

import math
import os
import stat
import zipfile
import zlib
from pathlib import Path, PurePosixPath

import numpy as np

from ..errors import BRDFFormatError

__all__ = [
    "MAX_NETWORK_FILE_BYTES", "MAX_SIDECAR_BYTES", "MAX_NETWORK_LAYERS", "MAX_LAYER_UNITS",
    "MAX_NETWORK_WEIGHTS", "MAX_TENSOR_FILE_BYTES", "MAX_ZIP_MEMBERS", "MAX_ABS_VALUE",
    "describe_exception", "regular_file_size", "read_file_capped", "open_zip",
    "unsafe_member_reason", "read_zip_member", "check_plausible_float64",
    "h5_child", "h5_hard_child", "h5_string_list_attr", "h5_dataset_shape", "h5_read_dataset",
]

#: Largest Neural-BRDF ``.h5`` file or zip member read (the published networks are 19 kB).
MAX_NETWORK_FILE_BYTES = 16 << 20
#: Largest Keras JSON sidecar read (the published ones are 1.8 kB).
MAX_SIDECAR_BYTES = 1 << 20
#: Most Dense layers in a network (the published ones have 3).
MAX_NETWORK_LAYERS = 16
#: Widest layer (the published ones have 21 units).
MAX_LAYER_UNITS = 1024
#: Most weights (kernels + biases) in a network (the published ones have 675).
MAX_NETWORK_WEIGHTS = 1 << 16
#: Largest RGL tensor file read (the RGL database's RGB files are 0.7 MB).
MAX_TENSOR_FILE_BYTES = 64 << 20
#: Most entries in a ``.zip`` collection (the published ones have up to 208).
MAX_ZIP_MEMBERS = 100_000
#: Largest magnitude of a stored BRDF value accepted in MERL and UTIA tables: larger values
#: (or subnormal ones) are not reflectance data, typically a byte-swapped file.
MAX_ABS_VALUE = 1e15


def describe_exception(exc: BaseException, limit: int = 200) -> str:
    """One line ``Type: message`` of an exception raised by a third-party parser."""
    text = " ".join(str(exc).split()) or "no details"
    if len(text) > limit:
        text = text[:limit] + "..."
    return f"{type(exc).__name__}: {text}"


def _kind_of(mode: int) -> str:
    for test, what in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return what
    return "not a regular file"


def regular_file_size(path, what: str, max_bytes: int | None = None) -> int:
    """Size of ``path`` after checking it is a readable regular file of at most ``max_bytes``.

    Never opens the file (a FIFO or a device would block or never end).
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise BRDFFormatError(path, f"expected {what}, found no such file") from None
    except (OSError, ValueError) as exc:
        raise BRDFFormatError(path, f"expected {what}, found an unreadable path "
                                    f"({describe_exception(exc)})") from None
    if not stat.S_ISREG(st.st_mode):
        raise BRDFFormatError(path, f"expected {what}, found {_kind_of(st.st_mode)}")
    if max_bytes is not None and st.st_size > max_bytes:
        raise BRDFFormatError(path, f"expected {what} of at most {max_bytes} bytes, found "
                                    f"{st.st_size} bytes")
    return st.st_size


def read_file_capped(path, what: str, max_bytes: int) -> bytes:
    """The bytes of a regular file of at most ``max_bytes`` (checked before and while reading)."""
    regular_file_size(path, what, max_bytes)
    try:
        with open(path, "rb") as fh:
            data = fh.read(max_bytes + 1)
    except OSError as exc:
        raise BRDFFormatError(path, f"expected a readable {what}, found "
                                    f"{describe_exception(exc)}") from None
    if len(data) > max_bytes:  # the file grew after stat
        raise BRDFFormatError(path, f"expected {what} of at most {max_bytes} bytes, found more")
    return data


# -- zip archives -------------------------------------------------------------------------
def open_zip(path, what: str = "a .zip collection") -> zipfile.ZipFile:
    """Open a zip archive for reading; any parser failure becomes a :class:`BRDFFormatError`."""
    regular_file_size(path, what)
    try:
        zf = zipfile.ZipFile(path)
    except Exception as exc:  # zipfile raises BadZipFile, ValueError, OverflowError, EOFError...
        raise BRDFFormatError(path, f"expected {what}, found an unreadable archive "
                                    f"({describe_exception(exc)})") from None
    if len(zf.infolist()) > MAX_ZIP_MEMBERS:
        n = len(zf.infolist())
        zf.close()
        raise BRDFFormatError(path, f"expected {what} of at most {MAX_ZIP_MEMBERS} entries, "
                                    f"found {n}")
    return zf


def unsafe_member_reason(name: str) -> str | None:
    """Why a zip member name must not be used (``None`` when it is safe).

    Unsafe: empty, absolute (``/x``, ``\\\\x``, ``C:x``), any ``..`` component (backslashes count
    as separators, as in zips written on Windows), a control character (it would break a
    one-line message).
    """
    if not name:
        return "an empty name"
    if any(not c.isprintable() for c in name):
        return "a control character in its name"
    posix = name.replace("\\", "/")
    if posix.startswith("/") or (len(name) > 1 and name[1] == ":"):
        return "an absolute path"
    if ".." in PurePosixPath(posix).parts:
        return "a '..' component"
    return None


def read_zip_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, where, max_bytes: int) -> bytes:
    """Read one member in memory with a hard cap of ``max_bytes`` on its uncompressed size.

    The declared size is checked first; the read stops after ``max_bytes + 1`` bytes whatever
    the header says. Only stored and deflated members are read (bzip2/LZMA decompression
    cannot be capped cheaply by :mod:`zipfile`). A corrupt stream, a CRC mismatch or an
    encrypted member raises :class:`BRDFFormatError` naming ``where``.
    """
    name = info.filename
    if info.file_size > max_bytes:
        raise BRDFFormatError(where, f"expected member {name!r} of at most {max_bytes} bytes, "
                                     f"found a declared size of {info.file_size} bytes")
    if info.flag_bits & 0x1:
        raise BRDFFormatError(where, f"expected an unencrypted member {name!r}, found an "
                                     f"encrypted one")
    if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
        raise BRDFFormatError(where, f"expected member {name!r} stored or deflated, found "
                                     f"compression method {info.compress_type}")
    chunks, total = [], 0
    try:
        with zf.open(info) as fh:
            while True:
                block = fh.read(min(1 << 16, max_bytes + 1 - total))
                if not block:
                    break
                chunks.append(block)
                total += len(block)
                if total > max_bytes:
                    raise BRDFFormatError(where, f"expected member {name!r} of at most "
                                                 f"{max_bytes} bytes, found it inflating beyond "
                                                 f"(declared {info.file_size} bytes)")
    except BRDFFormatError:
        raise
    except Exception as exc:  # BadZipFile (CRC), zlib.error, EOFError, OSError, ...
        raise BRDFFormatError(where, f"expected a readable member {name!r}, found a corrupt one "
                                     f"({describe_exception(exc)})") from None
    return b"".join(chunks)


# -- float tables -------------------------------------------------------------------------
def check_plausible_float64(raw: np.ndarray, path, what: str) -> None:
    """Refuse NaN/inf, magnitudes above :data:`MAX_ABS_VALUE` and subnormal values.

    ``raw`` holds little-endian float64 as read. When the values are implausible but their
    byte-swapped reading is not, the message says the file is big-endian.
    """
    if _plausible(raw):
        return
    finite = np.isfinite(raw)
    if not finite.all():
        bad = int(raw.size - np.count_nonzero(finite))
        swapped = raw.byteswap()
        hint = (" (the file looks byte-swapped: big-endian float64)"
                if _plausible(swapped) else "")
        raise BRDFFormatError(path, f"expected finite float64 {what}, found {bad} NaN/inf{hint}")
    a = np.abs(raw)
    n_big = int(np.count_nonzero(a > MAX_ABS_VALUE))
    n_sub = int(np.count_nonzero((a > 0) & (a < np.finfo(np.float64).tiny)))
    if _plausible(raw.byteswap()):
        raise BRDFFormatError(path, f"expected little-endian float64 {what}, found "
                                    f"big-endian values (byte-swapped file: {n_big} values "
                                    f"above {MAX_ABS_VALUE:g}, {n_sub} subnormal)")
    raise BRDFFormatError(path, f"expected {what} of magnitude at most {MAX_ABS_VALUE:g} "
                                f"and not subnormal, found {n_big} larger (max "
                                f"{float(a.max()):.3g}) and {n_sub} subnormal values")


_CHUNK = 1 << 16
_MAX_BITS = np.array(MAX_ABS_VALUE, dtype=np.float64).view(np.uint64)
_TINY_BITS = np.array(np.finfo(np.float64).tiny, dtype=np.float64).view(np.uint64)


def _plausible(raw: np.ndarray) -> bool:
    """Every value is 0 or a normal float of magnitude ≤ MAX_ABS_VALUE (not NaN/inf).

    On the IEEE-754 bits with the sign cleared, magnitude order is integer order (NaN and
    inf above every finite value), so two reductions decide it: ``max(bits) ≤ bits(MAX)``
    and ``min(bits − 1) ≥ bits(tiny) − 1`` (0 wraps around to the largest integer)."""
    if raw.size == 0:
        return True
    words = np.ascontiguousarray(raw, dtype=np.float64).reshape(-1).view(np.uint64)
    buf = np.empty(min(words.size, _CHUNK), dtype=np.uint64)   # small, reused: no page faults
    for k in range(0, words.size, _CHUNK):
        bits = buf[:min(_CHUNK, words.size - k)]
        np.bitwise_and(words[k:k + _CHUNK], np.uint64(0x7FFF_FFFF_FFFF_FFFF), out=bits)
        if bits.max() > _MAX_BITS:
            return False
        np.subtract(bits, np.uint64(1), out=bits)
        if bits.min() < _TINY_BITS - np.uint64(1):
            return False
    return True


# -- HDF5 -----------------------------------------------------------------------------------
def _h5():
    import h5py
    from h5py import h5d, h5l, h5s, h5t, h5z

    return h5py, h5d, h5l, h5s, h5t, h5z


def h5_child(group, path: str, where, *, what: str = "object"):
    """``group[path]`` following **hard links only**, one component at a time.

    Soft links, external links and user-defined links are refused without being followed
    (an external link would open another file; a soft link is not how Keras writes weights).
    """
    h5py, _, h5l, *_ = _h5()
    parts = [p for p in str(path).split("/")]
    if not parts or any(p in ("", ".", "..") for p in parts):
        raise BRDFFormatError(where, f"expected a relative HDF5 path for {what}, found {path!r}")
    obj = group
    for k, part in enumerate(parts):
        if not isinstance(obj, h5py.Group):
            raise BRDFFormatError(where, f"expected a group at {'/'.join(parts[:k])!r}, found a "
                                         f"{type(obj).__name__}")
        key = part.encode("utf-8", "surrogateescape")
        if not obj.id.links.exists(key):
            raise BRDFFormatError(where, f"expected {what} {path!r}, found no {part!r} in "
                                         f"{obj.name!r}")
        kind = obj.id.links.get_info(key).type
        if kind != h5l.TYPE_HARD:
            label = {h5l.TYPE_SOFT: "a soft link", h5l.TYPE_EXTERNAL: "an external link"}.get(
                kind, f"a user-defined link (type {kind})")
            raise BRDFFormatError(where, f"expected {what} {path!r} stored in the file, found "
                                         f"{label} at {part!r} (links are not followed)")
        obj = obj[part]
    return obj


def h5_hard_child(group, name: str):
    """``group[name]`` when ``name`` is a single component reached by a hard link, else
    ``None`` (nothing is followed)."""
    h5py, _, h5l, *_ = _h5()
    if not isinstance(group, h5py.Group) or not name or "/" in name or name in (".", ".."):
        return None
    key = name.encode("utf-8", "surrogateescape")
    if not group.id.links.exists(key) or group.id.links.get_info(key).type != h5l.TYPE_HARD:
        return None
    return group[name]


def h5_string_list_attr(obj, name: str, where, *, max_len: int) -> list[str]:
    """A 1-D attribute of (byte) strings, checked before it is read (``[]`` when absent or
    an empty array of any type, as Keras writes for weightless layers)."""
    _, _, _, h5s, h5t, _ = _h5()
    from h5py import h5a

    key = name.encode()
    if not h5a.exists(obj.id, key):
        return []
    aid = h5a.open(obj.id, key)
    space = aid.get_space()
    if space.get_simple_extent_type() != h5s.SIMPLE or len(space.shape) != 1:
        raise BRDFFormatError(where, f"expected attribute {name!r} of {obj.name!r} as a 1-D "
                                     f"array, found shape {space.shape}")
    n = int(space.shape[0])
    if n > max_len:
        raise BRDFFormatError(where, f"expected at most {max_len} entries in attribute "
                                     f"{name!r} of {obj.name!r}, found {n}")
    if n == 0:
        return []
    tid = aid.get_type()
    if tid.get_class() != h5t.STRING:
        raise BRDFFormatError(where, f"expected strings in attribute {name!r} of "
                                     f"{obj.name!r}, found HDF5 type class {tid.get_class()}")
    if not tid.is_variable_str() and tid.get_size() > 4096:
        raise BRDFFormatError(where, f"expected short strings in attribute {name!r}, found "
                                     f"{tid.get_size()} bytes each")
    values = obj.attrs[name]
    out = []
    for v in np.asarray(values, dtype=object).ravel():
        s = v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)
        if len(s) > 4096:
            raise BRDFFormatError(where, f"expected short strings in attribute {name!r}, found "
                                         f"one of {len(s)} characters")
        out.append(s)
    return out


_IEEE_NAMES = ("F16LE", "F16BE", "F32LE", "F32BE", "F64LE", "F64BE")
_IEEE_NUMPY = ("<f2", ">f2", "<f4", ">f4", "<f8", ">f8")


def _ieee_dtype(dset) -> np.dtype | None:
    _, _, _, _, h5t, _ = _h5()
    tid = dset.id.get_type()
    if tid.get_class() != h5t.FLOAT:
        return None
    for name, np_name in zip(_IEEE_NAMES, _IEEE_NUMPY):
        if tid.equal(getattr(h5t, "IEEE_" + name)):
            return np.dtype(np_name)
    return None


def _type_label(dset) -> str:
    try:
        return str(dset.dtype)
    except Exception:  # no NumPy equivalent (bitfield, reference, opaque...)
        return f"HDF5 type class {dset.id.get_type().get_class()}"


def h5_dataset_shape(dset, where, label: str, *, ndim: int, max_dim: int,
                     max_elements: int) -> tuple[int, ...]:
    """Validate a dataset **without reading its data** and return its shape.

    Accepted: a dataset stored inside the file (compact, contiguous, or chunked with the
    gzip/shuffle/fletcher32 filters only), of an IEEE float type (16/32/64-bit, either byte
    order), with ``ndim`` dimensions each in ``1..max_dim`` and at most ``max_elements``
    elements (also per chunk). Refused with a message naming the dataset: virtual datasets
    (VDS), external storage, other filters, other types, scalar/null/absurd shapes.
    """
    h5py, h5d, _, h5s, _, h5z = _h5()
    if not isinstance(dset, h5py.Dataset):
        raise BRDFFormatError(where, f"expected {label} as an HDF5 dataset, found a "
                                     f"{type(dset).__name__}")
    dcpl = dset.id.get_create_plist()
    layout = dcpl.get_layout()
    if layout == h5d.VIRTUAL:
        raise BRDFFormatError(where, f"expected {label} stored in the file, found a virtual "
                                     f"dataset (VDS) mapping other files")
    if dcpl.get_external_count() > 0:
        ext = dcpl.get_external(0)[0]
        raise BRDFFormatError(where, f"expected {label} stored in the file, found external "
                                     f"storage in {ext!r}")
    if layout not in (h5d.COMPACT, h5d.CONTIGUOUS, h5d.CHUNKED):
        raise BRDFFormatError(where, f"expected {label} with a compact, contiguous or chunked "
                                     f"layout, found layout {layout}")
    space = dset.id.get_space()
    if space.get_simple_extent_type() != h5s.SIMPLE:
        kind = "a scalar" if space.get_simple_extent_type() == h5s.SCALAR else "an empty"
        raise BRDFFormatError(where, f"expected {label} as a {ndim}-D array, found {kind} "
                                     f"dataspace")
    shape = tuple(int(n) for n in space.shape)
    if len(shape) != ndim or any(n < 1 or n > max_dim for n in shape) \
            or math.prod(shape) > max_elements:
        raise BRDFFormatError(where, f"expected {label} as a {ndim}-D array of dimensions "
                                     f"1..{max_dim} and at most {max_elements} elements, found "
                                     f"shape {shape}")
    if _ieee_dtype(dset) is None:
        raise BRDFFormatError(where, f"expected {label} of IEEE float16/32/64 type, found "
                                     f"{_type_label(dset)}")
    allowed = (h5z.FILTER_DEFLATE, h5z.FILTER_SHUFFLE, h5z.FILTER_FLETCHER32)
    for i in range(dcpl.get_nfilters()):
        code, _, _, fname = dcpl.get_filter(i)
        if code not in allowed:
            raise BRDFFormatError(where, f"expected {label} uncompressed or with the gzip, "
                                         f"shuffle and fletcher32 filters, found filter {code} "
                                         f"({fname.decode('utf-8', 'replace')!r})")
    if layout == h5d.CHUNKED:
        chunk = tuple(int(c) for c in dcpl.get_chunk())
        if len(chunk) != ndim or any(c < 1 for c in chunk) or math.prod(chunk) > max_elements:
            raise BRDFFormatError(where, f"expected chunks of {label} of at most {max_elements} "
                                         f"elements, found chunk shape {chunk}")
    return shape


def h5_read_dataset(dset, where, label: str, *, max_raw_bytes: int) -> np.ndarray:
    """Read a dataset validated by :func:`h5_dataset_shape` as a native float64 array.

    Chunked datasets are read chunk by chunk as raw bytes and their filters undone here, each
    inflation capped at the chunk's size: HDF5's own deflate filter grows its buffer without
    bound, so a lying chunk could inflate to gigabytes. Chunks never written hold the fill
    value (HDF5's semantics).
    """
    _, h5d, _, _, _, h5z = _h5()
    dtype = _ieee_dtype(dset)
    dcpl = dset.id.get_create_plist()
    shape = tuple(int(n) for n in dset.id.get_space().shape)
    if dcpl.get_layout() != h5d.CHUNKED:
        from h5py import h5s

        out = np.empty(shape, dtype=dtype)
        dset.id.read(h5s.ALL, h5s.ALL, out)
        return out.astype(np.float64)
    chunk = tuple(int(c) for c in dcpl.get_chunk())
    filters = [dcpl.get_filter(i)[0] for i in range(dcpl.get_nfilters())]
    chunk_bytes = math.prod(chunk) * dtype.itemsize
    fill = np.zeros(1, dtype=dtype)
    dcpl.get_fill_value(fill)
    out = np.full(shape, fill[0], dtype=np.float64)
    n_grid = math.prod(-(-s // c) for s, c in zip(shape, chunk))
    n = dset.id.get_num_chunks()
    if n > n_grid:
        raise BRDFFormatError(where, f"expected at most {n_grid} chunks in {label}, found {n}")
    for i in range(n):
        info = dset.id.get_chunk_info(i)
        offset = tuple(int(o) for o in info.chunk_offset)
        if any(o % c or o >= s for o, c, s in zip(offset, chunk, shape)):
            raise BRDFFormatError(where, f"expected chunk offsets of {label} on the chunk grid "
                                         f"{chunk} inside {shape}, found {offset}")
        if info.size > max_raw_bytes:
            raise BRDFFormatError(where, f"expected chunks of {label} of at most "
                                         f"{max_raw_bytes} stored bytes, found {info.size}")
        mask, raw = dset.id.read_direct_chunk(offset)
        data = bytes(raw)
        if len(data) != info.size:
            raise BRDFFormatError(where, f"expected a chunk of {label} of {info.size} stored "
                                         f"bytes, found {len(data)}")
        for k in reversed(range(len(filters))):
            if mask & (1 << k):
                continue  # this filter was skipped for this chunk
            code = filters[k]
            if code == h5z.FILTER_FLETCHER32:
                if len(data) < 4:
                    raise BRDFFormatError(where, f"expected a fletcher32 checksum in a chunk of "
                                                 f"{label}, found {len(data)} bytes")
                data = data[:-4]
            elif code == h5z.FILTER_DEFLATE:
                cap = chunk_bytes + 4 * filters.count(h5z.FILTER_FLETCHER32)
                d = zlib.decompressobj()
                try:
                    inflated = d.decompress(data, cap + 1)
                except zlib.error as exc:
                    raise BRDFFormatError(where, f"expected a valid gzip chunk in {label}, found "
                                                 f"a corrupt one ({exc})") from None
                if len(inflated) > cap or (not d.eof and d.unconsumed_tail):
                    raise BRDFFormatError(where, f"expected a chunk of {label} inflating to "
                                                 f"{chunk_bytes} bytes, found it inflating "
                                                 f"beyond {cap} bytes (compression bomb)")
                if not d.eof:
                    raise BRDFFormatError(where, f"expected a complete gzip chunk in {label}, "
                                                 f"found a truncated stream")
                data = inflated
            elif code == h5z.FILTER_SHUFFLE:
                k_size = dtype.itemsize
                m = len(data) // k_size
                head = np.frombuffer(data[:m * k_size], np.uint8).reshape(k_size, m)
                data = head.T.tobytes() + data[m * k_size:]
        if len(data) != chunk_bytes:
            raise BRDFFormatError(where, f"expected chunks of {label} of {chunk_bytes} bytes "
                                         f"once decoded, found {len(data)}")
        block = np.frombuffer(data, dtype=dtype).reshape(chunk)
        sl = tuple(slice(o, min(o + c, s)) for o, c, s in zip(offset, chunk, shape))
        with np.errstate(invalid="ignore"):  # NaN payloads: refused later, with the file named
            out[sl] = block[tuple(slice(0, x.stop - x.start) for x in sl)]
    return out

