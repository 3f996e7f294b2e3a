"""Helpers shared by the test modules (pytest imports this file; tests never import each other)."""

from __future__ import annotations

import io
import os
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest

from radarviz.viz_app.bench.tune_frame import CHROMIUM, CHROMIUM_ARGS

RrdContents = tuple[dict[str, int], dict[str, dict[str, list]]]


def read_rrd(path: Path) -> RrdContents:
    """Temporal rows per entity, and the temporal columns of each entity, of a ``.rrd`` file."""
    from rerun.chunk import RrdReader

    rows: dict[str, int] = defaultdict(int)
    cols: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for chunk in RrdReader(str(path)).stream():
        if chunk.is_static:
            rows.setdefault(chunk.entity_path, 0)
            continue
        rows[chunk.entity_path] += chunk.num_rows
        rb = chunk.to_record_batch()
        for name, field in zip(rb.schema.names, rb.schema, strict=True):
            col = rb.column(name)
            if pa.types.is_timestamp(field.type):
                continue  # log time: not ours to check
            if pa.types.is_duration(field.type):
                col = col.cast(pa.int64())  # nanoseconds
            cols[chunk.entity_path][name].extend(col.to_pylist())
    return rows, cols


@pytest.fixture
def rrd_contents() -> Callable[[Path], RrdContents]:
    """``read_rrd`` as a fixture, for tests that read a recording back."""
    return read_rrd


# --- headless Chromium ----------------------------------------------------------------------


@pytest.fixture
def chromium() -> tuple[str, list[str]]:
    """Debian Chromium's path and headless arguments, for ``playwright``'s ``launch``.

    Skips when the browser or playwright is missing, except under ``CI=true``, where that is a
    failure (CI installs both).
    """
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
    return CHROMIUM, CHROMIUM_ARGS


def coloured_fraction(rgba: np.ndarray) -> float:
    """Share of saturated pixels in the window below the top bar and above the time panel.

    The Rerun viewer's chrome is grey; the data (series lines, tracks, ellipses) are coloured.
    """
    h = rgba.shape[0]
    region = rgba[60 : h - 60, :, :3]
    saturation = region.max(axis=-1) - region.min(axis=-1)
    return float((saturation > 0.3).mean())


#: Coloured share above which a viewer screenshot shows data (an empty viewer shows 0; the
#: sparsest scene, the velocity tab, about 0.004).
MIN_COLOURED = 0.002


def check_viewer_shows_data(page: Any, shot: Path, timeout: float = 90.0) -> float:
    """Screenshot a Rerun viewer ``page`` every 2 s until its time-series side is coloured,
    save the last screenshot at ``shot`` and assert that it shows data; returns the fraction.

    The viewer (egui, all drawn in one canvas) streams the recording, then draws it, so the
    first screenshots may show only its grey chrome.
    """
    from matplotlib.image import imread

    coloured = 0.0
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        coloured = coloured_fraction(imread(io.BytesIO(page.screenshot())))
        if coloured > MIN_COLOURED:
            break
        time.sleep(2.0)
    shot.parent.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(shot))
    assert coloured > MIN_COLOURED, (
        f"the viewer shows no data (coloured fraction {coloured:.4f}, see {shot})"
    )
    return coloured


@pytest.fixture
def viewer_shows_data() -> Callable[..., float]:
    """``check_viewer_shows_data`` as a fixture."""
    return check_viewer_shows_data
