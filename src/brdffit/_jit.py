"""Numba, imported and compiled on first use (a CLI that starts at once).

Importing Numba costs ~0.2 s of CPU and loading a cached kernel another ~0.3 s, so modules
that merely *define* compiled kernels must not import it: ``brdffit fit x.binary`` reads a
MERL file through :mod:`brdffit.io.merl` without ever calling its kernels. A module writes::

    from .._jit import lazy_numba
    _numba = lazy_numba()          # None when Numba is not installed (NumPy fall-backs)
    ...
    if _numba is not None:
        kernel = _numba.njit(cache=True, nogil=True)(kernel)

and ``_numba.njit(...)(fn)`` returns a :class:`LazyDispatcher` that imports Numba and compiles
``fn`` (from the on-disk cache with ``cache=True``) the first time it is called; every other
attribute of ``_numba`` is the real module's (imported then). A kernel may call another
``LazyDispatcher`` (a helper shared by kernels): Numba types it as the dispatcher it stands
for.

A kernel with a NumPy fall-back asks :meth:`LazyDispatcher.worth_compiling` first: small
jobs (a few evaluations of a MERL table, ``brdffit info``'s albedos) run in NumPy until
:data:`COMPILE_AFTER` elements have been handled that way, when loading Numba pays off.
"""

from __future__ import annotations

import sys
import threading
from importlib.util import find_spec

__all__ = ["lazy_numba", "LazyDispatcher", "LazyNumba", "COMPILE_AFTER"]

#: Elements a kernel's NumPy fall-back handles before the kernel is compiled. Importing Numba
#: and loading a cached kernel costs 0.4-0.9 s of CPU; the kernels repay it after about this
#: much work (MERL table lookups of 65,536 direction pairs: 77 ms in NumPy, 12 ms compiled).
COMPILE_AFTER = 1 << 19


class LazyDispatcher:
    """``numba.njit(**options)(fn)``, made on the first call (thread-safe)."""

    def __init__(self, fn, options: dict):
        self.py_func = fn
        self._options = dict(options)
        self._dispatcher = None
        self._lock = threading.Lock()
        self._fallback_work = 0
        self.__name__ = getattr(fn, "__name__", "kernel")
        self.__doc__ = getattr(fn, "__doc__", None)
        self.__wrapped__ = fn

    def compiled(self):
        """The Numba dispatcher (imports Numba and compiles or loads ``fn`` if needed)."""
        if self._dispatcher is None:
            with self._lock:
                if self._dispatcher is None:
                    import numba

                    _type_lazy_dispatchers()
                    self._dispatcher = numba.njit(**self._options)(self.py_func)
        return self._dispatcher

    def worth_compiling(self, n: int) -> bool:
        """Whether ``n`` more elements should go to the compiled kernel rather than to the
        caller's NumPy fall-back: yes once it is compiled or Numba is loaded anyway, or when
        the elements left to the fall-back (counted here) would pass :data:`COMPILE_AFTER`.
        The two paths agree to rounding (≈ 1e-14), not bit for bit."""
        if self._dispatcher is not None or "numba" in sys.modules:
            return True
        self._fallback_work += int(n)
        return self._fallback_work > COMPILE_AFTER

    def __call__(self, *args, **kwargs):
        return (self._dispatcher or self.compiled())(*args, **kwargs)

    def __getattr__(self, name):  # signatures, inspect_types, ... of the real dispatcher
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self.compiled(), name)


_TYPED = False


def _type_lazy_dispatchers() -> None:
    """Let compiled code call a :class:`LazyDispatcher` (a kernel's helper): Numba types it as
    the dispatcher it stands for (registered once, when Numba is imported)."""
    global _TYPED
    if _TYPED:
        return
    from numba import typeof
    from numba.extending import typeof_impl

    typeof_impl.register(LazyDispatcher)(lambda val, c: typeof(val.compiled()))
    _TYPED = True


class LazyNumba:
    """Stands for the ``numba`` module: ``njit`` is lazy, the rest imports Numba."""

    @staticmethod
    def njit(*args, **options):
        if args and callable(args[0]) and len(args) == 1 and not options:  # @njit bare
            return LazyDispatcher(args[0], {})
        if args:
            raise TypeError("lazy njit: pass options as keywords (cache=True, nogil=True...)")
        return lambda fn: LazyDispatcher(fn, options)

    def __getattr__(self, name):
        import numba

        return getattr(numba, name)


_LAZY = LazyNumba()


def lazy_numba() -> LazyNumba | None:
    """A lazy stand-in for ``numba`` when it is installed (found without importing it), else
    ``None``."""
    try:
        return _LAZY if find_spec("numba") is not None else None
    except (ImportError, ValueError):  # pragma: no cover
        return None
