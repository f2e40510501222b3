"""Procedural scene content (NumPy only, no Mitsuba): environment, torus knot, texture."""

from __future__ import annotations

import numpy as np

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
