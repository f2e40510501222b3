"""The versioned on-disk format of fitted models (``.npz`` + JSON header).

A fit file is a NumPy ``.npz`` archive holding the model's tables (float32 unless a model
needs more) and one ``__header__`` entry: UTF-8 JSON with

``{"format": "brdffit-fit", "version": 1, "model": KIND, "params": {...},
"source": {"spec": ..., "sha256": ...}, "options": {...}, "fit_info": {...},
"brdffit_version": ..., "created": ISO-8601}``.

Models take part by subclassing :class:`~brdffit.serialization.SerializableModel` (re-exported
here) with a unique ``fit_kind``, implementing ``to_state`` / ``from_state`` and declaring a
``state_schema`` (:mod:`brdffit.schema`). Writing is atomic.

Loading files brdffit did not write
-----------------------------------
:func:`load_fit` trusts nothing in the file, and never uses :func:`numpy.load` (which
decompresses whole members and can unpickle). It reads the zip directory itself and, in this
order, before any table is decompressed:

1. the archive: at most :data:`MAX_MEMBERS` ``.npy`` members, no duplicates, no encryption,
   stored or deflated only, each declaring at most :data:`MAX_MEMBER_BYTES` uncompressed
   (:data:`MAX_HEADER_BYTES` for ``__header__``) and :data:`MAX_TOTAL_BYTES` in all;
2. each member's ``.npy`` header (magic, version 1.0/2.0, ≤ 64 KiB, parsed from a capped
   stream): object dtypes are refused (nothing is ever unpickled);
3. the JSON header: an object, at most 64 levels deep, ``format`` = ``brdffit-fit``,
   ``version`` an integer (not a boolean) from 1 to :data:`FORMAT_VERSION`, a known ``model``;
4. the model's schema on the parameters and the *declared* shapes and dtypes (so a table
   declaring 24 TiB, or one of the wrong shape, is refused unread); each member's size must
   equal its header plus the declared data;

then reads each table with a hard byte cap (a deflate stream that inflates past its declared
size, or fails its CRC, is an error) and checks the schema again on the values (finite,
physical ranges). Every problem is one :class:`~brdffit.errors.BRDFFormatError` naming the
file and the field (``params.distribution.params.alpha_x: expected a finite number > 0 and
<= 100, found -1``). :func:`save_fit` applies the same schema, so a model whose state would
not load is not written.
"""

from __future__ import annotations

import datetime as _dt
import json
import zipfile
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.lib import format as _npy

from .._atomic import atomic_write
from .._json import strict_json_default

if TYPE_CHECKING:
    from ..brdf import BRDF
from ..errors import BRDFFormatError
from ._checksum import source_checksum
from ..schema import ArrayHeader, StateError, show
from ..serialization import SerializableModel, model_registry, resolve_kind
from .._version import __version__

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "SerializableModel", "save_fit", "load_fit",
           "read_fit_header", "is_fit_file", "source_checksum", "model_registry",
           "MAX_FILE_BYTES", "MAX_MEMBERS", "MAX_MEMBER_BYTES", "MAX_TOTAL_BYTES",
           "MAX_HEADER_BYTES"]

FORMAT_NAME = "brdffit-fit"
FORMAT_VERSION = 1
#: oldest format version this brdffit reads
MIN_FORMAT_VERSION = 1

#: size of a fit file on disk
MAX_FILE_BYTES = 512 << 20
#: members of the archive (tables + header)
MAX_MEMBERS = 256
#: declared uncompressed size of one table member
MAX_MEMBER_BYTES = 64 << 20
#: declared uncompressed size of all members together
MAX_TOTAL_BYTES = 256 << 20
#: the JSON header (a fit's header is a few kB)
MAX_HEADER_BYTES = 4 << 20
#: a ``.npy`` member header (NumPy writes ~128 bytes)
MAX_NPY_HEADER = 64 << 10
#: nesting depth of the JSON header
MAX_JSON_DEPTH = 64

_HEADER_KEY = "__header__"


def _fail(path, problem: str) -> BRDFFormatError:
    return BRDFFormatError(path, " ".join(str(problem).split()))


def _why(exc: BaseException) -> str:
    text = " ".join(str(exc).split())[:300]
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


# ------------------------------------------------------------------------------------------
# writing
# ------------------------------------------------------------------------------------------
def save_fit(model: BRDF, path: str | os.PathLike, *, source=None, options: dict | None = None,
             fit_info: dict | None = None, source_sha256: str | None = None) -> Path:
    """Write ``model`` to ``path`` (``.npz``) atomically and return the path.

    Parameters
    ----------
    model : BRDF
        A fitted model that can be saved (``SerializableModel`` with a ``fit_kind``).
    path : str or os.PathLike
        The fit file to write (replaced atomically; nothing is written on error).
    source : str, optional
        The input's load spec (default ``model.source``), recorded with the SHA-256 of its
        file (:func:`source_checksum`), or ``source_sha256`` when the caller computed it.
    options, fit_info : dict, optional
        Recorded instead of ``model.fit_options`` / ``model.fit_info``.

    The state is checked against the model's schema first (exactly as :func:`load_fit` will
    read it): a model that could not be loaded back raises ``BRDFFormatError`` and nothing
    is written.
    """
    if not isinstance(model, SerializableModel) or not model.fit_kind:
        raise TypeError(f"{type(model).__name__} cannot be saved as a fit file")
    params, arrays = model.to_state()
    source = source if source is not None else getattr(model, "source", None)
    header = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "model": model.fit_kind,
        "name": getattr(model, "name", None),
        "params": params,
        "source": {"spec": None if source is None else str(source),
                   "sha256": source_sha256 if source_sha256 is not None
                   else source_checksum(source)},
        "options": options if options is not None else (model.fit_options or {}),
        "fit_info": fit_info if fit_info is not None else (model.fit_info or {}),
        "brdffit_version": __version__,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }
    for key in arrays:
        if key.startswith("__"):
            raise ValueError(f"array name {key!r} is reserved")
    blob = json.dumps(header, default=strict_json_default, sort_keys=True).encode("utf-8")
    path = Path(path)
    arrays = {k: np.asarray(v) for k, v in arrays.items()}
    # what load_fit will see: the JSON round trip of the header, the arrays as stored
    _check_header(path, json.loads(blob), len(blob), writing=True)
    _check_state(path, type(model), json.loads(blob)["params"], arrays, writing=True)
    for key, arr in arrays.items():
        if arr.nbytes > MAX_MEMBER_BYTES - MAX_NPY_HEADER:
            raise _fail(path, f"refusing to write a fit file that would not load: array "
                              f"{key!r} has {arr.nbytes} bytes (limit {MAX_MEMBER_BYTES})")
    with atomic_write(path) as fh:
        np.savez(fh, __header__=np.frombuffer(blob, dtype=np.uint8), **arrays)
    return path


# ------------------------------------------------------------------------------------------
# reading: the archive
# ------------------------------------------------------------------------------------------
class _Capped:
    """A read-only view of ``fh`` that yields at most ``limit`` bytes (counts them)."""

    def __init__(self, fh, limit: int):
        self.fh, self.left, self.consumed = fh, limit, 0

    def read(self, n: int = -1) -> bytes:
        n = self.left if n is None or n < 0 else min(n, self.left)
        data = self.fh.read(n) if n > 0 else b""
        self.left -= len(data)
        self.consumed += len(data)
        return data


class _Member:
    __slots__ = ("key", "info", "header", "fortran", "offset")

    def __init__(self, key, info):
        self.key, self.info = key, info
        self.header: ArrayHeader | None = None
        self.fortran = False
        self.offset = 0


class _FitArchive:
    """The members of a fit file, read with the checks of the module docstring."""

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.is_file():
            raise _fail(path, "no such fit file")
        size = self.path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise _fail(path, f"expected a fit file of at most {MAX_FILE_BYTES >> 20} MiB, "
                              f"found {size} bytes")
        try:
            self.zf = zipfile.ZipFile(self.path)
        except Exception as exc:  # noqa: BLE001 - zipfile raises many kinds on corrupt input
            raise _fail(path, f"expected a brdffit fit file (.npz zip archive), could not read "
                              f"it: {_why(exc)}") from None
        try:
            self.members = self._directory()
        except BaseException:
            self.zf.close()
            raise

    def close(self) -> None:
        self.zf.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _directory(self) -> dict[str, _Member]:
        infos = self.zf.infolist()
        if len(infos) > MAX_MEMBERS:
            raise _fail(self.path, f"expected at most {MAX_MEMBERS} members in the .npz, found "
                                   f"{len(infos)}")
        members: dict[str, _Member] = {}
        total = 0
        for info in infos:
            name = info.filename
            if not name.endswith(".npy") or len(name) > 260 or name.startswith("/"):
                raise _fail(self.path, f"expected .npy members in the .npz, found {name[:80]!r}")
            key = name[:-4]
            if not key:
                raise _fail(self.path, f"expected named .npy members, found {name!r}")
            if key in members:
                raise _fail(self.path, f"member {name[:80]!r} is duplicated")
            if info.flag_bits & 0x1:
                raise _fail(self.path, f"member {name!r} is encrypted")
            if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
                raise _fail(self.path, f"member {name!r}: expected stored or deflated data, "
                                       f"found compression method {info.compress_type}")
            limit = MAX_HEADER_BYTES + MAX_NPY_HEADER if key == _HEADER_KEY else MAX_MEMBER_BYTES
            if info.file_size > limit:
                raise _fail(self.path, f"member {name!r} declares {info.file_size} bytes "
                                       f"uncompressed, more than the {limit} a fit-file "
                                       f"{'header' if key == _HEADER_KEY else 'table'} may have")
            total += info.file_size
            members[key] = _Member(key, info)
        if total > MAX_TOTAL_BYTES:
            raise _fail(self.path, f"members declare {total} bytes uncompressed in all, more "
                                   f"than the {MAX_TOTAL_BYTES} a fit file may have")
        if _HEADER_KEY not in members:
            raise _fail(self.path, f"expected a '{_HEADER_KEY}' entry in the .npz, found none")
        return members

    def _open(self, m: _Member):
        """Open member ``m`` and parse its ``.npy`` header; returns the open stream."""
        name = m.info.filename
        try:
            fh = self.zf.open(m.info)
        except Exception as exc:  # noqa: BLE001
            raise _fail(self.path, f"could not open member {name!r}: {_why(exc)}") from None
        try:
            capped = _Capped(fh, MAX_NPY_HEADER)
            version = _npy.read_magic(capped)
            if version == (1, 0):
                shape, fortran, dtype = _npy.read_array_header_1_0(capped, MAX_NPY_HEADER)
            elif version == (2, 0):
                shape, fortran, dtype = _npy.read_array_header_2_0(capped, MAX_NPY_HEADER)
            else:
                raise ValueError(f"unsupported .npy format version {version}")
        except BRDFFormatError:
            fh.close()
            raise
        except Exception as exc:  # noqa: BLE001 - corrupt header / deflate stream / CRC
            fh.close()
            raise _fail(self.path, f"member {name!r}: expected a .npy array, could not read "
                                   f"its header: {_why(exc)}") from None
        dtype = np.dtype(dtype)
        if dtype.hasobject:
            fh.close()
            raise _fail(self.path, f"member {name!r} is an object array (pickled Python objects "
                                   f"are never loaded)")
        if not all(isinstance(s, int) and s >= 0 for s in shape) or len(shape) > 32:
            fh.close()
            raise _fail(self.path, f"member {name!r}: invalid shape {shape!r}")
        m.header = ArrayHeader(tuple(int(s) for s in shape), dtype)
        m.fortran = bool(fortran)
        m.offset = capped.consumed
        return fh

    def headers(self) -> dict[str, ArrayHeader]:
        """Shape and dtype of every table member (the ``.npy`` headers only)."""
        out = {}
        for key, m in self.members.items():
            if key == _HEADER_KEY:
                continue
            fh = self._open(m)
            fh.close()
            out[key] = m.header
        return out

    def check_sizes(self) -> None:
        """Each member must hold exactly its header plus its declared data."""
        for m in self.members.values():
            if m.header is None:
                continue
            nbytes = m.header.size * m.header.dtype.itemsize
            if m.info.file_size != m.offset + nbytes:
                raise _fail(self.path, f"member {m.info.filename!r}: its header declares shape "
                                       f"{m.header.shape} {m.header.dtype} ({nbytes} bytes of data), "
                                       f"the member holds {m.info.file_size - m.offset}")

    def read(self, key: str) -> np.ndarray:
        """The array of member ``key``, reading at most its declared bytes."""
        m = self.members[key]
        fh = self._open(m)
        name = m.info.filename
        nbytes = m.header.size * m.header.dtype.itemsize
        if m.info.file_size != m.offset + nbytes:
            fh.close()
            raise _fail(self.path, f"member {name!r}: its header declares {nbytes} bytes of "
                                   f"data, the member holds {m.info.file_size - m.offset}")
        try:
            buf = bytearray()
            while len(buf) < nbytes:
                chunk = fh.read(min(nbytes - len(buf), 1 << 22))
                if not chunk:
                    break
                buf += chunk
            extra = fh.read(1)      # reaching the end also checks the CRC
        except Exception as exc:  # noqa: BLE001 - zlib.error, BadZipFile (CRC), EOFError...
            raise _fail(self.path, f"member {name!r}: could not read its data: {_why(exc)}") \
                from None
        finally:
            fh.close()
        if len(buf) != nbytes or extra:
            raise _fail(self.path, f"member {name!r}: expected {nbytes} bytes of data, found "
                                   f"{len(buf) + len(extra)}{'+' if extra else ''}")
        shape, dtype = m.header.shape, m.header.dtype
        if nbytes == 0:
            return np.empty(shape, dtype=dtype)
        arr = np.frombuffer(buf, dtype=dtype)
        if m.fortran:
            return arr.reshape(shape[::-1]).transpose()
        return arr.reshape(shape)

    def header_bytes(self) -> bytes:
        m = self.members[_HEADER_KEY]
        fh = self._open(m)
        fh.close()
        h = m.header
        if h.dtype != np.uint8 or len(h.shape) != 1:
            raise _fail(self.path, f"expected the '{_HEADER_KEY}' entry to be a 1D uint8 array "
                                   f"(UTF-8 JSON), found shape {h.shape} {h.dtype}")
        if h.size > MAX_HEADER_BYTES:
            raise _fail(self.path, f"expected a fit header of at most {MAX_HEADER_BYTES} bytes, "
                                   f"found {h.size}")
        return self.read(_HEADER_KEY).tobytes()


# ------------------------------------------------------------------------------------------
# reading: header and state
# ------------------------------------------------------------------------------------------
def _json_depth_ok(obj) -> bool:
    stack = [(obj, 1)]
    while stack:
        o, d = stack.pop()
        if d > MAX_JSON_DEPTH:
            return False
        if isinstance(o, dict):
            stack.extend((v, d + 1) for v in o.values())
        elif isinstance(o, list):
            stack.extend((v, d + 1) for v in o)
    return True


def _type_name(v) -> str:
    return show(v)


def _parse_header(path, raw: bytes) -> dict:
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _fail(path, f"fit header is not UTF-8 text: {_why(exc)}") from None
    try:
        header = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise _fail(path, f"fit header is not valid JSON: {_why(exc)}") from None
    _check_header(path, header, len(raw))
    return header


def _check_header(path, header, nbytes: int, *, writing: bool = False) -> None:
    pre = "refusing to write a fit file that would not load: " if writing else ""
    if nbytes > MAX_HEADER_BYTES:
        raise _fail(path, f"{pre}expected a fit header of at most {MAX_HEADER_BYTES} bytes, "
                          f"found {nbytes}")
    if not isinstance(header, dict):
        raise _fail(path, f"{pre}expected the fit header to be a JSON object, found "
                          f"{_type_name(header)}")
    if not _json_depth_ok(header):
        raise _fail(path, f"{pre}fit header: expected JSON nested at most {MAX_JSON_DEPTH} "
                          f"levels deep, found deeper")
    fmt = header.get("format")
    if fmt != FORMAT_NAME:
        raise _fail(path, f"{pre}format: expected {FORMAT_NAME!r}, found {_type_name(fmt)}")
    v = header.get("version")
    if not isinstance(v, int) or isinstance(v, bool) or v < MIN_FORMAT_VERSION:
        raise _fail(path, f"{pre}version: expected a fit format version, an integer from "
                          f"{MIN_FORMAT_VERSION} to {FORMAT_VERSION}, found {_type_name(v)}")
    if v > FORMAT_VERSION:
        raise _fail(path, f"{pre}version: fit format version {v} is newer than this brdffit "
                          f"supports ({FORMAT_VERSION})")
    kind = header.get("model")
    if not isinstance(kind, str) or not kind or len(kind) > 256:
        raise _fail(path, f"{pre}model: expected a model kind name, found {_type_name(kind)}")
    if not isinstance(header.get("params"), dict):
        raise _fail(path, f"{pre}params: expected an object, found "
                          f"{_type_name(header.get('params'))}")
    for key in ("options", "fit_info", "source"):
        if header.get(key) is not None and not isinstance(header[key], dict):
            raise _fail(path, f"{pre}{key}: expected an object, found {_type_name(header[key])}")
    for key in ("name", "brdffit_version", "created"):
        if header.get(key) is not None and not isinstance(header[key], str):
            raise _fail(path, f"{pre}{key}: expected a string, found {_type_name(header[key])}")
    src = header.get("source") or {}
    for key in ("spec", "sha256"):
        if src.get(key) is not None and not isinstance(src[key], str):
            raise _fail(path, f"{pre}source.{key}: expected a string, found "
                              f"{_type_name(src[key])}")


def _resolve(path, kind: str) -> type:
    try:
        return resolve_kind(kind)
    except KeyError as exc:
        raise _fail(path, f"model: {str(exc).strip(chr(34) + chr(39))}") from None
    except ValueError as exc:
        raise _fail(path, f"model: {exc}") from None


def _check_state(path, cls, params, arrays, *, writing: bool = False) -> None:
    try:
        cls.validate_state(params, arrays)
    except StateError as exc:
        pre = (f"refusing to write a {cls.fit_kind!r} fit file that would not load: "
               if writing else f"invalid {cls.fit_kind!r} fit: ")
        raise _fail(path, f"{pre}{exc}") from None


def read_fit_header(path) -> dict:
    """The JSON header of a fit file (checked: an object, format, version, model kind)."""
    with _FitArchive(path) as ar:
        return _parse_header(path, ar.header_bytes())


def is_fit_file(path) -> bool:
    """True when ``path`` is a brdffit fit file with a readable, well-formed header."""
    try:
        read_fit_header(path)
        return True
    except BRDFFormatError:
        return False


def load_fit(path: str | os.PathLike) -> BRDF:
    """Load a model written by :func:`save_fit`, validating it (see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        A fit file (``.npz``); treated as untrusted: sizes, shapes, dtypes and values are
        checked against the model's schema before anything is decompressed or built.

    Returns
    -------
    BRDF
        The fitted model, with ``fit_info``, ``fit_options`` and ``source`` from the file.

    Raises :class:`~brdffit.errors.BRDFFormatError` naming the file (and the field) for any
    file that is not a well-formed fit of a known kind within its schema.
    """
    path_ = Path(path)
    with _FitArchive(path_) as ar:
        header = _parse_header(path, ar.header_bytes())
        cls = _resolve(path, header["model"])
        params = header["params"]
        _check_state(path, cls, params, ar.headers())       # shapes/dtypes, before any data
        ar.check_sizes()
        arrays = {k: ar.read(k) for k in ar.members if k != _HEADER_KEY}
    _check_state(path, cls, params, arrays)                  # values
    try:
        model = cls.from_state(params, arrays)
    except (BRDFFormatError, MemoryError, RecursionError):
        raise
    except Exception as exc:  # noqa: BLE001 - one clear error for any state from_state refuses
        raise _fail(path, f"invalid {header['model']!r} fit: {_why(exc)}") from None
    model.fit_info = header.get("fit_info") or {}
    model.fit_options = header.get("options") or {}
    src = (header.get("source") or {}).get("spec")
    if src and getattr(model, "source", None) is None:
        try:
            model.source = src
        except AttributeError:
            pass
    return model


def table_bytes(model) -> int:
    """Bytes of the model's numerical tables (what the papers report as model size)."""
    _, arrays = model.to_state()
    return int(sum(np.asarray(a).nbytes for a in arrays.values()))


__all__.append("table_bytes")
