"""The web viewer renders a recording in headless Debian Chromium (playwright).

Required in CI (``CI=true``): there a missing browser is a failure, not a skip.
"""

from __future__ import annotations

import io
import os
import shutil
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from radarviz.viz_app.rerun.recording import recording_file
from radarviz.viz_app.rerun.scenes import record_preset
from radarviz.viz_app.rerun.viewer import free_port, viewer_url

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
ARTIFACTS = Path(__file__).resolve().parents[1] / "test-artifacts"


def _browser_or_fail() -> None:
    have = Path(CHROMIUM).exists()
    try:
        import playwright  # noqa: F401
    except ImportError:
        have = False
    if not have:
        if os.environ.get("CI") == "true":
            pytest.fail(
                "CI=true but Debian chromium or python playwright is missing "
                "(.ci/run installs both)"
            )
        pytest.skip("chromium / playwright not installed (apt-get install chromium)")


def _answers(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=2):
            return True
    except OSError:
        return False


def _wait_http(url: str, timeout: float = 30.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            with urllib.request.urlopen(url, timeout=2):
                return
        except OSError:
            time.sleep(0.2)
    raise TimeoutError(f"{url} did not answer within {timeout} s")


def _coloured_fraction(rgba: np.ndarray) -> float:
    """Share of saturated pixels in the right 40% of the window below the top bar."""
    h, w = rgba.shape[:2]
    region = rgba[60 : h - 60, int(0.6 * w) :, :3]
    saturation = region.max(axis=-1) - region.min(axis=-1)
    return float((saturation > 0.3).mean())


def test_web_viewer_renders_a_recording(tmp_path: Path) -> None:
    _browser_or_fail()
    from playwright.sync_api import sync_playwright

    rrd = tmp_path / "prosov.rrd"
    with recording_file(rrd) as rec:
        record_preset(rec, "prosov")
    grpc, web = free_port(), free_port()
    exe = Path(sys.executable).with_name("radarviz")
    proc = subprocess.Popen(
        [str(exe), "view", str(rrd), "--port", str(grpc), "--web-port", str(web)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        _wait_http(f"http://127.0.0.1:{web}/")
        ARTIFACTS.mkdir(exist_ok=True)
        shot = ARTIFACTS / "viewer.png"
        with sync_playwright() as p:
            # launch() gives every browser a fresh temporary profile (user data dir).
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(viewer_url("127.0.0.1", web, grpc))
            page.wait_for_selector("canvas", timeout=60_000)
            # The viewer (egui, all drawn in the canvas) streams the recording, then draws.
            # Its chrome is grey; the data (series lines, tracks) are coloured: poll until the
            # time-series side of the window shows coloured pixels.
            coloured = 0.0
            end = time.monotonic() + 90
            while time.monotonic() < end:
                coloured = _coloured_fraction(imread(io.BytesIO(page.screenshot())))
                if coloured > 0.005:
                    break
                time.sleep(2.0)
            page.screenshot(path=str(shot))
            browser.close()
        assert coloured > 0.005, f"the viewer shows no data (coloured fraction {coloured:.4f})"
        assert shot.stat().st_size > 10_000
    finally:
        os.killpg(proc.pid, 15)
        proc.wait(timeout=10)
    # Stopping `radarviz view` stops the viewer it started (no orphaned server on the port).
    end = time.monotonic() + 10
    while time.monotonic() < end and _answers(f"http://127.0.0.1:{web}/"):
        time.sleep(0.2)
    assert not _answers(f"http://127.0.0.1:{web}/"), "the web viewer outlived radarviz view"
