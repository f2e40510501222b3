"""Readers and writers of measured BRDF formats and of fitted models, and :func:`load`.

==================  ==========================================  ===========================
format              reader / writer                              returns
==================  ==========================================  ===========================
MERL ``.binary``    :func:`read_merl` / :func:`write_merl`,      :class:`~.merl.MERLBRDF`
                    :func:`resample_to_merl`
Neural-BRDF         :func:`read_nbrdf` (``.h5``),                :class:`~.nbrdf.NBRDF`
                    :func:`read_nbrdf_collection` (``.zip``)
RGL ``.bsdf``       :func:`read_rgl`                             ``RGLBRDF``
UTIA ``.bin``       :func:`read_utia` / :func:`write_utia`       :class:`~.utia.UTIABRDF`
fit files ``.npz``  :func:`save_fit` / :func:`load_fit`          the fitted model
==================  ==========================================  ===========================

:func:`load` accepts any of these paths and ``collection.zip:material``; ``synthetic:NAME``
is read by :func:`brdffit.load` (:mod:`brdffit.loading`), above the readers.
Submodules are imported lazily so that ``import brdffit.io`` stays cheap.
"""

from __future__ import annotations

import os
from importlib import import_module
from pathlib import Path

from typing import TYPE_CHECKING

from ..errors import BRDFFormatError

if TYPE_CHECKING:                       # annotations only: keeps `import brdffit.io` cheap
    from ..brdf import BRDF

__all__ = ["load", "resolve_spec", "data_search_path", "find_data_file", "read_merl", "write_merl",
           "resample_to_merl", "read_nbrdf", "read_nbrdf_collection", "list_materials",
           "read_utia", "write_utia", "read_rgl", "save_fit", "load_fit", "SUPPORTED_FORMATS"]

_LAZY = {
    "read_merl": ".merl", "write_merl": ".merl", "resample_to_merl": ".merl",
    "MERLBRDF": ".merl",
    "read_nbrdf": ".nbrdf", "read_nbrdf_collection": ".nbrdf", "list_materials": ".nbrdf",
    "NBRDF": ".nbrdf",
    "read_utia": ".utia", "write_utia": ".utia", "UTIABRDF": ".utia",
    "read_rgl": ".rgl",
    "save_fit": ".fitfile", "load_fit": ".fitfile",
}

#: Format name → the reader :func:`load` calls (imported on first use, through ``_LAZY``).
_READERS = {"merl": "read_merl", "nbrdf": "read_nbrdf", "rgl": "read_rgl", "utia": "read_utia",
            "fit": "load_fit"}

#: Extension → format name understood by :func:`load`.
SUPPORTED_FORMATS = {".binary": "merl", ".h5": "nbrdf", ".zip": "nbrdf-collection",
                     ".bsdf": "rgl", ".bin": "utia", ".npz": "fit"}


def _lazy(name: str):
    """The public name ``name`` of a reader module, which is imported on first use."""
    return getattr(import_module(_LAZY[name], __name__), name)


def _checks():
    """:mod:`brdffit.io._limits` (the checks of files and archives before they are read),
    imported on first use: it imports NumPy."""
    from . import _limits

    return _limits


def __getattr__(name):
    if name in _LAZY:
        return _lazy(name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def data_search_path() -> list[Path]:
    """Folders searched for a *relative* path that does not exist in the working directory.

    ``$BRDFFIT_DATA`` (``os.pathsep``-separated), then, in a development checkout, the
    ``../shared/data`` tree next to the repository and its ``nbrdf``, ``rgl`` sub-folders.
    This is what makes ``merl_nbrdf.zip:gold-metallic-paint`` work from any folder.
    """
    dirs = [Path(p) for p in os.environ.get("BRDFFIT_DATA", "").split(os.pathsep) if p]
    shared = Path(__file__).resolve().parents[3].parent / "shared" / "data"
    dirs += [shared, shared / "nbrdf", shared / "rgl"]
    return [d for d in dirs if d.is_dir()]


def find_data_file(path) -> Path | None:
    """``path`` if it exists, else the first match under :func:`data_search_path` (relative
    paths only), else ``None``."""
    path = Path(path)
    if path.exists():
        return path
    if not path.is_absolute():
        for d in data_search_path():
            if (d / path).exists():
                return d / path
    return None


_find = find_data_file  # used by brdffit.batch


def _sniff(path: Path) -> str | None:
    """Format from the first bytes (for files with an unknown or misleading extension).

    ``path`` must be a regular file (checked by :func:`resolve_spec`: a FIFO would block).
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(16)
    except OSError:
        return None
    if head.startswith(b"tensor_file\0"):
        return "rgl"
    if head.startswith(b"\x89HDF\r\n\x1a\n"):
        return "nbrdf"
    if head.startswith(b"PK"):
        try:
            with _checks().open_zip(path, "a .zip archive") as zf:
                names = zf.namelist()
        except BRDFFormatError:
            return None
        return "fit" if "__header__.npy" in names else "nbrdf-collection"
    if len(head) >= 12:
        import numpy as np

        if tuple(np.frombuffer(head[:12], "<i4")) == (90, 90, 180):
            return "merl"
    from .utia import UTIA_FILE_SIZE

    try:
        if path.stat().st_size == UTIA_FILE_SIZE:
            return "utia"
    except OSError:
        return None
    return None


def _check_path_text(text: str, shown) -> None:
    if "\0" in text:
        raise BRDFFormatError(shown, "expected a path or spec without NUL bytes, found one")


def _find_checked(path: Path, shown) -> Path | None:
    """:func:`find_data_file` with path errors (name too long, ...) as ``BRDFFormatError``."""
    try:
        return _find(path)
    except (OSError, ValueError) as exc:
        raise BRDFFormatError(shown, f"expected a BRDF file, found an unusable path "
                                     f"({_checks().describe_exception(exc)})") from None


def resolve_spec(spec) -> tuple[str, Path | None, str | None]:
    """Split a load spec into ``(kind, path, member)``.

    ``kind`` is a format name of :data:`SUPPORTED_FORMATS` or ``"synthetic"``; ``member`` is
    the material of a ``.zip`` collection or the synthetic name. Raises
    :class:`~brdffit.errors.BRDFFormatError` for a missing file, a path that is not a regular
    file (directory, FIFO, device: never opened) or an unknown format.
    """
    text = os.fspath(spec)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    _check_path_text(text, text)
    if text.startswith("synthetic:"):
        return "synthetic", None, text[len("synthetic:"):]
    path = Path(text)
    member = None
    found = _find_checked(path, text)
    if found is None and ":" in text:
        # archive.zip:material  (the zip part may be relative, absolute or on the data path)
        head, _, tail = text.rpartition(":")
        zpath = _find_checked(Path(head), head)
        if zpath is not None and zpath.is_file():
            found, member = zpath, tail
        elif head.lower().endswith(".zip"):
            raise BRDFFormatError(head, "expected a .zip collection, found no such file")
    if found is None:
        raise BRDFFormatError(text, "expected a BRDF file or spec (path, collection.zip:material "
                                    "or synthetic:NAME), found no such file")
    _checks().regular_file_size(found, "a BRDF file")  # directories, FIFOs, devices: never opened
    kind = SUPPORTED_FORMATS.get(found.suffix.lower()) or _sniff(found)
    if kind is None:
        raise BRDFFormatError(found, f"expected one of the formats {sorted(SUPPORTED_FORMATS)} "
                                     f"(by extension or content), found an unrecognised file")
    if member is not None and kind != "nbrdf-collection":
        raise BRDFFormatError(found, f"expected a .zip collection before ':{member}', "
                                     f"found a {kind} file")
    return kind, found, member


def load(spec: str | os.PathLike, **options) -> BRDF:
    """Load a BRDF from a path or spec and return it (a :class:`~brdffit.brdf.BRDF`).

    ``spec`` is one of

    * a file: ``.binary`` (MERL), ``.h5`` (Neural-BRDF), ``.bsdf`` (RGL), ``.bin`` (UTIA),
      ``.npz`` (brdffit fit file); unknown extensions are recognised by content;
    * ``collection.zip:material`` (Neural-BRDF collection; the zip path may be relative,
      absolute, or a bare file name found on :func:`data_search_path`);
    ``synthetic:NAME`` raises :class:`~brdffit.errors.BRDFFormatError` here: the synthetic
    materials build models, a layer above the readers; :func:`brdffit.load` reads them.

    Keyword ``options`` go to the reader (e.g. ``interpolation="nearest"`` for MERL,
    ``precision="float64"`` for Neural-BRDF).
    """
    kind, path, member = resolve_spec(spec)
    if kind == "synthetic":  # built by brdffit.synthetic, a layer above the readers
        raise BRDFFormatError(os.fspath(spec), "expected a file spec, found a synthetic "
                                               "material: brdffit.load reads synthetic:NAME")
    if kind == "nbrdf-collection":
        if not member:
            names = _lazy("list_materials")(path)
            shown = ", ".join(names[:10]) + (", ..." if len(names) > 10 else "")
            raise BRDFFormatError(path, f"expected collection.zip:material, found no material; "
                                        f"{len(names)} materials: {shown}")
        return _lazy("read_nbrdf_collection")(path, member, **options)
    if kind in _READERS:  # the reader's module is imported now, not by `import brdffit.io`
        return _lazy(_READERS[kind])(path, **options)
    raise BRDFFormatError(path, f"unsupported format {kind!r}")  # pragma: no cover
