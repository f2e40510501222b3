"""Test-only Dask worker preload: fitters that misbehave, registered in the *workers* only.

The fault tests load this file into their local cluster's workers with Dask's standard
preload mechanism (``dask.config.set({"distributed.worker.preload": [this file]})``), so the
test process's own fitter registry is never touched (a poisonous fitter there would kill
pytest). Nothing in brdffit itself knows about these fitters.

* ``test-poison``: kills its worker process with SIGKILL (what the kernel's OOM killer or the
  nanny's memory limit do to a material that exhausts the worker's memory).
* ``test-copy``: returns the (synthetic, saveable) reference itself — a fit that costs
  nothing, for tests of the batch's bookkeeping rather than of fitting.
* ``test-slow-copy``: writes ``<marker_dir>/<pid>.<random>`` (one per attempt; so the test knows which worker runs it),
  waits ``delay`` seconds, then returns the reference — a task the test can kill its worker
  under.
* With ``BRDFFIT_TEST_WORKER_VERSION`` set in the test process (copied into the preload's
  config by the test), the worker pretends to be another brdffit version.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import brdffit
from brdffit.fit.registry import register_fitter


def _poison(brdf, **_):
    os.kill(os.getpid(), signal.SIGKILL)


def _copy(brdf, **_):
    return brdf


def _slow_copy(brdf, marker_dir: str, delay: float = 2.0):
    (Path(marker_dir) / f"{os.getpid()}.{os.urandom(4).hex()}").write_text("running")
    time.sleep(delay)
    return brdf


register_fitter("test-poison", _poison, description="test: SIGKILLs its worker")
register_fitter("test-copy", _copy, description="test: the reference itself")
register_fitter("test-slow-copy", _slow_copy, description="test: slow copy")

_version = os.environ.get("BRDFFIT_TEST_WORKER_VERSION")
if _version:
    brdffit.__version__ = _version
