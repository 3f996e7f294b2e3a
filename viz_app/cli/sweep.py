"""``radarviz sweep`` and ``radarviz bench-sweep``: the flags and the two commands.

The work is in ``viz_app.sweep.run`` (chunks, store, scheduling) and ``viz_app.bench.sweep``
(the scaling benchmark); this module turns flags into a ``SweepSpec`` and prints the outcome.
The fixed σβ, σr, T, scans, runs and seed are checked once, by ``core.experiments.sweep.SweepBase``
against the parameter table; a bad one is reported under its flag.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from radarviz.core.experiments.prosov import ALL_METHODS, BLOCK_RUNS
from radarviz.core.experiments.sweep import GRID_AXES, SWEEP_PRESETS, SweepBase, SweepSpec
from radarviz.core.finite import check_finite_document
from radarviz.core.params import ParameterError, check_choice, check_int
from radarviz.viz_app.bench.sweep import DEFAULT_GRID, DEFAULT_RUNS, format_bench, run_bench
from radarviz.viz_app.cli.args import integer, number, print_report
from radarviz.viz_app.cli.commands import Registrar
from radarviz.viz_app.cli.params import add_parameter, map_flag, parameter_flags
from radarviz.viz_app.io.atomic import check_outputs, commit_together
from radarviz.viz_app.runtime import tune_allocator
from radarviz.viz_app.sweep.run import (
    SCHEDULER_HELP,
    ChunkStore,
    SweepAbortedError,
    check_scheduler,
    chunk_dir,
    parse_grid,
    run_sweep,
)


def add_commands(sub: Registrar) -> None:
    """Register ``sweep`` and ``bench-sweep`` on the ``radarviz`` parser."""
    _add_bench_command(sub)
    sw = sub.add_parser(
        "sweep",
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
    add_parameter(sw, "runs", note="per grid point")
    add_parameter(sw, "seed", note="the same at every grid point")
    preset = SWEEP_PRESETS["prosov"]
    add_parameter(sw, "steps", default=None, shown_default=preset.steps)
    where = "where the grid does not vary it"
    add_parameter(
        sw, "sigma_beta_deg", default=None, shown_default=preset.sigma_beta_deg, note=where
    )
    add_parameter(sw, "sigma_r_m", default=None, shown_default=preset.sigma_r_m, note=where)
    range_axis = GRID_AXES["range_km"]
    sw.add_argument(
        "--range-km",
        type=number,
        default=None,
        help=f"{range_axis.meaning} (km), in ({range_axis.low:g}, {range_axis.high:g}], "
        f"default {preset.range_km:g} ({where})",
    )
    map_flag(sw, "range_km", "--range-km")
    add_parameter(
        sw,
        "period_s",
        "--period",
        "--period-s",
        default=None,
        shown_default=preset.period_s,
        note=where,
    )
    sw.add_argument(
        "--dims",
        type=integer,
        default=2,
        choices=(2, 3),
        help="2: the paper's plane; 3: the same target at an elevation, the radar measuring "
        "elevation too, every method in 3D (grid axes elevation_deg, sigma_elevation_deg)",
    )
    map_flag(sw, "dims", "--dims")
    elevation_axis = GRID_AXES["elevation_deg"]
    sw.add_argument(
        "--elevation-deg",
        type=number,
        default=None,
        help=f"{elevation_axis.meaning} (deg), in [{elevation_axis.low:g}, "
        f"{elevation_axis.high:g}], default {preset.elevation_deg:g} (with --dims 3, {where})",
    )
    map_flag(sw, "elevation_deg", "--elevation-deg")
    add_parameter(
        sw,
        "sigma_elevation_deg",
        default=None,
        shown_default=preset.sigma_elevation_deg,
        note=f"with --dims 3, {where}",
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


def _add_bench_command(sub: argparse._SubParsersAction) -> None:
    b = sub.add_parser("bench-sweep")
    b.add_argument(
        "--grid",
        nargs="+",
        default=list(DEFAULT_GRID),
        metavar="NAME=SPEC",
        help=f"grid axes as for sweep (default {' '.join(DEFAULT_GRID)})",
    )
    add_parameter(
        b,
        "runs",
        default=DEFAULT_RUNS,
        note="per grid point: 10^6 runs on the default 4-point grid",
    )
    add_parameter(b, "seed")
    add_parameter(b, "steps")
    b.add_argument(
        "--methods",
        nargs="+",
        default=list(ALL_METHODS),
        metavar="METHOD",
        help="methods to run (default all)",
    )
    b.add_argument(
        "--workers",
        type=integer,
        nargs="+",
        default=[1, 2],
        help="worker counts to time, in this order; efficiency is relative to the "
        "smallest (default 1 2)",
    )
    b.add_argument("--json", action="store_true", help="print only JSON")


def _spec_from_args(args: argparse.Namespace) -> SweepSpec:
    check_choice("--preset", args.preset, SWEEP_PRESETS)
    preset = SWEEP_PRESETS[args.preset]
    axes = parse_grid(args.grid)
    check_int("--block", args.block, low=1, high=10_000_000)
    flags = parameter_flags(args)
    fixed: dict[str, float] = {}
    for name, spec in GRID_AXES.items():  # the values themselves are checked once, by SweepBase
        value = getattr(args, name)
        if value is None:
            fixed[name] = getattr(preset, name)
        else:
            fixed[name] = value
            if args.dims not in spec.dims:
                raise ParameterError(f"{flags[name]} needs --dims 3")
            if any(a.name == name for a in axes):
                raise ParameterError(
                    f"{flags[name]} conflicts with --grid {name}: give one of them"
                )
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
        steps=preset.steps if args.steps is None else args.steps,
        speed_mps=preset.speed_mps,
        runs=args.runs,
        seed=args.seed,
        methods=tuple(args.methods),
        dims=args.dims,
        elevation_deg=fixed["elevation_deg"],
        sigma_elevation_deg=fixed["sigma_elevation_deg"],
    )
    spec = SweepSpec(base=base, axes=axes, block=args.block)
    spec.configs()  # every grid point's config is checked before any work starts
    return spec


def _check_output_paths(
    args: argparse.Namespace, spec: SweepSpec
) -> tuple[Path, Path | None, Path | None, list[Path]]:
    """Fail before any work if an output cannot be written where asked, or would replace
    another output (``viz_app.io.atomic.check_outputs``): the table, the recording, the chunks
    directory beside the table, and the figures of ``--plot`` (their names are known before
    computing, ``figure_paths``). A ``--plot`` directory that does not exist is created here,
    so a path that cannot be one fails now; returned are the directories created, which the
    caller removes again if the sweep writes nothing."""
    from radarviz.viz_app.sweep.output import figure_paths

    check_outputs([("--out", args.out), ("--rrd", args.rrd)])
    out = Path(args.out)
    rrd = None if args.rrd is None else Path(args.rrd)
    chunks = chunk_dir(out)
    if chunks.exists() and not chunks.is_dir():
        raise ParameterError(
            f"--out: its chunks directory {str(chunks)!r} exists and is not a directory"
        )
    if args.plot is None:
        return out, None, rrd, []
    if not args.plot.strip():
        raise ParameterError("--plot must name a directory (got an empty string)")
    plot = Path(args.plot)
    if plot.exists() and not plot.is_dir():
        raise ParameterError(f"--plot must name a directory (got the file {args.plot!r})")
    created = [d for d in (plot, *plot.parents) if not d.exists()][::-1]
    try:
        plot.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ParameterError(
            f"--plot: cannot create the directory {args.plot!r} ({exc.strerror or exc})"
        ) from None
    try:
        figures = [("--plot", path) for path in figure_paths(spec, plot)]
        check_outputs([("--out", out), ("--rrd", rrd), *figures])
    except ParameterError:
        _remove_empty(created)
        raise
    return out, plot, rrd, created


def _remove_empty(directories: list[Path]) -> None:
    """Remove the directories ``_check_output_paths`` created, deepest first, if still empty."""
    for d in reversed(directories):
        try:
            d.rmdir()
        except OSError:
            return


def cmd_sweep(args: argparse.Namespace) -> int:
    spec = _spec_from_args(args)
    scheduler = check_scheduler(args.scheduler)
    if args.workers is None:
        workers = os.cpu_count() or 1
    else:
        workers = check_int("--workers", args.workers, low=1, high=1024)
    out, plot_dir, rrd, created = _check_output_paths(args, spec)
    try:
        code = _sweep(args, spec, scheduler, workers, out, plot_dir, rrd)
    except BaseException:
        _remove_empty(created)
        raise
    if code:
        _remove_empty(created)
    return code


def _sweep(
    args: argparse.Namespace,
    spec: SweepSpec,
    scheduler: str,
    workers: int,
    out: Path,
    plot_dir: Path | None,
    rrd: Path | None,
) -> int:
    """The sweep once its outputs are checked (``cmd_sweep``)."""
    from radarviz.viz_app.reports.prosov import check_tracking_result
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
    for i, result in enumerate(run.results):  # before any output: all good or none written
        check_tracking_result(f"sweep: point {i}", result)
    figures: list[str] = []
    with commit_together():  # the table, the figures and the recording: all or none
        write_parquet(sweep_table(spec, run.results), out)
        if plot_dir is not None:
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
    check_finite_document("sweep", doc, nonnegative=True)  # counts and times
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


def cmd_bench_sweep(args: argparse.Namespace) -> int:
    axes = parse_grid(args.grid)
    for w in args.workers:
        check_int("--workers", w, low=1, high=1024)
    for m in args.methods:
        if m not in ALL_METHODS:
            raise ParameterError(f"--methods must be among {', '.join(ALL_METHODS)} (got {m!r})")
    spec = SweepSpec(
        base=SweepBase(
            runs=args.runs, seed=args.seed, steps=args.steps, methods=tuple(args.methods)
        ),
        axes=axes,
    )
    spec.configs()
    tune_allocator()
    doc = run_bench(spec, list(args.workers))
    check_finite_document("bench-sweep", doc, nonnegative=True)
    print_report(doc, args.json, format_bench)
    return 0


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "sweep": cmd_sweep,
    "bench-sweep": cmd_bench_sweep,
}
