"""The velocity vector scan by scan: a scenario's radars measured, fused and solved per scan.

Each scan the radars' (r̂, β̂, ε̂) are fused into one position (``fuse_positions``) and their
radial velocities give the full velocity vector V̂ with its first-order covariance
(``estimate_velocity``). A scan whose geometry metric m exceeds ``M_WARN`` keeps its estimate
but is *flagged* (its linear statistics may not hold); a scan whose geometry is singular has no
estimate (NaN) and a message.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.params import check_int
from radarviz.core.scenarios.multi_radar import (
    SIGMA_FIELDS,
    RadarMeasurements,
    Scenario3D,
    generate_measurements,
)
from radarviz.core.velocity.estimate import (
    FusedPosition,
    GeometryError,
    estimate_velocity,
    fuse_positions,
)


class VelocityScans(NamedTuple):
    """Per-scan results of ``estimate_scans`` (N scans, R radars).

    Attributes:
        scenario: what was measured.
        measurements: radar name → its measurements (``truth`` in each is the same target).
        n: (N,) scan numbers 1 … N; t: (N,) scan times, s.
        fused: the fused positions (``points`` (N, R, 3) each radar's converted point).
        velocity: (N, 3) V̂, m/s (NaN where the geometry is singular).
        covariance: (N, 3, 3) its first-order covariance, (m/s)².
        m: (N,) the geometry metric (NaN where singular).
        flagged: (N,) m above ``M_WARN``: the estimate is kept but not to be trusted.
        messages: (scan, text) of every flagged or singular scan, in scan order.
    """

    scenario: Scenario3D
    measurements: dict[str, RadarMeasurements]
    n: NDArray[np.int64]
    t: NDArray[np.float64]
    fused: FusedPosition
    velocity: NDArray[np.float64]
    covariance: NDArray[np.float64]
    m: NDArray[np.float64]
    flagged: NDArray[np.bool_]
    messages: list[tuple[int, str]]

    @property
    def true_position(self) -> NDArray[np.float64]:
        return self.measurements[self.scenario.radars[0].name].true_position

    @property
    def true_velocity(self) -> NDArray[np.float64]:
        return self.measurements[self.scenario.radars[0].name].true_velocity

    @property
    def sites(self) -> NDArray[np.float64]:
        return np.array([r.position for r in self.scenario.radars])

    def stacked(self, field: str) -> NDArray[np.float64]:
        """(N, R) of one measured quantity (``range``, ``azimuth``, ``elevation``,
        ``radial_velocity``) over the radars."""
        radars = self.scenario.radars
        return np.stack([getattr(self.measurements[r.name], field) for r in radars], axis=-1)


def estimate_scans(scenario: Scenario3D, scans: int, seed: int | None) -> VelocityScans:
    """Measure ``scenario`` over ``scans`` scans (noise from ``seed``; None: noise-free) and
    estimate the fused position and the velocity vector at every scan."""
    check_int("scans", scans, low=1)
    radars = scenario.radars
    period = radars[0].period_s
    meas = generate_measurements(scenario, (scans - 1) * period, seed=seed)
    first = meas[radars[0].name]
    n = np.arange(1, len(first.t) + 1)
    k = len(n)
    sites = np.array([r.position for r in radars])
    stack = {
        f: np.stack([getattr(meas[r.name], f) for r in radars], axis=-1)
        for f in ("range", "azimuth", "elevation", "radial_velocity")
    }
    sig = {f: np.array([getattr(r, f) for r in radars]) for f in SIGMA_FIELDS}
    angle_sigmas = {f: sig[f] for f in ("sigma_beta_rad", "sigma_elevation_rad")}
    fused = fuse_positions(
        sites,
        stack["range"],
        stack["azimuth"],
        stack["elevation"],
        sigma_r_m=sig["sigma_r_m"],
        **angle_sigmas,
    )
    vel = np.full((k, 3), np.nan)
    cov = np.full((k, 3, 3), np.nan)
    m = np.full(k, np.nan)
    flagged = np.zeros(k, dtype=bool)
    messages: list[tuple[int, str]] = []
    for i in range(k):
        try:
            est = estimate_velocity(
                sites,
                stack["radial_velocity"][i],
                stack["azimuth"][i],
                stack["elevation"][i],
                sigma_vr_mps=sig["sigma_vr_mps"],
                **angle_sigmas,
            )
        except GeometryError as exc:
            messages.append((int(n[i]), f"velocity at scan {n[i]}: {exc}"))
            continue
        m[i] = est.m
        vel[i], cov[i] = est.velocity, est.covariance
        if est.warning:
            flagged[i] = True
            messages.append((int(n[i]), f"velocity at scan {n[i]}: {est.warning}"))
    return VelocityScans(scenario, meas, n, first.t, fused, vel, cov, m, flagged, messages)
