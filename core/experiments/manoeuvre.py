"""``reproduce manoeuvre``: tracking manoeuvring aircraft with each method and motion model.

Monte Carlo over the flights of ``core.scenarios.manoeuvre`` (F flights × M noise runs, one
batch of B = F·M tracks): every method of ``METHODS_3D`` tracks every run with each motion
model, through the streaming tracker's own step (``core.tracking.stream.TrackGroup``), so the
figures are those of ``radarviz track`` on such files. Per method and model:

* position RMSE over every plot after ``burn_in_plots`` and every run, against the RMSE of
  the raw converted measurements (``ucm``'s point of each plot) over the same plots;
* mean position NEES over the same plots (3 degrees of freedom; consistent: 3) and, per
  plot, whether the run-averaged NEES lies in its χ² band (``core.metrics.nees_band``);
* the consistency monitor's figure (``core.tracking.consistency``): the fraction of NIS
  windows outside their band, and the fraction of runs it flags (out more than
  ``INCONSISTENT_FRACTION`` of the time).

Every figure carries a 95% delete-a-group jackknife band over the runs (``core.confidence``).

The straight-line check runs Prosov's target (one radar, 150 km, 200 m/s radially outward,
σr = 250 m, σβ = 1°, T = 10 s, 60 scans, 2D) with the matched filter (CV, Q = 0) and the
default IMM, and reports the IMM's RMSE over scans 31–60 relative to the matched filter's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.confidence import BAND_GROUPS, group_sums, jackknife_band
from radarviz.core.filters.measurement import DopplerMeasurement
from radarviz.core.filters.methods import (
    ALL_METHODS,
    METHODS_3D,
    PolarNoise,
    PolarPlot,
    method_groups,
    method_named,
)
from radarviz.core.filters.models import DEFAULT_IMM, CVModel, IMMModel
from radarviz.core.finite_memory.fit import finite_memory_fit
from radarviz.core.finite_memory.start import finite_memory_start
from radarviz.core.metrics import nees_band
from radarviz.core.params import ParameterError, check, check_int
from radarviz.core.scenarios.manoeuvre import FLIGHTS, ManoeuvrePlots, manoeuvre_plots
from radarviz.core.scenarios.planar import polar_measurements, prosov_target
from radarviz.core.tracking.consistency import (
    INCONSISTENT_FRACTION,
    NIS_BAND_LEVEL,
    ConsistencyEvent,
    ConsistencyMonitor,
    out_of_band,
    windowed_nis,
)
from radarviz.core.tracking.stream import Plot, StreamOptions, StreamTracker, TrackGroup

#: The motion models compared: the papers' Q = 0, the CV filter the user tried (σa = 1),
#: and the default IMM of ``radarviz track``.
DEFAULT_MODELS: dict[str, CVModel | IMMModel] = {
    "cv-q0": CVModel(0.0),
    "cv-sa1": CVModel(1.0),
    "imm": DEFAULT_IMM,
}


@dataclass(frozen=True)
class ManoeuvreConfig:
    """The experiment's settings.

    Attributes:
        runs: noise runs per flight (M).  seed: root of the noise.
        methods: from ``METHODS_3D``.  models: name → motion model.
        burn_in_plots: plots left out of RMSE and NEES at the start (the track's transient
            from a one-plot start with σv0).
        nis_window: w of the consistency monitor.  sigma_v0_mps: the start's velocity std.
        straight_runs: runs of the straight-line check (0: skip it).
    """

    runs: int = 8
    seed: int = 1
    methods: tuple[str, ...] = METHODS_3D
    models: dict[str, CVModel | IMMModel] = field(default_factory=lambda: dict(DEFAULT_MODELS))
    burn_in_plots: int = 30
    nis_window: int = 10
    sigma_v0_mps: float = 1000.0
    straight_runs: int = 256
    finite_memory_k: int = 5

    def __post_init__(self) -> None:
        check_int("runs", self.runs, low=2, high=10_000)
        check("seed", self.seed)
        for m in self.methods:
            if m not in METHODS_3D:
                raise ParameterError(
                    f"methods must be among {', '.join(METHODS_3D)} (got {m!r})", "methods"
                )
        check_int("burn_in_plots", self.burn_in_plots, low=0, high=500)
        check("nis_window", self.nis_window)
        check("sigma_v0_mps", self.sigma_v0_mps)
        if self.straight_runs:
            check_int("straight_runs", self.straight_runs, low=2, high=100_000)
        if self.finite_memory_k:
            check_int("finite_memory_k", self.finite_memory_k, low=3, high=100)


class Figure(NamedTuple):
    """A Monte Carlo figure and its 95% jackknife band."""

    value: float
    lo: float
    hi: float


class ModelResult(NamedTuple):
    """One method with one motion model on the manoeuvring flights."""

    rmse_m: Figure
    rmse_ratio: Figure  # RMSE / raw converted measurement RMSE
    nees: Figure  # mean position NEES (dof 3)
    nees_plots_in_band: float  # fraction of plots whose run-averaged NEES is in its band
    nis_out_fraction: Figure
    flagged_runs: float  # fraction of runs the monitor flags


class StraightLineResult(NamedTuple):
    """The IMM against the matched CV filter on Prosov's straight-line target (2D)."""

    runs: int
    rmse_cv_m: dict[str, float]
    rmse_imm_m: dict[str, float]
    ratio: dict[str, Figure]  # IMM / CV RMSE over scans 31–60


class FlightTracks(NamedTuple):
    """One flight tracked by one method with several motion models (the demo's scene).

    Attributes:
        time_s: (N,) plot times.  radar: (N,) radar index.  truth_m: (N, 3) true position.
        measured_m: (N, 3) each plot's naive converted point (site + r̂ u(β̂, ε̂)).
        estimates: model → (N, 3) track positions.  errors_m: model → (N,) |x̂ − x|.
        windows: model → (W, 4) the monitor's (time, q, lo, hi) per window.
        events: model → the monitor's events.
    """

    time_s: NDArray[np.float64]
    radar: NDArray[np.int64]
    truth_m: NDArray[np.float64]
    measured_m: NDArray[np.float64]
    estimates: dict[str, NDArray[np.float64]]
    errors_m: dict[str, NDArray[np.float64]]
    windows: dict[str, NDArray[np.float64]]
    events: dict[str, list[ConsistencyEvent]]


def track_flight(
    flight: int = 4,
    seed: int = 1,
    method: str = "ucm",
    models: dict[str, CVModel | IMMModel] | None = None,
    nis_window: int = 10,
) -> FlightTracks:
    """Flight ``flight`` of ``FLIGHTS`` (noise run 0 of ``seed``) tracked plot by plot by
    ``StreamTracker`` with each model (default: Q = 0 and the IMM), the monitor watching."""
    models = models or {"cv-q0": CVModel(0.0), "imm": DEFAULT_IMM}
    plots, mp = flight_plots(flight, seed)
    sched = mp.schedule
    measured = np.array(
        [
            np.asarray(p.site)
            + p.range_m
            * np.array(
                [
                    np.cos(p.elevation_rad) * np.cos(p.azimuth_rad),
                    np.cos(p.elevation_rad) * np.sin(p.azimuth_rad),
                    np.sin(p.elevation_rad),
                ]
            )
            for p in plots
        ]
    )
    truth = mp.true_position_m[:, 0]
    est, err, win, ev = {}, {}, {}, {}
    for label, motion in models.items():
        mon = ConsistencyMonitor(nis_window, keep_history=True)
        opts = _stream_options(motion, mon)
        rows = StreamTracker((method,), True, opts).add_block(plots)
        x = np.array([r[0][1][0::2] for r in rows])
        est[label], err[label] = x, np.linalg.norm(x - truth, axis=-1)
        win[label], ev[label] = mon.history(method), list(mon.events)
    return FlightTracks(sched.time_s, sched.radar, truth, measured, est, err, win, ev)


def flight_plots(
    flight: int, seed: int, steps: int | None = None, through_degrees: bool = False
) -> tuple[list[Plot], ManoeuvrePlots]:
    """Flight ``flight`` of ``FLIGHTS``, noise run 0 of ``seed``, as the tracker's plots (and
    the arrays they came from). ``through_degrees``: angles and their σ rounded through
    degrees, as a measurement file gives them (so tracking the file equals tracking these)."""
    mp = manoeuvre_plots(1, seed, (FLIGHTS[flight],), steps=steps)
    sched = mp.schedule

    def angle(v: float) -> float:
        return math.radians(math.degrees(v)) if through_degrees else v

    plots = []
    for n, t in enumerate(sched.time_s):
        r = sched.radars[int(sched.radar[n])]
        vr = float(mp.radial_velocity_mps[n, 0, 0])
        doppler = bool(mp.doppler[n])
        plots.append(
            Plot(
                float(t),
                float(mp.range_m[n, 0, 0]),
                angle(float(mp.azimuth_rad[n, 0, 0])),
                r.sigma_r_m,
                angle(r.sigma_beta_rad),
                tuple(map(float, r.position)),
                r.name,
                angle(float(mp.elevation_rad[n, 0, 0])),
                angle(r.sigma_elevation_rad),
                vr if doppler else None,
                r.sigma_vr_mps if doppler else 0.0,
            )
        )
    return plots, mp


def _stream_options(motion: CVModel | IMMModel, monitor: ConsistencyMonitor) -> StreamOptions:
    if isinstance(motion, IMMModel):
        return StreamOptions(
            model="imm",
            imm_sigma_a_mps2=motion.sigma_a_mps2,
            transition_prob=motion.transition,
            imm_turn_rate_degps=motion.turn_rate_degps,
            monitor=monitor,
        )
    return StreamOptions(model="cv", sigma_a_mps2=motion.sigma_a_mps2, monitor=monitor)


class FiniteMemoryResult(NamedTuple):
    """The sliding-window finite-memory track of one radar (``track --finite-memory K``)."""

    radar: str
    k: int
    with_doppler: bool
    rmse_m: Figure
    raw_rmse_m: Figure  # that radar's own converted plots, same plots
    rmse_ratio: Figure
    nees: Figure


class ManoeuvreResult(NamedTuple):
    config: ManoeuvreConfig
    flights: tuple[str, ...]
    plots_per_flight: int
    raw_rmse_m: Figure
    results: dict[str, dict[str, ModelResult]]  # model → method → result
    nees_band_per_plot: tuple[float, float]
    straight: StraightLineResult | None
    finite_memory: tuple[FiniteMemoryResult, ...] = ()


def _groups_of(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per-group sums (G, ...) of per-run values (..., B) (run b in group b mod G)."""
    return group_sums(values, 0, BAND_GROUPS)


def _ratio_figure(num: NDArray[np.float64], den: NDArray[np.float64], sqrt: bool) -> Figure:
    """(Σ num / Σ den)[^½] over runs (B,) with its jackknife band: an RMSE (num = Σ e², den =
    count), a mean (sqrt False), or a ratio of two RMSEs over the same plots and runs."""
    gn, gd = _groups_of(num), _groups_of(den)
    f = (lambda v: np.sqrt(v)) if sqrt else (lambda v: v)
    est = f(num.sum() / den.sum())
    loo = f((num.sum() - gn) / (den.sum() - gd))
    lo, hi = jackknife_band(est, loo)
    return Figure(float(est), float(lo), float(hi))


def _track_batch(
    mp: ManoeuvrePlots,
    methods: tuple[str, ...],
    motion: CVModel | IMMModel,
    sigma_v0_mps: float,
) -> tuple[dict[str, NDArray], dict[str, NDArray], dict[str, NDArray], NDArray[np.int64]]:
    """Track every run: per method, position errors (N, B, 3), NEES (N, B), NIS (N − 1, B)
    and the NIS dof (N − 1,) of each update."""
    n_plots, f, m = mp.range_m.shape
    b = f * m
    sched = mp.schedule
    truth = np.repeat(mp.true_position_m, m, axis=1)  # (N, B, 3)
    errs, nees, nis = {}, {}, {}
    dof = np.zeros(n_plots - 1, dtype=np.int64)
    for names in method_groups(methods):
        group = TrackGroup(names, 3, motion, sigma_v0_mps)
        e = np.empty((len(names), n_plots, b, 3))
        q = np.empty((len(names), n_plots, b))
        s = np.empty((len(names), n_plots - 1, b))
        for n in range(n_plots):
            radar = sched.radars[int(sched.radar[n])]
            plot = PolarPlot(
                *(v[n].reshape(b) for v in (mp.range_m, mp.azimuth_rad, mp.elevation_rad))
            )
            noise = PolarNoise(radar.sigma_r_m, radar.sigma_beta_rad, radar.sigma_elevation_rad)
            pre = group.group.start_parts(plot, noise) if group.group.converted else None
            doppler = None
            if mp.doppler[n]:
                doppler = DopplerMeasurement(
                    mp.radial_velocity_mps[n].reshape(b),
                    plot.azimuth_rad,
                    plot.elevation_rad,
                    radar.sigma_vr_mps,
                    radar.sigma_beta_rad,
                    radar.sigma_elevation_rad,
                )
            site = np.asarray(radar.position, dtype=np.float64)
            state, stats = group.add_arrays(float(sched.time_s[n]), plot, noise, site, pre, doppler)
            x = state.x.reshape(len(names), b, 6)
            P = state.P.reshape(len(names), b, 6, 6)
            err = x[..., 0::2] - truth[n]
            e[:, n] = err
            Ppos = P[..., 0::2, 0::2]
            q[:, n] = np.einsum(
                "...i,...i->...", err, np.linalg.solve(Ppos, err[..., None])[..., 0]
            )
            if stats is not None:
                s[:, n - 1] = stats.nis.reshape(len(names), b)
                dof[n - 1] = stats.dof
        for i, name in enumerate(names):
            errs[name], nees[name], nis[name] = e[i], q[i], s[i]
    return errs, nees, nis, dof


def raw_converted_errors(mp: ManoeuvrePlots) -> NDArray[np.float64]:
    """Errors (N, B, 3) of every plot's ``ucm`` converted point (site + conversion) against
    the truth: the accuracy of the measurements themselves."""
    n_plots, f, m = mp.range_m.shape
    b = f * m
    ucm = method_named("ucm")
    truth = np.repeat(mp.true_position_m, m, axis=1)
    out = np.empty((n_plots, b, 3))
    for n in range(n_plots):
        radar = mp.schedule.radars[int(mp.schedule.radar[n])]
        plot = PolarPlot(*(v[n].reshape(b) for v in (mp.range_m, mp.azimuth_rad, mp.elevation_rad)))
        noise = PolarNoise(radar.sigma_r_m, radar.sigma_beta_rad, radar.sigma_elevation_rad)
        z, _ = ucm.convert(plot, noise)
        for a in range(3):
            out[n, :, a] = z[a] + radar.position[a] - truth[n, :, a]
    return out


def _model_result(
    e: NDArray, nees: NDArray, nis: NDArray, dof: NDArray, raw2: NDArray, cfg: ManoeuvreConfig
) -> ModelResult:
    burn = cfg.burn_in_plots
    e2 = (e[burn:] ** 2).sum(-1).sum(0)  # per run (B,)
    count = np.full(e2.shape, float(e.shape[0] - burn))
    rmse = _ratio_figure(e2, count, sqrt=True)
    ratio = _ratio_figure(e2, raw2, sqrt=True)  # same plots, same runs
    nees_fig = _ratio_figure(nees[burn:].sum(0), count, sqrt=False)
    lo, hi = nees_band(3, nees.shape[1])
    per_plot = nees[burn:].mean(axis=1)
    in_band = float(np.mean((per_plot >= lo) & (per_plot <= hi)))
    q, D = windowed_nis(nis, dof, cfg.nis_window)
    below, above = out_of_band(q, D, NIS_BAND_LEVEL)
    out = (below | above).astype(np.float64)  # (W, B)
    out_per_run = out.sum(0)
    nis_fig = _ratio_figure(out_per_run, np.full(out_per_run.shape, float(out.shape[0])), False)
    flagged = float(np.mean(out.mean(0) > INCONSISTENT_FRACTION))
    return ModelResult(rmse, ratio, nees_fig, in_band, nis_fig, flagged)


def straight_line_check(
    runs: int, seed: int, models: tuple[CVModel, IMMModel], sigma_v0_mps: float
) -> StraightLineResult:
    """The matched CV filter (Q = 0) and the IMM on Prosov's straight-line target (2D, every
    2D method), same runs; RMSE over scans 31–60 and the IMM/CV ratio with its band."""
    target = prosov_target()
    truth = target.truth()  # (N, 4)
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
    sigma_r_m, sigma_beta_rad = 250.0, np.radians(1.0)
    r_hat, b_hat = polar_measurements(
        truth, sigma_r_m=sigma_r_m, sigma_beta_rad=sigma_beta_rad, runs=runs, rng=rng
    )
    e2: dict[str, dict[str, NDArray]] = {}
    for label, motion in zip(("cv", "imm"), models, strict=True):
        e2[label] = {}
        for names in method_groups(ALL_METHODS):
            group = TrackGroup(names, 2, motion, sigma_v0_mps)
            acc = np.zeros((len(names), runs))
            for n in range(target.steps):
                plot = PolarPlot(r_hat[:, n], b_hat[:, n])
                noise = PolarNoise(sigma_r_m, sigma_beta_rad)
                pre = group.group.start_parts(plot, noise) if group.group.converted else None
                st, _ = group.add_arrays(
                    n * target.period_s, plot, noise, np.zeros(2), pre, None, with_stats=False
                )
                if n >= 30:
                    x = st.x.reshape(len(names), runs, 4)
                    acc += (x[..., 0] - truth[n, 0]) ** 2 + (x[..., 2] - truth[n, 2]) ** 2
            for i, name in enumerate(names):
                e2[label][name] = acc[i]
    ratio = {
        name: _ratio_figure(e2["imm"][name], e2["cv"][name], sqrt=True) for name in ALL_METHODS
    }
    rmse = {
        label: {name: float(np.sqrt(v.mean() / 30.0)) for name, v in e2[label].items()}
        for label in e2
    }
    return StraightLineResult(runs, rmse["cv"], rmse["imm"], ratio)


def finite_memory_tracks(
    mp: ManoeuvrePlots, raw: NDArray[np.float64], radar: int, k: int, sigma_v0_mps: float
) -> FiniteMemoryResult:
    """Radar ``radar``'s sliding-window track over every run: at each of its plots from the
    k-th on, the finite-memory fit of its last k ranges (and radial velocities, if it has
    Doppler) placed on the plot's line of sight (``core.finite_memory``, the fit and start
    ``StreamTracker`` uses), against the truth and against that radar's own raw plots."""
    sched = mp.schedule
    site = sched.radars[radar]
    idx = np.flatnonzero(sched.radar == radar)
    _, f, m = mp.range_m.shape
    b = f * m
    doppler = bool(mp.doppler[idx[0]])
    fit = finite_memory_fit(
        k,
        sigma_r_m=site.sigma_r_m,
        sigma_vr_mps=site.sigma_vr_mps if doppler else None,
        period_s=site.period_s,
        with_doppler=doppler,
    )
    truth = np.repeat(mp.true_position_m, m, axis=1)
    ranges = mp.range_m[idx].reshape(idx.size, b)
    vrs = mp.radial_velocity_mps[idx].reshape(idx.size, b)
    e2 = np.zeros(b)
    raw2 = np.zeros(b)
    nees = np.zeros(b)
    for i in range(k - 1, idx.size):
        n = idx[i]
        st = finite_memory_start(
            fit,
            ranges[i - k + 1 : i + 1].T,
            vrs[i - k + 1 : i + 1].T if doppler else None,
            mp.azimuth_rad[n].reshape(b),
            mp.elevation_rad[n].reshape(b),
            sigma_beta_rad=site.sigma_beta_rad,
            sigma_elevation_rad=site.sigma_elevation_rad,
            sigma_v0_mps=sigma_v0_mps,
            site=np.asarray(site.position, dtype=np.float64),
        )
        err = st.x[..., 0::2] - truth[n]
        e2 += (err**2).sum(-1)
        raw2 += (raw[n] ** 2).sum(-1)
        Ppos = st.P[..., 0::2, 0::2]
        nees += np.einsum("bi,bi->b", err, np.linalg.solve(Ppos, err[..., None])[..., 0])
    count = np.full(b, float(idx.size - k + 1))
    return FiniteMemoryResult(
        site.name,
        k,
        doppler,
        _ratio_figure(e2, count, sqrt=True),
        _ratio_figure(raw2, count, sqrt=True),
        _ratio_figure(e2, raw2, sqrt=True),
        _ratio_figure(nees, count, sqrt=False),
    )


def run_manoeuvre(cfg: ManoeuvreConfig, flights: Sequence = FLIGHTS) -> ManoeuvreResult:
    """The whole experiment (module docstring)."""
    mp = manoeuvre_plots(cfg.runs, cfg.seed, tuple(flights))
    raw = raw_converted_errors(mp)
    burn = cfg.burn_in_plots
    raw2 = (raw[burn:] ** 2).sum(-1).sum(0)
    count = np.full(raw2.shape, float(raw.shape[0] - burn))
    results: dict[str, dict[str, ModelResult]] = {}
    for label, motion in cfg.models.items():
        errs, nees, nis, dof = _track_batch(mp, cfg.methods, motion, cfg.sigma_v0_mps)
        results[label] = {
            m: _model_result(errs[m], nees[m], nis[m], dof, raw2, cfg) for m in cfg.methods
        }
    straight = None
    if cfg.straight_runs:
        imm = next((v for v in cfg.models.values() if isinstance(v, IMMModel)), DEFAULT_IMM)
        straight = straight_line_check(
            cfg.straight_runs, cfg.seed, (CVModel(0.0), imm), cfg.sigma_v0_mps
        )
    fm: tuple[FiniteMemoryResult, ...] = ()
    if cfg.finite_memory_k:
        # The first radar (what ``track --finite-memory`` uses) and the first with Doppler.
        with_doppler = [
            j
            for j in range(len(mp.schedule.radars))
            if mp.doppler[np.flatnonzero(mp.schedule.radar == j)[0]]
        ]
        radars = [0, *with_doppler[:1]]
        fm = tuple(
            finite_memory_tracks(mp, raw, j, cfg.finite_memory_k, cfg.sigma_v0_mps)
            for j in dict.fromkeys(radars)
        )
    b = mp.range_m.shape[1] * mp.range_m.shape[2]
    return ManoeuvreResult(
        cfg,
        tuple(f.name for f in flights),
        mp.range_m.shape[0],
        _ratio_figure(raw2, count, sqrt=True),
        results,
        nees_band(3, b),
        straight,
        fm,
    )
