"""SHA-256 of the file behind a load spec, without NumPy: ``brdffit fit`` starts it on a
thread before NumPy is imported (hashlib and the reads release the GIL), so the hash of a
35 MB MERL file (~20 ms) overlaps the import instead of the fit, which ``save`` would otherwise wait for
(docs/design/startup-and-speed.md)."""

from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["source_checksum"]


def source_checksum(spec) -> str | None:
    """SHA-256 of the file behind a load spec (``path`` or ``archive.zip:member``); ``None``
    when it is not a regular file (a FIFO or a device is never opened)."""
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
