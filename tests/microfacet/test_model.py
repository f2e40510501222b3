"""MicrofacetBRDF / SumBRDF: Eq. 1 values, reciprocity, energy, sampling (chi-square), files."""

import math

import numpy as np
import pytest

from brdffit.brdf import IsotropicBRDF
from brdffit.io.fitfile import load_fit, save_fit
from brdffit.microfacet import (GGX, Beckmann, ConductorFresnel, DielectricFresnel,
                                GeneralizedSchlickFresnel, MicrofacetBRDF, ScaledDistribution,
                                SchlickFresnel, SumBRDF, TabulatedFresnel)
from brdffit.testing.chi2 import check_sampling


def _dirs(rng, n):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    return v


def _models():
    yield "ggx-iso", MicrofacetBRDF(GGX(0.3), SchlickFresnel(0.04))
    yield "beckmann-iso", MicrofacetBRDF(Beckmann(0.25), DielectricFresnel(1.5))
    yield "ggx-aniso-rho", MicrofacetBRDF(GGX(0.15, 0.45, 0.5), ConductorFresnel(1.2, 3.0))
    yield "beckmann-aniso-rho-diffuse", MicrofacetBRDF(
        Beckmann(0.2, 0.4, -0.5), DielectricFresnel(1.5), diffuse=[0.5, 0.3, 0.2])
    yield "ggx-diffuse-uncorrelated", MicrofacetBRDF(
        GGX(0.2), GeneralizedSchlickFresnel(0.5, 0.1), diffuse=0.3, correlated=False)
    yield "scaled-ggx", MicrofacetBRDF(ScaledDistribution(GGX(0.5), 0.4, 1.2))
    yield "two-lobe", SumBRDF([MicrofacetBRDF(GGX(0.08), SchlickFresnel(0.9), specular=0.4),
                               MicrofacetBRDF(Beckmann(0.4), SchlickFresnel(0.5))])


MODELS = list(_models())


def test_eval_matches_textbook_isotropic_ggx():
    a, f0 = 0.27, 0.05
    m = MicrofacetBRDF(GGX(a), SchlickFresnel(f0), diffuse=0.2)
    rng = np.random.default_rng(0)
    wi, wo = _dirs(rng, 50), _dirs(rng, 50)
    got = m.eval(wi, wo)[:, 0]
    for k in range(50):
        i, o = wi[k], wo[k]
        h = (i + o) / np.linalg.norm(i + o)
        th = math.acos(h[2])
        D = a * a / (math.pi * math.cos(th) ** 4 * (a * a + math.tan(th) ** 2) ** 2)
        lam = lambda w: (-1 + math.sqrt(1 + a * a * (1 - w[2] ** 2) / w[2] ** 2)) / 2  # noqa
        G = 1 / (1 + lam(i) + lam(o))
        c = float(i @ h)
        F = f0 + (1 - f0) * (1 - c) ** 5
        ref = F * D * G / (4 * i[2] * o[2]) + 0.2 / math.pi
        assert got[k] == pytest.approx(ref, rel=1e-10)


@pytest.mark.parametrize("name,m", MODELS, ids=[n for n, _ in MODELS])
def test_reciprocity_and_horizon(name, m):
    rng = np.random.default_rng(1)
    wi, wo = _dirs(rng, 2000), _dirs(rng, 2000)
    np.testing.assert_allclose(m.eval(wi, wo), m.eval(wo, wi), rtol=1e-10, atol=1e-14)
    assert np.all(m.eval(wi * [1, 1, -1], wo) == 0)
    assert np.all(m.eval(wi, wo) >= 0)


@pytest.mark.parametrize("dist", [GGX(0.3), Beckmann(0.3), GGX(0.1, 0.5, 0.6),
                                  Beckmann(0.6, 0.2, -0.4), GGX(1.0)], ids=repr)
def test_white_furnace_albedo_at_most_one(dist):
    m = MicrofacetBRDF(dist)                                    # F = 1
    th = np.array([0.0, 0.6, 1.2, 1.5])
    # importance-sampled estimate: weight f cos / pdf
    u = np.random.default_rng(4).random((40_000, 2))
    for t in th:
        wi = np.array([math.sin(t), 0, math.cos(t)])
        wo, pdf = m.sample(np.broadcast_to(wi, (len(u), 3)), u)
        ok = pdf > 0
        w = np.zeros(len(u))
        w[ok] = m.eval(wi, wo[ok])[:, 0] * wo[ok, 2] / pdf[ok]
        alb = w.mean()
        se = w.std() / np.sqrt(len(u))
        assert alb <= 1.0 + 4 * se + 1e-3, (t, alb)
        assert alb > 0.25                                       # not trivially zero
    # the uncorrelated G loses more energy than the height-correlated one
    unc = MicrofacetBRDF(dist, correlated=False)
    assert unc.albedo([1.2])[0, 0] < m.albedo([1.2])[0, 0]


def test_isotropic_models_are_isotropic_brdfs():
    iso = MicrofacetBRDF(GGX(0.2), SchlickFresnel(0.1))
    aniso = MicrofacetBRDF(GGX(0.2, 0.3))
    assert isinstance(iso, IsotropicBRDF) and iso.isotropic
    assert not isinstance(aniso, IsotropicBRDF) and not aniso.isotropic
    rng = np.random.default_rng(2)
    th, td, pd = rng.uniform(0, 1.4, 200), rng.uniform(0, 1.4, 200), rng.uniform(0, 6.2, 200)
    from brdffit.geometry import half_diff_to_io
    wi, wo = half_diff_to_io(th, rng.uniform(0, 6.2, 200), td, pd)
    ref = iso.eval(wi, wo)
    np.testing.assert_allclose(iso.eval_hd(th, td, pd), ref, rtol=1e-9, atol=1e-12)
    # isotropy: rotating both directions about the normal does not change the value
    c, s = math.cos(0.7), math.sin(0.7)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    np.testing.assert_allclose(iso.eval(wi @ R.T, wo @ R.T), ref, rtol=1e-9, atol=1e-12)
    assert not np.allclose(aniso.eval(wi @ R.T, wo @ R.T), aniso.eval(wi, wo))


WIS = [[0, 0, 1], [math.sin(0.8), 0, math.cos(0.8)],
       [math.sin(1.35) * math.cos(2.2), math.sin(1.35) * math.sin(2.2), math.cos(1.35)]]


@pytest.mark.parametrize("name,m", MODELS, ids=[n for n, _ in MODELS])
def test_sampling_chi2(name, m):
    ok, res = check_sampling(m, WIS, sample_count=30_000, res_theta=16, res_phi=32)
    for r in res:
        print(f"{name}: {r}")
    assert ok, "\n".join(str(r) for r in res)


def test_chi2_detects_a_wrong_pdf():
    class Wrong(MicrofacetBRDF):
        def pdf(self, wi, wo):                        # 30 % too dense towards +x
            return super().pdf(wi, wo) * (1.0 + 0.3 * np.asarray(wo)[..., 0])

    ok, res = check_sampling(Wrong(GGX(0.3)), WIS[1:2], sample_count=50_000, res_theta=24,
                             res_phi=48)
    assert not ok


def test_slope_sampling_fallback_matches_pdf():
    from brdffit.microfacet.base import SlopeDistribution

    class NoVNDF(GGX):
        sample_visible = SlopeDistribution.sample_visible    # the base one (raises)

    m = MicrofacetBRDF(NoVNDF(0.3, 0.2, 0.3), SchlickFresnel(0.1))
    assert not m._has_vndf
    ok, res = check_sampling(m, WIS[:2], sample_count=30_000, res_theta=16, res_phi=32)
    assert ok, "\n".join(str(r) for r in res)


@pytest.mark.parametrize("name,m", MODELS + [
    ("tabulated-fresnel", MicrofacetBRDF(GGX(0.2), TabulatedFresnel(
        np.linspace(0, np.pi / 2, 7), np.linspace(0.1, 1, 21).reshape(7, 3)))),
    ("no-fresnel", MicrofacetBRDF(Beckmann(0.3, 0.1, 0.2), None, specular=[1, 0.5, 0.2]))],
    ids=[n for n, _ in MODELS] + ["tabulated-fresnel", "no-fresnel"])
def test_save_load_round_trip(tmp_path, name, m):
    path = save_fit(m, tmp_path / f"{name}.npz")
    back = load_fit(path)
    assert type(back) is type(m)
    rng = np.random.default_rng(3)
    wi, wo = _dirs(rng, 500), _dirs(rng, 500)
    np.testing.assert_array_equal(back.eval(wi, wo), m.eval(wi, wo))
    np.testing.assert_array_equal(back.pdf(wi, wo), m.pdf(wi, wo))


def test_unregistered_component_is_a_clear_error():
    from brdffit.microfacet.base import Fresnel

    class Odd(Fresnel):
        def eval(self, c):
            return np.ones(np.shape(c) + (3,))

    with pytest.raises(TypeError, match="register_fresnel"):
        MicrofacetBRDF(GGX(0.2), Odd()).to_state()
    with pytest.raises(ValueError, match="unknown distribution kind"):
        MicrofacetBRDF.from_state({"distribution": {"kind": "nope", "params": {}}}, {})


def test_constructor_validation():
    with pytest.raises(TypeError):
        MicrofacetBRDF("ggx", None)
    with pytest.raises(ValueError):
        MicrofacetBRDF(GGX(0.2), None, diffuse=[0.1, -0.2, 0.3])


def test_registering_a_new_distribution_kind(tmp_path):
    from brdffit.microfacet import register_distribution

    class Stretched(GGX):                     # a "new" distribution with a table argument
        def __init__(self, alpha, table):
            super().__init__(alpha)
            self.table = np.asarray(table, dtype=float)

        def to_state(self):
            return {"alpha": self.alpha_x}, {"table": self.table}

        @classmethod
        def from_state(cls, params, arrays):
            return cls(params["alpha"], arrays["table"])

    register_distribution("test-stretched", Stretched)
    m = MicrofacetBRDF(Stretched(0.3, [1.0, 2.0]), SchlickFresnel(0.2))
    back = load_fit(save_fit(m, tmp_path / "s.npz"))
    assert type(back.distribution) is Stretched
    np.testing.assert_array_equal(back.distribution.table, [1.0, 2.0])
    wi = np.array([[0.3, 0.1, 0.95]]) / np.linalg.norm([0.3, 0.1, 0.95])
    np.testing.assert_array_equal(back.eval(wi, wi[:, [1, 0, 2]]), m.eval(wi, wi[:, [1, 0, 2]]))


def test_pickle_keeps_class_and_values():
    import pickle

    for m in (MicrofacetBRDF(GGX(0.2), SchlickFresnel(0.3), diffuse=0.1),
              MicrofacetBRDF(Beckmann(0.2, 0.3, 0.4)), MODELS[-1][1]):
        c = pickle.loads(pickle.dumps(m))
        assert type(c) is type(m)
        rng = np.random.default_rng(8)
        wi, wo = _dirs(rng, 50), _dirs(rng, 50)
        np.testing.assert_array_equal(c.eval(wi, wo), m.eval(wi, wo))
