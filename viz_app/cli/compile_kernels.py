"""``radarviz compile``: compile every numba kernel the commands use, once, in parallel.

numba compiles a kernel on its first call and caches the machine code beside the source
(``viz_app.numba_cache``), so the first ``demo`` or ``track`` on a fresh machine spent 11 to
75 s of CPU compiling and up to 0.9 GB of LLVM's working memory before its first result
(docs/performance.md, section 10). This command pays that once, at set-up (the README's
commands run it after ``pip install``): it runs the commands themselves on small inputs,
each in a process of its own, as many at a time as there are cores, so the kernels are
compiled for exactly the argument types the commands pass them (no list of signatures kept
by hand beside the code that calls them). A later run of any command loads the cached code.

The cache stamp is a hash of the kernel modules' sources, not of times or of the process, so
what this writes stays valid until a kernel module changes (an edit, a checkout); running
the command again then recompiles, and otherwise only loads (a few seconds).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from radarviz.viz_app.cli.args import integer
from radarviz.viz_app.cli.commands import Registrar


@dataclass(frozen=True)
class Job:
    """A warm-up: ``radarviz`` command lines run in order in one process each, in a
    temporary folder (``{d}`` in an argument is that folder)."""

    name: str
    commands: tuple[tuple[str, ...], ...]


def _simulate(preset: str, *extra: str) -> tuple[str, ...]:
    return (
        "simulate", "--preset", preset, "--out", f"{{d}}/{preset}.csv",
        "--radars-out", f"{{d}}/{preset}.toml", *extra,
    )  # fmt: skip


def _track(preset: str, out: str, *extra: str) -> tuple[str, ...]:
    return (
        "track", "--input", f"{{d}}/{preset}.csv", "--radars", f"{{d}}/{preset}.toml",
        "--out", f"{{d}}/{out}.csv", *extra,
    )  # fmt: skip


_TRUTH = ("--truth", "{d}/truth.csv")

#: The warm-ups, longest first (they are started in this order). Together they reach every
#: kernel of ``demo`` and of ``track`` in 2D and 3D, with and without Doppler, the IMM and
#: the cv model, labelled and associated plots, the recording's.
JOBS: tuple[Job, ...] = (
    Job(
        "track --associate gnn (2D, IMM and cv, --rrd)",
        (
            _simulate("crossing", "--scans", "30", "--truth-out", "{d}/truth.csv"),
            _track("crossing", "gnn", "--associate", "gnn", "--rrd", "{d}/gnn.rrd", *_TRUTH),
            _track("crossing", "gnn_cv", "--associate", "gnn", "--model", "cv"),
        ),
    ),
    Job(
        "track 3D, Doppler (IMM and cv, --rrd)",
        (
            _simulate("manoeuvre", "--scans", "40"),
            _track("manoeuvre", "m", "--rrd", "{d}/m.rrd"),
            _track("manoeuvre", "m_cv", "--model", "cv", "--doppler", "converted"),
            _track("manoeuvre", "m_fm", "--doppler", "ignore", "--init", "finite-memory"),
        ),
    ),
    Job(
        "track 2D (IMM and cv, --rrd)",
        (
            _simulate("prosov"),
            _track("prosov", "p", "--rrd", "{d}/p.rrd"),
            _track("prosov", "p_cv", "--model", "cv", "--init", "finite-memory"),
        ),
    ),
    Job("demo", (("demo", "--out", "{d}/demo.rrd"),)),
)


@dataclass(frozen=True)
class Done:
    """A job's outcome: wall and CPU seconds, and the error output of a command that failed."""

    job: Job
    wall_s: float
    cpu_s: float
    error: str | None


_ENTRY = "import sys; from radarviz_entry import main; sys.exit(main())"


def _run(job: Job, folder: Path) -> Done:
    import subprocess

    t0 = time.perf_counter()
    cpu = 0.0
    folder.mkdir()
    for command in job.commands:
        argv = [a.replace("{d}", str(folder)) for a in command]
        with tempfile.TemporaryFile("w+") as err:
            proc = subprocess.Popen(
                [sys.executable, "-c", _ENTRY, *argv], stdout=subprocess.DEVNULL, stderr=err
            )
            # Reaped here to read its own CPU time (RUSAGE_CHILDREN would mix the jobs, each
            # run by a thread of this process).
            _, status, usage = os.wait4(proc.pid, 0)
            proc.returncode = os.waitstatus_to_exitcode(status)
            cpu += usage.ru_utime + usage.ru_stime
            if proc.returncode:
                err.seek(0)
                tail = "\n".join(err.read().strip().splitlines()[-5:])
                wall = time.perf_counter() - t0
                return Done(job, wall, cpu, f"radarviz {' '.join(argv)}: {tail}")
    return Done(job, time.perf_counter() - t0, cpu, None)


def cached_kernels() -> int:
    """The number of compiled kernels in the package's numba cache (``*.nbc`` files, one per
    function and argument types)."""
    from radarviz.viz_app.numba_cache import _ROOTS

    return sum(1 for root in _ROOTS for _ in root.rglob("__pycache__/*.nbc"))


def compile_all(jobs: int, report: Callable[[str], None] = print) -> int:
    """Run ``JOBS``, ``jobs`` at a time; report each as it ends; the number that failed."""
    # Here, not at the top: the parser imports this module for every command.
    from concurrent.futures import ThreadPoolExecutor

    before = cached_kernels()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="radarviz-compile-") as tmp:
        with ThreadPoolExecutor(max_workers=jobs) as pool:
            futures = [pool.submit(_run, job, Path(tmp) / str(i)) for i, job in enumerate(JOBS)]
            failed = 0
            for future in futures:
                done = future.result()
                if done.error is None:
                    report(f"  {done.job.name}: {done.cpu_s:.1f} s CPU, {done.wall_s:.1f} s")
                else:
                    failed += 1
                    report(f"  {done.job.name}: FAILED\n{done.error}")
    after = cached_kernels()
    report(
        f"compiled {max(after - before, 0)} kernels ({after} cached) in "
        f"{time.perf_counter() - t0:.1f} s with {jobs} processes at a time"
    )
    return failed


def add_commands(sub: Registrar) -> None:
    """Register ``compile`` on the ``radarviz`` parser."""
    comp = sub.add_parser("compile")
    comp.add_argument(
        "--jobs",
        type=integer,
        default=None,
        help="processes at a time, >= 1 (default: the number of cores)",
    )


def cmd_compile(args: argparse.Namespace) -> int:
    from radarviz.core.cores import available_cores
    from radarviz.core.params import check_int

    jobs = available_cores() if args.jobs is None else args.jobs
    check_int("--jobs", jobs, low=1, high=256)
    print(f"compiling the kernels of {len(JOBS)} workloads, {jobs} at a time:", flush=True)
    return 1 if compile_all(jobs, lambda line: print(line, flush=True)) else 0


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {"compile": cmd_compile}
