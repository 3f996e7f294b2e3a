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
    world/truth/{t}/path, /position  the truth (``track --truth``): path (static), position at
                                     each truth time (on ``plot``: the plot of that time)
    inset/{m}/estimate, /covariance  the first (confirmed) target's estimate per method and
                                     its horizontal 1σ ellipse, about the methods' mean (m),
                                     framed so the ellipses show (they are metres in a map
                                     of kilometres)

In a file of many targets (a ``target`` column) every target and method is one entity:
``{m}`` above becomes ``{t}/{m}`` (``core.tracking.targets.track_name``; a label's characters
that an entity path reserves are escaped), coloured by method.

With the association (``track --associate gnn``) ``{t}`` is the track id and the recording
carries each track's status (``core.tracking.association``):

* a *confirmed* track (M of N hits) has the entities above, from the scan that confirms it.
* the rows of *tentative* tracks (not yet M of N hits) are one row per scan and method, all
  the scan's tentative tracks at once, at the scan's first plot::

      world/tentative/{m}/position     their positions, faint (``shapes.faint``: the method's
                                       hue mixed with the 3D view's light background, set in
                                       the blueprint) and small
      world/tentative/{m}/covariance   their 1σ ellipsoids, faint

  A scan with none gets an empty row, so the view shows the current scan's only. (Most
  tracks a file starts are clutter that lives a few scans: an entity per track and part made
  thousands of entities, and the recording's index of them, built when it is closed, was the
  run's peak memory.) Tentative tracks have no velocity arrows and take no colour of the
  palette, so the confirmed tracks' colours are the palette's first.
* a track's path is drawn once it is confirmed, its tentative start faint and thin; a track
  deleted while tentative has no path (dozens of clutter tracks live for a few scans).
* a deleted confirmed track is cleared (a recursive ``rr.Clear`` of ``world/tracks/{t}``) at
  the scan that deletes it, so its last position does not stay on screen; its path, static,
  stays.
* the time series carry confirmed rows only.
* plots are logged per scan, one row of all the scan's plots at its first plot, split by the
  status of the track each went to::

      world/measurements/{r}/confirmed   plots that updated (or confirmed) a confirmed track
      world/measurements/{r}/tentative   plots of tentative tracks: those that started one
                                         (no track took them) and their few followers

  the latter faint and small. A status with no plot in a scan gets an empty row, so the
  view shows the current scan only.

Timelines: ``plot`` (sequence 1, 2, … over the file's plots) and ``time`` (the file's time_s,
as a duration). Plots are buffered and sent column-wise (``send_columns``) every ``RRD_CHUNK``
plots, so memory stays bounded however long the file is; a 2D track is drawn at z = 0.
"""

from __future__ import annotations

import contextlib
import math
import os
from array import array
from collections import defaultdict
from collections.abc import Iterable, Iterator

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from radarviz.core.filters.state import position_index, velocity_index
from radarviz.core.tracking.association import CONFIRMED, TENTATIVE, AssociationReport
from radarviz.core.tracking.consistency import ConsistencyMonitor
from radarviz.core.tracking.scoring import Truth
from radarviz.core.tracking.stream import Plot, StateRow
from radarviz.core.tracking.targets import track_name
from radarviz.viz_app.io.plots import Radar
from radarviz.viz_app.newest import NewestValues
from radarviz.viz_app.palette import RADAR_GREYS, track_rgb
from radarviz.viz_app.rerun.recording import (
    colour,
    drain,
    ellipsoid_columns,
    log_text,
    recording_file,
)
from radarviz.viz_app.rerun.scenes import PresetLayout, blueprint_of
from radarviz.viz_app.rerun.shapes import (
    CLOUD_MARKER,
    FAINT_LINE,
    FAINT_MARKER,
    LIGHT,
    MARKER,
    SMALL_MARKER,
    THIN_LINE,
    faint,
    flip_y,
)

#: Plots buffered before the recording is sent a chunk (and the chunk flushed to the file):
#: the buffers and the chunk's encoding are what the recorder's memory holds at once (10⁵
#: plots of 7 methods peaked at 395 MiB with 4096, 376 MiB with 2048; 252 MiB without --rrd).
RRD_CHUNK = 2048
#: Velocity arrows show this many seconds of motion.
ARROW_SECONDS = 10.0
#: The time series of every confirmed track, ``plots/{series}/...``.
SERIES = ("sigma_pos_m", "speed_mps")
#: What the association's recording says about its drawing (the log's first line).
STATUS_LEGEND = (
    "faint, small: tentative tracks (fewer than M of N hits yet) and the plots that went to "
    "them, which include every plot no track took; bright: confirmed tracks and their plots. "
    "A deleted track is cleared at the scan that deletes it."
)


def _label(r: Radar) -> str:
    return f"{r.name}: σr {r.sigma_r_m:g} m, σβ {r.sigma_beta_deg:g}°"


def measured_point(p: Plot) -> tuple[float, float, float]:
    """The naive converted point of a plot in the absolute frame (2D: z = 0)."""
    el = p.elevation_rad or 0.0
    ce = math.cos(el)
    x = p.site[0] + p.range_m * ce * math.cos(p.azimuth_rad)
    y = p.site[1] + p.range_m * ce * math.sin(p.azimuth_rad)
    z = p.site[2] + p.range_m * math.sin(el) if p.elevation_rad is not None else 0.0
    return x, y, z


Row = tuple[int, float, np.ndarray, np.ndarray, str]
_POS, _VEL = list(position_index(3)), list(velocity_index(3))


class TrackRecorder:
    """Buffers plots and track states and sends them to a recording in chunks."""

    #: Plots after which ``add`` flushes by itself (None: only when asked).
    chunk_plots: int | None = RRD_CHUNK
    #: Whether tentative tracks' rows go to ``world/tentative/{m}``, one row per scan (a
    #: subclass drawing the tracks its own way says False).
    groups_tentative = True
    #: The newest values the layout's frames are drawn from (the inset's reaches, the time
    #: series' values) that are kept; None: every one (a file's whole run frames its views; a
    #: feed that never ends keeps a bounded number, ``live_recording``).
    layout_kept: int | None = None

    def __init__(
        self,
        rec: rr.RecordingStream,
        radars: Iterable[Radar],
        monitor: ConsistencyMonitor | None = None,
        truth: Truth | None = None,
    ):
        self.rec = rec
        self.truth = truth
        # Each plot's time, with a truth: where the truth's times fall on the ``plot``
        # timeline. (Packed doubles, not a list of floats: this and the inset's reaches are
        # what the recorder keeps per plot to the end, and a list costs four times the memory.)
        self._plot_times = array("d")
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
                    # Greys: a radar never takes a method's or a track's colour.
                    colors=[RADAR_GREYS[j % len(RADAR_GREYS)]],
                    labels=[_label(r)],
                ),
                static=True,
            )
        self.radars = radars
        self._lo = np.full(3, np.inf)
        self._hi = np.full(3, -np.inf)
        for r in radars:
            self._extend(np.array([[r.x_m, r.y_m, r.z_m]]))
        # Per measurement entity (below world/measurements): rows of (plot, time_s, points
        # (k, 3)); one plot a row, or with the association one scan of one status a row.
        self._meas: dict[str, list[tuple[int, float, np.ndarray]]] = defaultdict(list)
        # The association's current scan: (plot, time_s, radar, status, point) per plot.
        self._scan: list[tuple[int, float, str, str, tuple[float, float, float]]] = []
        #: Whether the plots came with statuses (the association).
        self.statuses = False
        # Per (target, method): the buffered states and statuses ("" the target of a file of
        # one; status "" without the association).
        self._tracks: dict[tuple[str, str], list[Row]] = defaultdict(list)
        # Each track's last drawn (confirmed) position: the next chunk's path strip starts there.
        self._last: dict[str, np.ndarray] = {}
        # A tentative track's positions not drawn as a path yet (until it is confirmed).
        self._pending: dict[str, np.ndarray] = {}
        # Targets deleted since the last flush: a tentative one's path is never drawn.
        self._deleted: set[str] = set()
        # Targets with a confirmed row (their own entities, cleared when deleted).
        self._confirmed: set[str] = set()
        # The current scan's tentative rows, by method: position (3,), covariance (3, 3).
        self._scan_tentative: dict[str, list[tuple[np.ndarray, np.ndarray]]] = defaultdict(list)
        # The scans' tentative rows, by method: (plot, time_s, positions (k, 3), covariances
        # (k, 3, 3)), one per scan.
        self._tentative: dict[str, list[tuple[int, float, np.ndarray, np.ndarray]]] = defaultdict(
            list
        )
        self._styled: set[str] = set()
        # Each track's colour, by method, or by track id when one method tracks many (the
        # ``_coloured``-th colour of the palette); a deleted track's is forgotten.
        self._colours: dict[str, tuple[int, int, int]] = {}
        self._coloured = 0
        self._methods: set[str] = set()
        # The confirmed rows' series values, for axes that ignore their outliers (the newest
        # ``layout_kept`` of each series).
        self._series = {name: NewestValues(self.layout_kept, np.float32) for name in SERIES}
        self._time_s = 0.0
        # The inset: the first target's estimates and 1σ ellipses about the methods' mean
        # (``_inset_rows``: plot, time_s, method, offset (2,), covariance (2, 2)).
        self._inset_target: str | None = None
        self._inset_rows: list[tuple[int, float, str, np.ndarray, np.ndarray]] = []
        self._inset_reach_m = NewestValues(self.layout_kept)
        rec.log("inset", flip_y(1.0), static=True)  # north up
        rec.log(
            "inset/reference",
            rr.Points2D([[0.0, 0.0]], radii=[SMALL_MARKER], colors=[colour("truth")]),
            static=True,
        )

    def _extend(self, pts: np.ndarray) -> None:
        ok = np.all(np.isfinite(pts), axis=1)
        if ok.any():
            self._lo = np.minimum(self._lo, pts[ok].min(axis=0))
            self._hi = np.maximum(self._hi, pts[ok].max(axis=0))

    def close(self) -> None:
        """Send what is buffered, a summary line in the log and the blueprint: a 3D view
        framed on every radar and plot, the whole run in the time series."""
        self.end_scan([])
        self.flush()
        if self.truth is not None:
            self._log_truth(self.truth)
        self._log_text(
            f"{self.count} plots from {len(self.radars)} radar(s): "
            + ", ".join(r.name for r in self.radars)
        )
        self.send_layout()

    def send_layout(self) -> None:
        """Send the blueprint: a 3D view framed on every radar and plot so far, the whole
        run in the time series (``close`` sends it at the end; a live session also at its
        start, so the viewer is laid out while the plots come)."""
        lo = np.where(np.isfinite(self._lo), self._lo, 0.0)
        hi = np.where(np.isfinite(self._hi), self._hi, 0.0)
        centre = (lo + hi) / 2.0
        size = max(float((hi - lo).max()), 1e3)
        eye = centre + size * np.array([0.3, -1.0, 0.9])
        whole = rrb.VisibleTimeRange(
            "plot", start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.infinite()
        )
        series = "confirmed tracks' " if self.statuses else ""
        plots = [
            rrb.TimeSeriesView(
                origin=f"plots/{name}",
                name=series + title,
                time_ranges=whole,
                plot_legend=rrb.PlotLegend(corner="RightTop"),
                axis_y=self._robust_axis(name),
            )
            for name, title in (
                ("sigma_pos_m", "√trace of the position covariance, m"),
                ("speed_mps", "track speed, m/s"),
            )
        ]
        title = "radars, plots and tracks, m"
        if self.statuses:
            title += " (faint: tentative; deleted tracks cleared)"
        #: The recording's layout (``PresetLayout`` of ``viz_app.rerun.scenes``): one tab.
        self.layout = PresetLayout(
            (
                rrb.Horizontal(
                    rrb.Vertical(
                        rrb.Spatial3DView(
                            origin="world",
                            name=title,
                            background=rrb.Background(
                                kind=rrb.BackgroundKind.SolidColor, color=LIGHT
                            ),
                            eye_controls=rrb.EyeControls3D(
                                position=tuple(eye),
                                look_target=tuple(centre),
                                eye_up=(0.0, 0.0, 1.0),
                            ),
                        ),
                        rrb.TextLogView(origin="log", name="log"),
                        row_shares=[4, 1],
                    ),
                    rrb.Vertical(self._inset_view(), *plots, row_shares=[3, 2, 2]),
                    column_shares=[3, 2],
                    name="tracks",
                ),
            ),
            timeline="plot",
            tabbed=False,
        )
        self.rec.send_blueprint(blueprint_of(self.layout))

    def _robust_axis(self, series: str) -> rrb.ScalarAxis | None:
        """A y range holding the series' values but not their outliers (a clutter plot that
        briefly pulls a track makes a speed spike that would flatten every other curve):
        ``plot2d.robust_limits`` with a margin; None (the view's own) without values."""
        from radarviz.viz_app.rerun.plot2d import robust_limits

        if not len(self._series[series]):
            return None
        lo, hi = robust_limits([self._series[series].values()])
        pad = 0.08 * max(hi - lo, abs(hi) * 0.05, 1e-9)
        return rrb.ScalarAxis(range=(max(lo - pad, 0.0), hi + pad))

    @classmethod
    @contextlib.contextmanager
    def to_file(
        cls,
        path: str | os.PathLike,
        radars: Iterable[Radar],
        monitor: ConsistencyMonitor | None = None,
        truth: Truth | None = None,
    ) -> Iterator[TrackRecorder]:
        """A recorder writing ``path`` atomically (replaced if it exists); ``monitor``: its
        NIS band exits and returns are written to the log as they happen; ``truth`` (a truth
        file's, ``viz_app.io.score_files.read_truth``) is drawn in black."""
        with recording_file(path, overwrite=True, to_disk=True) as rec:
            recorder = cls(rec, radars, monitor, truth)
            yield recorder
            recorder.close()

    def add(self, plot: Plot, rows: list[StateRow], status: str = "") -> None:
        """One plot and its tracks' rows; ``status`` (the association's): the status of the
        plot's track after its scan, ``tentative`` or ``confirmed`` ("" without)."""
        self.count += 1
        self._time_s = plot.time_s
        if self.truth is not None:
            self._plot_times.append(plot.time_s)
        if status and not self.statuses:
            self.statuses = True
            self._log_text(STATUS_LEGEND)
        if self.monitor is not None:
            # The tracker runs ahead by a block of plots: log the events up to this plot's time.
            # The monitor may keep only its newest events (``events_kept``): ``events`` starts
            # at its ``first``-th event, and any older one not logged yet is gone.
            events, seen = self.monitor.events, self.monitor.events_seen
            first = seen - len(events)
            self._events_logged = max(self._events_logged, first)
            while (
                self._events_logged < seen
                and events[self._events_logged - first].time_s <= plot.time_s
            ):
                event = events[self._events_logged - first]
                level = "WARN" if event.kind == "leaves" else "INFO"
                self._log_text(event.message(), level)
                self._events_logged += 1
        point = measured_point(plot)
        if status:
            self._scan.append((self.count, plot.time_s, plot.radar, status, point))
        else:
            self._meas[plot.radar].append((self.count, plot.time_s, np.array([point])))
        if rows and (self._inset_target is None or plot.target == self._inset_target):
            if status != TENTATIVE:  # the inset follows a confirmed track (or the only one)
                self._inset_target = plot.target
                self._add_inset(rows)
        if status == CONFIRMED:
            self._confirmed.add(plot.target)
        for method, x, P in rows:
            self._methods.add(method)
            self._tracks[(plot.target, method)].append((self.count, plot.time_s, x, P, status))
            if status == TENTATIVE and self.groups_tentative:
                self._scan_tentative[method].append((x[_POS], np.asarray(P)[np.ix_(_POS, _POS)]))
        if self.chunk_plots is not None and self.count % self.chunk_plots == 0:
            self.flush()

    def _log_truth(self, truth: Truth) -> None:
        """The truth: each target's path (a static black strip) and its position at each
        truth time, on the ``time`` timeline and at the plot of that time on ``plot``."""
        times = np.asarray(self._plot_times)
        pos = np.asarray(truth.position_m, dtype=np.float64)
        if pos.shape[1] == 2:
            pos = np.c_[pos, np.zeros(len(pos))]
        self._extend(pos)
        black = colour("truth")
        for target in dict.fromkeys(truth.targets.tolist()):
            sel = np.flatnonzero(truth.targets == target)
            sel = sel[np.argsort(truth.times_s[sel], kind="stable")]
            t, p = truth.times_s[sel], pos[sel]
            base = f"world/truth/{rr.escape_entity_path_part(str(target))}"
            self.rec.log(
                f"{base}/path",
                rr.LineStrips3D([p], colors=[black], radii=[FAINT_LINE]),
                static=True,
            )
            n = np.clip(np.searchsorted(times, t, side="right"), 1, None) if times.size else 1
            k = len(t)
            self.rec.send_columns(
                f"{base}/position",
                indexes=self.indexes(list(np.broadcast_to(n, k)), list(t)),
                columns=rr.Points3D.columns(
                    positions=p,
                    colors=[black] * k,
                    radii=[SMALL_MARKER] * k,
                    labels=[f"truth {target}"] * k,
                ),
            )

    def _add_inset(self, rows: list[StateRow]) -> None:
        """The inset's rows of one plot: each method's horizontal position offset from the
        methods' mean (m) and its horizontal position covariance."""
        POS = list(position_index(3))[:2]
        xy = np.array([x[POS] for _, x, _ in rows])
        ref = xy.mean(axis=0)
        for (method, _, P), p in zip(rows, xy, strict=True):
            cov = np.asarray(P)[np.ix_(POS, POS)]
            off = p - ref
            reach = float(np.abs(off).max() + np.sqrt(max(np.linalg.eigvalsh(cov).max(), 0.0)))
            if np.isfinite(reach):
                self._inset_reach_m.add([reach])
            self._inset_rows.append((self.count, self._time_s, method, off, cov))

    def _send_inset(self) -> None:
        """The buffered inset rows, one ``send_columns`` per method and part."""
        from radarviz.viz_app.rerun.shapes import LINE, ellipse_outline

        if not self._inset_rows:
            return
        by_method: dict[str, list] = defaultdict(list)
        for row in self._inset_rows:
            by_method[row[2]].append(row)
        for method, items in by_method.items():
            n, t, _, off, cov = zip(*items, strict=True)
            off, cov = np.array(off), np.array(cov)
            k = len(n)
            rgb = self._colours.get(self._inset_name(method), colour(method))
            idx = self.indexes(list(n), list(t))
            self.rec.send_columns(
                f"inset/{method}/estimate",
                indexes=idx,
                columns=rr.Points2D.columns(
                    positions=off, colors=[rgb] * k, radii=[MARKER] * k, labels=[method] * k
                ),
            )
            self.rec.send_columns(
                f"inset/{method}/covariance",
                indexes=idx,
                columns=rr.LineStrips2D.columns(
                    strips=ellipse_outline(off, cov), colors=[rgb] * k, radii=[LINE] * k
                ),
            )
        self._inset_rows.clear()

    def _inset_name(self, method: str) -> str:
        return self._entity_name(self._inset_target or "", method)

    def _inset_view(self) -> rrb.Spatial2DView:
        """The inset's view: ± a round distance holding every offset and 1σ ellipse."""
        from radarviz.viz_app.rerun.prosov_scene import nice_ceiling

        # Most rows, not the start's wide ellipses, set the frame (those then overflow it).
        reaches = self._inset_reach_m.values()
        reach = float(np.percentile(reaches, 80)) if reaches.size else 1.0
        half = nice_ceiling(max(1.15 * reach, 1.0))
        who = f"track {self._inset_target}" if self._inset_target else "the target"
        return rrb.Spatial2DView(
            origin="inset",
            name=f"{who}: each method's estimate and 1σ ellipse about their mean (black), "
            f"view ±{half:g} m, east right, north up",
            visual_bounds=rrb.VisualBounds2D(
                x_range=[-1.6 * half, 1.6 * half], y_range=[-half, half]
            ),
        )

    def end_scan(self, deleted: list[str]) -> None:
        """The association's scan is complete: its plots become one row per status (at its
        first plot), and the tracks ``deleted`` at it are cleared at its last plot."""
        if self._scan:
            n, t, radar = self._scan[0][0], self._scan[0][1], self._scan[0][2]
            for status in (CONFIRMED, TENTATIVE):
                pts = [p for *_, s, p in self._scan if s == status]
                self._meas[f"{radar}/{status}"].append((n, t, np.array(pts).reshape(-1, 3)))
            if self.groups_tentative:
                for method in self._methods:
                    got = self._scan_tentative.pop(method, [])
                    pos = np.array([p for p, _ in got]).reshape(-1, 3)
                    cov = np.array([c for _, c in got]).reshape(-1, 3, 3)
                    self._tentative[method].append((n, t, pos, cov))
            end_n, end_t = self._scan[-1][0], self._scan[-1][1]
            self._scan.clear()
        else:
            end_n, end_t = self.count, self._time_s
        for target in deleted:
            self._deleted.add(target)
            if target not in self._confirmed:
                continue  # a tentative track has no entity of its own
            self.rec.send_columns(
                f"world/tracks/{rr.escape_entity_path_part(target)}",
                indexes=self.indexes([end_n], [end_t]),
                columns=rr.Clear.columns(is_recursive=[True]),
            )

    def report(self, account: AssociationReport) -> None:
        """The association's account in the log: where each radar's plots went, and a warning
        when too many never reached a confirmed track (``viz_app.reports.plot_account``)."""
        from radarviz.viz_app.reports.plot_account import association_lines, untracked_warning

        for line in association_lines(account):
            self._log_text(line)
        warning = untracked_warning(account)
        if warning is not None:
            self._log_text(warning, "WARN")

    def _log_text(self, text: str, level: str = "INFO") -> None:
        """A line in the log at the current plot, on both timelines (``plot`` and ``time``):
        the log view lists only entries timed on the active timeline, so a line on ``plot``
        alone leaves it empty when the viewer is on ``time``."""
        at = self.indexes([max(self.count, 1)], [self._time_s])
        log_text(self.rec, text, level, at=at)

    def indexes(self, n: list[int], t: list[float]) -> list[rr.TimeColumn]:
        return [
            rr.TimeColumn("plot", sequence=np.asarray(n, dtype=np.int64)),
            rr.TimeColumn("time", duration=np.asarray(t, dtype=np.float64)),
        ]

    def flush(self) -> None:
        """Send everything buffered (one ``send_columns`` per entity) and empty the buffers."""
        self._send_measurements()
        self._send_tentative()
        for (target, method), items in self._tracks.items():
            if items:
                self._send_track(target, method, items)
        self._forget_deleted()
        self._send_inset()
        self._tracks.clear()
        self.chunk += 1
        drain(self.rec)  # the chunk's encoded bytes to the file: memory stays flat with its length

    def _send_measurements(self) -> None:
        """The buffered plots, one ``send_columns`` per measurement entity."""
        for entity, items in self._meas.items():
            if not items:
                continue
            n, t, pts = zip(*items, strict=True)
            allpts = np.concatenate(pts)
            self._extend(allpts)
            m = len(allpts)
            dim = entity.endswith(f"/{TENTATIVE}")
            rgb = faint(colour("measurement")) if dim else colour("measurement")
            self.rec.send_columns(
                f"world/measurements/{entity}",
                indexes=self.indexes(list(n), list(t)),
                columns=rr.Points3D.columns(
                    positions=allpts,
                    # Under a tentative track's 2.5 pt marker, which starts on its plot.
                    radii=[CLOUD_MARKER if dim else SMALL_MARKER] * m,
                    colors=[rgb] * m,
                ).partition([len(p) for p in pts]),
            )
        self._meas.clear()

    def _send_tentative(self) -> None:
        """The buffered scans' tentative rows, one ``send_columns`` per method and part."""
        for method, items in self._tentative.items():
            if not items:
                continue
            n, t, pos, cov = zip(*items, strict=True)
            sizes = [len(p) for p in pos]
            allpos, allcov = np.concatenate(pos), np.concatenate(cov)
            m = len(allpos)
            dim = faint(colour(method))
            idx = self.indexes(list(n), list(t))
            base = f"world/tentative/{method}"
            self.rec.send_columns(
                f"{base}/position",
                indexes=idx,
                columns=rr.Points3D.columns(
                    positions=allpos, colors=[dim] * m, radii=[FAINT_MARKER] * m
                ).partition(sizes),
            )
            self.rec.send_columns(
                f"{base}/covariance",
                indexes=idx,
                columns=ellipsoid_columns(allpos, allcov, [dim] * m).partition(sizes),
            )
        self._tentative.clear()

    def _forget_deleted(self, targets: set[str] | None = None) -> None:
        """Deleted tracks (``targets``, or all deleted since the last flush) have no more
        rows: forget their path's state (a tentative one has no path), colour and series
        style (the inset's track keeps its colour: the inset's rows name it)."""
        targets = set(self._deleted) if targets is None else targets
        for target in targets:
            for name in [self._entity_name(target, m) for m in self._methods]:
                self._pending.pop(name, None)
                self._last.pop(name, None)
                self._styled.discard(name)
                if target != self._inset_target:
                    self._colours.pop(name, None)
            self._confirmed.discard(target)
        self._deleted -= targets

    def _entity_name(self, target: str, method: str) -> str:
        """The entity name of a target's method (``{t}/{m}``, or ``{m}`` in a file of one)."""
        return track_name(rr.escape_entity_path_part(target), method) if target else method

    def _track_colour(self, target: str, name: str, method: str) -> tuple[int, int, int]:
        """A track's colour: by id when one method tracks many targets, else by method."""
        rgb = self._colours.get(name)
        if rgb is None:
            by_id = bool(target) and len(self._methods) == 1
            rgb = self._colours[name] = track_rgb(self._coloured) if by_id else colour(method)
            self._coloured += 1
        return rgb

    def _path_strips(
        self,
        name: str,
        pos: np.ndarray,
        tentative: np.ndarray,
        rgb: tuple[int, int, int] | None,
    ) -> tuple[int, list[np.ndarray], list, list[float]]:
        """A track's path for its buffered positions ``pos``: the index of its first
        confirmed row (``len(pos)``: still tentative, the positions kept until it is
        confirmed) and the strips to draw, their colours and radii (none while tentative:
        ``rgb``, the track's colour, may then be None)."""
        # Statuses only go tentative → confirmed: the chunk's confirmed rows are a suffix.
        first = int(np.argmin(tentative)) if not tentative.all() else len(pos)
        start = self._pending.pop(name, np.zeros((0, 3)))
        if first == len(pos):  # still tentative: its path waits for the confirmation
            self._pending[name] = np.vstack([start, pos])
            return first, [], [], []
        assert rgb is not None, "a confirmed track is drawn in its colour"
        strips, colours_, radii = [], [], []
        early = np.vstack([start, pos[:first]])
        if len(early):  # the tentative start, faint, joined to the first confirmed row
            strips.append(np.vstack([early, pos[first : first + 1]]))
            colours_.append(faint(rgb))
            radii.append(FAINT_LINE)
        later = pos[first:] if name not in self._last else np.vstack([self._last[name], pos])
        strips.append(later)
        colours_.append(rgb)
        radii.append(THIN_LINE)
        self._last[name] = pos[-1]
        return first, strips, colours_, radii

    def _send_series(
        self,
        target: str,
        method: str,
        name: str,
        rgb: tuple[int, int, int],
        at: list[rr.TimeColumn],
        cov: np.ndarray,
        vel: np.ndarray,
        entity: str | None = None,
    ) -> None:
        """A track's confirmed rows' time series (√trace of the position covariance, speed)
        at the indexes ``at``, in ``plots/{series}/{entity}`` (``entity`` defaults to the
        track's ``name``); the series are styled at the track's first call."""
        rec = self.rec
        entity = name if entity is None else entity
        if name not in self._styled:  # a track's first confirmed chunk
            self._styled.add(name)
            for series in SERIES:
                rec.log(
                    f"plots/{series}/{entity}",
                    rr.SeriesLines(colors=[rgb], names=[track_name(target, method)]),
                    static=True,
                )
        for series, values in (
            ("sigma_pos_m", np.sqrt(np.trace(cov, axis1=1, axis2=2))),
            ("speed_mps", np.linalg.norm(vel, axis=1)),
        ):
            rec.send_columns(
                f"plots/{series}/{entity}", indexes=at, columns=rr.Scalars.columns(scalars=values)
            )
            self._series[series].add(values)  # for its axis (``_robust_axis``)

    def _send_track(self, target: str, method: str, items: list[Row]) -> None:
        """One track's buffered rows: its confirmed rows' position, covariance and velocity
        (its tentative ones are the scans' rows of ``world/tentative/{m}``), its path
        strip(s) and its confirmed rows' time series."""
        rec = self.rec
        name = self._entity_name(target, method)
        n, t, xs, ps, statuses = zip(*items, strict=True)
        x, P = np.array(xs), np.array(ps)
        pos, vel = x[:, _POS], x[:, _VEL]
        cov = P[:, _POS][:, :, _POS]
        tentative = np.array([s == TENTATIVE for s in statuses])
        if tentative.all():  # no entity yet: the positions wait for the path's start
            self._path_strips(name, pos, tentative, None)
            return
        rgb = self._track_colour(target, name, method)
        first, strips, colours_, radii = self._path_strips(name, pos, tentative, rgb)
        sel = slice(first, None)  # statuses only go tentative → confirmed: a suffix
        pos_c, vel_c, cov_c = pos[sel], vel[sel], cov[sel]
        k = len(pos_c)
        at = self.indexes(list(n[sel]), list(t[sel]))
        base = f"world/tracks/{name}"
        rec.send_columns(
            f"{base}/position",
            indexes=at,
            columns=rr.Points3D.columns(
                positions=pos_c,
                colors=[rgb] * k,
                radii=[MARKER] * k,
                labels=[track_name(target, method) if target else method] * k,
            ),
        )
        rec.send_columns(
            f"{base}/covariance", indexes=at, columns=ellipsoid_columns(pos_c, cov_c, [rgb] * k)
        )
        rec.send_columns(
            f"{base}/velocity",
            indexes=at,
            columns=rr.Arrows3D.columns(
                origins=pos_c, vectors=vel_c * ARROW_SECONDS, colors=[rgb] * k
            ),
        )
        rec.log(
            f"{base}/path/{self.chunk:06d}",
            rr.LineStrips3D(strips, colors=colours_, radii=radii),
            static=True,
        )
        self._send_series(target, method, name, rgb, at, cov_c, vel_c)
