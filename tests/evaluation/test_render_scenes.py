"""Procedural scene content (NumPy only, no Mitsuba): environment, torus knot, texture."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.evaluation.render.scenes import procedural_envmap, roughness_texture, torus_knot


def test_procedural_envmap():
    env = procedural_envmap(256, 128)
    assert env.shape == (128, 256, 3) and env.dtype == np.float32
    assert np.all(np.isfinite(env)) and env.min() >= 0
    # HDR: a sun far brighter than the sky, sky brighter than the ground
    assert env.max() > 50 * np.median(env)
    assert env[:20].mean() > env[-20:].mean()


def test_torus_knot_is_a_closed_outward_mesh():
    v, f, n, uv = torus_knot(n_u=96, n_v=12)
    assert v.shape == n.shape == (96 * 12, 3) and uv.shape == (96 * 12, 2)
    assert f.dtype == np.uint32 and f.max() < len(v)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
    # every edge is shared by exactly two faces, in opposite directions (closed, oriented)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]).astype(np.int64)
    key = e[:, 0] * len(v) + e[:, 1]
    rev = e[:, 1] * len(v) + e[:, 0]
    assert len(np.unique(key)) == len(key)
    assert np.all(np.isin(rev, key))
    # face normals agree with the vertex normals (outward winding)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    assert np.all(np.sum(fn * n[f[:, 0]], axis=1) > 0)
    # the enclosed volume is positive (divergence theorem) and smaller than the bounding box
    vol = np.sum(np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]]))) / 6.0
    ext = v.max(0) - v.min(0)
    assert 0 < vol < 0.5 * np.prod(ext)


def test_roughness_texture_range():
    t = roughness_texture(64)
    assert t.shape == (64, 64) and t.min() > 0.2 and t.max() < 2.6 and t.max() / t.min() > 5


def test_paper_scene_suite(shared_data):
    """Bagher 2016 §5's four scenes: a sphere under three maps of increasing dynamic range
    (measured here) and the knot mesh; exposures fixed per scene."""
    from brdffit.evaluation.render.scenes import envmap_stats, scene_suite

    shared_data("envmaps", "sunrise.exr")
    specs, notes = scene_suite("paper")
    assert [s.name for s in specs] == ["sphere-courtyard", "sphere-studio", "sphere-sunrise",
                                       "knot-courtyard"] and notes == []
    assert [s.base for s in specs] == ["sphere-env"] * 3 + ["knot"]
    assert [s.max_depth for s in specs] == [2, 2, 2, 4]
    stats = [envmap_stats(m) for m in ("courtyard", "studio", "sunrise")]
    dec = [s["decades"] for s in stats]
    assert dec[0] < dec[1] < dec[2] and dec[0] < 4.5 and dec[2] > 6.0
    assert stats[0]["top_energy"] < 0.1 < 0.4 < stats[2]["top_energy"]
    for s, st in zip(specs, stats):
        assert s.exposure == pytest.approx(1.0 / st["mean"])


def test_scene_suite_falls_back_without_envmaps(tmp_path, monkeypatch):
    from brdffit.evaluation.render import scenes as S

    monkeypatch.setattr(S, "ENVMAP_DIR", tmp_path)
    specs, notes = S.scene_suite("paper")
    assert [s.name for s in specs] == ["sphere-env", "knot"] and all(s.envmap is None for s in specs)
    assert len(notes) == 1 and "procedural" in notes[0] and str(tmp_path) in notes[0]
    one, _ = S.scene_suite("sphere-point,knot")
    assert [s.name for s in one] == ["sphere-point", "knot"] and one[0].envmap is None
    with pytest.raises(ValueError, match="no environment map"):
        S.scene_spec("sphere-studio")
    with pytest.raises(ValueError, match="unknown scene"):
        S.scene_spec("teapot")
