"""The chi-square sampler test must accept correct samplers and reject wrong ones."""

import numpy as np

from brdffit.brdf import BRDF
from brdffit.testing.chi2 import ChiSquareTest, check_sampling, pdf_integral


class Lambert(BRDF):
    isotropic = True

    def eval(self, wi, wo):
        ok = (np.asarray(wi)[..., 2] > 0) & (np.asarray(wo)[..., 2] > 0)
        return np.where(ok, 0.5 / np.pi, 0.0)[..., None] * np.ones(3)


class PhongLobe(Lambert):
    """Samples cos^n around the normal; ``wrong_pdf`` reports the density for another n."""

    def __init__(self, n=8.0, pdf_n=None):
        self.n, self.pdf_n = n, n if pdf_n is None else pdf_n

    def sample(self, wi, u):
        u = np.asarray(u)
        ct = u[..., 0] ** (1.0 / (self.n + 1))
        st = np.sqrt(1 - ct**2)
        phi = 2 * np.pi * u[..., 1]
        wo = np.stack([st * np.cos(phi), st * np.sin(phi), ct], -1)
        return wo, self.pdf(wi, wo)

    def pdf(self, wi, wo):
        ct = np.maximum(np.asarray(wo)[..., 2], 0.0)
        return (self.pdf_n + 1) / (2 * np.pi) * ct**self.pdf_n


def test_cosine_sampler_passes():
    ok, res = check_sampling(Lambert(), [[0, 0, 1], [0.6, 0, 0.8]], sample_count=50_000)
    assert ok, [str(r) for r in res]
    assert abs(res[0].pdf_integral - 1.0) < 1e-3


def test_lobe_sampler_passes_and_wrong_pdf_fails():
    r = ChiSquareTest(PhongLobe(8.0), [0, 0, 1], sample_count=50_000).run()
    assert r.passed, str(r)
    bad = ChiSquareTest(PhongLobe(8.0, pdf_n=9.0), [0, 0, 1], sample_count=50_000).run()
    assert not bad.passed and bad.p_value < 1e-6, str(bad)


def test_unnormalised_pdf_is_reported():
    class Scaled(PhongLobe):
        def pdf(self, wi, wo):
            return 1.2 * super().pdf(wi, wo)

    r = ChiSquareTest(Scaled(4.0), [0, 0, 1], sample_count=20_000).run()
    assert not r.passed
    assert abs(r.pdf_integral - 1.2) < 1e-2
    assert abs(pdf_integral(Lambert(), [0, 0, 1]) - 1.0) < 1e-4


def test_tabulated_visible_sampler_at_grazing_incidence():
    """The visible-normal sampler of a tabulated (Dupuy 2015) distribution against its pdf
    at θi = 80°, α = 1. Regression: the pdf was normalised by σ from the node quadrature of
    Eq. 3 (2.8 % smaller than the integral the sampler draws from), so the pdf integrated to
    more than the fraction of valid samples and the histogram was off."""
    from brdffit.microfacet import MicrofacetBRDF
    from brdffit.microfacet.tabulated import TabulatedSlopeDistribution
    from brdffit.testing.furnace import _ggx_slope_table

    b = MicrofacetBRDF(TabulatedSlopeDistribution(_ggx_slope_table()), None)
    t = np.radians(80.0)
    r = ChiSquareTest(b, [np.sin(t), 0.0, np.cos(t)], sample_count=100_000, res_theta=32,
                      res_phi=64).run()
    assert r.passed, str(r)
    assert abs(r.pdf_integral - r.valid_fraction) < 0.005, str(r)
