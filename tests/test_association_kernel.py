"""The association's compiled route (``core.tracking.kernels_associate``) against the Python
route on the numpy engine, the reference: the same track of every plot, the same
confirmations and the same per-radar account, on the layout of real multi-radar data
(rotating radars with staggered phases and periods, partial coverage, P_D < 1, clutter),
batch by batch or many batches in one call; and its assignment against scipy's.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from radarviz.core.experiments.association import rotating_scene_plots
from radarviz.core.scenarios.rotating import RotatingRadar, air_traffic, rotating_plots
from radarviz.core.tracking.association import (
    AssociationOptions,
    GNNTracker,
    ScanResult,
    gnn_assign,
    plot_batches,
    sparse_gnn_assign,
)
from radarviz.core.tracking.consistency import ConsistencyMonitor
from radarviz.core.tracking.coverage import RadarCoverage
from radarviz.core.tracking.kernels_associate import lsap, sparse_assign
from radarviz.core.tracking.stream import Plot, StreamOptions

SITES = ((-40e3, -40e3), (40e3, -40e3), (40e3, 40e3), (-40e3, 40e3))
OPTIONS = StreamOptions(model="imm")


def rotating_scene(seed: int, targets: int, duration_s: float) -> list[Plot]:
    """Four radars of 60 km coverage 113 km apart (periods 4.0–5.1 s, phases staggered),
    P_D 0.85, 8 false plots a turn, en-route traffic with turns: each plot at its beam's
    time."""
    sites = [
        RotatingRadar(
            f"r{j}",
            x,
            y,
            period_s=4.0 + 0.37 * j,
            phase_rad=1.3 * j,
            max_range_m=60e3,
            detection_prob=0.85,
            clutter_per_turn=8.0,
        )
        for j, (x, y) in enumerate(SITES)
    ]
    rng = np.random.default_rng(seed)
    traffic = air_traffic(rng, targets, duration_s, turn_rate_dps=2.0, en_route=True)
    return rotating_scene_plots(sites, rotating_plots(rng, sites, traffic, duration_s))


def batches_of(plots: list[Plot]) -> list[list[Plot]]:
    return [[p for _, p in b] for b in plot_batches(enumerate(plots), 22.5)]


def run(gnn: GNNTracker, batches: list[list[Plot]], per_call: int) -> list[ScanResult]:
    out: list[ScanResult] = []
    for k in range(0, len(batches), per_call):
        if per_call == 1:
            out.append(gnn.add_batch(batches[k]))
        else:
            out += gnn.add_batches(batches[k : k + per_call])
    return out


def summary(gnn: GNNTracker, results: list[ScanResult]) -> tuple:
    return (
        [t for r in results for t in r.track_ids],
        [s for r in results for s in r.statuses],
        [r.confirmed for r in results],
        [r.deleted for r in results],
        gnn.ever_confirmed,
        gnn.report(),
    )


COVERAGE = {"r1": RadarCoverage(rotation_period_s=4.37, max_range_m=55e3)}


@pytest.mark.parametrize("seed", [4, 5])
def test_compiled_route_associates_as_the_numpy_route(seed: int) -> None:
    plots = rotating_scene(seed, targets=60, duration_s=60.0)
    batches = batches_of(plots)
    reference = GNNTracker(
        ("ucm",), False, replace(OPTIONS, engine="numpy"), AssociationOptions(), coverage=COVERAGE
    )
    assert reference._compiled is None  # the Python route
    want = summary(reference, run(reference, batches, 1))
    for per_call in (1, 7, 1000):
        gnn = GNNTracker(("ucm",), False, OPTIONS, AssociationOptions(), coverage=COVERAGE)
        assert gnn._compiled is not None
        got = summary(gnn, run(gnn, batches, per_call))
        assert got == want, per_call
    # The scene asks something of the association: clutter, deletions and many tracks.
    ids, _, _, deleted, confirmed, report = want
    assert len(set(ids)) > 80 and sum(map(len, deleted)) > 10 and len(confirmed) >= 55
    assert report.estimated["r0"]["rotation_period_s"] == pytest.approx(4.0, rel=0.02)
    assert "rotation_period_s" not in report.estimated["r1"]


def capacities(gnn: GNNTracker) -> tuple[int, ...]:
    """The track slots of the arrays that grow with the tracks: the book's, the tracker's
    rows, the live tracks' and the monitor's."""
    c = gnn._compiled
    assert c is not None and c.tracks.feed is not None
    rows = {a.shape[0] for a in c.tracks.feed.arrays.values()}
    assert len(rows) == 1
    return gnn.book.alive.shape[0], c.tracks.started.shape[0], c.live.pos.shape[0], *rows


def test_room_reserved_at_the_start_is_the_room_the_tracks_take() -> None:
    """A tracker given room for its tracks at the start (``GNNTracker.reserve``, as
    ``radarviz live``'s) keeps its arrays at that size through calls that grow another's
    from nothing, and tracks as that one does."""
    plots = rotating_scene(4, targets=60, duration_s=60.0)
    batches = batches_of(plots)

    def made() -> GNNTracker:
        options = replace(OPTIONS, monitor=ConsistencyMonitor(keep_deleted=False))
        return GNNTracker(("ucm",), False, options, AssociationOptions(), coverage=COVERAGE)

    plain = made()
    want = summary(plain, run(plain, batches, 40))
    gnn = made()
    gnn.reserve(256)
    room = capacities(gnn)
    assert room == (256,) * 4
    assert summary(gnn, run(gnn, batches, 40)) == want
    assert capacities(gnn) == room
    # The scene needs the room: up to 142 live tracks and a call's 60 plots.
    assert capacities(plain)[0] > 128


def test_a_tracker_that_does_not_keep_the_confirmed_ids_counts_them() -> None:
    """``keep_confirmed=False`` (``radarviz live``'s): the same tracks and account, the
    number of tracks confirmed, not their ids."""
    plots = rotating_scene(5, targets=40, duration_s=40.0)
    batches = batches_of(plots)
    kept = GNNTracker(("ucm",), False, OPTIONS, AssociationOptions(), coverage=COVERAGE)
    want = summary(kept, run(kept, batches, 7))
    counted = GNNTracker(
        ("ucm",), False, OPTIONS, AssociationOptions(), coverage=COVERAGE, keep_confirmed=False
    )
    got = summary(counted, run(counted, batches, 7))
    assert got[4] == [] and counted.tracks_confirmed == len(want[4]) >= 30
    assert got[:4] + got[5:] == want[:4] + want[5:]
    assert kept.tracks_confirmed == len(kept.ever_confirmed)


def test_compiled_route_gives_the_requested_methods_their_rows() -> None:
    """Every requested method's rows follow the compiled route's assignment, as the
    Python route's on the same engine: the same states."""
    plots = rotating_scene(6, targets=20, duration_s=30.0)
    batches = batches_of(plots)
    methods = ("naive", "ucm", "ekf")
    python = GNNTracker(methods, False, OPTIONS, AssociationOptions())
    python._compiled = None  # the Python route, on the compiled engine
    compiled = GNNTracker(methods, False, OPTIONS, AssociationOptions())
    a, b = run(python, batches, 1), run(compiled, batches, 50)
    assert [r.track_ids for r in a] == [r.track_ids for r in b]
    for ra, rb in zip(a, b, strict=True):
        for pa, pb in zip(ra.rows, rb.rows, strict=True):
            for (ma, xa, Pa), (mb, xb, Pb) in zip(pa, pb, strict=True):
                assert ma == mb
                np.testing.assert_allclose(xb, xa, rtol=1e-9, atol=1e-9)
                np.testing.assert_allclose(Pb, Pa, rtol=1e-9, atol=1e-9)


def test_whole_scans_and_measured_periods_take_the_same_route() -> None:
    """A scan-stamped radar's whole scans (``add_scan``) and a feed's measured periods."""
    plots = rotating_scene(7, targets=25, duration_s=40.0)
    stamped = [replace(p, time_s=float(np.floor(p.time_s / 4.0) * 4.0)) for p in plots]
    stamped.sort(key=lambda p: (p.time_s, p.radar))
    scans: list[list[Plot]] = []
    for p in stamped:
        if scans and scans[-1][0].radar == p.radar and scans[-1][0].time_s == p.time_s:
            scans[-1].append(p)
        else:
            scans.append([p])
    numpy = replace(OPTIONS, engine="numpy")
    ref = GNNTracker(("ucm",), False, numpy, AssociationOptions())
    fast = GNNTracker(("ucm",), False, OPTIONS, AssociationOptions())
    a = [ref.add_scan(s) for s in scans]
    b = [fast.add_scan(s) for s in scans]
    assert summary(ref, a) == summary(fast, b)
    batches = batches_of(plots)
    periods = [4.0 + 0.37 * int(b[0].radar[1:]) for b in batches]
    ref = GNNTracker(("ucm",), False, numpy, AssociationOptions())
    fast = GNNTracker(("ucm",), False, OPTIONS, AssociationOptions())
    a = ref.add_batches(batches, periods)
    b = fast.add_batches(batches, periods)
    assert summary(ref, a) == summary(fast, b)
    assert "rotation_period_s" not in fast.report().estimated["r0"]


def test_lsap_is_scipys_assignment() -> None:
    rng = np.random.default_rng(1)
    for _ in range(300):
        nr, nc = rng.integers(1, 9, size=2)
        cost = rng.normal(size=(nr, nc)) * (rng.random((nr, nc)) < 0.7)
        r, c = lsap(cost)
        sr, sc = linear_sum_assignment(cost)
        assert r.tolist() == sr.tolist() and c.tolist() == sc.tolist()


def test_sparse_assign_is_the_components_optimum() -> None:
    rng = np.random.default_rng(2)
    gate = 9.21
    for _ in range(200):
        k, p = rng.integers(1, 12, size=2)
        n = int(rng.integers(1, k * p + 1))
        flat = rng.choice(k * p, size=n, replace=False)
        rows, cols = (flat // p).astype(np.int64), (flat % p).astype(np.int64)
        d2 = rng.uniform(0.0, 12.0, size=n)
        out_r, out_c = np.empty(n, np.int64), np.empty(n, np.int64)
        m = sparse_assign(rows, cols, d2, gate, int(k), int(p), out_r, out_c)
        # The dense matrix's optimum (scipy's assignment): the same objective; a pair at
        # most once per track and per plot, every pair inside the gate.
        dense = np.full((int(k), int(p)), np.inf)
        dense[rows, cols] = d2
        want_r, want_c = gnn_assign(dense, gate)
        got_r, got_c = out_r[:m], out_c[:m]
        assert np.unique(got_r).size == m and np.unique(got_c).size == m
        assert np.all(dense[got_r, got_c] < gate)
        got, want = np.sum(dense[got_r, got_c] - gate), np.sum(dense[want_r, want_c] - gate)
        assert got == pytest.approx(want, rel=1e-12, abs=1e-12)  # the sums' order only
        r2, c2 = sparse_gnn_assign(rows, cols, d2, gate, (int(k), int(p)))
        assert sorted(zip(r2.tolist(), c2.tolist(), strict=True)) == sorted(
            zip(got_r.tolist(), got_c.tolist(), strict=True)
        )


@pytest.mark.parametrize("sigma_beta_deg", [0.15, 0.5])
def test_the_sweeps_skip_judges_as_testing_every_track(sigma_beta_deg: float) -> None:
    """The compiled sweep tests a track only from its bound on when the beam can pass it
    (``kernels_associate._due``); with a model tolerance no batch meets (a new beam model
    at every batch, every track tested at every batch) the same misses follow: the same
    tracks, statuses, expected detections and judgement times. At σβ 0.5° the plots' own
    azimuths stray from the beam model more, and new models start more often."""
    sites = [
        RotatingRadar(
            f"r{j}", x, y, period_s=4.0 + 0.37 * j, phase_rad=1.3 * j, max_range_m=60e3,
            sigma_beta_rad=np.radians(sigma_beta_deg), detection_prob=0.85,
            clutter_per_turn=8.0, clockwise=j != 2,
        )
        for j, (x, y) in enumerate(SITES)
    ]  # fmt: skip
    rng = np.random.default_rng(11)
    traffic = air_traffic(rng, 200, 50.0, turn_rate_dps=2.0, en_route=True)
    batches = batches_of(rotating_scene_plots(sites, rotating_plots(rng, sites, traffic, 50.0)))
    gnns = [GNNTracker(("ucm",), False, OPTIONS, AssociationOptions()) for _ in range(2)]
    every = gnns[1]._compiled
    assert every is not None
    every.rules = every.rules._replace(model_tolerance_rad=-1.0)
    results = [run(gnn, batches, 500) for gnn in gnns]
    assert summary(gnns[0], results[0]) == summary(gnns[1], results[1])
    a, b = gnns[0].book, gnns[1].book
    live = a.live_slots()
    assert np.array_equal(live, b.live_slots()) and live.size > 150
    for name in ("hits", "expected", "misses", "judged_s", "hit_s"):
        assert np.array_equal(getattr(a, name)[live], getattr(b, name)[live]), name
    # The skip was in force: most live tracks' bounds lie ahead of the last batch.
    end = batches[-1][-1].time_s
    skip = gnns[0]._compiled
    assert skip is not None
    used = skip.live.slot[: skip.counters[0]]  # the live positions, holes (−1) included
    assert np.array_equal(used[used >= 0], live)  # in order of initiation
    assert np.mean(skip.live.due_s[:, : used.size][:, used >= 0] > end) > 0.5
