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


def _median_by_sort(v, w):
    """The definition: the smallest value whose cumulative weight (sorted) reaches half."""
    order = np.argsort(v, kind="stable")
    cw = np.cumsum(w[order])
    return v[order][min(int(np.searchsorted(cw, 0.5 * cw[-1])), v.size - 1)]


def test_the_weighted_median_by_selection_is_the_sorted_definition():
    """Selection (O(n)) against the sort, with ties, zero weights and sizes on both sides
    of the size where the selection hands over to a sort."""
    from brdffit.losses.objective import weighted_median

    rng = np.random.default_rng(7)
    for trial in range(60):
        n = int(rng.integers(1, 40_000))
        v = rng.random(n) if trial % 2 else rng.integers(0, 30, n).astype(float)
        w = rng.random(n) * (rng.random(n) < 0.6)
        w[int(rng.integers(n))] = 1.0
        assert weighted_median(v, w) == _median_by_sort(v, w), trial
    v = np.arange(10_000.0)
    assert weighted_median(v, (v == 1234.0).astype(float)) == 1234.0   # one weighted value


def test_the_weighted_median_narrowed_by_its_bracket_is_the_sorted_definition():
    """Above 65,536 values a bracket read off every 64th value narrows the search first; it
    is checked, so values whose subsample says nothing (no weight there) or misleads (the
    weight sits between its members) give the sorted definition too."""
    from brdffit.losses.objective import weighted_median

    rng = np.random.default_rng(11)
    for trial in range(12):
        n = int(rng.integers(70_000, 300_000))
        v = rng.lognormal(0.0, 3.0, n) if trial % 3 else rng.integers(0, 50, n).astype(float)
        w = rng.random(n) * (rng.random(n) < 0.7)
        assert weighted_median(v, w) == _median_by_sort(v, w), trial
    n = 100_000
    v = rng.random(n)
    off_subsample = np.ones(n)
    off_subsample[::64] = 0.0                                 # the subsample has no weight
    assert weighted_median(v, off_subsample) == _median_by_sort(v, off_subsample)
    heavy = np.ones(n)
    heavy[1] = 10.0 * n                                       # not in the subsample
    assert weighted_median(v, heavy) == v[1]


def test_the_compressive_weight_keeps_its_input_shape_and_its_series_near_zero():
    from brdffit.losses.objective import compressive_weight

    x = np.array([[-1.0, 0.0, 1e-14, 0.5, 2.0]])
    w = compressive_weight(x, np.array([[1.0]]))
    assert w.shape == (1, 5) and np.all(w[0, :2] == 1.0)
    assert w[0, 2] == pytest.approx((1.0 - 0.5 * (1e-14 * np.log(2))) ** 1.4, rel=1e-15)
    assert np.isscalar(compressive_weight(2.0, 1.0))
    assert compressive_weight(2.0, 1.0) == pytest.approx(((1 - 0.25) / np.log(2) / 2) ** 1.4)
