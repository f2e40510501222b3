"""One compiled render kernel for every material and every peak window: the evaluators'
and the proposal's parameters and the window's position are kernel parameters, not
constants, so a second material (or window) is rendered without a new LLVM compilation;
the window sensor renders the same pixels with the same random numbers as a film crop."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.evaluation.render import available

needs_mitsuba = pytest.mark.skipif(not available(), reason="Mitsuba 3 LLVM back-end unavailable")


def _models(alpha, f0, diffuse):
    from brdffit.microfacet import GGX, Beckmann, MicrofacetBRDF, SchlickFresnel

    return {"ggx": MicrofacetBRDF(GGX(alpha), SchlickFresnel(f0), diffuse=diffuse),
            "beckmann": MicrofacetBRDF(Beckmann(1.5 * alpha), SchlickFresnel(f0[::-1]),
                                       diffuse=diffuse)}


def _compiled(dr, render) -> list:
    """The hashes of the kernels ``render()`` did not find in memory (new kernels, whether
    Dr.Jit then compiled them or loaded them from its disk cache)."""
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        render()
        return [k["hash"] for k in dr.kernel_history()
                if k["type"] == dr.KernelType.JIT and not k["cache_hit"]]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)


@needs_mitsuba
@pytest.mark.render
def test_a_second_material_reuses_the_first_ones_kernel():
    from brdffit.evaluation.render._mitsuba import load
    from brdffit.evaluation.render.core import MultiRenderer
    from brdffit.evaluation.render.proposal import Proposal

    _, dr = load()
    first = MultiRenderer(_models(0.2, [0.9, 0.6, 0.3], [0.05, 0.05, 0.1]), scene="sphere-env",
                          resolution=16, proposal=Proposal([0.1, 0.4], [0.3, 0.3], 0.4))
    first.render(0, 2)
    second = MultiRenderer(_models(0.35, [0.5, 0.4, 0.8], [0.2, 0.1, 0.02]), scene="sphere-env",
                           resolution=16, proposal=Proposal([0.05, 0.3], [0.2, 0.5], 0.3))
    assert _compiled(dr, lambda: second.render(1, 2)) == []
    a, b = first.render(1, 2).images, second.render(1, 2).images
    assert not np.allclose(a["ggx"], b["ggx"])        # the parameters did reach the kernel


def _merl_table(seed: int) -> np.ndarray:
    """A smooth positive full-φ MERL-grid table (90, 90, 360, 3): a measured reference."""
    rng = np.random.default_rng(seed)
    th = np.linspace(0.0, 1.0, 90)[:, None, None, None]
    td = np.linspace(0.0, 1.0, 90)[None, :, None, None]
    ph = np.linspace(0.0, 2.0 * np.pi, 360, endpoint=False)[None, None, :, None]
    lobe = np.exp(-rng.uniform(5.0, 40.0) * th ** 2) * (1.0 + 0.5 * td ** 4)
    return (rng.uniform(0.02, 0.2, 3) + rng.uniform(1.0, 30.0, 3) * lobe
            * (1.0 + 0.05 * np.cos(ph)))


@needs_mitsuba
@pytest.mark.render
def test_a_second_measured_reference_reuses_the_first_ones_kernel():
    """The reference table is read with packet loads (``_gather_rgb``); the kernel must not
    depend on which table it reads, or every material compiles its renders again."""
    from brdffit.evaluation.render._mitsuba import load
    from brdffit.evaluation.render.core import MultiRenderer
    from brdffit.evaluation.render.drjit_eval import MERLTableEval
    from brdffit.evaluation.render.proposal import Proposal

    _, dr = load()
    refs = [MERLTableEval(_merl_table(seed)) for seed in (1, 2, 3)]

    def renderer(ev):
        return MultiRenderer({"ref": None}, scene="sphere-env", resolution=16,
                             proposal=Proposal([0.2], [0.5], 0.5), evaluators={"ref": ev})

    renderer(refs[0]).render(0, 2)
    images = [renderer(refs[0]).render(1, 2).images["ref"]]
    for ev in refs[1:]:
        mr = renderer(ev)
        assert _compiled(dr, lambda: mr.render(1, 2)) == []
        images.append(mr.render(1, 2).images["ref"])
    assert not np.allclose(images[0], images[1])      # each table did reach the kernel


@needs_mitsuba
@pytest.mark.render
def test_window_renders_the_film_crop_with_one_kernel():
    from brdffit.evaluation.render._mitsuba import load
    from brdffit.evaluation.render.core import MultiRenderer
    from brdffit.evaluation.render.scenes import _camera

    mi, dr = load()
    mr = MultiRenderer(_models(0.2, [0.9, 0.6, 0.3], [0.05, 0.05, 0.1]), scene="sphere-env",
                       resolution=32)
    window = mr.render(3, 16, crop=(12, 14, 3, 3)).images["ggx"]
    cam = _camera(32, 4)
    cam["film"] |= {"crop_offset_x": 12, "crop_offset_y": 14, "crop_width": 3, "crop_height": 3}
    crop = np.array(mi.render(mr.scene, integrator=mr.integrator, sensor=mi.load_dict(cam),
                              seed=3, spp=16))[..., 4:7]
    assert window.shape == crop.shape == (3, 3, 3)
    assert crop.max() > 0
    np.testing.assert_allclose(window, crop, rtol=1e-4, atol=1e-6 * crop.max())
    assert _compiled(dr, lambda: mr.render(3, 16, crop=(20, 5, 3, 3))) == []
    for outside in ((30, 5, 3, 3), (-1, 0, 3, 3), (0, 0, 0, 3)):
        with pytest.raises(ValueError, match="crop: expected a window inside the 32² film"):
            mr.render(3, 16, crop=outside)


@needs_mitsuba
@pytest.mark.render
def test_table_packet_loads_read_the_rgb_entries():
    """``_table_buffer``'s RGBA entries read by ``_gather_rgb`` are the RGB values a plain
    ``Color3f`` gather reads from the unpadded table (0 for inactive lanes)."""
    from brdffit.evaluation.render._mitsuba import load
    from brdffit.evaluation.render.drjit_eval import _gather_rgb, _table_buffer

    mi, dr = load()
    table = np.random.default_rng(5).random((6, 7, 3)) + 0.01
    eps, buf = _table_buffer(table, "log")
    plain = mi.Float(np.log(table + eps).astype(np.float32).ravel())
    index = mi.UInt32(np.random.default_rng(6).permutation(42))
    active = mi.Bool(np.arange(42) % 5 != 0)
    got, want = _gather_rgb(buf, index, active), dr.gather(mi.Color3f, plain, index, active)
    for c in range(3):
        np.testing.assert_array_equal(np.array(got[c]), np.array(want[c]))
    assert np.count_nonzero(np.array(want[0])) == int(np.count_nonzero(np.arange(42) % 5))
