"""The ``manoeuvre`` preset of ``radarviz simulate``: one flight of
``core.scenarios.manoeuvre`` seen by its three radars, as plots and radars for the files.

(The ``prosov`` and ``fusion`` presets are ``viz_app.io.plots.simulated_plots``.)
"""

from __future__ import annotations

import math

from radarviz.core.experiments.manoeuvre import flight_plots
from radarviz.core.params import check_choice
from radarviz.core.scenarios.manoeuvre import DOPPLER_RADARS, FLIGHTS, MANOEUVRE_RADARS
from radarviz.core.tracking.stream import Plot
from radarviz.viz_app.io.plots import SIM_PRESETS, Radar

#: Every preset ``simulate`` accepts.
ALL_PRESETS: tuple[str, ...] = (*SIM_PRESETS, "manoeuvre")
#: The flights the manoeuvre preset can write (``--flight``).
FLIGHT_NAMES: tuple[str, ...] = tuple(f.name for f in FLIGHTS)


def manoeuvre_radars() -> list[Radar]:
    """The scenario's radars as radars-file entries (σ in degrees; Doppler only where it is)."""
    return [
        Radar(
            s.name,
            *map(float, s.position),
            s.sigma_r_m,
            math.degrees(s.sigma_azimuth_rad),
            math.degrees(s.sigma_elevation_rad),
            s.sigma_vr_mps if s.name in DOPPLER_RADARS else None,
        )
        for s in MANOEUVRE_RADARS
    ]


def manoeuvre_file_plots(
    flight: str, seed: int, steps: int | None = None
) -> tuple[list[Plot], list[Radar]]:
    """Flight ``flight``'s plots (noise run 0 of ``seed``), angles rounded through degrees as
    the file gives them; ``steps``: scans per radar (default the whole flight)."""
    check_choice("flight", flight, FLIGHT_NAMES)
    plots, _ = flight_plots(FLIGHT_NAMES.index(flight), seed, steps, through_degrees=True)
    return plots, manoeuvre_radars()
