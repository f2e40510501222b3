"""The passes over the samples of the NPF fits (``Samples.stats``): a channel is passed over
only when its result is used and not already known, without changing a fit. A fit whose
every ``Samples.stats`` call passes over all three channels (the plain kernel call) gives the
same iterates bit for bit, in fewer channel passes."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.fit.npf import _kernels, _solver, fit_npf
from brdffit.grid import tabulate_merl_grid
from brdffit.losses.objective import prepare_objective
from brdffit.microfacet.npf_model import D_THETA_H, F_THETA_D, G_THETA, NPFMicrofacetBRDF


@pytest.fixture(scope="module")
def data():
    """An independent-G material (G-from-D cannot fit it exactly: its searches and polish
    run), channels of different roughness (they finish at different times)."""
    t = np.tan(D_THETA_H)[:, None]
    D = np.exp(-(t / np.array([0.25, 0.35, 0.5])) ** 2) / np.cos(D_THETA_H)[:, None] ** 4
    F = 0.4 + 0.6 * (1 - np.cos(F_THETA_D))[:, None] ** 5 * np.array([1.0, 0.8, 0.6])
    G = (1 - 0.4 * (G_THETA / G_THETA[-1]) ** 2)[:, None] * np.array([1.0, 0.9, 0.95])
    m = NPFMicrofacetBRDF(D / D.max(0) + 1e-3, F, G, [0.05, 0.08, 0.02], [0.6, 0.4, 0.9])
    return tabulate_merl_grid(m)


def _counting(monkeypatch, plain: bool):
    """Count the kernel's channel passes; with ``plain`` every call passes over all channels
    and nothing is re-used (the reference)."""
    count = {"calls": 0, "channels": 0}
    kernel = _kernels.p_stats

    def p_stats(*args):
        chans = args[-1]
        if plain:
            chans = np.ones(3, bool)
        count["calls"] += 1
        count["channels"] += int(np.sum(chans))
        return kernel(*args[:-1], chans)

    monkeypatch.setattr(_kernels, "p_stats", p_stats)
    if plain:
        monkeypatch.setattr(_solver, "STATS_MEMO", 0)
    return count


def test_stats_reuses_a_channel_with_the_same_inputs(data, monkeypatch):
    smp = _solver.Samples.from_objective(prepare_objective(*data))
    rng = np.random.default_rng(0)
    G, X, rho_d = rng.uniform(0.5, 1.0, (3, 90)), rng.random((3, 8100)), rng.random(3)
    count = _counting(monkeypatch, plain=False)
    E, S = smp.stats(G, X, rho_d)
    G2 = G.copy()
    G2[1, 5] *= 1.01                                  # channel 1 changes
    E2, S2 = smp.stats(G2, X, rho_d)
    assert count == {"calls": 2, "channels": 4}
    assert np.array_equal(E2[[0, 2]], E[[0, 2]]) and E2[1] != E[1]
    assert all(np.array_equal(a[[0, 2]], b[[0, 2]]) for a, b in zip(S2, S))
    E3, S3 = smp.stats(G, X, rho_d, chans=[False, True, False])   # remembered: no pass
    assert count["calls"] == 2 and np.array_equal(E3[1], E[1]) and np.isnan(E3[[0, 2]]).all()
    assert np.array_equal(S3[2][1], S[2][1]) and np.all(S3[2][[0, 2]] == 0.0)


def test_g_from_d_fit_is_unchanged_in_fewer_channel_passes(data, monkeypatch):
    """Measured on this material: plain 695 calls (2085 channel passes), 693 calls and 1546
    channel passes (0.74×) with the channels skipped and re-used."""
    runs = {}
    for plain in (True, False):
        with monkeypatch.context() as m:
            count = _counting(m, plain)
            fit = fit_npf(data=data, variant="g-from-d", init="slices")
            runs[plain] = count, fit.fit_info
    (c_plain, plain), (c_new, new) = runs[True], runs[False]
    assert new["history"] == plain["history"]                      # bit for bit
    assert new["objective_per_channel"] == plain["objective_per_channel"]
    assert new["nit"] == plain["nit"] and new["line_search_evals"] == plain["line_search_evals"]
    assert c_plain["channels"] == 3 * c_plain["calls"]
    assert c_new["channels"] <= 0.8 * c_plain["channels"]
