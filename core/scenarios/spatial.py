"""The Prosov target in 3D and noisy spherical measurements of it.

The 3D reproduction keeps the planar experiment's range and radial motion (r0 = 150 km,
outward at 200 m/s, ``core.scenarios.planar.prosov_target``) and lifts the line of sight to
elevation E: the target starts at r0 u(0, E) and moves along u(0, E), u the direction cosines
of ``core.geometry.direction_cosines``. At E = 0 its x and y are the planar target's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from radarviz.core.geometry import polar_coordinates
from radarviz.core.params import check, check_real, default


@dataclass(frozen=True)
class ConstantVelocityTarget3D:
    """A target in uniform straight-line motion in 3D, sampled once per scan.

    Attributes:
        x0_m, y0_m, z0_m: position at the first scan, radar-centred, m.
        vx_mps, vy_mps, vz_mps: velocity, m/s.
        period_s: scan period T, s.  steps: number of scans N.
    """

    x0_m: float
    y0_m: float
    z0_m: float
    vx_mps: float
    vy_mps: float
    vz_mps: float
    period_s: float
    steps: int

    def __post_init__(self) -> None:
        check("period_s", self.period_s)
        check("steps", self.steps)
        for name in ("x0_m", "y0_m", "z0_m", "vx_mps", "vy_mps", "vz_mps"):
            check_real(name, getattr(self, name))

    @property
    def dims(self) -> int:
        return 3

    @property
    def elevation_deg(self) -> float:
        """Elevation of the first position seen from the radar, degrees."""
        return float(np.rad2deg(np.arctan2(self.z0_m, np.hypot(self.x0_m, self.y0_m))))

    def truth(self) -> NDArray[np.float64]:
        """True states (N, 6) as (x, ẋ, y, ẏ, z, ż) at scans n = 1 … N."""
        t = np.arange(self.steps) * self.period_s
        out = np.empty((self.steps, 6))
        starts = (self.x0_m, self.y0_m, self.z0_m)
        speeds = (self.vx_mps, self.vy_mps, self.vz_mps)
        for a in range(3):
            out[:, 2 * a] = starts[a] + speeds[a] * t
            out[:, 2 * a + 1] = speeds[a]
        return out


def prosov_target_3d(
    elevation_deg: float = default("target_elevation_deg"),
    period_s: float = default("period_s"),
    steps: int = default("steps"),
    *,
    target_range_m: float = default("target_range_m"),
    target_speed_mps: float = default("target_speed_mps"),
) -> ConstantVelocityTarget3D:
    """Prosov's target at elevation E: r0 u(0, E) moving radially outward along u(0, E)."""
    check("target_elevation_deg", elevation_deg)
    check("target_range_m", target_range_m)
    check("target_speed_mps", target_speed_mps)
    el = np.deg2rad(elevation_deg)
    ce, se = float(np.cos(el)), float(np.sin(el))
    r0, v = target_range_m, target_speed_mps
    return ConstantVelocityTarget3D(r0 * ce, 0.0, r0 * se, v * ce, 0.0, v * se, period_s, steps)


def spherical_measurements(
    truth: NDArray[np.float64],
    *,
    sigma_r_m: float,
    sigma_beta_rad: float,
    sigma_elevation_rad: float,
    runs: int,
    rng: np.random.Generator,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Noisy (r̂, β̂, ε̂) of a radar at the origin, each (M, N), for truth (N, 6).

    Drawn in the planar order (ranges, then azimuths) and then the elevations, so the first
    two are ``core.scenarios.planar.polar_measurements``' draws for the same generator.
    """
    r, beta, eps = polar_coordinates([truth[:, 0], truth[:, 2], truth[:, 4]])
    steps = truth.shape[0]
    r_hat = r + sigma_r_m * rng.standard_normal((runs, steps))
    beta_hat = beta + sigma_beta_rad * rng.standard_normal((runs, steps))
    eps_hat = eps + sigma_elevation_rad * rng.standard_normal((runs, steps))
    return r_hat, beta_hat, eps_hat
