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
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import re
import sys
import time
import zipfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

import numpy as np

from radarviz.core.experiments.prosov import ALL_METHODS, BLOCK_RUNS, TrackingConfig, TrackingResult
from radarviz.core.experiments.sweep import (
    CHUNK_VERSION,
    GRID_AXES,
    SWEEP_PRESETS,
    ChunkSums,
    ChunkTask,
    GridAxis,
    SweepBase,
    SweepSpec,
    check_chunk,
    chunk_key,
    compute_chunk,
    reduce_chunks,
)
from radarviz.core.params import ParameterError, check_choice, check_int, check_real
from radarviz.viz_app.bench.sweep import add_command as add_bench_command
from radarviz.viz_app.bench.sweep import cmd_bench_sweep
from radarviz.viz_app.cli.args import integer, number
from radarviz.viz_app.io.atomic import atomic_write

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
        check_real(f"--grid {name} ({spec.unit})", v, low=spec.low, high=spec.high)
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
    from radarviz.viz_app.runtime import tune_allocator

    tune_allocator()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    chunk = task(config, index, size)
    return chunk, time.perf_counter() - wall0, time.process_time() - cpu0


class SweepAbortedError(RuntimeError):
    """The cluster gave up on a chunk (its workers kept dying); one line for the user."""


@contextlib.contextmanager
def dask_client(scheduler: str, workers: int) -> Iterator[Any]:
    """A ``distributed.Client``: on a new LocalCluster (``local``) or at an address.

    The local cluster has ``workers`` single-threaded worker processes (the filters hold the
    GIL between many small numpy calls, so threads would not scale), listens on 127.0.0.1
    only (free ports) and has no dashboard.
    """
    from distributed import Client, LocalCluster

    if scheduler == "local":
        with (
            LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
                # No dashboard; the scheduler's small HTTP server (health, metrics) still
                # starts, so give it a free loopback port instead of the shared default 8787.
                scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                silence_logs=logging.ERROR,
            ) as cluster,
            Client(cluster) as client,
        ):
            yield client
    else:
        with Client(scheduler, timeout="20s") as client:
            yield client


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


# --------------------------------------------------------------------------- command line


def add_commands(sub: argparse._SubParsersAction) -> None:
    """Register ``sweep`` and ``bench-sweep`` on the ``radarviz`` parser."""
    add_bench_command(sub)
    sw = sub.add_parser(
        "sweep",
        help="the Prosov Monte Carlo over a parameter grid, on Dask (resumable)",
        description="Monte Carlo of every method at every grid point; chunks run on Dask and "
        "are kept beside the output so a re-run resumes. Results are identical whatever the "
        "scheduler or number of workers.",
    )
    sw.add_argument(
        "--preset",
        default="prosov",
        help=f"fixed parameters to start from (default prosov; one of {', '.join(SWEEP_PRESETS)})",
    )
    sw.add_argument(
        "--grid",
        nargs="+",
        default=[],
        metavar="NAME=SPEC",
        help="grid axes, NAME=START:STOP:STEP (stop included when on the grid) or "
        f"NAME=V1,V2,...; NAME one of {', '.join(GRID_AXES)}",
    )
    sw.add_argument(
        "--runs", type=integer, default=1000, help="Monte Carlo runs per grid point (default 1000)"
    )
    sw.add_argument(
        "--seed",
        type=integer,
        default=1,
        help="random seed, the same at every grid point (default 1)",
    )
    sw.add_argument("--steps", type=integer, default=None, help="scans per run (default 60)")
    sw.add_argument(
        "--sigma-beta-deg",
        type=number,
        default=None,
        help="σβ in degrees where the grid does not vary it (default 1)",
    )
    sw.add_argument(
        "--sigma-r-m",
        type=number,
        default=None,
        help="σr in metres where the grid does not vary it (default 250)",
    )
    sw.add_argument(
        "--range-km",
        type=number,
        default=None,
        help="initial range in km where the grid does not vary it (default 150)",
    )
    sw.add_argument(
        "--period",
        type=number,
        default=None,
        help="scan period T in s where the grid does not vary it (default 10)",
    )
    sw.add_argument(
        "--methods",
        nargs="+",
        default=list(ALL_METHODS),
        metavar="METHOD",
        help=f"methods to run (default all: {' '.join(ALL_METHODS)})",
    )
    sw.add_argument("--scheduler", default="local", help=f"{SCHEDULER_HELP} (default local)")
    sw.add_argument(
        "--workers",
        type=integer,
        default=None,
        help="worker processes of the local cluster (default: CPU count)",
    )
    sw.add_argument(
        "--block",
        type=integer,
        default=BLOCK_RUNS,
        help=f"runs per chunk (default {BLOCK_RUNS}, the block of reproduce prosov; "
        "another value changes the last bits of the results)",
    )
    sw.add_argument(
        "--out",
        required=True,
        metavar="SWEEP.parquet",
        help="Parquet file to write (replaced); chunks go to SWEEP.parquet.chunks/",
    )
    sw.add_argument("--plot", metavar="DIR", help="write heat-map figures (PNG) into DIR")
    sw.add_argument("--rrd", metavar="OUT.rrd", help="write a Rerun recording of the heat maps")
    sw.add_argument(
        "--json",
        action="store_true",
        help="print only a JSON summary (points, chunks, timings, files)",
    )


def _spec_from_args(args: argparse.Namespace) -> SweepSpec:
    check_choice("--preset", args.preset, SWEEP_PRESETS)
    preset = SWEEP_PRESETS[args.preset]
    axes = parse_grid(args.grid)
    check_int("--runs", args.runs, low=2, high=10**10)
    check_int("--seed", args.seed, low=0)
    check_int("--block", args.block, low=1, high=10_000_000)
    steps = (
        preset.steps
        if args.steps is None
        else check_int("--steps", args.steps, low=2, high=100_000)
    )
    fixed: dict[str, float] = {}
    for name, flag in (
        ("sigma_beta_deg", "--sigma-beta-deg"),
        ("sigma_r_m", "--sigma-r-m"),
        ("range_km", "--range-km"),
        ("period_s", "--period"),
    ):
        value = getattr(args, flag[2:].replace("-", "_"))
        spec = GRID_AXES[name]
        if value is None:
            fixed[name] = getattr(preset, name)
        else:
            fixed[name] = check_real(flag, value, low=spec.low, high=spec.high)
            if any(a.name == name for a in axes):
                raise ParameterError(f"{flag} conflicts with --grid {name}: give one of them")
    for m in args.methods:
        if m not in ALL_METHODS:
            raise ParameterError(f"--methods must be among {', '.join(ALL_METHODS)} (got {m!r})")
    if len(set(args.methods)) != len(args.methods):
        raise ParameterError(f"--methods repeats a method ({' '.join(args.methods)})")
    base = SweepBase(
        sigma_r_m=fixed["sigma_r_m"],
        sigma_beta_deg=fixed["sigma_beta_deg"],
        range_km=fixed["range_km"],
        period_s=fixed["period_s"],
        steps=steps,
        speed_mps=preset.speed_mps,
        runs=args.runs,
        seed=args.seed,
        methods=tuple(args.methods),
    )
    spec = SweepSpec(base=base, axes=axes, block=args.block)
    spec.configs()  # every grid point's config is checked before any work starts
    return spec


def _check_output_paths(args: argparse.Namespace) -> tuple[Path, Path | None, Path | None]:
    """Fail before any work if an output cannot be written where asked."""
    out = Path(args.out)
    if not args.out.strip() or out.is_dir():
        raise ParameterError(f"--out must name a file (got {args.out!r})")
    if not out.parent.is_dir():
        raise FileNotFoundError(2, "no such directory", str(out.parent))
    plot = rrd = None
    if args.plot is not None:
        if not args.plot.strip():
            raise ParameterError("--plot must name a directory (got an empty string)")
        plot = Path(args.plot)
        if plot.exists() and not plot.is_dir():
            raise ParameterError(f"--plot must name a directory (got the file {args.plot!r})")
    if args.rrd is not None:
        if not args.rrd.strip() or Path(args.rrd).is_dir():
            raise ParameterError(f"--rrd must name a file (got {args.rrd!r})")
        rrd = Path(args.rrd)
        if not rrd.parent.is_dir():
            raise FileNotFoundError(2, "no such directory", str(rrd.parent))
    return out, plot, rrd


def chunk_dir(out: Path) -> Path:
    """Where the chunks of the sweep writing ``out`` are kept: ``<out>.chunks/``."""
    return out.with_name(out.name + ".chunks")


def cmd_sweep(args: argparse.Namespace) -> int:
    spec = _spec_from_args(args)
    scheduler = check_scheduler(args.scheduler)
    if args.workers is None:
        workers = os.cpu_count() or 1
    else:
        workers = check_int("--workers", args.workers, low=1, high=1024)
    out, plot_dir, rrd = _check_output_paths(args)
    from radarviz.viz_app.runtime import tune_allocator
    from radarviz.viz_app.sweep.output import plot_sweep, record_sweep, sweep_table, write_parquet

    tune_allocator()
    bar = None
    if not args.json:
        from radarviz.viz_app.cli.progress import ProgressBar

        n = int(np.prod(spec.shape, dtype=np.int64))
        bar = ProgressBar(f"sweep {n} point(s)")
    wall0 = time.perf_counter()
    try:
        run = run_sweep(spec, ChunkStore(chunk_dir(out)), scheduler, workers, progress=bar)
    except SweepAbortedError as exc:
        print(f"radarviz: error: {exc}", file=sys.stderr)
        return 1
    write_parquet(sweep_table(spec, run.results), out)
    figures: list[str] = []
    if plot_dir is not None:
        plot_dir.mkdir(parents=True, exist_ok=True)
        figures = [str(p) for p in plot_sweep(spec, run.results, plot_dir)]
    if rrd is not None:
        record_sweep(spec, run.results, rrd)
    wall = time.perf_counter() - wall0
    doc = {
        "points": len(run.results),
        "runs_per_point": spec.base.runs,
        "chunks": run.computed + run.reused,
        "computed": run.computed,
        "reused": run.reused,
        "scheduler": scheduler,
        "workers": run.workers,
        "startup_s": round(run.startup_s, 3),
        "compute_s": round(run.compute_s, 3),
        "chunk_wall_s": round(run.chunk_wall_s, 3),
        "chunk_cpu_s": round(run.chunk_cpu_s, 3),
        "wall_s": round(wall, 3),
        "out": str(out),
        "chunks_dir": str(chunk_dir(out)),
        "figures": figures,
        "rrd": str(rrd) if rrd is not None else None,
    }
    if args.json:
        json.dump(doc, sys.stdout)
        sys.stdout.write("\n")
        return 0
    print(
        f"sweep: {doc['points']} point(s) × {spec.base.runs} runs, {doc['chunks']} chunks "
        f"({run.computed} computed, {run.reused} reused from {doc['chunks_dir']})"
    )
    if run.computed:
        print(
            f"computed in {run.compute_s:.2f} s on {run.workers} worker(s) ({scheduler}; "
            f"start-up {run.startup_s:.2f} s); {wall:.2f} s in all"
        )
        print(
            f"the chunks themselves took {run.chunk_wall_s:.2f} s wall, "
            f"{run.chunk_cpu_s:.2f} s CPU, summed over workers"
        )
    print(f"results written to {out}")
    for f in figures:
        print(f"figure written to {f}")
    if rrd is not None:
        print(f"recording written to {rrd}")
    return 0


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "sweep": cmd_sweep,
    "bench-sweep": cmd_bench_sweep,
}
