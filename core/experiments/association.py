"""``reproduce association``: GNN association of crossing targets in clutter, per method.

Monte Carlo over runs of the crossing scene (``core.scenarios.crossing``): run i draws its
detections and clutter from child i of ``SeedSequence(seed)``. Every method tracks every run
with the association of ``core.tracking.association`` *gated by itself* (the method's own
prediction and innovation covariance score the plots), so what a method's conversion does to
the gate shows in its association; all methods see the same plots of a run (common random
numbers), so their differences are paired. Per method:

* GOSPA per scan (``core.tracking.gospa``, α = 2) between the truth positions and the
  confirmed tracks' positions at the scan time (a track missed in the scan: its prediction),
  with its localisation, missed and false parts;
* per run: the track swaps and false tracks of ``core.tracking.gospa.TrackCounter`` (the
  CLEAR MOT matching), and the confirmed tracks.

Every mean over runs carries its 95% band, mean ± t_{R−1} s/√R (s the runs' sample std; the
runs are independent): pointwise per scan for the GOSPA curves.

The filters are the constant-velocity model with white-noise acceleration σa (the targets fly
straight; σa > 0 keeps the gate from closing on a wrong velocity) and the first-plot start
with velocity std σv0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.confidence import student_t_quantile
from radarviz.core.filters.methods import ALL_METHODS
from radarviz.core.params import check, check_choice, check_distinct, check_int, default
from radarviz.core.scenarios.crossing import CrossingScene, crossing_scans
from radarviz.core.scenarios.rotating import RotatingPlots, RotatingRadar
from radarviz.core.tracking.association import AssociationOptions, GNNTracker
from radarviz.core.tracking.gospa import TrackCounter, gospa
from radarviz.core.tracking.stream import Plot, StreamOptions

#: Most runs of the experiment (each run filters every method scan by scan).
MAX_RUNS = 10_000
#: GOSPA parts per scan, in this order in ``AssociationResult.gospa``.
GOSPA_PARTS: tuple[str, ...] = ("distance", "localisation", "missed", "false")


@dataclass(frozen=True)
class AssociationConfig:
    """The experiment (module docstring).

    Attributes:
        scene: the crossing scene.
        runs, seed: Monte Carlo runs and the root of their seeds.
        methods: the methods compared (each gates its own tracks).
        association: gate, M-of-N and deletion (its ``method`` is replaced per method).
        sigma_a_mps2, sigma_v0_mps: the filters' process noise and start velocity std.
        gospa_cutoff_m, gospa_order: GOSPA's c (m) and p.
    """

    scene: CrossingScene = field(default_factory=CrossingScene)
    runs: int = 20
    seed: int = default("seed")
    methods: tuple[str, ...] = ALL_METHODS
    association: AssociationOptions = field(default_factory=AssociationOptions)
    sigma_a_mps2: float = 1.0
    sigma_v0_mps: float = 300.0
    gospa_cutoff_m: float = default("gospa_cutoff_m")
    gospa_order: float = default("gospa_order")

    def __post_init__(self) -> None:
        check_int("runs", self.runs, low=2, high=MAX_RUNS)
        check("seed", self.seed)
        if not self.methods:
            check_choice("methods", "", ALL_METHODS)
        for m in self.methods:
            check_choice("methods", m, ALL_METHODS)
        check_distinct("methods", tuple(self.methods))
        check("sigma_a_mps2", self.sigma_a_mps2)
        check("sigma_v0_mps", self.sigma_v0_mps)
        check("gospa_cutoff_m", self.gospa_cutoff_m)
        check("gospa_order", self.gospa_order)


class AssociationResult(NamedTuple):
    """Per-run results of every method (module docstring).

    Attributes:
        config: the experiment.
        times_s: (N,) scan times.
        gospa: (methods, runs, N, 4) the GOSPA distance (m) and its three parts (m^p) per scan.
        swaps, false_tracks, tracks: (methods, runs) per run.
    """

    config: AssociationConfig
    times_s: NDArray[np.float64]
    gospa: NDArray[np.float64]
    swaps: NDArray[np.int64]
    false_tracks: NDArray[np.int64]
    tracks: NDArray[np.int64]


def scan_plots(scene: CrossingScene, rng: np.random.Generator) -> list[list[Plot]]:
    """One run's scans as ``Plot`` records of the radar "radar" at the origin (2D)."""
    sigma_beta_rad = math.radians(scene.sigma_beta_deg)
    return [
        [
            Plot(float(t), float(r), float(b), scene.sigma_r_m, sigma_beta_rad, radar="radar")
            for r, b in zip(s.range_m, s.azimuth_rad, strict=True)
        ]
        for t, s in zip(scene.times_s, crossing_scans(scene, rng), strict=True)
    ]


def rotating_scene_plots(radars: list[RotatingRadar], plots: RotatingPlots) -> list[Plot]:
    """A rotating-radar scene's plots (``core.scenarios.rotating``) as ``Plot`` records, each
    with its radar's name, site and accuracies (2D, unlabelled)."""
    return [
        Plot(
            float(t),
            float(r),
            float(b),
            radars[j].sigma_r_m,
            radars[j].sigma_beta_rad,
            site=(radars[j].x_m, radars[j].y_m, 0.0),
            radar=radars[j].name,
        )
        for t, j, r, b in zip(
            plots.time_s, plots.radar, plots.range_m, plots.azimuth_rad, strict=True
        )
    ]


def track_run(
    cfg: AssociationConfig, method: str, scans: list[list[Plot]]
) -> tuple[NDArray[np.float64], TrackCounter]:
    """One method on one run: GOSPA (N, 4) per scan and the run's track counter."""
    scene = cfg.scene
    truth = scene.truth()
    options = StreamOptions(
        sigma_a_mps2=cfg.sigma_a_mps2, sigma_v0_mps=cfg.sigma_v0_mps, model="cv"
    )
    assoc = AssociationOptions(**{**cfg.association.__dict__, "method": method})
    tracker = GNNTracker((method,), False, options, assoc)
    counter = TrackCounter(cfg.gospa_cutoff_m)
    out = np.empty((len(scans), len(GOSPA_PARTS)))
    truth_ids = list(range(scene.targets))
    for k, (t, plots) in enumerate(zip(scene.times_s, scans, strict=True)):
        tracker.add_scan(plots)
        ids, state = tracker.states(method, float(t))
        xy, est = truth[k][:, [0, 2]], state.x[:, [0, 2]]
        g = gospa(xy, est, cfg.gospa_cutoff_m, cfg.gospa_order)
        out[k] = (g.distance, g.localisation, g.missed, g.false)
        counter.add(truth_ids, xy, ids, est)
    return out, counter


def run_association(cfg: AssociationConfig) -> AssociationResult:
    """Every method on every run (module docstring)."""
    scene = cfg.scene
    k = len(cfg.methods)
    g = np.empty((k, cfg.runs, scene.scans, len(GOSPA_PARTS)))
    swaps = np.zeros((k, cfg.runs), dtype=np.int64)
    false = np.zeros((k, cfg.runs), dtype=np.int64)
    tracks = np.zeros((k, cfg.runs), dtype=np.int64)
    for r, child in enumerate(np.random.SeedSequence(cfg.seed).spawn(cfg.runs)):
        scans = scan_plots(scene, np.random.default_rng(child))
        for i, m in enumerate(cfg.methods):
            g[i, r], counter = track_run(cfg, m, scans)
            swaps[i, r], false[i, r], tracks[i, r] = (
                counter.swaps,
                counter.false_tracks,
                counter.tracks,
            )
    return AssociationResult(cfg, scene.times_s, g, swaps, false, tracks)


class MeanBand(NamedTuple):
    """A mean over runs and its 95% band (lo, hi), each of the statistic's shape."""

    mean: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]


def mean_band(values: NDArray[np.float64], axis: int = 0) -> MeanBand:
    """Mean over the runs along ``axis`` and mean ± t_{R−1, 0.975} s/√R (independent runs)."""
    v = np.asarray(values, dtype=np.float64)
    runs = v.shape[axis]
    mean = v.mean(axis=axis)
    half = student_t_quantile(runs - 1) * v.std(axis=axis, ddof=1) / math.sqrt(runs)
    return MeanBand(mean, mean - half, mean + half)
