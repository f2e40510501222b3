"""Shared fixtures: random unit directions, and the location of ../shared/data; Dr.Jit's
debug mode for the render layer's tests.

The tests of the render layer (:data:`DEBUG_TESTS`: the renderer, the common-random-numbers
comparison, the furnace of the Dr.Jit evaluators, the Mitsuba export, the engine round
trips) run in Dr.Jit's debug mode (``BRDFFIT_DRJIT_DEBUG=1`` and the flags themselves,
inherited by their child processes): each gather and scatter is bounds-checked and a stray
one is reported on stderr instead of reading memory that may or may not be mapped on the
machine at hand. A test whose captured output holds such a report fails, whatever it
asserted itself. Every render path goes through those tests once in debug mode; the
end-to-end tests (command line, batch, report) run in the mode users run, which is 2.5×
faster on them. ``BRDFFIT_DRJIT_DEBUG`` set in the environment applies to every test.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
_OUT_OF_BOUNDS = "out-of-bounds"
#: the environment's choice, for every test; None: debug mode for :data:`DEBUG_TESTS` only
_DEBUG_FROM_ENV = os.environ.get("BRDFFIT_DRJIT_DEBUG")
#: the test files of the render layer (paths relative to tests/, prefixes)
DEBUG_TESTS = ("evaluation/test_render", "evaluation/test_crn", "evaluation/test_furnace",
               "evaluation/test_engines_", "export/test_mitsuba")


def in_debug_mode(path) -> bool:
    """Whether the test file at ``path`` runs in Dr.Jit's debug mode (module docstring)."""
    if _DEBUG_FROM_ENV is not None:
        return _DEBUG_FROM_ENV.strip() not in ("", "0")
    rel = Path(path).resolve().relative_to(Path(__file__).resolve().parent).as_posix()
    return rel.startswith(DEBUG_TESTS)


@pytest.fixture(autouse=True)
def drjit_debug_mode(request, monkeypatch):
    """Dr.Jit's debug mode on for the render layer's tests, off for the others: the variable
    for child processes and for Mitsuba's first load here, the flags once it is loaded."""
    on = in_debug_mode(request.node.path)
    monkeypatch.setenv("BRDFFIT_DRJIT_DEBUG", "1" if on else "0")
    dr = sys.modules.get("drjit")
    if dr is not None and hasattr(dr, "JitFlag"):
        dr.set_flag(dr.JitFlag.Debug, on)
        dr.set_flag(dr.JitFlag.PacketOps, not on)     # debug mode checks packets wrongly
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Fail a test during which Dr.Jit reported an out-of-bounds access (module docstring)."""
    outcome = yield
    report = outcome.get_result()
    err = "".join(text for name, text in report.sections
                  if name == f"Captured stderr {report.when}")
    if report.passed and _OUT_OF_BOUNDS in err:
        lines = [ln for ln in err.splitlines() if _OUT_OF_BOUNDS in ln]
        report.outcome = "failed"
        report.longrepr = (f"Dr.Jit's debug mode reported {len(lines)} out-of-bounds "
                           "access(es) during this test:\n" + "\n".join(lines[:10]))


def shared_data_path(*parts) -> Path:
    """Path under ../shared/data, skipping the test with a clear reason when it is absent."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"needs the shared data set at {p} (absent on this machine)")
    return p


@pytest.fixture
def shared_data():
    return shared_data_path


def random_hemisphere(rng, n):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    return v


@pytest.fixture
def null_device(tmp_path):
    """A character device that discards what is written (the null device, major 1 minor 3)
    of the test's own: a node in ``tmp_path`` when the tests run as root, so that a
    regression that replaces devices cannot destroy the machine's ``/dev/null``; else
    ``/dev/null`` itself (which a non-root process cannot replace)."""
    import stat

    if hasattr(os, "geteuid") and os.geteuid() == 0:
        node = tmp_path / "null"
        try:
            os.mknod(node, stat.S_IFCHR | 0o666, os.makedev(1, 3))
            with open(node, "wb") as fh:  # a filesystem mounted nodev refuses device nodes
                fh.write(b"probe")
            return node
        except OSError:
            pass
    if not stat.S_ISCHR(os.stat("/dev/null").st_mode):
        pytest.skip("/dev/null is not a character device on this machine")
    return Path("/dev/null")


@pytest.fixture
def rng():
    return np.random.default_rng(1234)
