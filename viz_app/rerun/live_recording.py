"""``radarviz live``'s recording: the tracks as they are now, a few entities per method.

``TrackRecorder`` (``track --rrd``) gives every track and method its own entities and sends
each its rows: on a file, a chunk of 2048 plots at a time, that is a few calls per track.
A live session flushes every run of the tracker (about ten a second): the same layout costs
six calls per track per flush, a few hundred tracks make thousands of calls a second, and the
viewer falls behind the feed (the call's overhead, not the data, is the cost). So a live
session draws the tracks' current state instead, one row per flush per method::

    world/tracks/{m}/position    every live track's latest position (tentative ones faint and
                                 smaller, confirmed ones labelled with their id)
    world/tracks/{m}/covariance  their 1σ ellipsoids
    world/tracks/{m}/velocity    their velocity arrows (10 s of motion)
    world/tracks/{m}/path/{k}    the paths drawn since the last path chunk, one static strip
                                 set every ``PATH_S`` s of the session (a track's path is drawn
                                 once it is confirmed, as ``TrackRecorder``'s); each flush draws
                                 the buffered rows of a ``1 / PATH_SPREAD`` share of the
                                 tracks, oldest first, so no flush pays for them all

A deleted track leaves the row at the flush after its scan (nothing to clear), and the
recorder forgets it (its colour, its path's and series' state); its path, static, stays
until its chunk's entity is reused (``PATH_CHUNKS``), so neither the recorder's memory nor
the viewer's grows with the tracks ever started. A method left out of ``shown`` (the live
panel's boxes) gets empty rows and no new path strips until it is shown again; it is still
tracked. The time series (per confirmed track, as ``TrackRecorder``'s) are one call per
track and series, a millisecond each: their rows wait in a queue of tracks,
``SERIES_TRACKS`` of which are sent per flush, so a flush's cost stays bounded however many
tracks are confirmed; a track's series lags by the queue's length over that (seconds for a
few hundred confirmed tracks). The plots, the inset, the log and the layout are
``TrackRecorder``'s; nothing is flushed but by ``flush``.

Entities are a bounded set, made early: the Rerun SDK keeps a few kilobytes for every entity
path it has been sent, for the life of the recording, cleared or not (about 4.7 KiB each,
measured on rerun-sdk 0.41), so a path per track ever started is memory that grows with the
session. A confirmed track's time series therefore go to a *slot*, ``plots/{series}/{k}``
(``{k}`` a four-digit number), taken when its first series rows are sent and given back when
it is deleted and its rows are all sent; the lowest free slot is taken next, so the slots in
use number the most tracks confirmed at once, and a slot's next track starts with a ``Clear``
that ends its last track's line (and its legend names the new one). The ``PATH_CHUNKS`` path
entities of every method are all made at the start, empty. Nor does a track's id go through
the SDK's entity path escaping (``_entity_name``), whose strings the SDK keeps for good.
"""

from __future__ import annotations

import heapq
import time
from collections.abc import Callable, Iterable

import numpy as np
import rerun as rr

from radarviz.core.filters.state import position_index, velocity_index
from radarviz.core.tracking.association import TENTATIVE
from radarviz.core.tracking.consistency import ConsistencyMonitor
from radarviz.core.tracking.stream import Plot, StateRow
from radarviz.core.tracking.targets import track_name
from radarviz.viz_app.io.plots import Radar
from radarviz.viz_app.rerun.recording import ellipsoid_columns
from radarviz.viz_app.rerun.shapes import FAINT_MARKER, MARKER, faint
from radarviz.viz_app.rerun.track_recording import ARROW_SECONDS, SERIES, TrackRecorder

#: Seconds of the session between two path chunks.
PATH_S = 1.0
#: Tracks whose time series a flush sends.
SERIES_TRACKS = 4
#: A flush draws the path of one in this many tracks with buffered rows.
PATH_SPREAD = 5
#: Path chunks kept: the chunk after the last reuses the first's entity (a static row
#: replaces the one before), so the viewer holds the paths of the last ten minutes, not
#: every path ever drawn.
PATH_CHUNKS = 600
#: The newest values the layout's frames are drawn from (``TrackRecorder.layout_kept``).
LAYOUT_KEPT = 100_000

_POS, _VEL = list(position_index(3)), list(velocity_index(3))


class LiveTrackRecorder(TrackRecorder):
    """``TrackRecorder``'s plots, inset and layout; the tracks as the module docstring says."""

    chunk_plots = None
    # Its tentative tracks are rows of the current state, as its confirmed ones.
    groups_tentative = False
    layout_kept = LAYOUT_KEPT

    def __init__(
        self,
        rec: rr.RecordingStream,
        radars: Iterable[Radar],
        monitor: ConsistencyMonitor | None = None,
        clock: Callable[[], float] = time.monotonic,
    ):
        super().__init__(rec, radars, monitor)
        self.clock = clock
        # Each live track's (target, method) latest state and whether it is tentative.
        self._now: dict[tuple[str, str], tuple[np.ndarray, np.ndarray, bool]] = {}
        # The path strips drawn since the last path chunk, by method: strips, colours, radii.
        self._strips: dict[str, tuple[list, list, list]] = {}
        self._last_path = clock()
        self._at: tuple[int, float] = (0, 0.0)
        # Confirmed rows waiting for their time series, by track entity name (its target,
        # method, colour; rows of plot, time_s, covariance, velocity), oldest first.
        self._waiting: dict[str, tuple[str, str, tuple, list]] = {}
        #: The methods drawn (None: every one).
        self.shown: frozenset[str] | None = None
        # The series slot of each track entity name holding one; the slots given back
        # (a heap: the lowest is taken first) and how many were ever made.
        self._slots: dict[str, int] = {}
        self._free_slots: list[int] = []
        self._slots_made = 0
        self._paths_made: set[str] = set()

    def add(self, plot: Plot, rows: list[StateRow], status: str = "") -> None:
        super().add(plot, rows, status)
        self._at = (self.count, plot.time_s)
        tentative = status == TENTATIVE
        for method, x, P in rows:
            self._now[(plot.target, method)] = (x, P, tentative)

    def end_scan(self, deleted: list[str]) -> None:
        """The scan's plots become rows (``TrackRecorder.end_scan``); the tracks ``deleted``
        at it leave the current state."""
        super().end_scan([])
        for target in deleted:
            self._deleted.add(target)
            for method in self._methods:
                self._now.pop((target, method), None)

    def flush(self) -> None:
        """Send the buffered plots, every method's current tracks (one row each) and the
        inset; draw a share of the paths, send a few tracks' time series, and the path chunk
        once ``PATH_S`` has passed since the last."""
        self._make_path_entities()
        self._send_measurements()
        self._send_now()
        self._send_inset()
        self._draw_paths(-(-len(self._tracks) // PATH_SPREAD))
        if self.clock() - self._last_path >= PATH_S:
            self._send_paths()
        self._send_waiting(SERIES_TRACKS)

    def close(self) -> None:
        self.end_scan([])
        self.flush()
        self._draw_paths(len(self._tracks))
        self._send_paths()
        self._send_waiting(len(self._waiting))
        super().close()  # nothing left buffered: its log lines and the layout

    def _entity_name(self, target: str, method: str) -> str:
        """A track's name as the recorder's key (``track_name``), not escaped as an entity
        path: a live track has no entity of its own (its state is a row of the method's
        entities, its time series a slot's). The Rerun SDK keeps every string it escapes for
        the life of the process (``rr.escape_entity_path_part``: about 73 bytes each, measured
        on rerun-sdk 0.41), so escaping the id of every track ever started, the clutter's
        included, made the session's memory grow with them."""
        return track_name(target, method) if target else method

    def _send_now(self) -> None:
        """One row per method of every live track: position, 1σ ellipsoid, velocity."""
        by_method: dict[str, list[tuple[str, tuple]]] = {m: [] for m in self._methods}
        for (target, method), state in self._now.items():
            by_method[method].append((target, state))
        n, t = self._at
        idx = self.indexes([n], [t])
        for method, tracks in by_method.items():
            if self.shown is not None and method not in self.shown:
                tracks = []
            k = len(tracks)
            if k:
                x = np.array([s[0] for _, s in tracks])
                P = np.array([s[1] for _, s in tracks])
                pos, vel, cov = x[:, _POS], x[:, _VEL], P[:, _POS][:, :, _POS]
            else:
                pos, vel, cov = np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3, 3))
            rgbs, radii, labels = [], [], []
            for target, (*_, tentative) in tracks:
                rgb = self._track_colour(target, self._entity_name(target, method), method)
                rgbs.append(faint(rgb) if tentative else rgb)
                radii.append(FAINT_MARKER if tentative else MARKER)
                # A confirmed track's id beside it (tentative ones are too many to name).
                labels.append("" if tentative else track_name(target, method))
            base = f"world/tracks/{method}"
            self.rec.send_columns(
                f"{base}/position",
                indexes=idx,
                columns=rr.Points3D.columns(
                    positions=pos, colors=rgbs, radii=radii, labels=labels
                ).partition([k]),
            )
            self.rec.send_columns(
                f"{base}/covariance",
                indexes=idx,
                columns=ellipsoid_columns(pos, cov, rgbs).partition([k]),
            )
            self.rec.send_columns(
                f"{base}/velocity",
                indexes=idx,
                columns=rr.Arrows3D.columns(
                    origins=pos, vectors=vel * ARROW_SECONDS, colors=rgbs
                ).partition([k]),
            )

    def _draw_paths(self, tracks: int) -> None:
        """The path strips of the buffered rows of the ``tracks`` tracks buffered longest
        (kept for the next path chunk), their confirmed rows queued for the time series; the
        tracks deleted whose rows are all drawn are forgotten."""
        for key in list(self._tracks)[:tracks]:
            items = self._tracks.pop(key)
            if not items:
                continue
            target, method = key
            name = self._entity_name(target, method)
            n, t, xs, ps, statuses = zip(*items, strict=True)
            x, P = np.array(xs), np.array(ps)
            pos, vel, cov = x[:, _POS], x[:, _VEL], P[:, _POS][:, :, _POS]
            tentative = np.array([s == TENTATIVE for s in statuses])
            rgb = self._track_colour(target, name, method)
            first, s, c, r = self._path_strips(name, pos, tentative, rgb)
            if not s:
                continue
            got = self._strips.setdefault(method, ([], [], []))
            got[0].extend(s)
            got[1].extend(c)
            got[2].extend(r)
            rows = self._waiting.setdefault(name, (target, method, rgb, []))[3]
            rows.extend(zip(n[first:], t[first:], cov[first:], vel[first:], strict=True))
        self._forget_deleted(self._deleted - {target for target, _ in self._tracks})

    def _make_path_entities(self) -> None:
        """Every path entity of each method tracked so far, made once, empty (the module
        docstring says why)."""
        for method in self._methods:
            if method in self._paths_made:
                continue
            self._paths_made.add(method)
            for k in range(PATH_CHUNKS):
                self.rec.log(
                    f"world/tracks/{method}/path/{k:06d}", rr.LineStrips3D([]), static=True
                )

    def _send_paths(self) -> None:
        """The strips drawn since the last path chunk: one static entity per method."""
        self._last_path = self.clock()
        for method, (s, c, r) in self._strips.items():
            if self.shown is not None and method not in self.shown:
                continue
            self.rec.log(
                f"world/tracks/{method}/path/{self.chunk % PATH_CHUNKS:06d}",
                rr.LineStrips3D(s, colors=c, radii=r),
                static=True,
            )
        self._strips.clear()
        self.chunk += 1

    def _send_waiting(self, tracks: int) -> None:
        """The time series of the ``tracks`` tracks waiting longest."""
        for name in list(self._waiting)[:tracks]:
            target, method, rgb, rows = self._waiting.pop(name)
            n, t, cov, vel = zip(*rows, strict=True)
            at = self.indexes(list(n), list(t))
            slot = self._series_slot(name, n[0], t[0])
            self._send_series(target, method, name, rgb, at, np.array(cov), np.array(vel), slot)
            if (target, method) not in self._now:  # deleted: no series rows after these
                self._styled.discard(name)
                self._give_back_slot(name)

    def _forget_deleted(self, targets: set[str] | None = None) -> None:
        """``TrackRecorder._forget_deleted``; a deleted track with no rows waiting for its
        series gives its slot back."""
        targets = set(self._deleted) if targets is None else targets
        super()._forget_deleted(targets)
        for target in targets:
            for method in self._methods:
                name = self._entity_name(target, method)
                if name not in self._waiting:
                    self._give_back_slot(name)

    def _series_slot(self, name: str, n: int, t: float) -> str:
        """The series slot of the track entity ``name``, taken at its first rows (plot ``n``,
        time ``t``): a slot a track held before is cleared there, so the two tracks' lines
        do not join."""
        slot = self._slots.get(name)
        if slot is None:
            if self._free_slots:
                slot = heapq.heappop(self._free_slots)
                for series in SERIES:
                    self.rec.send_columns(
                        f"plots/{series}/{slot:04d}",
                        indexes=self.indexes([n], [t]),
                        columns=rr.Clear.columns(is_recursive=[False]),
                    )
            else:
                slot = self._slots_made
                self._slots_made += 1
            self._slots[name] = slot
        return f"{slot:04d}"

    def _give_back_slot(self, name: str) -> None:
        slot = self._slots.pop(name, None)
        if slot is not None:
            heapq.heappush(self._free_slots, slot)
