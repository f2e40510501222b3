"""brdffit._jit: kernels compiled on first use, and kernels that call other lazy kernels."""

import numpy as np
import pytest

from brdffit._jit import LazyDispatcher, lazy_numba

_numba = lazy_numba()
pytestmark = pytest.mark.skipif(_numba is None, reason="numba not installed")


def _half(x):
    return 0.5 * x


def _halves(x, out):
    for i in range(x.shape[0]):
        out[i] = _half(x[i])


def test_a_kernel_calls_a_lazy_helper():
    global _half
    helper = _numba.njit(nogil=True, inline="always")(_half)
    assert isinstance(helper, LazyDispatcher)
    saved, _half = _half, helper
    try:
        kernel = _numba.njit(nogil=True)(_halves)
        x, out = np.arange(5.0), np.empty(5)
        kernel(x, out)
        np.testing.assert_array_equal(out, 0.5 * x)
    finally:
        _half = saved
