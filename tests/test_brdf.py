"""The BRDF protocol's measured domain, followed through the pipeline (grid, fits, errors)."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.brdf import IsotropicBRDF, measured_mask
from brdffit.geometry import half_diff_to_io
from brdffit.grid import merl_node_values, tabulate_merl_grid

RHO = np.array([0.5, 0.3, 0.2])
LIMIT = np.radians(60.0)


class Lambert(IsotropicBRDF):
    name = "lambert"

    def __init__(self, rho=RHO):
        self.rho = np.asarray(rho, dtype=np.float64)

    def eval_hd(self, theta_h, theta_d, phi_d):
        wi, wo = half_diff_to_io(theta_h, 0.0, theta_d, phi_d)
        up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        return np.where(up[..., None], self.rho / np.pi, 0.0)


class Capped(Lambert):
    """A Lambertian measurement up to θi = 60°, with garbage (×1000) beyond it."""

    name = "capped"
    measured_domain = "θi ≤ 60°"

    def eval_hd(self, theta_h, theta_d, phi_d):
        wi, wo = half_diff_to_io(theta_h, 0.0, theta_d, phi_d)
        f = super().eval_hd(theta_h, theta_d, phi_d)
        return np.where((wi[..., 2] < np.cos(LIMIT))[..., None], 1000.0 * f, f)

    def measured(self, wi, wo):
        return super().measured(wi, wo) & (np.asarray(wi)[..., 2] >= np.cos(LIMIT))


def test_measured_mask_is_none_without_a_domain():
    wi = np.array([[0.0, 0.0, 1.0]])
    assert measured_mask(Lambert(), wi, wi) is None
    assert measured_mask(Capped(), wi, wi).tolist() == [True]
    assert Lambert().measured(wi, -wi).tolist() == [False]        # below the horizon


def test_grid_marks_samples_outside_the_domain_invalid():
    values, valid = tabulate_merl_grid(Capped())
    th, td, pd = np.meshgrid(*(g() for g in _merl_axes()), indexing="ij")
    wi, wo = half_diff_to_io(th, 0.0, td, pd)
    outside = wi[..., 2] < np.cos(LIMIT)
    up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    assert outside.any() and not valid[outside].any()
    assert valid[~outside & up].all()
    v, m = merl_node_values(Capped(), slice(None), [10, 60], slice(None, None, 9))
    np.testing.assert_array_equal(m, (~outside & up)[:, [10, 60], ::9])
    assert v.shape == m.shape + (3,)


def _merl_axes():
    from brdffit.grid import merl_phi_d, merl_theta_d, merl_theta_h

    return merl_theta_h, merl_theta_d, merl_phi_d


def test_errors_and_fits_ignore_what_was_not_measured():
    """The garbage beyond 60° is invisible to the error metrics and to the fit: a Lambertian
    fit of the capped measurement is exact, and its error over the domain is 0."""
    from brdffit.cli.fit import quick_error
    from brdffit.evaluation.metrics import BRDFMetrics, cosine_weighted_relative_error
    from brdffit.fit import fit

    ref, exact = Capped(), Lambert()
    assert cosine_weighted_relative_error(ref, exact, n_samples=1 << 12) == pytest.approx(0, abs=1e-12)
    assert cosine_weighted_relative_error(Lambert(RHO * 1000), exact, n_samples=1 << 12) > 0.9
    q = quick_error(ref, exact)
    assert q["cos_rel_error"] == pytest.approx(0.0, abs=1e-12) and "θi ≤ 60°" in q["method"]
    m = BRDFMetrics(ref, n_samples=1 << 12).evaluate(exact)
    assert m["cos_rel_error"] == pytest.approx(0, abs=1e-12)
    assert m["normalized_l2"] == pytest.approx(0, abs=1e-9)
    model = fit(ref, model="ggx-diffuse")
    np.testing.assert_allclose(model.fit_info["rho_d"], RHO, rtol=0.02)
    assert quick_error(ref, model)["cos_rel_error"] < 0.02

