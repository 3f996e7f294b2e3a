"""Doppler-aided tracking: a finite-memory track start, then an EKF with a radial-velocity row.

Gorshkov and Zavizhenets (2016) end with the remark that the first k = 3 finite-memory estimates
(state and R) should initialise the Kalman filter that follows. This module does that for one
2D radar measuring range r̂, azimuth β̂ and, optionally, Doppler radial velocity V̂r:

1. Start at scan k from the least-squares fit of (r, Vr, a) over scans 1 … k
   (``core.finite_memory.fit``), range only or range + Doppler. In line-of-sight coordinates
   (unit vectors u = (cos β, sin β) along the line of sight, w = (−sin β, cos β) across it, β
   the newest measured azimuth):

       position = r̂ u,          var along = R11,  var across = r̂² σβ²
       velocity = V̂r u,         var along = R22,  var across = σv0²  (nothing observed)
       cov(position along, velocity along) = R12

   (the acceleration is dropped: the filter that follows is constant velocity).
2. Continue with the polar EKF on (r̂, β̂) (``core.filters.polar.ekf_update``) and, for the
   Doppler variant, then a second, scalar update with V̂r (``doppler_los_update``).

Why the Doppler row is not the textbook EKF row. The joint EKF on (r̂, β̂, V̂r) linearises

       Vr = (x ẋ + y ẏ) / r,   ∂Vr/∂(x, ẋ, y, ẏ) = ((ẋ − Vr x/r)/r, x/r, (ẏ − Vr y/r)/r, y/r)

at the prediction. Its position derivative is (tangential speed)/r, which at the start is
taken as 0 (the cross-range velocity is unobserved) while a cross-range position error of
r σβ really moves Vr by v_t σβ: metres per second against σVr = 1 m/s for the CMW radars.
That filter diverges there (RLS6, σβ = 1°: position NEES above 10³ by scan 10; it is kept as
``ekf_doppler_update``, checked against filterpy, for the record). Using the *measured*
line of sight instead makes the row linear in the velocity, with the bearing error moved into
its variance, and it stays consistent for RLS1–RLS4; for RLS5–RLS6 at σβ = 1° its NEES
still sits at 3–10 (the range-only EKF's at 2.5–4.4): the precise radars' errors are far
from Gaussian after the polar-to-Cartesian step, and the app says so rather than hiding it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.cv import CVBatch, as_batch, cv_predict, empty_batch
from radarviz.core.filters.polar import ekf_update, wrap_angle
from radarviz.core.finite_memory.fit import FiniteMemoryFit, finite_memory_fit, preset
from radarviz.core.metrics import MetricsAccumulator, TrackMetrics, nees_band
from radarviz.core.params import check, check_int, default
from radarviz.core.scenarios.planar import ConstantVelocityTarget2D

VARIANTS: tuple[str, ...] = ("range_only", "range_doppler")


def doppler_target(period_s: float = 10.0, steps: int = 60) -> ConstantVelocityTarget2D:
    """A crossing target: 100 km out at 36.9°, moving at (−200, 100) m/s (radial and tangential)."""
    return ConstantVelocityTarget2D(80e3, 60e3, -200.0, 100.0, period_s, steps)


@dataclass(frozen=True)
class DopplerTrackingConfig:
    """Monte Carlo of the finite-memory start plus EKF, range only beside range + Doppler.

    Attributes:
        radar: preset name (RLS1 … RLS6) giving σr, σVr and T.
        sigma_beta_deg: azimuth noise σβ, degrees.
        runs: Monte Carlo runs.  seed: root of ``SeedSequence``.
        steps: scans per run.  start_scans: k of the finite-memory start.
        sigma_v0_mps: std of the unobserved cross-range velocity at the start.
        sigma_a_mps2: process noise of the EKF (discrete white-noise acceleration).
    """

    radar: str = "RLS3"
    sigma_beta_deg: float = default("sigma_beta_deg")
    runs: int = default("runs")
    seed: int = default("seed")
    steps: int = default("steps")
    start_scans: int = 3
    sigma_v0_mps: float = default("sigma_v0_mps")
    sigma_a_mps2: float = default("sigma_a_mps2")
    target: ConstantVelocityTarget2D | None = field(default=None)

    def __post_init__(self) -> None:
        """Every field but ``radar``, ``start_scans`` and ``target`` is checked against
        ``core.params.PARAMETERS``; ``start_scans`` must fit in the run."""
        preset(self.radar)
        for name in ("sigma_beta_deg", "runs", "seed", "steps", "sigma_v0_mps", "sigma_a_mps2"):
            check(name, getattr(self, name))
        check_int("start_scans", self.start_scans, low=2, high=self.steps)

    def scenario(self) -> ConstantVelocityTarget2D:
        if self.target is not None:
            return self.target
        return doppler_target(preset(self.radar).period_s, self.steps)


class PolarDopplerMeasurements(NamedTuple):
    """Measurements of M runs over N scans, each (M, N): range (m), azimuth (rad), Vr (m/s)."""

    r: NDArray[np.float64]
    beta: NDArray[np.float64]
    vr: NDArray[np.float64]


def radial_velocity(truth: NDArray[np.float64]) -> NDArray[np.float64]:
    """Vr = (x ẋ + y ẏ)/r of states (..., 4)."""
    x, vx, y, vy = truth[..., 0], truth[..., 1], truth[..., 2], truth[..., 3]
    return (x * vx + y * vy) / np.hypot(x, y)


def polar_doppler_measurements(
    truth: NDArray[np.float64],
    sigma_r: float,
    sigma_beta: float,
    sigma_vr: float,
    runs: int,
    rng: np.random.Generator,
) -> PolarDopplerMeasurements:
    """Noisy (r̂, β̂, V̂r) for ``runs`` runs of the (N, 4) truth; independent Gaussian errors."""
    steps = truth.shape[0]
    r = np.hypot(truth[:, 0], truth[:, 2])
    beta = np.arctan2(truth[:, 2], truth[:, 0])
    vr = radial_velocity(truth)
    return PolarDopplerMeasurements(
        r + sigma_r * rng.standard_normal((runs, steps)),
        beta + sigma_beta * rng.standard_normal((runs, steps)),
        vr + sigma_vr * rng.standard_normal((runs, steps)),
    )


def finite_memory_start(
    fit: FiniteMemoryFit,
    ranges: NDArray[np.float64],
    radial_velocities: NDArray[np.float64] | None,
    beta: NDArray[np.float64],
    sigma_beta: float,
    sigma_v0: float,
) -> CVBatch:
    """CV track states at the newest of k scans from the finite-memory fit (module docstring).

    Args:
        fit: a full-order (3-parameter) or at least 2-parameter fit over k scans.
        ranges: (M, k) oldest first.  radial_velocities: (M, k) or None (range only).
        beta: (M,) azimuth at the newest scan (rad).
    """
    if fit.order < 2:
        raise ValueError(
            f"a track start needs range and radial velocity; k = {fit.k} fits only "
            f"{fit.order} parameter"
        )
    z = ranges if radial_velocities is None else np.concatenate([ranges, radial_velocities], 1)
    W = fit.W[:2]
    theta = z @ W.T  # (M, 2): r̂, V̂r at the newest scan
    r_hat, vr_hat = theta[:, 0], theta[:, 1]
    c, s = np.cos(beta), np.sin(beta)
    m = ranges.shape[0]
    x = np.zeros((m, 4))
    x[:, 0], x[:, 2] = r_hat * c, r_hat * s
    x[:, 1], x[:, 3] = vr_hat * c, vr_hat * s
    # Covariance in (pos along, vel along, pos across, vel across), then rotated.
    L = np.zeros((m, 4, 4))
    L[:, 0, 0], L[:, 1, 1] = fit.R[0, 0], fit.R[1, 1]
    L[:, 0, 1] = L[:, 1, 0] = fit.R[0, 1]
    L[:, 2, 2] = r_hat**2 * sigma_beta**2
    L[:, 3, 3] = sigma_v0**2
    # State (x, ẋ, y, ẏ) = G (along p, along v, across p, across v).
    G = np.zeros((m, 4, 4))
    G[:, 0, 0], G[:, 0, 2] = c, -s
    G[:, 2, 0], G[:, 2, 2] = s, c
    G[:, 1, 1], G[:, 1, 3] = c, -s
    G[:, 3, 1], G[:, 3, 3] = s, c
    P = G @ L @ G.transpose(0, 2, 1)
    return as_batch(x, 0.5 * (P + P.transpose(0, 2, 1)))


def ekf_doppler_update(
    state: CVBatch,
    r: NDArray[np.float64],
    beta: NDArray[np.float64],
    vr: NDArray[np.float64],
    sigma_r: float,
    sigma_beta: float,
    sigma_vr: float,
) -> CVBatch:
    """EKF update of every run with (r̂, β̂, V̂r); Joseph form, bearing residual wrapped.

    h(x) = (√(x² + y²), atan2(y, x), (x ẋ + y ẏ)/r),   H = ∂h/∂x at the prediction
    S = H P Hᵀ + R,  K = P Hᵀ S⁻¹,  x⁺ = x + K (z − h(x)),
    P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ,   R = diag(σr², σβ², σVr²)
    """
    x, P = state.x, state.P
    px, vx, py, vy = x[:, 0], x[:, 1], x[:, 2], x[:, 3]
    rp = np.hypot(px, py)
    vrp = (px * vx + py * vy) / rp
    m = state.runs
    H = np.zeros((m, 3, 4))
    H[:, 0, 0], H[:, 0, 2] = px / rp, py / rp
    H[:, 1, 0], H[:, 1, 2] = -py / rp**2, px / rp**2
    H[:, 2, 0] = (vx - vrp * px / rp) / rp
    H[:, 2, 1] = px / rp
    H[:, 2, 2] = (vy - vrp * py / rp) / rp
    H[:, 2, 3] = py / rp
    R = np.diag([sigma_r**2, sigma_beta**2, sigma_vr**2])
    PHt = P @ H.transpose(0, 2, 1)
    S = H @ PHt + R
    K = np.linalg.solve(S, PHt.transpose(0, 2, 1)).transpose(0, 2, 1)  # P Hᵀ S⁻¹, S symmetric
    nu = np.stack([r - rp, wrap_angle(beta - np.arctan2(py, px)), vr - vrp], axis=-1)
    x_new = x + (K @ nu[:, :, None])[:, :, 0]
    A = np.eye(4) - K @ H
    P_new = A @ P @ A.transpose(0, 2, 1) + K @ R @ K.transpose(0, 2, 1)
    return as_batch(x_new, 0.5 * (P_new + P_new.transpose(0, 2, 1)))


class DopplerTrackingResult(NamedTuple):
    """Per-scan statistics of both variants; scans before the start are NaN.

    Attributes:
        config: what was run.  n: (N,) scans 1 … N.
        metrics: variant → the issue-2 metrics (position bias, RMSE, filter σ, NEES).
        rmse_vr / sigma_vr_filter: variant → (N,) RMSE of the track's radial velocity and the
            filter's σ of it (√(g P gᵀ), g = ∂Vr/∂state).
        start_fits: variant → the finite-memory fit used for the start.
        nees_pos_band95: the 95% χ² band of the run-averaged position NEES.
    """

    config: DopplerTrackingConfig
    n: NDArray[np.int64]
    metrics: dict[str, TrackMetrics]
    rmse_vr: dict[str, NDArray[np.float64]]
    sigma_vr_filter: dict[str, NDArray[np.float64]]
    start_fits: dict[str, FiniteMemoryFit]
    nees_pos_band95: tuple[float, float]


def _vr_stats(state: CVBatch, truth_n: NDArray[np.float64]) -> tuple[float, float]:
    """(Σ (V̂r − Vr)², Σ g P gᵀ) over the runs of one scan."""
    x, P = state.x, state.P
    px, vx, py, vy = x[:, 0], x[:, 1], x[:, 2], x[:, 3]
    rp = np.hypot(px, py)
    vrp = (px * vx + py * vy) / rp
    g = np.stack([(vx - vrp * px / rp) / rp, px / rp, (vy - vrp * py / rp) / rp, py / rp], -1)
    var = np.einsum("mi,mij,mj->m", g, P, g)
    err = vrp - radial_velocity(truth_n)
    return float((err * err).sum()), float(var.sum())


def doppler_los_update(
    state: CVBatch,
    vr: NDArray[np.float64],
    beta: NDArray[np.float64],
    sigma_vr: float,
    sigma_beta: float,
) -> CVBatch:
    """Doppler as a linear velocity measurement along the *measured* line of sight.

        V̂r = u(β̂)·v + e,   H = (0, cos β̂, 0, sin β̂),
        var e = σVr² + (ŵ·v̂)² σβ² + σβ² wᵀ P_vv w       (the bearing error tilts u: δVr ≈ v_t δβ)

    Linear in the state, so the Kalman update is exact given that variance: no dependence on
    the predicted position, which is what makes the EKF row fail when σVr is small (see the
    module docstring). Joseph form.
    """
    x, P = state.x, state.P
    c, s = np.cos(beta), np.sin(beta)
    vt = -s * x[:, 1] + c * x[:, 3]
    p_vt = s * s * P[:, 1, 1] - 2.0 * s * c * P[:, 1, 3] + c * c * P[:, 3, 3]
    r_e = sigma_vr**2 + (vt * vt + p_vt) * sigma_beta**2
    h = np.zeros((state.runs, 4))
    h[:, 1], h[:, 3] = c, s
    Ph = np.einsum("mij,mj->mi", P, h)
    S = np.einsum("mi,mi->m", h, Ph) + r_e
    K = Ph / S[:, None]
    x_new = x + K * (vr - (c * x[:, 1] + s * x[:, 3]))[:, None]
    A = np.eye(4) - K[:, :, None] * h[:, None, :]
    P_new = A @ P @ A.transpose(0, 2, 1) + r_e[:, None, None] * K[:, :, None] * K[:, None, :]
    return as_batch(x_new, 0.5 * (P_new + P_new.transpose(0, 2, 1)))


def run_doppler_tracking(config: DopplerTrackingConfig) -> DopplerTrackingResult:
    """Monte Carlo of both variants on the same measurements (common random numbers)."""
    radar = preset(config.radar)
    sr, svr, T = radar.sigma_r_m, radar.sigma_vr_mps, radar.period_s
    sb = float(np.deg2rad(config.sigma_beta_deg))
    target = config.scenario()
    truth = target.truth()
    steps, k = truth.shape[0], config.start_scans
    rng = np.random.default_rng(np.random.SeedSequence(config.seed))
    meas = polar_doppler_measurements(truth, sr, sb, svr, config.runs, rng)
    metrics, rmse_vr, sig_vr, fits = {}, {}, {}, {}
    for variant in VARIANTS:
        doppler = variant == "range_doppler"
        fit = finite_memory_fit(k, sr, svr, T, with_doppler=doppler)
        fits[variant] = fit
        state = finite_memory_start(
            fit,
            meas.r[:, :k],
            meas.vr[:, :k] if doppler else None,
            meas.beta[:, k - 1],
            sb,
            config.sigma_v0_mps,
        )
        acc = MetricsAccumulator(steps)
        sq, var = np.full(steps, np.nan), np.full(steps, np.nan)
        acc.add(k - 1, state, truth[k - 1])
        sq[k - 1], var[k - 1] = _vr_stats(state, truth[k - 1])
        buf_a, buf_b = empty_batch(config.runs), empty_batch(config.runs)
        for n in range(k, steps):
            pred = cv_predict(state, T, config.sigma_a_mps2, out=buf_a)
            state = ekf_update(pred, meas.r[:, n], meas.beta[:, n], sr, sb, out=buf_b)
            if doppler:
                state = doppler_los_update(state, meas.vr[:, n], meas.beta[:, n], svr, sb)
            acc.add(n, state, truth[n])
            sq[n], var[n] = _vr_stats(state, truth[n])
        metrics[variant] = acc.result()
        rmse_vr[variant] = np.sqrt(sq / config.runs)
        sig_vr[variant] = np.sqrt(var / config.runs)
    return DopplerTrackingResult(
        config=config,
        n=np.arange(1, steps + 1),
        metrics=metrics,
        rmse_vr=rmse_vr,
        sigma_vr_filter=sig_vr,
        start_fits=fits,
        nees_pos_band95=nees_band(2, config.runs),
    )
