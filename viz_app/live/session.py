"""``radarviz live``: an ASTERIX feed tracked as it arrives.

Two threads and a bounded queue between them:

* **the reader** (a thread) receives the feed, a UDP socket (``UdpFeed``; a multicast group
  is joined) or a growing ``.ast`` file (``FollowedFile``), and decodes it with the file
  reader itself (``viz_app.io.asterix.AsterixReader``, reading the feed as a file that never
  ends), so a datagram is checked exactly as a recorded file is. Each plot goes into the
  queue with the time its datagram arrived; a full queue (the tracker behind) drops the plot
  and counts it. A datagram that is not a run of data blocks, and a record the reader
  refuses, are counted as malformed, each kind reported once on stderr, and the feed goes
  on (the reader starts again on the next datagram; its duplicate window restarts with it).
* **the tracker** (the calling thread) takes the plots from the queue, puts them in time
  order (``core.tracking.association.time_ordered``, with the session's ``Horizon``: short
  while the feed comes in order, as it adds its length to every plot's latency), cuts them
  into batches (``plot_batches``) and runs the held batches in one compiled call
  (``viz_app.io.plots.BatchRunner``, the runner of ``track --associate``) as soon as the
  queue is empty (the tracker has caught up; at most every ``MIN_RUN_S``), and at the latest
  when ``budget_s`` has passed since the first of them was held, or ``READ_BLOCK`` plots are
  held: a light feed's plots are tracked as they come, a heavy one's in larger runs. The
  kernels are loaded before the feed starts (``warm_up``), not by its first plots. Results
  go to a ``LiveTrackRecorder`` (``viz_app.rerun.live_recording``: ``track --rrd``'s plots,
  one row of every live track per method), flushed after every run, so the viewer shows each
  run as it is done. Where the latency goes is counted too (``LATENCY_PARTS``).

A plot earlier than the latest received by more than the horizon cannot be put back in
order; it is counted as out of order and passed over (``time_ordered`` would refuse it), and
the horizon grows so that the next one as late is taken.

Every plot the reader decodes is counted once: tracked, out of order, or dropped; every
datagram: delivered to the reader or malformed. Records the reader passes over are counted
as it counts them in a file (duplicates, track-only).
"""

from __future__ import annotations

import math
import queue
import re
import socket
import struct
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import IO, Any

import numpy as np

from radarviz.core.params import ParameterError
from radarviz.core.tracking.association import GNNTracker, plot_batches, time_ordered
from radarviz.core.tracking.stream import Plot
from radarviz.viz_app.io.asterix import AsterixReader, ScanTiming, tiled_blocks
from radarviz.viz_app.io.plots import READ_BLOCK, BatchRunner, Radar, scan_period
from radarviz.viz_app.live.control import LiveControl
from radarviz.viz_app.live.replay import Address
from radarviz.viz_app.newest import NewestValues

#: Seconds a blocking receive or file read waits before looking at the stop flag.
POLL_S = 0.05
#: Plots the queue between the reader and the tracker holds; beyond, plots are dropped.
QUEUE_PLOTS = 65_536
#: Largest UDP datagram.
MAX_DATAGRAM = 65_535
#: Latencies kept for the percentiles (the newest).
LATENCIES_KEPT = 1_000_000
#: Where a plot's latency goes (s each): from its datagram's arrival to the tracker taking it
#: from the queue (decoding, the queue), from there to its batch held (the time order
#: horizon, the batch waiting for its last plot), to the run starting, the run (association),
#: and the recording's flush after it.
LATENCY_PARTS = ("queue", "order", "wait", "run", "flush")
#: Latencies kept per part.
PARTS_KEPT = 100_000
#: Shortest time between two runs of the tracker (s): a run as soon as the queue is empty
#: would otherwise make a run, and a flush to the viewer, of every datagram of a light feed.
MIN_RUN_S = 0.02
#: Tracks the session's tracker has room for from its start (``GNNTracker.reserve``): those
#: a run may start (one per plot, ``READ_BLOCK`` and a batch) beside about three thousand
#: live ones. A tracker's arrays otherwise double when a run needs more room, and the first
#: long run (the tracker held up a second) came minutes into a soak: 3.9 MiB at once, from
#: 620 track slots to 2 480, over a scene of about 330 live tracks.
RESERVED_TRACKS = 4 * READ_BLOCK
#: The queue's end mark.
_END = None


@dataclass
class FeedCounts:
    """The session's account (module docstring). ``malformed`` counts by kind."""

    datagrams: int = 0
    octets: int = 0
    malformed: Counter = field(default_factory=Counter)
    plots: int = 0
    tracked: int = 0
    out_of_order: int = 0
    dropped: int = 0
    duplicates: int = 0
    track_only: int = 0

    def document(self) -> dict[str, Any]:
        return {
            "datagrams": self.datagrams,
            "octets": self.octets,
            "malformed": dict(self.malformed),
            "plots": self.plots,
            "tracked": self.tracked,
            "out_of_order": self.out_of_order,
            "dropped": self.dropped,
            "duplicate_records": self.duplicates,
            "track_only_records": self.track_only,
        }


def malformed_kind(message: str) -> str:
    """A refused record's kind: the reader's message without its place and numbers, so each
    kind is said once however often it comes."""
    what = message.split(": ", 1)[-1] if ", item " not in message else message
    what = re.sub(r"^.*?, item ", "item ", what)
    return re.sub(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", "N", what)


class _Feed:
    """A feed read as a binary file by ``AsterixReader``: ``read`` blocks until octets come
    and returns b"" once ``stop`` is set; ``arrived`` is when the last octets came."""

    def __init__(self, stop: threading.Event, counts: FeedCounts):
        self.stop = stop
        self.counts = counts
        self.arrived = time.monotonic()
        #: Whether the session has read all it was asked for (``read_feed``): ``read``
        #: then ends the feed, as it does once ``interrupts`` (``radarviz live``'s Ctrl-C,
        #: counted by its signal handler) is not 0.
        self.enough: Callable[[], bool] = lambda: False
        self.interrupts = 0

    def ended(self) -> bool:
        """Whether the feed is over (stopped, read as far as asked, or interrupted): the
        reader's thread sets ``stop`` then, so a signal handler never has to."""
        if not self.stop.is_set() and (self.interrupts or self.enough()):
            self.stop.set()
        return self.stop.is_set()

    def read(self, n: int = -1) -> bytes:
        raise NotImplementedError


class UdpFeed(_Feed):
    """Datagrams of a UDP socket bound to ``address`` (a multicast group joined on every
    interface); a datagram not tiled by ASTERIX data blocks is counted malformed and skipped."""

    def __init__(self, address: Address, stop: threading.Event, counts: FeedCounts, warn: Callable):
        super().__init__(stop, counts)
        self.warn = warn
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        if address.multicast:
            # Several listeners of one group on a machine is how multicast feeds are used.
            # Not for a unicast port: with SO_REUSEADDR Linux lets a second socket bind a
            # port in use and takes its datagrams from the first without a word.
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        # A burst of a whole scan must not overflow the kernel's buffer while the reader
        # decodes: ask for a large one (the kernel caps it).
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 24)
        try:
            sock.bind(("" if address.multicast else address.host, address.port))
            if address.multicast:
                group = struct.pack("4s4s", socket.inet_aton(address.host), bytes(4))
                sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, group)
        except OSError as exc:
            sock.close()
            why = exc.strerror or exc
            raise ParameterError(f"--udp {address}: cannot listen ({why})") from None
        sock.settimeout(POLL_S)
        self.sock = sock

    def read(self, n: int = -1) -> bytes:
        while not self.ended():
            try:
                data = self.sock.recv(MAX_DATAGRAM)
            except TimeoutError:
                continue
            self.counts.datagrams += 1
            self.counts.octets += len(data)
            if tiled_blocks(data) is None:
                note(self.counts, "a datagram that is not a run of ASTERIX data blocks", self.warn)
                continue
            self.arrived = time.monotonic()
            return data
        return b""

    def close(self) -> None:
        self.sock.close()


class FollowedFile(_Feed):
    """A growing file of data blocks, read as it grows (from its start)."""

    def __init__(self, fh: IO[bytes], stop: threading.Event, counts: FeedCounts):
        super().__init__(stop, counts)
        self.fh = fh

    def read(self, n: int = -1) -> bytes:
        while not self.ended():
            data = self.fh.read(1 << 16)
            if data:
                self.counts.octets += len(data)
                self.arrived = time.monotonic()
                return data
            time.sleep(POLL_S)
        return b""

    def close(self) -> None:
        self.fh.close()


def note(counts: FeedCounts, kind: str, warn: Callable[[str], None]) -> None:
    """Count a malformed input of ``kind``; its first one is said."""
    counts.malformed[kind] += 1
    if counts.malformed[kind] == 1:
        warn(f"malformed input skipped (counted, said once): {kind}")


class Horizon:
    """The time order horizon (s of feed time) of a session: ``FLOOR_S`` at the start, then
    ``MARGIN`` times the largest lateness seen (how much earlier a plot came than the latest
    before it), at most ``cap_s`` (``--reorder-s``). It never shrinks, so a plot the reader
    lets in is never refused by ``time_ordered`` later. A feed in time order waits only the
    floor; the first plot of a feed later than the horizon is passed over (counted out of
    order) and the horizon grows to take the next one like it."""

    #: Horizon at the start (s): a few of the records' time-of-day steps (1/128 s).
    FLOOR_S = 0.05
    #: The horizon over the largest lateness seen.
    MARGIN = 2.0

    def __init__(self, cap_s: float):
        self.cap_s = cap_s
        self.s = min(self.FLOOR_S, cap_s)

    def admits(self, lateness_s: float) -> bool:
        """Whether a plot ``lateness_s`` earlier than the latest before it (> 0) is let in
        (within the horizon); the horizon grows by it either way."""
        admitted = lateness_s <= self.s
        grown = min(self.cap_s, self.MARGIN * lateness_s)
        if grown > self.s:
            self.s = grown
        return admitted

    def __call__(self) -> float:
        return self.s


def read_feed(
    feed: _Feed,
    source: str,
    radars: dict[str, Radar],
    out: queue.Queue,
    horizon: Horizon,
    max_plots: int | None,
    warn: Callable[[str], None],
    timing: dict[str, ScanTiming] | None = None,
) -> None:
    """The reader thread (module docstring): decode ``feed`` into ``out`` until it ends,
    or until ``max_plots`` plots and duplicate records have come (a duplicate is a plot the
    feed sent, passed over). ``timing``: each radar's antenna timing as the feed's CAT034
    messages tell it so far (``AsterixReader.scan_timing``), kept up to date for the tracker
    (``track_feed``), across the reader's restarts."""
    counts, stop = feed.counts, feed.stop
    latest = -math.inf
    reader: AsterixReader | None = None

    def enough() -> bool:
        if max_plots is None:
            return False
        now = reader.counts.duplicates_dropped if reader is not None else 0
        return counts.plots + counts.duplicates + now >= max_plots

    feed.enough = enough  # a duplicate last record stops the feed too
    try:
        while not stop.is_set():
            reader = None
            try:
                reader = AsterixReader(feed, source, radars)  # type: ignore[arg-type]
                services = 0
                for position, plot in reader:
                    counts.plots += 1
                    if timing is not None and reader.counts.cat034_messages != services:
                        services = reader.counts.cat034_messages
                        timing.update(reader.scan_timing)
                    late = latest - plot.time_s
                    if late > 0 and not horizon.admits(late):
                        counts.out_of_order += 1
                    else:
                        latest = max(latest, plot.time_s)
                        try:
                            out.put_nowait((feed.arrived, position, plot))
                        except queue.Full:
                            counts.dropped += 1
                    if enough():
                        stop.set()
                        break
                if not stop.is_set():  # the feed ended by itself
                    stop.set()
            except ParameterError as exc:
                if not stop.is_set():
                    note(counts, malformed_kind(str(exc)), warn)
            finally:
                if reader is not None:
                    counts.duplicates += reader.counts.duplicates_dropped
                    counts.track_only += reader.counts.track_only_skipped
    finally:
        out.put(_END)


@dataclass
class LiveResult:
    """What a session did: its counts, the tracker, each tracked plot's latency (s, from its
    datagram's arrival to its rows logged) and the session's length (s)."""

    counts: FeedCounts
    tracker: GNNTracker
    latencies_s: np.ndarray
    seconds: float


def track_feed(
    plots: queue.Queue,
    tracker: GNNTracker | LiveControl,
    counts: FeedCounts,
    sector_deg: float,
    horizon_s: float | Callable[[], float],
    budget_s: float,
    on_rows: Callable[..., None],
    on_scan: Callable[[list[str]], None] | None,
    after_run: Callable[[], None] | None,
    timing: dict[str, ScanTiming] | None = None,
) -> list[float]:
    """The tracker (module docstring): until the reader's end mark, associate the queue's
    plots whenever the queue is empty (the tracker has caught up with the feed; at most every
    ``MIN_RUN_S``), and at the latest ``budget_s`` after the first held plot; returns the
    latencies (s) of the newest ``LATENCIES_KEPT`` plots, and their parts
    (``LATENCY_PARTS``) for the newest ``PARTS_KEPT``.

    Given a ``LiveControl`` (``viz_app.live.control``) instead of a tracker, the settings
    the panel left there are taken before every run (a new tracker, if the change asks for
    one, gets the held plots), and track ids are the control's (``LiveControl.track_id``)."""
    control = tracker if isinstance(tracker, LiveControl) else None

    def rows_named(plot: Plot, rows: list, status: str = "") -> None:
        if control is not None and control.generation:
            plot = replace(plot, target=control.track_id(plot.target))
        on_rows(plot, rows, status)

    def scan_named(deleted: list[str]) -> None:
        if on_scan is not None:
            on_scan([control.track_id(t) for t in deleted] if control is not None else deleted)

    first = control.tracker if control is not None else tracker
    assert isinstance(first, GNNTracker)
    locate = lambda key, column: f"plot {key[1]}"  # noqa: E731
    runner = BatchRunner(first, "live", locate, rows_named, scan_named)
    latencies = NewestValues(LATENCIES_KEPT)
    parts = {name: NewestValues(PARTS_KEPT) for name in LATENCY_PARTS}
    first_held = [0.0]
    last_run = [0.0]
    held_at: list[tuple[int, float]] = []  # (plots, when) of every batch held

    def run() -> None:
        if control is not None and control.apply(on_scan):
            runner.tracker = control.tracker
        start = last_run[0] = time.monotonic()
        keys = runner.run()
        if not keys:
            return
        ran = time.monotonic()
        if after_run is not None:
            after_run()
        now = time.monotonic()
        k = np.array([(key[0], key[2]) for key in keys])
        n, at = zip(*held_at, strict=True)
        held = np.repeat(np.array(at), n)
        held_at.clear()
        latencies.add(now - k[:, 0])
        parts["queue"].add(k[:, 1] - k[:, 0])
        parts["order"].add(held - k[:, 1])
        parts["wait"].add(start - held)
        parts["run"].add(np.full(len(keys), ran - start))
        parts["flush"].add(np.full(len(keys), now - ran))
        counts.tracked += len(keys)

    def due() -> bool:
        if runner.held == 0:
            return False
        now = time.monotonic()
        return (
            runner.held >= READ_BLOCK
            or now - first_held[0] >= budget_s
            or (plots.empty() and now - last_run[0] >= MIN_RUN_S)
        )

    def arrivals() -> Iterator[tuple[tuple[float, int, float], Plot]]:
        while True:
            try:
                item = plots.get(timeout=MIN_RUN_S if runner.held else budget_s / 2)
            except queue.Empty:
                item = False
            if item is _END:
                return
            if item:
                arrived, position, plot = item
                yield (arrived, position, time.monotonic()), plot
            if due():
                run()

    for batch in plot_batches(time_ordered(arrivals(), horizon_s), sector_deg):
        now = time.monotonic()
        if runner.held == 0:
            first_held[0] = now
        runner.hold(batch, scan_period(timing, batch))
        held_at.append((len(batch), now))
    run()
    return latencies.values(), {name: ring.values() for name, ring in parts.items()}


def warm_up(make: Callable[..., GNNTracker], options: Any, association: Any, radars: dict) -> None:
    """Load the tracker's compiled kernels (from the cache, or compiled) before the feed's clock
    starts: a throwaway tracker of the same options (a monitor of its own) takes a target
    seen four times by every radar, so the first plots of the feed do not wait for them."""
    from radarviz.core.tracking.consistency import ConsistencyMonitor

    tracker = make(replace(options, monitor=ConsistencyMonitor(keep_deleted=False)), association)
    batches = []
    for k in range(4):
        for radar in radars.values():
            period_s = radar.rotation_period_s or 4.0
            site = (radar.x_m, radar.y_m, radar.z_m)
            x, y = radar.x_m + 20e3 + 50.0 * period_s * k, radar.y_m + 20e3
            r = math.hypot(x - radar.x_m, y - radar.y_m)
            az = math.atan2(x - radar.x_m, y - radar.y_m) % (2 * math.pi)
            sigma_r_m, sigma_beta_rad = radar.sigma_r_m, math.radians(radar.sigma_beta_deg)
            t = period_s * k
            batches.append([Plot(t, r, az, sigma_r_m, sigma_beta_rad, site, radar.name)])
    batches.sort(key=lambda b: b[0].time_s)
    tracker.add_batches(batches, [None] * len(batches))


def latency_ms(latencies_s: np.ndarray | list[float]) -> dict[str, float | None]:
    """Median and 99th percentile of the latencies, ms (None without any)."""
    if len(latencies_s) == 0:
        return {"median": None, "p99": None}
    a = np.asarray(latencies_s) * 1e3
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99))}


def warn_line(text: str) -> None:
    print(f"radarviz: live: {text}", file=sys.stderr, flush=True)
