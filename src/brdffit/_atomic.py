"""Atomic file output: write to a temporary file in the destination folder, then rename."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

__all__ = ["atomic_write", "atomic_path"]


@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None):
    """Yield a temporary path next to ``path``; on success it replaces ``path`` atomically.

    On any exception the temporary file is removed and ``path`` is left untouched, so a
    failed or interrupted write never leaves a partial output.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # name parts truncated: a legal 255-byte file name must not give a too long temporary name
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:64]}.",
                               suffix=(suffix or path.suffix or ".tmp")[:16], dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp's 0600 would leak into the final file
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_write(path, mode: str = "wb"):
    """Open a temporary file for writing; on success it atomically replaces ``path``."""
    with atomic_path(path) as tmp, open(tmp, mode) as fh:
        yield fh
