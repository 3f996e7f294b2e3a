"""``radarviz bench-sweep``: how a sweep scales with the number of local Dask workers.

The same sweep is computed from scratch (no chunk store) on a LocalCluster of 1, 2, …
workers. For each it reports the compute wall time T_w (first chunk submitted to last one
back; cluster start-up apart) and the parallel efficiency E_w = T_1 / (w · T_w), and checks
that every run gave the same numbers bit for bit as the first. (Efficiency is relative to
the smallest worker count timed.)

It also sums the chunks' own wall and CPU seconds. On an idle machine they are equal; when
chunk wall time exceeds CPU time, another process was taking the cores and the efficiency
says more about the machine than about the sweep — the report shows the load average too.
"""

from __future__ import annotations

import argparse
import os
from typing import Any

import numpy as np

from radarviz.core.experiments.prosov import ALL_METHODS, TrackingResult
from radarviz.core.experiments.sweep import SweepBase, SweepSpec
from radarviz.core.params import ParameterError, check_int
from radarviz.viz_app.cli.args import integer, print_report

DEFAULT_GRID = ("sigma_beta_deg=1,2", "range_km=100,150")
DEFAULT_RUNS = 250_000


def add_command(sub: argparse._SubParsersAction) -> None:
    b = sub.add_parser("bench-sweep", help="scaling of a sweep over 1, 2, … local Dask workers")
    b.add_argument(
        "--grid",
        nargs="+",
        default=list(DEFAULT_GRID),
        metavar="NAME=SPEC",
        help=f"grid axes as for sweep (default {' '.join(DEFAULT_GRID)})",
    )
    b.add_argument(
        "--runs",
        type=integer,
        default=DEFAULT_RUNS,
        help=f"runs per grid point (default {DEFAULT_RUNS}: 10^6 runs on the default 4-point grid)",
    )
    b.add_argument("--seed", type=integer, default=1, help="random seed (default 1)")
    b.add_argument("--steps", type=integer, default=60, help="scans per run (default 60)")
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


def _same(a: list[TrackingResult], b: list[TrackingResult]) -> bool:
    return all(
        np.array_equal(x, y, equal_nan=True)
        for ra, rb in zip(a, b, strict=True)
        for m in ra.metrics
        for x, y in zip(ra.metrics[m], rb.metrics[m], strict=True)
    )


def run_bench(spec: SweepSpec, worker_counts: list[int]) -> dict[str, Any]:
    """Time the sweep on each worker count, in the order given (later runs may find the
    machine warmer); efficiency relative to the smallest count."""
    from radarviz.viz_app.sweep.run import run_sweep

    rows: list[dict[str, Any]] = []
    reference: list[TrackingResult] | None = None
    for w in worker_counts:
        load_before = os.getloadavg()[0]
        run = run_sweep(spec, store=None, scheduler="local", workers=w)
        rows.append(
            {
                "workers": run.workers,
                "compute_s": round(run.compute_s, 3),
                "startup_s": round(run.startup_s, 3),
                "chunk_wall_s": round(run.chunk_wall_s, 3),
                "chunk_cpu_s": round(run.chunk_cpu_s, 3),
                "load_avg_1min_before_after": [round(load_before, 2), round(os.getloadavg()[0], 2)],
                "identical_to_first": True if reference is None else _same(reference, run.results),
            }
        )
        if reference is None:
            reference = run.results
    # Efficiency against the fewest workers timed (normally 1), whatever the order run in.
    base = min(rows, key=lambda r: r["workers"])
    t_ref, w_ref = base["compute_s"], base["workers"]
    for r in rows:
        r["speedup"] = round(t_ref / r["compute_s"], 3)
        r["efficiency"] = round(t_ref * w_ref / (r["workers"] * r["compute_s"]), 3)
    return {
        "points": int(np.prod(spec.shape, dtype=np.int64)),
        "runs_per_point": spec.base.runs,
        "total_runs": int(np.prod(spec.shape, dtype=np.int64)) * spec.base.runs,
        "chunks": len(spec.tasks()),
        "methods": list(spec.base.methods),
        "steps": spec.base.steps,
        "cpu_count": os.cpu_count(),
        "runs": rows,
    }


def format_bench(doc: dict[str, Any]) -> str:
    lines = [
        f"sweep scaling: {doc['points']} points × {doc['runs_per_point']} runs = "
        f"{doc['total_runs']} runs, {doc['chunks']} chunks, {doc['steps']} scans, "
        f"{len(doc['methods'])} methods, {doc['cpu_count']} CPUs",
        "workers  compute s  speed-up  efficiency  chunk wall s  chunk CPU s  load before/after"
        "  identical",
    ]
    for r in doc["runs"]:
        lo, hi = r["load_avg_1min_before_after"]
        lines.append(
            f"{r['workers']:7d}  {r['compute_s']:9.2f}  {r['speedup']:8.3f}  "
            f"{r['efficiency']:10.3f}  {r['chunk_wall_s']:12.2f}  {r['chunk_cpu_s']:11.2f}  "
            f"{lo:6.2f} / {hi:<6.2f}  {r['identical_to_first']}"
        )
    return "\n".join(lines)


def cmd_bench_sweep(args: argparse.Namespace) -> int:
    from radarviz.viz_app.runtime import tune_allocator
    from radarviz.viz_app.sweep.run import parse_grid

    axes = parse_grid(args.grid)
    check_int("--runs", args.runs, low=2, high=10**10)
    check_int("--seed", args.seed, low=0)
    check_int("--steps", args.steps, low=2, high=100_000)
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
    print_report(doc, args.json, format_bench)
    return 0
