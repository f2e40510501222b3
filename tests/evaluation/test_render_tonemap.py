"""Bagher 2016 §5 tone mapping (no Mitsuba needed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from brdffit.evaluation.tonemap import auto_exposure, tonemap


def test_formula_values():
    x = np.array([0.0, 50.0, 100.0, 1e6])
    # hand values: 1 - 2^(-0.02*50) = 1/2, 1 - 2^-2 = 3/4
    want = [0.0, 0.5 ** (1 / 2.2), 0.75 ** (1 / 2.2), 1.0]
    np.testing.assert_allclose(tonemap(x), want, rtol=1e-12, atol=1e-12)
    assert tonemap(np.array([1.0]), exposure=1.0, gamma=2.8)[0] == pytest.approx(0.5 ** (1 / 2.8))


def test_monotone_bounded_and_robust():
    x = np.array([-3.0, np.nan, np.inf, 0.1, 1.0, 10.0])
    y = tonemap(x, exposure=0.5)
    assert np.all(np.isfinite(y)) and np.all((y >= 0) & (y <= 1))
    assert y[0] == 0 and y[1] == 0
    assert np.all(np.diff(y[3:]) > 0)
    with pytest.raises(ValueError):
        tonemap(x, exposure=-1)
    with pytest.raises(ValueError):
        tonemap(x, exposure="bright")


def test_auto_exposure_maps_median_to_half():
    rng = np.random.default_rng(0)
    img = rng.lognormal(0.0, 1.0, (32, 32, 3))
    mask = np.zeros((32, 32), bool)
    mask[8:24, 8:24] = True
    e = auto_exposure(img, mask)
    med = np.median(img.max(-1)[mask])
    assert e == pytest.approx(1.0 / med)
    assert 1 - 2 ** (-e * med) == pytest.approx(0.5)
    out = tonemap(img, "auto", mask=mask)
    np.testing.assert_allclose(out, tonemap(img, e))
    assert auto_exposure(np.zeros((4, 4, 3))) == pytest.approx(0.02)
    assert math.isfinite(e)
