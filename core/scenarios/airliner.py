"""Airliners seen by one rotating radar: straight legs joined by coordinated turns, the test
scene of the IMM's consistency in turns (``core.experiments.turns``, ``docs/manoeuvre.md``).

Four flight plans (:data:`AIRLINER_FLIGHTS`, 900 s each) at 160–250 m/s and 3–10 km altitude,
each a sequence of straight legs (some with a gentle climb, descent or speed change) and
coordinated turns at 1.5–3°/s (``core.scenarios.manoeuvre.Leg``: constant speed and turn
rate, a horizontal acceleration of v ω ≈ 5.5–13 m/s²) through 60–180°. They are flown by
``core.scenarios.manoeuvre.fly`` on its 0.1 s grid.

One radar (:data:`AIRLINER_RADAR`) at the origin, 27–128 km from the flights: a rotating
3D surveillance radar with σr = 50 m, σβ = 0.15°, σε = 0.3° and a scan period of 4.5 s (the
revisit of one target), no Doppler. At 100 km σβ is 260 m across the line of sight.

:func:`turn_mask` marks the plots taken inside a turn leg, the segments where the IMM's
consistency is judged.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from radarviz.core.scenarios.manoeuvre import Flight, Leg, PlotSchedule
from radarviz.core.scenarios.multi_radar import RadarSite

_DEG = math.radians(1.0)

#: The flight plans (module docstring).
AIRLINER_FLIGHTS: tuple[Flight, ...] = (
    Flight(
        "arrival",
        (80e3, 40e3, 9000.0),
        math.radians(200.0),
        240.0,
        0.0,
        (
            Leg(150.0),
            Leg(30.0, -3.0 * _DEG),
            Leg(200.0, accel_mps2=-0.15, climb_mps=-8.0),
            Leg(60.0, 1.5 * _DEG, climb_mps=-8.0),
            Leg(160.0, climb_mps=-5.0),
            Leg(60.0, -3.0 * _DEG),
            Leg(240.0),
        ),
    ),
    Flight(
        "departure",
        (-40e3, -55e3, 3000.0),
        math.radians(20.0),
        160.0,
        10.0,
        (
            Leg(120.0, accel_mps2=0.3, climb_mps=10.0),
            Leg(60.0, 2.0 * _DEG, climb_mps=10.0),
            Leg(200.0, accel_mps2=0.1, climb_mps=8.0),
            Leg(90.0, -2.0 * _DEG),
            Leg(430.0),
        ),
    ),
    Flight(
        "en-route",
        (-90e3, 90e3, 10000.0),
        math.radians(-20.0),
        250.0,
        0.0,
        (
            Leg(200.0),
            Leg(40.0, 1.5 * _DEG),
            Leg(250.0),
            Leg(60.0, -2.5 * _DEG),
            Leg(350.0),
        ),
    ),
    Flight(
        "vectoring",
        (50e3, -70e3, 5000.0),
        math.radians(90.0),
        180.0,
        0.0,
        (
            Leg(120.0),
            Leg(60.0, 3.0 * _DEG),
            Leg(100.0),
            Leg(30.0, -3.0 * _DEG),
            Leg(120.0, climb_mps=-5.0),
            Leg(90.0, 2.0 * _DEG),
            Leg(380.0),
        ),
    ),
)

#: The radar of the scene (module docstring).
AIRLINER_RADAR = RadarSite(
    "surveillance",
    (0.0, 0.0, 30.0),
    sigma_r_m=50.0,
    sigma_beta_rad=math.radians(0.15),
    sigma_elevation_rad=math.radians(0.3),
    sigma_vr_mps=0.0,
    period_s=4.5,
)


def turn_mask(schedule: PlotSchedule, flights: tuple[Flight, ...]) -> NDArray[np.bool_]:
    """(N, F): whether plot n of flight f is taken inside one of its turn legs (a leg with
    ω ≠ 0; the plot at a leg's first instant belongs to that leg)."""
    out = np.zeros((schedule.time_s.size, len(flights)), dtype=bool)
    for f, flight in enumerate(flights):
        t0 = 0.0
        for leg in flight.legs:
            t1 = t0 + leg.duration_s
            if leg.turn_rate_radps != 0.0:
                out[:, f] |= (schedule.time_s >= t0) & (schedule.time_s < t1)
            t0 = t1
    return out
