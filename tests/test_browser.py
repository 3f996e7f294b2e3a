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

from radarviz.viz_app.rerun.recording import recording_file
from radarviz.viz_app.rerun.scenes import record_preset
from radarviz.viz_app.rerun.viewer import free_port, viewer_url

ARTIFACTS = Path(__file__).resolve().parents[1] / "test-artifacts"


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


def test_web_viewer_renders_a_recording(
    tmp_path: Path, chromium: tuple[str, list[str]], viewer_shows_data
) -> None:
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
        executable, args = chromium
        with sync_playwright() as p:
            # launch() gives every browser a fresh temporary profile (user data dir).
            browser = p.chromium.launch(executable_path=executable, args=args)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
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
