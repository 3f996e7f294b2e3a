"""``radarviz live``'s command: flags checked, the viewer and the recording set up, the
session (``viz_app.live.session``) run, the account said and saved.

The viewer is the tuning panel's: a ``rerun --serve-web`` child bound to ``--host``
(127.0.0.1 by default) in its own process group, stopped at the end. ``--rrd`` sends the same
stream to a staged temporary file beside the target as well, renamed onto it once it reads
back whole (``viz_app.rerun.recording.verify_recording``); Ctrl-C ends the session the same
way, so the file holds what was tracked until then.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import hashlib
import json
import queue
import signal
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from radarviz.core.finite import check_finite_document
from radarviz.core.params import ParameterError, check_int, check_real
from radarviz.core.tracking.stream import Plot
from radarviz.viz_app.io.atomic import Stage, atomic_write, check_outputs
from radarviz.viz_app.io.plots import load_radars, radar_coverage
from radarviz.viz_app.live.control import LiveControl
from radarviz.viz_app.live.replay import parse_address
from radarviz.viz_app.live.session import (
    QUEUE_PLOTS,
    RESERVED_TRACKS,
    FeedCounts,
    FollowedFile,
    Horizon,
    UdpFeed,
    latency_ms,
    read_feed,
    track_feed,
    warm_up,
    warn_line,
)
from radarviz.viz_app.rerun.viewer import is_loopback
from radarviz.viz_app.runtime import peak_rss_mb

if TYPE_CHECKING:
    from radarviz.viz_app.live.panel import LivePanel

#: How long a saved recording may take to read back whole after the stream ends (s).
SETTLE_S = 10.0
#: Longest session asked for (s): a day.
MAX_DURATION_S = 86_400.0
#: Consistency events the session's monitor keeps (``ConsistencyMonitor.events_kept``): each
#: goes to the viewer's log as it comes, and a feed of hours makes them without end.
EVENTS_KEPT = 1000


def _options(args: argparse.Namespace) -> tuple[Any, Any, Any, tuple[str, ...]]:
    """The tracker's options as ``track --associate gnn`` builds them from the same flags."""
    from radarviz.core.experiments.prosov import ALL_METHODS
    from radarviz.core.tracking.association import AssociationOptions
    from radarviz.core.tracking.consistency import ConsistencyMonitor
    from radarviz.core.tracking.stream import StreamOptions, motion_fields
    from radarviz.viz_app.cli.track import LIVE_ASSOCIATION_FLAGS

    given = {n: getattr(args, n) for n, _ in LIVE_ASSOCIATION_FLAGS}
    association = AssociationOptions(**{k: v for k, v in given.items() if v is not None})
    # Hours of a feed start millions of tracks: the monitor keeps the live ones, and the
    # newest of their events.
    monitor = ConsistencyMonitor(keep_deleted=False, events_kept=EVENTS_KEPT)
    options = StreamOptions(monitor=monitor, **motion_fields())
    methods = tuple(args.method) if args.method else ALL_METHODS
    return association, monitor, options, methods


def run_live(args: argparse.Namespace) -> int:
    check_real("--reorder-s", args.reorder_s, low=0.0, high=60.0, low_open=False)
    check_real("--budget-ms", args.budget_ms, low=0.0, high=10_000.0)
    if args.duration_s is not None:
        check_real("--duration-s", args.duration_s, low=0.0, high=MAX_DURATION_S)
    if args.max_plots is not None:
        check_int("--max-plots", args.max_plots, low=1, high=10**12)
    check_int("--viewer-port", args.viewer_port, low=0, high=65535)
    check_int("--panel-port", args.panel_port, low=0, high=65535)
    inputs = [("--radars", args.radars)] + ([("--follow", args.follow)] if args.follow else [])
    check_outputs([("--rrd", args.rrd), ("--summary", args.summary)], inputs)
    address = parse_address("--udp", args.udp) if args.udp else None
    exposed = not is_loopback(args.host)
    if address is not None and not address.loopback and not exposed:
        raise ParameterError(
            f"--udp {address} listens beyond this machine: give --host (an address of this "
            "machine, or 0.0.0.0) to say so"
        )
    if exposed:
        warn_line(
            f"binding {args.host}: the feed's socket and the viewer are reachable from other "
            "machines"
        )
    radars = load_radars(args.radars)
    association, monitor, options, methods = _options(args)
    from radarviz.core.tracking.association import GNNTracker

    coverage = {n: radar_coverage(r) for n, r in radars.items()}

    def make(options: Any, association: Any) -> GNNTracker:
        # Memory that does not grow with the session: the ids of the tracks confirmed are
        # not kept (their number is), the tracks' arrays are made at their size at once.
        made = GNNTracker(
            methods, False, options, association, coverage=coverage, keep_confirmed=False
        )
        made.reserve(RESERVED_TRACKS)
        return made

    try:
        tracker = make(options, association)
    except ParameterError as exc:
        if exc.parameter:
            raise
        raise ParameterError(f"--{exc}") from None
    control = LiveControl(tracker, options, association, make)

    counts = FeedCounts()
    stop = threading.Event()
    feed: UdpFeed | FollowedFile
    if address is not None:
        feed = UdpFeed(address, stop, counts, warn_line)
        source = f"udp {address}"
    else:
        feed = FollowedFile(open(args.follow, "rb"), stop, counts)
        source = args.follow
    with contextlib.ExitStack() as stack:
        stack.callback(feed.close)
        recorder, finish, viewer = _recording(args, radars, monitor, stack)
        if args.panel:
            _serve_panel(args, control, viewer, stack)
        if recorder is not None:

            def show(c: LiveControl) -> None:
                recorder.shown = frozenset(c.settings.shown)

            control.listeners.append(show)
        plots: queue.Queue = queue.Queue(QUEUE_PLOTS)
        horizon = Horizon(args.reorder_s)
        # The antennas' timing the feed's CAT034 messages give, for the batches' periods.
        timing: dict = {}
        warm_up(make, options, association, radars)
        # What is made by now (the imported modules, the compiled kernels) lives to
        # the end: frozen out of the cycle collector's reach, so its full passes walk only
        # what the session makes, not the pauses of a second a plot's latency would take.
        gc.collect()
        gc.freeze()
        reader = threading.Thread(
            target=read_feed,
            args=(feed, source, radars, plots, horizon, args.max_plots, warn_line, timing),
            name="live-reader",
            daemon=True,
        )
        if args.duration_s is not None:
            timer = threading.Timer(args.duration_s, stop.set)
            timer.daemon = True
            timer.start()
            stack.callback(timer.cancel)
        start = time.monotonic()
        reader.start()
        stack.enter_context(_ctrl_c_ends(feed))
        print(f"radarviz: live: tracking {source}; stop with Ctrl-C", file=sys.stderr, flush=True)
        laid_out = [False]

        def after_run() -> None:
            if recorder is not None:
                recorder.flush()
                if not laid_out[0]:
                    recorder.send_layout()
                    laid_out[0] = True

        # The plots' track ids in order, and their tracks' statuses, hashed: two runs on the
        # same feed (or this one and ``track --associate gnn`` on its recording) compare by
        # them, in memory that does not grow with the session as a list of them would.
        ids, statuses = hashlib.sha256(), hashlib.sha256()
        log_rows = recorder.add if recorder is not None else _discard

        def on_rows(plot: Plot, rows: list, status: str = "") -> None:
            ids.update(plot.target.encode() + b"\n")
            statuses.update(status.encode() + b"\n")
            log_rows(plot, rows, status)

        latencies: Any = []
        parts: dict[str, Any] = {}
        try:
            latencies, parts = track_feed(
                plots,
                control,
                counts,
                association.batch_sector_deg,
                horizon,
                args.budget_ms / 1e3,
                on_rows,
                recorder.end_scan if recorder is not None else None,
                after_run,
                timing,
            )
        except KeyboardInterrupt:  # a second Ctrl-C (``_ctrl_c_ends``)
            feed.interrupts += 1
        interrupted = feed.interrupts > 0
        stop.set()
        reader.join(timeout=5.0)
        # Plots the tracker had not finished at an interrupt (in the queue, waiting for their
        # time order or their batch): still accounted for, as untracked.
        left = counts.plots - counts.tracked - counts.out_of_order - counts.dropped
        seconds = time.monotonic() - start
        tracker = control.tracker
        if recorder is not None:
            recorder.report(tracker.report())
        finish()
    doc = _summary(source, counts, tracker, latencies, seconds, left)
    doc["settings"] = control.document()
    doc["latency_parts_ms"] = {k: latency_ms(v)["median"] for k, v in parts.items()}
    doc["track_ids_sha256"] = ids.hexdigest()
    doc["track_statuses_sha256"] = statuses.hexdigest()
    check_finite_document("live", doc, nonnegative=True)
    if args.summary:
        with atomic_write(args.summary, "w", encoding="utf-8") as fh:
            json.dump(doc, fh, indent=2, allow_nan=False)
            fh.write("\n")
    print(f"radarviz: live: {account_line(doc)}", file=sys.stderr, flush=True)
    if interrupted:
        saved = f"; {args.rrd} holds the session so far" if args.rrd else ""
        print(f"radarviz: interrupted: live stopped{saved}", file=sys.stderr)
        return 130
    return 0


@contextlib.contextmanager
def _ctrl_c_ends(feed: UdpFeed | FollowedFile) -> Iterator[None]:
    """Ctrl-C (SIGINT) ends the session as the end of its feed does: the handler only
    counts it (``feed.interrupts``), the reader's thread sees the count within ``POLL_S``
    and ends the feed, the tracker tracks what is queued and returns, and the recording is
    finished whole. Nothing is raised into the tracker, the recorder or a finalizer running
    on the main thread (a ``KeyboardInterrupt`` raised inside a ``__del__`` or a callback of
    the cycle collector is printed and dropped, and the session went on for ever). A second
    Ctrl-C raises ``KeyboardInterrupt`` as usual. Outside the main thread (no signals
    there), nothing is installed."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: Any) -> None:
        feed.interrupts += 1
        signal.signal(signal.SIGINT, signal.default_int_handler)

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _discard(*_: object) -> None:
    """No recording: the rows are not kept (the account and the latency still are)."""


def _recording(
    args: argparse.Namespace, radars: dict, monitor: Any, stack: contextlib.ExitStack
) -> tuple[Any, Any, str | None]:
    """The recorder (None without viewer and ``--rrd``), the function ending it, and the
    viewer's address for the panel's page (None without viewer)."""
    if args.no_viewer and args.rrd is None:
        return None, lambda: None, None
    import rerun as rr

    from radarviz.viz_app.rerun.live_recording import LiveTrackRecorder
    from radarviz.viz_app.rerun.recording import new_recording, verify_recording

    sinks = []
    stage = None
    if args.rrd is not None:
        stage = Stage(args.rrd, overwrite=True)
        stack.callback(stage.abort)  # a no-op once renamed
        stage.close_fd()
        sinks.append(rr.FileSink(str(stage.path)))
    viewer = None
    if not args.no_viewer:
        grpc, viewer = _serve_viewer(args, stack)
        sinks.append(rr.GrpcSink(grpc))
    rec = new_recording()
    rec.set_sinks(*sinks)
    recorder = LiveTrackRecorder(rec, radars.values(), monitor)

    def finish() -> None:
        recorder.close()
        rec.flush()
        rec.disconnect()
        if stage is not None:
            stage.commit(verify=settled)

    def settled(path: Path) -> None:
        # The file sink writes from its own thread; beside a gRPC sink that is slow to drain,
        # the footer has been seen to land just after ``disconnect`` returns: read the file
        # back until it is whole, for a few seconds, before calling it broken.
        end = time.monotonic() + SETTLE_S
        while True:
            try:
                verify_recording(path)
                return
            except Exception:
                if time.monotonic() > end:
                    raise
                time.sleep(0.2)

    return recorder, finish, viewer


def _serve_viewer(args: argparse.Namespace, stack: contextlib.ExitStack) -> tuple[str, str]:
    """Start the web viewer (``tune``'s), print its address; the gRPC address to log to and
    the viewer's address for the panel's page."""
    from radarviz.viz_app.rerun.viewer import (
        bind_address,
        check_port_free,
        connect_address,
        free_port,
        viewer_url,
        wait_viewer,
    )
    from radarviz.viz_app.tune.page import embedded_viewer_url
    from radarviz.viz_app.tune.serve import grpc_uri, start_rerun, stop_process_group, wait_port

    bind = bind_address("--host", args.host)
    check_port_free("--viewer-port", bind, args.viewer_port)
    connect = connect_address(bind)
    grpc_port = free_port(connect)
    web_port = args.viewer_port or free_port(connect)
    proc = start_rerun(bind, grpc_port, web_port)
    stack.callback(stop_process_group, proc)
    wait_port(bind, grpc_port, proc=proc)
    wait_viewer(proc, "--viewer-port", bind, web_port)
    print(f"viewer {viewer_url(connect, web_port, grpc_port)}", flush=True)
    return grpc_uri(bind, grpc_port), embedded_viewer_url(connect, web_port, grpc_port)


def _serve_panel(
    args: argparse.Namespace, control: LiveControl, viewer: str | None, stack: contextlib.ExitStack
) -> LivePanel:
    """Start the panel (``tune``'s guarded Viser server, with the viewer beside the controls
    when there is one) on ``--host``, print its address."""
    from radarviz.viz_app.live.panel import LivePanel
    from radarviz.viz_app.rerun.viewer import bind_address, check_port_free, connect_address
    from radarviz.viz_app.tune.guard import PanelGuard, guarded_viser_server
    from radarviz.viz_app.tune.page import panel_page, serve_page

    bind = bind_address("--host", args.host)
    check_port_free("--panel-port", bind, args.panel_port)
    guard = PanelGuard(host=args.host, bind=bind)
    page = panel_page(viewer, title="radarviz live") if viewer is not None else None
    wrap = (lambda inner: serve_page(inner, page)) if page is not None else None
    server = guarded_viser_server(guard, args.panel_port, wrap=wrap, verbose=False)
    stack.callback(server.stop)
    panel = LivePanel(server, control)
    stack.callback(panel.close)
    print(f"panel {guard.url(connect_address(bind), server.get_port())}", flush=True)
    return panel


def _summary(
    source: str, counts: FeedCounts, tracker: Any, latencies: Any, seconds: float, left: int
) -> dict[str, Any]:
    report = tracker.report()
    doc = {"source": source, "seconds": seconds, **counts.document()}
    doc["untracked_at_stop"] = left
    doc["latency_ms"] = latency_ms(latencies)
    doc["tracks_started"] = report.started
    doc["tracks_confirmed"] = report.confirmed
    doc["peak_rss_mb"] = peak_rss_mb()
    return doc


def account_line(doc: dict[str, Any]) -> str:
    """The summary as one line of words."""
    bad = sum(doc["malformed"].values())
    lat = doc["latency_ms"]
    latency = (
        f"latency median {lat['median']:.0f} ms, p99 {lat['p99']:.0f} ms"
        if lat["median"] is not None
        else "no plot tracked"
    )
    return (
        f"{doc['datagrams']} datagrams ({bad} malformed), {doc['plots']} plots: "
        f"{doc['tracked']} tracked, {doc['out_of_order']} out of order, {doc['dropped']} "
        f"dropped, {doc['untracked_at_stop']} untracked at the stop; "
        f"{doc['duplicate_records']} duplicate records; {latency}; {doc['tracks_started']} "
        f"tracks started, {doc['tracks_confirmed']} confirmed, in {doc['seconds']:.1f} s"
    )
