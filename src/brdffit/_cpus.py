"""The number of CPUs this process may use."""

from __future__ import annotations

import os

__all__ = ["usable_cpus"]


def usable_cpus() -> int:
    """The CPUs this process may run on: its affinity mask where the system has one (Linux;
    a container or ``taskset`` may allow fewer than the machine has), else
    :func:`os.cpu_count` (macOS and Windows have no ``sched_getaffinity``); at least 1.

    >>> usable_cpus() >= 1
    True
    """
    getaffinity = getattr(os, "sched_getaffinity", None)
    if getaffinity is not None:
        return max(1, len(getaffinity(0)))
    return max(1, os.cpu_count() or 1)
