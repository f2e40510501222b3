"""Independent-G's slice start of a fitted model reads only the two MERL slices it uses."""

from __future__ import annotations

import numpy as np

from brdffit.fit.npf import _model_slice_start, _slice_start
from brdffit.grid import tabulate_merl_grid
from brdffit.microfacet.sgd import SGD
from brdffit.microfacet.sgd_model import PerChannelMicrofacetBRDF


def test_slice_start_of_a_model_equals_that_of_its_full_tabulation():
    model = PerChannelMicrofacetBRDF([dict(distribution=SGD(0.1 + 0.1 * c, 1.2 + 0.1 * c),
                                           rho_d=0.05 * c, rho_s=0.5 + 0.2 * c,
                                           F0=0.3 + 0.2 * c, F1=0.1) for c in range(3)])
    fast = _model_slice_start(model)
    full = _slice_start(*tabulate_merl_grid(model))
    for name in ("D", "F", "G", "rho_d", "rho_s"):
        a, b = getattr(fast, name), getattr(full, name)
        assert a.shape == b.shape
        assert np.array_equal(a, b), name           # the same nodes, the same values
    assert not np.allclose(fast.D, fast.D[:, :1])   # a real slice, not a constant
