"""The independent-G default strategy (issue 35): the start set of ``starts=None`` and the
windowed stop of the best start's continuation. Cheap checks; the objectives they were
chosen for are measured by ``bench/bench_best_known.py --models npf``."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.fit import npf
from brdffit.fit.npf import _solver
from brdffit.grid import tabulate_merl_grid
from brdffit.microfacet.npf_model import G_THETA, NPFMicrofacetBRDF

from .test_npf import RHO_D, RHO_S, _d, _f


@pytest.fixture(scope="module")
def data():
    D = _d([0.25, 0.35, 0.5])
    G = (1 - 0.4 * (G_THETA / G_THETA[-1]) ** 2)[:, None] * np.array([1.0, 0.9, 0.95])
    return tabulate_merl_grid(NPFMicrofacetBRDF(D, _f(), G, RHO_D, RHO_S))


def _monitor_stop(history, window, tol=1e-6, max_iter=10_000):
    """The iteration at which :class:`_solver.Monitor` stops on ``history`` and its reason."""
    mon = _solver.Monitor(np.ones(3), tol, max_iter, window=window)
    mon.history.append(float(history[0]))
    for k, e in enumerate(history[1:], 1):
        if mon.push(np.array([e, 0.0, 0.0])):
            return k, mon.reason
    return None, mon.reason


def test_window_rule_stops_when_the_decrease_over_the_window_is_small():
    # a crawl: relative decrease 2e-5 per iteration, then 2e-6 from iteration 300 on
    rate = np.where(np.arange(1000) < 300, 2e-5, 2e-6)
    history = np.cumprod(np.concatenate([[1.0], 1.0 - rate]))
    # plain rule (tol 1e-6 for 3 iterations): never fires on this history
    assert _monitor_stop(history, None)[0] is None
    # W = 100, k = 5: stop once the last 100 iterations lost < 100·5·1e-6 = 5e-4: at
    # iteration k the window holds (400 - k) fast and (k - 300) slow iterations, so
    # (400 - k)·2e-5 + (k - 300)·2e-6 < 5e-4 first holds at k = 384
    k, reason = _monitor_stop(history, (100, 5.0))
    assert k == 384 and reason == "relative decrease < 0.0005 over the last 100 iterations"
    # the window never fires before it is full, and scales with tol
    assert _monitor_stop(history[:100], (100, 1e9))[0] is None
    assert _monitor_stop(history, (100, 5.0), tol=1e-8)[0] is None
    # the window's stop counts as converged (fit_info, _CONVERGED_REASONS)
    assert reason.startswith(npf._CONVERGED_REASONS)


def test_default_starts_and_the_continuation_window(data, monkeypatch):
    """``starts=None`` screens :data:`DEFAULT_STARTS` (the paper's eight starts) and only the
    continuation of the best start runs with :data:`CONTINUATION_WINDOW`."""
    assert npf.DEFAULT_STARTS == ("random", "ones", "sgd", "slices", "g-from-d")
    assert set(npf.DEFAULT_STARTS) <= set(npf.ALL_STARTS)
    assert npf.CONTINUATION_WINDOW == (100, 5.0)
    windows = []
    run = _solver.run_independent_g

    def spy(*args, **kw):
        windows.append(kw.get("window"))
        return run(*args, **kw)

    monkeypatch.setattr(_solver, "run_independent_g", spy)
    fit = npf.fit_npf(data=data, max_iter=6, start_max_iter=3, polish=0, n_random=1)
    info = fit.fit_info
    labels = ["random-0", "ones", "sgd", "slices", "g-from-d"]
    assert [s["start"] for s in info["starts"]] == labels
    assert fit.fit_options["starts"] == list(npf.DEFAULT_STARTS)
    assert all(s["status"] == "ok" for s in info["starts"])
    assert info["g_from_d_start"]["iterations"] > 0       # the G-from-D fit of that start
    assert windows == [None] * 5 + [npf.CONTINUATION_WINDOW]
    assert "continuation" in info and info["iterations"] == 5 * 3 + 3
    assert "over the last 100 iterations" in info["criterion"]


def test_the_g_from_d_start_runs_the_first_round_only_and_joins_the_pick_at_the_end(data):
    """:data:`PROTECTED_STARTS` (the G-from-D fit) is screened apart: it runs the first
    round of :data:`SCREEN_ROUNDS` and drops no start; the others' rounds are those without
    it."""
    kw = dict(data=data, max_iter=22, start_max_iter=20, polish=0, n_random=1)
    fit = npf.fit_npf(**kw).fit_info
    alone = npf.fit_npf(starts=("random", "ones", "sgd", "slices"), **kw).fit_info
    first = npf.SCREEN_ROUNDS[0][0]
    by = {r["start"]: r for r in fit["starts"]}
    assert max(by["g-from-d"]["iterations_per_channel"]) <= first
    others = [r for r in fit["starts"] if r["start"] != "g-from-d"]
    assert any(max(r["iterations_per_channel"]) > first for r in others)   # later rounds ran
    assert [r["iterations_per_channel"] for r in others] == \
        [r["iterations_per_channel"] for r in alone["starts"]]
    for c, label in enumerate(fit["best_start_per_channel"]):
        E = {r["start"]: r["objective_per_channel"][c] for r in fit["starts"]}
        assert E[label] == min(E.values())
