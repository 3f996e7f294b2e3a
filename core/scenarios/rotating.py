"""Air traffic seen by rotating radars: the layout of a real multi-radar plot stream.

Each radar's antenna turns at its own period T_j with its own phase, and stamps each plot
when its beam passes the target, so a time-ordered file of several radars is a stream of
short runs of one radar, each plot with its own time (no synchronous scans). Each radar
covers only ranges up to its ``max_range_m``: a target outside one radar's coverage is seen
by the others only.

* **Radars** (``RotatingRadar``): site, period, phase (the beam's azimuth at t = 0), rotation
  sense (real antennas turn clockwise seen from above: azimuth, counter-clockwise from the x
  axis, decreasing), coverage, accuracies, detection probability P_D and false plots per
  revolution λ (uniform in range within the coverage and in azimuth, what a CFAR detector
  gives).
* **Targets** (``air_traffic``): straight legs at constant speed joined by coordinated turns,
  drawn per target: start on a circle, heading towards a point near the centre (or, en
  route, anywhere in the disc with any heading), speed in [v_min, v_max], a turn of
  ``turn_deg`` at ``turn_rate_dps`` half way.
* **Stamping.** The beam's azimuth is θ(t) = θ₀ + d ω t (d = ±1, ω = 2π / T). In revolution
  n the beam passes a target at the time t with θ(t) ≡ β(p(t)) (mod 2π), found by the
  fixed point t ← t_n + ((d (β(p(t)) − θ(t_n))) mod 2π) / ω from the revolution's start
  t_n (three iterations: the target's azimuth moves a few milliradians per revolution).
  Each crossing inside the coverage is detected with probability P_D; the plot is the true
  (r, β) plus Gaussian noise (σr, σβ).

Pure numpy; every draw from the caller's ``numpy.random.Generator``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

#: ``RotatingPlots.origin`` of a false plot.
CLUTTER = -1


@dataclass(frozen=True)
class RotatingRadar:
    """One rotating 2D radar (module docstring). Distances m, angles rad, time s."""

    name: str
    x_m: float
    y_m: float
    period_s: float = 4.0
    phase_rad: float = 0.0
    clockwise: bool = True
    max_range_m: float = 80e3
    min_range_m: float = 500.0
    sigma_r_m: float = 50.0
    sigma_beta_rad: float = math.radians(0.15)
    detection_prob: float = 0.9
    clutter_per_turn: float = 5.0

    @property
    def site(self) -> NDArray[np.float64]:
        return np.array([self.x_m, self.y_m])

    def beam(self, time_s: NDArray[np.float64]) -> NDArray[np.float64]:
        """θ(t), the beam's azimuth (unwrapped)."""
        d = -1.0 if self.clockwise else 1.0
        return self.phase_rad + d * (2 * math.pi / self.period_s) * time_s


class Traffic(NamedTuple):
    """Targets' truth sampled every ``step_s``: times (N,), positions (N, K, 2), velocities
    (N, K, 2)."""

    times_s: NDArray[np.float64]
    position_m: NDArray[np.float64]
    velocity_mps: NDArray[np.float64]

    def at(self, t: NDArray[np.float64], k: NDArray[np.intp]) -> NDArray[np.float64]:
        """Positions of targets ``k`` at times ``t`` (M,) each: (M, 2), linear between
        samples."""
        step = self.times_s[1] - self.times_s[0]
        i = np.clip(((t - self.times_s[0]) / step).astype(np.intp), 0, self.times_s.size - 2)
        w = ((t - self.times_s[i]) / step)[:, None]
        return (1 - w) * self.position_m[i, k] + w * self.position_m[i + 1, k]


def air_traffic(
    rng: np.random.Generator,
    targets: int,
    duration_s: float,
    radius_m: float = 60e3,
    speed_mps: tuple[float, float] = (150.0, 250.0),
    turn_deg: float = 60.0,
    turn_rate_dps: float = 1.5,
    step_s: float = 0.1,
    en_route: bool = False,
) -> Traffic:
    """Straight legs with one coordinated turn each (module docstring); ``en_route``: each
    target starts anywhere in the disc of ``radius_m`` (uniform in area) with any heading,
    traffic already under way, instead of on the disc's rim heading inwards (which packs
    many targets into one ring at the start)."""
    n = math.ceil(duration_s / step_s) + 1
    t = np.arange(n) * step_s
    start_angle = rng.uniform(0, 2 * math.pi, targets)
    start = radius_m * np.stack([np.cos(start_angle), np.sin(start_angle)], -1)
    aim = rng.uniform(-0.3, 0.3, (targets, 2)) * radius_m
    heading = np.arctan2(aim[:, 1] - start[:, 1], aim[:, 0] - start[:, 0])
    if en_route:
        start = start * np.sqrt(rng.uniform(0.0, 1.0, targets))[:, None]
        heading = rng.uniform(0, 2 * math.pi, targets)
    speed = rng.uniform(*speed_mps, targets)
    sense = rng.choice([-1.0, 1.0], targets)
    turn_time = math.radians(turn_deg) / math.radians(turn_rate_dps)
    t_turn = rng.uniform(0.3, 0.6, targets) * duration_s
    # Heading over time: constant, then a ramp at the turn rate, then constant.
    ramp = np.clip(t[:, None] - t_turn[None, :], 0.0, turn_time)
    psi = heading[None, :] + sense[None, :] * math.radians(turn_rate_dps) * ramp
    vel = speed[None, :, None] * np.stack([np.cos(psi), np.sin(psi)], -1)
    pos = start[None] + np.concatenate(
        [np.zeros((1, targets, 2)), np.cumsum(0.5 * (vel[1:] + vel[:-1]) * step_s, axis=0)]
    )
    return Traffic(t, pos, vel)


class RotatingPlots(NamedTuple):
    """Every radar's plots merged in time order, (P,) each: time, radar index, range,
    azimuth (rad, counter-clockwise from x), and origin (target index, or ``CLUTTER``)."""

    time_s: NDArray[np.float64]
    radar: NDArray[np.intp]
    range_m: NDArray[np.float64]
    azimuth_rad: NDArray[np.float64]
    origin: NDArray[np.intp]


def _crossings(
    radar: RotatingRadar, traffic: Traffic, duration_s: float
) -> tuple[NDArray, NDArray]:
    """(time, target) of every beam crossing of every target within the duration."""
    T = radar.period_s
    omega = 2 * math.pi / T
    d = -1.0 if radar.clockwise else 1.0
    turns = np.arange(int(duration_s / T) + 1)
    k_all = traffic.position_m.shape[1]
    t0 = np.repeat(turns * T, k_all)
    k = np.tile(np.arange(k_all), turns.size)
    t = t0.copy()
    theta0 = radar.beam(t0)
    for _ in range(3):
        p = traffic.at(np.minimum(t, duration_s), k) - radar.site
        beta = np.arctan2(p[:, 1], p[:, 0])
        t = t0 + np.mod(d * (beta - theta0), 2 * math.pi) / omega
    keep = t < duration_s
    return t[keep], k[keep]


def rotating_plots(
    rng: np.random.Generator,
    radars: list[RotatingRadar],
    traffic: Traffic,
    duration_s: float,
) -> RotatingPlots:
    """The radars' plots of ``traffic`` over ``duration_s`` (module docstring)."""
    parts = []
    for j, radar in enumerate(radars):
        t, k = _crossings(radar, traffic, duration_s)
        p = traffic.at(t, k) - radar.site
        r = np.hypot(p[:, 0], p[:, 1])
        b = np.arctan2(p[:, 1], p[:, 0])
        seen = (r >= radar.min_range_m) & (r <= radar.max_range_m)
        seen &= rng.random(t.size) < radar.detection_prob
        t, k, r, b = t[seen], k[seen], r[seen], b[seen]
        r = r + radar.sigma_r_m * rng.standard_normal(r.size)
        b = b + radar.sigma_beta_rad * rng.standard_normal(b.size)
        # False plots: Poisson(λ) per revolution, uniform in range and azimuth, stamped
        # when the beam passes their azimuth.
        turns = int(duration_s / radar.period_s) + 1
        n_false = rng.poisson(radar.clutter_per_turn, turns)
        turn = np.repeat(np.arange(turns), n_false)
        frac = rng.random(turn.size)
        tf = (turn + frac) * radar.period_s
        bf = radar.beam(tf)
        rf = rng.uniform(radar.min_range_m, radar.max_range_m, turn.size)
        kf = tf < duration_s
        parts.append(
            (
                np.r_[t, tf[kf]],
                np.full(t.size + int(kf.sum()), j),
                np.r_[r, rf[kf]],
                np.r_[b, bf[kf]],
                np.r_[k, np.full(int(kf.sum()), CLUTTER)],
            )
        )
    cols = [np.concatenate(c) for c in zip(*parts, strict=True)]
    order = np.argsort(cols[0], kind="stable")
    time_s, radar_i, range_m, az, origin = (c[order] for c in cols)
    az = np.mod(az + math.pi, 2 * math.pi) - math.pi
    return RotatingPlots(time_s, radar_i.astype(np.intp), range_m, az, origin.astype(np.intp))
