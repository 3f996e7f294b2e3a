"""Every tab of every recording shows data in every view, on every timeline it has.

Each recording is served once and opened in headless Chromium at 1600 × 1000; the test then
sends the viewer blueprints (over the viewer's gRPC port, as the Python SDK does) opening
each tab on each timeline in turn, which is what clicking the tab and the timeline menu does.
Where each view sits is computed from the blueprint's containers and shares; a view whose
frame (below its title bar, and a text log's column header) holds fewer than
``MIN_DATA_PIXELS`` coloured pixels is empty and fails the test. The viewer's chrome, the
grids of the 3D views, the charts' boxes and "No data available." are all grey, so only drawn
data counts.

Required in CI (``CI=true``), like the other browser tests.
"""

from __future__ import annotations

import io
import itertools
import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rerun.blueprint as rrb

from radarviz.viz_app.rerun.recording import new_recording, recording_file
from radarviz.viz_app.rerun.scenes import PresetLayout, blueprint_of, log_preset
from radarviz.viz_app.rerun.viewer import free_port, viewer_url, wait_viewer

ARTIFACTS = Path(__file__).resolve().parents[1] / "test-artifacts" / "views"
DOCS = Path(__file__).resolve().parents[1] / "docs"
VIEWPORT = {"width": 1600, "height": 1000}
#: The tab content's top and bottom rows at 1600 × 1000 (below the tab bar, above the time
#: panel), and each view's title bar height, px.
CONTENT_TOP, CONTENT_BOTTOM, TITLE_BAR = 62, 972, 30
#: A view with fewer coloured pixels than this inside its frame shows no data.
MIN_DATA_PIXELS = 40
#: A text-log view's column header (below its title bar), px: left out of its frame, since
#: the header's active-timeline column is highlighted in colour even when no entry is listed.
LOG_HEADER = 36
#: Rows that change when the active tab (the tab bar) or the timeline (the time panel) does.
TAB_BAR = slice(36, 60)
TIME_PANEL = slice(975, 1000)
#: How long the viewer may take to draw every view of a tab, s: the first tab waits for the
#: whole recording to stream in (a demo on a loaded 2-core machine: minutes), later ones only
#: for the switch.
FIRST_SETTLE_S, SETTLE_S = 360.0, 90.0


Rect = tuple[int, int, int, int]


def view_rects(node: object, rect: Rect) -> list[tuple[str, Rect]]:
    """(name, (x0, y0, x1, y1)) of every view of a blueprint container laid out in ``rect``:
    Horizontal and Vertical split by their shares, Grid row-major into ``grid_columns``."""
    contents = getattr(node, "contents", None)
    if contents is None or not hasattr(node, "kind"):
        return [(str(getattr(node, "name", "") or type(node).__name__), rect)]
    kids = list(contents)
    x0, y0, x1, y1 = rect
    kind = str(node.kind).lower()
    out: list[tuple[str, Rect]] = []

    def cuts(lo: int, hi: int, shares: list[float] | None, n: int) -> list[tuple[int, int]]:
        w = np.asarray(shares if shares else [1.0] * n, dtype=float)
        edges = lo + (hi - lo) * np.r_[0.0, np.cumsum(w)] / w.sum()
        return [(int(a), int(b)) for a, b in itertools.pairwise(edges)]

    if "horizontal" in kind:
        for kid, (a, b) in zip(kids, cuts(x0, x1, node.column_shares, len(kids)), strict=True):
            out += view_rects(kid, (a, y0, b, y1))
    elif "vertical" in kind:
        for kid, (a, b) in zip(kids, cuts(y0, y1, node.row_shares, len(kids)), strict=True):
            out += view_rects(kid, (x0, a, x1, b))
    elif "grid" in kind:
        cols = int(node.grid_columns or math.ceil(math.sqrt(len(kids))))
        rows = math.ceil(len(kids) / cols)
        xs, ys = cuts(x0, x1, None, cols), cuts(y0, y1, None, rows)
        for i, kid in enumerate(kids):
            (a, b), (c, d) = xs[i % cols], ys[i // cols]
            out += view_rects(kid, (a, c, b, d))
    else:
        raise AssertionError(f"unknown container kind {kind}")
    return out


def data_pixels(shot: np.ndarray, rect: Rect, header: int = 0) -> int:
    """Coloured pixels (saturation above 0.25) inside a view's frame, its title bar, a
    ``header`` below it (``frame_header``) and a margin for the separators left out."""
    x0, y0, x1, y1 = rect
    region = shot[y0 + TITLE_BAR + header : y1 - 6, x0 + 6 : x1 - 6, :3]
    if region.size == 0:
        return 0
    return int(((region.max(axis=-1) - region.min(axis=-1)) > 0.25).sum())


def frame_header(view: object) -> int:
    """Rows below a view's title bar that are chrome, not data: a text log's column header
    (a log view with no entry on the active timeline is otherwise taken for one with data)."""
    return LOG_HEADER if isinstance(view, rrb.TextLogView) else 0


def timelines(path: Path) -> list[str]:
    """The timelines a recording has (its chunks' index columns)."""
    from rerun.chunk import RrdReader

    names: set[str] = set()
    for chunk in RrdReader(str(path)).stream():
        names |= set(chunk.timeline_names)
    return sorted(names)


def _shot(page) -> np.ndarray:
    from matplotlib.image import imread

    return imread(io.BytesIO(page.screenshot(timeout=120_000)), format="png")


def check_every_tab(
    rrd: Path, layout: PresetLayout, recording_id: str, label: str, chromium
) -> list[Path]:
    """Serve ``rrd``, open each tab of ``layout`` on each of its timelines, and assert every
    view shows data; returns the screenshots (``ARTIFACTS/{label}_{tab}_{timeline}.png``)."""
    from matplotlib.image import imsave
    from playwright.sync_api import sync_playwright

    grpc, web = free_port(), free_port()
    exe = Path(sys.executable).with_name("radarviz")
    proc = subprocess.Popen(
        [str(exe), "view", str(rrd), "--port", str(grpc), "--web-port", str(web)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    shots: list[Path] = []
    ctl = None
    try:
        # ``radarviz view`` reads the whole file back before serving it (a demo: ~40 MB).
        wait_viewer(proc, "--web-port", "127.0.0.1", web, timeout=240.0)
        executable, args = chromium
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=executable, args=args)
            page = browser.new_page(viewport=VIEWPORT)
            page.goto(viewer_url("127.0.0.1", web, grpc))
            page.wait_for_selector("canvas", timeout=60_000)
            ctl = new_recording(recording_id)
            ctl.connect_grpc(f"rerun+http://127.0.0.1:{grpc}/proxy")
            previous: np.ndarray | None = None
            content = (0, CONTENT_TOP, VIEWPORT["width"], CONTENT_BOTTOM)
            for timeline in [layout.timeline] + [t for t in timelines(rrd) if t != layout.timeline]:
                for i, tab in enumerate(layout.tabs):
                    if previous is not None:
                        ctl.send_blueprint(blueprint_of(layout, i, timeline))
                        ctl.flush()
                    rects = view_rects(tab, content)
                    headers = [frame_header(v) for v in _views(tab)]
                    end = time.monotonic() + (SETTLE_S if previous is not None else FIRST_SETTLE_S)
                    last, empty, shot = None, None, None
                    while time.monotonic() < end:
                        shot = _shot(page)
                        switched = previous is None or any(
                            np.abs(shot[rows] - previous[rows]).max() > 0.1
                            for rows in (TAB_BAR, TIME_PANEL)
                        )
                        counts = [
                            data_pixels(shot, r, h)
                            for (_, r), h in zip(rects, headers, strict=True)
                        ]
                        empty = [
                            name
                            for (name, _), c in zip(rects, counts, strict=True)
                            if c < MIN_DATA_PIXELS
                        ]
                        stable = last is not None and np.abs(shot - last).max() < 0.02
                        if switched and not empty and stable:
                            break
                        last = shot
                        time.sleep(1.5)
                    assert shot is not None
                    path = ARTIFACTS / f"{label}_{i}_{timeline}.png"
                    path.parent.mkdir(parents=True, exist_ok=True)
                    imsave(path, shot)
                    shots.append(path)
                    assert not empty, f"{label}, tab {tab.name!r} on {timeline}: empty {empty}"
                    previous = shot
            browser.close()
    finally:
        if ctl is not None:
            ctl.disconnect()
        os.killpg(proc.pid, 15)
        proc.wait(timeout=10)
    return shots


def write_docs(shot: Path, label: str) -> None:
    """With ``RADARVIZ_WRITE_DOCS=1``: ``shot`` becomes ``docs/viewer_{label}.png``."""
    if os.environ.get("RADARVIZ_WRITE_DOCS") == "1":
        shutil.copyfile(shot, DOCS / f"viewer_{label}.png")


@pytest.mark.parametrize(
    "preset", ["demo", "prosov", "prosov3d", "gorshkov", "velocity", "manoeuvre"]
)
def test_every_tab_of_a_preset_shows_data(preset: str, tmp_path: Path, chromium) -> None:
    """Each preset's tabs on each timeline of its recording (scan and time):
    no view empty. With ``RADARVIZ_WRITE_DOCS=1`` the first tab's screenshot on the
    preset's own timeline replaces ``docs/viewer_{preset}.png``."""
    rrd = tmp_path / f"{preset}.rrd"
    with recording_file(rrd) as rec:
        layout = log_preset(rec, preset)
        rec.send_blueprint(blueprint_of(layout))
        rid = rec.get_recording_id()
    shots = check_every_tab(rrd, layout, rid, preset, chromium)
    assert len(shots) == len(layout.tabs) * len(timelines(rrd))
    write_docs(shots[0], preset)


def test_every_view_of_a_tracked_crossing_scene_shows_data(
    tmp_path: Path, chromium, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``track --associate gnn --rrd`` on ``simulate --preset crossing`` (clutter, P_D < 1):
    its one tab on the ``plot`` and ``time`` timelines, no view empty (``docs/viewer_track.png``
    with ``RADARVIZ_WRITE_DOCS=1``)."""
    from radarviz.viz_app.cli.main import main
    from radarviz.viz_app.rerun import track_recording

    m, r = tmp_path / "m.csv", tmp_path / "r.toml"
    argv = ["simulate", "--preset", "crossing", "--out", str(m), "--radars-out", str(r)]
    assert main([*argv, "--scans", "30", "--clutter-per-scan", "2"]) == 0
    made: list[track_recording.TrackRecorder] = []
    close = track_recording.TrackRecorder.close

    def keep(self: track_recording.TrackRecorder) -> None:
        close(self)
        made.append(self)

    monkeypatch.setattr(track_recording.TrackRecorder, "close", keep)
    rrd = tmp_path / "tracks.rrd"
    track = ["track", "--input", str(m), "--radars", str(r), "--out", str(tmp_path / "t.csv")]
    track += ["--associate", "gnn", "--method", "ucm", "--model", "cv", "--sigma-a", "1"]
    assert main([*track, "--sigma-v0", "300", "--rrd", str(rrd)]) == 0
    (recorder,) = made
    layout = recorder.layout
    assert isinstance(layout.tabs[0], rrb.Horizontal)
    shots = check_every_tab(rrd, layout, recorder.rec.get_recording_id(), "track", chromium)
    assert len(shots) == len(timelines(rrd)) == 2
    write_docs(shots[0], "track")


#: A notebook cell's viewer (about 900 px wide, ``show(height=640)``): the tab content's rows.
NOTEBOOK = (0, CONTENT_TOP, 900, 612)
#: Smallest frame (below the title bar) a view may get there, px: a chart's numbers and
#: labels are sized for about 150 px of height; half the width for small multiples.
MIN_NOTEBOOK_FRAME = (440, 120)


def _views(node: object) -> list[object]:
    contents = getattr(node, "contents", None)
    if contents is None or not hasattr(node, "kind"):
        return [node]
    return [v for k in contents for v in _views(k)]


@pytest.mark.parametrize("preset", ["prosov", "prosov3d", "gorshkov", "velocity", "manoeuvre"])
def test_the_notebook_layout_stacks_every_view_legibly(preset: str) -> None:
    """``narrow_layout`` (what ``radarviz.show`` sends for a notebook cell) holds every view
    of the wide layout once, each at least ``MIN_NOTEBOOK_FRAME`` at 900 × 640 (the wide
    layout there squeezes views to a third of that), the legend above each page of small
    multiples, and no view id twice (the viewer would draw it once)."""
    from radarviz.viz_app.rerun.recording import new_recording
    from radarviz.viz_app.rerun.scenes import _is_legend, narrow_layout

    rec = new_recording()
    rec.set_sinks()
    wide = log_preset(rec, preset)
    narrow = narrow_layout(wide)
    ids = [v.id for t in narrow.tabs for v in _views(t)]
    assert len(ids) == len(set(ids))
    shown = {v.id for t in wide.tabs for v in _views(t) if not _is_legend(v)}
    assert {v.id for t in narrow.tabs for v in _views(t) if not _is_legend(v)} == shown
    for tab in narrow.tabs:
        legends = {str(v.name) for v in _views(tab) if _is_legend(v)} | {"log"}
        for name, (x0, y0, x1, y1) in view_rects(tab, NOTEBOOK):
            frame = (x1 - x0, y1 - y0 - TITLE_BAR)
            if name not in legends:
                assert frame[0] >= MIN_NOTEBOOK_FRAME[0], (tab.name, name, frame)
                assert frame[1] >= MIN_NOTEBOOK_FRAME[1], (tab.name, name, frame)
        if any("grid" in str(getattr(k, "kind", "")).lower() for k in tab.contents):
            assert _is_legend(tab.contents[0]), tab.name
    squeezed = [
        name
        for tab in wide.tabs
        for name, (x0, y0, x1, y1) in view_rects(tab, NOTEBOOK)
        if x1 - x0 < MIN_NOTEBOOK_FRAME[0] or y1 - y0 - TITLE_BAR < MIN_NOTEBOOK_FRAME[1]
    ]
    assert squeezed  # what the stacked layout is for
