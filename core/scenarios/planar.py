"""Seeded scenarios and measurement generation.

A scenario is the true state sequence of one target; measurements are drawn for M Monte Carlo
runs at once (run index leading). Every draw comes from a ``numpy.random.Generator`` the
caller seeds, so an experiment is reproducible bit for bit for the same seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from radarviz.core.geometry import polar_coordinates
from radarviz.core.params import check, check_real, default


@dataclass(frozen=True)
class ConstantVelocityTarget2D:
    """A target in uniform straight-line motion, sampled once per scan.

    Attributes:
        x0_m, y0_m: position at the first scan (n = 1), radar-centred, m.
        vx_mps, vy_mps: velocity, m/s.
        period_s: scan period T, s.
        steps: number of scans N.
    """

    x0_m: float
    y0_m: float
    vx_mps: float
    vy_mps: float
    period_s: float
    steps: int

    def __post_init__(self) -> None:
        check("period_s", self.period_s)
        check("steps", self.steps)
        for name in ("x0_m", "y0_m", "vx_mps", "vy_mps"):
            check_real(name, getattr(self, name))

    def truth(self) -> NDArray[np.float64]:
        """True states (N, 4) as (x, ẋ, y, ẏ) at scans n = 1 … N."""
        t = np.arange(self.steps) * self.period_s
        out = np.empty((self.steps, 4))
        out[:, 0] = self.x0_m + self.vx_mps * t
        out[:, 1] = self.vx_mps
        out[:, 2] = self.y0_m + self.vy_mps * t
        out[:, 3] = self.vy_mps
        return out


def prosov_target(
    period_s: float = default("period_s"),
    steps: int = default("steps"),
    *,
    target_range_m: float = default("target_range_m"),
    target_speed_mps: float = default("target_speed_mps"),
) -> ConstantVelocityTarget2D:
    """Prosov's experiment: r0 = 150 km, β0 = 0, moving radially outward at 200 m/s.

    The defaults come from ``core.params.PARAMETERS``; the target starts at (r0, 0) and moves
    along +x at ``target_speed_mps``.
    """
    check("target_range_m", target_range_m)
    check("target_speed_mps", target_speed_mps)
    return ConstantVelocityTarget2D(target_range_m, 0.0, target_speed_mps, 0.0, period_s, steps)


def polar_measurements(
    truth: NDArray[np.float64],
    *,
    sigma_r_m: float,
    sigma_beta_rad: float,
    runs: int,
    rng: np.random.Generator,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Noisy range and azimuth of a radar at the origin, for ``runs`` independent runs.

    Args:
        truth: (N, 4) true states (x, ẋ, y, ẏ).
        sigma_r_m: range noise σr, m.  sigma_beta_rad: azimuth noise σβ, rad.
        runs: M.  rng: the generator all noise is drawn from (ranges first, then azimuths).

    Pass the σ's by keyword. (They are still accepted by position for the callers in
    ``core.tracking.stream`` and the tuning panel's ``simulate``.)

    Returns:
        (r̂, β̂), each (M, N): r̂ = r + v_r, β̂ = β + v_β, v ~ N(0, σ²) independent.
    """
    r, beta = polar_coordinates([truth[:, 0], truth[:, 2]])
    steps = truth.shape[0]
    # r + σ v formed in the draws' own arrays (no temporaries; the same numbers bit for bit)
    r_hat = rng.standard_normal((runs, steps))
    r_hat *= sigma_r_m
    r_hat += r
    beta_hat = rng.standard_normal((runs, steps))
    beta_hat *= sigma_beta_rad
    beta_hat += beta
    return r_hat, beta_hat
