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


def test_a_read_only_table_is_prepared_once_per_options():
    from brdffit.losses.objective import ObjectiveOptions, prepare_objective

    rng = np.random.default_rng(0)
    values = rng.uniform(0.01, 1.0, (90, 90, 180, 3))
    first = prepare_objective(values)
    assert prepare_objective(values) is not first                 # writable: prepared anew
    values.setflags(write=False)
    shared = prepare_objective(values)
    assert prepare_objective(values) is shared
    assert not shared.w.flags.writeable and not shared.z.flags.writeable
    np.testing.assert_array_equal(shared.w, first.w)
    other = prepare_objective(values, options=ObjectiveOptions(compressive=False))
    assert other is not shared and not np.array_equal(other.w, shared.w)
