"""A truth-free consistency monitor: each track's NIS over a sliding window against its χ² band.

A filter whose model matches the target produces innovations ν with covariance S, so each
update's NIS = νᵀ S⁻¹ ν (``core.filters.innovation``) is χ²(m) with m the plot's measured
components, and successive innovations are independent. Over the last w updates of a track::

    q = Σ NIS / D,   D = Σ m            (normalised windowed NIS: ≈ 1 when consistent)
    D q ~ χ²(D)   ⇒   band [χ²_D(α/2) / D,  χ²_D(1 − α/2) / D]   (two-sided, 1 − α = 0.95)

(Bar-Shalom, Li and Kirubarajan 2001, sec. 5.4.2, the single-run time-average NIS test.) A
consistent track is outside its band about α = 5% of the time (the windows overlap, so the
out-of-band time comes in runs, but its expected fraction is still α); a filter that cannot
follow its target (Q = 0 on a turning aircraft) sees innovations far beyond S and stays above
the band. Nothing here needs the truth, so it runs on a user's file.

The monitor counts, per track, the windows (one per update once w updates are in) that lie
below or above the band. A consistent track strays out briefly (that is the 5%), and one
outlying plot keeps the w windows that hold it out; a track whose windows stay out for
``sustain`` successive updates (default 2w: more than one outlier's worth) has *left* its
band: the monitor records a :class:`ConsistencyEvent` then, and another when it is back in.
"""

from __future__ import annotations

import functools
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.chi2 import chi2_quantile
from radarviz.core.params import check, check_int, check_real

#: Two-sided probability of the band.
NIS_BAND_LEVEL = 0.95
#: A track out of its band more than this fraction of the time is reported as inconsistent
#: (four times the 5% a consistent track spends outside).
INCONSISTENT_FRACTION = 0.2


@functools.lru_cache(maxsize=256)
def nis_band(dof: int, level: float = NIS_BAND_LEVEL) -> tuple[float, float]:
    """The band (lo, hi) of the normalised windowed NIS q = Σ NIS / D for D = ``dof``.

    The χ²_D quantiles at (1 − level)/2 and (1 + level)/2, by ``core.chi2.chi2_quantile``
    (no scipy: it would be a quarter of a ``track`` run's start-up).
    """
    tail = (1.0 - level) / 2.0
    return chi2_quantile(tail, dof) / dof, chi2_quantile(1.0 - tail, dof) / dof


class ConsistencyEvent(NamedTuple):
    """A track leaving (``"leaves"``) or re-entering (``"returns"``) its NIS band.

    Attributes:
        track: the track's name (a method, or ``method/model``).
        time_s: the time of the update whose window crossed.
        kind: ``"leaves"`` or ``"returns"``.
        q: the window's normalised NIS.  lo, hi: its band.
    """

    track: str
    time_s: float
    kind: Literal["leaves", "returns"]
    q: float
    lo: float
    hi: float

    def message(self) -> str:
        side = "above" if self.q > self.hi else "below"
        if self.kind == "leaves":
            value = f"{self.q:.3g}" if math.isfinite(self.q) else "not finite (a broken track)"
            return (
                f"track {self.track} has left its NIS band at t = {self.time_s:g} s: windowed "
                f"NIS/dof {value} {side} [{self.lo:.3g}, {self.hi:.3g}]"
            )
        return f"track {self.track} is back in its NIS band at t = {self.time_s:g} s"


class TrackConsistency(NamedTuple):
    """One track's consistency figures.

    Attributes:
        updates: NIS values received.  windows: full windows tested.
        above, below: windows above / below the band.
        fraction_out: (above + below) / windows (NaN before the first full window).
        mean_nis_per_dof: Σ NIS / Σ m over the whole track (≈ 1 when consistent).
        first_exit_s: time of the first exit, ``sustain`` windows out (None: never left).
        inconsistent: fraction_out > ``INCONSISTENT_FRACTION``.
    """

    updates: int
    windows: int
    above: int
    below: int
    fraction_out: float
    mean_nis_per_dof: float
    first_exit_s: float | None
    inconsistent: bool


@dataclass
class _Track:
    window: deque = field(default_factory=deque)
    nis_sum: float = 0.0
    dof_sum: int = 0
    total_nis: float = 0.0
    total_dof: int = 0
    updates: int = 0
    windows: int = 0
    above: int = 0
    below: int = 0
    run_out: int = 0
    left: bool = False
    first_exit_s: float | None = None
    history: list = field(default_factory=list)


class ConsistencyMonitor:
    """Windowed NIS of every track it is fed (module docstring).

    Args:
        window: w, updates per window (``core.params``: nis_window).
        level: the band's two-sided probability.
        on_event: called with each event as it happens (e.g. a warning printer).
        sustain: successive out-of-band windows that make an exit (default 2w).
        keep_history: keep every window's (time, q, lo, hi) (``history``; for recordings).
        keep_deleted: keep the records of tracks the tracker deleted (``forget``), for a
            run's final figures; False for a session that runs for hours (``radarviz
            live``), whose memory must follow the live tracks.
        events_kept: the newest events kept (``events``; None: every one, for a run's
            account); ``events_seen`` counts them all. A session that runs for hours keeps
            a bounded number: its events go to the viewer's log as they come
            (``TrackRecorder``), none is read again later.
    """

    def __init__(
        self,
        window: int = 10,
        level: float = NIS_BAND_LEVEL,
        on_event: Callable[[ConsistencyEvent], None] | None = None,
        sustain: int | None = None,
        keep_history: bool = False,
        keep_deleted: bool = True,
        events_kept: int | None = None,
    ) -> None:
        self.window = int(check("nis_window", window))
        self.sustain = 2 * self.window if sustain is None else int(check("nis_window", sustain))
        self.level = check_real("level", level, low=0.0, high=1.0, high_open=True)
        self.on_event = on_event
        self.keep_history = keep_history
        self.keep_deleted = keep_deleted
        if events_kept is not None:
            check_int("events_kept", events_kept, low=1)
        self.events: deque[ConsistencyEvent] = deque(maxlen=events_kept)
        self.events_seen = 0
        self._tracks: dict[str, _Track] = {}
        #: Feeds that hold some tracks' state in arrays (``core.tracking.compiled``): their
        #: state is written into the records before any is read.
        self.feeds: list[Any] = []

    def _sync(self) -> None:
        for feed in self.feeds:
            feed.store()

    @property
    def tracks(self) -> tuple[str, ...]:
        self._sync()
        return tuple(self._tracks)

    def add(self, track: str, time_s: float, nis: float, dof: int) -> None:
        """One update's NIS (with m = ``dof`` components) for ``track`` at ``time_s``."""
        if self.feeds:
            self._sync()
        if not math.isfinite(nis):
            nis = math.inf  # a broken track is as far out of its band as it gets
        tr = self._tracks.setdefault(track, _Track())
        tr.updates += 1
        tr.total_nis += nis
        tr.total_dof += dof
        tr.window.append((nis, dof))
        tr.nis_sum += nis
        tr.dof_sum += dof
        if len(tr.window) > self.window:
            old_nis, old_dof = tr.window.popleft()
            tr.nis_sum -= old_nis
            tr.dof_sum -= old_dof
        if len(tr.window) < self.window:
            return
        if math.isinf(tr.nis_sum):  # a running sum does not recover from inf: recompute
            tr.nis_sum = math.fsum(v for v, _ in tr.window)
        q = tr.nis_sum / tr.dof_sum
        lo, hi = nis_band(tr.dof_sum, self.level)
        tr.windows += 1
        if self.keep_history:
            tr.history.append((time_s, q, lo, hi))
        out = not lo <= q <= hi
        tr.above += q > hi
        tr.below += q < lo
        tr.run_out = tr.run_out + 1 if out else 0
        if tr.run_out == self.sustain or (tr.left and not out):
            tr.left = out
            if out and tr.first_exit_s is None:
                tr.first_exit_s = time_s
            self.record(ConsistencyEvent(track, time_s, "leaves" if out else "returns", q, lo, hi))

    def record(self, event: ConsistencyEvent) -> None:
        """An event happened: kept (the newest ``events_kept``), counted, and handed to
        ``on_event``."""
        self.events.append(event)
        self.events_seen += 1
        if self.on_event is not None:
            self.on_event(event)

    def forget(self, tracks: list[str]) -> None:
        """Drop the records of ``tracks`` (deleted by the tracker), unless ``keep_deleted``."""
        if self.keep_deleted:
            return
        self._sync()
        for track in tracks:
            self._tracks.pop(track, None)

    def result(self, track: str) -> TrackConsistency:
        """The figures of ``track`` so far."""
        self._sync()
        tr = self._tracks[track]
        frac = (tr.above + tr.below) / tr.windows if tr.windows else math.nan
        mean = tr.total_nis / tr.total_dof if tr.total_dof else math.nan
        return TrackConsistency(
            tr.updates,
            tr.windows,
            tr.above,
            tr.below,
            frac,
            mean,
            tr.first_exit_s,
            bool(tr.windows) and frac > INCONSISTENT_FRACTION,
        )

    def history(self, track: str) -> NDArray[np.float64]:
        """(W, 4) rows (time, q, lo, hi) of every window of ``track`` (``keep_history``)."""
        self._sync()
        rows = self._tracks[track].history if track in self._tracks else []
        return np.array(rows, dtype=np.float64).reshape(-1, 4)

    def results(self) -> dict[str, TrackConsistency]:
        self._sync()
        return {name: self.result(name) for name in self._tracks}


def windowed_nis(
    nis: NDArray[np.float64], dof: NDArray[np.int64], window: int
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Every full window's q = Σ NIS / D and D, for a batch of tracks at once.

    Args:
        nis: (N, ...) NIS of N successive updates of each track (same plots for all).
        dof: (N,) measured components of each update.
        window: w.

    Returns:
        q (N − w + 1, ...) and D (N − w + 1,): window i ends at update i + w − 1, as the
        monitor's i-th test.
    """
    window = int(check("nis_window", window))
    c = np.concatenate([np.zeros((1, *nis.shape[1:])), np.cumsum(nis, axis=0)])
    d = np.concatenate([[0], np.cumsum(dof)])
    D = d[window:] - d[:-window]
    q = (c[window:] - c[:-window]) / D.reshape(-1, *([1] * (nis.ndim - 1)))
    return q, D


def out_of_band(
    q: NDArray[np.float64], D: NDArray[np.int64], level: float = NIS_BAND_LEVEL
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """(below, above) the band for windows q (W, ...) of D (W,) components."""
    bands = np.array([nis_band(int(v), level) for v in D])  # few distinct D: cached
    shape = (-1, *([1] * (q.ndim - 1)))
    return q < bands[:, 0].reshape(shape), q > bands[:, 1].reshape(shape)
