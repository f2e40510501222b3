"""Shared fixtures: random unit directions, and the location of ../shared/data; Dr.Jit's
debug mode for the whole suite.

Every render of the suite runs in Dr.Jit's debug mode (``BRDFFIT_DRJIT_DEBUG=1``, set here
unless the environment says otherwise, inherited by every child process): each gather and
scatter is bounds-checked and a stray one is reported on stderr instead of reading memory
that may or may not be mapped on the machine at hand. A test whose captured output holds
such a report fails, whatever it asserted itself.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
os.environ.setdefault("BRDFFIT_DRJIT_DEBUG", "1")
_OUT_OF_BOUNDS = "out-of-bounds"


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
