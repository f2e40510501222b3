"""One BLAS thread for brdffit's fits (fits and a CLI that finish fast).

The fits do many *small* linear-algebra calls (least-squares Jacobians of a few columns,
90×90 systems, 3-10 variable normal equations). A multi-threaded OpenBLAS wakes and spins
its threads for each of them, which made whole ``brdffit fit`` processes 1.1-2.5× slower
(measurements: docs/design/startup-and-speed.md). No fit here has a matrix large enough for
BLAS threads to pay off, and parallel work (NPF starts, batch workers) is parallel above
BLAS.

* :func:`single_thread_env` — the command line, *before NumPy is imported*: sets
  ``OPENBLAS_NUM_THREADS`` (and the MKL/BLIS/Accelerate equivalents) to 1 unless the user
  set them; batch workers inherit it.
* :func:`single_blas_thread` — the library: ``threadpoolctl`` limits BLAS to one thread
  for the block. The public fitting functions (``fit_tabulated``, ``fit_analytic_diffuse``,
  ``fit_two_slice``, ``fit_cook_torrance``, ``fit_npf`` and the functions built on them),
  every fitter of :mod:`brdffit.fit.registry` and :func:`brdffit.export.export` run in one
  (a ggx-diffuse fit of ``synthetic:gold-ggx`` from Python: 2.9 → 0.8 s CPU on the 2-core
  machine).
"""

from __future__ import annotations

import functools
import os
import sys
import threading
from contextlib import contextmanager
from typing import Callable, Iterator

__all__ = ["ENV_VARS", "single_thread_env", "single_blas_thread", "with_single_blas_thread"]

ENV_VARS = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
            "VECLIB_MAXIMUM_THREADS")


def single_thread_env() -> bool:
    """Set the BLAS thread variables the user has not set to 1; ``False`` (nothing done)
    when NumPy is already imported (its BLAS read them at load time)."""
    if "numpy" in sys.modules:
        return False
    for name in ENV_VARS:
        os.environ.setdefault(name, "1")
    return True


def _env_says_one() -> bool:
    return os.environ.get("OPENBLAS_NUM_THREADS") == "1" and "numpy" in sys.modules


#: how deep this thread is in :func:`single_blas_thread` blocks (a registry fitter wraps a
#: public fitting function that wraps its own: only the outermost sets the limit)
_nesting = threading.local()


@contextmanager
def single_blas_thread() -> Iterator[None]:
    """Limit BLAS to one thread inside the block (no-op without ``threadpoolctl``, when the
    environment already did it, or inside another such block of this thread)."""
    depth = getattr(_nesting, "depth", 0)
    if depth or _env_says_one():
        yield
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - a declared dependency
        yield
        return
    _nesting.depth = 1
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            yield
    finally:
        _nesting.depth = 0


def with_single_blas_thread(fn: Callable) -> Callable:
    """``fn`` run inside :func:`single_blas_thread` (signature and docs kept)."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with single_blas_thread():
            return fn(*args, **kwargs)

    return wrapper
