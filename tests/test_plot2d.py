"""The charts drawn as 2D entities (``viz_app.rerun.plot2d``): ticks, log axes, outlier-proof
ranges, labels that do not cover each other, and curves drawn where their values say."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from radarviz.viz_app.rerun import plot2d
from radarviz.viz_app.rerun.recording import indexes, recording_file


def test_linear_ticks_are_round_and_cover_the_data() -> None:
    a = plot2d.linear_axis(-350.0, 314.0)
    np.testing.assert_allclose(a.ticks, [-400, -200, 0, 200, 400])
    assert (a.lo, a.hi) == (-400.0, 400.0)
    b = plot2d.linear_axis(3.0, 7.0, include_zero=True)
    assert b.lo == 0.0 and b.hi >= 7.0
    # A constant series still gets a span.
    c = plot2d.linear_axis(5.0, 5.0)
    assert c.lo < 5.0 < c.hi


def test_log_axis_holds_the_data_and_numbers_its_ends() -> None:
    a = plot2d.log_axis(1.1, 18.5)
    assert (a.lo, a.hi) == (1.0, 20.0)
    np.testing.assert_allclose(a.ticks, [1, 2, 5, 10, 20])
    b = plot2d.log_axis(0.47, 85.0)
    assert (b.lo, b.hi) == (0.2, 100.0)
    np.testing.assert_allclose(b.ticks, [0.2, 1, 10, 100])
    np.testing.assert_allclose(b.to_unit(np.array([0.2, 100.0])), [0.0, 1.0])


def test_robust_limits_ignore_a_spike() -> None:
    rng = np.random.default_rng(1)
    speeds = [250.0 + rng.normal(size=300), 180.0 + rng.normal(size=300), np.array([2100.0])]
    lo, hi = plot2d.robust_limits(speeds)
    assert 175.0 < lo < 180.0 and 250.0 < hi < 255.0
    # Without outliers the limits are the data's.
    lo, hi = plot2d.robust_limits([np.array([1.0, 2.0, 3.0])])
    assert (lo, hi) == (1.0, 3.0)


def test_spread_keeps_order_and_gap_inside_the_box() -> None:
    y = np.array([10.0, 11.0, 12.0, 90.0, 99.0])
    s = plot2d.spread(y, 17.0, 0.0, 100.0)
    assert np.all(np.diff(s[np.argsort(y)]) >= 17.0 - 1e-9)
    assert s.min() >= 0.0 and s.max() <= 100.0


@pytest.mark.parametrize("value", [0.0, 1000.0, 0.492, -12.9, 2.5e6])
def test_format_value_is_short(value: float) -> None:
    text = plot2d.format_value(value)
    assert len(text) <= 6
    assert float(text.replace("e", "e+") if "e" in text and "-" not in text else text) == (
        pytest.approx(value, rel=0.05)
    )


def test_a_chart_draws_its_curves_ticks_band_and_cursor(tmp_path: Path, rrd_contents) -> None:
    """The drawn curve is the data mapped into the box; the tick labels are the axis' numbers;
    the cursor labels each curve's value per scan."""
    x = np.arange(1.0, 11.0)
    y = 10.0 ** np.linspace(0.0, 2.0, 10)  # 1 … 100: two decades
    path = tmp_path / "c.rrd"
    with recording_file(path) as rec:
        plot = plot2d.log_plot(
            rec,
            "charts/t/q",
            [plot2d.Curve("q", x, y, (0, 114, 178))],
            width=200.0,
            log_y=True,
            band=plot2d.Band("95% band", x[[0, -1]], np.array([2.0]), np.array([5.0])),
            cursor=indexes(x.astype(int), x),
            cursor_x=x,
            unit=" m",
        )
    rows, cols = rrd_contents(path)
    assert (plot.y.lo, plot.y.hi) == (1.0, 100.0)
    # Two entities: the static drawing (grid, band, curve and numbers) and the cursor.
    assert sorted(r for r in rows if r != "/__properties") == ["/charts/t/q", "/charts/t/q/cursor"]
    drawn = _static(path, "/charts/t/q")
    strips = drawn["LineStrips2D:strips"][0]
    curve = np.array(strips[-1])  # the curve is drawn last, over the grid and the band
    np.testing.assert_allclose(curve[:, 0], (x - 1.0) / 9.0 * 200.0, rtol=1e-5)
    np.testing.assert_allclose(curve[:, 1], np.linspace(0.0, 100.0, 10), atol=1e-3)
    assert drawn["LineStrips2D:colors"][0][-1] == 0x0072B2FF
    texts = drawn["Points2D:labels"][0]
    assert {"1", "10", "100", "95% band"} <= set(texts)
    assert rows["/charts/t/q/cursor"] == 10
    labels = [[t for t in v if t] for v in cols["/charts/t/q/cursor"]["Points2D:labels"]]
    assert labels[0] == ["q 1 m"] and labels[-1] == ["q 100 m"]
    points = cols["/charts/t/q/cursor"]["Points2D:positions"]
    dots = np.array([v[0] for v in points])  # each scan: the dot, then its label
    np.testing.assert_allclose(dots[:, 0], (x - 1.0) / 9.0 * 200.0, rtol=1e-5)
    np.testing.assert_allclose(dots[:, 1], np.linspace(0.0, 100.0, 10), atol=1e-3)
    assert all(v[0] == "" for v in cols["/charts/t/q/cursor"]["Points2D:labels"])


def test_a_forest_plot_draws_its_rows_on_a_numbered_axis(tmp_path: Path, rrd_contents) -> None:
    """Each row's mean and interval are drawn where the x axis puts them, the axis' numbers
    end with its unit, the rows' names sit left of the box (which the view frames, so none is
    cut off) and each row's value at the scan is written out."""
    n = 3
    centre = np.array([[-157.0, 6.0], [-100.0, 0.0], [50.0, -20.0]])
    half = np.array([[10.0, 11.0], [12.0, 13.0], [14.0, 900.0]])
    axis = plot2d.linear_axis(-500.0, 500.0, 4)
    path = tmp_path / "f.rrd"
    with recording_file(path) as rec:
        plot = plot2d.forest_plot(
            rec,
            "f/bias",
            ["naive", "ucm"],
            [(213, 94, 0), (0, 158, 115)],
            centre,
            half,
            axis,
            indexes(np.arange(1, n + 1), np.arange(n) * 10.0),
            width=200.0,
            unit=" m",
            x_unit="m",
            reference="truth",
        )
    rows, cols = rrd_contents(path)
    assert sorted(r for r in rows if r != "/__properties") == ["/f/bias", "/f/bias/scan"]
    assert rows["/f/bias/scan"] == n
    # Each scan: the rows' dots (naive, ucm), then their values.
    points = [np.array(v) for v in cols["/f/bias/scan"]["Points2D:positions"]]
    dots = np.array([v[0] for v in points])
    np.testing.assert_allclose(dots[:, 0], (centre[:, 0] + 500.0) / 1000.0 * 200.0, rtol=1e-5)
    assert np.all(dots[:, 1] > 0.5 * plot2d.HEIGHT)  # the first row above the second
    ucm = np.array([v[1] for v in points])
    assert np.all(ucm[:, 1] < 0.5 * plot2d.HEIGHT)
    # An interval beyond the axis is drawn to the box's edge only.
    ends = np.array(cols["/f/bias/scan"]["LineStrips2D:strips"][2][1])
    np.testing.assert_allclose(ends[:, 0], [0.0, 200.0], atol=1e-4)
    values = cols["/f/bias/scan"]["Points2D:labels"]
    assert values[0] == ["", "", "-157 ± 10 m", "6 ± 11 m"] and values[2][3] == "-20 ± 900 m"
    assert plot.x_unit == "m"
    drawn = _static(path, "/f/bias")
    texts = drawn["Points2D:labels"][0]
    at = {t: p for t, p in zip(texts, drawn["Points2D:positions"][0], strict=True)}
    assert {"naive", "ucm", "truth"} <= set(texts)
    ticks = [t for t in texts if t not in ("naive", "ucm", "truth")]
    assert ticks[0] == "-500" and ticks[-1] == "500 m" and "0" in ticks
    # The reference line at x = 0, in the middle of the box.
    reference = np.array(drawn["LineStrips2D:strips"][0][-1])
    np.testing.assert_allclose(reference[:, 0], [100.0, 100.0], atol=1e-4)
    names = {
        "Points2D:positions": [[at["naive"], at["ucm"]]],
        "Points2D:labels": [["naive", "ucm"]],
    }
    # The names fit the room the view leaves left of the box (about 0.06 HEIGHT a character,
    # centred on their point).
    for (x, _), name in zip(
        names["Points2D:positions"][0], names["Points2D:labels"][0], strict=True
    ):
        assert x - 0.03 * plot2d.HEIGHT * len(name) >= -plot2d.FOREST_MARGIN_LEFT * plot2d.HEIGHT


def _static(path: Path, entity: str) -> dict[str, list]:
    """The static columns of ``entity`` in the recording at ``path``."""
    from rerun.chunk import RrdReader

    for chunk in RrdReader(str(path)).stream():
        if chunk.is_static and chunk.entity_path == entity:
            rb = chunk.to_record_batch()
            return {name: rb.column(name).to_pylist() for name in rb.schema.names}
    raise AssertionError(f"no static {entity}")
