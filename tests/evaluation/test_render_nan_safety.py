"""Every Dr.Jit evaluator reads only inside its tables, whatever the directions (issue 30).

Mitsuba's kernels carry lanes they do not use: a path that left the scene has ``wi = wo = 0``
(an invalid surface interaction), others are below the horizon. On an AVX2 CPU a table index
computed from NaN (``UInt32(NaN)`` = 2³¹) made the knot scene crash. Here each evaluator
kind gets such directions, with every lane active, under Dr.Jit's debug mode, which checks
the bounds of every gather and reports a stray one on stderr.
"""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.evaluation.render import available

pytestmark = [pytest.mark.render,
              pytest.mark.skipif(not available(), reason="Mitsuba 3 LLVM back-end unavailable")]

NAN, INF = float("nan"), float("inf")
#: (wi, wo) pairs a kernel can carry in lanes it does not use, plus valid ones
HOSTILE = [
    ((0, 0, 0), (0, 0, 0)),                # escaped path: invalid interaction
    ((0, 0, 0), (0, 0, -0.0)),
    ((NAN, NAN, NAN), (0, 0, 1)),
    ((0, 0, 1), (NAN, 0, NAN)),
    ((0.6, 0, 0.8), (-0.6, 0, -0.8)),      # wi = −wo
    ((INF, 0, 1), (0, 0, 1)),
    ((0, -INF, 1), (0, 0, INF)),
    ((0.6, 0, -0.8), (0, 0.6, 0.8)),       # below the horizon
    ((1e30, 1e30, 1e30), (-1e30, 0, 1e-30)),
    ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),    # grazing
    ((0.6, 0, 0.8), (0, 0.6, 0.8)),        # valid
    ((0, 0, 1), (0, 0, 1)),
]


def _brdfs():
    from brdffit.microfacet.sgd_model import PerChannelMicrofacetBRDF
    from brdffit.microfacet import (Beckmann, ConductorFresnel, GGX, MicrofacetBRDF,
                                    SchlickFresnel)
    from brdffit.microfacet.npf_model import D_THETA_H, F_THETA_D, G_THETA, NPFMicrofacetBRDF
    from brdffit.microfacet.sgd import SGD

    D = np.exp(-(np.tan(D_THETA_H) / 0.2) ** 2)[:, None] * np.array([1.0, 0.9, 0.8])
    F = (0.5 + 0.5 * (1 - np.cos(F_THETA_D)) ** 5)[:, None] * np.ones(3)
    G = np.cos(G_THETA)[:, None] ** 0.1 * np.ones(3)
    return {
        "ggx-conductor": (MicrofacetBRDF(GGX(0.2), ConductorFresnel([0.2, 0.9, 1.1],
                                                                    [3.9, 2.4, 2.2])), "auto"),
        "beckmann-schlick": (MicrofacetBRDF(Beckmann(0.3, 0.1, 0.3), SchlickFresnel(0.5),
                                            diffuse=0.1), "auto"),
        "sgd-per-channel": (PerChannelMicrofacetBRDF(
            [dict(distribution=SGD(0.15 * c, 1.2), rho_d=0.05 * c, rho_s=0.3, F0=0.05,
                  F1=0.02) for c in (1, 2, 3)]), "auto"),
        "npf": (NPFMicrofacetBRDF(D, F, G, [0.05, 0.04, 0.03], [0.3, 0.3, 0.3]), "auto"),
        "merl-table": (MicrofacetBRDF(GGX(0.1), SchlickFresnel(0.9)), "table"),
        "table-4d": (MicrofacetBRDF(GGX(0.3, 0.1), SchlickFresnel(0.9)), "table"),
    }


@pytest.fixture
def debug_mode():
    from brdffit.evaluation.render._mitsuba import load

    _, dr = load()
    before = dr.flag(dr.JitFlag.Debug), dr.flag(dr.JitFlag.PacketOps)
    dr.set_flag(dr.JitFlag.Debug, True)
    dr.set_flag(dr.JitFlag.PacketOps, False)
    yield
    dr.set_flag(dr.JitFlag.Debug, before[0])
    dr.set_flag(dr.JitFlag.PacketOps, before[1])


@pytest.mark.parametrize("name", list(_brdfs()))
def test_hostile_directions_read_no_table_out_of_bounds(name, debug_mode, capfd):
    from brdffit.evaluation.render._mitsuba import load
    from brdffit.evaluation.render.drjit_eval import to_numpy, to_vec3
    from brdffit.evaluation.render.proposal import proposal_for
    from brdffit.evaluation.render.translate import to_evaluator

    mi, dr = load()
    brdf, mode = _brdfs()[name]
    ev = to_evaluator(brdf, mode=mode)
    wi = to_vec3(np.array([p[0] for p in HOSTILE], float))
    wo = to_vec3(np.array([p[1] for p in HOSTILE], float))
    f = to_numpy(ev.eval(wi, wo, 1.0, True))
    p = to_numpy(ev.pdf(wi, wo, 1.0, True))
    u = mi.Float(np.full(len(HOSTILE), 0.3, np.float32))
    u2 = mi.Point2f(np.full(len(HOSTILE), 0.7, np.float32), np.full(len(HOSTILE), 0.2, np.float32))
    s_wo, s_pdf = ev.sample(wi, u, u2, 1.0, True)
    sampled = to_numpy(s_wo), to_numpy(s_pdf)
    # the proposal of a comparison goes through the same evaluators' helpers
    prop = proposal_for(brdf)
    to_numpy(prop.pdf(wi, wo, 1.0, True))
    dr.eval()
    err = capfd.readouterr().err
    assert "out-of-bounds" not in err, err
    # lanes with no valid pair of directions give 0, valid lanes finite values
    invalid = [not (np.isfinite(a).all() and np.isfinite(b).all() and a[2] > 0 and b[2] > 0)
               for a, b in HOSTILE]
    for k, bad in enumerate(invalid):
        if bad and (np.isnan(HOSTILE[k][0]).any() or np.isnan(HOSTILE[k][1]).any()
                    or HOSTILE[k][0][2] <= 0 or HOSTILE[k][1][2] <= 0):
            assert np.all(f[k] == 0), (k, f[k])
            assert p[k] == 0, (k, p[k])
    assert np.isfinite(f[-2:]).all() and np.isfinite(p[-2:]).all()
    assert np.isfinite(sampled[0][-2:]).all()


def test_the_render_layer_tests_run_in_drjit_debug_mode():
    """tests/conftest.py: this file is one of DEBUG_TESTS (unless the environment chose)."""
    import os

    from tests.conftest import _DEBUG_FROM_ENV

    if _DEBUG_FROM_ENV is not None:
        pytest.skip("BRDFFIT_DRJIT_DEBUG is set in the environment: it applies to every test")
    from brdffit.evaluation.render import _mitsuba

    _mitsuba.load()
    import drjit as dr

    assert os.environ["BRDFFIT_DRJIT_DEBUG"] == "1"
    assert dr.flag(dr.JitFlag.Debug) and not dr.flag(dr.JitFlag.PacketOps)
