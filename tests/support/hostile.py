"""Run the ``brdffit`` command on a hostile input under limits, and judge the outcome.

The malformed-input suite (``tests/``) and ``bench/bench_robustness.py`` both use
:func:`run_limited`: the command runs in a child process with an address-space limit
(``RLIMIT_AS``, default 1 GiB) and a wall-clock timeout, and :class:`Outcome` records its exit
status, standard error, wall time and peak resident memory. :meth:`Outcome.problems` lists
what breaks brdffit's promise for a rejected input (README "Security and robustness"):

* exit status 1 (an error, not a crash, usage error or success);
* exactly one line on standard error, naming the file, no traceback;
* no output left behind in the output folder;
* under ``max_seconds`` (5 s) and under the memory limit.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Sequence

__all__ = ["Outcome", "run_limited", "MEMORY_LIMIT", "MAX_SECONDS"]

#: Address-space limit of the child (bytes): a rejected input must stay below it.
MEMORY_LIMIT = 1 << 30
#: Wall-clock limit of a rejected input (seconds).
MAX_SECONDS = 5.0


@dataclasses.dataclass
class Outcome:
    """What one run of the command did."""

    argv: list[str]
    returncode: int
    stdout: str
    stderr: str
    seconds: float
    peak_rss_bytes: int
    timed_out: bool = False

    @property
    def error_lines(self) -> list[str]:
        return [line for line in self.stderr.splitlines() if line.strip()]

    def problems(self, *, names: str | Sequence[str] = (), out_dir: Path | None = None,
                 code: int = 1, max_seconds: float = MAX_SECONDS,
                 max_bytes: int = MEMORY_LIMIT) -> list[str]:
        """Ways this outcome breaks the contract for a rejected input ([] when clean).

        ``names``: strings the error line must contain (e.g. the file's name);
        ``out_dir``: a folder that must be empty or absent afterwards.
        """
        found = []
        if self.timed_out:
            found.append(f"timed out after {self.seconds:.1f} s")
        if self.returncode != code:
            found.append(f"exit status {self.returncode}, expected {code}")
        lines = self.error_lines
        if len(lines) != 1:
            found.append(f"{len(lines)} lines on stderr, expected 1: {self.stderr[-400:]!r}")
        if "Traceback" in self.stderr:
            found.append("traceback on stderr")
        for name in [names] if isinstance(names, str) else names:
            if name and name not in self.stderr:
                found.append(f"error does not name {name!r}: {self.stderr.strip()[:300]!r}")
        if self.seconds > max_seconds:
            found.append(f"took {self.seconds:.2f} s (limit {max_seconds} s)")
        if self.peak_rss_bytes > max_bytes:
            found.append(f"peak memory {self.peak_rss_bytes / 2**20:.0f} MiB "
                         f"(limit {max_bytes / 2**20:.0f} MiB)")
        if out_dir is not None and Path(out_dir).exists():
            left = sorted(str(p.relative_to(out_dir)) for p in Path(out_dir).rglob("*"))
            if left:
                found.append(f"output left behind: {left[:5]}")
        return found


_LAUNCHER = ("import os, resource, sys\n"
             "n = int(sys.argv[1])\n"
             "resource.setrlimit(resource.RLIMIT_AS, (n, n))\n"
             "os.execv(sys.executable, [sys.executable, '-m', 'brdffit', *sys.argv[2:]])\n")


def run_limited(args: Sequence[str], *, cwd=None, max_bytes: int = MEMORY_LIMIT,
                timeout: float = 60.0, env: dict | None = None) -> Outcome:
    """Run ``python -m brdffit ARGS`` with an address-space limit of ``max_bytes``.

    The child gets one thread per numerical library (so the limit measures the input, not
    thread stacks) and inherits the environment otherwise. Peak resident memory is the
    child's ``VmHWM`` (/proc) polled every 5 ms once it runs brdffit: ``wait4``'s
    ``ru_maxrss`` cannot be used, since Linux keeps in it the RSS the child had *before*
    exec — this (possibly large) test process's, copied by fork.
    """
    # the limit is set by a small launcher that then execs brdffit (no preexec_fn)
    argv = [sys.executable, "-c", _LAUNCHER, str(int(max_bytes)), *map(str, args)]
    child_env = {**os.environ, **(env or {}), "OMP_NUM_THREADS": "1",
                 "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                 "NUMBA_NUM_THREADS": "1", "PYTHONFAULTHANDLER": ""}
    t0 = time.perf_counter()
    with tempfile.TemporaryFile("w+") as fout, tempfile.TemporaryFile("w+") as ferr:
        proc = subprocess.Popen(argv, cwd=cwd, env=child_env, stdout=fout, stderr=ferr,
                                text=True)
        timed_out = False
        peak = 0
        while True:
            peak = max(peak, _hwm_after_exec(proc.pid))
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - t0 > timeout:
                proc.kill()
                timed_out = True
                _, status, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.005)
        seconds = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        fout.seek(0), ferr.seek(0)
        out, err = fout.read(), ferr.read()
    return Outcome(list(map(str, args)), proc.returncode, out, err, seconds, peak, timed_out)


def _hwm_after_exec(pid: int) -> int:
    """``VmHWM`` of ``pid`` in bytes once it has exec'd the launcher or brdffit (its
    command line is then ``python -c …`` or ``python -m brdffit …``), else 0."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            argv = fh.read().split(b"\0")
        if not (argv[1:2] == [b"-c"] or argv[1:3] == [b"-m", b"brdffit"]):
            return 0                                   # still the fork of this process
        with open(f"/proc/{pid}/status", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0
