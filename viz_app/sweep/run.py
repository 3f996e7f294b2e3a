"""``radarviz sweep``: the Prosov Monte Carlo over a parameter grid, on Dask or in-process.

    radarviz sweep --preset prosov --grid sigma_beta_deg=0.5:3:0.5 range_km=50:300:50 \\
        --runs 100000 [--scheduler local|serial|tcp://HOST:PORT] --out SWEEP.parquet

Every grid point is cut into the blocks of ``core.experiments.prosov.run_tracking`` (chunks, see
``core.experiments.sweep``); chunks are computed wherever the scheduler puts them, each finished
chunk is saved beside the output (``SWEEP.parquet.chunks/``, one small ``.npz`` per chunk, named by
a hash of everything its value depends on), and every grid point is reduced from its chunks in
block order. So the numbers do not depend on the scheduler, the number of workers, the order
chunks finish in, a worker dying mid-sweep, or an interrupted sweep resumed later: a re-run
loads the chunks already on disk and computes only the missing ones.

Chunk files are written by this (the client) process, not by the workers, so a remote
``tcp://`` cluster needs no shared file system; the workers need ``radarviz`` importable.
The command's flags are in ``viz_app.cli.sweep``.
"""

from __future__ import annotations

import contextlib
import logging
import re
import time
import zipfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

import numpy as np

from radarviz.core.experiments.prosov import TrackingConfig, TrackingResult
from radarviz.core.experiments.sweep import (
    CHUNK_VERSION,
    GRID_AXES,
    ChunkSums,
    ChunkTask,
    GridAxis,
    SweepSpec,
    check_chunk,
    chunk_key,
    compute_chunk,
    reduce_chunks,
)
from radarviz.core.params import ParameterError, check_choice
from radarviz.viz_app.io.atomic import atomic_write
from radarviz.viz_app.runtime import sigint_deferred, tune_allocator

#: Values one grid axis may have (a guard against a mistyped step such as 0.5:300:0.001).
MAX_AXIS_VALUES = 1000
SCHEDULER_HELP = "serial (no Dask), local (an in-process Dask LocalCluster) or tcp://HOST:PORT"
_ADDRESS = re.compile(r"^(tcp|tls)://(\[[0-9a-fA-F:]+\]|[A-Za-z0-9_.-]+):(\d{1,5})$")

ChunkFn = Callable[[TrackingConfig, int, int], ChunkSums]
ProgressFn = Callable[[int, int], None]


# --------------------------------------------------------------------------- grid syntax


def _decimal(axis: str, text: str, what: str) -> Decimal:
    try:
        d = Decimal(text.strip())
    except InvalidOperation:
        raise ParameterError(f"--grid {axis} {what} must be a number (got {text!r})") from None
    if not d.is_finite():
        raise ParameterError(f"--grid {axis} {what} must be a finite number (got {text!r})")
    return d


def parse_axis(text: str) -> GridAxis:
    """One ``--grid`` item: ``name=start:stop:step`` or ``name=v1,v2,...``.

    A range runs from start in steps of step and includes stop when stop lands on the grid
    (``0.5:3:0.5`` → 0.5, 1, …, 3; ``50:300:40`` → 50, 90, …, 290). It is computed in decimal
    arithmetic, so ``0.1:0.3:0.1`` gives 0.1, 0.2, 0.3 exactly as typed, not 0.30000000000000004.
    """
    name, sep, rest = text.partition("=")
    name = name.strip()
    if not sep:
        raise ParameterError(
            f"--grid items must look like NAME=START:STOP:STEP or NAME=V1,V2,... (got {text!r})"
        )
    check_choice("--grid name", name, GRID_AXES)
    spec = GRID_AXES[name]
    if ":" in rest:
        parts = rest.split(":")
        if len(parts) != 3:
            raise ParameterError(f"--grid {name} range must be START:STOP:STEP (got {rest!r})")
        start, stop, step = (
            _decimal(name, p, w) for p, w in zip(parts, ("start", "stop", "step"), strict=True)
        )
        if step <= 0:
            raise ParameterError(f"--grid {name} step must be a number > 0 (got {parts[2]!r})")
        if stop < start:
            raise ParameterError(f"--grid {name} stop must be >= start (got {parts[0]}:{parts[1]})")
        count = int((stop - start) // step) + 1
        if count > MAX_AXIS_VALUES:
            raise ParameterError(
                f"--grid {name} must have at most {MAX_AXIS_VALUES} values (got {count})"
            )
        decimals = [start + k * step for k in range(count)]
    else:
        items = [p for p in rest.split(",")]
        if not rest.strip() or any(not p.strip() for p in items):
            raise ParameterError(f"--grid {name} needs values, e.g. {name}=1,2 (got {rest!r})")
        if len(items) > MAX_AXIS_VALUES:
            raise ParameterError(
                f"--grid {name} must have at most {MAX_AXIS_VALUES} values (got {len(items)})"
            )
        decimals = [_decimal(name, p, "value") for p in items]
    values = tuple(float(d) for d in decimals)
    for v in values:
        spec.check(f"--grid {name} ({spec.unit})", v)
    if len(set(values)) != len(values):
        raise ParameterError(f"--grid {name} repeats a value ({rest})")
    return GridAxis(name, values)


def parse_grid(items: Sequence[str]) -> tuple[GridAxis, ...]:
    """Every ``--grid`` item, in order (the first axis varies slowest)."""
    axes = tuple(parse_axis(t) for t in items)
    names = [a.name for a in axes]
    for n in names:
        if names.count(n) > 1:
            raise ParameterError(f"--grid {n} is given more than once")
    return axes


def check_scheduler(text: str) -> str:
    """``serial``, ``local`` or a Dask scheduler address ``tcp://HOST:PORT``."""
    if text in ("serial", "local"):
        return text
    m = _ADDRESS.match(text)
    if m is None or not 0 < int(m.group(3)) < 65536:
        raise ParameterError(f"--scheduler must be {SCHEDULER_HELP} (got {text!r})")
    return text


# --------------------------------------------------------------------------- chunk store


class ChunkStore:
    """Finished chunks on disk: ``<dir>/<chunk_key>.npz``, written atomically.

    A file holds the chunk's arrays and its key; a file that cannot be read, whose key does
    not match, or whose arrays do not fit the block counts as missing and is recomputed.
    Because the name hashes every input of the chunk (``core.experiments.sweep.chunk_key``), a sweep
    with another seed, σ, target or method list never picks up a stale chunk.
    """

    def __init__(self, directory: Path) -> None:
        self.directory = directory

    def path(self, key: str) -> Path:
        return self.directory / f"{key}.npz"

    def load(self, task: ChunkTask, key: str) -> ChunkSums | None:
        path = self.path(key)
        if not path.is_file():
            return None
        try:
            with np.load(path, allow_pickle=False) as z:
                chunk = ChunkSums(
                    index=int(z["index"]),
                    methods=tuple(str(m) for m in z["methods"]),
                    runs=z["runs"].astype(np.int64, copy=False),
                    sums=z["sums"].astype(np.float64, copy=False),
                )
                stored_key = str(z["key"])
            if stored_key != key:
                return None
            check_chunk(task.config, chunk, task.index, task.size)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            return None  # unreadable or foreign: recompute it
        return chunk

    def save(self, key: str, chunk: ChunkSums) -> None:
        """Write to a temporary name in the same directory, then rename onto the key's name,
        so a reader never sees half a chunk (an interrupted write leaves only a ``.tmp``)."""
        self.directory.mkdir(parents=True, exist_ok=True)
        final = self.path(key)
        with atomic_write(final) as fh:
            np.savez(
                fh,
                key=np.array(key),
                version=np.array(CHUNK_VERSION),
                index=np.array(chunk.index, dtype=np.int64),
                methods=np.array(chunk.methods),
                runs=chunk.runs,
                sums=chunk.sums,
            )


# --------------------------------------------------------------------------- scheduling


@dataclass(frozen=True)
class SweepRun:
    """The results of a sweep and what it took.

    Attributes:
        results: one ``TrackingResult`` per grid point, in ``spec.points()`` order.
        computed / reused: chunks computed now / loaded from the store.
        compute_s: wall time from the first submitted chunk to the last finished one.
        startup_s: wall time to start (or connect to) the scheduler.
        workers: Dask workers that were available (1 for ``serial``).
        chunk_wall_s / chunk_cpu_s: wall and CPU seconds of the computed chunks, summed
            (the last successful attempt of each; a chunk lost with a worker is not counted).
    """

    results: list[TrackingResult]
    computed: int
    reused: int
    compute_s: float
    startup_s: float
    workers: int
    chunk_wall_s: float = 0.0
    chunk_cpu_s: float = 0.0


def _worker_chunk(
    task: ChunkFn, config: TrackingConfig, index: int, size: int
) -> tuple[ChunkSums, float, float]:
    """Runs on a worker: keep freed memory for reuse (see ``viz_app.runtime``), then compute.

    Returns the chunk with the wall and CPU seconds it took: their totals tell scheduling
    overhead (wall time of the sweep above the chunks' own) apart from a slower core (chunk
    wall time above its CPU time: another process had the CPU). ``tune_allocator`` is called
    on every chunk because a worker restarted by its nanny starts with glibc's defaults
    again; the call takes microseconds.
    """
    tune_allocator()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    chunk = task(config, index, size)
    return chunk, time.perf_counter() - wall0, time.process_time() - cpu0


class SweepAbortedError(RuntimeError):
    """The cluster gave up on a chunk (its workers kept dying); one line for the user."""


def local_security() -> Any:
    """Dask TLS for one local cluster: a certificate made now, known only to this process.

    Needs the ``cryptography`` package (a dependency of radarviz).
    """
    from distributed.security import Security

    return Security.temporary()


@contextlib.contextmanager
def dask_client(scheduler: str, workers: int) -> Iterator[Any]:
    """A ``distributed.Client``: on a new LocalCluster (``local``) or at an address.

    The local cluster has ``workers`` single-threaded worker processes (the filters hold the
    GIL between many small numpy calls, so threads would not scale), listens on 127.0.0.1
    only (free ports) and has no dashboard.

    A Dask scheduler runs whatever a connected client submits, and 127.0.0.1 admits every
    program of every user on the machine. So the local cluster speaks TLS with certificates
    made for this run only (``Security.temporary()``: a throw-away CA, key and certificate
    held in memory and handed to the workers through the nanny, ``require_encryption``): a
    client must present that certificate, and a plain ``tcp://`` client, or a ``tls://`` one
    without it, is refused before it can submit anything. ``tcp://HOST:PORT`` is the user's
    own scheduler, with the security they gave it.
    """
    from distributed import Client, LocalCluster

    if scheduler == "local":
        import dask

        security = local_security()
        # Workers forked from a forkserver that ignores SIGINT: the terminal's Ctrl-C goes to
        # the whole process group, and each worker printed its own KeyboardInterrupt
        # traceback (~33 lines); now only this process sees it. The cluster starts with the
        # interrupt held back (``sigint_deferred``), so it is whole when the sweep stops.
        with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}):
            _start_forkserver_deaf_to_sigint()
            with contextlib.ExitStack() as stack:
                with sigint_deferred():
                    cluster = stack.enter_context(
                        LocalCluster(
                            n_workers=workers,
                            threads_per_worker=1,
                            processes=True,
                            host="127.0.0.1",
                            protocol="tls",
                            security=security,
                            dashboard_address=None,
                            # No dashboard; the scheduler's small HTTP server (health,
                            # metrics) still starts, so give it a free loopback port instead
                            # of the shared default 8787.
                            scheduler_kwargs={
                                "dashboard": False,
                                "dashboard_address": "127.0.0.1:0",
                            },
                            # CRITICAL, not ERROR: a Ctrl-C closes the scheduler while a
                            # worker's heartbeat may be in flight, and that worker logged
                            # a 40-line ERROR trace after the one-line message. The sweep
                            # reports its own failures (a chunk's exception is raised
                            # here, dying workers end in SweepAbortedError).
                            silence_logs=logging.CRITICAL,
                        )
                    )
                    client = stack.enter_context(Client(cluster, security=security))
                yield client
    else:
        with Client(scheduler, timeout="20s") as client:
            yield client


def _start_forkserver_deaf_to_sigint() -> None:
    """Start multiprocessing's forkserver (the parent of the local cluster's workers) with
    SIGINT ignored, which it keeps and every worker forked from it inherits. (Blocking the
    signal instead would not do: a new Python process unblocks every signal as it starts.)
    A Ctrl-C in the moment the server is started is lost; one that is already running is
    left as it is."""
    import multiprocessing.forkserver
    import signal

    from distributed.utils import get_mp_context

    get_mp_context()  # distributed's preload list for the server (imports, so not ignoring)
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        multiprocessing.forkserver.ensure_running()
    finally:
        signal.signal(signal.SIGINT, previous)


def run_sweep(
    spec: SweepSpec,
    store: ChunkStore | None,
    scheduler: str = "serial",
    workers: int = 1,
    progress: ProgressFn | None = None,
    task: ChunkFn = compute_chunk,
    client: Any | None = None,
) -> SweepRun:
    """Compute every chunk that is not in ``store``, then reduce each grid point in order.

    Args:
        store: where finished chunks are loaded from and saved to (None: keep nothing).
        scheduler: ``serial``, ``local`` or ``tcp://HOST:PORT`` (ignored if ``client`` given).
        workers: worker processes of a ``local`` cluster.
        progress: called as ``progress(runs_done, runs_total)``, reused chunks counted first.
        task: the chunk function; it must be pure, because Dask recomputes the chunks of a
            worker that dies. (Tests pass one that kills its worker once.)
        client: an existing ``distributed.Client`` to use instead of starting one.
    """
    tasks = spec.tasks()
    keys = [chunk_key(t.config, t.index, t.size) for t in tasks]
    total_runs = sum(t.size for t in tasks)
    found: dict[int, ChunkSums] = {}
    if store is not None:
        for i, (t, k) in enumerate(zip(tasks, keys, strict=True)):
            chunk = store.load(t, k)
            if chunk is not None:
                found[i] = chunk
    reused = len(found)
    done = sum(tasks[i].size for i in found)
    if progress is not None:
        progress(done, total_runs)
    missing = [i for i in range(len(tasks)) if i not in found]

    chunk_wall = chunk_cpu = 0.0

    def finished(i: int, timed: tuple[ChunkSums, float, float]) -> None:
        nonlocal done, chunk_wall, chunk_cpu
        chunk, wall_s, cpu_s = timed
        chunk_wall += wall_s
        chunk_cpu += cpu_s
        check_chunk(tasks[i].config, chunk, tasks[i].index, tasks[i].size)
        if store is not None:
            store.save(keys[i], chunk)
        found[i] = chunk
        done += tasks[i].size
        if progress is not None:
            progress(done, total_runs)

    t0 = time.perf_counter()
    startup = 0.0
    n_workers = 1
    if missing and (client is not None or scheduler != "serial"):
        with contextlib.ExitStack() as stack:
            if client is None:
                client = stack.enter_context(dask_client(scheduler, workers))
            startup = time.perf_counter() - t0
            n_workers = len(client.scheduler_info(n_workers=-1)["workers"])
            t0 = time.perf_counter()
            _run_on_dask(client, tasks, keys, missing, task, finished)
    else:
        for i in missing:
            t = tasks[i]
            finished(i, _worker_chunk(task, t.config, t.index, t.size))
    compute_s = time.perf_counter() - t0 if missing else 0.0

    results = []
    by_point: dict[int, list[ChunkSums]] = {}
    for i, t in enumerate(tasks):
        by_point.setdefault(t.point, []).append(found[i])
    for p, cfg in enumerate(spec.configs()):
        results.append(reduce_chunks(cfg, by_point[p], spec.block))
    return SweepRun(
        results, len(missing), reused, compute_s, startup, n_workers, chunk_wall, chunk_cpu
    )


def _run_on_dask(
    client: Any,
    tasks: list[ChunkTask],
    keys: list[str],
    missing: list[int],
    task: ChunkFn,
    finished: Callable[[int, tuple[ChunkSums, float, float]], None],
) -> None:
    """Submit the missing chunks and hand each one to ``finished`` as it completes.

    Completion order is whatever the cluster makes it; ``finished`` only stores the chunk,
    the reduction later walks the blocks in order. Dask's task keys are the chunk keys. A
    worker that dies takes
    its running chunk with it; the scheduler resubmits that chunk elsewhere (up to
    ``distributed.scheduler.allowed-failures`` times), and being pure it comes back the same.
    """
    from distributed import KilledWorker, as_completed

    # One config object per grid point is shipped with each of its chunks: a few hundred
    # bytes, cheaper than scattering it and simpler to survive worker restarts.
    futures = {}
    for i in missing:
        t = tasks[i]
        fut = client.submit(
            _worker_chunk, task, t.config, t.index, t.size, key=f"chunk-{keys[i]}", pure=False
        )
        futures[fut] = i
    for fut in as_completed(list(futures)):
        try:
            result = fut.result()
        except KilledWorker:
            # Give up on the sweep, not on the work: every chunk already finished is saved.
            for other in futures:
                other.cancel()
            t = tasks[futures[fut]]
            raise SweepAbortedError(
                f"Dask gave up on chunk {t.index} of grid point {t.point}: workers died "
                "while it was on them more often than distributed.scheduler.allowed-failures "
                "allows (a crash or out of memory?); the finished chunks are kept: re-run to "
                "resume"
            ) from None
        finished(futures[fut], result)


def chunk_dir(out: Path) -> Path:
    """Where the chunks of the sweep writing ``out`` are kept: ``<out>.chunks/``."""
    return out.with_name(out.name + ".chunks")
