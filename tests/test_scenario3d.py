"""The 3D multi-radar scenario: piecewise manoeuvring truth and per-radar seeded measurements."""

from __future__ import annotations

import math

import numpy as np
import pytest

from radarviz.core.params import ParameterError
from radarviz.core.scenarios.multi_radar import (
    RadarSite,
    Scenario3D,
    Segment,
    Trajectory3D,
    generate_measurements,
    polar_measurement,
)
from radarviz.core.velocity.estimate import estimate_velocity

DEG = math.pi / 180.0


def _sigmas(r_m: float, az_deg: float, el_deg: float, vr_mps: float) -> dict[str, float]:
    return {
        "sigma_r_m": r_m,
        "sigma_beta_rad": az_deg * DEG,
        "sigma_elevation_rad": el_deg * DEG,
        "sigma_vr_mps": vr_mps,
    }


RADARS = (
    RadarSite("A", (0.0, 0.0, 0.0), **_sigmas(50.0, 0.1, 0.2, 1.0), period_s=5.0),
    RadarSite("B", (80e3, 0.0, 0.0), **_sigmas(100.0, 0.3, 0.5, 3.0), period_s=10.0),
    RadarSite("C", (40e3, 70e3, 0.0), **_sigmas(150.0, 0.5, 1.0, 5.0), period_s=5.0, t0_s=2.5),
)
TRAJ = Trajectory3D(
    (40e3, 30e3, 10e3),
    (216.5, 125.0, 5.0),
    (Segment(60.0), Segment(90.0, turn_rate=2.0 * DEG), Segment(60.0)),
)
SCEN = Scenario3D(RADARS, TRAJ)


def test_noise_free_measurements_invert_to_the_truth() -> None:
    meas = generate_measurements(SCEN, 200.0, seed=None)
    assert [m.t.size for m in meas.values()] == [41, 21, 40]  # own periods and phases
    for m in meas.values():
        ce = np.cos(m.elevation)
        los = np.stack([ce * np.cos(m.azimuth), ce * np.sin(m.azimuth), np.sin(m.elevation)], -1)
        pos = np.asarray(m.radar.position) + m.range[:, None] * los
        np.testing.assert_allclose(pos, m.true_position, atol=1e-6)
        np.testing.assert_allclose(np.sum(los * m.true_velocity, -1), m.radial_velocity, atol=1e-9)
    # Where the three radars scan together, their radial velocities give the full velocity.
    a, b = meas["A"], meas["B"]
    common = np.intersect1d(a.t, b.t)[3]
    rows = [np.flatnonzero(m.t == common)[0] for m in (a, b)]
    c_pos, c_vel = TRAJ.state(np.array([common]))
    _, azc, elc, vrc = polar_measurement(RADARS[2].position, c_pos[0], c_vel[0])
    est = estimate_velocity(
        np.array([r.position for r in RADARS]),
        [a.radial_velocity[rows[0]], b.radial_velocity[rows[1]], vrc],
        [a.azimuth[rows[0]], b.azimuth[rows[1]], azc],
        [a.elevation[rows[0]], b.elevation[rows[1]], elc],
        sigma_vr_mps=1.0,
        sigma_beta_rad=0.01,
        sigma_elevation_rad=0.01,
    )
    np.testing.assert_allclose(est.velocity, c_vel[0], atol=1e-8)


def test_turn_keeps_speed_and_turns_by_rate_times_duration() -> None:
    t = np.linspace(0.0, 250.0, 501)
    pos, vel = TRAJ.state(t)
    speed = np.linalg.norm(vel, axis=-1)
    np.testing.assert_allclose(speed, speed[0], rtol=1e-12)
    heading = np.unwrap(np.arctan2(vel[:, 1], vel[:, 0]))
    assert heading[-1] - heading[0] == pytest.approx(90.0 * 2.0 * DEG, rel=1e-9)
    # Continuity, and position is the integral of velocity (trapezoid on a fine grid).
    step = np.diff(pos, axis=0)
    np.testing.assert_allclose(
        step, 0.5 * (vel[1:] + vel[:-1]) * np.diff(t)[:, None], rtol=1e-4, atol=1e-3
    )


def test_measurements_are_seeded_and_noisy() -> None:
    m1 = generate_measurements(SCEN, 100.0, seed=3)
    m2 = generate_measurements(SCEN, 100.0, seed=3)
    m3 = generate_measurements(SCEN, 100.0, seed=4)
    assert np.array_equal(m1["B"].range, m2["B"].range)
    assert not np.array_equal(m1["B"].range, m3["B"].range)
    err = m1["A"].range - np.linalg.norm(m1["A"].true_position, axis=-1)
    assert 0 < np.std(err) < 5 * RADARS[0].sigma_r_m


def test_bad_scenarios_raise_one_line() -> None:
    with pytest.raises(
        ParameterError, match=r"period_s must be a finite number in \[0.001, 3600\]"
    ):
        RadarSite("X", (0.0, 0.0, 0.0), **_sigmas(1.0, 0.5, 0.5, 1.0), period_s=0.0)
    with pytest.raises(TypeError):  # the accuracies are keyword-only: no silent swap
        RadarSite("X", (0.0, 0.0, 0.0), 1.0, 0.01, 0.01, 1.0, 10.0)  # type: ignore[misc]
    with pytest.raises(ParameterError, match="unique"):
        Scenario3D((RADARS[0], RADARS[0]), TRAJ)
    with pytest.raises(ParameterError, match="times must be"):
        TRAJ.state([-1.0])
