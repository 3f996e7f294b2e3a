"""``radarviz bench-sweep``: how a sweep scales with the number of local Dask workers.

The same sweep is computed from scratch (no chunk store) on a LocalCluster of 1, 2, …
workers. For each it reports the compute wall time T_w (first chunk submitted to last one
back; cluster start-up apart) and the parallel efficiency E_w = T_1 / (w · T_w), and checks
that every run gave the same numbers bit for bit as the first. (Efficiency is relative to
the smallest worker count timed.)

It also sums the chunks' own wall and CPU seconds. On an idle machine they are equal; when
chunk wall time exceeds CPU time, another process was taking the cores and the efficiency
says more about the machine than about the sweep — the report shows the load average too.
The command's flags are in ``viz_app.cli.sweep``.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from radarviz.core.experiments.prosov import TrackingResult
from radarviz.core.experiments.sweep import SweepSpec
from radarviz.viz_app.sweep.run import run_sweep

DEFAULT_GRID = ("sigma_beta_deg=1,2", "range_km=100,150")
DEFAULT_RUNS = 250_000


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
