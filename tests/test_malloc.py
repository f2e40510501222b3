"""The command line's malloc settings (brdffit._malloc): freed arrays are reused, not
page-faulted in again."""

import json
import os
import subprocess
import sys

import pytest

from brdffit._malloc import WORKER_MALLOC_ENV, tune_this_process

# A 40 MB array (above glibc's largest dynamic mmap threshold, 32 MiB) made, freed and made
# again; minor page faults of the second one (NumPy's huge pages off: one fault per 4 KiB).
_SECOND_ARRAY_FAULTS = """
import json, resource, sys
from brdffit._malloc import tune_this_process
tuned = tune_this_process() if sys.argv[1] == "tune" else False
import numpy as np
def faults(): return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
a = np.ones(5_000_000); del a
f0 = faults(); a = np.ones(5_000_000); f1 = faults()
print(json.dumps({"tuned": tuned, "faults": f1 - f0}))
"""


def _second_array_faults(mode: str, **env) -> dict:
    run_env = {k: v for k, v in os.environ.items() if k not in WORKER_MALLOC_ENV}
    run_env.update(NUMPY_MADVISE_HUGEPAGE="0", **env)
    out = subprocess.run([sys.executable, "-c", _SECOND_ARRAY_FAULTS, mode], env=run_env,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc mallopt: Linux only")
def test_tuned_process_reuses_freed_arrays_without_page_faults():
    plain = _second_array_faults("plain")
    tuned = _second_array_faults("tune")
    assert tuned["tuned"] is True
    assert plain["faults"] > 5000          # 40 MB of fresh 4 KiB pages
    assert tuned["faults"] < 200           # the freed heap, reused


def test_the_users_malloc_variables_win(monkeypatch):
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    assert tune_this_process() is False
    if sys.platform.startswith("linux"):  # and the settings of a user who set them are kept
        assert _second_array_faults("tune", MALLOC_TRIM_THRESHOLD_="65536")["tuned"] is False


def test_the_command_line_tunes_its_process(monkeypatch, capsys):
    import brdffit.cli as cli

    calls = []
    monkeypatch.setattr(cli, "tune_this_process", lambda: calls.append(1) or True)
    assert cli.main(["models", "--json"]) == 0
    assert calls == [1]
