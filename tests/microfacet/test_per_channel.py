"""Three models, one per colour channel (brdffit.microfacet.per_channel)."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.io.fitfile import load_fit, save_fit
from brdffit.microfacet import GGX, Beckmann, MicrofacetBRDF, SchlickFresnel
from brdffit.microfacet.per_channel import PerChannelBRDF
from tests.support.closed_forms import directions


def _models():
    return [MicrofacetBRDF(GGX(0.1), SchlickFresnel(0.9), diffuse=0.1),
            MicrofacetBRDF(Beckmann(0.3), SchlickFresnel(0.5)),
            MicrofacetBRDF(GGX(0.5, 0.2), SchlickFresnel(0.2), diffuse=0.3)]


def test_channel_c_is_channel_c_of_model_c_and_the_file_round_trips(tmp_path):
    models = _models()
    pc = PerChannelBRDF(models, name="pc")
    wi = directions(np.array([0.1, 0.6, 1.2]), np.array([0.0, 1.0, 2.0]))
    wo = directions(np.array([0.4, 0.2, 0.9]), np.array([3.0, 0.5, 4.0]))
    f = pc.eval(wi, wo)
    for c, m in enumerate(models):
        np.testing.assert_array_equal(f[..., c], m.eval(wi, wo)[..., c])
    back = load_fit(save_fit(pc, tmp_path / "pc.npz"))
    assert isinstance(back, PerChannelBRDF) and back.fit_kind == "tabulated_per_channel"
    np.testing.assert_array_equal(back.eval(wi, wo), f)


def test_three_models_are_required():
    with pytest.raises(ValueError, match="3 models"):
        PerChannelBRDF(_models()[:2])
