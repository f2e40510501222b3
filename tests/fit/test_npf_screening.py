"""Independent-G's per-channel machinery (issue 35): channel masks of the G passes, runs that
stop per channel and go on where they stopped (``carry``), channels of different runs
combined into one run, the two-round screening and the long-baseline over-relaxation of the
continuation. The channels are independent problems: whatever is done to one must not change
another, and a channel must follow the same iterates however the runs are cut and combined."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.fit import npf
from brdffit.fit.npf import _kernels, _solver
from brdffit.grid import tabulate_merl_grid
from brdffit.losses.objective import prepare_objective
from brdffit.microfacet.npf_model import G_THETA, NPFMicrofacetBRDF

from .test_npf import RHO_D, RHO_S, _d, _f
from .test_npf_kernels import _samples

NH, ND, NG = 90, 90, 90


@pytest.fixture(scope="module")
def smp():
    D = _d([0.25, 0.35, 0.5])
    G = (1 - 0.4 * (G_THETA / G_THETA[-1]) ** 2)[:, None] * np.array([1.0, 0.9, 0.95])
    data = tabulate_merl_grid(NPFMicrofacetBRDF(D, _f(), G, RHO_D, RHO_S))
    return _solver.Samples.from_objective(prepare_objective(*data))


def _start(seed):
    return npf._random_start(np.random.default_rng(seed))



@pytest.mark.parametrize("chans", [(True, False, True), (False, True, False)])
def test_g_passes_of_the_channels_asked_are_those_of_all_channels(chans):
    """The G normal equations and the line statistics of a channel asked are bit for bit
    those of the all-channel pass; the others are 0."""
    arrays, f = _samples("merl", seed=4)
    X = (f["rho_s"][:, None, None] * f["D"][:, :, None] * f["F"][:, None, :]).reshape(3, -1)
    on = np.array(chans)
    full = [np.full((3, NG), np.nan) for _ in range(6)]
    part = [np.full((3, NG), np.nan) for _ in range(6)]
    _kernels.g_normal_equations(*arrays, f["G"], X, f["rho_d"], *full, np.ones(3, bool))
    _kernels.g_normal_equations(*arrays, f["G"], X, f["rho_d"], *part, on)
    for a, b in zip(part, full):
        assert np.array_equal(a[on], b[on]) and np.all(a[~on] == 0.0)
    dG = np.random.default_rng(5).normal(0.0, 0.1, (3, NG))
    Q_full, Q_part = np.full((3, NH * ND, 11), np.nan), np.full((3, NH * ND, 11), np.nan)
    _kernels.p_stats_line(*arrays, f["G"], dG, Q_full, np.ones(3, bool))
    _kernels.p_stats_line(*arrays, f["G"], dG, Q_part, on)
    assert np.array_equal(Q_part[on], Q_full[on]) and np.all(Q_part[~on] == 0.0)


def test_channel_monitors_stop_a_channel_by_its_share_of_the_window():
    """With ``window = (W, k)`` a channel stops once its decrease over W iterations is below
    ``W·k·tol/3`` of the summed objective; the summed rule stops every channel."""
    smp = _solver.Samples.__new__(_solver.Samples)
    smp.sum_wzz = np.ones(3)
    mon = _solver.ChannelMonitors(smp, 1e-6, window=(10, 5.0))
    E = np.array([1.0, 0.1, 0.01])
    mon.start(E)
    on = np.ones(3, bool)
    # channel 0 falls 1e-4 per iteration (relative to the sum 1.11: ~1e-3 over 10, above
    # the limit 10·5e-6/3 = 1.67e-5 of the sum), channel 1 by 1e-7 per iteration (1e-6 over
    # 10: below 1.67e-5 · 1.11), channel 2 by 1e-5 (1e-4 over 10: above)
    rate = np.array([1e-4, 1e-7, 1e-5])
    stops = []
    for it in range(1, 16):
        stop = mon.push(E - rate * it, on)
        stops += [(it, int(c)) for c in np.flatnonzero(stop)]
        on &= ~stop
    assert stops == [(10, 1)]           # at the first full window, channel 1 only
    assert mon.channel_reasons()[1].startswith(npf._CONVERGED_REASONS)
    # then no decrease: the summed rule (relative decrease < tol for 3 iterations) stops
    # every channel still running at the third iteration, before their windows would
    flat = E - rate * 15
    for k in range(3):
        stop = mon.push(flat, on)
        assert stop.any() == (k == 2)
    assert np.array_equal(stop, [True, False, True])
    assert mon.reason().startswith("relative decrease")


def test_a_run_cut_in_two_with_its_carry_is_the_same_run(smp):
    one = _solver.run_independent_g(_start(1), smp, max_iter=8, extrapolate=True)
    a = _solver.run_independent_g(_start(1), smp, max_iter=5, extrapolate=True)
    b = _solver.run_independent_g(a.state, smp, max_iter=3, extrapolate=True, carry=a.carry)
    for x, y in zip(_solver._state_arrays(one.state), _solver._state_arrays(b.state)):
        np.testing.assert_allclose(x, y, rtol=1e-10)
    np.testing.assert_allclose(one.history, b.history, rtol=1e-12)
    assert b.iterations == 3 and len(b.history) == 9


def test_combined_channels_follow_their_own_runs(smp):
    """Channel c of a run combined from runs r_c (``combine_channels``) goes on as r_c alone
    would; a channel not ``active`` is left as it was and its objective kept."""
    runs = [_solver.run_independent_g(_start(s), smp, max_iter=3, extrapolate=True)
            for s in (1, 2, 3)]
    alone = [_solver.run_independent_g(r.state.copy(), smp, max_iter=4, extrapolate=True,
                                       carry=r.carry) for r in runs]
    runs = [_solver.run_independent_g(_start(s), smp, max_iter=3, extrapolate=True)
            for s in (1, 2, 3)]                       # fresh carries (the above used them)
    st, carry = _solver.combine_channels(runs)
    on = np.array([True, False, True])
    frozen = st.copy()
    both = _solver.run_independent_g(st, smp, max_iter=4, extrapolate=True, active=on,
                                     carry=carry)
    for c in (0, 2):
        for x, y in zip(_solver._state_arrays(both.state), _solver._state_arrays(alone[c].state)):
            np.testing.assert_allclose(x[c], y[c], rtol=1e-10)
        assert both.E[c] == pytest.approx(alone[c].E[c], rel=1e-10)
    for x, y in zip(_solver._state_arrays(both.state), _solver._state_arrays(frozen)):
        assert np.array_equal(x[1], y[1])
    assert both.E[1] == runs[1].E[1]


def test_jump_never_raises_the_objective_and_leaves_other_channels(smp):
    """From the midpoint between a start and the truth, with the start as the anchor, the
    jump points at the truth: it must be taken (and only lower the objective), the
    objective it returns must be the state's, and a channel not asked must not move."""
    D = _d([0.25, 0.35, 0.5])
    G = (1 - 0.4 * (G_THETA / G_THETA[-1]) ** 2)[:, None] * np.array([1.0, 0.9, 0.95])
    truth = _solver.MFState(D.T.copy(), _f().T.copy(), G.T.copy(), RHO_D.copy(),
                            RHO_S.copy())
    anchor = _start(4)
    st = _solver.MFState(*(0.5 * (a + b) for a, b in zip(_solver._state_arrays(truth),
                                                          _solver._state_arrays(anchor))))
    E0, S0 = _solver._stats(st, smp)
    before = st.copy()
    on = np.array([True, True, False])
    S, E, accepted = _solver._jump(st, anchor, smp, 1e-6, E0, S0, on)
    assert accepted >= 2 and np.all(E[:2] < 0.5 * E0[:2]) and E[2] == E0[2]
    E_exact, _ = _solver._stats(st, smp)
    np.testing.assert_allclose(E, E_exact, rtol=1e-8, atol=1e-12 * smp.sum_wzz.max())
    for x, y in zip(_solver._state_arrays(st), _solver._state_arrays(before)):
        assert np.array_equal(x[2], y[2])


def test_screening_rounds_continue_only_the_close_starts(monkeypatch):
    """After a round only the starts within ``ratio`` of a channel's best (at most ``keep``)
    run on, in that channel; ``SCREEN_ROUNDS = False`` runs every start all the way."""
    D = _d([0.25, 0.35, 0.5])
    G = (1 - 0.4 * (G_THETA / G_THETA[-1]) ** 2)[:, None] * np.array([1.0, 0.9, 0.95])
    table = tabulate_merl_grid(NPFMicrofacetBRDF(D, _f(), G, RHO_D, RHO_S))
    kw = dict(data=table, starts=("random", "ones"), n_random=2, max_iter=6,
              start_max_iter=5, polish=0)
    assert npf.SCREEN_ROUNDS == ((15, 1.005, None), (50, 1.005, 2))

    def run(rounds):
        monkeypatch.setattr(npf, "SCREEN_ROUNDS", rounds)
        return npf.fit_npf(**kw)

    fit = run(((2, 1.0, 1),))
    info = fit.fit_info
    E2 = np.array([s["objective_per_channel"] for s in info["starts"]])
    its = np.array([s["iterations_per_channel"] for s in info["starts"]])
    # ratio 1, keep 1: exactly one start per channel ran the 3 more iterations, the best
    assert np.all((its == 2) | (its == 5)) and np.all(np.sum(its == 5, axis=0) == 1)
    labels = [s["start"] for s in info["starts"]]
    assert info["best_start_per_channel"] == [labels[int(np.argmax(its[:, c]))]
                                              for c in range(3)]
    assert info["iterations"] == 3 * 2 + 3 + 1
    assert fit.fit_options["screen_rounds"] == [[2, 1.0, 1]]
    full = run(False).fit_info
    assert all(s["iterations_per_channel"] == [5, 5, 5] for s in full["starts"])
    assert np.all(E2.min(axis=0) >= np.array(full["objective_per_channel"]) * (1 - 1e-9))
    # two rounds: all within ×10 after 1 iteration go on to 3, then the best to 5
    two = run(((1, 10.0, None), (3, 1.0, 1))).fit_info
    its = np.array([s["iterations_per_channel"] for s in two["starts"]])
    assert np.all(np.isin(its, (1, 3, 5))) and np.all(np.sum(its == 5, axis=0) == 1)
    for bad in ((0, 1.0, 1),), ((3, 1.0, 1), (2, 1.0, 1)), ((2, 0.5, 1),):
        with pytest.raises(ValueError, match="screen_rounds"):
            run(bad)


def test_jump_cap_keeps_every_factor_sample_above_half_its_value():
    a, b = _start(6), _start(7)
    cap = _solver._jump_cap(a, b)
    lowest = np.full(3, np.inf)
    for nm in ("D", "F", "G"):
        x, d = getattr(a, nm), getattr(a, nm) - getattr(b, nm)
        ratio = (x + cap[:, None] * d) / x
        assert np.all(ratio >= 0.5 - 1e-12)
        lowest = np.minimum(lowest, ratio.min(axis=1))
    np.testing.assert_allclose(lowest, 0.5)              # the cap is reached, not passed
