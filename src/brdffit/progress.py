"""Progress of long tasks (iterations, current objective) for whoever listens.

A long fit calls :func:`report` as it goes (the NPF solvers once per iteration, through
:func:`step_callback`); nothing happens unless a listener is installed with :func:`listening`
— the CLI's status line, the batch worker that forwards events to the client's progress
display and log. Events are plain dicts (JSON-safe values)::

    {"stage": "npf independent-G start ones", "iteration": 40, "max_iterations": 100,
     "objective": 6.1e-05, "elapsed_s": 3.2}

Listeners are process-wide (a stack guarded by a lock, not a context variable) so that the
worker threads of a fit (the NPF starts run on a thread pool) report too. Each listener is
throttled: it receives at most one event per ``min_interval`` seconds, plus every event
marked ``final``.

>>> seen = []
>>> with listening(seen.append, min_interval=0.0):
...     report(stage="demo", iteration=1, objective=2.0)
>>> seen[0]["stage"], seen[0]["iteration"], seen[0]["objective"]
('demo', 1, 2.0)
>>> report(stage="nobody listens")      # a no-op
"""

from __future__ import annotations

import math
import threading
import time
from contextlib import contextmanager
from typing import Callable, Iterator

__all__ = ["listening", "report", "step_callback", "active", "describe"]

_lock = threading.Lock()
_listeners: list["_Listener"] = []


class _Listener:
    def __init__(self, fn: Callable[[dict], None], min_interval: float):
        self.fn, self.min_interval = fn, float(min_interval)
        self.t0 = time.monotonic()
        self.last = -math.inf

    def offer(self, event: dict, now: float) -> dict | None:
        """The event to deliver (with ``elapsed_s``) or ``None`` when throttled."""
        if not event.get("final") and now - self.last < self.min_interval:
            return None
        self.last = now
        return {**event, "elapsed_s": round(now - self.t0, 3)}


def active() -> bool:
    """Whether anyone listens (callers may skip building an event when not)."""
    return bool(_listeners)


@contextmanager
def listening(fn: Callable[[dict], None], min_interval: float = 1.0) -> Iterator[None]:
    """Deliver the events reported inside the block to ``fn`` (at most one per
    ``min_interval`` seconds, plus ``final`` ones). A listener that raises is dropped for
    the rest of the block: progress display never breaks a fit."""
    listener = _Listener(fn, min_interval)
    with _lock:
        _listeners.append(listener)
    try:
        yield
    finally:
        with _lock:
            if listener in _listeners:
                _listeners.remove(listener)


def report(**event) -> None:
    """Send ``event`` (keyword fields, see the module docstring) to the listeners."""
    if not _listeners:
        return
    now = time.monotonic()
    with _lock:
        deliveries = [(lst, lst.offer(event, now)) for lst in _listeners]
    for lst, ev in deliveries:
        if ev is None:
            continue
        try:
            lst.fn(ev)
        except Exception:  # noqa: BLE001 – a display must not break the fit
            with _lock:
                if lst in _listeners:
                    _listeners.remove(lst)


def step_callback(callback: Callable | None, stage: str,
                  max_iterations: int | None = None) -> Callable[[int, float], None] | None:
    """A solver callback ``(iteration, objective)`` that calls ``callback`` (the user's, if
    any) and reports the step as ``stage`` when someone listens; ``None`` when neither."""
    if callback is None and not _listeners:
        return None

    def step(iteration: int, objective: float) -> None:
        if callback is not None:
            callback(iteration, objective)
        if _listeners:
            report(stage=stage, iteration=int(iteration), max_iterations=max_iterations,
                   objective=float(objective))

    return step


def describe(event: dict) -> str:
    """One line of a progress event: ``stage iteration i/n, objective E, t s``.

    >>> describe({"stage": "start ones", "iteration": 40, "max_iterations": 100,
    ...           "objective": 6.1e-05, "elapsed_s": 3.2})
    'start ones: iteration 40/100, objective 6.1e-05, 3 s'
    """
    parts = []
    if event.get("iteration") is not None:
        cap = event.get("max_iterations")
        parts.append(f"iteration {event['iteration']}" + (f"/{cap}" if cap else ""))
    if isinstance(event.get("objective"), (int, float)):
        parts.append(f"objective {event['objective']:.3g}")
    if isinstance(event.get("elapsed_s"), (int, float)):
        parts.append(f"{event['elapsed_s']:.0f} s")
    return f"{event.get('stage', '')}: " + ", ".join(parts)
