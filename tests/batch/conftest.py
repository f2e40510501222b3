"""Fixtures of the batch tests: one small local Dask cluster shared by the tests that only
need *a* cluster (fault tests that need special workers start their own)."""

from __future__ import annotations

from pathlib import Path

import pytest

PLUGIN = str(Path(__file__).with_name("_faults_plugin.py"))


@pytest.fixture(scope="session")
def dask_client():
    """A client of a one-worker local cluster (brdffit's own settings) whose worker also knows
    the test fitters of ``_faults_plugin.py`` (e.g. ``test-copy``); closed at the end."""
    import dask
    import distributed  # noqa: F401 – its config defaults must exist before dask.config.set

    from brdffit.batch import _client

    with dask.config.set({"distributed.worker.preload": [PLUGIN]}):
        client, cluster = _client(None, 1, None)
    try:
        yield client
    finally:
        client.close()
        cluster.close()
