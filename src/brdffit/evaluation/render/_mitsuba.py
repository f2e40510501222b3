"""Lazy, checked import of Mitsuba 3 / Dr.Jit with the ``llvm_ad_rgb`` variant.

Mitsuba's LLVM back-end crashes with the machine's default LLVM 15; it needs Debian's
libLLVM 19. :func:`load` sets ``DRJIT_LIBLLVM_PATH`` (when unset) to the first existing of
``/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1`` and ``/usr/lib/*/libLLVM.so.19*`` *before*
importing drjit/mitsuba, then selects the variant. Nothing here runs at ``import brdffit``.

Three environment variables, read once by :func:`load` and inherited by every worker
process (``demo``, ``batch``, the renderer's child process of :mod:`brdffit._isolation`):

``BRDFFIT_DRJIT_DEBUG=1``
    Dr.Jit's debug mode: every ``gather``/``scatter`` is bounds-checked and an out-of-bounds
    access is reported on stderr (``drjit.gather(): out-of-bounds read ...``) and skipped
    instead of reading or writing stray memory. Packet operations are switched off with it:
    Dr.Jit 1.5's debug check of *packet* scatters reports in-bounds writes of Mitsuba's
    8-channel image blocks as out of bounds and drops them (``bench/repro/drjit_debug_packet_scatter.py``).
    ``make test`` runs the suite this way.
``BRDFFIT_LLVM_TARGET=avx2``
    Compile the kernels for an AVX2 CPU without AVX-512 (Haswell's instruction set, 8 lanes)
    instead of the host: the code path of most users' machines, where a masked gather is
    scalarised and an out-of-bounds index faults. ``native`` (or unset) is the host.
``BRDFFIT_RENDER_THREADS=N``
    Dr.Jit runs its kernels on ``N`` threads (unset: one per CPU). A local batch gives its
    workers ``cores // workers`` (:func:`brdffit.batch._client`): with every core already
    busy, more threads only wait for one another (a render task's renderer spends 1.1× the
    CPU with two threads as with one, 2 workers on 2 cores: docs/design/batch.md).
"""

from __future__ import annotations

import glob
import os

from ...errors import BRDFError

__all__ = ["load", "available", "VARIANT", "LLVM_TARGETS", "MitsubaUnavailable"]

VARIANT = "llvm_ad_rgb"
_LLVM_CANDIDATES = ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1", "/usr/lib/*/libLLVM.so.19*",
                    "/usr/lib/*/libLLVM-19.so")
_cache: tuple | None = None
#: LLVM targets of ``BRDFFIT_LLVM_TARGET``: (CPU, features, vector width).
LLVM_TARGETS = {"avx2": ("haswell", "+avx2,+fma,+f16c,+bmi,+bmi2,+lzcnt,+popcnt,+sse4.2,"
                                    "-avx512f,-avx512vl,-avx512bw,-avx512dq,-avx512cd", 8)}


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
    _configure(dr)
    _cache = (mi, dr)
    return _cache


def _set_llvm_target(dr, cpu: str, features: str, width: int) -> None:
    """Dr.Jit's ``jit_llvm_set_target`` (exported by libdrjit-core, not bound in Python)."""
    import ctypes

    lib = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
    try:
        fn = lib._Z19jit_llvm_set_targetPKcS0_j  # jit_llvm_set_target(const char*, const char*, uint32_t)
    except AttributeError:
        raise MitsubaUnavailable("BRDFFIT_LLVM_TARGET: this Dr.Jit does not export "
                                 "jit_llvm_set_target") from None
    fn.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32]
    fn.restype = None
    fn(cpu.encode(), features.encode(), int(width))


def _render_threads() -> int | None:
    """``BRDFFIT_RENDER_THREADS`` as a positive integer (``None`` when unset)."""
    value = os.environ.get("BRDFFIT_RENDER_THREADS", "").strip()
    if not value:
        return None
    if not value.isdigit() or not 1 <= int(value) <= 4096:
        raise MitsubaUnavailable(f"BRDFFIT_RENDER_THREADS: expected an integer from 1 to "
                                 f"4096, found {value!r}")
    return int(value)


def _configure(dr) -> None:
    """Apply ``BRDFFIT_DRJIT_DEBUG``, ``BRDFFIT_LLVM_TARGET`` and ``BRDFFIT_RENDER_THREADS``
    (module docstring)."""
    threads = _render_threads()
    if threads is not None:
        dr.set_thread_count(threads)
    target = os.environ.get("BRDFFIT_LLVM_TARGET", "").strip().lower()
    if target and target != "native":
        if target not in LLVM_TARGETS:
            raise MitsubaUnavailable(f"BRDFFIT_LLVM_TARGET: expected one of native, "
                                     f"{', '.join(LLVM_TARGETS)}, found {target!r}")
        _set_llvm_target(dr, *LLVM_TARGETS[target])
    if os.environ.get("BRDFFIT_DRJIT_DEBUG", "").strip() not in ("", "0"):
        dr.set_flag(dr.JitFlag.Debug, True)
        dr.set_flag(dr.JitFlag.PacketOps, False)


def available() -> bool:
    """True when :func:`load` succeeds (used by tests to skip cleanly)."""
    try:
        load()
        return True
    except MitsubaUnavailable:
        return False
