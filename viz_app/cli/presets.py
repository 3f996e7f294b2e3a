"""The ``manoeuvre`` and ``crossing`` presets of ``radarviz simulate``: one flight of
``core.scenarios.manoeuvre`` seen by its three radars, or one run of the crossing targets in
clutter of ``core.scenarios.crossing`` (unlabelled plots, for ``track --associate gnn``), as
plots and radars for the files.

(The ``prosov`` and ``fusion`` presets are ``viz_app.io.plots.simulated_plots``.)
"""

from __future__ import annotations

import csv
import math

import numpy as np

from radarviz.core.experiments.association import scan_plots
from radarviz.core.experiments.manoeuvre import flight_plots
from radarviz.core.params import check_choice
from radarviz.core.scenarios.crossing import CrossingScene
from radarviz.core.scenarios.manoeuvre import DOPPLER_RADARS, FLIGHTS, MANOEUVRE_RADARS
from radarviz.core.tracking.stream import Plot
from radarviz.viz_app.io.plots import SIM_PRESETS, Radar, atomic_text

#: Every preset ``simulate`` accepts.
ALL_PRESETS: tuple[str, ...] = (*SIM_PRESETS, "manoeuvre", "crossing")
#: Columns of the crossing preset's truth file (``simulate --truth-out``).
TRUTH_COLUMNS = ("time_s", "target", "x_m", "y_m", "vx_mps", "vy_mps")
#: The flights the manoeuvre preset can write (``--flight``).
FLIGHT_NAMES: tuple[str, ...] = tuple(f.name for f in FLIGHTS)


def manoeuvre_radars() -> list[Radar]:
    """The scenario's radars as radars-file entries (σ in degrees; Doppler only where it is)."""
    return [
        Radar(
            s.name,
            *map(float, s.position),
            s.sigma_r_m,
            math.degrees(s.sigma_beta_rad),
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


def crossing_file_plots(scene: CrossingScene, seed: int) -> tuple[list[Plot], list[Radar]]:
    """Run 0 of ``seed`` of the crossing scene (``core.experiments.association.scan_plots``,
    the reproduction's run 0), angles rounded through degrees as the file gives them, no
    target labels; its one radar "radar" at the origin."""
    scans = scan_plots(scene, np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0]))
    plots = [
        Plot(
            p.time_s,
            p.range_m,
            math.radians(math.degrees(p.azimuth_rad)),
            p.sigma_r_m,
            math.radians(scene.sigma_beta_deg),
            radar=p.radar,
        )
        for scan in scans
        for p in scan
    ]
    return plots, [Radar("radar", 0.0, 0.0, 0.0, scene.sigma_r_m, scene.sigma_beta_deg)]


def write_crossing_truth(path: str, scene: CrossingScene) -> int:
    """The scene's true states per scan and target as CSV (``TRUTH_COLUMNS``, target
    labels "0", "1", …); returns rows. Join ``commit_together`` with the plots' files."""
    truth = scene.truth()
    with atomic_text(path) as fh:
        w = csv.writer(fh)
        w.writerow(TRUTH_COLUMNS)
        for t, states in zip(scene.times_s, truth, strict=True):
            for i, (x, vx, y, vy) in enumerate(states):
                w.writerow([float(t), str(i), float(x), float(y), float(vx), float(vy)])
    return int(truth.shape[0] * truth.shape[1])
