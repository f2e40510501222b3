"""Lazy, checked import of Mitsuba 3 / Dr.Jit with the ``llvm_ad_rgb`` variant.

Mitsuba's LLVM back-end crashes with the machine's default LLVM 15; it needs Debian's
libLLVM 19. :func:`load` sets ``DRJIT_LIBLLVM_PATH`` (when unset) to the first existing of
``/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1`` and ``/usr/lib/*/libLLVM.so.19*`` *before*
importing drjit/mitsuba, then selects the variant. Nothing here runs at ``import brdffit``.
"""

from __future__ import annotations

import glob
import os

from ...errors import BRDFError

__all__ = ["load", "available", "VARIANT", "MitsubaUnavailable"]

VARIANT = "llvm_ad_rgb"
_LLVM_CANDIDATES = ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1", "/usr/lib/*/libLLVM.so.19*",
                    "/usr/lib/*/libLLVM-19.so")
_cache: tuple | None = None


class MitsubaUnavailable(BRDFError):
    """Mitsuba 3 or its LLVM back-end cannot be used on this machine."""


def _find_llvm() -> str | None:
    for pattern in _LLVM_CANDIDATES:
        hits = sorted(glob.glob(pattern))
        if hits:
            return hits[0]
    return None


def load():
    """Return ``(mi, dr)`` with the ``llvm_ad_rgb`` variant set; raise
    :class:`MitsubaUnavailable` (a :class:`~brdffit.errors.BRDFError`) when impossible."""
    global _cache
    if _cache is not None:
        return _cache
    if not os.environ.get("DRJIT_LIBLLVM_PATH"):
        lib = _find_llvm()
        if lib is None:
            raise MitsubaUnavailable(
                "Mitsuba's LLVM back-end needs Debian's libllvm19 (expected "
                "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1, found none); run make install as root")
        os.environ["DRJIT_LIBLLVM_PATH"] = lib
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as exc:
        raise MitsubaUnavailable(f"expected the mitsuba and drjit packages, import failed: {exc}")
    try:
        mi.set_variant(VARIANT)
    except (ImportError, AttributeError, RuntimeError) as exc:
        raise MitsubaUnavailable(
            f"Mitsuba variant {VARIANT!r} unavailable ({exc}); Mitsuba's LLVM back-end needs "
            "Debian's libllvm19; run make install as root")
    _cache = (mi, dr)
    return _cache


def available() -> bool:
    """True when :func:`load` succeeds (used by tests to skip cleanly)."""
    try:
        load()
        return True
    except MitsubaUnavailable:
        return False
