"""``radarviz bench``'s ``association`` figures: the cost of associating unlabelled plots.

``targets`` targets on an 8 km grid (rows of up to 40, from 50 km out), each flying
straight at 150 m/s along x plus its own velocity (normal, 20 m/s per axis: no two paths
cross), seen by one 2D radar (σr = 50 m, σβ = 0.1°, T = 5 s), every target detected every
scan and no clutter, ``scans`` scans; the tracks start with σv0 = 200 m/s, so that neighbours
are never in each other's first gate and the association is unambiguous. The same plots
are tracked three times in one run, method ``ucm`` with the cv model, the three interleaved
scan by scan (so that a shared machine's load falls on all three alike):

* ``associated_plots_per_s``: without labels, by ``core.tracking.association.GNNTracker``
  (the coarse gate box, d² of the candidate pairs, the per-component assignment, M-of-N);
* ``dense_plots_per_s``: the same by ``GNNTracker(dense=True)`` (the d² matrix of every
  live track against every plot, one assignment on it), and ``dense_over_sparse``, the
  ratio of their times (the sparse route's speed-up); ``same_as_dense``: whether the two
  gave every plot the same track id;
* ``labelled_plots_per_s``: with each plot's true target label, by
  ``core.tracking.targets.TargetTracker`` (the filtering alone);
* ``association_over_labelled`` (and ``dense_over_labelled``): the ratio of the times per
  plot (the association's overhead; the filtering is the same), and ``correct``: whether
  every confirmed track followed one target (the association made no error, so the runs
  filtered the same plots per track).

* ``stamped_*``: the same scene with each plot at its own time, uniform within
  ``STAMP_WINDOW_S`` of its scan's start (a rotating radar's time stamps; scans of that
  window), associated by the sparse route against the labelled filtering, interleaved the
  same way (``stamped_correct``: every track on one target).

* ``rotating_*``: the layout of real multi-radar data (``core.scenarios.rotating``):
  ``targets`` targets of air traffic en route (anywhere in a disc of 60 km, any heading)
  over ``ROTATING_S`` seconds, four rotating radars
  113 km apart (periods 4.0 to 5.1 s, phases staggered, 80 km coverage, P_D 0.9, 5 false
  plots a revolution), each plot stamped by its radar's beam; the plots associated as they
  come with the defaults of ``track --associate gnn`` (IMM, gate ``ucm``, ``plot_batches``:
  a few plots a batch; the batches of ``LABELLED_BLOCK`` plots handed over at once,
  ``GNNTracker.add_batches``, as the command does) by the compiled route
  (``rotating_plots_per_cpu_s``, the gating method's own filtering included) and, with
  ``reference``, by the numpy engine (``rotating_numpy_plots_per_cpu_s``, the reference
  route, and ``rotating_same_as_numpy``: the same track ids), against the labelled
  filtering of the same plots (each plot's true target, a false plot its own label) in
  blocks of ``LABELLED_BLOCK`` (``rotating_labelled_plots_per_cpu_s``; the ratio of the
  times ``rotating_over_labelled``). Times are CPU seconds (``time.process_time``: a shared
  machine's other work is not counted), the passes interleaved block by block;
  ``rotating_purity`` and ``rotating_tracks_per_target`` (``core.tracking.plot_scores``)
  say the association held the targets.

``dense=False`` leaves the dense route out (its K × P matrix is the cost it measures).
"""

from __future__ import annotations

import gc
import math
import time
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

GRID_M = 8e3
SIGMA_R_M, SIGMA_BETA_DEG, PERIOD_S = 50.0, 0.1, 5.0
#: The stamped pass: each plot's own time within this much of its scan's start (s).
STAMP_WINDOW_S = 1.0


#: The rotating pass: seconds of traffic, and the labelled filtering's block of plots.
ROTATING_S = 40.0
LABELLED_BLOCK = 2048
#: The rotating pass's radars: (x, y) sites (m), periods 4.0 + 0.37 j s, phases 1.3 j rad.
ROTATING_SITES = ((-40e3, -40e3), (40e3, -40e3), (40e3, 40e3), (-40e3, 40e3))


def bench_rotating(
    targets: int, duration_s: float = ROTATING_S, seed: int = 3, reference: bool = False
) -> dict[str, Any]:
    """The ``rotating_*`` figures (module docstring)."""
    from radarviz.core.experiments.association import rotating_scene_plots
    from radarviz.core.scenarios.rotating import (
        CLUTTER,
        RotatingRadar,
        air_traffic,
        rotating_plots,
    )
    from radarviz.core.tracking.association import AssociationOptions, GNNTracker, plot_batches
    from radarviz.core.tracking.plot_scores import plot_scores
    from radarviz.core.tracking.stream import Plot, StreamOptions
    from radarviz.core.tracking.targets import TargetTracker

    sites = [
        RotatingRadar(f"r{j}", x, y, period_s=4.0 + 0.37 * j, phase_rad=1.3 * j)
        for j, (x, y) in enumerate(ROTATING_SITES)
    ]
    rng = np.random.default_rng(seed)
    traffic = air_traffic(rng, targets, duration_s, turn_rate_dps=1.0, en_route=True)
    pl = rotating_plots(rng, sites, traffic, duration_s)
    plots = rotating_scene_plots(sites, pl)
    labels = [f"t{o}" if o != CLUTTER else f"c{i}" for i, o in enumerate(pl.origin.tolist())]
    labelled = [replace(p, target=t) for p, t in zip(plots, labels, strict=True)]
    options = StreamOptions(model="imm")
    engines = ("compiled", "numpy") if reference else ("compiled",)
    # A throw-away pass first: the kernels' first calls load their machine code.
    for engine in engines:
        warm = GNNTracker(("ucm",), False, replace(options, engine=engine), AssociationOptions())
        for batch in plot_batches(enumerate(plots[:200]), warm.association.batch_sector_deg):
            warm.add_batch([p for _, p in batch])
    TargetTracker(("ucm",), False, options).add_block(labelled[:200])
    # As ``radarviz track`` does before it tracks: what is loaded by now frozen out of the
    # cycle collector's reach (a full pass over it costs tens of milliseconds).
    gc.collect()
    gc.freeze()
    gnns = {
        e: GNNTracker(("ucm",), False, replace(options, engine=e), AssociationOptions())
        for e in engines
    }
    tracker = TargetTracker(("ucm",), False, options)
    cpu = dict.fromkeys((*engines, "labelled"), 0.0)
    ids: dict[str, list[str]] = {e: [] for e in engines}
    sector = gnns["compiled"].association.batch_sector_deg
    # As ``radarviz track`` does: the batches of a block of plots in one call.
    blocks: list[tuple[list[list[Plot]], int, int]] = []  # (batches, first plot, end)
    chunk: list[list[Plot]] = []
    done = 0
    for batch in plot_batches(enumerate(plots), sector):
        chunk.append([p for _, p in batch])
        end = batch[-1][0] + 1
        if end - done >= LABELLED_BLOCK or end == len(plots):
            blocks.append((chunk, done, end))
            done, chunk = end, []

    def associate(engine: str, chunk: list[list[Plot]]) -> None:
        t0 = time.process_time()
        for result in gnns[engine].add_batches(chunk):
            ids[engine] += result.track_ids
        cpu[engine] += time.process_time() - t0

    # The compiled route and the labelled filtering block by block, interleaved (the same
    # conditions for both); the numpy engine's reference pass after them, on its own (a
    # thousand times slower, run between the blocks it would leave the caches cold).
    for chunk, lo, hi in blocks:
        associate("compiled", chunk)
        t0 = time.process_time()
        tracker.add_block(labelled[lo:hi])
        cpu["labelled"] += time.process_time() - t0
    if reference:
        for chunk, _, _ in blocks:
            associate("numpy", chunk)
    gc.unfreeze()
    n = len(plots)
    gnn = gnns["compiled"]
    score = plot_scores(pl.origin, ids["compiled"], set(gnn.ever_confirmed))
    doc: dict[str, Any] = {
        "rotating_targets": targets,
        "rotating_radars": len(sites),
        "rotating_duration_s": duration_s,
        "rotating_plots": n,
        "rotating_plots_per_batch": n / max(1, gnn.batches),
        "rotating_plots_per_cpu_s": n / cpu["compiled"],
        "rotating_labelled_plots_per_cpu_s": n / cpu["labelled"],
        "rotating_over_labelled": cpu["compiled"] / cpu["labelled"],
        "rotating_purity": score.purity,
        "rotating_tracks_per_target": score.tracks_per_target,
    }
    if reference:
        doc |= {
            "rotating_numpy_plots_per_cpu_s": n / cpu["numpy"],
            "rotating_same_as_numpy": ids["numpy"] == ids["compiled"],
        }
    return doc


def bench_association(
    targets: int, scans: int = 8, seed: int = 3, dense: bool = True
) -> dict[str, Any]:
    """The ``association`` figures (module docstring)."""
    from radarviz.core.tracking.association import AssociationOptions, GNNTracker
    from radarviz.core.tracking.stream import Plot, StreamOptions
    from radarviz.core.tracking.targets import TargetTracker

    rng = np.random.default_rng(seed)
    cols = min(targets, 40)
    k = np.arange(targets)
    x0, y0 = 5e4 + GRID_M * (k % cols), GRID_M * (k // cols - (targets // cols) / 2)
    v = np.array([150.0, 0.0]) + rng.normal(0.0, 20.0, (targets, 2))
    sigma_beta_rad = math.radians(SIGMA_BETA_DEG)

    def scan(t: NDArray[np.float64]) -> list[Plot]:
        """Every target's plot, target i's at time t[i], in time order."""
        x, y = x0 + v[:, 0] * t, y0 + v[:, 1] * t
        r = np.hypot(x, y) + SIGMA_R_M * rng.standard_normal(targets)
        b = np.arctan2(y, x) + sigma_beta_rad * rng.standard_normal(targets)
        return [
            Plot(
                float(t[i]),
                float(r[i]),
                float(b[i]),
                SIGMA_R_M,
                sigma_beta_rad,
                radar="radar",
                target=str(i),
            )
            for i in np.argsort(t, kind="stable").tolist()
        ]

    scan_plots = [scan(np.full(targets, n * PERIOD_S)) for n in range(scans)]
    stamped = [
        scan(n * PERIOD_S + STAMP_WINDOW_S * rng.uniform(size=targets)) for n in range(scans)
    ]
    options = StreamOptions(model="cv", sigma_a_mps2=1.0, sigma_v0_mps=200.0)
    # A throw-away pass over two scans of a few targets first: lazy imports and first-call
    # costs (half a second) would otherwise fall on whichever route runs first.
    # The stamped pass takes routes of its own (each plot predicted to its own time), so it
    # is warmed too: without it its figure moved 8× from run to run.
    warm = [[p for p in plots if int(p.target) < 5] for plots in scan_plots[:2]]
    warm_stamped = [[p for p in plots if int(p.target) < 5] for plots in stamped[:2]]
    for dense_route, window_s, scans_of in (
        (False, 0.0, warm),
        (True, 0.0, warm),
        (False, STAMP_WINDOW_S, warm_stamped),
    ):
        opts = AssociationOptions(scan_window_s=window_s)
        warm_gnn = GNNTracker(("ucm",), False, options, opts, dense=dense_route)
        for plots in scans_of:
            warm_gnn.add_scan([replace(p, target="") for p in plots])
    for scans_of in (warm, warm_stamped):
        warm_labelled = TargetTracker(("ucm",), False, options)
        for plots in scans_of:
            warm_labelled.add_block(plots)
    labelled = TargetTracker(("ucm",), False, options)
    sparse = GNNTracker(("ucm",), False, options, AssociationOptions())
    reference = GNNTracker(("ucm",), False, options, AssociationOptions(), dense=True)
    truth_of: dict[str, set[str]] = {}
    same = True
    t_labelled = t_gnn = t_dense = 0.0
    for plots in scan_plots:
        bare = [replace(p, target="") for p in plots]
        t0 = time.perf_counter()
        labelled.add_block(plots)
        t1 = time.perf_counter()
        res = sparse.add_scan(bare)
        t2 = time.perf_counter()
        t_labelled += t1 - t0
        t_gnn += t2 - t1
        if dense:
            t2 = time.perf_counter()
            ref = reference.add_scan(bare)
            t_dense += time.perf_counter() - t2
            same = same and ref.track_ids == res.track_ids
        for p, track in zip(plots, res.track_ids, strict=True):
            truth_of.setdefault(track, set()).add(p.target)
    # The stamped pass: the same scene, each plot at its own time (a rotating radar's time
    # stamps), scans of STAMP_WINDOW_S; the sparse route against the labelled filtering.
    stamped_gnn = GNNTracker(
        ("ucm",), False, options, AssociationOptions(scan_window_s=STAMP_WINDOW_S)
    )
    stamped_labelled = TargetTracker(("ucm",), False, options)
    t_stamped = t_stamped_labelled = 0.0
    stamped_confirmed: set[str] = set()
    for plots in stamped:
        bare = [replace(p, target="") for p in plots]
        t0 = time.perf_counter()
        stamped_labelled.add_block(plots)
        t1 = time.perf_counter()
        res = stamped_gnn.add_scan(bare)
        t2 = time.perf_counter()
        t_stamped_labelled += t1 - t0
        t_stamped += t2 - t1
        for p, track in zip(plots, res.track_ids, strict=True):
            stamped_confirmed.add(f"{track}:{p.target}")
    n = targets * scans
    doc: dict[str, Any] = {
        "targets": targets,
        "scans": scans,
        "associated_plots_per_s": n / t_gnn,
        "labelled_plots_per_s": n / t_labelled,
        "association_over_labelled": t_gnn / t_labelled,
        "correct": len(sparse.ever_confirmed) == targets
        and all(len(truth_of[t]) == 1 for t in sparse.ever_confirmed),
        "stamped_window_s": STAMP_WINDOW_S,
        "stamped_plots_per_s": n / t_stamped,
        "stamped_labelled_plots_per_s": n / t_stamped_labelled,
        "stamped_over_labelled": t_stamped / t_stamped_labelled,
        "stamped_correct": len(stamped_gnn.ever_confirmed) == targets
        and len(stamped_confirmed) == len({c.split(":")[0] for c in stamped_confirmed}),
    }
    doc |= bench_rotating(targets, reference=dense)
    if dense:
        doc |= {
            "dense_plots_per_s": n / t_dense,
            "dense_over_sparse": t_dense / t_gnn,
            "dense_over_labelled": t_dense / t_labelled,
            "same_as_dense": same,
        }
    return doc


def format_association(doc: dict[str, Any]) -> str:
    """One line of ``format_bench``."""
    line = (
        f"association (GNN, ucm), {doc['targets']} targets × {doc['scans']} scans, no "
        f"clutter: {doc['associated_plots_per_s']:.0f} plots/s against "
        f"{doc['labelled_plots_per_s']:.0f} plots/s with the true labels "
        f"(association/labelled {doc['association_over_labelled']:.1f}× the time; "
        f"{'every track on one target' if doc['correct'] else 'ASSOCIATION ERRORS'})"
    )
    if "dense_plots_per_s" in doc:
        line += (
            f"; the dense d² matrix {doc['dense_plots_per_s']:.0f} plots/s, "
            f"{doc['dense_over_sparse']:.1f}× the sparse route's time "
            f"({doc['dense_over_labelled']:.1f}× labelled; "
            f"{'the same track ids' if doc['same_as_dense'] else 'OTHER TRACK IDS'})"
        )
    line += (
        f"; each plot its own time stamp (scans of {doc['stamped_window_s']:g} s): "
        f"{doc['stamped_plots_per_s']:.0f} plots/s against "
        f"{doc['stamped_labelled_plots_per_s']:.0f} labelled "
        f"({doc['stamped_over_labelled']:.1f}× the time; "
        f"{'every track on one target' if doc['stamped_correct'] else 'ASSOCIATION ERRORS'})"
    )
    line += (
        f"; rotating radars ({doc['rotating_radars']}, each plot stamped by its beam, "
        f"{doc['rotating_plots_per_batch']:.1f} plots a batch), {doc['rotating_targets']} "
        f"targets: {doc['rotating_plots_per_cpu_s']:.0f} plots per CPU-second against "
        f"{doc['rotating_labelled_plots_per_cpu_s']:.0f} labelled "
        f"({doc['rotating_over_labelled']:.1f}× the time; purity "
        f"{doc['rotating_purity']:.3f}"
    )
    if "rotating_numpy_plots_per_cpu_s" in doc:
        line += (
            f"; the numpy engine {doc['rotating_numpy_plots_per_cpu_s']:.0f}, "
            f"{'the same track ids' if doc['rotating_same_as_numpy'] else 'OTHER TRACK IDS'}"
        )
    return line + ")"
