"""The objective of Bagher et al. 2016 (brdffit.losses.objective): the grid geometry."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.losses.objective import merl_grid_geometry


def test_merl_grid_geometry_is_shared_and_read_only():
    a, b = merl_grid_geometry(), merl_grid_geometry()
    assert a is not b and all(a[k] is b[k] for k in a)          # computed once per process
    with pytest.raises(ValueError):
        a["cos_i"][0, 0, 0] = 2.0
    a["cos_i"] = None                                            # the caller's own dict
    assert merl_grid_geometry()["cos_i"] is b["cos_i"]
    # θh = θd = 0: both directions on the normal
    np.testing.assert_allclose([b["cos_i"][0, 0, 0], b["cos_o"][0, 0, 0]], 1.0)
