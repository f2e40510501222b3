"""Fit files, importance sampling (chi-square) and registry of the tabulated fit."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.fit.tabulated import fit_tabulated
from brdffit.microfacet.conversions import to_ggx
from brdffit.io.fitfile import load_fit, read_fit_header, save_fit, table_bytes
from brdffit.microfacet import GGX, Beckmann, MicrofacetBRDF, SchlickFresnel
from brdffit.microfacet.tabulated import TabulatedSlopeDistribution, radial_rule
from brdffit.testing.chi2 import check_sampling


def _white_backscatter(dist, theta, phi=None):
    if phi is None:
        o = np.stack([np.sin(theta), 0 * theta, np.cos(theta)], -1)
    else:
        th, ph = np.meshgrid(theta, phi, indexing="ij")
        o = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    return MicrofacetBRDF(dist, None).eval(o, o)[..., 0]


@pytest.fixture(scope="module")
def iso_fit():
    return fit_tabulated(MicrofacetBRDF(GGX(0.3), SchlickFresnel(0.6)), hotspot="G2", tol=1e-8)


@pytest.fixture(scope="module")
def aniso_fit():
    return fit_tabulated(MicrofacetBRDF(Beckmann(0.25, 0.1, 0.3), SchlickFresnel(0.5)),
                         n=40, n_phi=40, hotspot="G2", tol=1e-8)


def _random_pairs(n=500, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2, n, 3))
    v[..., 2] = np.abs(v[..., 2])
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return v[0], v[1]


@pytest.mark.parametrize("which", ["iso_fit", "aniso_fit"])
def test_save_load_identical_eval(which, request, tmp_path):
    model = request.getfixturevalue(which)
    path = save_fit(model, tmp_path / "fit.npz", source="synthetic:test")
    back = load_fit(path)
    wi, wo = _random_pairs()
    np.testing.assert_array_equal(back.eval(wi, wo), model.eval(wi, wo))
    np.testing.assert_array_equal(back.pdf(wi, wo), model.pdf(wi, wo))
    header = read_fit_header(path)
    assert header["fit_info"]["eigenvalue"] == pytest.approx(model.fit_info["eigenvalue"])
    assert header["options"]["hotspot"] == "G2"
    assert type(back.distribution) is type(model.distribution)


def test_table_sizes(iso_fit, aniso_fit):
    # isotropic N = 90: P, σ (G1) and RGB Fresnel in float32 = 5 x 90 x 4 B (paper: 2.1 KB)
    assert table_bytes(iso_fit) == 90 * 5 * 4
    _, arrays = aniso_fit.to_state()
    assert all(a.dtype == np.float32 for a in arrays.values())
    assert arrays["distribution.P"].shape == (40, 40)


def test_save_load_edited_roughness(iso_fit, tmp_path):
    edited = MicrofacetBRDF(iso_fit.distribution.with_roughness(0.5, 1.5), iso_fit.fresnel)
    back = load_fit(save_fit(edited, tmp_path / "e.npz"))
    wi, wo = _random_pairs(seed=1)
    np.testing.assert_array_equal(back.eval(wi, wo), edited.eval(wi, wo))
    assert not back.isotropic


def test_chi2_visible_sampling_isotropic(iso_fit):
    wis = [[0, 0, 1], [np.sin(1.1), 0, np.cos(1.1)]]
    ok, res = check_sampling(iso_fit, wis, sample_count=60000, res_theta=16, res_phi=32, ires=3)
    assert ok, "\n".join(map(str, res))


def test_chi2_visible_sampling_anisotropic(aniso_fit):
    wis = [[0.3, -0.5, np.sqrt(1 - 0.34)], [np.sin(1.3) * 0.6, np.sin(1.3) * 0.8, np.cos(1.3)]]
    ok, res = check_sampling(aniso_fit, wis, sample_count=60000, res_theta=16, res_phi=32, ires=3)
    assert ok, "\n".join(map(str, res))


def test_chi2_detects_a_wrong_pdf(iso_fit):
    """The sampling test can fail: a model whose pdf ignores the roughness edit is caught."""
    edited = MicrofacetBRDF(iso_fit.distribution.with_roughness(0.6), iso_fit.fresnel)

    class Wrong(type(edited)):
        def pdf(self, wi, wo):
            return iso_fit.pdf(wi, wo)

    wrong = Wrong.__new__(Wrong)
    wrong.__dict__.update(edited.__dict__)
    ok, _ = check_sampling(wrong, [[0, 0, 1]], sample_count=60000, res_theta=16, res_phi=32,
                           ires=3)
    assert not ok


def test_visible_sampling_matches_visible_density_with_stretch():
    """Sampled visible normals of an edited (αx ≠ αy) table follow pdf_visible."""
    _, theta, r, _ = radial_rule(90, "gauss")
    d = TabulatedSlopeDistribution(GGX(1.0).pdf(np.stack([r, 0 * r], -1)), rule="gauss")
    d = d.with_roughness(0.2, 0.5)
    ref = GGX(0.2, 0.5)
    w = np.array([np.sin(0.9) * np.cos(0.4), np.sin(0.9) * np.sin(0.4), np.cos(0.9)])
    u = np.random.default_rng(2).random((100000, 2))
    m = d.sample_visible(w, u)
    m0 = ref.sample_visible(w, u)
    # same law as the analytic GGX visible normals (moments of the sampled normals)
    np.testing.assert_allclose(m.mean(0), m0.mean(0), atol=4e-3)
    np.testing.assert_allclose((m**2).mean(0), (m0**2).mean(0), atol=4e-3)


def test_registry_exposes_models():
    from brdffit.fit import registry

    names = registry.list_fitters()
    assert {"tabulated", "ggx", "beckmann"} <= set(names)
    assert registry.get("ggx").accepts("iterations")
    with pytest.raises(KeyError):
        registry.get("no-such-model")


def test_summary_reports_alphas(iso_fit):
    from brdffit.fit import registry

    s = registry.summarize("tabulated", iso_fit)
    assert s["ggx_alpha"][0] == pytest.approx(0.3, rel=5e-3)
    assert s["eigenvalue"] == pytest.approx(0.6, rel=1e-3)  # F0 of Schlick(0.6), white
    g = to_ggx(iso_fit)
    assert registry.summarize("ggx", g)["alpha"][0] == pytest.approx(0.3, rel=5e-3)


class _MerlTable:
    """A MERL-grid table in memory, as the MERL reader exposes it (``merl_table``)."""

    isotropic = True
    name = "merl-grid"
    source = None

    def __init__(self, values, valid):
        self._t = (values, valid)

    def merl_table(self):
        return self._t

    def eval(self, wi, wo):  # pragma: no cover - the fit reads the table only
        raise AssertionError("a MERL-grid fit must read the table, not evaluate the BRDF")


def test_merl_grid_input_with_invalid_samples():
    from brdffit.grid import tabulate_merl_grid

    brdf = MicrofacetBRDF(Beckmann(0.15), SchlickFresnel([0.9, 0.7, 0.4]))
    values, valid = tabulate_merl_grid(brdf)
    clean = fit_tabulated(_MerlTable(values, valid), hotspot="G2")
    assert clean.distribution.rule == "merl"
    bad_vals, bad_valid = values.copy(), valid.copy()
    rng = np.random.default_rng(0)
    idx = rng.random(valid.shape) < 0.05
    idx[5, 0, 0] = idx[20, 0, :] = True  # invalid backscattering samples too
    bad_vals[idx] = -1.0  # MERL's marker of missing data
    bad_valid[idx] = False
    noisy = fit_tabulated(_MerlTable(bad_vals, bad_valid), hotspot="G2")
    d0, d1 = clean.distribution, noisy.distribution
    big = d0.table > 1e-3 * d0.table.max()
    np.testing.assert_allclose(d1.table[big], d0.table[big], rtol=2e-2)
    np.testing.assert_allclose(noisy.fresnel.values, clean.fresnel.values, atol=2e-3)
    assert np.all(np.isfinite(noisy.fresnel.values))


def test_real_neural_brdf_material(shared_data):
    from brdffit.io import load

    z = shared_data("nbrdf", "merl_nbrdf.zip")
    model = fit_tabulated(load(f"{z}:gold-metallic-paint"))
    d = model.distribution
    assert np.all(d.table >= 0) and np.all(np.isfinite(model.fresnel.values))
    assert d._interpolant_integral() == pytest.approx(1.0, abs=1e-6)
    assert 0 < model.fit_info["eigenvalue"] < 10


def test_per_channel_fit_round_trip_and_sampling(tmp_path):
    from brdffit.microfacet.per_channel import PerChannelBRDF

    brdf = MicrofacetBRDF(GGX(0.2), SchlickFresnel([0.9, 0.5, 0.2]))
    model = fit_tabulated(brdf, per_channel=True, n=32, hotspot="G2", tol=1e-8)
    assert isinstance(model, PerChannelBRDF)
    back = load_fit(save_fit(model, tmp_path / "pc.npz"))
    wi, wo = _random_pairs(seed=4)
    np.testing.assert_array_equal(back.eval(wi, wo), model.eval(wi, wo))
    ok, res = check_sampling(model, [[0.3, 0.2, np.sqrt(0.87)]], sample_count=40000,
                             res_theta=16, res_phi=32, ires=3)
    assert ok, "\n".join(map(str, res))


def test_anisotropic_visible_sampling_matches_analytic():
    """Rejection-sampled visible normals of a 2D table follow the analytic VNDF (grazing w)."""
    d0 = Beckmann(0.25, 0.1, 0.3)
    _, theta, _, _ = radial_rule(48, "gauss")
    phi = 2 * np.pi * np.arange(48) / 48
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    r = np.tan(th)
    d = TabulatedSlopeDistribution(d0.pdf(np.stack([-r * np.cos(ph), -r * np.sin(ph)], -1)),
                                   rule="gauss")
    w = np.array([np.sin(1.35) * np.cos(2.0), np.sin(1.35) * np.sin(2.0), np.cos(1.35)])
    u = np.random.default_rng(7).random((100000, 2))
    m = d.sample_visible(w, u)
    m0 = d0.sample_visible(w, u)
    np.testing.assert_allclose(m.mean(0), m0.mean(0), atol=4e-3)
    np.testing.assert_allclose((m**2).mean(0), (m0**2).mean(0), atol=4e-3)
    # deterministic for given (w, u) although the rejection draws extra numbers
    np.testing.assert_array_equal(d.sample_visible(w, u[:100]), d.sample_visible(w, u[:100]))


def test_sampling_tables_are_built_on_first_use_with_the_same_samples():
    """The fit builds its sampling tables on first use; prepare_sampling builds them now:
    the same samples either way."""
    brdf = MicrofacetBRDF(GGX(0.3), SchlickFresnel(0.9))
    lazy = fit_tabulated(brdf).distribution
    eager = fit_tabulated(brdf).distribution
    assert lazy._sampling is None and lazy._visible is None   # a saved fit never needs them
    eager.prepare_sampling()
    assert eager._sampling is not None and eager._visible is not None
    u = np.random.default_rng(2).random((1000, 2))
    w = np.array([0.3, 0.1, 0.9]) / np.linalg.norm([0.3, 0.1, 0.9])
    np.testing.assert_array_equal(lazy.sample(u), eager.sample(u))
    np.testing.assert_array_equal(lazy.sample_visible(w, u), eager.sample_visible(w, u))
    np.testing.assert_array_equal(lazy.sigma_visible(w), eager.sigma_visible(w))
