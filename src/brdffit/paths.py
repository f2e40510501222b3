"""The one function that turns a name (material, model, label) into a path component.

Every folder or file name brdffit derives from a user-visible name — batch fits, records and
renders, report folders, the comparison's material folders — goes through :func:`slug`, so
that two different names can never share a folder and silently overwrite each other.

Rules (a name is any string; the *slug* is what appears on disk and in report URLs):

* a name that is already a safe, lower-case path component — ``[a-z0-9_]`` followed by
  ``[a-z0-9._-]``, not ending in ``.``, at most :data:`MAX_KEEP` characters, not a reserved
  device name of Windows (``con``, ``nul``, ``com1``...) and not itself of the hashed form
  below — is its own slug: ``alum-bronze`` stays ``alum-bronze``, ``nan.bin`` stays
  ``nan.bin``, so existing output folders stay valid;
* any other name becomes ``<readable>--<hash>``: ``readable`` is an ASCII transliteration
  (NFKD, unsafe characters → ``_``, at most :data:`MAX_READABLE` characters, ``_`` if nothing
  is left) and ``hash`` the first :data:`HASH_LEN` hex digits of the SHA-256 of the exact
  name (UTF-8). ``mat a`` → ``mat_a--…`` (≠ ``mat_a``), ``金`` → ``_--…`` (≠ ``銀``),
  ``..`` → ``_--…``, ``Gold`` → ``Gold--…``.

Properties: the slug is never empty, ``.`` or ``..``, contains only ``[A-Za-z0-9._-]``, is at
most 80 characters, and depends on nothing but the name (stable across runs and machines).
Two different names get different slugs — even on a case-insensitive file system, since every
slug containing an upper-case letter carries a hash — unless their 48-bit hashes collide
(:func:`check_unique` refuses that case outright).
"""

from __future__ import annotations

import hashlib
import re
import unicodedata
from typing import Iterable

__all__ = ["slug", "check_unique", "MAX_KEEP", "MAX_READABLE", "HASH_LEN"]

#: Longest name kept as is; longest readable part of a hashed slug; hex digits of the hash.
MAX_KEEP, MAX_READABLE, HASH_LEN = 80, 60, 12

_KEEP = re.compile(r"[a-z0-9_](?:[a-z0-9._-]*[a-z0-9_-])?")
_HASHED = re.compile(r"--[0-9a-f]{%d}$" % HASH_LEN)
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")
_WINDOWS_DEVICES = {"con", "prn", "aux", "nul", *(f"com{i}" for i in range(10)),
                    *(f"lpt{i}" for i in range(10))}


def slug(name) -> str:
    """The file-system and URL safe, collision-free path component of ``name`` (rules above)."""
    text = str(name)
    if (len(text) <= MAX_KEEP and _KEEP.fullmatch(text) and not _HASHED.search(text)
            and text.split(".", 1)[0] not in _WINDOWS_DEVICES):
        return text
    ascii_text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    readable = _UNSAFE.sub("_", ascii_text).lstrip("._-")[:MAX_READABLE].rstrip(".-")
    digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:HASH_LEN]
    return f"{readable or '_'}--{digest}"


def check_unique(names: Iterable[str], what: str = "names") -> dict[str, str]:
    """``{name: slug}`` for distinct ``names``; ``ValueError`` if two of them would share a
    folder (equal slugs, also compared case-insensitively) — a hash collision, in practice
    never, but then refusing is the only safe answer."""
    seen: dict[str, str] = {}
    out: dict[str, str] = {}
    for name in names:
        if name in out:
            continue
        s = slug(name)
        other = seen.get(s.casefold())
        if other is not None:
            raise ValueError(f"{what} {other!r} and {name!r} map to the same folder {s!r}; "
                             f"rename one of them")
        seen[s.casefold()] = name
        out[name] = s
    return out
