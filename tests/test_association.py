"""Association of unlabelled plots (``core.tracking.association``), GOSPA and the track counts
(``core.tracking.gospa``), the crossing scene (``core.scenarios.crossing``), ``track
--associate gnn``, ``simulate --preset crossing`` and ``reproduce association``.

* GOSPA equals an independent brute force over every partial assignment of small sets (any
  c, p), its parts add up, and hand cases give the closed forms.
* The GNN assignment equals a brute force over every partial assignment of a small gated
  matrix; the broadcast d² matrix equals a pair-by-pair EKF innovation written out here
  (finite-difference Jacobian), and the converted methods' pair by pair.
* The gate's d² of a track's plot equals the NIS its update then reports (cv and IMM, converted
  and polar methods): ``TargetTracker.predicted`` is the step's own prediction. A forgotten
  track's row goes to a fresh track; the others are untouched.
* Hand-built scans: two well separated targets keep ids "1" and "2"; a gated-out plot starts a
  tentative track that dies exactly when M of N has become impossible; confirmation at the
  M-th hit, to the scan; a confirmed track dies after ``delete_misses`` misses, to the scan.
* The scene: false plots per scan Poisson with mean λ, detections with frequency P_D (to
  within 4 Monte Carlo standard errors), every plot in the region, the paths crossing at the
  middle scan at the angle asked.
* End to end: ``simulate --preset crossing`` then ``track --associate gnn``: few confirmed
  tracks, each target's track id stable away from the crossing, every method's rows of a plot
  under the same track id; the Rerun recording has every track, drawn by its status (tentative
  rows faint, deleted tracks cleared at their scan), against the tracker's own account.
* Bad input: one line naming the flag and its range, exit 2, nothing written.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from radarviz.core.filters.methods import PolarNoise, PolarPlot
from radarviz.core.filters.predict import cv_predict
from radarviz.core.filters.state import CVBatch
from radarviz.core.params import ParameterError
from radarviz.core.scenarios.crossing import CLUTTER, CrossingScene, crossing_scans
from radarviz.core.tracking.association import (
    CONFIRMED,
    TENTATIVE,
    AssociationOptions,
    GNNTracker,
    gate_box_pairs,
    gate_threshold,
    gnn_assign,
    mahalanobis_matrix,
    mahalanobis_pairs,
    plot_batches,
    scan_groups,
    sparse_gnn_assign,
)
from radarviz.core.tracking.gospa import TrackCounter, gospa
from radarviz.core.tracking.stream import Plot, StreamOptions
from radarviz.viz_app.cli.main import main

SIGMA_R, SIGMA_B = 50.0, math.radians(0.3)


# ------------------------------------------------------------------------------------------
# GOSPA
# ------------------------------------------------------------------------------------------


def brute_gospa(X: np.ndarray, Y: np.ndarray, c: float, p: float) -> float:
    """min over every partial injection γ of Σ_γ min(d, c)^p + c^p/2 (m + n − 2|γ|), written
    from the definition (García-Fernández et al. 2017, eq. 1 with α = 2)."""
    m, n = len(X), len(Y)
    best = math.inf
    for k in range(min(m, n) + 1):
        for rows in itertools.combinations(range(m), k):
            for cols in itertools.permutations(range(n), k):
                s = sum(
                    min(float(np.linalg.norm(X[i] - Y[j])), c) ** p
                    for i, j in zip(rows, cols, strict=True)
                )
                best = min(best, s + c**p / 2 * (m + n - 2 * k))
    return best ** (1 / p)


@pytest.mark.parametrize("seed", range(40))
def test_gospa_equals_the_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    m, n = rng.integers(0, 5, size=2)
    X, Y = rng.uniform(0, 10, (m, 2)), rng.uniform(0, 10, (n, 2))
    c, p = float(rng.uniform(0.5, 6)), float(rng.choice([1.0, 2.0, 3.5]))
    g = gospa(X, Y, c, p)
    assert g.distance == pytest.approx(brute_gospa(X, Y, c, p), rel=1e-12, abs=1e-12)
    assert g.distance**p == pytest.approx(g.localisation + g.missed + g.false, rel=1e-12)
    k = len(g.assigned)
    assert g.missed == pytest.approx(c**p / 2 * (m - k))
    assert g.false == pytest.approx(c**p / 2 * (n - k))
    for i, j in g.assigned:
        assert np.linalg.norm(X[i] - Y[j]) < c


def test_gospa_hand_cases() -> None:
    X = np.array([[0.0, 0.0], [100.0, 0.0]])
    assert gospa(X, X, 10.0).distance == 0.0
    # One target missed: (c²/2)^(1/2); one false track as well: c.
    assert gospa(X, X[:1], 10.0).distance == pytest.approx(10.0 / math.sqrt(2))
    assert gospa(X[:1], [[50.0, 0.0]], 10.0).distance == pytest.approx(10.0)
    # An estimate 3 m off and one 30 m off (beyond c = 10): 3² + c²/2 + c²/2.
    g = gospa(X, [[3.0, 0.0], [130.0, 0.0]], 10.0)
    assert g.distance == pytest.approx(math.sqrt(9.0 + 100.0))
    assert (g.localisation, g.missed, g.false) == pytest.approx((9.0, 50.0, 50.0))
    # p = 1: a pair at d < c costs d; two unassigned points cost c/2 each.
    assert gospa([[0.0, 0.0]], [[4.0, 3.0]], 6.0, 1.0).distance == pytest.approx(5.0)
    assert gospa([], [], 6.0).distance == 0.0


def test_track_counter_counts_swaps_and_false_tracks() -> None:
    c = TrackCounter(100.0)
    truth = ["A", "B"]
    # Scans 1-2: A ↔ track 1, B ↔ track 2; scan 3: the tracks cross over (a real swap, both
    # truths switch); a clutter track "9" is reported at every scan and never near a truth.
    for a_track, b_track in (((0, 0), (1000, 0)), ((0, 10), (1000, 10))):
        c.add(truth, [[0, 0], [1000, 0]], ["1", "2", "9"], [a_track, b_track, (5e3, 5e3)])
    assert c.swaps == 0
    c.add(truth, [[0, 0], [1000, 0]], ["1", "2", "9"], [(1000, 0), (0, 0), (5e3, 5e3)])
    assert c.swaps == 2
    assert (c.tracks, c.false_tracks) == (3, 1)
    # Two tracks near one truth: the one it is matched to stays, the optimal assignment's
    # preference for the nearer other track does not count as a swap.
    d = TrackCounter(100.0)
    d.add(["A"], [[0, 0]], ["1", "2"], [(5, 0), (50, 0)])
    d.add(["A"], [[0, 0]], ["1", "2"], [(40, 0), (1, 0)])
    assert d.swaps == 0 and d.false_tracks == 1  # "2" never matched


# ------------------------------------------------------------------------------------------
# The gate and the assignment
# ------------------------------------------------------------------------------------------


def brute_assign(d2: np.ndarray, gate: float) -> float:
    """max Σ (γ − d²) over every partial assignment whose pairs are inside the gate."""
    k, p = d2.shape
    best = 0.0
    for n in range(1, min(k, p) + 1):
        for rows in itertools.combinations(range(k), n):
            for cols in itertools.permutations(range(p), n):
                pairs = [(r, q) for r, q in zip(rows, cols, strict=True) if d2[r, q] < gate]
                best = max(best, sum(gate - d2[r, q] for r, q in pairs))
    return best


@pytest.mark.parametrize("seed", range(30))
def test_gnn_assignment_is_the_global_optimum(seed: int) -> None:
    rng = np.random.default_rng(seed)
    k, p = rng.integers(1, 5, size=2)
    d2 = rng.uniform(0, 20, (k, p))
    gate = 9.21
    rows, cols = gnn_assign(d2, gate)
    assert len(set(rows.tolist())) == len(rows) and len(set(cols.tolist())) == len(cols)
    assert np.all(d2[rows, cols] < gate)
    assert float((gate - d2[rows, cols]).sum()) == pytest.approx(brute_assign(d2, gate))


def test_gnn_is_global_not_greedy() -> None:
    # Greedy would give plot 0 to track 0 (d² 1) and leave track 1 with nothing in its gate;
    # the global optimum gives plot 0 to track 1 and plot 1 to track 0.
    d2 = np.array([[1.0, 2.0], [1.5, np.inf]])
    rows, cols = gnn_assign(d2, 9.0)
    assert sorted(zip(rows.tolist(), cols.tolist(), strict=True)) == [(0, 1), (1, 0)]
    assert gate_threshold(0.99, 2) == pytest.approx(-2 * math.log(0.01))  # χ²(2): closed form


def ekf_d2(x: np.ndarray, P: np.ndarray, r: float, b: float, site: np.ndarray) -> float:
    """νᵀ S⁻¹ ν of one polar plot, written out: h(x) = (|p − s|, atan2), H by central
    differences, S = H P Hᵀ + diag(σr², σβ²)."""

    def h(state: np.ndarray) -> np.ndarray:
        dx, dy = state[0] - site[0], state[2] - site[1]
        return np.array([math.hypot(dx, dy), math.atan2(dy, dx)])

    H = np.zeros((2, 4))
    for i in range(4):
        e = np.zeros(4)
        e[i] = 1e-3
        H[:, i] = (h(x + e) - h(x - e)) / 2e-3
    nu = np.array([r, b]) - h(x)
    nu[1] = (nu[1] + math.pi) % (2 * math.pi) - math.pi
    S = H @ P @ H.T + np.diag([SIGMA_R**2, SIGMA_B**2])
    return float(nu @ np.linalg.solve(S, nu))


@pytest.mark.parametrize("method", ["ekf", "ukf", "ucm", "ducm", "naive"])
def test_distance_matrix_equals_pair_by_pair(method: str) -> None:
    rng = np.random.default_rng(5)
    k, p = 3, 4
    x = np.stack([rng.uniform(2e4, 4e4, k), rng.normal(0, 200, k)], -1)
    x = np.stack([x[:, 0], x[:, 1], rng.uniform(-1e4, 1e4, k), rng.normal(0, 200, k)], -1)
    A = rng.normal(size=(k, 4, 4))
    P = A @ A.mT * np.array([1e4, 1e2, 1e4, 1e2])[:, None] + np.eye(4) * 1e3
    P = 0.5 * (P + P.mT)
    r = rng.uniform(2e4, 4e4, p)
    b = rng.uniform(-0.3, 0.3, p)
    site = rng.uniform(-1e3, 1e3, (p, 2))
    noise = PolarNoise(np.full(p, SIGMA_R), np.full(p, SIGMA_B))
    d2 = mahalanobis_matrix(method, CVBatch(x, P), PolarPlot(r, b), noise, site)
    assert d2.shape == (k, p)
    for i in range(k):
        for j in range(p):
            one = mahalanobis_matrix(
                method,
                CVBatch(x[i : i + 1], P[i : i + 1]),
                PolarPlot(r[j : j + 1], b[j : j + 1]),
                PolarNoise(noise.sigma_r_m[j : j + 1], noise.sigma_beta_rad[j : j + 1]),
                site[j : j + 1],
            )[0, 0]
            assert d2[i, j] == pytest.approx(one, rel=1e-10)
            if method in ("ekf", "ukf"):  # the polar innovation, written out independently
                assert d2[i, j] == pytest.approx(ekf_d2(x[i], P[i], r[j], b[j], site[j]), rel=1e-5)


# ------------------------------------------------------------------------------------------
# Hand-built scans
# ------------------------------------------------------------------------------------------


def polar(x: float, y: float) -> tuple[float, float]:
    return math.hypot(x, y), math.atan2(y, x)


def plot_at(t: float, x: float, y: float) -> Plot:
    r, b = polar(x, y)
    return Plot(t, r, b, SIGMA_R, SIGMA_B, radar="radar")


def tracker(**kw: object) -> GNNTracker:
    options = StreamOptions(model="cv", sigma_a_mps2=1.0, sigma_v0_mps=300.0)
    return GNNTracker(("ucm", "ekf"), False, options, AssociationOptions(**kw))


def target(k: int, y0: float) -> tuple[float, float]:
    """A target at (30 km, y0) flying +x at 200 m/s, at scan k (T = 5 s), no noise."""
    return 3e4 + 1000.0 * k, y0


def test_two_separated_targets_keep_their_ids() -> None:
    gnn = tracker()
    for k in range(12):
        scan = [plot_at(5.0 * k, *target(k, 0.0)), plot_at(5.0 * k, *target(k, 8e3))]
        if k % 2:
            scan.reverse()  # the order within a scan tells nothing
        res = gnn.add_scan(scan)
        ids = dict(zip([p.range_m for p in scan], res.track_ids, strict=True))
        assert ids[scan[0].range_m] == ("1" if k % 2 == 0 else "2")
        assert res.statuses == [CONFIRMED if k >= 2 else TENTATIVE] * 2
        # Every method's rows of a plot follow the one assignment.
        assert [[m for m, *_ in rows] for rows in res.rows] == [["ucm", "ekf"]] * 2
    assert gnn.live(CONFIRMED) == ["1", "2"] and gnn.ever_confirmed == ["1", "2"]


def test_gated_out_plot_starts_a_tentative_track_that_dies() -> None:
    gnn = tracker(confirm_m=3, confirm_n=4)
    for k in range(5):
        gnn.add_scan([plot_at(5.0 * k, *target(k, 0.0))])
    assert gnn.live() == ["1"]
    # A plot 20 km off the track: far outside its gate, it starts track "2".
    res = gnn.add_scan([plot_at(25.0, *target(5, 0.0)), plot_at(25.0, 3e4, 2e4)])
    assert res.track_ids == ["1", "2"] and res.statuses == [CONFIRMED, TENTATIVE]
    # Missed at the next scan: 1 hit + 2 scans left can still reach M = 3; missed again:
    # 1 + 1 < 3, deleted at exactly that scan.
    res = gnn.add_scan([plot_at(30.0, *target(6, 0.0))])
    assert res.deleted == [] and gnn.live() == ["1", "2"]
    res = gnn.add_scan([plot_at(35.0, *target(7, 0.0))])
    assert res.deleted == ["2"] and gnn.live() == ["1"]


@pytest.mark.parametrize(
    ("hits", "confirmed_at", "deleted_at"),
    [
        ((0, 1, 2), 2, None),  # M = 3 hits in a row: confirmed at the third scan
        ((0, 2, 3), 3, None),  # a miss in between: at the fourth, the last chance
        ((0, 1, 3), 3, None),
        ((0, 3), None, 2),  # two misses: 1 + 1 < 3 after the third scan
        ((0, 1), None, 3),  # hits at 1, 2, then misses: 2 + 0 < 3 after the fourth
    ],
)
def test_m_of_n_confirmation_timing(
    hits: tuple[int, ...], confirmed_at: int | None, deleted_at: int | None
) -> None:
    gnn = tracker(confirm_m=3, confirm_n=4)  # a confirmed track's 3 misses come after scan 4
    for k in range(5):
        scan = [plot_at(5.0 * k, *target(k, 0.0))] if k in hits else []
        res = gnn.add_scan(scan)
        assert res.confirmed == (["1"] if k == confirmed_at else []), k
        assert res.deleted == (["1"] if k == deleted_at else []), k


def test_confirmed_track_dies_after_its_misses() -> None:
    gnn = tracker(confirm_m=2, confirm_n=3, delete_misses=4)
    for k in range(3):
        gnn.add_scan([plot_at(5.0 * k, *target(k, 0.0))])
    assert gnn.live(CONFIRMED) == ["1"]
    for k in range(3, 7):
        res = gnn.add_scan([])
        assert res.deleted == (["1"] if k == 6 else []), k


def test_scans_are_runs_of_one_radar_within_the_window() -> None:
    def p(t: float, radar: str) -> tuple[int, Plot]:
        return 0, Plot(t, 1e4, 0.0, SIGMA_R, SIGMA_B, radar=radar)

    items = [p(0, "a"), p(0, "a"), p(0, "b"), p(1, "b"), p(1, "a"), p(3, "a")]
    sizes = [len(s) for s in scan_groups(items, 0.0)]
    assert sizes == [2, 1, 1, 1, 1]
    assert [len(s) for s in scan_groups(items, 2.0)] == [2, 2, 2]


class NISLog:
    """A stand-in consistency monitor that keeps every NIS it is given."""

    def __init__(self) -> None:
        self.values: dict[str, list[float]] = {}

    def add(self, track: str, time_s: float, nis: float, dof: int) -> None:
        self.values.setdefault(track, []).append(nis)


@pytest.mark.parametrize("model", ["cv", "imm"])
@pytest.mark.parametrize("method", ["ucm", "ducm", "ekf", "ukf"])
def test_gate_d2_is_the_updates_nis(model: str, method: str) -> None:
    """The d² of a track's plot before the scan (``predicted``: the prediction to the plot's
    time, for the IMM the mixed models predicted and combined) equals the NIS the update then
    reports to the consistency monitor (``cv_step`` / ``imm_step``'s own statistics). Two
    radars take turns (one off the origin), and within a scan (window 1 s) the second
    target's plot is 0.5 s after the first's: each pair is predicted to its plot's own time."""
    log = NISLog()
    options = StreamOptions(model=model, sigma_a_mps2=2.0, sigma_v0_mps=300.0, monitor=log)
    gnn = GNNTracker((method,), False, options, AssociationOptions(method=method, scan_window_s=1))
    rng = np.random.default_rng(1)
    sites = {"a": (0.0, 0.0, 0.0), "b": (1e4, -2e4, 0.0)}
    gates = []
    for k in range(8):
        radar = "ab"[k % 2]
        sx, sy, _ = sites[radar]
        scan = []
        for y0, dt in ((0.0, 0.0), (9e3, 0.5)):
            x, y = target(k, y0)
            r, b = polar(x - sx, y - sy)
            r += 50 * rng.standard_normal()
            b += SIGMA_B * rng.standard_normal()
            scan.append(Plot(5.0 * k + dt, r, b, SIGMA_R, SIGMA_B, sites[radar], radar))
        if k:
            gates.append(np.diag(gnn.distances(["1", "2"], scan)))
        assert [len(s) for s in scan_groups([(0, p) for p in scan], 1.0)] == [2]
        assert gnn.add_scan(scan).track_ids == ["1", "2"]
    nis = np.array([log.values[f"{t}/{method}"] for t in ("1", "2")]).T
    assert np.allclose(np.array(gates), nis, rtol=1e-9, atol=1e-12)


def test_three_d_targets_keep_their_ids() -> None:
    """3D plots (elevation): the gate is χ²(3) and two separated targets keep their ids."""
    options = StreamOptions(model="cv", sigma_a_mps2=1.0, sigma_v0_mps=300.0)
    gnn = GNNTracker(("ucm", "ekf"), True, options, AssociationOptions())
    assert gnn.gate == pytest.approx(gate_threshold(0.999, 3))
    se = math.radians(0.3)
    for k in range(6):
        scan = []
        for y0, z in ((0.0, 3e3), (8e3, 9e3)):
            x, y = target(k, y0)
            ground = math.hypot(x, y)
            r, el = math.hypot(ground, z), math.atan2(z, ground)
            scan.append(
                Plot(
                    5.0 * k,
                    r,
                    math.atan2(y, x),
                    SIGMA_R,
                    SIGMA_B,
                    radar="radar",
                    elevation_rad=el,
                    sigma_elevation_rad=se,
                )
            )
        res = gnn.add_scan(scan[::-1] if k % 2 else scan)
        assert res.track_ids == (["2", "1"] if k % 2 else ["1", "2"])
    assert gnn.live(CONFIRMED) == ["1", "2"]
    with pytest.raises(ParameterError, match="every plot of a 3D track needs an elevation"):
        gnn.add_scan([plot_at(30.0, *target(6, 0.0))])


def test_forgotten_rows_are_reused_by_fresh_tracks() -> None:
    """``TargetTracker.forget``: a new target takes a forgotten row and starts afresh; the
    other targets' tracks are untouched (equal to a tracker that never forgot)."""
    from radarviz.core.tracking.targets import TargetTracker

    # The numpy engine's banks (the compiled engine's forget: tests/test_association_engines.py).
    options = StreamOptions(model="cv", sigma_a_mps2=1.0, engine="numpy")
    a, b = TargetTracker(("ucm", "ekf"), False, options), TargetTracker(("ucm",), False, options)
    c = TargetTracker(("ucm", "ekf"), False, options)
    for k in range(4):
        p, q = plot_at(5.0 * k, *target(k, 0.0)), plot_at(5.0 * k, *target(k, 5e3))
        a.add_block([replace(p, target="x"), replace(q, target="y")])
        c.add_block([replace(p, target="x")])
    a.forget(["y"])
    p, q = plot_at(20.0, *target(4, 0.0)), plot_at(20.0, *target(4, -5e3))
    rows = a.add_block([replace(p, target="x"), replace(q, target="z")])
    fresh = b.add_block([replace(q, target="z")])[0]
    assert a.targets == ("x", "z") and a._rows_used == 2
    assert np.array_equal(rows[1][0][1], fresh[0][1]) and np.array_equal(rows[1][0][2], fresh[0][2])
    ref = c.add_block([replace(p, target="x")])[0]
    for (m1, x1, P1), (m2, x2, P2) in zip(rows[0], ref, strict=True):
        assert m1 == m2 and np.array_equal(x1, x2) and np.array_equal(P1, P2)


def test_track_recording_has_every_track(tmp_path: Path, rrd_contents) -> None:
    m, r, _ = simulate(tmp_path, "--clutter-per-scan", "1", "--scans", "12")
    out, rrd = tmp_path / "t.csv", tmp_path / "t.rrd"
    argv = ["track", "--input", str(m), "--radars", str(r), "--out", str(out), "--rrd", str(rrd)]
    assert main([*argv, "--associate", "gnn", "--method", "ucm"]) == 0
    with out.open() as fh:
        ids = {row["target"] for row in csv.DictReader(fh)}
    with out.open() as fh:
        confirmed = {row["target"] for row in csv.DictReader(fh) if row["status"] == CONFIRMED}
    rows, _ = rrd_contents(rrd)
    # /world/tracks/{id}/{method}/position, one entity per confirmed track (and
    # /world/tracks/{id} the clear of a deleted one); the tentative ones share
    # /world/tentative/{method}.
    parts = [p.split("/") for p in rows if p.startswith("/world/tracks/")]
    recorded = {q[3] for q in parts}
    assert {q[4] for q in parts if len(q) > 4} == {"ucm"}
    assert len(confirmed) >= 2 and recorded == confirmed, (confirmed, sorted(rows)[:20])
    assert len(ids - confirmed) >= 1 and "/world/tentative/ucm/position" in rows


def _packed(rgb: tuple[int, int, int]) -> int:
    """Rerun's colour component: 0xRRGGBBAA."""
    return (rgb[0] << 24) | (rgb[1] << 16) | (rgb[2] << 8) | 0xFF


def test_track_recording_draws_the_status(tmp_path: Path, rrd_contents) -> None:
    """The association's recording against the tracker's own account of the same plots
    (``GNNTracker.add_batch`` batch by batch): a confirmed track's rows from its confirmation
    on in its own entities, bright; each scan's tentative rows as one faint row per method; a
    recursive clear of exactly the deleted confirmed tracks at the last plot of the scan that
    deleted them, paths and time series for confirmed tracks only, and each scan's plots as
    one row per status."""
    from radarviz.viz_app.io.plots import PlotReader, load_radars
    from radarviz.viz_app.palette import rgb
    from radarviz.viz_app.rerun.shapes import faint

    m, r, _ = simulate(tmp_path, "--clutter-per-scan", "2", "--scans", "12")
    out, rrd = tmp_path / "t.csv", tmp_path / "t.rrd"
    argv = ["track", "--input", str(m), "--radars", str(r), "--out", str(out), "--rrd", str(rrd)]
    model = ["--model", "cv", "--sigma-a", "1"]
    assert main([*argv, "--associate", "gnn", "--method", "ucm", "ekf", *model]) == 0

    reader = PlotReader(m.read_text().splitlines(), str(m), load_radars(str(r)))
    gnn = GNNTracker(
        ("ucm", "ekf"), False, StreamOptions(model="cv", sigma_a_mps2=1.0), AssociationOptions()
    )
    ids: list[str] = []
    statuses: list[str] = []
    deleted: dict[str, int] = {}  # id → the plot (1, 2, …) ending the scan that deleted it
    scans: list[list[str]] = []
    for scan in plot_batches(reader, AssociationOptions().batch_sector_deg):
        res = gnn.add_batch([p for _, p in scan])
        ids += res.track_ids
        statuses += res.statuses
        scans.append(res.statuses)
        deleted.update((t, len(ids)) for t in res.deleted)
    with out.open() as fh:
        file_rows = list(csv.DictReader(fh))
    # The same run: one row per plot and method, the same ids and statuses.
    for method in ("ucm", "ekf"):
        got = [(row["target"], row["status"]) for row in file_rows if row["method"] == method]
        assert got == list(zip(ids, statuses, strict=True))
    confirmed = {t for t, s in zip(ids, statuses, strict=True) if s == CONFIRMED}
    never = set(ids) - confirmed
    assert len(confirmed) >= 2 and len(never) >= 5 and len(deleted) >= 5

    rows, cols = rrd_contents(rrd)
    assert not any(p.startswith("/world/tracks/") and p.split("/")[3] in never for p in rows)
    scan_first = list(itertools.accumulate([1] + [len(s) for s in scans[:-1]]))
    for method in ("ucm", "ekf"):
        bright, dim = _packed(rgb(method)), _packed(faint(rgb(method)))
        assert bright != dim
        for t in confirmed:
            c = cols[f"/world/tracks/{t}/{method}/position"]
            mine = [n + 1 for n, (u, s) in enumerate(zip(ids, statuses, strict=True)) if u == t]
            assert c["plot"] == [n for n in mine if statuses[n - 1] == CONFIRMED], (t, method)
            assert {x[0] for x in c["Points3D:colors"]} == {bright}
            ellipsoids = cols[f"/world/tracks/{t}/{method}/covariance"]["Ellipsoids3D:colors"]
            assert {x[0] for x in ellipsoids} == {bright}
        # One row per scan at its first plot, holding the scan's tentative rows, all faint.
        for part, kind in (("position", "Points3D"), ("covariance", "Ellipsoids3D")):
            c = cols[f"/world/tentative/{method}/{part}"]
            assert c["plot"] == scan_first
            assert [len(x) for x in c[f"{kind}:colors"]] == [s.count(TENTATIVE) for s in scans]
            assert {x for row in c[f"{kind}:colors"] for x in row} == {dim}
    clears = {
        p.split("/")[3]: c
        for p, c in cols.items()
        if p.count("/") == 3 and p.startswith("/world/tracks/")
    }
    want_clears = {t: [n] for t, n in deleted.items() if t in confirmed}
    assert {t: c["plot"] for t, c in clears.items()} == want_clears
    assert len(deleted.keys() - confirmed) >= 5  # tentative tracks died: no clear of theirs
    assert all(c["Clear:is_recursive"] == [[True]] for c in clears.values())
    paths = {tuple(p.split("/")[3:5]) for p in rows if "/path/" in p}
    assert paths == set(itertools.product(confirmed, ("ucm", "ekf")))
    series = {tuple(p.split("/")[3:5]) for p in rows if p.startswith("/plots/sigma_pos_m/")}
    assert series == paths
    for t in confirmed:
        n_confirmed = sum(u == t and s == CONFIRMED for u, s in zip(ids, statuses, strict=True))
        assert rows[f"/plots/sigma_pos_m/{t}/ekf"] == n_confirmed
    plot_colour = {CONFIRMED: rgb("measurement"), TENTATIVE: faint(rgb("measurement"))}
    for status in (CONFIRMED, TENTATIVE):
        c = cols[f"/world/measurements/radar/{status}"]
        assert [len(x) for x in c["Points3D:positions"]] == [s.count(status) for s in scans]
        assert {x for row in c["Points3D:colors"] for x in row} == {_packed(plot_colour[status])}
    assert rows.get("/world/measurements/radar") is None  # plots are under their status only


def test_api_recording_of_associated_tracks_is_the_commands(tmp_path: Path, rrd_contents) -> None:
    """``radarviz.record(track_file(..., association=...))`` writes the recording of ``track
    --associate gnn --rrd`` on the same file: the same entities, every row's time, position,
    colour and radius, and the same recursive clears (the row ids aside, which are unique
    per write). The log may differ only by the command's NIS band exits (``record`` has no
    monitor)."""
    import radarviz
    from radarviz.viz_app.rerun.track_recording import STATUS_LEGEND

    m, r, _ = simulate(tmp_path, "--clutter-per-scan", "2")
    out, cli_rrd = tmp_path / "t.csv", tmp_path / "cli.rrd"
    argv = ["track", "--input", str(m), "--radars", str(r), "--out", str(out)]
    flags = ["--associate", "gnn", "--method", "ucm", "ekf", "--model", "cv", "--sigma-a", "1"]
    assert main([*argv, "--rrd", str(cli_rrd), *flags]) == 0
    tracks = radarviz.track_file(
        str(m), str(r), ["ucm", "ekf"], sigma_a_mps2=1.0, association=AssociationOptions()
    )
    assert tracks.scans[-1].plots == len(tracks.plots)
    api_rrd = radarviz.record(tracks, tmp_path / "api.rrd")

    cli_rows, cli_cols = rrd_contents(cli_rrd)
    api_rows, api_cols = rrd_contents(api_rrd)
    # Not a vacuous equality: the scene has deleted tracks, their clears and faint rows.
    clears = [p for p in cli_rows if p.count("/") == 3 and p.startswith("/world/tracks/")]
    deleted = {t for s in tracks.scans for t in s.deleted}
    confirmed = {s.target for s in tracks.steps if s.status == CONFIRMED}
    assert len(deleted) >= 5 and {p.split("/")[3] for p in clears} == deleted & confirmed
    assert "/world/measurements/radar/tentative" in cli_rows
    assert "/world/tentative/ucm/position" in cli_rows
    assert set(api_rows) == set(cli_rows)
    for entity in cli_rows:
        if entity == "/log":
            continue
        assert api_rows[entity] == cli_rows[entity], entity
        want = {k: v for k, v in cli_cols[entity].items() if not k.endswith("RowId")}
        got = {k: v for k, v in api_cols[entity].items() if not k.endswith("RowId")}
        assert got == want, entity
    cli_log, api_log = cli_cols["/log"]["TextLog:text"], api_cols["/log"]["TextLog:text"]
    assert api_log[0] == [STATUS_LEGEND] and api_log[0] == cli_log[0]
    assert api_log[-1] == cli_log[-1]  # the summary line
    # Every line is on both timelines: the log view lists only the active timeline's lines.
    for log in (cli_cols["/log"], api_cols["/log"]):
        assert len(log["plot"]) == len(log["time"]) == len(log["TextLog:text"])
        assert None not in log["plot"] and None not in log["time"]


# ------------------------------------------------------------------------------------------
# The crossing scene
# ------------------------------------------------------------------------------------------


def test_crossing_scene_statistics() -> None:
    scene = CrossingScene(
        targets=3, crossing_angle_deg=25.0, detection_prob=0.8, clutter_per_scan=4.0, scans=40
    )
    truth = scene.truth()
    mid = (scene.scans - 1) / 2
    # Every path passes through the crossing point at the middle time (between scans 19, 20).
    centre = 0.5 * (truth[19, :, [0, 2]] + truth[20, :, [0, 2]])
    assert np.allclose(centre.T, [scene.crossing_range_m, 0.0], atol=1e-6)
    assert mid == 19.5
    v = truth[0, :, [1, 3]].T
    ang = np.degrees(np.arctan2(v[:, 1], v[:, 0])) % 360.0  # headings about 180°
    assert np.diff(np.sort(ang)) == pytest.approx([25.0, 25.0])
    rng = np.random.default_rng(2)
    runs = [crossing_scans(scene, rng) for _ in range(25)]
    scans = [s for run in runs for s in run]
    clutter = np.array([np.sum(s.origin == CLUTTER) for s in scans])
    detected = np.array([np.sum(s.origin >= 0) for s in scans])
    n = len(scans)
    # Poisson(λ): mean λ, standard error √(λ/n); Bernoulli(P_D): √(P_D(1−P_D)/(3n)).
    assert abs(clutter.mean() - 4.0) < 4 * math.sqrt(4.0 / n)
    assert abs(clutter.var(ddof=1) - 4.0) < 4 * math.sqrt((4.0 + 2 * 16.0) / n)
    assert abs(detected.mean() / 3 - 0.8) < 4 * math.sqrt(0.8 * 0.2 / (3 * n))
    r_lo, r_hi, b_lo, b_hi = scene.region()
    for s in scans:
        c = s.origin == CLUTTER
        assert np.all((s.range_m[c] >= r_lo) & (s.range_m[c] <= r_hi))
        assert np.all((s.azimuth_rad[c] >= b_lo) & (s.azimuth_rad[c] <= b_hi))


# ------------------------------------------------------------------------------------------
# The command line
# ------------------------------------------------------------------------------------------


def simulate(tmp_path: Path, *extra: str) -> tuple[Path, Path, Path]:
    m, r, t = tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "truth.csv"
    argv = ["simulate", "--preset", "crossing", "--out", str(m), "--radars-out", str(r)]
    assert main([*argv, "--truth-out", str(t), "--scans", "30", *extra]) == 0
    return m, r, t


def test_track_associate_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    m, r, t = simulate(tmp_path, "--clutter-per-scan", "2", "--crossing-angle-deg", "30")
    with m.open() as fh:
        assert "target" not in next(csv.reader(fh))
    out = tmp_path / "tracks.csv"
    argv = ["track", "--input", str(m), "--radars", str(r), "--out", str(out)]
    assert (
        main(
            [
                *argv,
                "--associate",
                "gnn",
                "--method",
                "ucm",
                "ekf",
                "--model",
                "cv",
                "--sigma-a",
                "1",
                "--sigma-v0",
                "300",
            ]
        )
        == 0
    )
    assert "confirmed tracks (gnn, gate ucm)" in capsys.readouterr().out
    with out.open() as fh:
        rows = list(csv.DictReader(fh))
    # Every plot's two rows (ucm, ekf) carry one track id and status.
    assert [row["method"] for row in rows[:4]] == ["ucm", "ekf", "ucm", "ekf"]
    for a, b in zip(rows[::2], rows[1::2], strict=True):
        assert (a["time_s"], a["target"], a["status"]) == (b["time_s"], b["target"], b["status"])
    confirmed = {row["target"] for row in rows if row["status"] == "confirmed"}
    assert 2 <= len(confirmed) <= 4
    with t.open() as fh:
        truth = list(csv.DictReader(fh))
    # Each target's nearest confirmed ucm track, scan by scan, away from the crossing (scans
    # 5-11 and 18-29 of 30; the crossing is at 14.5): one id per stretch, a different one for
    # each target.
    est: dict[float, list[tuple[str, float, float]]] = {}
    for row in rows:
        if row["status"] == "confirmed" and row["method"] == "ucm":
            est.setdefault(float(row["time_s"]), []).append(
                (row["target"], float(row["x_m"]), float(row["y_m"]))
            )
    for stretch in (range(5, 12), range(18, 30)):
        ids: dict[str, set[str]] = {}
        for tr in truth:
            k = round(float(tr["time_s"]) / 5.0)
            if k not in stretch or float(tr["time_s"]) not in est:
                continue
            x, y = float(tr["x_m"]), float(tr["y_m"])
            tid, ex, ey = min(
                est[float(tr["time_s"])], key=lambda e: math.hypot(e[1] - x, e[2] - y)
            )
            if math.hypot(ex - x, ey - y) < 1000.0:
                ids.setdefault(tr["target"], set()).add(tid)
        assert len(ids) == 2 and all(len(v) == 1 for v in ids.values()), ids
        assert ids["0"] != ids["1"]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (
            ["--associate", "gnn", "--gate-probability", "1.5"],
            "--gate-probability must be a finite number in (0, 1) (got 1.5)",
        ),
        (
            ["--associate", "gnn", "--gate-probability", "0"],
            "--gate-probability must be a finite number in (0, 1) (got 0.0)",
        ),
        (
            ["--associate", "gnn", "--confirm-m", "5", "--confirm-n", "3"],
            "--confirm-m must be at most confirm_n = 3 (M of N scans; got 5)",
        ),
        (["--associate", "gnn", "--confirm-n", "0"], "--confirm-n must be an integer in [1, 100]"),
        (
            ["--associate", "gnn", "--delete-misses", "0"],
            "--delete-misses must be an integer in [1, 1000]",
        ),
        (
            ["--associate", "gnn", "--scan-window-s", "-1"],
            "--scan-window-s must be a finite number in [0, 3600]",
        ),
        (
            ["--associate", "gnn", "--associate-method", "kalman"],
            "--associate-method must be one of naive, seed, cmkf_d, ucm, ducm, ekf, ukf",
        ),
        (["--associate", "nn"], "--associate must be one of none, gnn (got 'nn')"),
        (
            ["--gate-probability", "0.99"],
            "--gate-probability is the association's; it needs --associate gnn",
        ),
        (["--associate", "gnn", "--init", "finite-memory"], "--init must be first-plot"),
    ],
)
def test_bad_association_flags(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    m, r, _ = simulate(tmp_path)
    out = tmp_path / "tracks.csv"
    capsys.readouterr()
    argv = ["track", "--input", str(m), "--radars", str(r), "--out", str(out), *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"radarviz: error: {message}") and err.count("\n") == 1, err
    assert not out.exists()


def test_associate_refuses_a_labelled_file(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    m = tmp_path / "m.csv"
    m.write_text("time_s,radar,range_m,azimuth_deg,target\n0,radar,1e4,0,a\n")
    r = tmp_path / "r.toml"
    r.write_text(
        "[radars.radar]\nx_m = 0.0\ny_m = 0.0\nz_m = 0.0\nsigma_r_m = 50.0\nsigma_beta_deg = 0.3\n"
    )
    out = tmp_path / "t.csv"
    argv = ["track", "--input", str(m), "--radars", str(r), "--out", str(out), "--associate", "gnn"]
    assert main(argv) == 2
    assert f"{m} line 1, column target: --associate is for plots without" in capsys.readouterr().err
    assert not out.exists()


def test_crossing_scans_beyond_the_range_name_the_scans(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """At 40 km, 250 m/s and 5 s a scan, 56 scans keep the paths 5 km clear of the radar: more
    is refused as ``--scans`` (the flag given), not as the range the scans would need."""
    m, r = tmp_path / "m.csv", tmp_path / "r.toml"
    argv = ["simulate", "--preset", "crossing", "--out", str(m), "--radars-out", str(r)]
    assert main([*argv, "--scans", "57"]) == 2
    assert capsys.readouterr().err == (
        "radarviz: error: --scans must be an integer in [2, 56] (got 57)\n"
    )
    assert not m.exists() and not r.exists()
    assert main([*argv, "--scans", "56"]) == 0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--pd", "0"], "--pd must be a finite number in (0, 1] (got 0.0)"),
        (["--clutter-per-scan", "-1"], "--clutter-per-scan must be a finite number in [0, 10000]"),
        (["--crossing-angle-deg", "0"], "--crossing-angle-deg must be a finite number in (0, 180]"),
        (["--targets", "1"], "--targets must be an integer in [2, 1000]"),
    ],
)
def test_bad_scene_flags(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    m, r = tmp_path / "m.csv", tmp_path / "r.toml"
    argv = ["simulate", "--preset", "crossing", "--out", str(m), "--radars-out", str(r), *extra]
    assert main(argv) == 2
    assert capsys.readouterr().err.startswith(f"radarviz: error: {message}")
    assert not m.exists() and not r.exists()
    aso = ["reproduce", "association", "--runs", "2", "--methods", "ucm", *extra]
    assert main(aso) == 2
    assert capsys.readouterr().err.startswith(f"radarviz: error: {message}")
    # The scene's flags belong to the crossing preset: another preset refuses them.
    argv[2] = "prosov"
    assert main(argv) == 2
    assert capsys.readouterr().err == (
        f"radarviz: error: {extra[0]} is the crossing preset's (--preset crossing)\n"
    )


def test_reproduce_association_json_and_figure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    png = tmp_path / "a.png"
    argv = [
        "reproduce",
        "association",
        "--runs",
        "3",
        "--scans",
        "16",
        "--methods",
        "ucm",
        "ekf",
        "--json",
        "--plot",
        str(png),
    ]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert png.stat().st_size > 10_000
    assert list(doc["methods"]) == ["ucm", "ekf"] and len(doc["times_s"]) == 16
    for e in doc["methods"].values():
        band = e["gospa_per_scan_m"]
        assert all(
            lo <= m <= hi for lo, m, hi in zip(band["lo"], band["mean"], band["hi"], strict=True)
        )
        # No track at the first scan (M = 3): GOSPA is c (two targets missed, c²/2 each).
        assert band["mean"][0] == pytest.approx(doc["gospa"]["cutoff_m"])
    # The paired differences from the reference (ucm): its own are 0; ekf's are the
    # difference of the two methods' means (same runs).
    assert doc["reference"] == "ucm"
    ucm, ekf = doc["methods"]["ucm"], doc["methods"]["ekf"]
    assert ucm["minus_reference"]["false_tracks"] == {"delta": 0.0, "lo": 0.0, "hi": 0.0}
    for key in ("gospa_m", "swaps", "false_tracks"):
        d = ekf["minus_reference"][key]["delta"]
        assert d == pytest.approx(ekf[key]["mean"] - ucm[key]["mean"], abs=1e-9)
    assert main(["reproduce", "association", "--runs", "1"]) == 2
    assert "--runs must be an integer in [2, 10000]" in capsys.readouterr().err


def test_reproduce_association_refuses_a_nan(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import radarviz.core.experiments.association as exp

    real = exp.run_association

    def spoiled(cfg: exp.AssociationConfig) -> exp.AssociationResult:
        result = real(cfg)
        result.gospa[0, 1, 3, 0] = math.nan
        return result

    monkeypatch.setattr(exp, "run_association", spoiled)
    png = tmp_path / "a.png"
    argv = ["reproduce", "association", "--runs", "2", "--scans", "8", "--methods", "ucm"]
    assert main([*argv, "--plot", str(png)]) == 1
    out, err = capsys.readouterr()
    assert out == "" and not png.exists()
    assert err == (
        "radarviz: error: reproduce association: methods.ucm.gospa_per_scan_m.mean[3] is NaN "
        "(not a finite result)\n"
    )


def test_bench_association_figures_are_consistent() -> None:
    """``radarviz bench``'s association figures (speed is not asserted): the plots counted,
    the ratio equal to its two rates, and the association without error on its easy grid."""
    from radarviz.viz_app.bench.association import bench_association, format_association

    doc = bench_association(30, scans=6)
    assert (doc["targets"], doc["scans"], doc["correct"]) == (30, 6, True)
    assert doc["association_over_labelled"] == pytest.approx(
        doc["labelled_plots_per_s"] / doc["associated_plots_per_s"], rel=1e-12
    )
    assert doc["dense_over_sparse"] == pytest.approx(
        doc["associated_plots_per_s"] / doc["dense_plots_per_s"], rel=1e-12
    )
    assert doc["same_as_dense"] and doc["stamped_correct"]
    assert doc["stamped_over_labelled"] == pytest.approx(
        doc["stamped_labelled_plots_per_s"] / doc["stamped_plots_per_s"], rel=1e-12
    )
    assert "every track on one target" in format_association(doc)
    assert "the same track ids" in format_association(doc)


def test_reproduction_without_clutter_or_misses() -> None:
    """P_D = 1, no clutter, paths crossing at 60°: every run confirms exactly the targets at
    the third scan (M = 3), never swaps them, and from then on GOSPA is localisation alone
    (nothing missed, nothing false); before, it is every target missed, c²/2 each."""
    from radarviz.core.experiments.association import AssociationConfig, run_association

    scene = CrossingScene(
        targets=3, crossing_angle_deg=60.0, detection_prob=1.0, clutter_per_scan=0.0, scans=20
    )
    cfg = AssociationConfig(scene=scene, runs=3, methods=("ucm", "ekf"))
    res = run_association(cfg)
    assert np.all(res.swaps == 0) and np.all(res.false_tracks == 0) and np.all(res.tracks == 3)
    c2 = cfg.gospa_cutoff_m**2
    assert np.all(res.gospa[:, :, :2, 2] == 3 * c2 / 2)  # scans 1-2: all three missed
    assert np.all(res.gospa[:, :, 2:, 2] == 0) and np.all(res.gospa[..., 3] == 0)
    loc = res.gospa[:, :, 2:, 1]
    assert np.allclose(res.gospa[:, :, 2:, 0] ** 2, loc) and np.all(loc > 0)


def test_simulate_crossing_writes_its_three_files_together(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The plots, the radars and the truth are one unit (``commit_together``): the truth's
    rename failing leaves none of the three (they did not exist) and no temporary file."""
    import errno
    import os

    m, r, t = tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "truth.csv"
    real = os.replace

    def failing(src, dst, *args, **kwargs):
        if os.path.realpath(dst) == os.path.realpath(t):
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        return real(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", failing)
    argv = ["simulate", "--preset", "crossing", "--out", str(m), "--radars-out", str(r)]
    assert main([*argv, "--truth-out", str(t)]) == 1
    assert f"cannot write {t}" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------------------
# The sparse route: coarse box, per-component assignment
# ------------------------------------------------------------------------------------------


def sparse_instance(rng: np.random.Generator, k: int, p: int, density: float) -> np.ndarray:
    """A random d² matrix, most pairs outside the gate (∞), the rest uniform on [0, 12):
    continuous values, so the optimum is unique with probability 1 (no ties)."""
    d2 = rng.uniform(0.0, 12.0, (k, p))
    d2[rng.uniform(size=(k, p)) > density] = np.inf
    return d2


def as_pairs(d2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r, c = np.nonzero(np.isfinite(d2))
    return r, c, d2[r, c]


@pytest.mark.parametrize("seed", range(40))
def test_sparse_assignment_is_the_global_optimum(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    gate = 9.21
    k, p = rng.integers(1, 6, size=2)
    d2 = sparse_instance(rng, int(k), int(p), 0.4)
    rows, cols = sparse_gnn_assign(*as_pairs(d2), gate, d2.shape)
    assert len(set(rows.tolist())) == len(rows) and len(set(cols.tolist())) == len(cols)
    assert np.all(d2[rows, cols] < gate)
    assert float((gate - d2[rows, cols]).sum()) == pytest.approx(brute_assign(d2, gate))
    # Larger instances, many components: exactly the dense assignment (checked above).
    d2 = sparse_instance(rng, 60, 70, 0.03)
    rows, cols = sparse_gnn_assign(*as_pairs(d2), gate, d2.shape)
    dense_rows, dense_cols = gnn_assign(d2, gate)
    assert rows.tolist() == dense_rows.tolist() and cols.tolist() == dense_cols.tolist()


def test_sparse_assignment_takes_components_apart() -> None:
    # Component {0, 1} × {0, 1} is the greedy trap of test_gnn_is_global_not_greedy; track 2
    # and plot 2 are a component of one edge; track 3 has nothing in its gate.
    d2 = np.full((4, 3), np.inf)
    d2[:2, :2] = [[1.0, 2.0], [1.5, np.inf]]
    d2[2, 2] = 8.0
    rows, cols = sparse_gnn_assign(*as_pairs(d2), 9.0, d2.shape)
    assert list(zip(rows.tolist(), cols.tolist(), strict=True)) == [(0, 1), (1, 0), (2, 2)]
    empty = np.zeros(0, dtype=np.intp)
    assert sparse_gnn_assign(empty, empty, np.zeros(0), 9.0, (3, 0))[0].size == 0


@pytest.mark.parametrize(
    ("method", "dims", "span_s"),
    [("ucm", 2, 0.0), ("naive", 2, 0.0), ("cmkf_d", 3, 0.0), ("ucm", 2, 3.0), ("seed", 3, 3.0)],
)
def test_gate_box_keeps_every_pair_inside_the_gate(method: str, dims: int, span_s: float) -> None:
    """Every pair the dense d² puts inside the gate, each track predicted (cv, σa 5 m/s²) to
    its plot's own time in [0, span] s, is in the box built from the two end times."""
    rng = np.random.default_rng(11)
    k, p, n = 60, 80, 2 * dims
    gate = gate_threshold(0.999, dims)
    x = np.zeros((k, n))
    x[:, 0], x[:, 2] = rng.uniform(2e4, 3e4, k), rng.uniform(-3e3, 3e3, k)
    x[:, 1], x[:, 3] = rng.normal(0, 200, k), rng.normal(0, 200, k)
    if dims == 3:
        x[:, 4] = rng.uniform(1e3, 3e3, k)
    A = rng.normal(size=(k, n, n))
    P = A @ A.mT * rng.uniform(1e2, 3e4, (k, 1, 1)) + np.eye(n) * 1e2
    v = np.tile([1.0, 0.1], dims)  # velocity std a tenth of the position's (per second)
    P = P * v[:, None] * v[None, :]
    state = CVBatch(x, P)
    times = span_s * rng.uniform(size=p)
    r = rng.uniform(1.95e4, 3.05e4, p)
    b = rng.uniform(-0.12, 0.12, p)
    el = rng.uniform(0.03, 0.15, p) if dims == 3 else None
    site = rng.uniform(-300, 300, (p, dims))
    noise = PolarNoise(rng.uniform(20, 80, p), np.radians(rng.uniform(0.05, 0.3, p)), 2e-3)
    d2 = np.empty((k, p))
    for j in range(p):  # each plot against every track at its own time
        one = PolarPlot(r[j : j + 1], b[j : j + 1], None if el is None else el[j : j + 1])
        d2[:, j] = mahalanobis_matrix(
            method,
            cv_predict(state, times[j], 5.0),
            one,
            PolarNoise(noise.sigma_r_m[j : j + 1], noise.sigma_beta_rad[j : j + 1], 2e-3),
            site[j : j + 1],
        )[:, 0]
    early = cv_predict(state, float(times.min()), 5.0)
    late = cv_predict(state, float(times.max()), 5.0)
    rows, cols = gate_box_pairs(method, early, late, PolarPlot(r, b, el), noise, site, gate)
    inside = set(zip(*np.nonzero(d2 < gate), strict=True))
    boxed_pairs = set(zip(rows.tolist(), cols.tolist(), strict=True))
    assert len(inside) > 20  # the instance has pairs in the gate, and the box ...
    assert inside <= boxed_pairs  # ... keeps them all
    assert len(boxed_pairs) < 0.2 * k * p  # and drops most of the others
    pred = cv_predict(CVBatch(x[rows], P[rows]), times[cols], 5.0)
    pairs = mahalanobis_pairs(
        method,
        pred,
        PolarPlot(r[cols], b[cols], None if el is None else el[cols]),
        PolarNoise(noise.sigma_r_m[cols], noise.sigma_beta_rad[cols], 2e-3),
        site[cols],
    )
    assert np.allclose(pairs, d2[rows, cols], rtol=1e-9, atol=0)  # the same statistic
    if span_s == 0.0:
        assert np.array_equal(pairs, d2[rows, cols])  # the same numbers, elementwise


def run_both(
    scans: list[list[Plot]],
    methods: tuple[str, ...],
    model: str,
    interval: bool = True,
    **assoc: object,
) -> list[tuple[GNNTracker, list]]:
    options = StreamOptions(model=model, sigma_a_mps2=1.0, sigma_v0_mps=300.0)
    out = []
    for dense in (True, False):
        gnn = GNNTracker(methods, False, options, AssociationOptions(**assoc), dense=dense)
        gnn._interval = interval  # False: the per-time boxes of a model without a time bound
        out.append((gnn, [gnn.add_scan(list(plots)) for plots in scans]))
    return out


@pytest.mark.parametrize(
    ("gating", "model", "jitter_s", "interval"),
    [
        ("ucm", "cv", 0.0, True),
        ("ucm", "imm", 0.0, True),
        ("ucm", "cv", 0.4, True),
        ("ucm", "imm", 0.4, True),
        ("ucm", "cv", 0.4, False),
        ("ducm", "cv", 0.0, True),
        ("ekf", "cv", 0.4, True),
    ],
)
def test_sparse_route_equals_the_dense_route(
    gating: str, model: str, jitter_s: float, interval: bool
) -> None:
    from radarviz.core.experiments.association import scan_plots

    scene = CrossingScene(
        targets=3, crossing_angle_deg=10.0, detection_prob=0.9, clutter_per_scan=10.0, scans=25
    )
    rng = np.random.default_rng(7)
    scans = scan_plots(scene, rng)
    if jitter_s:  # each plot its own time within the scan (a rotating radar's time stamps)
        scans = [
            sorted(
                (replace(p, time_s=p.time_s + jitter_s * rng.uniform()) for p in s),
                key=lambda p: p.time_s,
            )
            for s in scans
        ]
    methods = ("ucm", "ekf")
    (dense, a), (sparse, b) = run_both(scans, methods, model, interval, method=gating)
    assert sum(len(r.track_ids) for r in a) > 300
    assert sum(len(r.confirmed) for r in a) >= 3 and sum(len(r.deleted) for r in a) > 20
    for ra, rb in zip(a, b, strict=True):
        assert ra.track_ids == rb.track_ids and ra.statuses == rb.statuses
        assert ra.confirmed == rb.confirmed and ra.deleted == rb.deleted
        # The same filtering to rounding: on the IMM's compiled association route the kernel
        # filters the plots itself, the same step functions compiled in another call (fused
        # multiply-adds and sums ordered by the compiler, ``core.filters.kernels_2d``).
        for rows_a, rows_b in zip(ra.rows, rb.rows, strict=True):
            for (ma, xa, Pa), (mb, xb, Pb) in zip(rows_a, rows_b, strict=True):
                assert ma == mb
                np.testing.assert_allclose(xb, xa, rtol=1e-9, atol=1e-9)
                np.testing.assert_allclose(Pb, Pa, rtol=1e-9, atol=1e-9)
    assert dense.ever_confirmed == sparse.ever_confirmed


def test_bench_only_association(capsys: pytest.CaptureFixture[str]) -> None:
    """``bench --only association``: the association figures alone, at ``--targets``."""
    assert main(["bench", "--only", "association", "--targets", "20", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)["association"]
    assert (doc["targets"], doc["correct"], doc["same_as_dense"]) == (20, True, True)
    assert main(["bench", "--only", "association", "--targets", "0"]) == 2
    assert "--targets" in capsys.readouterr().err


def test_track_rrd_draws_the_truth_file(tmp_path: Path, capsys, rrd_contents) -> None:
    """``track --rrd --truth``: each truth target's path (static) and its position at each truth
    time, on the ``time`` timeline at the truth's times; ``--truth`` without ``--rrd`` is a
    one-line error (exit 2) before any tracking."""
    from radarviz.viz_app.io.score_files import read_truth

    m, r, t = simulate(tmp_path, "--clutter-per-scan", "1")
    out, rrd = tmp_path / "tracks.csv", tmp_path / "tracks.rrd"
    argv = ["track", "--input", str(m), "--radars", str(r), "--out", str(out)]
    argv += ["--associate", "gnn", "--method", "ucm", "--model", "cv", "--sigma-a", "1"]
    assert main([*argv, "--truth", str(t)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--truth" in err and "--rrd" in err
    assert not out.exists()
    assert main([*argv, "--rrd", str(rrd), "--truth", str(t)]) == 0
    truth = read_truth(str(t))
    rows, cols = rrd_contents(rrd)
    for target in set(truth.targets.tolist()):
        entity = f"/world/truth/{target}/position"
        times = np.sort(truth.times_s[truth.targets == target])
        assert rows[entity] == len(times)
        np.testing.assert_allclose(np.array(cols[entity]["time"]) / 1e9, times, atol=1e-6)
        assert f"/world/truth/{target}/path" in rows
