"""Shared fixtures: random unit directions, and the location of ../shared/data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def shared_data_path(*parts) -> Path:
    """Path under ../shared/data, skipping the test with a clear reason when it is absent."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"needs the shared data set at {p} (absent on this machine)")
    return p


@pytest.fixture
def shared_data():
    return shared_data_path


def random_hemisphere(rng, n):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    return v


@pytest.fixture
def rng():
    return np.random.default_rng(1234)
