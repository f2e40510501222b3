"""``brdffit fit`` shows the iterations of a long fit on the terminal (issue 15.5)."""

from __future__ import annotations

import rich.console

from brdffit.cli.fit import _live_progress
from brdffit.progress import report


class _FakeStatus:
    def __init__(self, log):
        self.log = log

    def start(self):
        self.log.append("start")

    def update(self, text):
        self.log.append(text)

    def stop(self):
        self.log.append("stop")


def test_status_line_follows_the_fit_and_stops(monkeypatch):
    log = []
    monkeypatch.setattr(rich.console.Console, "status", lambda self, text: _FakeStatus(log))
    with _live_progress(enabled=True):
        report(stage="G-from-D AWLS", iteration=7, max_iterations=300, objective=1.5e-4)
    assert log[0] == "start" and log[-1] == "stop"
    assert "fitting – G-from-D AWLS: iteration 7/300, objective 0.00015" in log[1]


def test_nothing_shown_for_fits_without_progress_or_when_disabled(monkeypatch):
    log = []
    monkeypatch.setattr(rich.console.Console, "status", lambda self, text: _FakeStatus(log))
    with _live_progress(enabled=True):
        pass                                 # a closed-form fit: no event, no status line
    with _live_progress(enabled=False):
        report(stage="x", iteration=1)
    assert log == []
