"""A radar feed replayed and tracked as it comes (``radarviz replay``, ``radarviz live``).

* The test's capture: a rotating-radar scene of four radars and a few hundred targets
  (``core.scenarios.rotating``), written as ASTERIX (``viz_app.io.asterix.write_asterix``)
  and wrapped in a pcap, one UDP datagram per data block of ``RECORDS_PER_DATAGRAM`` records,
  each stamped with its first plot's time (as a capture of the feed would be).
* ``replay``: every datagram reaches a socket the test listens on, byte for byte and in
  order, and at the capture's pace: the arrival times' span is the capture's span over the
  speed, within a loose margin (the machine is shared: this checks the pacing is applied,
  not its precision).
* ``live``: the capture replayed at 2000 plots/s for over a minute into
  ``live --udp … --no-viewer``:
  every plot accounted for (tracked, out of order, dropped: here all tracked), and the
  plots' track ids, in order, those of ``track --associate gnn`` on the capture itself
  (compared by the summary's hash of them); the latency is in the summary, finite.
* Bad input: one line naming the flag, exit 2.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import re
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_pcap import as_block, ethernet, ipv4, records_of, udp

from radarviz.core.experiments.association import rotating_scene_plots
from radarviz.core.scenarios.rotating import RotatingRadar, air_traffic, rotating_plots
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io import asterix as ax
from radarviz.viz_app.io.plots import Radar

ROOT = Path(__file__).resolve().parents[1]
RADARVIZ = str(Path(sys.executable).with_name("radarviz"))
#: CAT048 records per datagram of the test's capture (a real feed sends a sector's plots).
RECORDS_PER_DATAGRAM = 16
SITES = ((-40e3, -40e3), (40e3, -40e3), (40e3, 40e3), (-40e3, 40e3))


def rotating_radars() -> list[RotatingRadar]:
    """Four radars 113 km apart, periods 4.0 to 5.1 s, phases staggered."""
    return [
        RotatingRadar(f"r{j}", x, y, period_s=4.0 + 0.37 * j, phase_rad=1.3 * j)
        for j, (x, y) in enumerate(SITES)
    ]


def write_capture(
    tmp: Path, targets: int = 300, duration_s: float = 60.0, seed: int = 5
) -> tuple[Path, Path, int, list[float]]:
    """The test's capture (module docstring): its path, the radars file, its plots and each
    datagram's capture time."""
    sites = rotating_radars()
    rng = np.random.default_rng(seed)
    traffic = air_traffic(rng, targets, duration_s, turn_deg=60.0, turn_rate_dps=1.5)
    plots = rotating_scene_plots(sites, rotating_plots(rng, sites, traffic, duration_s))
    radars = ax.with_source_ids(
        [
            Radar(s.name, s.x_m, s.y_m, 0.0, s.sigma_r_m, math.degrees(s.sigma_beta_rad))
            for s in sites
        ]
    )
    ast, toml = tmp / "feed.ast", tmp / "radars.toml"
    ax.write_asterix(str(ast), str(toml), plots, radars)
    with open(ast, "rb") as fh:
        records = [r for _, _, b in ax.data_blocks(fh, "feed.ast") for r in records_of(b)]
    frames, times = [], []
    for k in range(0, len(records), RECORDS_PER_DATAGRAM):
        frames.append(ethernet(ipv4(udp(as_block(records[k : k + RECORDS_PER_DATAGRAM])))))
        times.append(plots[k].time_s)
    out = struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 1)
    for t, f in zip(times, frames, strict=True):
        sec = int(t)
        out += struct.pack("<IIII", 1_700_000_000 + sec, round((t - sec) * 1e6), len(f), len(f))
        out += f
    cap = tmp / "feed.pcap"
    cap.write_bytes(out)
    return cap, toml, len(plots), times


def listen() -> tuple[socket.socket, int]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    sock.bind(("127.0.0.1", 0))
    return sock, sock.getsockname()[1]


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, int, list[float]]:
    return write_capture(tmp_path_factory.mktemp("live"), duration_s=LIVE_SCENE_S)


#: The scene's length (s of feed time: about 160 plots/s, 130 000 plots) and the rate its
#: replay into ``live`` is sped up to (plots/s), so the feed lasts over a minute.
LIVE_SCENE_S, LIVE_RATE = 800.0, 2000.0


def test_replay_sends_every_datagram_in_order_at_the_capture_pace(capture) -> None:
    cap, _, _, times = capture
    speed = 160.0
    sock, port = listen()
    got: list[tuple[float, bytes]] = []
    sock.settimeout(5.0)

    def receive() -> None:
        while len(got) < len(times):
            try:
                data = sock.recv(65536)
            except TimeoutError:
                return
            got.append((time.monotonic(), data))

    thread = threading.Thread(target=receive)
    thread.start()
    argv = [RADARVIZ, "replay", str(cap), "--to", f"127.0.0.1:{port}", "--speed", str(speed)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    thread.join()
    sock.close()
    assert done.returncode == 0, done.stderr
    assert f"replayed {len(times)} datagrams" in done.stderr
    with open(cap, "rb") as fh:
        from radarviz.viz_app.io.pcap import CaptureCounts, udp_datagrams

        sent = [d.payload for d in udp_datagrams(fh, "c", CaptureCounts())]
    assert [d for _, d in got] == sent
    span = (times[-1] - times[0]) / speed
    arrived = got[-1][0] - got[0][0]
    # Paced: not sent as fast as the socket goes (that takes milliseconds), nor slower than
    # the pace plus a generous allowance for a shared machine.
    assert 0.9 * span <= arrived <= span + 5.0
    # And spread along: half the datagrams (by capture time) arrive near half-time.
    mid = len(times) // 2
    assert abs((got[mid][0] - got[0][0]) - (times[mid] - times[0]) / speed) < 0.25 * span + 1.0


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--speed", "0"], "--speed must be a finite number in (0, 10000]"),
        (["--speed", "nan"], "--speed must be a finite number"),
        (["--to", "127.0.0.1"], "--to must be HOST:PORT"),
        (["--to", "127.0.0.1:70000"], "--to port must be in [1, 65535]"),
    ],
)
def test_replay_bad_input_is_one_line_exit_2(
    capture, extra: list[str], words: str, capsys: pytest.CaptureFixture
) -> None:
    assert main(["replay", str(capture[0]), *extra]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1


def test_replay_of_an_ast_file_paces_by_time_of_day(tmp_path: Path) -> None:
    """A file of data blocks: a datagram per block, paced by the blocks' times of day."""
    from radarviz.viz_app.live.replay import paced, recorded_feed

    write_capture(tmp_path, targets=20, duration_s=20.0)
    ast = tmp_path / "feed.ast"
    clock = [0.0]
    sleeps: list[float] = []

    def sleep(s: float) -> None:
        sleeps.append(s)
        clock[0] += s

    sent: list[bytes] = []

    def send(payload: bytes) -> bool:
        sent.append(payload)
        return True

    with open(ast, "rb") as fh:
        counts = paced(recorded_feed(fh, "feed.ast"), 2.0, send, lambda: clock[0], sleep)
    with open(ast, "rb") as fh:
        blocks = [b for _, _, b in ax.data_blocks(fh, "feed.ast")]
    assert sent == blocks
    # Sent at half the recording's times: the last block at its time of day over 2.
    assert counts.span_s > 10.0
    assert clock[0] == pytest.approx(counts.span_s / 2.0, abs=1e-9)


def free_udp_port() -> int:
    sock, port = listen()
    sock.close()
    return port


def test_live_tracks_a_replayed_feed_as_track_does_the_capture(capture, tmp_path: Path) -> None:
    cap, toml, n_plots, times = capture
    out = tmp_path / "t.csv"
    argv = ["track", "--input", str(cap), "--radars", str(toml), "--out", str(out)]
    assert main([*argv, "--associate", "gnn", "--method", "ucm"]) == 0
    expected, statuses = hashlib.sha256(), hashlib.sha256()
    with open(out, newline="") as fh:
        for row in csv.DictReader(fh):
            expected.update(row["target"].encode() + b"\n")
            statuses.update(row["status"].encode() + b"\n")

    port = free_udp_port()
    summary = tmp_path / "live.json"
    live = subprocess.Popen(
        [
            RADARVIZ, "live", "--udp", f"127.0.0.1:{port}", "--radars", str(toml),
            "--method", "ucm", "--no-viewer", "--max-plots", str(n_plots),
            "--duration-s", "240", "--summary", str(summary),
        ],
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    try:
        # The live side is listening once it says so.
        assert live.stderr is not None
        line = live.stderr.readline()
        assert "tracking udp" in line, line
        speed = LIVE_RATE * (times[-1] - times[0]) / n_plots
        assert (times[-1] - times[0]) / speed >= 60.0
        replay = [RADARVIZ, "replay", str(cap), "--to", f"127.0.0.1:{port}"]
        replay += ["--speed", f"{speed:.6f}"]
        done = subprocess.run(replay, capture_output=True, timeout=300)
        assert done.returncode == 0, done.stderr
        err = live.stderr.read()
        assert live.wait(timeout=300) == 0, err
    finally:
        if live.poll() is None:
            live.kill()
    doc = json.loads(summary.read_text())
    assert doc["datagrams"] == len(times) and doc["malformed"] == {}
    assert doc["plots"] == n_plots
    parts = ("tracked", "out_of_order", "dropped", "untracked_at_stop")
    assert sum(doc[k] for k in parts) == n_plots
    assert doc["tracked"] == n_plots  # a clean loopback feed: nothing lost
    assert doc["track_ids_sha256"] == expected.hexdigest()
    assert doc["track_statuses_sha256"] == statuses.hexdigest()
    lat = doc["latency_ms"]
    assert 0.0 < lat["median"] <= lat["p99"]
    assert f"{n_plots} tracked" in err and "latency median" in err


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--udp", "10.1.2.3:8600"], "--udp 10.1.2.3:8600 listens beyond this machine"),
        (["--udp", "127.0.0.1:8600", "--budget-ms", "0"], "--budget-ms must be a finite number"),
        (["--udp", "127.0.0.1:8600", "--duration-s", "-1"], "--duration-s must be a finite"),
        (["--udp", "127.0.0.1:8600", "--max-plots", "0"], "--max-plots must be"),
        (["--udp", "127.0.0.1"], "--udp must be HOST:PORT"),
    ],
)
def test_live_bad_input_is_one_line_exit_2(
    capture, extra: list[str], words: str, capsys: pytest.CaptureFixture
) -> None:
    assert main(["live", "--radars", str(capture[1]), "--no-viewer", *extra]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1, err


def test_live_on_a_port_in_use_is_one_line_exit_2(capture, capsys: pytest.CaptureFixture) -> None:
    """A port another socket holds (even one that allows reuse) is refused in one line: a
    second listener on a unicast port would take the feed from the first without a word."""
    holder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    holder.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    holder.bind(("127.0.0.1", 0))
    port = holder.getsockname()[1]
    with holder:
        argv = ["live", "--radars", str(capture[1]), "--no-viewer", "--udp", f"127.0.0.1:{port}"]
        argv += ["--duration-s", "2"]  # a run that shared the port would end, exit 0
        assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"--udp 127.0.0.1:{port}: cannot listen (Address already in use)" in err, err
    assert err.count("\n") == 1, err


def test_replay_to_a_closed_port_says_so_and_exits_1(capture) -> None:
    """Nothing listens at the address: the host's "port unreachable" answers come back as
    refused sends (the sending socket is connected), said when the first comes and counted at
    the end, exit 1, no traceback; the replay goes on meanwhile (a receiver may start late)."""
    cap, _, _, times = capture
    port = free_udp_port()
    done = subprocess.run(
        [RADARVIZ, "replay", str(cap), "--to", f"127.0.0.1:{port}", "--speed", "2000"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 1, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 2 and "Traceback" not in done.stderr, done.stderr
    to = f"127.0.0.1:{port}"
    assert (
        lines[0] == f"radarviz: replay: {to} refuses datagrams (nothing listens there); sending on"
    )
    said = re.fullmatch(
        rf"radarviz: error: replay to {to}: (\d+) of (\d+) datagrams refused .*", lines[1]
    )
    assert said is not None, lines[1]
    refused, sent = int(said[1]), int(said[2])
    assert sent == len(times) and 0 < refused < sent, lines[1]


def test_live_counts_malformed_datagrams_once_and_goes_on(tmp_path: Path) -> None:
    """A datagram that is not ASTERIX (twice: said once), a record sent twice (a duplicate,
    counted by the reader) and the feed's plots all tracked after them."""
    _, toml, n_plots, _ = write_capture(tmp_path, targets=10, duration_s=20.0)
    with open(tmp_path / "feed.ast", "rb") as fh:
        blocks = [b for _, _, b in ax.data_blocks(fh, "feed.ast")]
    last = records_of(blocks[0])[-1:]  # within the reader's duplicate window of itself
    port = free_udp_port()
    summary = tmp_path / "live.json"
    live = subprocess.Popen(
        [
            RADARVIZ, "live", "--udp", f"127.0.0.1:{port}", "--radars", str(toml),
            "--method", "ucm", "--no-viewer", "--max-plots", str(n_plots + 1),
            "--duration-s", "120", "--summary", str(summary),
        ],
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    try:
        assert live.stderr is not None
        assert "tracking udp" in live.stderr.readline()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
            for payload in [b"not asterix", *blocks[:1], b"\x30\x00", as_block(last), *blocks[1:]]:
                out.sendto(payload, ("127.0.0.1", port))
                time.sleep(0.002)
        err = live.stderr.read()
        assert live.wait(timeout=120) == 0, err
    finally:
        if live.poll() is None:
            live.kill()
    doc = json.loads(summary.read_text())
    assert doc["malformed"] == {"a datagram that is not a run of ASTERIX data blocks": 2}, err
    assert err.count("not a run of ASTERIX data blocks") == 1
    assert doc["duplicate_records"] == 1
    # The duplicate counts toward --max-plots: the session stops at the feed's last plot.
    assert doc["tracked"] == doc["plots"] == n_plots


def test_live_follows_a_growing_file_and_ctrl_c_leaves_a_valid_recording(tmp_path: Path) -> None:
    from radarviz.viz_app.rerun.recording import verify_recording

    _, toml, n_plots, _ = write_capture(tmp_path, targets=10, duration_s=20.0)
    data = (tmp_path / "feed.ast").read_bytes()
    with open(tmp_path / "feed.ast", "rb") as fh:
        cut = [off for off, _, _ in ax.data_blocks(fh, "feed.ast")][1] + 5  # inside a block
    grown = tmp_path / "grown.ast"
    grown.write_bytes(data[:cut])
    rrd, summary = tmp_path / "live.rrd", tmp_path / "live.json"
    live = subprocess.Popen(
        [
            RADARVIZ, "live", "--follow", str(grown), "--radars", str(toml), "--method", "ucm",
            "--no-viewer", "--rrd", str(rrd), "--summary", str(summary), "--reorder-s", "0",
        ],
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    try:
        assert live.stderr is not None
        assert "tracking" in live.stderr.readline()
        time.sleep(1.0)
        with open(grown, "ab") as fh:
            fh.write(data[cut:])
        # The follower polls every 50 ms: seconds are ample for its 167 plots (not a timing
        # check: the account below must balance whenever the interrupt comes).
        time.sleep(3.0)
        live.send_signal(signal.SIGINT)
        err = live.stderr.read()
        assert live.wait(timeout=120) == 130, err
    finally:
        if live.poll() is None:
            live.kill()
    assert "interrupted" in err and str(rrd) in err
    verify_recording(rrd)  # a whole recording, footer and all
    doc = json.loads(summary.read_text())
    assert doc["plots"] == n_plots
    assert doc["tracked"] + doc["untracked_at_stop"] == n_plots
    assert not list(tmp_path.glob(".live.rrd.*"))  # no temporary file left behind


def test_bench_live_accounts_for_every_plot_sent(capsys: pytest.CaptureFixture) -> None:
    """``bench --only live`` (small: 3 s at 400 plots/s, with the viewer): the plots asked
    for are sent, each accounted for once, and the latency is a finite ordered pair."""
    argv = ["bench", "--only", "live", "--live-rate", "400", "--live-seconds", "3"]
    assert main([*argv, "--live-targets", "100", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)["live"]
    assert doc["viewer"] and doc["sent_plots"] == 1200
    parts = ("tracked", "dropped", "out_of_order", "untracked_at_stop", "duplicates")
    assert sum(doc[k] for k in parts) == doc["sent_plots"]
    assert doc["malformed"] == 0
    assert 0.0 < doc["latency_median_ms"] <= doc["latency_p99_ms"]
    assert doc["peak_rss_mb"] > 0.0
    assert main(["bench", "--only", "live", "--live-rate", "0"]) == 2


def test_the_horizon_waits_little_on_an_ordered_feed_and_grows_on_a_late_plot() -> None:
    """``Horizon`` as the reader uses it, then ``time_ordered`` with it: an ordered feed
    waits only the floor; a plot later than the horizon is passed over and the horizon
    grows to twice its lateness, so the next one as late is taken; the cap holds; what is
    let in comes out in time order, never refused."""
    from radarviz.core.tracking.association import time_ordered
    from radarviz.core.tracking.stream import Plot
    from radarviz.viz_app.live.session import Horizon

    h = Horizon(1.0)
    assert h() == Horizon.FLOOR_S
    times = [0.0, 0.1, 0.2, 0.03, 0.3, 0.25, 0.4, 0.15, 0.5, 2.0, 0.2, 2.1]
    latest, admitted, refused = -math.inf, [], []
    for k, t in enumerate(times):
        late = latest - t
        if late > 0 and not h.admits(late):
            refused.append(k)
            continue
        latest = max(latest, t)
        admitted.append((k, Plot(t, 1e4, 0.0, 10.0, 0.01)))
    # 0.03 comes 0.17 s late (beyond 0.05): refused, horizon 0.34; 0.25 (0.05 late) and
    # 0.15 (0.25 late) are then let in; 0.2 after 2.0 (1.8 late) is beyond the 1 s cap.
    assert refused == [3, 10] and h() == 1.0
    out = [p.time_s for _, p in time_ordered(iter(admitted), h)]
    assert out == sorted(out) and len(out) == len(times) - 2


def test_the_feeds_cat034_period_holds_its_batches_and_a_duplicate_counts_to_max_plots(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The reader keeps the antennas' timing its CAT034 messages give (``timing``), which the
    tracker's batches are held with (their radar's I034/041 period, as ``track`` holds a
    file's); a duplicate record counts toward ``max_plots`` with the plots, so a feed of
    three records, one a duplicate, ends at ``max_plots`` 3 without waiting for more."""
    import io
    import queue

    from test_asterix import RADARS, block, rec
    from test_pcap import north

    from radarviz.viz_app.io.plots import BatchRunner, parse_radars
    from radarviz.viz_app.live import session

    radars = parse_radars(RADARS, "r.toml")
    data = north(25, 201, 0.5, 4.5) + block(rec(128)) + block(rec(128)) + block(rec(256))
    counts, stop, out = session.FeedCounts(), threading.Event(), queue.Queue()
    feed = session.FollowedFile(io.BytesIO(data), stop, counts)
    timing: dict = {}
    reader = threading.Thread(
        target=session.read_feed,
        args=(feed, "f", radars, out, session.Horizon(1.0), 3, session.warn_line, timing),
    )
    reader.start()
    reader.join(timeout=30.0)
    assert not reader.is_alive() and stop.is_set()  # ended by the account, not the poll
    assert (counts.plots, counts.duplicates) == (2, 1)
    assert timing["north"].rotation_period_s == 4.5

    held: list[float | None] = []

    class Runner(BatchRunner):
        def hold(self, batch: list, period: float | None = None) -> None:
            held.append(period)
            super().hold(batch, period)

    monkeypatch.setattr(session, "BatchRunner", Runner)
    from radarviz.core.tracking.association import AssociationOptions, GNNTracker
    from radarviz.core.tracking.stream import StreamOptions, motion_fields

    tracker = GNNTracker(("ucm",), False, StreamOptions(**motion_fields()), AssociationOptions())
    tracked: list[str] = []
    session.track_feed(out, tracker, counts, 30.0, 0.0, 1e-3, lambda p, r, s="": tracked.append(
        p.target), None, None, timing)  # fmt: skip
    assert len(tracked) == 2 and held and set(held) == {4.5}


def test_the_live_recorder_draws_tentative_tracks_in_its_current_state(
    tmp_path: Path, rrd_contents
) -> None:
    """A live session's tentative tracks are rows of its current state (faint, in
    ``world/tracks/{m}/position``), never the per-scan rows ``track --rrd`` groups them into:
    those would pile up unsent in a session that never ends."""
    import numpy as np

    from radarviz.core.tracking.stream import Plot
    from radarviz.viz_app.io.plots import Radar
    from radarviz.viz_app.rerun.live_recording import LiveTrackRecorder
    from radarviz.viz_app.rerun.recording import recording_file

    radar = Radar("r", 0.0, 0.0, 0.0, 50.0, 0.3)
    x, P = np.zeros(6), np.eye(6)
    out = tmp_path / "live.rrd"
    with recording_file(out) as rec:
        recorder = LiveTrackRecorder(rec, [radar])
        for scan in range(3):
            for k, status in enumerate(("tentative", "confirmed")):
                plot = Plot(5.0 * scan + k, 1e4 + k, 0.1 * k, 50.0, 0.005, radar="r")
                recorder.add(replace(plot, target=str(k)), [("ucm", x + k, P)], status)
            recorder.end_scan([])
            recorder.flush()
            assert not recorder._tentative and not recorder._scan_tentative
        recorder.close()
    rows, cols = rrd_contents(out)
    assert not any(p.startswith("/world/tentative") for p in rows)
    # Each flush's row holds both tracks, the tentative one with the confirmed one.
    sizes = [len(c) for c in cols["/world/tracks/ucm/position"]["Points3D:positions"]]
    assert len(sizes) >= 3 and set(sizes) == {2}


def test_the_live_recorder_reuses_series_slots_so_its_entities_stay_bounded(
    tmp_path: Path, rrd_contents
) -> None:
    """The Rerun SDK keeps a few kilobytes per entity path for the recording's life: a live
    session's entities must not grow with the tracks ever started. Forty tracks, at most two
    alive at once: their time series share two slots, and a slot's next track starts with a
    ``Clear`` (its line does not join the last one's); the path entities are made at once."""
    import numpy as np

    from radarviz.core.tracking.stream import Plot
    from radarviz.viz_app.io.plots import Radar
    from radarviz.viz_app.rerun.live_recording import PATH_CHUNKS, LiveTrackRecorder
    from radarviz.viz_app.rerun.recording import recording_file

    radar = Radar("r", 0.0, 0.0, 0.0, 50.0, 0.3)
    x, P = np.zeros(6), np.eye(6)
    out = tmp_path / "live.rrd"
    with recording_file(out) as rec:
        recorder = LiveTrackRecorder(rec, [radar], clock=iter(range(10**6)).__next__)
        for track in range(40):
            for scan in range(4):  # two tracks overlap: this one and the one before
                plot = Plot(10.0 * track + scan, 1e4, 0.1, 50.0, 0.005, radar="r")
                recorder.add(replace(plot, target=str(track)), [("ucm", x + track, P)], "confirmed")
                recorder.end_scan([str(track - 1)] if scan == 3 and track else [])
                recorder.flush()
        recorder.end_scan([str(39)])
        recorder.close()
    rows, cols = rrd_contents(out)
    series = {p for p in rows if p.startswith("/plots/sigma_pos_m/")}
    assert series == {"/plots/sigma_pos_m/0000", "/plots/sigma_pos_m/0001"}
    paths = {p for p in rows if p.startswith("/world/tracks/ucm/path/")}
    assert len(paths) == PATH_CHUNKS
    clears = sum(
        1 for c in cols["/plots/sigma_pos_m/0000"].get("Clear:is_recursive", []) if c is not None
    )
    assert clears >= 10  # the slot held about half the forty tracks, one after another


def test_the_live_recorders_layout_values_take_their_memory_at_the_start() -> None:
    """What a live recorder keeps to frame its views (the newest ``layout_kept`` values of
    each time series and of the inset's reaches) is a ring taken at the start: rows sent for
    a while do not make its traced memory grow. (A list of every flush's small arrays,
    trimmed at twice ``layout_kept``, grew by an object per array until then: 54 kB here.)"""
    import gc
    import tracemalloc

    import numpy as np

    from radarviz.core.tracking.stream import Plot
    from radarviz.viz_app.io.plots import Radar
    from radarviz.viz_app.rerun.live_recording import LiveTrackRecorder

    class Discard:
        def __getattr__(self, name: str):
            return lambda *args, **kwargs: None

    class Small(LiveTrackRecorder):
        layout_kept = 1000

    radar = Radar("r", 0.0, 0.0, 0.0, 50.0, 0.3)
    x, P = np.zeros(6), np.eye(6)
    recorder = Small(Discard(), [radar], clock=iter(range(10**6)).__next__)
    scan = 0

    def scans(n: int) -> None:
        nonlocal scan
        for _ in range(n):
            for track in range(4):
                plot = Plot(2.0 * scan, 1e4 + track, 0.1, 50.0, 0.005, radar="r")
                rows = [("ucm", x + track + 1e-3 * scan, P)]
                recorder.add(replace(plot, target=str(track)), rows, "confirmed")
            recorder.end_scan([])
            recorder.flush()
            scan += 1

    tracemalloc.start()
    try:
        scans(300)  # past layout_kept values of each series and reach
        gc.collect()
        before = tracemalloc.get_traced_memory()[0]
        scans(180)  # up to about twice layout_kept: the old list's longest
        gc.collect()
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert grown < 20_000, grown
    assert len(recorder._series["speed_mps"]) == recorder.layout_kept


def test_the_live_recorder_logs_the_events_of_a_monitor_keeping_only_its_newest() -> None:
    """A live session's monitor keeps its newest events only (``EVENTS_KEPT``): the recorder
    logs each event it still has once, up to the plot's time, and goes on with the ones
    that come after the oldest are gone."""
    import numpy as np

    from radarviz.core.tracking.consistency import ConsistencyEvent, ConsistencyMonitor
    from radarviz.core.tracking.stream import Plot
    from radarviz.viz_app.io.plots import Radar
    from radarviz.viz_app.rerun.live_recording import LiveTrackRecorder

    class Discard:
        def __getattr__(self, name: str):
            return lambda *args, **kwargs: None

    logged: list[str] = []

    class Logging(LiveTrackRecorder):
        def _log_text(self, text: str, level: str = "INFO") -> None:
            logged.append(text)

    monitor = ConsistencyMonitor(events_kept=2)
    radar = Radar("r", 0.0, 0.0, 0.0, 50.0, 0.3)
    recorder = Logging(Discard(), [radar], monitor, clock=iter(range(10**6)).__next__)
    x, P = np.zeros(6), np.eye(6)

    def event(t: float) -> None:
        monitor.record(ConsistencyEvent(f"{t:g}/ucm", t, "returns", 1.0, 0.5, 2.0))

    def plot(t: float) -> None:
        p = Plot(t, 1e4, 0.1, 50.0, 0.005, radar="r", target="1")
        recorder.add(p, [("ucm", x, P)], "confirmed")

    for t in range(5):
        event(float(t))
    plot(10.0)  # the first three are gone: the newest two are logged
    event(11.0)
    event(13.0)
    plot(12.0)  # the one at 13 s waits for its plot's time
    plot(14.0)
    tracks = [line.split()[1] for line in logged if line.startswith("track ")]
    assert tracks == ["3/ucm", "4/ucm", "11/ucm", "13/ucm"]


def test_the_live_recorder_leaves_track_ids_out_of_the_sdks_string_store(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The Rerun SDK keeps every string ``rr.escape_entity_path_part`` is given for the life
    of the process (about 73 bytes each): a live session, which starts a track for every
    clutter plot, must not escape its track ids, or its memory grows with the tracks ever
    started. Sixty tracks started and deleted, half of them confirmed: no id is escaped."""
    import numpy as np
    import rerun as rr

    from radarviz.core.tracking.stream import Plot
    from radarviz.viz_app.io.plots import Radar
    from radarviz.viz_app.rerun.live_recording import LiveTrackRecorder

    escaped: list[str] = []
    real = rr.escape_entity_path_part

    def counted(part: str) -> str:
        escaped.append(part)
        return real(part)

    monkeypatch.setattr(rr, "escape_entity_path_part", counted)

    class Discard:
        def __getattr__(self, name: str):
            return lambda *args, **kwargs: None

    radar = Radar("r", 0.0, 0.0, 0.0, 50.0, 0.3)
    x, P = np.zeros(6), np.eye(6)
    recorder = LiveTrackRecorder(Discard(), [radar], clock=iter(range(10**6)).__next__)
    for track in range(60):
        status = "confirmed" if track % 2 else "tentative"
        for scan in range(3):
            plot = Plot(10.0 * track + scan, 1e4, 0.1, 50.0, 0.005, radar="r")
            recorder.add(replace(plot, target=str(track)), [("ucm", x + track, P)], status)
            recorder.end_scan([str(track)] if scan == 2 else [])
            recorder.flush()
    recorder.close()
    assert recorder.count == 180 and not recorder._now
    assert escaped == []
