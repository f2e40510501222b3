"""Conversions of a tabulated microfacet model (brdffit.microfacet.conversions)."""

from __future__ import annotations

import pytest

from brdffit.fit.tabulated import fit_tabulated
from brdffit.microfacet import GGX, Beckmann, MicrofacetBRDF, SchlickFresnel
from brdffit.microfacet.conversions import to_beckmann, to_ggx


def test_conversions_reuse_fresnel_and_return_microfacet_brdfs():
    brdf = MicrofacetBRDF(GGX(0.15, 0.3), SchlickFresnel(0.8))
    model = fit_tabulated(brdf, n=40, n_phi=40, hotspot="G2", tol=1e-8)
    g = to_ggx(model)
    b = to_beckmann(model)
    assert isinstance(g.distribution, GGX) and isinstance(b.distribution, Beckmann)
    assert g.fresnel is model.fresnel and b.fresnel is model.fresnel
    assert g.distribution.alpha_x == pytest.approx(0.15, rel=0.02)
    assert g.distribution.alpha_y == pytest.approx(0.3, rel=0.02)
