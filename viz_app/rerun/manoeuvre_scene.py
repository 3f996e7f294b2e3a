"""The manoeuvre scene: one manoeuvring flight tracked with the papers' Q = 0 and the IMM,
and what the consistency monitor sees (``core.experiments.manoeuvre.track_flight``).

Entity paths (timeline ``scan`` = plot number 1, 2, …, and ``time``)::

    manoeuvre/map/radars                  radar sites (static)
    manoeuvre/map/truth/path              the flight (static strip)
    manoeuvre/map/scale                   the scale bar and its length (static)
    manoeuvre/map/truth/position          the aircraft, per plot
    manoeuvre/map/plots                   each plot's naive converted point, per plot
    manoeuvre/map/tracks/{model}/position the model's track position, per plot
    manoeuvre/map/tracks/{model}/path     its path (static strip)
    plots/manoeuvre/error_m/{model}       |x̂ − x|, m, per plot
    plots/manoeuvre/nis/{model}           windowed NIS per degree of freedom, per window
    plots/manoeuvre/nis/band_lo, band_hi  its 95% χ² band (the IMM's windows)
    log                                   the monitor's band exits and returns

``{model}`` is ``cv-q0`` or ``imm``; the flight is ``s-turns`` (two pairs of standard-rate
reversals, a speed change and a climbing turn).
"""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from radarviz.core.experiments.manoeuvre import FlightTracks, track_flight
from radarviz.core.scenarios.manoeuvre import FLIGHTS, MANOEUVRE_RADARS
from radarviz.viz_app.palette import radar_rgb_avoiding, rgb
from radarviz.viz_app.rerun import plot2d
from radarviz.viz_app.rerun.recording import log_series, log_text
from radarviz.viz_app.rerun.shapes import MARKER, SMALL_MARKER, THIN_LINE, colours, radii

ROOT = "manoeuvre"
#: The flight the scene shows (an index into ``FLIGHTS``).
FLIGHT = 4


def log_manoeuvre(rec: rr.RecordingStream, seed: int = 1) -> FlightTracks:
    """Track the flight and log it (module docstring); returns what was logged."""
    ft = track_flight(FLIGHT, seed)
    n = ft.time_s.size
    scans = np.arange(1, n + 1)
    at = [rr.TimeColumn("scan", sequence=scans), rr.TimeColumn("time", duration=ft.time_s)]
    # Radars in colours the motion models do not use.
    models = [rgb(label) for label in ft.estimates]
    tone = [radar_rgb_avoiding(j, models) for j in range(len(MANOEUVRE_RADARS))]
    rec.log(
        f"{ROOT}/map/radars",
        rr.Points3D(
            [r.position for r in MANOEUVRE_RADARS],
            radii=[MARKER],
            colors=tone,
            labels=[r.name for r in MANOEUVRE_RADARS],
        ),
        static=True,
    )
    rec.log(
        f"{ROOT}/map/truth/path",
        rr.LineStrips3D([ft.truth_m], colors=[rgb("truth")], radii=[THIN_LINE]),
        static=True,
    )
    sites = np.array([r.position for r in MANOEUVRE_RADARS], dtype=float)
    plot2d.log_scale_bar_3d(rec, f"{ROOT}/map/scale", np.concatenate([sites, ft.truth_m]))
    rec.send_columns(
        f"{ROOT}/map/truth/position",
        indexes=at,
        columns=rr.Points3D.columns(
            positions=ft.truth_m, colors=colours(rgb("truth"), n), radii=radii(MARKER, n)
        ),
    )
    rec.send_columns(
        f"{ROOT}/map/plots",
        indexes=at,
        columns=rr.Points3D.columns(
            positions=ft.measured_m,
            colors=np.array([tone[int(k)] for k in ft.radar], dtype=np.uint8),
            radii=radii(SMALL_MARKER, n),
        ),
    )
    for label, x in ft.estimates.items():
        c = rgb(label)
        rec.send_columns(
            f"{ROOT}/map/tracks/{label}/position",
            indexes=at,
            columns=rr.Points3D.columns(positions=x, colors=colours(c, n), radii=radii(MARKER, n)),
        )
        rec.log(
            f"{ROOT}/map/tracks/{label}/path",
            rr.LineStrips3D([x], colors=[c], radii=[THIN_LINE]),
            static=True,
        )
        log_series(
            rec, f"plots/{ROOT}/error_m/{label}", scans, ft.time_s, ft.errors_m[label], c, label
        )
        w = ft.windows[label]
        idx = np.searchsorted(ft.time_s, w[:, 0]) + 1  # the plot each window ends at
        log_series(rec, f"plots/{ROOT}/nis/{label}", idx, w[:, 0], w[:, 1], c, label)
        for e in ft.events[label]:
            k = int(np.searchsorted(ft.time_s, e.time_s)) + 1
            level = "WARN" if e.kind == "leaves" else "INFO"
            log_text(rec, f"{label}: {e.message()}", level, k, float(e.time_s))
    w = ft.windows["imm"]
    idx = np.searchsorted(ft.time_s, w[:, 0]) + 1
    for j, part in ((2, "band_lo"), (3, "band_hi")):
        log_series(rec, f"plots/{ROOT}/nis/{part}", idx, w[:, 0], w[:, j], rgb("band"), part)
    _log_charts(rec, ft, at)
    log_text(
        rec,
        f"manoeuvre: flight {FLIGHTS[FLIGHT].name}, {n} plots from 3 radars; ucm tracked with "
        "Q = 0 (cv-q0) and the IMM (imm); the monitor's windowed NIS against its 95% band",
        scan=1,
        time_s=float(ft.time_s[0]),
    )
    return ft


#: Box width of the scene's charts (drawn units, height ``plot2d.HEIGHT``).
CHART_WIDTH = 150.0


def _log_charts(rec: rr.RecordingStream, ft: FlightTracks, at: list[rr.TimeColumn]) -> None:
    """The position error per plot (log scale, a cursor labelling it) and the windowed NIS
    per degree of freedom over the IMM's 95% χ² band (log scale: it spans decades), against
    the flight's time."""
    plot2d.log_plot(
        rec,
        f"charts/{ROOT}/error_m",
        [plot2d.Curve(label, ft.time_s, e, rgb(label)) for label, e in ft.errors_m.items()],
        width=CHART_WIDTH,
        x_label="t, s",
        log_y=True,
        cursor=at,
        cursor_x=ft.time_s,
        unit=" m",
    )
    w = ft.windows["imm"]
    plot2d.log_plot(
        rec,
        f"charts/{ROOT}/nis",
        [plot2d.Curve(label, w[:, 0], w[:, 1], rgb(label)) for label, w in ft.windows.items()],
        width=CHART_WIDTH,
        x_label="t, s",
        log_y=True,
        band=plot2d.Band("95% χ² band", w[:, 0], w[:, 2], w[:, 3]),
    )


def views() -> rrb.Container:
    """The scene's tab: the map beside the error and the windowed NIS."""
    return rrb.Horizontal(
        rrb.Spatial3DView(origin=f"{ROOT}/map", name="Manoeuvre: radars, plots, truth, tracks, m"),
        rrb.Vertical(
            plot2d.plot_view(
                f"charts/{ROOT}/error_m",
                "position error |x̂ − x|, m (log scale): Q = 0 against the IMM",
                CHART_WIDTH,
            ),
            plot2d.plot_view(
                f"charts/{ROOT}/nis",
                "windowed NIS per degree of freedom (log scale) and the 95% χ² band",
                CHART_WIDTH,
            ),
        ),
        column_shares=[3, 2],
        name="Manoeuvre: Q = 0 against the IMM",
    )
