"""brdffit._isolation: a crash in the child process is an exception in the parent."""

from __future__ import annotations

import operator
import os
import signal

import pytest

from brdffit._isolation import ChildCrashed, IsolatedProcess, crash_text
from brdffit.progress import listening, report


def _segfault():
    os.kill(os.getpid(), signal.SIGSEGV)


def _exit(status):
    os._exit(status)


def _fail():
    raise ValueError("a bad value")


def _noisy(x):
    print("printed to stdout")  # must not corrupt the pipe
    report(stage="working on x", final=True)
    return {"x": x, "pid": os.getpid()}


class _Unpicklable(Exception):
    def __reduce__(self):
        raise TypeError("no")


def _fail_unpicklable():
    raise _Unpicklable("odd")


def test_results_exceptions_and_output_of_the_child():
    with IsolatedProcess() as child:
        assert child.call(operator.mul, 6, 7) == 42
        got = child.call(_noisy, [1, 2])
        assert got["x"] == [1, 2] and got["pid"] != os.getpid()
        with pytest.raises(ValueError, match="a bad value"):
            child.call(_fail)
        with pytest.raises(RuntimeError, match="_Unpicklable: odd"):
            child.call(_fail_unpicklable)
        assert child.call(operator.add, 1, 1) == 2 and child.starts == 1
        assert child.cpu_seconds >= 0.0


def test_a_signal_in_the_child_names_the_signal_and_the_stage_and_the_next_call_restarts():
    with IsolatedProcess("the renderer") as child:
        first = child.call(_noisy, 1)["pid"]
        child.stage = "rendering knot-courtyard for gold-ggx"
        with pytest.raises(ChildCrashed) as info:
            child.call(_segfault)
        assert str(info.value) == ("the renderer crashed (SIGSEGV) while rendering "
                                   "knot-courtyard for gold-ggx")
        assert info.value.signal_name == "SIGSEGV"
        again = child.call(_noisy, 2)["pid"]
        assert again != first and child.starts == 2


def test_an_exit_is_reported_with_its_status_and_init_calls_are_replayed():
    calls = [(operator.add, (1, 2), {})]
    with IsolatedProcess("the worker", init=calls) as child:
        with pytest.raises(ChildCrashed, match=r"the worker stopped \(exit status 7\)") as info:
            child.call(_exit, 7)
        assert info.value.exit_status == 7 and info.value.signal_name is None
        assert child.call(operator.neg, 3) == -3 and child.starts == 2


def test_progress_events_of_the_child_reach_the_parent_and_name_the_stage():
    seen = []
    with IsolatedProcess() as child, listening(seen.append, min_interval=0.0):
        child.call(_noisy, 0)
        assert child.stage == "working on x"
    assert any(e.get("stage") == "working on x" for e in seen)


def test_crash_text():
    assert crash_text(-signal.SIGSEGV) == "SIGSEGV" and crash_text(-signal.SIGKILL) == "SIGKILL"
    assert crash_text(3) == "exit status 3"


def _init_fails():
    raise ValueError("init failed")


def test_a_call_that_does_not_pickle_is_not_sent_and_a_failed_init_keeps_no_child():
    from brdffit._isolation import NotSendable

    with IsolatedProcess() as child:
        with pytest.raises(NotSendable, match="cannot send"):
            child.call(operator.add, lambda: 1, 2)
        assert child.call(operator.add, 1, 2) == 3
    with IsolatedProcess(init=[(_init_fails, (), {})]) as child:
        for _ in range(2):  # each call starts a child and runs the init again
            with pytest.raises(ValueError, match="init failed"):
                child.call(operator.add, 1, 2)
        assert child.starts == 2 and child._proc is None


class _OnlyHere:
    """A class the child cannot import (the test makes it a class of ``__main__``)."""

    def __reduce__(self):
        return (_OnlyHere, ())


def test_a_call_the_child_cannot_load_is_not_sendable_and_the_child_goes_on(monkeypatch):
    import sys

    from brdffit._isolation import NotSendable

    monkeypatch.setattr(_OnlyHere, "__module__", "__main__")
    monkeypatch.setattr(sys.modules["__main__"], "_OnlyHere", _OnlyHere, raising=False)
    with IsolatedProcess() as child:
        with pytest.raises(NotSendable, match="cannot load the call"):
            child.call(operator.eq, _OnlyHere(), 1)
        assert child.call(operator.add, 1, 2) == 3 and child.starts == 1


_STATE = {}


def _remember(x):
    _STATE["x"] = x


def _recall():
    return _STATE.get("x"), os.getpid()


def test_reinit_runs_the_new_init_in_the_running_child_and_a_new_child_replays_it():
    with IsolatedProcess(init=[(_remember, (1,), {})]) as child:
        assert child.call(_recall)[0] == 1 and child.running
        pid = child.call(_recall)[1]
        child.reinit([(_remember, (2,), {})])
        assert child.call(_recall) == (2, pid) and child.starts == 1
        with pytest.raises(ChildCrashed):
            child.call(_segfault)
        assert not child.running
        child.reinit([(_remember, (3,), {})])     # no child: made at the next start
        assert child.call(_recall)[0] == 3 and child.starts == 2
        with pytest.raises(ValueError, match="init failed"):
            child.reinit([(_init_fails, (), {})])  # a child whose init fails is not kept
        assert not child.running
