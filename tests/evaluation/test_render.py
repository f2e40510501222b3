"""Rendering with Mitsuba 3: white furnace, table vs closed form, noise floor, scenes,
spatially varying roughness. Small images (≤ 64²) and spp to keep the budget."""

from __future__ import annotations

import os

import numpy as np
import pytest

from brdffit.evaluation.render import available

pytestmark = [pytest.mark.render,
              pytest.mark.skipif(not available(), reason="Mitsuba 3 LLVM back-end unavailable")]

RES, SPP = 48, 64


def _ggx(alpha=0.2, diffuse=(0.1, 0.1, 0.2)):
    from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel

    return MicrofacetBRDF(GGX(alpha), SchlickFresnel([0.9, 0.6, 0.3]), diffuse=list(diffuse))


def _view_cosines(res, fov=30.0, distance=4.2):
    """cos θv of the unit sphere seen by the scenes' camera, NaN off the sphere (own
    ray-sphere intersection, independent of Mitsuba)."""
    c = (np.arange(res) + 0.5) / res * 2 - 1
    x, y = np.meshgrid(c, -c)
    tn = np.tan(np.radians(fov / 2))
    d = np.stack([x * tn, y * tn, -np.ones_like(x)], -1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.array([0.0, 0.0, distance])
    b = d @ o
    disc = b * b - (o @ o - 1.0)
    t = -b - np.sqrt(np.where(disc > 0, disc, np.nan))
    p = o + t[..., None] * d
    return -np.sum(d * p, -1)


def test_white_furnace_matches_albedo():
    """White-Fresnel GGX sphere in a constant unit environment: each pixel is the
    directional albedo at its viewing angle (≤ 1: energy is lost, never created)."""
    from brdffit.evaluation.render import render_ex
    from brdffit.microfacet import GGX, MicrofacetBRDF

    brdf = MicrofacetBRDF(GGX(0.5), None)
    res = render_ex(brdf, scene="sphere-env", envmap=np.ones((8, 16, 3), np.float32),
                    spp=SPP, resolution=RES, seed=0)
    assert res.info["path"] == "closed-form"
    cv = _view_cosines(RES)
    inside = res.mask & np.isfinite(cv)
    assert inside.sum() > 0.4 * RES * RES
    thetas = np.linspace(0.0, np.radians(89.0), 24)
    alb = brdf.albedo(thetas, n_samples=1 << 16)[:, 0]
    expected = np.interp(np.arccos(np.clip(cv[inside], 0, 1)), thetas, alb)
    got = res.image[inside].mean(-1)
    assert abs(got.mean() / expected.mean() - 1.0) < 0.01
    # per viewing-angle band: matches and never exceeds 1
    bands = np.digitize(cv[inside], [0.3, 0.6, 0.85])
    for k in range(4):
        sel = bands == k
        assert got[sel].mean() <= 1.0 + 1e-3
        assert abs(got[sel].mean() - expected[sel].mean()) < 0.02
    assert expected.mean() < 0.99  # the test is not comparing 1 with 1


def test_table_path_agrees_with_closed_form():
    from brdffit.evaluation.render import Renderer, psnr

    brdf = _ggx()
    closed = Renderer(brdf, spp=SPP, resolution=RES, mode="closed")
    a, b = closed.render(0), closed.render(1)
    floor = psnr(a.image, b.image, a.mask)
    # same seed → same sample streams → the same image (deterministic)
    np.testing.assert_array_equal(closed.render(0).image, a.image)
    table = Renderer(brdf, spp=SPP, resolution=RES, mode="table").render(0)
    assert table.info["path"] == "table"
    p_table = psnr(a.image, table.image, a.mask)
    # a slightly different material is clearly detected at these settings
    other = Renderer(_ggx(alpha=0.3), spp=SPP, resolution=RES, mode="closed").render(0)
    p_other = psnr(a.image, other.image, a.mask)
    assert p_table > floor - 3.0, (p_table, floor)
    assert p_other < p_table - 3.0, (p_other, p_table)
    assert 20.0 < floor < 80.0


def test_noise_floor_reports_psnr():
    from brdffit.evaluation.render import noise_floor

    nf = noise_floor(_ggx(), scene="sphere-point", spp=16, resolution=32)
    assert np.isfinite(nf["psnr"]) and nf["psnr"] > 15.0
    assert nf["seeds"] == [0, 1]


@pytest.mark.parametrize("scene", ["sphere-point", "knot"])
def test_scenes_render_foreground(scene):
    from brdffit.evaluation.render import render, render_ex

    img, mask = render(_ggx(), scene=scene, spp=8, resolution=32, return_mask=True)
    alpha = render_ex(_ggx(), scene=scene, spp=8, resolution=32).alpha
    assert img.shape == (32, 32, 3) and img.dtype == np.float32
    assert np.all(np.isfinite(img)) and img.min() >= 0
    assert 0.1 < mask.mean() < 0.95           # object and background both present
    assert img[mask].mean() > 1e-3            # lit
    assert np.abs(img[alpha <= 0]).max() < 1e-6   # emitters hidden: background black
    assert np.all(alpha[mask] >= 0.999) and (alpha <= 0).mean() > 0.05


def test_spatially_varying_roughness():
    from brdffit.evaluation.render import Renderer, psnr

    brdf = _ggx(diffuse=(0.0, 0.0, 0.0))
    plain = Renderer(brdf, scene="sphere-svrough", spp=16, resolution=RES,
                     alpha_texture=np.ones((4, 4), np.float32)).render(0)
    ref = Renderer(brdf, scene="sphere-env", spp=16, resolution=RES).render(0)
    # a unit roughness texture is the uniform material (same sample streams)
    assert psnr(ref.image, plain.image, ref.mask) > 60.0
    textured = Renderer(brdf, scene="sphere-svrough", spp=16, resolution=RES).render(0)
    assert psnr(ref.image, textured.image, ref.mask) < 35.0


def test_tabulated_distribution_with_roughness_texture():
    """A tabulated slope distribution (Dupuy 2015) holding a GGX(0.25) table renders the
    spatially varying roughness scene like the closed-form GGX(0.25) (Eq. 9 applied per
    texel to the table in Dr.Jit)."""
    from brdffit.evaluation.render import Renderer, psnr
    from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel
    from brdffit.microfacet.tabulated import TabulatedSlopeDistribution, radial_rule

    a = 0.25
    _, _, r, _ = radial_rule(90, "merl")
    p = 1.0 / (np.pi * a * a * (1.0 + (r / a) ** 2) ** 2)
    fres = SchlickFresnel([0.9, 0.7, 0.4])
    tab = MicrofacetBRDF(TabulatedSlopeDistribution(p, rule="merl"), fres)
    ggx = MicrofacetBRDF(GGX(a), fres)
    opts = dict(scene="sphere-svrough", spp=32, resolution=RES)
    rt = Renderer(tab, **opts)
    assert rt.evaluator.path == "closed-form" and "radial-table" in rt.evaluator.describe()
    rg = Renderer(ggx, **opts)
    g0, g1 = rg.render(0), rg.render(1)
    floor = psnr(g0.image, g1.image, g0.mask)
    t0 = rt.render(0)
    p_tab = psnr(g0.image, t0.image, g0.mask)
    p_other = psnr(g0.image, Renderer(MicrofacetBRDF(GGX(0.35), fres), **opts).render(0).image, g0.mask)
    assert p_tab > floor - 3.0, (p_tab, floor)
    assert p_other < p_tab - 3.0, (p_other, p_tab)


def test_roughness_texture_on_table_path_warns():
    from brdffit.evaluation.render import Renderer

    with pytest.warns(RuntimeWarning, match="roughness texture is ignored"):
        Renderer(_ggx(), scene="sphere-svrough", spp=4, resolution=16, mode="table")


def test_plugin_by_name_in_scene_dict():
    """The registered plugin name works in plain Mitsuba dicts (evaluator_id)."""
    from brdffit.evaluation.render import drjit_eval as dj
    from brdffit.evaluation.render import plugin

    key = plugin.register_evaluator(dj.MicrofacetEval(dj.GGXDist(0.2), dj.ConstantFresnelDJ(1.0)))
    try:
        bsdf = dj.mi.load_dict({"type": plugin.PLUGIN_NAME, "evaluator_id": key})
        assert "microfacet" in bsdf.to_string()
    finally:
        plugin.unregister_evaluator(key)
    with pytest.raises(Exception, match="evaluator"):
        dj.mi.load_dict({"type": plugin.PLUGIN_NAME, "evaluator_id": key})


def test_render_threads_are_read_checked_and_applied(monkeypatch):
    """``BRDFFIT_RENDER_THREADS``: a positive integer or a clear error; a new process's
    Dr.Jit runs that many threads."""
    import subprocess
    import sys

    from brdffit.evaluation.render import _mitsuba

    monkeypatch.delenv("BRDFFIT_RENDER_THREADS", raising=False)
    assert _mitsuba._render_threads() is None
    monkeypatch.setenv("BRDFFIT_RENDER_THREADS", " 3 ")
    assert _mitsuba._render_threads() == 3
    for bad in ("0", "-1", "two", "1.5", "99999"):
        monkeypatch.setenv("BRDFFIT_RENDER_THREADS", bad)
        with pytest.raises(_mitsuba.MitsubaUnavailable, match="BRDFFIT_RENDER_THREADS: "
                                                             "expected an integer"):
            _mitsuba._render_threads()
    code = ("from brdffit.evaluation.render._mitsuba import load; "
            "mi, dr = load(); print(dr.thread_count())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "BRDFFIT_RENDER_THREADS": "1"}, timeout=120)
    assert out.returncode == 0 and out.stdout.split()[-1] == "1", out.stderr[-1000:]
