"""Manoeuvring aircraft seen by several radars: the scenario of ``simulate --preset manoeuvre``
and ``reproduce manoeuvre``.

A flight is a start (position, heading, ground speed, vertical speed) and a list of legs; each
:class:`Leg` holds for ``duration_s`` a turn rate ω (rad/s, positive counter-clockwise from x
towards y), an along-track acceleration a (m/s²) and a commanded vertical speed that the
aircraft reaches at ``VERTICAL_ACCEL_MPS2`` (so climbs and descents start and end smoothly).
The flight plans (:data:`FLIGHTS`) are what an approach or en-route sector sees: standard-rate
turns (3°/s, ``STANDARD_RATE_RADPS``) and half-rate turns (1.5°/s, an airliner at 25° bank),
climbs and descents at 5–15 m/s, accelerations and decelerations of 0.5–1 m/s² between
140 and 280 m/s, at 1.4–11 km altitude. The plans are written for this project (no recorded
trajectories are shipped).

The truth is integrated on a grid of ``STEP_S`` = 0.1 s: over one step the heading turns by
ω·dt and the speed changes by a·dt, and the position advances along the mid-step velocity
(second order in dt: the error against the exact arc is below 1 mm per step at 250 m/s and
3°/s). Every radar's scan phase is a multiple of the step, so plot times fall on the grid.

Radars (:data:`MANOEUVRE_RADARS`): three 3D sites 63–142 km apart, none within 20 km
horizontally of any flight (the cone above a radar is blind), σr = 60 m, σβ = 0.15°,
σε = 0.3°, T = 5 s, scans staggered by 1.7 s; the third also measures radial velocity
(σVr = 1 m/s). Plot j of radar k is (r, β, ε[, Vr]) of the truth at t0_k + j T plus Gaussian
noise; the noise of run i comes from child i of ``SeedSequence(seed)`` (runs are
independent, flights share the noise stream of a run).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.params import check, check_int
from radarviz.core.scenarios.multi_radar import RadarSite, polar_measurement

#: The truth's integration step, s (every scan time is a multiple of it).
STEP_S = 0.1
#: A standard-rate turn, 3°/s (rad/s).
STANDARD_RATE_RADPS = math.radians(3.0)
#: How fast the vertical speed follows its command, m/s².
VERTICAL_ACCEL_MPS2 = 1.0


class Leg(NamedTuple):
    """A piece of a flight plan: for ``duration_s`` s, turn at ``turn_rate_radps``,
    accelerate along track at ``accel_mps2`` and steer the vertical speed to ``climb_mps``."""

    duration_s: float
    turn_rate_radps: float = 0.0
    accel_mps2: float = 0.0
    climb_mps: float = 0.0


class Flight(NamedTuple):
    """A flight plan: start position (m), heading (rad from x towards y), ground speed (m/s),
    vertical speed (m/s), then its legs."""

    name: str
    position_m: tuple[float, float, float]
    heading_rad: float
    speed_mps: float
    climb_mps: float
    legs: tuple[Leg, ...]

    @property
    def duration_s(self) -> float:
        return float(sum(leg.duration_s for leg in self.legs))


_HALF_RATE = STANDARD_RATE_RADPS / 2.0

#: The flight plans, 1200 s each (240 scans of every radar).
FLIGHTS: tuple[Flight, ...] = (
    Flight(
        "approach",
        (90e3, 60e3, 6000.0),
        math.radians(200.0),
        230.0,
        0.0,
        (
            Leg(150.0),
            Leg(60.0, -STANDARD_RATE_RADPS, climb_mps=-10.0),
            Leg(240.0, accel_mps2=-0.3, climb_mps=-8.0),
            Leg(30.0, STANDARD_RATE_RADPS, climb_mps=-5.0),
            Leg(300.0, climb_mps=-5.0),
            Leg(60.0, -STANDARD_RATE_RADPS, accel_mps2=-0.25),
            Leg(360.0),
        ),
    ),
    Flight(
        "departure",
        (10e3, -20e3, 3000.0),
        math.radians(30.0),
        150.0,
        12.0,
        (
            Leg(200.0, accel_mps2=0.3, climb_mps=15.0),
            Leg(90.0, _HALF_RATE, climb_mps=12.0),
            Leg(250.0, accel_mps2=0.1, climb_mps=8.0),
            Leg(120.0, -_HALF_RATE, climb_mps=5.0),
            Leg(540.0, climb_mps=0.0),
        ),
    ),
    Flight(
        "holding",
        (40e3, 80e3, 5000.0),
        math.radians(0.0),
        200.0,
        0.0,
        (
            Leg(120.0),
            Leg(60.0, STANDARD_RATE_RADPS),
            Leg(120.0),
            Leg(60.0, STANDARD_RATE_RADPS),
            Leg(120.0, climb_mps=-5.0),
            Leg(60.0, STANDARD_RATE_RADPS, climb_mps=-5.0),
            Leg(120.0),
            Leg(60.0, STANDARD_RATE_RADPS),
            Leg(480.0, accel_mps2=0.1),
        ),
    ),
    Flight(
        "en-route",
        (-40e3, 20e3, 11000.0),
        math.radians(10.0),
        250.0,
        0.0,
        (
            Leg(300.0),
            Leg(40.0, _HALF_RATE),
            Leg(200.0, accel_mps2=-0.2),
            Leg(300.0, climb_mps=-12.0),
            Leg(80.0, -_HALF_RATE, climb_mps=-12.0),
            Leg(280.0, accel_mps2=-0.1, climb_mps=0.0),
        ),
    ),
    Flight(
        "s-turns",
        (100e3, -10e3, 4000.0),
        math.radians(120.0),
        180.0,
        0.0,
        (
            Leg(100.0),
            Leg(40.0, STANDARD_RATE_RADPS),
            Leg(40.0, -STANDARD_RATE_RADPS),
            Leg(100.0, accel_mps2=1.0),
            Leg(40.0, -STANDARD_RATE_RADPS),
            Leg(40.0, STANDARD_RATE_RADPS),
            Leg(200.0, accel_mps2=-1.0 / 3.0, climb_mps=10.0),
            Leg(60.0, STANDARD_RATE_RADPS, climb_mps=10.0),
            Leg(580.0, climb_mps=0.0),
        ),
    ),
    Flight(
        "go-around",
        (70e3, 30e3, 3500.0),
        math.radians(250.0),
        160.0,
        -6.0,
        (
            Leg(240.0, accel_mps2=-0.05, climb_mps=-6.0),
            Leg(60.0, accel_mps2=0.8, climb_mps=12.0),
            Leg(60.0, STANDARD_RATE_RADPS, climb_mps=12.0),
            Leg(120.0, accel_mps2=0.2, climb_mps=6.0),
            Leg(60.0, STANDARD_RATE_RADPS, climb_mps=0.0),
            Leg(300.0, climb_mps=-5.0),
            Leg(60.0, STANDARD_RATE_RADPS, accel_mps2=-0.3),
            Leg(300.0, climb_mps=-4.0),
        ),
    ),
)

#: The radars of the scenario (see the module docstring); the third has Doppler.
MANOEUVRE_RADARS: tuple[RadarSite, ...] = tuple(
    RadarSite(
        name,
        site,
        sigma_r_m=60.0,
        sigma_beta_rad=math.radians(0.15),
        sigma_elevation_rad=math.radians(0.3),
        sigma_vr_mps=vr,
        period_s=5.0,
        t0_s=t0,
    )
    for name, site, vr, t0 in (
        ("north", (20e3, 60e3, 50.0), 0.0, 0.0),
        ("south", (0.0, 0.0, 20.0), 0.0, 1.7),
        ("east", (130e3, -30e3, 100.0), 1.0, 3.4),
    )
)
#: Which radars report radial velocity.
DOPPLER_RADARS: tuple[str, ...] = ("east",)


class FlightTruth(NamedTuple):
    """A flight on the integration grid: times (K,), positions and velocities (K, 3)."""

    time_s: NDArray[np.float64]
    position_m: NDArray[np.float64]
    velocity_mps: NDArray[np.float64]


def fly(flight: Flight) -> FlightTruth:
    """Integrate a flight plan on the ``STEP_S`` grid (module docstring)."""
    steps = round(flight.duration_s / STEP_S)
    pos = np.empty((steps + 1, 3))
    vel = np.empty((steps + 1, 3))
    p = np.array(flight.position_m, dtype=np.float64)
    heading, speed, vz = flight.heading_rad, flight.speed_mps, flight.climb_mps
    dt = STEP_S
    k = 0
    bounds = np.cumsum([round(leg.duration_s / STEP_S) for leg in flight.legs])
    for leg_index, end in enumerate(bounds):
        leg = flight.legs[leg_index]
        while k < end:
            pos[k] = p
            vel[k] = (speed * math.cos(heading), speed * math.sin(heading), vz)
            # Mid-step velocity: heading, speed and climb half-way through the step.
            dvz = float(
                np.clip(leg.climb_mps - vz, -VERTICAL_ACCEL_MPS2 * dt, VERTICAL_ACCEL_MPS2 * dt)
            )
            h_mid = heading + 0.5 * leg.turn_rate_radps * dt
            s_mid = speed + 0.5 * leg.accel_mps2 * dt
            p = p + dt * np.array(
                (s_mid * math.cos(h_mid), s_mid * math.sin(h_mid), vz + 0.5 * dvz)
            )
            heading += leg.turn_rate_radps * dt
            speed += leg.accel_mps2 * dt
            vz += dvz
            k += 1
    pos[k] = p
    vel[k] = (speed * math.cos(heading), speed * math.sin(heading), vz)
    return FlightTruth(np.arange(steps + 1) * STEP_S, pos, vel)


class PlotSchedule(NamedTuple):
    """Every radar's scans of the scenario merged in time order (ties: radar order).

    Attributes:
        time_s: (N,) plot times.  radar: (N,) index into ``radars``.  grid: (N,) index of the
        plot time on the truth grid.  radars: the radars.
    """

    time_s: NDArray[np.float64]
    radar: NDArray[np.int64]
    grid: NDArray[np.int64]
    radars: tuple[RadarSite, ...]


def plot_schedule(
    duration_s: float, radars: tuple[RadarSite, ...] = MANOEUVRE_RADARS
) -> PlotSchedule:
    """The scan times t0_k + j T_k ≤ ``duration_s`` of every radar, merged (module docstring)."""
    times, which = [], []
    for k, r in enumerate(radars):
        n = math.floor((duration_s - r.t0_s) / r.period_s + 1e-9) + 1
        times.append(r.t0_s + r.period_s * np.arange(n))
        which.append(np.full(n, k))
    t = np.concatenate(times)
    w = np.concatenate(which)
    order = np.lexsort((w, t))
    t, w = t[order], w[order]
    return PlotSchedule(t, w, np.rint(t / STEP_S).astype(np.int64), radars)


class ManoeuvrePlots(NamedTuple):
    """Noisy plots of F flights × M runs, on one schedule of N plots.

    Attributes:
        schedule: the N plot times and radars.
        range_m, azimuth_rad, elevation_rad, radial_velocity_mps: (N, F, M) measured values
            (radial velocity NaN for a radar without Doppler).
        true_position_m, true_velocity_mps: (N, F, 3) truth at the plot times.
        doppler: (N,) whether plot n carries a radial velocity.
    """

    schedule: PlotSchedule
    range_m: NDArray[np.float64]
    azimuth_rad: NDArray[np.float64]
    elevation_rad: NDArray[np.float64]
    radial_velocity_mps: NDArray[np.float64]
    true_position_m: NDArray[np.float64]
    true_velocity_mps: NDArray[np.float64]
    doppler: NDArray[np.bool_]


def manoeuvre_plots(
    runs: int = 1,
    seed: int = 1,
    flights: tuple[Flight, ...] = FLIGHTS,
    radars: tuple[RadarSite, ...] = MANOEUVRE_RADARS,
    steps: int | None = None,
) -> ManoeuvrePlots:
    """Noisy plots of every flight, ``runs`` noise realisations each (module docstring).

    ``steps``: scans of each radar to keep (default: the whole flight).
    """
    runs = check_int("runs", runs, low=1)
    seed = int(check("seed", seed))
    duration = min(f.duration_s for f in flights)
    if steps is not None:
        # The fastest radar's scans of the whole flight: more would be a longer flight than
        # the scene has, so they are refused rather than silently cut to it.
        period_s = min(r.period_s for r in radars)
        whole = math.floor(duration / period_s + 1e-9) + 1
        steps = check_int("steps", steps, low=2, high=whole)
        duration = min(duration, (steps - 1) * period_s)
    sched = plot_schedule(duration, radars)
    truths = [fly(f) for f in flights]
    tp = np.stack([tr.position_m[sched.grid] for tr in truths], axis=1)  # (N, F, 3)
    tv = np.stack([tr.velocity_mps[sched.grid] for tr in truths], axis=1)
    sites = np.array([r.position for r in radars], dtype=np.float64)[sched.radar]  # (N, 3)
    r, az, el, vr = polar_measurement(sites[:, None, :], tp, tv)  # (N, F)
    sig = np.array(
        [[x.sigma_r_m, x.sigma_beta_rad, x.sigma_elevation_rad, x.sigma_vr_mps] for x in radars]
    )[sched.radar]  # (N, 4)
    n, f = r.shape
    noise = np.stack(
        [
            np.random.default_rng(child).standard_normal((4, n, f))
            for child in np.random.SeedSequence(seed).spawn(runs)
        ],
        axis=-1,
    )  # (4, N, F, M)
    doppler = np.array([radars[k].name in DOPPLER_RADARS for k in sched.radar])
    meas = [v[..., None] + sig[:, i, None, None] * noise[i] for i, v in enumerate((r, az, el, vr))]
    meas[3][~doppler] = np.nan
    return ManoeuvrePlots(sched, *meas, tp, tv, doppler)
