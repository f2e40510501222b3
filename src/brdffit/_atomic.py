"""Outputs: written whole or not at all, never replacing what is not a regular file.

Every file brdffit writes is first written to a temporary file in the destination folder and
then put in place by :func:`place`, the one way an output lands:

* a **new path** or an existing **regular file**: ``os.replace`` (atomic); a replaced file
  keeps its permission bits (and, when brdffit runs as root, its owner);
* a **symbolic link** whose target is a regular file or missing: the link itself is
  replaced by the new regular file (the file it pointed to is left as it was);
* a **character device or a FIFO** (``/dev/null``, ``/dev/stdout`` of a pipe, ``mkfifo``),
  also through a link: written *through*, as a shell redirection does: the finished
  temporary file is copied into it and the device or FIFO stays (``-o /dev/null`` discards);
* a **directory, socket or block device**: refused (:class:`OutputError`), nothing written.

:func:`destination_kind` tells which case a path is, :func:`check_writable` tries the
destination folder before any work starts, and every error names the user's path, never a
temporary one.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import tempfile
from pathlib import Path

from .errors import BRDFError, printable

__all__ = ["atomic_write", "atomic_path", "place", "destination_kind", "check_writable",
           "OutputError", "WRITE_THROUGH"]

#: Destination kinds written through instead of replaced (:func:`place`).
WRITE_THROUGH = ("character device", "FIFO")


class OutputError(BRDFError, OSError):
    """An output that cannot or must not be written (one line naming the path)."""


def destination_kind(path) -> str:
    """``"new"``, ``"regular file"``, ``"character device"``, ``"FIFO"``, ``"directory"``,
    ``"socket"``, ``"block device"`` or ``"other"``: what ``path`` is, following symbolic
    links (a dangling link is ``"new"``)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "new"
    except OSError:
        return "new" if not os.path.lexists(path) else "other"
    for test, name in ((stat.S_ISREG, "regular file"), (stat.S_ISDIR, "directory"),
                       (stat.S_ISCHR, "character device"), (stat.S_ISFIFO, "FIFO"),
                       (stat.S_ISSOCK, "socket"), (stat.S_ISBLK, "block device")):
        if test(mode):
            return name
    return "other"


def _refuse(path, kind: str) -> OutputError:
    return OutputError(f"{printable(str(path))}: expected a file name to write (a new path, a "
                       f"regular file, a character device or a FIFO), found a {kind}")


def check_writable(path) -> str:
    """Check, before any work, that ``path`` can be written by :func:`place`: its kind is
    allowed, its folder exists and a file can be created there. Returns the kind
    (:func:`destination_kind`); raises :class:`OutputError` (one line naming ``path``).

    The folder is not created: a mistyped folder is an error, not a new tree."""
    path = Path(path)
    kind = destination_kind(path)
    if kind in WRITE_THROUGH:
        if not os.access(path, os.W_OK):
            raise OutputError(f"{printable(str(path))}: cannot write the {kind} (permission "
                              "denied)")
        return kind
    if kind not in ("new", "regular file"):
        raise _refuse(path, kind)
    parent = path.parent
    if not parent.is_dir():
        found = destination_kind(parent)
        found = "none (create it first)" if found == "new" else f"a {found}"
        raise OutputError(f"{printable(str(path))}: expected a folder {printable(str(parent))}, "
                          f"found {found}")
    try:
        fd, probe = tempfile.mkstemp(prefix=".brdffit-probe.", dir=parent)
    except OSError as exc:
        raise OutputError(f"{printable(str(path))}: cannot write there "
                          f"({(exc.strerror or str(exc)).lower()})") from None
    os.close(fd)
    os.unlink(probe)
    return kind


def place(tmp, final) -> None:
    """Put the finished temporary file ``tmp`` at ``final`` (module docstring); ``tmp`` is
    gone afterwards (moved, or copied into a device or FIFO and removed)."""
    tmp, final = Path(tmp), Path(final)
    kind = destination_kind(final)
    try:
        if kind in WRITE_THROUGH:
            with open(tmp, "rb") as src, open(final, "wb") as dst:
                shutil.copyfileobj(src, dst, 1 << 20)
            os.unlink(tmp)
            return
        if kind not in ("new", "regular file"):
            raise _refuse(final, kind)
        if kind == "regular file" and not os.path.islink(final):
            st = os.stat(final)
            os.chmod(tmp, stat.S_IMODE(st.st_mode))
            if hasattr(os, "geteuid") and os.geteuid() == 0:
                with contextlib.suppress(OSError):
                    os.chown(tmp, st.st_uid, st.st_gid)
        os.replace(tmp, final)
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(f"{printable(str(final))}: could not write the file "
                          f"({(exc.strerror or str(exc)).lower()})") from None


@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None):
    """Yield a temporary path next to ``path``; on success :func:`place` puts it at ``path``.

    On any exception the temporary file is removed and ``path`` is left untouched, so a
    failed or interrupted write never leaves a partial output. The folder of ``path`` is
    created when missing (the command line checks ``-o`` first: :func:`check_writable`).
    """
    path = Path(path)
    kind = destination_kind(path)
    if kind not in ("new", "regular file", *WRITE_THROUGH):
        raise _refuse(path, kind)
    # a device or FIFO (e.g. /dev/null): the temporary file goes to the system's temp folder
    folder = Path(tempfile.gettempdir()) if kind in WRITE_THROUGH else path.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
        # name parts truncated: a legal 255-byte file name must not give a too long temporary name
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:64]}.",
                                   suffix=(suffix or path.suffix or ".tmp")[:16], dir=folder)
    except OSError as exc:
        raise OutputError(f"{printable(str(path))}: cannot write there "
                          f"({(exc.strerror or str(exc)).lower()})") from None
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp's 0600 would leak into the final file
    try:
        yield Path(tmp)
        place(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_write(path, mode: str = "wb"):
    """Open a temporary file for writing; on success :func:`place` puts it at ``path``."""
    with atomic_path(path) as tmp, open(tmp, mode) as fh:
        yield fh
