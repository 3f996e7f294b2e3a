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

from radarviz.core.filters.state import position_index, velocity_index
from radarviz.core.tracking.stream import Plot, StateRow
from radarviz.viz_app.io.plots import Radar
from radarviz.viz_app.rerun.recording import (
    colour,
    default_blueprint,
    ellipsoid_axes,
    log_radar_site,
    recording_file,
)

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

    def __init__(self, rec: rr.RecordingStream, radars: Iterable[Radar]):
        self.rec = rec
        self.count = 0
        self.chunk = 0
        radars = list(radars)
        for r in radars:
            log_radar_site(rec, r.name, (r.x_m, r.y_m, r.z_m), _label(r))
        self._meas: dict[str, list[tuple[int, float, tuple[float, float, float]]]] = defaultdict(
            list
        )
        self._tracks: dict[str, list[tuple[int, float, np.ndarray, np.ndarray]]] = defaultdict(list)
        # Each method's last drawn position: the next chunk's path strip starts there.
        self._last: dict[str, np.ndarray] = {}
        centre = np.mean([[r.x_m, r.y_m, r.z_m] for r in radars], axis=0) if radars else (0, 0, 0)
        rec.send_blueprint(default_blueprint(("sigma_pos_m", "speed_mps"), centre))

    @classmethod
    @contextlib.contextmanager
    def to_file(cls, path: str | os.PathLike, radars: Iterable[Radar]) -> Iterator[TrackRecorder]:
        """A recorder writing ``path`` atomically (replaced if it exists)."""
        with recording_file(path, overwrite=True) as rec:
            recorder = cls(rec, radars)
            yield recorder
            recorder.flush()

    def add(self, plot: Plot, rows: list[StateRow]) -> None:
        self.count += 1
        self._meas[plot.radar].append((self.count, plot.time_s, measured_point(plot)))
        for method, x, P in rows:
            self._tracks[method].append((self.count, plot.time_s, x, P))
        if self.count % RRD_CHUNK == 0:
            self.flush()

    def _indexes(self, n: list[int], t: list[float]) -> list[rr.TimeColumn]:
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
            rec.send_columns(
                f"world/measurements/{radar}",
                indexes=self._indexes(list(n), list(t)),
                columns=rr.Points3D.columns(
                    positions=np.array(pts),
                    radii=[150.0] * len(pts),
                    colors=[(90, 90, 90)] * len(pts),
                ),
            )
        for method, items in self._tracks.items():
            if not items:
                continue
            n, t, xs, ps = zip(*items, strict=True)
            x, P = np.array(xs), np.array(ps)
            POS, VEL = list(position_index(3)), list(velocity_index(3))
            pos, vel = x[:, POS], x[:, VEL]
            cov = P[:, POS][:, :, POS]
            rgb = colour(method)
            k = len(pos)
            idx = self._indexes(list(n), list(t))
            base = f"world/tracks/{method}"
            rec.send_columns(
                f"{base}/position",
                indexes=idx,
                columns=rr.Points3D.columns(positions=pos, colors=[rgb] * k, radii=[250.0] * k),
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
            strip = pos if method not in self._last else np.vstack([self._last[method], pos])
            self._last[method] = pos[-1]
            rec.log(
                f"{base}/path/{self.chunk:06d}", rr.LineStrips3D([strip], colors=[rgb]), static=True
            )
            if self.chunk == 0:
                for series in ("sigma_pos_m", "speed_mps"):
                    rec.log(
                        f"plots/{series}/{method}",
                        rr.SeriesLines(colors=[rgb], names=[method]),
                        static=True,
                    )
            rec.send_columns(
                f"plots/sigma_pos_m/{method}",
                indexes=idx,
                columns=rr.Scalars.columns(scalars=np.sqrt(np.trace(cov, axis1=1, axis2=2))),
            )
            rec.send_columns(
                f"plots/speed_mps/{method}",
                indexes=idx,
                columns=rr.Scalars.columns(scalars=np.linalg.norm(vel, axis=1)),
            )
        self._meas.clear()
        self._tracks.clear()
        self.chunk += 1
