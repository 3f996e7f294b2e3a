"""``radarviz bench --only tune``: a change in ``radarviz tune`` to the first frame that draws it.

``radarviz tune --no-browser`` runs in its own process; its one page (the controls and the
Rerun viewer side by side) is opened in headless Debian Chromium (playwright, software WebGL,
``VIEWPORT``). The page's frames are taken as the compositor swaps them in (CDP
``Page.startScreencast``, :class:`Screencast`), each with its own swap time, so a frame is
timed to itself, not to the end of a screenshot (which takes a while with software WebGL and
makes the page draw a frame of its own). The panel is driven through its own controls, in the
order prosov → velocity → gorshkov → prosov; in each scene, after the switch to it, the
scene's own parameter is changed ``changes`` times: a σβ slider step (prosov, velocity: the
keypress is the change; the page reports the slider let go, and the step runs without the
typing pause) or a typed C0 (Gorshkov, whose first tab σβ does not enter: timed from the last
keystroke, no Enter, so the panel's settling pause is inside the figure).

A change's figure (:meth:`Screencast.first_frame`) is the time from the change to the first
frame from which on the viewer's views (its chrome rows cut off) stay what they are when the
viewer has settled (no view changing for ``STILL_S``), where that settled frame shows data
(coloured pixels, ``MIN_COLOURED_VIEW``: a viewer loading a run is grey) and differs from
the frame before the change (the new run is drawn, not the old one). The figures, s per scene:
``switch_s`` (the switch to the scene) and ``change_s`` (each change), with their medians.
"""

from __future__ import annotations

import base64
import io
import os
import queue
import re
import shutil
import signal
import statistics
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: The page's size in the browser (CSS px).
VIEWPORT = {"width": 1600, "height": 1000}
#: Debian Chromium, and its headless arguments (no GPU: software WebGL); the browser tests
#: launch it the same way (``tests/conftest.py``).
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
#: The viewer's chrome that changes by itself (its top bar; the time panel at the bottom):
#: rows left out when frames are compared (CSS px).
VIEWER_TOP_PX, VIEWER_BOTTOM_PX = 40, 60
#: Share of pixels that may differ between two frames of the same drawn run.
SAME_FRAME = 0.002
#: A drawn run holds still this long (s) before its frame counts as the final one.
STILL_S = 2.0
#: Share of saturated pixels above which the viewer's frame shows data (its chrome and empty
#: views are grey: a blank viewer shows 0).
MIN_COLOURED_VIEW = 0.002
#: The σβ slider's number box (the input beside the slider).
SLIDER_BOX = "xpath=ancestor::*[.//input[@type='text']][1]//input[@type='text']"
#: The budget from a change to the first complete frame, s.
FIRST_FRAME_BUDGET_S = 1.5
#: The order of the scenes: every switch, and back to the first scene shown before.
SCENE_ORDER = ("prosov", "velocity", "gorshkov", "prosov")
#: Changes per scene (``radarviz bench --only tune``).
DEFAULT_CHANGES = 3


def changed_share(a: np.ndarray, b: np.ndarray) -> float:
    """Share of pixels that differ between two RGB frames (0 … 1 floats)."""
    return float((np.abs(a - b).max(axis=-1) > 0.1).mean())


def coloured(frame: np.ndarray) -> float:
    """Share of saturated pixels: the data (the viewer's chrome and empty views are grey)."""
    saturation = frame.max(axis=-1) - frame.min(axis=-1)
    return float((saturation > 0.3).mean())


@dataclass
class Frame:
    """One screencast frame: its swap time (s since the epoch) and its JPEG bytes."""

    t: float
    jpeg: bytes
    _views: np.ndarray | None = None


@dataclass
class FirstFrame:
    """A change's measurement: seconds to the first complete frame, the settled views, the
    frames seen since the change, and the settled frame's whole JPEG (to look at)."""

    seconds: float
    views: np.ndarray
    frames: list[Frame]
    jpeg: bytes
    #: s from the change to the line of its run (the panel's settling pause, the run and
    #: its flush to the viewer's server): the rest of ``seconds`` is the viewer's.
    server_s: float | None = None


class Screencast:
    """The page's frames as the compositor swaps them in (CDP ``Page.startScreencast``).

    Frames come only while playwright is waiting on the page (the sync API pumps events
    then): :meth:`first_frame` waits with ``page.wait_for_timeout``, never ``time.sleep``,
    or the unacknowledged screencast stalls."""

    def __init__(self, page: Any, viewer: str = "#viewer") -> None:
        self.page = page
        self.viewer = viewer
        self.frames: list[Frame] = []
        self.cdp = page.context.new_cdp_session(page)
        self.cdp.on("Page.screencastFrame", self._frame)
        self.cdp.send("Page.startScreencast", {"format": "jpeg", "quality": 85})

    def _frame(self, event: dict) -> None:
        t = float(event["metadata"].get("timestamp") or time.time())
        self.frames.append(Frame(t, base64.b64decode(event["data"])))
        self.cdp.send("Page.screencastFrameAck", {"sessionId": event["sessionId"]})

    def stop(self) -> None:
        self.cdp.send("Page.stopScreencast")
        self.cdp.remove_listener("Page.screencastFrame", self._frame)

    def _views(self, frame: Frame, box: dict) -> np.ndarray:
        """The viewer's views in ``frame`` (its chrome rows cut off), RGB floats."""
        if frame._views is None:
            from matplotlib.image import imread

            img = imread(io.BytesIO(frame.jpeg), format="jpeg")[..., :3] / 255.0
            k = img.shape[1] / VIEWPORT["width"]  # frame pixels per CSS pixel
            top = round((box["y"] + VIEWER_TOP_PX) * k)
            bottom = round((box["y"] + box["height"] - VIEWER_BOTTOM_PX) * k)
            left, right = round(box["x"] * k), round((box["x"] + box["width"]) * k)
            frame._views = img[top:bottom, left:right]
        return frame._views

    def latest_views(self) -> np.ndarray | None:
        box = self.page.locator(self.viewer).bounding_box()
        return self._views(self.frames[-1], box) if self.frames and box else None

    def first_frame(
        self,
        t0: float,
        before: np.ndarray | None = None,
        ready=lambda: True,
        timeout: float = 60.0,
    ) -> FirstFrame:
        """Wait until the viewer has settled on a drawn frame after the change at ``t0``
        (s since the epoch) and time the first frame that already looked like it.

        Settled: ``ready()`` is true (the run is done), the newest frame shows data and
        differs from ``before`` (the frame before the change), and every frame of the last
        ``STILL_S`` looks like it (or none came: nothing was redrawn). The figure is the swap
        time of the first frame of the run of frames, up to the newest, that look like the
        newest, less ``t0``."""
        box = self.page.locator(self.viewer).bounding_box()
        assert box is not None, "the viewer's frame is not on the page"
        end = time.monotonic() + timeout
        probed: float | None = None  # the candidate's first frame when the viewer was probed
        while True:
            self.page.wait_for_timeout(100)
            since = [f for f in self.frames if f.t >= t0]
            if since and ready():
                last = self._views(since[-1], box)
                drawn = coloured(last) > MIN_COLOURED_VIEW
                new = before is None or changed_share(last, before) >= SAME_FRAME
                first = len(since) - 1
                while (
                    first > 0
                    and changed_share(self._views(since[first - 1], box), last) < SAME_FRAME
                ):
                    first -= 1
                if drawn and new and time.time() - since[first].t >= STILL_S:
                    if probed == since[first].t:
                        # keep the newest frame: the next change's frames start after it
                        self.frames = self.frames[-1:]
                        return FirstFrame(since[first].t - t0, last, since, since[-1].jpeg)
                    # No frame for STILL_S may also be a viewer too busy to draw (taking in
                    # a run): the candidate stands once the viewer has drawn frames since.
                    self._probe_viewer()
                    probed = since[first].t
            if time.monotonic() > end:
                raise AssertionError(
                    f"the viewer did not settle on a new drawn frame within {timeout} s "
                    f"({len(since)} frames since the change)"
                )

    def _probe_viewer(self) -> None:
        """Return once the viewer's page has run two animation frames (its main thread is
        free again), then let the screencast deliver what it drew."""
        handle = self.page.locator(self.viewer).element_handle()
        frame = handle.content_frame() if handle is not None else None
        if frame is not None:
            frame.evaluate(
                "() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))"
            )
        self.page.wait_for_timeout(300)


# --- the command and its page ------------------------------------------------------------


def _reader(proc: subprocess.Popen, lines: queue.Queue) -> None:
    assert proc.stdout is not None
    for line in proc.stdout:
        lines.put((time.time(), line.rstrip("\n")))


@dataclass
class TunePage:
    """``radarviz tune --no-browser`` on free ports, its page open in ``browser``: drives
    the controls and times each change (:meth:`switch`, :meth:`change`)."""

    proc: subprocess.Popen
    lines: queue.Queue
    log: list[str] = field(default_factory=list)
    runs: list[str] = field(default_factory=list)
    #: When each line of ``runs`` was read (s since the epoch).
    run_times: list[float] = field(default_factory=list)
    page: Any = None
    cast: Screencast | None = None
    previous: np.ndarray | None = None

    @classmethod
    def start(cls, cwd: Path | None = None) -> TunePage:
        from radarviz.viz_app.rerun.viewer import free_port

        exe = Path(sys.executable).with_name("radarviz")
        command = [str(exe), "tune", "--no-browser", "--port", str(free_port())]
        proc = subprocess.Popen(
            [*command, "--viewer-port", str(free_port())],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            start_new_session=True,
            cwd=cwd,
            env={**os.environ, "PYTHONUNBUFFERED": "1", "RERUN_ANALYTICS": "0"},
        )
        lines: queue.Queue = queue.Queue()
        threading.Thread(target=_reader, args=(proc, lines), daemon=True).start()
        return cls(proc, lines)

    def expect(self, pattern: str, timeout: float) -> re.Match:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                _, line = self.lines.get(timeout=0.2)
            except queue.Empty:
                if self.proc.poll() is not None:
                    break
                continue
            self.log.append(line)
            m = re.search(pattern, line)
            if m:
                return m
        raise AssertionError(f"no line matching {pattern!r} within {timeout} s; got {self.log}")

    def _drain(self) -> None:
        while True:
            try:
                t, line = self.lines.get_nowait()
            except queue.Empty:
                return
            self.log.append(line)
            if line.startswith(("run ", "error ")):
                self.runs.append(line)
                self.run_times.append(t)

    def ran(self, scene: str):
        """A ``ready`` for :meth:`Screencast.first_frame`: a run of ``scene`` has finished
        since ``runs`` was last cleared."""

        def done() -> bool:
            self._drain()
            return any(f" scene={scene} " in r for r in self.runs)

        return done

    def open(self, browser: Any, timeout: float = 120.0) -> None:
        """Open the panel's page and wait for the first run (Prosov) to be drawn."""
        panel = self.expect(r"^panel (\S+)", 90).group(1)
        self.expect(r"^run \S+ scene=prosov", 120)
        self.page = browser.new_page(viewport=VIEWPORT)
        t0 = time.time()
        self.page.goto(panel)
        self.controls.get_by_label("scene").first.wait_for(timeout=90_000)
        self.cast = Screencast(self.page)
        self.previous = self.cast.first_frame(t0, timeout=timeout).views

    @property
    def controls(self) -> Any:
        return self.page.frame_locator("#controls")

    def switch(self, scene: str) -> FirstFrame:
        """Choose ``scene`` in the scene box; timed from the click on its option."""
        assert self.cast is not None
        self._drain()
        self.runs.clear()
        self.run_times.clear()
        self.controls.get_by_label("scene").first.click()
        option = self.controls.get_by_role("option", name=scene)
        option.wait_for()
        t0 = time.time()
        option.click()
        return self._timed(scene, t0)

    def _timed(self, scene: str, t0: float) -> FirstFrame:
        """The first complete frame of the run of ``scene`` after the change at ``t0``, with
        the time its run's line came (``server_s``)."""
        assert self.cast is not None
        got = self.cast.first_frame(t0, self.previous, self.ran(scene))
        mine = [
            t for r, t in zip(self.runs, self.run_times, strict=True) if f" scene={scene} " in r
        ]
        got.server_s = mine[-1] - t0 if mine else None
        self.previous = got.views
        return got

    def change(self, scene: str, typed: str | None = None) -> FirstFrame:
        """One change of the scene's parameter: a σβ slider step (``typed`` None) or ``typed``
        into the scene's box (σβ's for prosov, C0 for gorshkov), timed from the keypress (the
        last keystroke)."""
        assert self.cast is not None
        self._drain()
        self.runs.clear()
        self.run_times.clear()
        if typed is None:
            slider = self.controls.get_by_role("slider").first
            slider.focus()
            t0 = time.time()
            slider.press("ArrowRight")
        else:
            if scene == "gorshkov":
                box = self.controls.get_by_label("C0", exact=True).first
            else:
                box = self.controls.get_by_role("slider").first.locator(SLIDER_BOX).first
            box.click()
            box.press("Control+a")
            box.type(typed[:-1], delay=80)  # a quick typist: 80 ms between keys
            self.page.wait_for_timeout(80)
            t0 = time.time()  # the last keystroke (``type`` returns only after its delay)
            box.press(typed[-1])
        return self._timed(scene, t0)

    def stop(self) -> None:
        """Stop ``radarviz tune`` and its servers (its process group)."""
        try:
            os.killpg(self.proc.pid, signal.SIGTERM)
        except ProcessLookupError:
            return
        try:
            self.proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(timeout=5)


#: The changes made in each scene by the bench, in turn: None is a σβ slider step, a string
#: a typed C0 (Gorshkov).
BENCH_CHANGES = {"prosov": None, "velocity": None, "gorshkov": ("25", "5", "40")}


def spread(values: list[float]) -> dict[str, float | int | None]:
    """n, median, min and max of ``values`` (None where there are none)."""
    if not values:
        return {"n": 0, "median": None, "min": None, "max": None}
    return {
        "n": len(values),
        "median": statistics.median(values),
        "min": min(values),
        "max": max(values),
    }


def bench_tune_frames(changes: int = DEFAULT_CHANGES, artifacts: Path | None = None) -> dict:
    """Per scene, s from a switch and from each change to the first complete frame, and the
    part of it until the run's line came (``server_s``: settling, run, flush); their medians
    and ranges (see the module's doc); ``artifacts``: each scene's settled frame saved there."""
    from playwright.sync_api import sync_playwright

    from radarviz.viz_app.runtime import machine

    host = machine()
    tune = TunePage.start()
    figures: dict[str, dict[str, list[float]]] = {}
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            tune.open(browser)
            for scene in SCENE_ORDER[1:]:
                fig = figures.setdefault(
                    scene, {"switch_s": [], "change_s": [], "change_server_s": []}
                )
                fig["switch_s"].append(tune.switch(scene).seconds)
                for k in range(changes):
                    typed = BENCH_CHANGES[scene]
                    got = tune.change(scene, None if typed is None else typed[k % len(typed)])
                    fig["change_s"].append(got.seconds)
                    if got.server_s is not None:
                        fig["change_server_s"].append(got.server_s)
                if artifacts is not None:
                    artifacts.mkdir(parents=True, exist_ok=True)
                    (artifacts / f"tune_frame_{scene}.jpg").write_bytes(got.jpeg)
            assert tune.cast is not None
            tune.cast.stop()
            browser.close()
    finally:
        tune.stop()
    return {
        "changes_per_scene": changes,
        "viewport": f"{VIEWPORT['width']}x{VIEWPORT['height']}",
        "budget_s": FIRST_FRAME_BUDGET_S,
        "seconds": figures,
        "summary_s": {
            scene: {k: spread(v) for k, v in fig.items()} for scene, fig in figures.items()
        },
        "machine": {**host, "load_avg_1min_after": machine()["load_avg_1min"]},
    }


def format_tune_frames(doc: dict) -> str:
    """One line per scene: the change's median first frame [min … max] over n, within the
    budget or not, its server part, and the switches."""
    load = doc["machine"]
    out = [
        f"tune: change → first complete frame in headless Chromium ({doc['viewport']}, "
        f"budget {doc['budget_s']:g} s; load {load['load_avg_1min']} → "
        f"{load['load_avg_1min_after']})"
    ]
    for scene, fig in doc["summary_s"].items():
        ch, sv = fig["change_s"], fig["change_server_s"]
        verdict = "within" if ch["median"] <= doc["budget_s"] else "OVER"
        sw = " ".join(f"{s:.2f}" for s in doc["seconds"][scene]["switch_s"])
        server = f"{sv['median']:.2f}" if sv["median"] is not None else "-"
        out.append(
            f"  {scene:9s} change {ch['median']:.2f} s median [{ch['min']:.2f} … "
            f"{ch['max']:.2f}] over {ch['n']} ({verdict} budget; of it to the run's line "
            f"{server} s); switch {sw} s"
        )
    return "\n".join(out)
