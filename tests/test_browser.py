"""The web viewer renders a recording in headless Debian Chromium (playwright).

Required in CI (``CI=true``): there a missing browser is a failure, not a skip.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from radarviz.core.filters.methods import ALL_METHODS
from radarviz.viz_app.palette import radar_rgb, rgb
from radarviz.viz_app.rerun.recording import recording_file
from radarviz.viz_app.rerun.scenes import record_preset
from radarviz.viz_app.rerun.viewer import free_port, viewer_url, wait_viewer

ARTIFACTS = Path(__file__).resolve().parents[1] / "test-artifacts"


def _answers(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=2):
            return True
    except OSError:
        return False


VIEWPORT = {"width": 1600, "height": 1000}
#: Pixels within this RGB distance of a palette colour count as that colour.
COLOUR_TOLERANCE = 30.0
#: Minimum pixels of each method's colour in the Prosov tab (its ellipse and estimate).
MIN_METHOD_PIXELS = 150


def colour_pixels(rgba: np.ndarray, colour: tuple[int, int, int]) -> int:
    """How many pixels of a screenshot are within ``COLOUR_TOLERANCE`` of ``colour``."""
    d = np.linalg.norm(rgba[..., :3] * 255.0 - np.array(colour, dtype=float), axis=-1)
    return int((d < COLOUR_TOLERANCE).sum())


def timeline_extent(shot: np.ndarray, y: int) -> tuple[int, int]:
    """The time slider's left and right ends in a screenshot: the longest run of dark pixels
    in row ``y`` (the slider's line, drawn across the time panel)."""
    dark = np.flatnonzero(shot[y, :, :3].max(axis=-1) < 0.35)
    assert dark.size, f"no time slider in row {y}"
    cuts = np.flatnonzero(np.diff(dark) > 1)
    starts = np.r_[dark[0], dark[cuts + 1]]
    ends = np.r_[dark[cuts], dark[-1]]
    k = int(np.argmax(ends - starts))
    assert ends[k] - starts[k] > shot.shape[1] // 3, (starts[k], ends[k])
    return int(starts[k]), int(ends[k])


def _shoot(page, path: Path) -> np.ndarray:
    from matplotlib.image import imread

    path.parent.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(path))
    return imread(str(path))


def _serve(rrd: Path) -> tuple[subprocess.Popen, int, int]:
    grpc, web = free_port(), free_port()
    exe = Path(sys.executable).with_name("radarviz")
    proc = subprocess.Popen(
        [str(exe), "view", str(rrd), "--port", str(grpc), "--web-port", str(web)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    wait_viewer(proc, "--web-port", "127.0.0.1", web, timeout=30.0)
    return proc, grpc, web


@pytest.mark.parametrize("preset", ["prosov", "prosov3d", "velocity", "gorshkov", "demo"])
def test_each_scene_opens_on_legible_views(
    preset: str, tmp_path: Path, chromium: tuple[str, list[str]], viewer_shows_data
) -> None:
    """Each preset opens, with no interaction, on views with content: at 1600 × 1000 every
    method's colour (Prosov) or every radar's (velocity, Gorshkov) covers at least a minimum
    of pixels, and the scene at an early scan differs from the last one."""
    from playwright.sync_api import sync_playwright

    rrd = tmp_path / f"{preset}.rrd"
    with recording_file(rrd) as rec:
        record_preset(rec, preset)
    proc, grpc, web = _serve(rrd)
    try:
        executable, args = chromium
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=executable, args=args)
            page = browser.new_page(viewport=VIEWPORT)
            page.goto(viewer_url("127.0.0.1", web, grpc))
            page.wait_for_selector("canvas", timeout=60_000)
            viewer_shows_data(page, ARTIFACTS / f"viewer_{preset}.png")
            time.sleep(8.0)  # let every view finish streaming
            late = _shoot(page, ARTIFACTS / f"viewer_{preset}.png")
            if preset in ("prosov", "prosov3d", "demo"):
                # In 3D the ellipsoids overlap: the outermost ones must show.
                names = {"demo": ["naive", "ucm"], "prosov3d": ["naive", "seed", "ucm", "ekf"]}
                names = names.get(preset, list(ALL_METHODS))
                for m in names:
                    assert colour_pixels(late, rgb(m)) > MIN_METHOD_PIXELS, (m, preset)
            else:
                for j in range(3):
                    assert colour_pixels(late, radar_rgb(j)) > MIN_METHOD_PIXELS, (j, preset)
            if preset != "gorshkov":
                # Click the time slider near its start: the cursor moves to an early scan.
                # The slider spans the recording's whole timeline (the demo's runs to the
                # manoeuvre scene's 721 scans, past the Prosov scene's 60), so the click is
                # placed on the slider as drawn, 2% along it.
                y = VIEWPORT["height"] - 14
                left, right = timeline_extent(late, y)
                page.mouse.click(int(left + 0.02 * (right - left)), y)
                time.sleep(4.0)
                early = _shoot(page, ARTIFACTS / f"viewer_{preset}_early.png")
                views = slice(60, VIEWPORT["height"] - 40)
                changed = np.abs(early[views, :, :3] - late[views, :, :3]).max(axis=-1) > 0.1
                assert changed.mean() > 0.002, (preset, changed.mean())
            browser.close()
    finally:
        os.killpg(proc.pid, 15)
        proc.wait(timeout=10)


def test_web_viewer_renders_a_recording(
    tmp_path: Path, chromium: tuple[str, list[str]], viewer_shows_data
) -> None:
    from playwright.sync_api import sync_playwright

    rrd = tmp_path / "prosov.rrd"
    with recording_file(rrd) as rec:
        record_preset(rec, "prosov")
    proc, grpc, web = _serve(rrd)
    try:
        executable, args = chromium
        with sync_playwright() as p:
            # launch() gives every browser a fresh temporary profile (user data dir).
            browser = p.chromium.launch(executable_path=executable, args=args)
            page = browser.new_page(viewport=VIEWPORT)
            page.goto(viewer_url("127.0.0.1", web, grpc))
            page.wait_for_selector("canvas", timeout=60_000)
            viewer_shows_data(page, ARTIFACTS / "viewer.png")
            browser.close()
    finally:
        os.killpg(proc.pid, 15)
        proc.wait(timeout=10)
    # Stopping `radarviz view` stops the viewer it started (no orphaned server on the port).
    end = time.monotonic() + 10
    while time.monotonic() < end and _answers(f"http://127.0.0.1:{web}/"):
        time.sleep(0.2)
    assert not _answers(f"http://127.0.0.1:{web}/"), "the web viewer outlived radarviz view"
