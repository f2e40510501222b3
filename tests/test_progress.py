"""brdffit.progress: events of long tasks, throttled, never breaking the caller."""

from __future__ import annotations

import doctest
import threading

import brdffit.progress as P


def test_doctests():
    assert doctest.testmod(P).failed == 0


def test_throttle_keeps_first_and_final_events():
    seen = []
    with P.listening(seen.append, min_interval=3600.0):
        for i in range(5):
            P.report(stage="s", iteration=i)
        P.report(stage="s", iteration=99, final=True)
    assert [e["iteration"] for e in seen] == [0, 99]
    assert all(e["elapsed_s"] >= 0 for e in seen)
    assert not P.active()


def test_a_failing_listener_is_dropped_and_the_caller_goes_on():
    calls = []

    def bad(event):
        calls.append(event)
        raise RuntimeError("display gone")

    with P.listening(bad, min_interval=0.0):
        P.report(stage="a")
        P.report(stage="b")                  # not delivered: the listener was dropped
    assert len(calls) == 1


def test_step_callback_calls_the_user_and_reports_from_threads():
    assert P.step_callback(None, "x") is None                 # nothing to do: no overhead
    mine, seen = [], []
    with P.listening(seen.append, min_interval=0.0):
        step = P.step_callback(lambda i, e: mine.append((i, e)), "awls", 10)
        threads = [threading.Thread(target=step, args=(k, 1.0 / (k + 1))) for k in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    assert sorted(mine) == sorted((k, 1.0 / (k + 1)) for k in range(4))
    assert len(seen) == 4 and {e["stage"] for e in seen} == {"awls"}
    assert {e["max_iterations"] for e in seen} == {10}


def test_npf_fit_reports_its_iterations():
    import brdffit
    from brdffit.fit.npf import G_FROM_D_STARTS

    seen = []
    with P.listening(seen.append, min_interval=0.0):
        brdffit.fit("synthetic:gold-ggx", model="npf-g-from-d", max_iter=3, polish=2)
    n_awls = 3 * len(G_FROM_D_STARTS)               # the AWLS of each start, in turn
    assert [e["iteration"] for e in seen[:n_awls]] == [1, 2, 3] * len(G_FROM_D_STARTS)
    assert all(e["stage"] == "G-from-D AWLS" and e["objective"] > 0 for e in seen[:n_awls])
    assert 1 <= len(seen[n_awls:]) <= 2            # the polish stops early if nothing is left
    assert all(e["stage"] == "LM polish" and e["objective"] > 0 for e in seen[n_awls:])
