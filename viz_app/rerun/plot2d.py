"""Line plots drawn as 2D entities with axes of their own: ticks with numbers, units, bands,
log scales, and labels that name each curve with its value.

Why not Rerun's time-series view: in a small view it shows one or two y ticks, cuts the
numbers at the left edge, and can only plot against a timeline (a curve against the window
length k would empty the view whenever another timeline is active). A plot here is a static
drawing in a ``Spatial2DView``, so it shows on every timeline; a per-scan *cursor* (a vertical
line and each curve's value, labelled) follows the time slider where the x axis is the scan.

Layout (drawn units, y up through a ``flip_y`` transform on the plot's entity): the plot box
is ``[0, width] × [0, HEIGHT]``; y tick numbers sit left of it, x tick numbers below, and the
curves' labels right of it. ``plot_view`` frames the box with room for all three, for a view of
about ``width / HEIGHT`` times wider than high.

A plot is two entities, so that a viewer has few chunks to take in before it can draw it
(its ingestion, not the drawing, sets how soon a new recording shows)::

    {p}         static: the transform (y up); one ``LineStrips2D`` holding, bottom to top,
                the grid lines and box, a shaded band (e.g. a χ² 95% band) and its edges, and
                the curves (strip colours per line); one ``Points2D`` of text: the tick
                numbers, the band's name and each curve's name and last value at its right end
    {p}/cursor  per scan: the cursor line (``LineStrips2D``) and, in one ``Points2D``, a dot
                on each curve and each curve's value, labelled (the dots' labels are empty)

Within one batch a later strip is drawn over an earlier one, hence the order above.

A *forest plot* (``forest_plot``) uses the same box and x axis for a few rows of per-scan
estimates, each a mean with its confidence interval: the rows' names sit left of the box
where a plot has its y numbers, and each row's value at the scan right of it. Its entities:
``{p}`` static (transform; grid, box and the reference line; tick numbers, row names and
the reference's name) and ``{p}/scan`` per scan (the intervals; the means and their values).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from numpy.typing import NDArray

from radarviz.viz_app.rerun.shapes import (
    LINE,
    MARKER,
    SMALL_MARKER,
    colours,
    flip_y,
    pale,
    radii,
)

#: Height of every plot box, drawn units (its width is given per plot).
HEIGHT = 100.0
#: Curve line and grid line radii (screen points).
CURVE_LINE = rr.Radius.ui_points(1.25)
GRID_LINE = rr.Radius.ui_points(0.4)
GRID = (215, 215, 215)
AXIS = (90, 90, 90)
#: Room around the box, as fractions of HEIGHT: left for the y numbers, below for the x
#: numbers, right for the curves' labels, above for the top number.
MARGIN_LEFT, MARGIN_BOTTOM, MARGIN_RIGHT, MARGIN_TOP = 0.34, 0.3, 0.95, 0.1
#: Room left of a forest plot's box for its rows' names (up to 6 characters), HEIGHT units.
FOREST_MARGIN_LEFT = 0.5


@dataclass(frozen=True)
class Curve:
    """One line of a plot: ``y`` against ``x`` (non-finite values break the line)."""

    label: str
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    colour: tuple[int, int, int]


@dataclass(frozen=True)
class Band:
    """A shaded interval [lo, hi] against ``x`` (constant bands: two-element arrays)."""

    label: str
    x: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    colour: tuple[int, int, int] = (170, 170, 170)


@dataclass(frozen=True)
class Axis:
    """An axis' drawn range and scale. ``log``: base-10 scale (the range must be > 0)."""

    lo: float
    hi: float
    log: bool = False
    ticks: NDArray[np.float64] = field(default_factory=lambda: np.empty(0))

    def to_unit(self, v: NDArray[np.float64]) -> NDArray[np.float64]:
        """Values → [0, 1] across the axis (outside the range: beyond 0 or 1)."""
        v = np.asarray(v, dtype=np.float64)
        if self.log:
            with np.errstate(divide="ignore", invalid="ignore"):
                lv = np.log10(np.where(v > 0, v, np.nan))
            return (lv - np.log10(self.lo)) / (np.log10(self.hi) - np.log10(self.lo))
        return (v - self.lo) / (self.hi - self.lo)


def nice_step(span: float, count: int = 5) -> float:
    """A tick step of 1, 2 or 5 × 10ⁿ giving about ``count`` intervals over ``span`` (> 0)."""
    raw = span / max(count, 1)
    exp = 10.0 ** np.floor(np.log10(raw))
    return float(min(m * exp for m in (1.0, 2.0, 5.0, 10.0) if m * exp >= raw * 0.999))


@dataclass(frozen=True)
class ScaleBar:
    """A map's distance scale: the bar's two ends (m, along +x from its start), where its
    label goes and the label ("50 km")."""

    ends: NDArray[np.float64]
    label_at: NDArray[np.float64]
    text: str


def scale_bar(start: Sequence[float], span_m: float, label_offset: Sequence[float]) -> ScaleBar:
    """The scale bar of a map ``span_m`` wide: ``nice_step(span_m, 5)`` long from ``start``
    (2D or 3D, m) along +x, its label ``label_offset`` from the bar's middle. One function
    for every map (2D or 3D), so each draws the same bar."""
    bar = nice_step(span_m, 5)
    a = np.asarray(start, dtype=float)
    b = a.copy()
    b[0] += bar
    return ScaleBar(np.stack([a, b]), (a + b) / 2.0 + np.asarray(label_offset), f"{bar / 1e3:g} km")


def log_scale_bar_3d(rec: rr.RecordingStream, entity: str, points_m: NDArray[np.float64]) -> None:
    """A 3D map's scale bar (:func:`scale_bar`, static, one entity): on the ground (z = 0)
    below the south-west corner of ``points_m`` (N, 3, m: the sites and paths the map
    frames), sized to their east–north extent, labelled south of it."""
    lo, hi = points_m.min(0), points_m.max(0)
    span = float(max(hi[0] - lo[0], hi[1] - lo[1]))
    bar = scale_bar([lo[0], lo[1] - 0.08 * span, 0.0], span, [0.0, -0.04 * span, 0.0])
    rec.log(
        entity,
        rr.LineStrips3D([bar.ends], colors=[AXIS], radii=[LINE]),
        rr.Points3D(
            [bar.label_at], radii=[0.0], colors=[AXIS], labels=[bar.text], show_labels=True
        ),
        static=True,
    )


def linear_axis(lo: float, hi: float, count: int = 4, include_zero: bool = False) -> Axis:
    """An axis on [lo, hi] widened to whole tick steps (about ``count`` intervals)."""
    if include_zero:
        lo, hi = min(lo, 0.0), max(hi, 0.0)
    if not np.isfinite(lo) or not np.isfinite(hi):
        lo, hi = 0.0, 1.0
    if hi - lo <= 1e-12 * max(abs(lo), abs(hi), 1.0):
        pad = max(abs(hi) * 0.1, 1.0)
        lo, hi = lo - pad, hi + pad
    step = nice_step(hi - lo, count)
    lo_t, hi_t = np.floor(lo / step + 1e-9) * step, np.ceil(hi / step - 1e-9) * step
    ticks = np.arange(lo_t, hi_t + step / 2, step)
    ticks[np.abs(ticks) < step * 1e-9] = 0.0
    return Axis(float(lo_t), float(hi_t), False, ticks)


def log_axis(lo: float, hi: float) -> Axis:
    """A base-10 axis on [lo, hi] (> 0) widened to the nearest 1, 2 or 5 × 10ⁿ; ticks at
    1, 2, 5 × 10ⁿ when it spans at most two decades, else at each decade, and at both ends."""
    lo = max(lo, 1e-300)
    hi = max(hi, lo * 1.001)
    steps = np.array([m * 10.0**d for d in range(-300, 301) for m in (1.0, 2.0, 5.0)])
    lo_t = float(steps[steps <= lo * 1.0001].max())
    hi_t = float(steps[steps >= hi * 0.9999].min())
    decades = np.log10(hi_t) - np.log10(lo_t)
    mult = (1.0, 2.0, 5.0) if decades <= 2.01 else (1.0,)
    d0, d1 = int(np.floor(np.log10(lo_t))), int(np.ceil(np.log10(hi_t)))
    ticks = np.array([m * 10.0**d for d in range(d0, d1 + 1) for m in mult])
    ticks = ticks[(ticks >= lo_t * 0.9999) & (ticks <= hi_t * 1.0001)]
    # The ends are numbered too (on a decade scale they may be 2 or 5 × 10ⁿ), unless that
    # puts them within 15% of the axis of a decade's number.
    axis = Axis(lo_t, hi_t, True, ticks)
    u = axis.to_unit(ticks)
    ends = [e for e in (lo_t, hi_t) if ticks.size == 0 or np.abs(u - axis.to_unit(e)).min() > 0.15]
    return Axis(lo_t, hi_t, True, np.unique(np.r_[ticks, ends]))


def robust_limits(values: Sequence[NDArray], reach: float = 3.0) -> tuple[float, float]:
    """(lo, hi) of the values inside Tukey's fences (``reach`` interquartile ranges beyond
    the quartiles), widened to the 0.5 and 99.5 percentiles: a single clutter spike then
    leaves the axis where the tracks are, while the bulk and a steady series' excursions stay
    inside. (0, 1) without finite values."""
    v = np.concatenate([np.ravel(np.asarray(a, dtype=np.float64)) for a in values])
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 1.0
    p_lo, q1, q3, p_hi = np.percentile(v, [0.5, 25.0, 75.0, 99.5])
    iqr = max(q3 - q1, 1e-9 * max(abs(q1), abs(q3), 1.0))
    inside = v[(v >= q1 - reach * iqr) & (v <= q3 + reach * iqr)]
    # A steady series has a tiny IQR: its 0.5–99.5 percentiles keep its real excursions in.
    return float(min(inside.min(), p_lo)), float(max(inside.max(), p_hi))


def format_value(v: float, step: float | None = None) -> str:
    """A tick or value number: no more digits than the step (or 3 significant) needs."""
    if not np.isfinite(v):
        return "–"
    if v == 0.0:
        return "0"
    a = abs(v)
    if a >= 1e6 or a < 1e-3:
        return f"{v:.2g}".replace("e+0", "e").replace("e-0", "e-")
    if step is not None and step > 0:
        digits = max(0, int(-np.floor(np.log10(step) + 1e-9)))
        return f"{v:.{digits}f}"
    if a >= 100.0:
        return f"{v:.0f}"
    return f"{v:.3g}"


def spread(
    y: NDArray[np.float64], gap: float, lo: float = -np.inf, hi: float = np.inf
) -> NDArray[np.float64]:
    """Label heights near ``y`` at least ``gap`` apart, in the same order, kept within
    [lo, hi] where they fit (for labels that would cover each other): the sorted heights are
    pushed up, the block re-centred on the heights' mean, then shifted into [lo, hi]."""
    y = np.asarray(y, dtype=np.float64)
    order = np.argsort(y)
    s = y[order].copy()
    for i in range(1, s.size):
        s[i] = max(s[i], s[i - 1] + gap)
    if s.size:
        s -= s.mean() - y[order].mean()
        s += max(lo - s[0], 0.0) if s[-1] - s[0] <= hi - lo else lo - s[0]
        s -= max(s[-1] - hi, 0.0) if s[-1] - s[0] <= hi - lo else 0.0
    out = np.empty_like(s)
    out[order] = s
    return out


#: Vertical room of one label, drawn units (labels are about 15 px high at the views' sizes).
LABEL_GAP = 0.17 * HEIGHT
#: How far below its point Rerun draws a label's centre, drawn units (about 11 px at the
#: views' sizes): labels meant level with a mark are raised by it.
LABEL_DROP = 0.09 * HEIGHT


@dataclass(frozen=True)
class Plot:
    """What ``log_plot`` drew: the box width and axes (to place further marks).

    ``x_label`` is written left of the x numbers (the scan, k); ``x_unit`` after the last
    x number ("500 m"), for plots whose left side holds other names."""

    width: float
    x: Axis
    y: Axis
    x_label: str = ""
    x_unit: str = ""

    def to_drawn(self, x: NDArray, y: NDArray) -> NDArray[np.float64]:
        """Data (x, y) → drawn positions (..., 2), clipped to the box."""
        u = np.clip(self.x.to_unit(x), 0.0, 1.0) * self.width
        w = np.clip(self.y.to_unit(y), 0.0, 1.0) * HEIGHT
        return np.stack([u, w], axis=-1)


def _segments(pos: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """The runs of finite rows of ``pos`` (N, 2), as separate strips."""
    ok = np.all(np.isfinite(pos), axis=-1)
    cuts = np.flatnonzero(np.diff(ok.astype(int)))
    bounds = np.r_[0, cuts + 1, ok.size]
    return [pos[a:b] for a, b in itertools.pairwise(bounds) if ok[a] and b - a > 1]


@dataclass
class _Layer:
    """Marks gathered for one static batch: line strips (each with its colour and radius) and
    text points (each with its label and colour), drawn in the order added."""

    strips: list[NDArray[np.float64]] = field(default_factory=list)
    strip_colours: list[tuple[int, int, int]] = field(default_factory=list)
    strip_radii: list[float] = field(default_factory=list)
    text_pos: list[list[float]] = field(default_factory=list)
    texts: list[str] = field(default_factory=list)
    text_colours: list[tuple[int, int, int]] = field(default_factory=list)

    def lines(
        self, strips: Sequence[NDArray[np.float64]], colour: tuple[int, int, int], radius: float
    ) -> None:
        self.strips.extend(np.asarray(s, dtype=np.float64) for s in strips)
        self.strip_colours.extend([colour] * len(strips))
        self.strip_radii.extend([float(radius)] * len(strips))

    def text(self, pos: Sequence[float], label: str, colour: tuple[int, int, int]) -> None:
        self.text_pos.append([float(pos[0]), float(pos[1])])
        self.texts.append(label)
        self.text_colours.append(colour)

    def log(self, rec: rr.RecordingStream, entity: str) -> None:
        """The transform (y up), the strips and the text at ``entity``: one static chunk."""
        parts: list = [flip_y(1.0)]
        if self.strips:
            parts.append(
                rr.LineStrips2D(
                    self.strips,
                    colors=np.array(self.strip_colours, dtype=np.uint8),
                    radii=np.array(self.strip_radii, dtype=np.float32),
                )
            )
        if self.texts:
            parts.append(
                rr.Points2D(
                    self.text_pos,
                    radii=[0.0],
                    colors=np.array(self.text_colours, dtype=np.uint8),
                    labels=self.texts,
                    show_labels=True,
                )
            )
        rec.log(entity, *parts, static=True)


def log_plot(
    rec: rr.RecordingStream,
    entity: str,
    curves: Sequence[Curve],
    *,
    width: float = 300.0,
    x_label: str = "scan",
    x_axis: Axis | None = None,
    y_axis: Axis | None = None,
    log_y: bool = False,
    robust: bool = False,
    include_zero: bool = False,
    band: Band | None = None,
    cursor: list[rr.TimeColumn] | None = None,
    cursor_x: NDArray | None = None,
    label_values: bool = True,
    unit: str = "",
) -> Plot:
    """Draw ``curves`` as a plot at ``entity`` (module docstring) and return its frame.

    Args:
        width: the box's width in drawn units (its height is ``HEIGHT``); match the view's
            shape (``plot_view``).
        x_axis, y_axis: fixed axes; by default from the data (``log_y``: base 10; ``robust``:
            outliers clipped to the box edge, ``robust_limits``; ``include_zero``: y from 0).
        band: a shaded interval drawn under the curves, named at its right end.
        cursor, cursor_x: time columns of the scans and each scan's x: the cursor line and the
            curves' values at it, labelled ("name value unit"). Curves must then share
            ``cursor_x``'s length (one value per scan).
        label_values: end labels carry the last finite value; else only the name.
        unit: appended to values in labels.
    """
    xs = [c.x for c in curves] + ([band.x] if band else [])
    ys = [c.y for c in curves] + ([band.lo, band.hi] if band else [])
    if x_axis is None:
        xa = np.concatenate([np.asarray(x, dtype=np.float64) for x in xs])
        x_axis = linear_axis(float(np.nanmin(xa)), float(np.nanmax(xa)), 5)
        x_axis = Axis(float(np.nanmin(xa)), float(np.nanmax(xa)), False, x_axis.ticks)
        x_axis = Axis(
            x_axis.lo,
            x_axis.hi,
            False,
            x_axis.ticks[(x_axis.ticks >= x_axis.lo - 1e-9) & (x_axis.ticks <= x_axis.hi + 1e-9)],
        )
    if y_axis is None:
        if log_y:
            pos = np.concatenate([np.ravel(np.asarray(y, dtype=np.float64)) for y in ys])
            pos = pos[np.isfinite(pos) & (pos > 0)]
            lo, hi = (
                (robust_limits([pos]) if robust else (pos.min(), pos.max()))
                if pos.size
                else (1.0, 10.0)
            )
            y_axis = log_axis(lo, hi)
        else:
            if robust:
                lo, hi = robust_limits(ys)
            else:
                flat = np.concatenate([np.ravel(np.asarray(y, dtype=np.float64)) for y in ys])
                flat = flat[np.isfinite(flat)]
                lo, hi = (float(flat.min()), float(flat.max())) if flat.size else (0.0, 1.0)
            y_axis = linear_axis(lo, hi, 4, include_zero)
    plot = Plot(width, x_axis, y_axis, x_label)
    layer = _Layer()
    _grid(layer, plot)
    if band is not None:
        _band(layer, plot, band)
    ends, end_labels, end_colours = [], [], []
    for c in curves:
        pos = plot.to_drawn(c.x, c.y)
        pos[~(np.isfinite(np.asarray(c.x, dtype=float)) & np.isfinite(np.asarray(c.y, float)))] = (
            np.nan
        )
        layer.lines(_segments(pos), c.colour, CURVE_LINE)
        ok = np.flatnonzero(np.isfinite(np.asarray(c.y, dtype=float)))
        if ok.size:
            last = ok[-1]
            ends.append(pos[last, 1])
            value = f" {format_value(float(c.y[last]))}{unit}" if label_values else ""
            end_labels.append(f"{c.label}{value}")
            end_colours.append(c.colour)
    if ends and cursor is None:
        _end_labels(layer, plot, np.array(ends), end_labels, end_colours)
    layer.log(rec, entity)
    if cursor is not None and cursor_x is not None:
        _log_cursor(rec, entity, plot, curves, cursor, np.asarray(cursor_x), unit)
    return plot


def _grid(layer: _Layer, plot: Plot) -> None:
    """The grid lines, the box over them, and the axes' numbers."""
    w = plot.width
    box = np.array([[0, 0], [w, 0], [w, HEIGHT], [0, HEIGHT], [0, 0]], dtype=np.float64)
    grid = []
    for t in plot.y.ticks:
        y = float(plot.y.to_unit(t)) * HEIGHT
        if 0.5 < y < HEIGHT - 0.5:
            grid.append(np.array([[0.0, y], [w, y]]))
    for t in plot.x.ticks:
        x = float(plot.x.to_unit(t)) * w
        if 0.5 < x < w - 0.5:
            grid.append(np.array([[x, 0.0], [x, HEIGHT]]))
    layer.lines(grid, GRID, GRID_LINE)
    layer.lines([box], AXIS, GRID_LINE)
    y_step = np.diff(plot.y.ticks).min() if plot.y.ticks.size > 1 and not plot.y.log else None
    x_step = np.diff(plot.x.ticks).min() if plot.x.ticks.size > 1 else None
    for t in plot.y.ticks:
        u = float(plot.y.to_unit(t))
        if -1e-6 <= u <= 1 + 1e-6:
            text = format_value(float(t), y_step)
            # Labels are centred on their point: a number's centre half its width left of
            # the box (about 0.045 HEIGHT per character at the views' sizes).
            layer.text([-0.03 * HEIGHT - 0.024 * HEIGHT * len(text), u * HEIGHT], text, AXIS)
    shown = [t for t in plot.x.ticks if -1e-6 <= float(plot.x.to_unit(t)) <= 1 + 1e-6]
    for i, t in enumerate(shown):
        text = format_value(float(t), x_step)
        if plot.x_unit and i == len(shown) - 1:
            text += f" {plot.x_unit}"
        layer.text([float(plot.x.to_unit(t)) * plot.width, -0.1 * HEIGHT], text, AXIS)
    if plot.x_label:
        left = -0.03 * HEIGHT - 0.024 * HEIGHT * len(plot.x_label)
        layer.text([left, -0.1 * HEIGHT], plot.x_label, AXIS)


def _band(layer: _Layer, plot: Plot, band: Band) -> None:
    """The band shaded by vertical strokes (Rerun's 2D views fill no polygons), its edges and
    its name."""
    x = np.asarray(band.x, dtype=np.float64)
    if x.size == 2:  # a constant band: densify so the strokes fill it
        x = np.linspace(x[0], x[1], 200)
        lo = np.full(x.size, float(np.asarray(band.lo)[0]))
        hi = np.full(x.size, float(np.asarray(band.hi)[0]))
    else:  # interpolated onto 300 strokes, so they overlap into a fill
        xs = np.linspace(np.nanmin(x), np.nanmax(x), 300)
        lo = np.interp(xs, x, np.asarray(band.lo, dtype=np.float64))
        hi = np.interp(xs, x, np.asarray(band.hi, dtype=np.float64))
        x = xs
    a, b = plot.to_drawn(x, lo), plot.to_drawn(x, hi)
    ok = np.all(np.isfinite(a), -1) & np.all(np.isfinite(b), -1)
    strokes = np.stack([a[ok], b[ok]], axis=1)
    spacing = plot.width / max(ok.sum(), 1)
    layer.lines(list(strokes), pale(band.colour, 0.6), max(0.6 * spacing, 0.3))
    layer.lines(_segments(a) + _segments(b), band.colour, GRID_LINE)
    if ok.any():
        top = float(b[ok][0, 1])
        layer.text(
            [0.2 * plot.width, min(top + 0.1 * HEIGHT, 0.93 * HEIGHT)], band.label, band.colour
        )


def label_x(plot: Plot, text: str) -> float:
    """Where a label right of the box is centred so that it starts just right of the box
    (labels are centred on their point; about 0.048 HEIGHT per character)."""
    return plot.width + 0.04 * HEIGHT + 0.024 * HEIGHT * len(text)


def _end_labels(
    layer: _Layer,
    plot: Plot,
    ends: NDArray[np.float64],
    labels: list[str],
    tones: list[tuple[int, int, int]],
) -> None:
    """Curve labels right of the box at their curves' last heights, spread apart."""
    y = spread(ends, LABEL_GAP, 0.0, HEIGHT)
    for text, yy, tone in zip(labels, y, tones, strict=True):
        layer.text([label_x(plot, text), yy], text, tone)


def _log_cursor(
    rec: rr.RecordingStream,
    entity: str,
    plot: Plot,
    curves: Sequence[Curve],
    cursor: list[rr.TimeColumn],
    cursor_x: NDArray,
    unit: str,
) -> None:
    """Per scan, at ``{entity}/cursor`` (one chunk): a vertical line at the scan and, right of
    the box, each curve's value there ("name value"), spread apart, with a dot on the curve."""
    n = cursor_x.size
    u = np.clip(plot.x.to_unit(cursor_x), 0.0, 1.0) * plot.width
    lines = np.stack([np.stack([u, np.zeros(n)], -1), np.stack([u, np.full(n, HEIGHT)], -1)], 1)
    columns = list(
        rr.LineStrips2D.columns(strips=lines, colors=colours(AXIS, n), radii=radii(GRID_LINE, n))
    )
    values = np.stack([np.asarray(c.y, dtype=np.float64) for c in curves], 1)  # (n, curves)
    heights = np.clip(plot.y.to_unit(values), 0.0, 1.0) * HEIGHT
    tones = [c.colour for c in curves]
    # Per scan: the dots (no label), then the labels (no radius).
    pos, point_colours, point_radii, texts, counts = [], [], [], [], []
    for k in range(n):
        ok = np.flatnonzero(np.isfinite(values[k]) & np.isfinite(heights[k]))
        counts.append(2 * ok.size)
        if not ok.size:
            continue
        y = spread(heights[k, ok], LABEL_GAP, 0.0, HEIGHT)
        for j in ok:
            pos.append([u[k], heights[k, j]])
            point_colours.append(tones[j])
            point_radii.append(SMALL_MARKER)
            texts.append("")
        for j, yy in zip(ok, y, strict=True):
            text = f"{curves[j].label} {format_value(float(values[k, j]))}{unit}"
            pos.append([label_x(plot, text), yy])
            point_colours.append(tones[j])
            point_radii.append(0.0)
            texts.append(text)
    if pos:
        total = len(pos)
        columns += list(
            rr.Points2D.columns(
                positions=np.array(pos),
                colors=np.array(point_colours, dtype=np.uint8),
                radii=np.array(point_radii, dtype=np.float32),
                labels=texts,
                show_labels=[True] * total,
            ).partition(counts)
        )
    rec.send_columns(f"{entity}/cursor", indexes=cursor, columns=columns)


def forest_plot(
    rec: rr.RecordingStream,
    entity: str,
    rows: Sequence[str],
    tones: Sequence[tuple[int, int, int]],
    centre: NDArray[np.float64],
    half_width: NDArray[np.float64],
    x_axis: Axis,
    cursor: list[rr.TimeColumn],
    *,
    width: float = 240.0,
    unit: str = "",
    x_unit: str = "",
    reference: str = "",
    reference_colour: tuple[int, int, int] = (0, 0, 0),
) -> Plot:
    """Per scan, each row's estimate ``centre`` ± ``half_width`` (both (N, rows)) as a dot on
    a horizontal interval, one row per name, over a numbered x axis (module docstring).

    Entities: ``{entity}`` static (grid, numbers, the rows' names left of the box) and
    ``{entity}/scan`` per scan: the rows' intervals (``LineStrips2D``, one per row) and, in
    one ``Points2D``, their means (dots, unlabelled) then each row's "centre ± half-width
    unit" right of the box. ``x_unit``: the axis' unit, written after its last number.
    ``reference``: a labelled vertical line at x = 0 (e.g. the truth, when the estimates are
    offsets from it). Values beyond the axis are drawn at its edge, so ``x_axis`` should hold
    every interval (the labels still give the true values).
    """
    count = len(rows)
    # One row per unit, the first at the top; above the rows, room for the reference's label.
    plot = Plot(width, x_axis, Axis(0.0, count + 0.7), x_unit=x_unit)
    layer = _Layer()
    _grid(layer, plot)
    heights = count - np.arange(count) - 0.5
    drawn_y = plot.to_drawn(np.zeros(count), heights)[:, 1]
    # A label is centred across on its point but drawn below it: the names and values are
    # raised by LABEL_DROP to stand level with their rows' dots. A name's centre sits half its
    # width (about 0.06 HEIGHT per character with its background) left of the box.
    for r, y, tone in zip(rows, drawn_y, tones, strict=True):
        layer.text([-0.05 * HEIGHT - 0.03 * HEIGHT * len(r), y + LABEL_DROP], r, tone)
    if reference:
        line = plot.to_drawn(np.zeros(2), np.array([0.0, count]))
        layer.lines([line], reference_colour, CURVE_LINE)
        top = plot.to_drawn(np.zeros(1), np.array([count + 0.35]))[0]
        layer.text(top, reference, reference_colour)
    layer.log(rec, entity)
    centre = np.asarray(centre, dtype=np.float64)
    half_width = np.asarray(half_width, dtype=np.float64)
    n = centre.shape[0]
    y = np.broadcast_to(heights, (n, count))
    mid = plot.to_drawn(centre, y)  # (n, rows, 2)
    ends = np.stack(
        [plot.to_drawn(centre - half_width, y), plot.to_drawn(centre + half_width, y)], 2
    )  # (n, rows, 2, 2)
    tone_rows = np.tile(np.asarray(tones, dtype=np.uint8), (n, 1))
    columns = list(
        rr.LineStrips2D.columns(
            strips=ends.reshape(-1, 2, 2), colors=tone_rows, radii=radii(CURVE_LINE, n * count)
        ).partition([count] * n)
    )
    # Per scan, the rows' dots then their values: (n · 2 rows) points, 2 rows per scan.
    texts = [
        [
            f"{format_value(float(c))} ± {format_value(float(h))}{unit}"
            for c, h in zip(centre[k], half_width[k], strict=True)
        ]
        for k in range(n)
    ]
    pos, labels = [], []
    for k in range(n):
        pos += [list(p) for p in mid[k]]
        labels += [""] * count
        pos += [[label_x(plot, texts[k][i]), mid[k, i, 1] + LABEL_DROP] for i in range(count)]
        labels += texts[k]
    columns += list(
        rr.Points2D.columns(
            positions=np.array(pos),
            colors=np.tile(np.asarray(tones, dtype=np.uint8), (2 * n, 1)),
            radii=np.tile(np.r_[np.full(count, MARKER), np.zeros(count)].astype(np.float32), n),
            labels=labels,
            show_labels=[True] * (2 * n * count),
        ).partition([2 * count] * n)
    )
    rec.send_columns(f"{entity}/scan", indexes=cursor, columns=columns)
    return plot


def plot_view(
    entity: str, name: str, width: float = 300.0, margin_left: float = MARGIN_LEFT
) -> rrb.Spatial2DView:
    """A 2D view of the plot at ``entity`` (box ``width`` × ``HEIGHT``), framed with room for
    its numbers and labels (``margin_left`` × ``HEIGHT`` left of the box: a forest plot's row
    names need ``FOREST_MARGIN_LEFT``). The view's origin is the plot's parent, so its y-up
    transform applies."""
    parent, _, leaf = entity.rpartition("/")
    return rrb.Spatial2DView(
        origin=parent or "/",
        contents=[f"$origin/{leaf}/**"],
        name=name,
        visual_bounds=rrb.VisualBounds2D(
            x_range=[-margin_left * HEIGHT, width + MARGIN_RIGHT * HEIGHT],
            y_range=[-(1.0 + MARGIN_TOP) * HEIGHT, MARGIN_BOTTOM * HEIGHT],
        ),
    )
