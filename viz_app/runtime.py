"""Process-level settings the command line applies before heavy numerical work."""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import platform
import resource
import signal
import sys
from collections.abc import Iterator
from types import FrameType
from typing import Any

from radarviz.core.cores import available_cores

# glibc mallopt parameters (malloc.h).
_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3


def tune_allocator() -> bool:
    """Ask glibc malloc to keep freed memory for reuse instead of returning it to the OS.

    The batched filters create many short-lived vectors of 10⁴ floats per scan. With glibc's
    defaults each one is unmapped or trimmed on free and faulted back in on the next
    allocation, which costs more than the arithmetic (about 2× slower, see ``radarviz bench``).
    Returns True if the settings were applied (glibc only; elsewhere a no-op).
    """
    if not sys.platform.startswith("linux"):
        return False
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    ok = mallopt(_M_MMAP_THRESHOLD, 32 * 1024 * 1024)
    ok &= mallopt(_M_TRIM_THRESHOLD, 256 * 1024 * 1024)
    ok &= mallopt(_M_TOP_PAD, 16 * 1024 * 1024)
    return bool(ok)


def peak_rss_mb() -> float:
    """Peak resident set size of this process so far, in MiB: Linux's VmHWM, this program's
    own peak. ``ru_maxrss`` (the fallback elsewhere) keeps the peak of the process this one
    was forked from across ``exec``: ``radarviz live`` started by the benchmark reported the
    benchmark's 950 MiB while it held 350."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0  # kB
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def machine() -> dict[str, Any]:
    """The machine a benchmark ran on: processor model, cores usable by this process, total
    memory in GiB and the 1-minute load average now (Linux's ``/proc``; elsewhere what the
    standard library knows). Throughput figures are only comparable with this beside them."""
    model = platform.processor() or platform.machine()
    mem_gib: float | None = None
    try:
        with open("/proc/cpuinfo") as fh:
            model = next(
                (ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")), model
            )
        with open("/proc/meminfo") as fh:
            kib = next(int(ln.split()[1]) for ln in fh if ln.startswith("MemTotal"))
        mem_gib = round(kib / 2**20, 1)
    except (OSError, StopIteration, ValueError):
        pass
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return {
        "cpu": model,
        "cores": available_cores(),
        "memory_gib": mem_gib,
        "load_avg_1min": round(load, 2) if load is not None else None,
        "python": platform.python_version(),
    }


@contextlib.contextmanager
def sigint_deferred() -> Iterator[None]:
    """Hold a Ctrl-C back while the block runs; raise it as ``KeyboardInterrupt`` when the
    block has ended (or instead of the error it ended with, which the interrupt caused).

    For a block that must not stop half way, such as the start of a Dask cluster: an
    interrupt in the middle of one left it half made, and its ``atexit`` close then failed
    with a traceback of its own. Once the block is over, what it made is whole and the
    ``with`` statements around it close it cleanly. Only in the main thread (where Python
    runs signal handlers); elsewhere the block runs as it is.
    """
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []

    def note(signum: int, frame: FrameType | None) -> None:
        caught.append(signum)

    previous = signal.signal(signal.SIGINT, note)
    try:
        yield
    except Exception:
        if not caught:
            raise
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        raise KeyboardInterrupt
