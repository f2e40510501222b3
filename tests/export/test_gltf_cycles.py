"""Cycles' Principled BSDF as Blender's glTF importer sets it up (brdffit.export.gltf_cycles):
its parts against the library's own components and against energy conservation. The check
against Blender itself is the round trip in tests/evaluation/test_engines_blender.py."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.export.gltf import GLTFBRDF, gltf_equivalent
from brdffit.export.gltf_cycles import (_MU_NODES, CyclesPrincipledBRDF, _lambda, _Lobe,
                                         _lobe_tables_kernel)
from brdffit.microfacet import GGX, DielectricFresnel, MicrofacetBRDF, SchlickFresnel
from tests.support.engine_materials import ENGINE_TEST_MATERIALS


def _pairs(n, seed):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2 * n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v[:n], v[n:]


def test_default_dielectric_is_the_real_fresnel_on_correlated_ggx():
    """specularFactor 1, white tint, ior 1.5, GGX: F of the real index (f0 = F0(1.5), f90
    = 1), height-correlated Smith; no diffuse (black base)."""
    wi, wo = _pairs(4000, 1)
    got = CyclesPrincipledBRDF([0, 0, 0], 0.0, 0.5, ior=1.5, multiscatter=False).eval(wi, wo)
    want = MicrofacetBRDF(GGX(0.25), DielectricFresnel(1.5), correlated=True).eval(wi, wo)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


def test_specular_factor_scales_f0_only():
    """glTF's f90 = specularFactor is not carried: at grazing V·H the reflectance still
    tends to 1, where the specification's BRDF tends to specularFactor."""
    wi = np.array([[np.sin(1.55), 0.0, np.cos(1.55)]])
    wo = np.array([[-np.sin(1.55), 0.0, np.cos(1.55)]])     # mirror pair: V·H = cos 88.8°
    kw = dict(base_color=[0, 0, 0], metallic=0.0, roughness=0.3, specular_factor=0.2, ior=1.5)
    cyc = CyclesPrincipledBRDF(**kw, multiscatter=False)
    spec = GLTFBRDF(**kw)
    ref = CyclesPrincipledBRDF(**dict(kw, specular_factor=1.0), multiscatter=False)
    assert cyc.eval(wi, wo)[0, 0] > 0.8 * ref.eval(wi, wo)[0, 0]
    assert spec.eval(wi, wo)[0, 0] < 0.3 * ref.eval(wi, wo)[0, 0]
    # at normal incidence F0 is scaled: F0(1.5) · 0.2
    n = np.array([[0.0, 0.0, 1.0]])
    ratio = cyc.eval(n, n)[0, 0] / ref.eval(n, n)[0, 0]
    assert ratio == pytest.approx(0.2, rel=0.02)


def _albedo(brdf, mu, n=200_000, seed=0):
    """Directional albedo at N·V = mu: ∫ f cos θi dωi by uniform hemisphere sampling."""
    rng = np.random.default_rng(seed)
    z = rng.random(n)
    phi = 2 * np.pi * rng.random(n)
    r = np.sqrt(1 - z * z)
    wi = np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)
    wo = np.broadcast_to([np.sqrt(1 - mu * mu), 0.0, mu], wi.shape)
    return 2 * np.pi * np.mean(brdf.eval(wi, wo) * z[:, None], axis=0)


@pytest.mark.parametrize("mu", [0.3, 0.7, 1.0])
def test_multiscatter_white_metal_conserves_energy(mu):
    """A white metal (F = 1) with multiscatter GGX reflects all the light (Cycles' energy
    compensation, 1 + (1 − E)/E); single-scatter GGX loses some at roughness 0.8."""
    multi = _albedo(CyclesPrincipledBRDF([1, 1, 1], 1.0, 0.8), mu)
    single = _albedo(CyclesPrincipledBRDF([1, 1, 1], 1.0, 0.8, multiscatter=False), mu)
    np.testing.assert_allclose(multi, 1.0, atol=0.03)
    assert np.all(single < 0.95)


def test_diffuse_is_dimmed_by_one_scalar():
    """Under a coloured specular tint, every channel of the diffuse is dimmed by the same
    factor (the largest channel of the specular albedo): the diffuse part of a white base
    (the BRDF minus that of a black base) is grey."""
    kw = dict(metallic=0.0, roughness=0.1, ior=1.5, specular_color=[0.0, 1.0, 0.5],
              multiscatter=False)
    wi, wo = _pairs(50, 3)
    white = CyclesPrincipledBRDF([1, 1, 1], **kw).eval(wi, wo)
    diffuse = (white - CyclesPrincipledBRDF([0, 0, 0], **kw).eval(wi, wo))[0]
    assert diffuse.max() - diffuse.min() < 1e-6 * diffuse.max()
    assert diffuse[0] < 0.99 / np.pi          # dimmed, red included (its own F0 is 0)


def test_equivalent_engine_is_checked_and_coats_are_layered():
    fit = MicrofacetBRDF(GGX(0.2), SchlickFresnel(0.04), diffuse=[0.5, 0.3, 0.2])
    with pytest.raises(ValueError, match="engine"):
        gltf_equivalent(fit, engine="unreal")
    eq = gltf_equivalent(fit, engine="blender")
    assert isinstance(eq, CyclesPrincipledBRDF) and eq.multiscatter
    assert not gltf_equivalent(fit, engine="blender-ggx").multiscatter
    wi, wo = _pairs(2000, 2)
    bare = CyclesPrincipledBRDF([0.5, 0.3, 0.2], 0.0, 0.4)
    coated = CyclesPrincipledBRDF([0.5, 0.3, 0.2], 0.0, 0.4, clearcoat=1.0,
                                  clearcoat_roughness=0.05)
    # far from the coat's mirror direction the coat only takes light away
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    off = h[:, 2] < 0.9
    assert np.all(coated.eval(wi, wo)[off] <= bare.eval(wi, wo)[off] + 1e-12)
    with pytest.raises(ValueError, match="anisotropy"):
        CyclesPrincipledBRDF([0.5, 0.5, 0.5], 0.0, 0.4, anisotropy_strength=0.5)


def _lobe_tables_per_node(lobe, n):
    """The lobe's ``(E, S)`` node by node: one VNDF quadrature per μ, written out."""
    u = (np.arange(n) + 0.5) / n
    U1, U2 = (x.ravel() for x in np.meshgrid(u, u, indexing="ij"))
    E, S = [], []
    for mu in _MU_NODES:
        wo = np.array([[np.sqrt(1.0 - mu * mu), 0.0, mu]])
        h = lobe._sample_visible_normals(wo, U1, U2)[0]
        c = h @ wo[0]
        wi_z = 2.0 * c * h[:, 2] - mu
        g2 = 1.0 / (1.0 + _lambda(lobe.alpha, wi_z) + _lambda(lobe.alpha, mu))
        w = np.where(wi_z > 0, g2 * (1.0 + _lambda(lobe.alpha, mu)), 0.0)
        E.append(w.mean())
        S.append((w * lobe.s(c)).mean() / w.mean() if lobe.eta else 0.0)
    return np.array(E), np.array(S)


@pytest.mark.parametrize("alpha, eta", [(0.0225, 1.5), (0.3, 1.5), (0.8, 2.4), (0.5, None),
                                        (1e-5, 1.01)])
def test_lobe_tables_kernel_and_numpy_agree_with_the_quadrature_per_node(alpha, eta):
    """The compiled kernel and the NumPy pass (all nodes at once) give the tables of the
    per-node quadrature to rounding."""
    lobe = _Lobe(alpha, eta, n=32)
    u = (np.arange(32) + 0.5) / 32
    want_E, want_S = _lobe_tables_per_node(lobe, 32)
    E, S = lobe._tables_numpy(u)
    np.testing.assert_allclose(E, want_E, rtol=1e-12, atol=0)
    np.testing.assert_allclose(S, want_S, rtol=1e-12, atol=1e-300)
    kE, kS = np.empty(_MU_NODES.size), np.empty(_MU_NODES.size)
    _lobe_tables_kernel(lobe.alpha, float(eta or 0.0), _MU_NODES, u, kE, kS)
    np.testing.assert_allclose(kE, want_E, rtol=1e-12, atol=0)
    np.testing.assert_allclose(kS, want_S, rtol=1e-12, atol=1e-300)
    assert np.all((E > 0) & (E <= 1.0 + 1e-12))


@pytest.mark.parametrize("kwargs", [
    *ENGINE_TEST_MATERIALS,
    dict(base_color=[0.6, 0.1, 0.3], metallic=0.0, roughness=0.05, ior=1.0),
    dict(base_color=[0.3, 0.3, 0.3], metallic=0.5, roughness=0.01, specular_factor=0.2)])
@pytest.mark.parametrize("multiscatter", [True, False])
def test_compiled_eval_is_the_numpy_eval(kwargs, multiscatter, monkeypatch):
    """``_eval_compiled`` (:func:`_cycles_kernel`) gives the NumPy path's values to rounding,
    below the horizon included."""
    import brdffit.export.gltf_cycles as gc

    rng = np.random.default_rng(7)
    v = rng.normal(size=(2, 50, 80, 3))
    wi, wo = v / np.linalg.norm(v, axis=-1, keepdims=True)
    brdf = CyclesPrincipledBRDF(**kwargs, multiscatter=multiscatter)
    got = brdf._eval_compiled(wi, wo)
    monkeypatch.setattr(gc, "_numba", None)
    want = brdf.eval(wi, wo)
    assert got.shape == want.shape == (50, 80, 3)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-15)
    assert np.any(want == 0) and np.all(want >= 0)
