"""The association on the compiled engine against the numpy engine (the reference).

``GNNTracker`` runs its filters and its gate's predictions on the engine its options ask for:
the compiled one by default (``core.tracking.compiled.CompiledTracks.predicted`` and
``forget``, the tracker kernels' own prediction, mixing and combination), or
``engine="numpy"``. The two must make the same association, plot for plot:

* ``CompiledTracks.predicted`` equals ``TargetTracker.predicted`` of the numpy engine (cv and
  IMM, 2D and 3D), to 1e-9 relative, one time or one per track, and the compiled gate's d²
  (``TargetTracker.gate_distances``) ``mahalanobis_pairs`` of it; ``forget`` frees the rows.
* On the rotating-radar scene (the association's batches as they come) and on the crossing
  scene (whole scans, clutter, confirmed tracks crossing): the same track ids, statuses,
  confirmations and deletions per batch, and every row to 1e-9 relative.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from test_rotating_association import radars, scene

from radarviz.core.experiments.association import rotating_scene_plots, scan_plots
from radarviz.core.scenarios.crossing import CrossingScene
from radarviz.core.tracking.association import (
    AssociationOptions,
    GNNTracker,
    ScanResult,
    mahalanobis_pairs,
    plot_batches,
)
from radarviz.core.tracking.consistency import ConsistencyMonitor
from radarviz.core.tracking.stream import Plot, StreamOptions, polar_arrays
from radarviz.core.tracking.targets import TargetTracker

TOL = 1e-9


def close(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal to ``TOL`` relative to the larger entry (a covariance's small off-diagonal terms
    are rounding next to its diagonal)."""
    scale = max(float(np.max(np.abs(a))), float(np.max(np.abs(b))), 1.0)
    return bool(np.all(np.abs(a - b) <= TOL * scale))


def labelled_plots(three_d: bool) -> list[Plot]:
    """Three targets flying apart, plots every 2 s by two radars, a time offset per target."""
    out = []
    for k in range(3):
        for j in range(8):
            t = 2.0 * j + 0.3 * k
            x, y, z = 2e4 + 150.0 * t, -1e4 + 4e3 * k + 20.0 * t, 3e3 + 200.0 * k
            site = (0.0, 0.0, 0.0) if j % 2 else (5e3, -3e3, 10.0)
            dx, dy, dz = x - site[0], y - site[1], z - site[2]
            out.append(
                Plot(
                    t,
                    math.sqrt(dx * dx + dy * dy + (dz * dz if three_d else 0.0)),
                    math.atan2(dy, dx),
                    40.0,
                    math.radians(0.2),
                    elevation_rad=math.atan2(dz, math.hypot(dx, dy)) if three_d else None,
                    sigma_elevation_rad=math.radians(0.3) if three_d else 0.0,
                    site=site,
                    radar=f"r{j % 2}",
                    target=f"T{k}",
                )
            )
    return sorted(out, key=lambda p: p.time_s)


@pytest.mark.parametrize("three_d", [False, True])
@pytest.mark.parametrize("model", ["cv", "imm"])
def test_compiled_prediction_is_the_numpy_engines(three_d: bool, model: str) -> None:
    methods = ("ucm", "ekf")
    trackers = [
        TargetTracker(methods, three_d, StreamOptions(model=model, engine=e))
        for e in ("numpy", "compiled")
    ]
    plots = labelled_plots(three_d)
    for tr in trackers:
        tr.add_block(plots)
    assert [tr.engine for tr in trackers] == ["numpy", "compiled"]
    ids = ["T2", "T0", "T1", "T0"]
    for method in methods:
        for when in (20.0, np.array([21.0, 19.9, 30.0, 14.6])):
            ref, got = (tr.predicted(method, ids, when) for tr in trackers)
            assert got.x.shape == ref.x.shape and got.P.shape == ref.P.shape
            assert close(ref.x, got.x) and close(ref.P, got.P), (method, when)
    with pytest.raises(ValueError, match="before a track's last plot"):
        trackers[1].predicted("ucm", ["T0"], 0.0)


@pytest.mark.parametrize("model", ["cv", "imm"])
def test_compiled_gate_distances_are_the_numpy_engines(model: str) -> None:
    """``TargetTracker.gate_distances`` (one compiled pass: prediction and d²) against the
    numpy engine's ``predicted`` scored by ``mahalanobis_pairs``, every method that converts
    the plot alone; None where it has no compiled form (numpy engine, a polar method)."""
    methods = ("naive", "seed", "cmkf_d", "ucm", "ekf")
    ref, fast = (
        TargetTracker(methods, False, StreamOptions(model=model, engine=e))
        for e in ("numpy", "compiled")
    )
    plots = labelled_plots(False)
    ref.add_block(plots)
    fast.add_block(plots)
    ids = ["T2", "T0", "T1", "T0", "T1"]
    times = np.array([15.1, 15.0, 21.0, 30.0, 14.6])
    probe = [
        replace(plots[i], time_s=float(t)) for i, t in zip((1, 4, 7, 9, 12), times, strict=True)
    ]
    plot, noise = polar_arrays(probe, 2)
    site = np.array([p.site for p in probe])[:, :2]
    for method in methods[:4]:
        want = mahalanobis_pairs(method, ref.predicted(method, ids, times), plot, noise, site)
        got = fast.gate_distances(method, ids, times, plot, noise, site)
        assert got is not None and np.all(np.abs(got - want) <= TOL * np.maximum(want, 1.0))
        assert ref.gate_distances(method, ids, times, plot, noise, site) is None
    assert fast.gate_distances("ekf", ids, times, plot, noise, site) is None


def test_compiled_forget_reuses_rows() -> None:
    """A forgotten target's row goes to the next new one, which starts afresh."""
    plots = labelled_plots(False)
    a = TargetTracker(("ucm",), False, StreamOptions(model="imm"))
    b = TargetTracker(("ucm",), False, StreamOptions(model="imm"))
    a.add_block(plots)
    a.forget(["T1"])
    assert a.targets == ("T0", "T2")
    fresh = replace(plots[-1], time_s=30.0, target="new")
    got = a.add_block([fresh])[0]
    want = b.add_block([fresh])[0]
    assert a._compiled is not None and a._compiled.slots["new"] == 1
    assert np.array_equal(got[0][1], want[0][1]) and np.array_equal(got[0][2], want[0][2])


def assert_same_results(ref: list[ScanResult], got: list[ScanResult]) -> None:
    """Per batch the same ids, statuses, confirmations, deletions; rows to ``TOL``."""
    assert len(ref) == len(got)
    for a, b in zip(ref, got, strict=True):
        assert a.track_ids == b.track_ids
        assert a.statuses == b.statuses
        assert (a.confirmed, a.deleted) == (b.confirmed, b.deleted)
        for ra, rb in zip(a.rows, b.rows, strict=True):
            assert [m for m, _, _ in ra] == [m for m, _, _ in rb]
            for (_, xa, Pa), (_, xb, Pb) in zip(ra, rb, strict=True):
                assert close(xa, xb) and close(Pa, Pb)


def test_rotating_scene_same_on_both_engines() -> None:
    """The defaults of ``track --associate gnn`` (IMM, ucm gate, plots as they come), four
    rotating radars, clutter, P_D < 1."""
    sites = radars()
    plots = rotating_scene_plots(sites, scene(7, sites, targets=12, duration_s=90.0))
    results: dict[str, list[ScanResult]] = {}
    for engine in ("numpy", "compiled"):
        gnn = GNNTracker(
            ("ucm",), False, StreamOptions(model="imm", engine=engine), AssociationOptions()
        )
        assert gnn.tracker.engine == engine
        batches = plot_batches(enumerate(plots), gnn.association.batch_sector_deg)
        results[engine] = [gnn.add_batch([p for _, p in b]) for b in batches]
    assert_same_results(results["numpy"], results["compiled"])
    assert sum(len(r.confirmed) for r in results["compiled"]) >= 12


@pytest.mark.parametrize("model", ["cv", "imm"])
def test_crossing_scene_same_on_both_engines(model: str) -> None:
    """Three targets crossing at 25°, P_D 0.8, clutter; two methods, the gate ``ekf`` (not
    boxed: every pair scored) or ``ucm``."""
    crossing = CrossingScene(
        targets=3, crossing_angle_deg=25.0, detection_prob=0.8, clutter_per_scan=4.0, scans=30
    )
    scans = scan_plots(crossing, np.random.default_rng(11))
    for gate in ("ucm", "ekf"):
        results: dict[str, list[ScanResult]] = {}
        for engine in ("numpy", "compiled"):
            options = StreamOptions(model=model, sigma_v0_mps=300.0, engine=engine)
            gnn = GNNTracker(("ucm", "ekf"), False, options, AssociationOptions(method=gate))
            results[engine] = [gnn.add_scan(s) for s in scans]
        assert_same_results(results["numpy"], results["compiled"])


def test_bench_rotating_figures_are_consistent() -> None:
    """``radarviz bench``'s rotating-radar association figures (speed is not asserted): the
    plots counted, the ratio equal to its two rates, the numpy engine's track ids the same."""
    from radarviz.viz_app.bench.association import bench_rotating

    doc = bench_rotating(12, duration_s=30.0, reference=True)
    assert (doc["rotating_targets"], doc["rotating_radars"]) == (12, 4)
    assert doc["rotating_plots"] > 12 * 4 and 1.0 <= doc["rotating_plots_per_batch"] < 4.0
    assert doc["rotating_over_labelled"] == pytest.approx(
        doc["rotating_labelled_plots_per_cpu_s"] / doc["rotating_plots_per_cpu_s"], rel=1e-12
    )
    assert doc["rotating_same_as_numpy"] and doc["rotating_purity"] > 0.9


def test_a_monitor_sees_the_same_on_both_engines_with_rows_reused() -> None:
    """With a consistency monitor, the compiled engine reuses a deleted track's row (its
    monitor state written to the monitor's records first): every track's figures and the
    events equal the numpy engine's. A monitor that does not ``keep_deleted`` keeps only
    tracks not deleted, with the same figures, and the rows follow the live tracks."""
    sites = radars()
    plots = rotating_scene_plots(sites, scene(7, sites, targets=12, duration_s=90.0))
    monitors: dict[str, ConsistencyMonitor] = {}
    peak_live, rows, longest, started = 0, 0, 0, 0
    for engine, keep in (("numpy", True), ("compiled", True), ("compiled-forgetting", False)):
        monitor = ConsistencyMonitor(keep_deleted=keep)
        options = StreamOptions(model="imm", engine=engine.split("-")[0], monitor=monitor)
        gnn = GNNTracker(("ucm",), False, options, AssociationOptions())
        for b in plot_batches(enumerate(plots), gnn.association.batch_sector_deg):
            gnn.add_batch([p for _, p in b])
            peak_live, longest = max(peak_live, len(gnn.live())), max(longest, len(b))
        monitors[engine] = monitor
        compiled = gnn.tracker._compiled
        if compiled is not None:
            rows, started = len(compiled._labels), gnn.report().started
    ref, got, kept = (monitors[k].results() for k in ("numpy", "compiled", "compiled-forgetting"))
    assert list(ref) == list(got) and len(ref) > len(kept) > 0
    for name, r in ref.items():
        for a, b in ((r, got[name]), *(((r, kept[name]),) if name in kept else ())):
            assert (a.updates, a.windows, a.above, a.below) == (
                b.updates,
                b.windows,
                b.above,
                b.below,
            )
            assert a.mean_nis_per_dof == pytest.approx(b.mean_nis_per_dof, rel=1e-9)
    assert monitors["numpy"].events == monitors["compiled"].events
    # A row serves one live track at a time: at most the live tracks at a batch's end, and
    # the tracks its plots started (each plot starts at most one) before the deleted went.
    assert rows <= peak_live + longest < started
