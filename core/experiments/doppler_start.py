"""Doppler-aided tracking: a finite-memory track start, then an EKF with a radial-velocity update.

Gorshkov and Zavizhenets (2016) end with the remark that the first k = 3 finite-memory estimates
(state and R) should initialise the Kalman filter that follows. This experiment does that for
one 2D radar measuring range r̂, azimuth β̂ and, optionally, Doppler radial velocity V̂r, by
Monte Carlo, range only beside range + Doppler on the same measurements:

1. Start at scan k from the least-squares fit of (r, Vr, a) over scans 1 … k
   (``core.finite_memory.start``).
2. Continue with the polar EKF on (r̂, β̂) (``core.filters.polar_ekf``) and, for the Doppler
   variant, then a second, scalar update with V̂r along the measured line of sight
   (``core.filters.doppler``; its docstring says why not the textbook EKF row).
   The optional variant ``range_converted_doppler`` (``DopplerTrackingConfig.variants``)
   replaces that second update by the converted-Doppler one, the pseudo-measurement r̂ V̂r
   (``core.filters.converted_doppler``), on the numpy engine; it starts like
   ``range_doppler``, so the two differ only in the Doppler update. The variant
   ``range_joint_doppler`` makes the EKF and the line-of-sight Doppler one update with the
   correlation of their angle errors (``core.filters.joint_doppler``), numpy engine too.

The line-of-sight update is consistent for RLS1 and over-confident by 2–4% for RLS2–RLS4
(the bearing error it shares with the EKF; the joint update removes that); for RLS5–RLS6 at
σβ = 1° its NEES sits at 3–10 (the range-only EKF's at 2.5–4.4): the precise radars' errors
are far from Gaussian after the polar-to-Cartesian step, and the app says so rather than
hiding it (``docs/finite_memory.md``, section 7).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.confidence import BAND_GROUPS, group_counts, group_sums, jackknife_band
from radarviz.core.filters.compiled import ENGINES, FilterSettings, filter_scans
from radarviz.core.filters.converted_doppler import converted_doppler_update
from radarviz.core.filters.doppler import doppler_update
from radarviz.core.filters.joint_doppler import joint_doppler_update
from radarviz.core.filters.polar_ekf import ekf_update
from radarviz.core.filters.predict import cv_predict
from radarviz.core.filters.state import CVBatch, empty_batch
from radarviz.core.finite_memory.fit import (
    FiniteMemoryFit,
    RadarPreset,
    finite_memory_fit,
    preset,
)
from radarviz.core.finite_memory.start import finite_memory_start
from radarviz.core.geometry import polar_coordinates, radial_velocity
from radarviz.core.metrics import (
    STAGE_ROWS,
    MetricsAccumulator,
    TrackMetrics,
    metric_band,
    nees_band,
)
from radarviz.core.params import ParameterError, check, check_choice, check_int, default
from radarviz.core.scenarios.planar import ConstantVelocityTarget2D

VARIANTS: tuple[str, ...] = ("range_only", "range_doppler")
#: Every variant a config may ask for: ``VARIANTS`` (the default), the converted Doppler and
#: the joint EKF + line-of-sight Doppler update with their errors' correlation.
ALL_VARIANTS: tuple[str, ...] = (*VARIANTS, "range_converted_doppler", "range_joint_doppler")
#: The Doppler update of each variant that has one.
DOPPLER_UPDATE: dict[str, str] = {
    "range_doppler": "line_of_sight",
    "range_converted_doppler": "converted",
    "range_joint_doppler": "joint",
}


def doppler_target(period_s: float = 10.0, steps: int = 60) -> ConstantVelocityTarget2D:
    """A crossing target: 100 km out at 36.9°, moving at (−200, 100) m/s (radial and tangential)."""
    return ConstantVelocityTarget2D(80e3, 60e3, -200.0, 100.0, period_s, steps)


@dataclass(frozen=True)
class DopplerTrackingConfig:
    """Monte Carlo of the finite-memory start plus EKF, range only beside range + Doppler.

    Attributes:
        radar: the radar giving σr, σVr and T: a preset name (RLS1 … RLS6) or a
            ``RadarPreset`` of its own (e.g. the tuning panel's σr, T and C0).
        sigma_beta_deg: azimuth noise σβ, degrees.
        runs: Monte Carlo runs.  seed: root of ``SeedSequence``.
        steps: scans per run.  start_scans: k of the finite-memory start.
        sigma_v0_mps: std of the unobserved cross-range velocity at the start.
        sigma_a_mps2: process noise of the EKF (discrete white-noise acceleration).
        engine: ``"compiled"`` (``core.filters.compiled``) or ``"numpy"`` (the reference),
            as ``core.experiments.prosov.TrackingConfig.engine``. The converted-Doppler
            variant always runs on the numpy engine (the compiled kernel has no such update).
        variants: which of ``ALL_VARIANTS`` to run (default ``VARIANTS``).
    """

    radar: str | RadarPreset = "RLS3"
    sigma_beta_deg: float = default("sigma_beta_deg")
    runs: int = default("runs")
    seed: int = default("seed")
    steps: int = default("steps")
    start_scans: int = 3
    sigma_v0_mps: float = default("sigma_v0_mps")
    sigma_a_mps2: float = default("sigma_a_mps2")
    target: ConstantVelocityTarget2D | None = field(default=None)
    engine: str = "compiled"
    variants: tuple[str, ...] = VARIANTS

    def __post_init__(self) -> None:
        """Every field but ``radar``, ``start_scans`` and ``target`` is checked against
        ``core.params.PARAMETERS``; ``start_scans`` must fit in the run."""
        self.radar_preset()
        for name in ("sigma_beta_deg", "runs", "seed", "steps", "sigma_v0_mps", "sigma_a_mps2"):
            check(name, getattr(self, name))
        check_int("start_scans", self.start_scans, low=2, high=self.steps)
        check_choice("engine", self.engine, ENGINES)
        if not self.variants:
            raise ParameterError(
                f"variants must name at least one of {', '.join(ALL_VARIANTS)}", "variants"
            )
        for v in self.variants:
            check_choice("variant", v, ALL_VARIANTS)

    def scenario(self) -> ConstantVelocityTarget2D:
        if self.target is not None:
            return self.target
        return doppler_target(self.radar_preset().period_s, self.steps)

    def radar_preset(self) -> RadarPreset:
        """The radar: the preset named ``radar``, or ``radar`` itself (its values checked)."""
        if isinstance(self.radar, RadarPreset):
            r = self.radar
            check("sigma_r_m", r.sigma_r_m)
            check("sigma_vr_mps", r.sigma_vr_mps)
            check("period_s", r.period_s)
            return r
        return preset(self.radar)


class PolarDopplerMeasurements(NamedTuple):
    """Measurements of M runs over N scans, each (M, N): range (m), azimuth (rad), Vr (m/s)."""

    r: NDArray[np.float64]
    beta: NDArray[np.float64]
    vr: NDArray[np.float64]


def polar_doppler_measurements(
    truth: NDArray[np.float64],
    *,
    sigma_r_m: float,
    sigma_beta_rad: float,
    sigma_vr_mps: float,
    runs: int,
    rng: np.random.Generator,
) -> PolarDopplerMeasurements:
    """Noisy (r̂, β̂, V̂r) for ``runs`` runs of the (N, 4) truth; independent Gaussian errors."""
    steps = truth.shape[0]
    r, beta = polar_coordinates([truth[:, 0], truth[:, 2]])
    vr = radial_velocity(truth[:, 0::2], truth[:, 1::2])
    return PolarDopplerMeasurements(
        r + sigma_r_m * rng.standard_normal((runs, steps)),
        beta + sigma_beta_rad * rng.standard_normal((runs, steps)),
        vr + sigma_vr_mps * rng.standard_normal((runs, steps)),
    )


class DopplerTrackingResult(NamedTuple):
    """Per-scan statistics of both variants; scans before the start are NaN.

    Attributes:
        config: what was run.  n: (N,) scans 1 … N.
        metrics: variant → the Prosov experiment's metrics (position bias, RMSE, filter σ, NEES).
        rmse_vr_mps / sigma_vr_filter_mps: variant → (N,) RMSE of the track's radial
            velocity and the filter's σ of it (√(g P gᵀ), g = ∂Vr/∂state), m/s.
        start_fits: variant → the finite-memory fit used for the start.
        nees_pos_band95: the 95% χ² band of the run-averaged position NEES of a consistent
            filter.
        leave_one_out: variant → the metrics with each group of runs left out, (G, N) fields
            (``MetricsAccumulator.leave_one_out``), for ``band95``.
        rmse_vr_mps_ci95: variant → the 95% Monte Carlo band (lo, hi) of ``rmse_vr_mps``,
            (N,) each: the delete-a-group jackknife (``core.confidence``) of
            √(Σ (V̂r − Vr)² / M).
    """

    config: DopplerTrackingConfig
    n: NDArray[np.int64]
    metrics: dict[str, TrackMetrics]
    rmse_vr_mps: dict[str, NDArray[np.float64]]
    sigma_vr_filter_mps: dict[str, NDArray[np.float64]]
    start_fits: dict[str, FiniteMemoryFit]
    nees_pos_band95: tuple[float, float]
    leave_one_out: dict[str, TrackMetrics]
    rmse_vr_mps_ci95: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]

    def band95(self, variant: str, name: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The 95% Monte Carlo band (lo, hi) per scan of one variant's ``TrackMetrics`` field
        (``"rmse_x_m"``, ``"nees_pos"``, …): the delete-a-group jackknife; NaN before the start."""
        return metric_band(
            name, getattr(self.metrics[variant], name), getattr(self.leave_one_out[variant], name)
        )


def _vr_stats(
    x: NDArray[np.float64], P: NDArray[np.float64], truth: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Per scan of K scans of m runs, x (K, m, 4), P (K, m, 4, 4), truth (K, 4): Σ (V̂r − Vr)²
    and Σ g P gᵀ over the runs, (K,) each, and the (V̂r − Vr)² per group of runs (G, K)
    (``core.confidence.group_sums``); g = ∂Vr/∂state at the estimate."""
    px, vx, py, vy = x[..., 0], x[..., 1], x[..., 2], x[..., 3]
    rp = polar_coordinates([px, py])[0]
    vrp = (px * vx + py * vy) / rp
    g = np.stack([(vx - vrp * px / rp) / rp, px / rp, (vy - vrp * py / rp) / rp, py / rp], -1)
    var = np.einsum("kmi,kmij,kmj->km", g, P, g)
    err = vrp - radial_velocity(truth[:, None, 0::2], truth[:, None, 1::2])
    return (err * err).sum(axis=-1), var.sum(axis=-1), group_sums(err, 0, square=True)


class _VariantSums:
    """One variant's running sums: the tracking metrics and the radial-velocity sums per scan
    (NaN at scans before the start)."""

    def __init__(self, steps: int) -> None:
        self.acc = MetricsAccumulator(steps)
        self.sq, self.var = np.full(steps, np.nan), np.full(steps, np.nan)
        self.sq_groups = np.full((BAND_GROUPS, steps), np.nan)

    def add(self, first: int, x: NDArray, P: NDArray, truth: NDArray) -> None:
        """Scans first … first + K − 1: x (K, m, 4), P (K, m, 4, 4), truth (K, 4)."""
        span = slice(first, first + x.shape[0])
        self.acc.add_scans(first, x, P, truth)
        self.sq[span], self.var[span], self.sq_groups[:, span] = _vr_stats(x, P, truth)

    def result(self, runs: int) -> dict[str, object]:
        """The variant's fields of ``DopplerTrackingResult``."""
        rmse = np.sqrt(self.sq / runs)
        counts = group_counts(0, runs)[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            loo = np.sqrt((self.sq - self.sq_groups) / (runs - counts))
        loo[counts[:, 0] == 0] = np.nan
        return {
            "metrics": self.acc.result(),
            "leave_one_out": self.acc.leave_one_out(),
            "rmse_vr_mps": rmse,
            "sigma_vr_filter_mps": np.sqrt(self.var / runs),
            "rmse_vr_mps_ci95": jackknife_band(rmse, loo),
        }


def run_doppler_tracking(config: DopplerTrackingConfig) -> DopplerTrackingResult:
    """Monte Carlo of both variants on the same measurements (common random numbers)."""
    radar = config.radar_preset()
    sigma_r_m, sigma_vr_mps, T = radar.sigma_r_m, radar.sigma_vr_mps, radar.period_s
    sigma_beta_rad = float(np.deg2rad(config.sigma_beta_deg))
    truth = config.scenario().truth()
    steps, k = truth.shape[0], config.start_scans
    rng = np.random.default_rng(np.random.SeedSequence(config.seed))
    meas = polar_doppler_measurements(
        truth,
        sigma_r_m=sigma_r_m,
        sigma_beta_rad=sigma_beta_rad,
        sigma_vr_mps=sigma_vr_mps,
        runs=config.runs,
        rng=rng,
    )
    settings = FilterSettings(
        sigma_r_m,
        sigma_beta_rad,
        T,
        config.sigma_a_mps2,
        config.sigma_v0_mps,
        sigma_vr_mps=sigma_vr_mps,
    )
    fits: dict[str, FiniteMemoryFit] = {}
    fields: dict[str, dict[str, object]] = {}
    for variant in config.variants:
        update = DOPPLER_UPDATE.get(variant)
        doppler = update is not None
        fit = finite_memory_fit(
            k, sigma_r_m=sigma_r_m, sigma_vr_mps=sigma_vr_mps, period_s=T, with_doppler=doppler
        )
        fits[variant] = fit
        start = finite_memory_start(
            fit,
            meas.r[:, :k],
            meas.vr[:, :k] if doppler else None,
            meas.beta[:, k - 1],
            sigma_beta_rad=sigma_beta_rad,
            sigma_v0_mps=config.sigma_v0_mps,
        )
        sums = _VariantSums(steps)
        sums.add(k - 1, start.x[None], start.P[None], truth[k - 1 : k])
        vr = meas.vr if doppler else None
        if update in ("converted", "joint"):
            chunks = _filter_numpy(meas.r, meas.beta, vr, settings, (k - 1, start), update)
        elif config.engine == "compiled":
            chunks = _filter_compiled(meas.r, meas.beta, vr, settings, (k - 1, start))
        else:
            chunks = _filter_numpy(meas.r, meas.beta, vr, settings, (k - 1, start))
        for first, x, P in chunks:
            sums.add(first, x, P, truth[first : first + x.shape[0]])
        fields[variant] = sums.result(config.runs)
    by_field = {
        name: {v: f[name] for v, f in fields.items()} for name in fields[config.variants[0]]
    }
    return DopplerTrackingResult(
        config=config,
        n=np.arange(1, steps + 1),
        start_fits=fits,
        nees_pos_band95=nees_band(2, config.runs),
        **by_field,
    )


Chunks = Iterator[tuple[int, NDArray[np.float64], NDArray[np.float64]]]


def _filter_compiled(r, beta, vr, settings: FilterSettings, start: tuple[int, CVBatch]) -> Chunks:
    """The polar EKF (and the Doppler update where ``vr`` is given) after ``start`` =
    (scan k, state), by the compiled kernel: (first scan, x (K, m, 4), P (K, m, 4, 4))."""
    chunk = max(1, STAGE_ROWS // r.shape[0])
    for c in filter_scans("ekf", r, beta, settings, chunk, radial_velocity_mps=vr, start=start):
        yield c.first, c.x, c.P


def _filter_numpy(
    r,
    beta,
    vr,
    settings: FilterSettings,
    start: tuple[int, CVBatch],
    doppler: str = "line_of_sight",
) -> Chunks:
    """``_filter_compiled`` by the numpy engine (the reference), one scan at a time;
    ``doppler``: ``"line_of_sight"`` (``core.filters.doppler``), ``"converted"``
    (``core.filters.converted_doppler``) or ``"joint"`` (``core.filters.joint_doppler``: the
    EKF and the line-of-sight Doppler as one update with their errors' correlation), the
    update V̂r enters by."""
    s = settings
    noise = {"sigma_r_m": s.sigma_r_m, "sigma_beta_rad": s.sigma_beta_rad}
    state = start[1]
    buffers = (empty_batch(state.batch_shape), empty_batch(state.batch_shape))
    for n in range(start[0] + 1, r.shape[1]):
        pred = cv_predict(state, s.period_s, s.sigma_a_mps2, out=buffers[n % 2])
        if vr is not None and doppler == "joint":
            state = joint_doppler_update(
                pred, (r[:, n], beta[:, n]), vr[:, n], sigma_vr_mps=s.sigma_vr_mps, **noise
            )
            yield n, state.x[None], state.P[None]
            continue
        state = ekf_update(pred, (r[:, n], beta[:, n]), **noise)
        if vr is not None and doppler == "converted":
            state = converted_doppler_update(
                state,
                r[:, n],
                vr[:, n],
                sigma_r_m=s.sigma_r_m,
                sigma_vr_mps=s.sigma_vr_mps,
            )
        elif vr is not None:
            state = doppler_update(
                state,
                vr[:, n],
                beta[:, n],
                sigma_vr_mps=s.sigma_vr_mps,
                sigma_beta_rad=s.sigma_beta_rad,
            )
        yield n, state.x[None], state.P[None]


#: The Doppler updates compared by ``compare_doppler_updates``.
DOPPLER_VARIANTS: tuple[str, ...] = (
    "range_doppler",
    "range_converted_doppler",
    "range_joint_doppler",
)


class DopplerConsistency(NamedTuple):
    """How consistent one Doppler update is on one radar: its position NEES against χ².

    Attributes:
        radar: the preset (RLS1 … RLS6).  variant: ``range_doppler`` (line of sight) or
            ``range_converted_doppler`` (r̂ V̂r).
        nees_mean: the position NEES averaged over the runs and the scans after the start.
        nees_mean_ci95: its 95% Monte Carlo band (delete-a-group jackknife over the runs).
        nees_last / nees_last_ci95: the run-averaged NEES at the last scan and its band.
        band95: where the run average of a consistent filter falls at one scan (χ², 2 dof).
        verdict: ``"consistent"`` when the last scan's Monte Carlo band overlaps the χ² band,
            ``"over-confident"`` when it lies above, ``"under-confident"`` below.
    """

    radar: str
    variant: str
    nees_mean: float
    nees_mean_ci95: tuple[float, float]
    nees_last: float
    nees_last_ci95: tuple[float, float]
    band95: tuple[float, float]
    verdict: str


def doppler_consistency(result: DopplerTrackingResult) -> list[DopplerConsistency]:
    """``DopplerConsistency`` of each Doppler variant of ``result``."""
    lo_b, hi_b = result.nees_pos_band95
    after = slice(result.config.start_scans, None)
    out = []
    for variant in result.metrics:
        if variant not in DOPPLER_UPDATE:
            continue
        full = result.metrics[variant].nees_pos
        loo = result.leave_one_out[variant].nees_pos
        mean_lo, mean_hi = jackknife_band(np.mean(full[after]), np.mean(loo[:, after], axis=-1))
        last_lo, last_hi = result.band95(variant, "nees_pos")
        lo, hi = float(last_lo[-1]), float(last_hi[-1])
        verdict = (
            "over-confident" if lo > hi_b else "under-confident" if hi < lo_b else "consistent"
        )
        out.append(
            DopplerConsistency(
                radar=result.config.radar_preset().name,
                variant=variant,
                nees_mean=float(np.mean(full[after])),
                nees_mean_ci95=(float(mean_lo), float(mean_hi)),
                nees_last=float(full[-1]),
                nees_last_ci95=(lo, hi),
                band95=(lo_b, hi_b),
                verdict=verdict,
            )
        )
    return out


def compare_doppler_updates(
    radars: tuple[str, ...] = ("RLS1", "RLS2", "RLS3", "RLS4", "RLS5", "RLS6"),
    *,
    sigma_beta_deg: float = default("sigma_beta_deg"),
    runs: int = default("runs"),
    seed: int = default("seed"),
    engine: str = "compiled",
) -> list[DopplerTrackingResult]:
    """The Doppler-aided Monte Carlo of each radar with both Doppler updates on the same
    measurements (``DOPPLER_VARIANTS``); ``doppler_consistency`` of each result says which is
    consistent. The configs are all built (and so checked) before any is run."""
    configs = [
        DopplerTrackingConfig(
            radar=name,
            sigma_beta_deg=sigma_beta_deg,
            runs=runs,
            seed=seed,
            engine=engine,
            variants=DOPPLER_VARIANTS,
        )
        for name in radars
    ]
    return [run_doppler_tracking(c) for c in configs]
