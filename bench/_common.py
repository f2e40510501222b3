"""Helpers shared by the benchmark scripts (run as ``python bench/bench_X.py``)."""

from __future__ import annotations

import numpy as np


def random_direction_pairs(n: int, seed: int = 0) -> list[np.ndarray]:
    """``[wi, wo]``: two arrays of ``n`` random unit vectors on the upper hemisphere."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(2):
        v = rng.normal(size=(n, 3))
        v[:, 2] = np.abs(v[:, 2])
        out.append(v / np.linalg.norm(v, axis=1, keepdims=True))
    return out
