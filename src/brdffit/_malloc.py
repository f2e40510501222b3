"""glibc ``malloc`` settings of brdffit's processes (fits and a CLI that finish fast).

NumPy takes every array above glibc's *mmap threshold* (128 KiB, raised on the fly up to
32 MiB) straight from the kernel and gives it back when freed, so each new temporary is
page-faulted in again. The fits make many temporaries of the size of their data (a MERL
table is 35 MB, one channel of it 12 MB), and a page fault is expensive here (≈ 5-8 µs on
the bench machine's virtual machine): a ``brdffit fit`` process of the tabulated model spent
a third of its CPU time in the kernel. With the settings below, arrays up to
:data:`MMAP_THRESHOLD` come from the heap and up to :data:`TRIM_THRESHOLD` of freed heap is
kept for the next ones (``mallopt(3)``: ``M_MMAP_THRESHOLD``, ``M_TRIM_THRESHOLD``).

* :data:`WORKER_MALLOC_ENV` — the environment of the batch's local Dask workers (set
  before they start; Dask's nanny would otherwise set ``MALLOC_TRIM_THRESHOLD_`` to 64 KiB,
  which also switches the dynamic threshold off: G-from-D 9.0 s vs 6.5 s per material).
* :func:`tune_this_process` — the same settings in the running process (the command line
  calls it first; the library never does: a program that imports brdffit keeps its own
  allocator settings).
"""

from __future__ import annotations

import os
import sys

__all__ = ["MMAP_THRESHOLD", "TRIM_THRESHOLD", "WORKER_MALLOC_ENV", "tune_this_process"]

#: Arrays up to this size come from the heap, not from fresh kernel pages (a MERL table fits).
MMAP_THRESHOLD = 64 << 20
#: Free heap kept for the next arrays before it is given back to the kernel.
TRIM_THRESHOLD = 128 << 20
WORKER_MALLOC_ENV = {"MALLOC_MMAP_THRESHOLD_": MMAP_THRESHOLD,
                     "MALLOC_TRIM_THRESHOLD_": TRIM_THRESHOLD}

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's <malloc.h>


def tune_this_process() -> bool:
    """Apply :data:`WORKER_MALLOC_ENV` to the running process with ``mallopt``; ``False``
    (nothing done) off glibc Linux or when the user set either variable (theirs wins)."""
    if not sys.platform.startswith("linux") or any(k in os.environ for k in WORKER_MALLOC_ENV):
        return False
    try:
        import ctypes

        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError, ImportError):  # no libc symbol (another C library)
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
