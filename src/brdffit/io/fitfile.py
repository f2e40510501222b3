"""The versioned on-disk format of fitted models (``.npz`` + JSON header).

A fit file is a NumPy ``.npz`` archive holding the model's tables (float32 unless a model
needs more) and one ``__header__`` entry: UTF-8 JSON with

``{"format": "brdffit-fit", "version": 1, "model": KIND, "params": {...},
"source": {"spec": ..., "sha256": ...}, "options": {...}, "fit_info": {...},
"brdffit_version": ..., "created": ISO-8601}``.

Models take part by subclassing :class:`SerializableModel` with a unique ``fit_kind`` and
implementing ``to_state`` / ``from_state``. Writing is atomic.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import zipfile
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from .._atomic import atomic_write
from .._json import strict_json_default
from ..errors import BRDFFormatError

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "SerializableModel", "save_fit", "load_fit",
           "read_fit_header", "is_fit_file", "source_checksum", "model_registry"]

FORMAT_NAME = "brdffit-fit"
FORMAT_VERSION = 1
_REGISTRY: dict[str, type] = {}


def model_registry() -> dict[str, type]:
    """Registered model kinds (``fit_kind`` → class)."""
    return dict(_REGISTRY)


class SerializableModel:
    """Mixin for fitted models that can be saved with :func:`save_fit`.

    Subclasses set ``fit_kind`` (unique string) and implement :meth:`to_state` and
    :meth:`from_state`. ``fit_info`` (eigenvalue, timings, convergence...) and
    ``fit_options`` are saved in the header when present.
    """

    fit_kind: ClassVar[str] = ""
    fit_info: dict | None = None
    fit_options: dict | None = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        kind = cls.__dict__.get("fit_kind")
        if kind:
            if kind in _REGISTRY and _REGISTRY[kind].__qualname__ != cls.__qualname__:
                raise TypeError(f"fit_kind {kind!r} registered twice")
            _REGISTRY[kind] = cls

    def to_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """Return ``(params, arrays)``: JSON-able parameters and named arrays."""
        raise NotImplementedError

    @classmethod
    def from_state(cls, params: dict[str, Any], arrays: dict[str, np.ndarray]):
        """Rebuild the model from :meth:`to_state` output."""
        raise NotImplementedError


def source_checksum(spec) -> str | None:
    """SHA-256 of the file behind a load spec (``path`` or ``archive.zip:member``)."""
    if spec is None:
        return None
    path = Path(str(spec).split(":", 1)[0] if ":" in str(spec) and not Path(str(spec)).exists()
                else str(spec))
    if not path.is_file():
        return None
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def save_fit(model, path, *, source=None, options: dict | None = None,
             fit_info: dict | None = None) -> Path:
    """Write ``model`` to ``path`` (``.npz``) atomically and return the path."""
    from .. import __version__

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
                   "sha256": source_checksum(source)},
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
    with atomic_write(path) as fh:
        np.savez(fh, __header__=np.frombuffer(blob, dtype=np.uint8),
                 **{k: np.asarray(v) for k, v in arrays.items()})
    return path


def _open(path) -> tuple[dict, dict[str, np.ndarray]]:
    path = Path(path)
    if not path.is_file():
        raise BRDFFormatError(path, "no such fit file")
    try:
        with np.load(path, allow_pickle=False) as npz:
            data = {k: npz[k] for k in npz.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise BRDFFormatError(path, f"expected a brdffit fit file (.npz), could not read it: {exc}")
    if "__header__" not in data:
        raise BRDFFormatError(path, "expected a '__header__' entry in the .npz, found none")
    try:
        header = json.loads(data.pop("__header__").tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise BRDFFormatError(path, f"fit header is not valid JSON: {exc}")
    if header.get("format") != FORMAT_NAME:
        raise BRDFFormatError(path, f"expected format {FORMAT_NAME!r}, found {header.get('format')!r}")
    if not isinstance(header.get("version"), int) or header["version"] > FORMAT_VERSION:
        raise BRDFFormatError(path, f"fit format version {header.get('version')!r} is newer than "
                                    f"this brdffit supports ({FORMAT_VERSION})")
    return header, data


def read_fit_header(path) -> dict:
    """The JSON header of a fit file."""
    return _open(path)[0]


def is_fit_file(path) -> bool:
    """True when ``path`` is a readable brdffit fit file."""
    try:
        _open(path)
        return True
    except BRDFFormatError:
        return False


def load_fit(path):
    """Load a model written by :func:`save_fit`."""
    from .. import microfacet as _mf  # noqa: F401  (registers the analytic model kinds)
    from ..fit import import_all

    import_all()  # registers the fitted model kinds

    header, arrays = _open(path)
    kind = header.get("model")
    cls = _REGISTRY.get(kind)
    if cls is None:
        raise BRDFFormatError(path, f"unknown model kind {kind!r}; known: {sorted(_REGISTRY)}")
    for key, arr in arrays.items():
        if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
            raise BRDFFormatError(path, f"table {key!r} contains NaN or infinite values")
    try:
        model = cls.from_state(header.get("params", {}), arrays)
    except (KeyError, ValueError, TypeError) as exc:
        raise BRDFFormatError(path, f"invalid {kind!r} fit: {exc}")
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
