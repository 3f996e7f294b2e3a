"""``radarviz track --rrd``: a measurement file's plots and tracks as a Rerun recording.

Entity paths follow ``viz_app.rerun.recording`` (``{r}`` a radar of the radars file, ``{m}`` a
method)::

    world/radars/{r}                 radar site (static labelled point)
    world/measurements/{r}           each plot, converted naively (site + r̂ u(β̂, ε̂)), per plot
    world/tracks/{m}/position        track position per plot
    world/tracks/{m}/covariance      1σ position ellipsoid per plot
    world/tracks/{m}/velocity        velocity arrow per plot (length: 10 s of motion)
    world/tracks/{m}/path/{k}        the track path, one static strip per chunk of plots
    plots/sigma_pos_m/{m}            √trace of the position covariance, m
    plots/speed_mps/{m}              track speed, m/s

In a file of many targets (a ``target`` column) every target and method is one entity:
``{m}`` above becomes ``{t}/{m}`` (``core.tracking.targets.track_name``; a label's characters
that an entity path reserves are escaped), coloured by method.

Timelines: ``plot`` (sequence 1, 2, … over the file's plots) and ``time`` (the file's time_s,
as a duration). Plots are buffered and sent column-wise (``send_columns``) every ``RRD_CHUNK``
plots, so memory stays bounded however long the file is; a 2D track is drawn at z = 0.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections import defaultdict
from collections.abc import Iterable, Iterator

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from radarviz.core.filters.state import position_index, velocity_index
from radarviz.core.tracking.consistency import ConsistencyMonitor
from radarviz.core.tracking.stream import Plot, StateRow
from radarviz.core.tracking.targets import track_name
from radarviz.viz_app.io.plots import Radar
from radarviz.viz_app.palette import radar_rgb
from radarviz.viz_app.rerun.recording import colour, ellipsoid_axes, log_text, recording_file
from radarviz.viz_app.rerun.shapes import MARKER, SMALL_MARKER, THIN_LINE

#: Plots buffered before the recording is sent a chunk.
RRD_CHUNK = 4096
#: Velocity arrows show this many seconds of motion.
ARROW_SECONDS = 10.0


def _label(r: Radar) -> str:
    return f"{r.name}: σr {r.sigma_range_m:g} m, σβ {r.sigma_azimuth_deg:g}°"


def measured_point(p: Plot) -> tuple[float, float, float]:
    """The naive converted point of a plot in the absolute frame (2D: z = 0)."""
    el = p.elevation_rad or 0.0
    ce = math.cos(el)
    x = p.site[0] + p.range_m * ce * math.cos(p.azimuth_rad)
    y = p.site[1] + p.range_m * ce * math.sin(p.azimuth_rad)
    z = p.site[2] + p.range_m * math.sin(el) if p.elevation_rad is not None else 0.0
    return x, y, z


class TrackRecorder:
    """Buffers plots and track states and sends them to a recording in chunks."""

    def __init__(
        self,
        rec: rr.RecordingStream,
        radars: Iterable[Radar],
        monitor: ConsistencyMonitor | None = None,
    ):
        self.rec = rec
        self.monitor = monitor
        self._events_logged = 0
        self.count = 0
        self.chunk = 0
        radars = list(radars)
        for j, r in enumerate(radars):
            rec.log(
                f"world/radars/{r.name}",
                rr.Points3D(
                    [(r.x_m, r.y_m, r.z_m)],
                    radii=[MARKER],
                    colors=[radar_rgb(j)],
                    labels=[_label(r)],
                ),
                static=True,
            )
        self.radars = radars
        self._lo = np.full(3, np.inf)
        self._hi = np.full(3, -np.inf)
        for r in radars:
            self._extend(np.array([[r.x_m, r.y_m, r.z_m]]))
        self._meas: dict[str, list[tuple[int, float, tuple[float, float, float]]]] = defaultdict(
            list
        )
        # Per (target, method): the buffered states ("" the target of a file of one).
        self._tracks: dict[tuple[str, str], list[tuple[int, float, np.ndarray, np.ndarray]]] = (
            defaultdict(list)
        )
        # Each track's last drawn position: the next chunk's path strip starts there.
        self._last: dict[str, np.ndarray] = {}
        self._styled: set[str] = set()

    def _extend(self, pts: np.ndarray) -> None:
        ok = np.all(np.isfinite(pts), axis=1)
        if ok.any():
            self._lo = np.minimum(self._lo, pts[ok].min(axis=0))
            self._hi = np.maximum(self._hi, pts[ok].max(axis=0))

    def close(self) -> None:
        """Send what is buffered, a summary line in the log and the blueprint: a 3D view
        framed on every radar and plot, the whole run in the time series."""
        self.flush()
        log_text(
            self.rec,
            f"{self.count} plots from {len(self.radars)} radar(s): "
            + ", ".join(r.name for r in self.radars),
            scan=max(self.count, 1),
            timeline="plot",
        )
        lo = np.where(np.isfinite(self._lo), self._lo, 0.0)
        hi = np.where(np.isfinite(self._hi), self._hi, 0.0)
        centre = (lo + hi) / 2.0
        size = max(float((hi - lo).max()), 1e3)
        eye = centre + size * np.array([0.3, -1.0, 0.9])
        whole = rrb.VisibleTimeRange(
            "plot", start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.infinite()
        )
        plots = [
            rrb.TimeSeriesView(
                origin=f"plots/{name}",
                name=title,
                time_ranges=whole,
                plot_legend=rrb.PlotLegend(corner="RightTop"),
            )
            for name, title in (
                ("sigma_pos_m", "√trace of the position covariance, m"),
                ("speed_mps", "track speed, m/s"),
            )
        ]
        self.rec.send_blueprint(
            rrb.Blueprint(
                rrb.Horizontal(
                    rrb.Vertical(
                        rrb.Spatial3DView(
                            origin="world",
                            name="radars, plots and tracks, m",
                            eye_controls=rrb.EyeControls3D(
                                position=tuple(eye),
                                look_target=tuple(centre),
                                eye_up=(0.0, 0.0, 1.0),
                            ),
                        ),
                        rrb.TextLogView(origin="log", name="log"),
                        row_shares=[4, 1],
                    ),
                    rrb.Vertical(*plots),
                    column_shares=[3, 2],
                ),
                rrb.TimePanel(timeline="plot", state="collapsed"),
                collapse_panels=True,
            )
        )

    @classmethod
    @contextlib.contextmanager
    def to_file(
        cls,
        path: str | os.PathLike,
        radars: Iterable[Radar],
        monitor: ConsistencyMonitor | None = None,
    ) -> Iterator[TrackRecorder]:
        """A recorder writing ``path`` atomically (replaced if it exists); ``monitor``: its
        NIS band exits and returns are written to the log as they happen."""
        with recording_file(path, overwrite=True) as rec:
            recorder = cls(rec, radars, monitor)
            yield recorder
            recorder.close()

    def add(self, plot: Plot, rows: list[StateRow]) -> None:
        self.count += 1
        if self.monitor is not None:
            # The tracker runs ahead by a block of plots: log the events up to this plot's time.
            events = self.monitor.events
            while (
                self._events_logged < len(events)
                and events[self._events_logged].time_s <= plot.time_s
            ):
                event = events[self._events_logged]
                level = "WARN" if event.kind == "leaves" else "INFO"
                log_text(self.rec, event.message(), level, scan=self.count, timeline="plot")
                self._events_logged += 1
        self._meas[plot.radar].append((self.count, plot.time_s, measured_point(plot)))
        for method, x, P in rows:
            self._tracks[(plot.target, method)].append((self.count, plot.time_s, x, P))
        if self.count % RRD_CHUNK == 0:
            self.flush()

    def indexes(self, n: list[int], t: list[float]) -> list[rr.TimeColumn]:
        return [
            rr.TimeColumn("plot", sequence=np.asarray(n, dtype=np.int64)),
            rr.TimeColumn("time", duration=np.asarray(t, dtype=np.float64)),
        ]

    def flush(self) -> None:
        """Send everything buffered (one ``send_columns`` per entity) and empty the buffers."""
        rec = self.rec
        for radar, items in self._meas.items():
            if not items:
                continue
            n, t, pts = zip(*items, strict=True)
            self._extend(np.array(pts))
            rec.send_columns(
                f"world/measurements/{radar}",
                indexes=self.indexes(list(n), list(t)),
                columns=rr.Points3D.columns(
                    positions=np.array(pts),
                    radii=[SMALL_MARKER] * len(pts),
                    colors=[colour("measurement")] * len(pts),
                ),
            )
        for (target, method), items in self._tracks.items():
            if not items:
                continue
            name = track_name(rr.escape_entity_path_part(target), method) if target else method
            n, t, xs, ps = zip(*items, strict=True)
            x, P = np.array(xs), np.array(ps)
            POS, VEL = list(position_index(3)), list(velocity_index(3))
            pos, vel = x[:, POS], x[:, VEL]
            cov = P[:, POS][:, :, POS]
            rgb = colour(method)
            k = len(pos)
            idx = self.indexes(list(n), list(t))
            base = f"world/tracks/{name}"
            rec.send_columns(
                f"{base}/position",
                indexes=idx,
                columns=rr.Points3D.columns(positions=pos, colors=[rgb] * k, radii=[MARKER] * k),
            )
            half, quat = ellipsoid_axes(cov)
            rec.send_columns(
                f"{base}/covariance",
                indexes=idx,
                columns=rr.Ellipsoids3D.columns(
                    centers=pos,
                    half_sizes=np.maximum(half, 1.0),
                    quaternions=quat,
                    colors=[rgb] * k,
                ),
            )
            rec.send_columns(
                f"{base}/velocity",
                indexes=idx,
                columns=rr.Arrows3D.columns(
                    origins=pos, vectors=vel * ARROW_SECONDS, colors=[rgb] * k
                ),
            )
            strip = pos if name not in self._last else np.vstack([self._last[name], pos])
            self._last[name] = pos[-1]
            rec.log(
                f"{base}/path/{self.chunk:06d}",
                rr.LineStrips3D([strip], colors=[rgb], radii=[THIN_LINE]),
                static=True,
            )
            if name not in self._styled:  # a track's first chunk
                self._styled.add(name)
                for series in ("sigma_pos_m", "speed_mps"):
                    rec.log(
                        f"plots/{series}/{name}",
                        rr.SeriesLines(colors=[rgb], names=[track_name(target, method)]),
                        static=True,
                    )
            rec.send_columns(
                f"plots/sigma_pos_m/{name}",
                indexes=idx,
                columns=rr.Scalars.columns(scalars=np.sqrt(np.trace(cov, axis1=1, axis2=2))),
            )
            rec.send_columns(
                f"plots/speed_mps/{name}",
                indexes=idx,
                columns=rr.Scalars.columns(scalars=np.linalg.norm(vel, axis=1)),
            )
        self._meas.clear()
        self._tracks.clear()
        self.chunk += 1
