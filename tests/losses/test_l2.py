"""Normalised L2 error of Bagher 2012 §6.3 (losses.l2)."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.brdf import IsotropicBRDF
from brdffit.losses.l2 import L2Reference, merl_grid_weights, normalized_l2


class _Lambert(IsotropicBRDF):
    def __init__(self, rho):
        self.rho = np.asarray(rho, dtype=float)

    def eval_hd(self, th, td, pd):
        return np.broadcast_to(self.rho / np.pi, np.shape(th) + (3,)).copy()


class _Phong(IsotropicBRDF):
    """A normalised Phong-like lobe in θh (peaky, to exercise the θh quadrature)."""

    def __init__(self, n):
        self.n = n

    def eval_hd(self, th, td, pd):
        v = (self.n + 2) / (2 * np.pi) * np.cos(th) ** self.n
        return np.repeat(np.asarray(v)[..., None], 3, axis=-1)


def test_weights_integrate_cosine_product():
    w, _ = merl_grid_weights(3)
    assert w.sum() == pytest.approx(np.pi**2, rel=2e-3)     # ∫∫ cos θi cos θo dωi dωo = π²


def test_lambertian_difference_is_albedo_difference():
    # E = |Δρ|/π · π = |Δρ| and the max albedo of a Lambertian ρ is ρ → E/A = |Δρ|/ρ
    ref, fit = _Lambert([0.5, 0.3, 0.2]), _Lambert([0.25, 0.3, 0.1])
    for method in ("grid", "mc"):
        r = L2Reference(ref, method, n=1 << 14, albedo_samples=4096).error(fit)
        np.testing.assert_allclose(r.per_channel, [0.5, 0.0, 0.5], atol=2e-3)
        np.testing.assert_allclose(r.max_albedo, [0.5, 0.3, 0.2], rtol=1e-3)
    assert normalized_l2(ref, ref, phi_stride=6) == 0.0


def test_grid_and_mc_agree_on_a_glossy_lobe():
    ref, fit = _Phong(40), _Lambert([0.2, 0.2, 0.2])
    g = L2Reference(ref, "grid", phi_stride=4, albedo_samples=4096).error(fit)
    m = L2Reference(ref, "mc", n=1 << 17, albedo_samples=4096).error(fit)
    assert g.value == pytest.approx(m.value, rel=0.02)
    assert g.value > 0.5          # a Lambertian is a poor fit of a glossy lobe


def test_method_validation():
    with pytest.raises(ValueError):
        L2Reference(_Lambert([0.1] * 3), "simpson")
