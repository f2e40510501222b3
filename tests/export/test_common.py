"""Helpers shared by the exporters (brdffit.export._common)."""

from __future__ import annotations

import numpy as np

from brdffit.brdf import IsotropicBRDF, _as_dirs
from brdffit.export._common import diffuse_kept_fraction


class _Layered(IsotropicBRDF):
    """``base/π · (1 − k cos θo)`` plus a lobe that ignores the base."""

    def __init__(self, base, k):
        self.base, self.k, self.name, self.source = np.asarray(base, float), k, "layered", None

    def eval(self, wi, wo):
        wi, wo = _as_dirs(wi, wo)
        lobe = 5.0 * wi[..., 2:3] ** 4 * wo[..., 2:3] ** 4
        return self.base / np.pi * (1.0 - self.k * wo[..., 2:3]) + lobe


def test_diffuse_kept_fraction_is_the_cosine_weighted_mean_of_the_attenuation():
    # no attenuation: 1 exactly (the lobe cancels in f(1) − f(0))
    np.testing.assert_allclose(diffuse_kept_fraction(lambda b: _Layered(b, 0.0)), 1.0, rtol=1e-12)
    # 1 − k cos θo with cos θo cosine-distributed: mean 1 − 2k/3
    kept = diffuse_kept_fraction(lambda b: _Layered(b, 0.3))
    np.testing.assert_allclose(kept, 1.0 - 0.2, rtol=3e-3)
    assert kept.shape == (3,)
    # deterministic
    np.testing.assert_array_equal(kept, diffuse_kept_fraction(lambda b: _Layered(b, 0.3)))
