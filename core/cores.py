"""The cores this process may use: the one count every thread pool of the project sizes itself
by (the Monte Carlo's blocks of runs, the tracker's split blocks, the track file's
formatters)."""

from __future__ import annotations

import os


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1
