"""The coat lobe of a coated diffuse model (brdffit.microfacet.coat)."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel, SumBRDF
from brdffit.microfacet.coat import COAT_F0, coat_alpha_weight, coat_parts


def _base():
    return MicrofacetBRDF(GGX(0.12), SchlickFresnel([0.6, 0.5, 0.4]), diffuse=[0.3, 0.2, 0.1])


def _coat(f0=COAT_F0, w=(0.3, 0.3, 0.3), diffuse=None):
    return MicrofacetBRDF(GGX(0.02, 0.08), SchlickFresnel(np.full(3, f0)),
                          specular=np.asarray(w), diffuse=diffuse)


def test_a_white_coat_of_index_1_5_over_a_lobe_is_recognised():
    base, coat = _base(), _coat()
    assert coat_parts(SumBRDF([base, coat])) == (base, coat)
    alpha, w = coat_alpha_weight(coat)
    assert alpha == pytest.approx(0.04) and w == pytest.approx(0.3)


@pytest.mark.parametrize("coat", [_coat(f0=0.05), _coat(w=(0.3, 0.2, 0.3)), _coat(w=(1.5,) * 3),
                                  _coat(diffuse=0.1)])
def test_other_second_lobes_are_not_a_coat(coat):
    assert coat_parts(SumBRDF([_base(), coat])) is None


def test_models_that_are_not_a_sum_of_two_lobes_have_no_coat():
    assert coat_parts(_base()) is None
    assert coat_parts(SumBRDF([_base(), _coat(), _coat()])) is None
