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
