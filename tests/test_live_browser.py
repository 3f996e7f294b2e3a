"""``radarviz live``'s web viewer in headless Debian Chromium (playwright): the tracks grow.

A small capture of the rotating-radar scene (``test_live.write_capture``: four radars, 40
targets) is replayed in two halves into ``radarviz live --udp … --method ucm`` with its web
viewer; after each half the test screenshots the viewer (1600 × 1000) and counts the pixels
of the tracks' colours (``palette.TRACK_SEQUENCE``: one method, each track its own colour).
The second screenshot's 3D view holds more of them than the first's: the paths of the
confirmed tracks have grown and new tracks came, live, without a reload. Required in CI
(``CI=true``).
"""

from __future__ import annotations

import io
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
from test_browser import ARTIFACTS, VIEWPORT, colour_pixels
from test_live import RADARVIZ, free_udp_port, write_capture

from radarviz.viz_app.live.replay import Address, paced, recorded_feed, udp_sender
from radarviz.viz_app.palette import TRACK_SEQUENCE

#: Replay speed of the capture (×): its 60 s in about 4 s.
SPEED = 15.0
#: How long the viewer may take to draw what was sent (s).
DRAWN_S = 30.0
#: Share of the track pixels two screenshots of a drawn view may differ by (antialiasing).
SETTLED = 0.02


def track_pixels(rgba: np.ndarray) -> int:
    """Pixels of the 3D view of a screenshot in any track colour (within
    ``COLOUR_TOLERANCE``): the layout's left three fifths, between the top bar and the log
    (the time series on the right grow too, but they are not the map)."""
    h, w = rgba.shape[:2]
    view = rgba[60 : int(0.76 * h), : int(0.58 * w)]
    return sum(colour_pixels(view, c) for c in TRACK_SEQUENCE)


def settled_track_pixels(page, above: int, path: Path) -> int:
    """Screenshot ``page`` every second until its track pixels exceed ``above`` and change
    by less than ``SETTLED`` of their count between two screenshots (the viewer has drawn
    what came; the redrawn frame is never exactly the same), at most ``DRAWN_S``; save the
    last at ``path`` and return its count."""
    from matplotlib.image import imread

    end = time.monotonic() + DRAWN_S
    last = -1
    while True:
        count = track_pixels(imread(io.BytesIO(page.screenshot())))
        settled = abs(count - last) <= SETTLED * count
        if (count > above and settled) or time.monotonic() > end:
            break
        last = count
        time.sleep(1.0)
    path.parent.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(path))
    return count


def test_live_viewer_shows_the_tracks_grow(tmp_path: Path, chromium) -> None:
    from playwright.sync_api import sync_playwright

    cap, toml, _, _ = write_capture(tmp_path, targets=40, duration_s=60.0)
    with open(cap, "rb") as fh:
        records = list(recorded_feed(fh, str(cap)))
    half = len(records) // 2
    port = free_udp_port()
    live = subprocess.Popen(
        [
            RADARVIZ, "live", "--udp", f"127.0.0.1:{port}", "--radars", str(toml),
            "--method", "ucm", "--duration-s", "300",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    try:
        assert live.stdout is not None and live.stderr is not None
        url = live.stdout.readline().split()[-1]  # "viewer URL", once it answers
        assert url.startswith("http://127.0.0.1:"), url
        assert "tracking udp" in live.stderr.readline()
        sock, send = udp_sender(Address("127.0.0.1", port))
        executable, args = chromium
        with sock, sync_playwright() as p:
            browser = p.chromium.launch(executable_path=executable, args=args)
            page = browser.new_page(viewport=VIEWPORT)
            page.goto(url)
            page.wait_for_selector("canvas", timeout=60_000)
            paced(iter(records[:half]), SPEED, send)
            first = settled_track_pixels(page, 0, ARTIFACTS / "live-half.png")
            paced(iter(records[half:]), SPEED, send)
            second = settled_track_pixels(page, first, ARTIFACTS / "live-whole.png")
            browser.close()
        live.send_signal(signal.SIGINT)  # Ctrl-C: the session ends, stops its viewer
        err = live.stderr.read()
        assert live.wait(timeout=60) == 130, err
    finally:
        if live.poll() is None:
            live.kill()
    assert first > 0, "the viewer shows no track after half the feed (see live-half.png)"
    # The traffic's count is steady: the markers and ellipses of the live tracks cover about
    # as much after the whole feed as after half, the paths about twice as much (overlaps
    # and the view's edge take some). A fifth more is growth, not a redrawn frame's noise.
    assert second > 1.2 * first, (first, second)
