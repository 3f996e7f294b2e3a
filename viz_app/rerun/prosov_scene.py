"""The Prosov scene in Rerun: the situation in km and each method in the target's frame.

Entity paths (``{m}`` a method: naive, seed, cmkf_d, ucm, ducm, ekf, ukf)::

    prosov/map                         static transform: metres drawn as km, north up
    prosov/map/radar                   the radar site, and the labels: where the radar is,
                                       the distance at the end, the scale bar's length
    prosov/map/paths                   the whole true trajectory, the scale bar and the
                                       displayed run's tracks (static strips)
    prosov/map/scan                    per scan: the displayed run's plot (converted naively,
                                       the first point), each method's estimate (then, in
                                       the order of the legend) and the true target (last)
    prosov/target                      static transform: the target frame (below), drawn with
                                       down-range up and exaggerated RANGE ×k (k in view names)
    prosov/target/{m}/scan             per scan, in one entity: the method's 1σ position
                                       ellipse (the first strip) and estimate (the last
                                       point), the true target at the frame's origin (the
                                       first point) and the view's scale (a label); for a
                                       conversion c (naive, seed, cmkf_d, ucm) a note, the
                                       Monte Carlo cloud of c's converted points
                                       (pale), the scan's converted point and the cloud's
                                       mean (an ×, the next two strips)
    prosov/target/polar/scan           the same marks of the naive points in grey (and a note),
                                       shown in
                                       the views of the filters fed polar plots (ducm, ekf,
                                       ukf)
    prosov/bias                        the bias forest plot (``plot2d.forest_plot``): its axis in m
    prosov/bias/scan                   each conversion's mean down-range offset ± 95% CI per scan
    prosov/legend                      one labelled swatch per method (static)
    plots/prosov/{metric}/{m}          per-scan Monte Carlo statistics (names carry units)
    plots/prosov/delta_x_percent/{reading}   Prosov's Δx(n), seed against naive
    plots/prosov/delta_x_percent/rmse_band95_{lo,hi}   the RMSE reading's 95% band

The target frame at scan n: origin at the true target, axes (cross-range, down-range) in m,
``core.geometry.range_cross_basis``. Every method's view has the same bounds, fixed over the
run, chosen so the largest 1σ ellipse fills most of the view; the method's colour is the same
in every view, plot and figure (``viz_app.palette``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from numpy.typing import NDArray

from radarviz.core.experiments.prosov import (
    SHOWN_CONVERSIONS,
    ConversionCloud,
    ProsovScene,
    TrackingConfig,
    conversion_cloud,
    prosov_scene,
)
from radarviz.core.filters.methods import ALL_METHODS
from radarviz.core.geometry import range_cross_basis
from radarviz.viz_app.palette import rgb
from radarviz.viz_app.rerun import plot2d
from radarviz.viz_app.rerun.recording import indexes, log_series, log_text
from radarviz.viz_app.rerun.shapes import (
    CLOUD_MARKER,
    LINE,
    MARKER,
    SMALL_MARKER,
    THIN_LINE,
    colours,
    ellipse_outline,
    legend_view,
    log_legend,
    pale,
    radii,
)

ROOT = "prosov"
#: The methods drawn, in the palette's order.
METHODS_SHOWN: tuple[str, ...] = ALL_METHODS
#: Per-scan statistics drawn, each at ``plots/prosov/<name>/<method>``: (name, attribute of
#: ``core.metrics.TrackMetrics``, view title).
SERIES: tuple[tuple[str, str, str], ...] = (
    ("bias_range_m", "bias_range_m", "track bias along range, m"),
    ("rmse_x_m", "rmse_x_m", "track RMSE in x, m"),
    ("nees_pos", "nees_pos", "position NEES (2 dof), 95% band grey"),
)
#: Cloud points drawn per scan and method, and points behind each mean.
CLOUD_SHOWN = 250
CLOUD_POINTS = 4000
#: Down-range exaggerations tried, smallest first.
_EXAGGERATIONS = (1, 2, 5, 10, 20, 50, 100)


@dataclass(frozen=True)
class TargetFrame:
    """How the target-frame views are drawn: the down-range exaggeration and the bounds.

    Attributes:
        exaggeration: down-range distances are drawn ×k (stated in every view's name).
        cross_half_m: the views show cross-range ±cross_half_m.
        range_half_m: … and down-range ±range_half_m (true metres).
        bias_half_m: the bias forest plot shows down-range offsets ±bias_half_m.
        map_extent_m: (x0, x1, y0, y1) of the true path in the situation map, m (the map is
            framed on it: ``MAP_HALF_WIDTH``).
    """

    exaggeration: int
    cross_half_m: float
    range_half_m: float
    bias_half_m: float
    map_extent_m: tuple[float, float, float, float]


def target_frame(scene: ProsovScene, cloud: ConversionCloud) -> TargetFrame:
    """Bounds that hold every method's 1σ ellipse at every scan, and an exaggeration that
    makes the down-range spread (σr, the conversion biases) visible next to the cross-range one.

    The cross-range spread r σβ is tens of times σr at the paper's ranges: drawn to scale, a
    1σ ellipse is a line and a 100 m bias invisible. k is the largest of 1, 2, 5, 10, … not
    above a third of the ellipses' cross-range / down-range axis ratio at the last scan.
    """
    half_cross = 0.0
    ratios = []
    for track in scene.tracks.values():
        cov = _frame_cov(scene, track.P)
        half_cross = max(half_cross, float(np.sqrt(cov[:, 0, 0]).max()))
        ratios.append(float(np.sqrt(cov[-1, 0, 0] / cov[-1, 1, 1])))
    ratio = float(np.median(ratios))
    k = max([e for e in _EXAGGERATIONS if e <= max(ratio / 3.0, 1.0)])
    cross = 1.1 * half_cross
    # Views are about 2.3 times wider than high; the down-range bound follows.
    reach = max(
        float(
            np.abs(cloud.offset_mean_m[c][:, 1]).max() + cloud.offset_half_width95_m[c][:, 1].max()
        )
        for c in SHOWN_CONVERSIONS
    )
    # The map is framed on the true path (the radar may be far off it), the plots' spread
    # across it included.
    xy = scene.truth[:, [0, 2]]
    x0, x1 = float(xy[:, 0].min()), float(xy[:, 0].max())
    if x1 - x0 < 1.0:  # a target standing still
        x0, x1 = x0 - 500.0, x1 + 500.0
    half_y = max(float(np.abs(xy[:, 1]).max()), 0.12 * (x1 - x0))
    return TargetFrame(
        k,
        nice_ceiling(cross),
        nice_ceiling(cross) / 2.3 / k,
        nice_ceiling(max(1.3 * reach, 1.0)),
        (x0, x1, -half_y, half_y),
    )


def nice_ceiling(v: float) -> float:
    """The smallest of 1, 1.5, 2, 3, 5, 7 × 10ⁿ at or above ``v`` (> 0): bounds that change in
    steps, so a panel re-using a view's blueprint needs only a few of them."""
    exp = 10.0 ** np.floor(np.log10(v))
    return float(min(m * exp for m in (1.0, 1.5, 2.0, 3.0, 5.0, 7.0, 10.0) if m * exp >= v))


def _basis(scene: ProsovScene) -> NDArray[np.float64]:
    """(N, 2, 2) rows (cross-range, down-range) at each scan's true position."""
    return range_cross_basis(np.zeros(2), scene.truth[:, [0, 2]])


def _to_frame(scene: ProsovScene, xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points (N, ..., 2) → offsets from the truth in the target frame, (N, ..., 2) m."""
    b = _basis(scene)
    d = xy - scene.truth[:, None, [0, 2]] if xy.ndim == 3 else xy - scene.truth[:, [0, 2]]
    bt = np.swapaxes(b, -1, -2)
    return d @ bt if d.ndim == 3 else (d[:, None, :] @ bt)[:, 0]


def _frame_cov(scene: ProsovScene, P: NDArray[np.float64]) -> NDArray[np.float64]:
    b = _basis(scene)
    pos = P[:, [0, 2], :][:, :, [0, 2]]
    return b @ pos @ np.swapaxes(b, -1, -2)


def _scan_axes(scene: ProsovScene) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    return np.arange(1, len(scene.times_s) + 1), scene.times_s


def log_map(rec: rr.RecordingStream, scene: ProsovScene, frame: TargetFrame, label: str) -> None:
    """The situation in km: radar, true path, the displayed run's plots and tracks."""
    scans, times = _scan_axes(scene)
    idx = indexes(scans, times)
    n = len(scans)
    base = f"{ROOT}/map"
    x0, x1, y0, y1 = frame.map_extent_m
    scale = 1.0 / (x1 - x0)
    cx, cy = (x0 + x1) / 2.0, (y0 + y1) / 2.0
    # Drawn (u, v) = scale (x − cx, −(y − cy)): the path's extent is u ∈ [−0.5, 0.5].
    rec.log(
        base,
        rr.Transform3D(
            translation=[-cx * scale, cy * scale, 0.0], mat3x3=np.diag([scale, -scale, 1.0])
        ),
        static=True,
    )
    truth = scene.truth[:, [0, 2]]
    end = truth[-1]
    width = x1 - x0
    # The radar is usually far off the framed path: a label at the map's left edge says where.
    left = cx - MAP_HALF_WIDTH / scale
    top = cy + 0.8 * MAP_HALF_HEIGHT / scale
    bottom = cy - 0.8 * MAP_HALF_HEIGHT / scale
    bar = plot2d.scale_bar(
        [cx - 0.45 * width, bottom], width, [0.0, 0.12 * MAP_HALF_HEIGHT / scale]
    )
    # The static marks in two entities (few chunks for the viewer to take in): the radar and
    # the labels; the lines, the true path first, then the scale bar and each track's path.
    rec.log(
        f"{base}/radar",
        rr.Points2D(
            [
                [0.0, 0.0],
                [left + 0.25 * width, top],
                [end[0], cy - 0.35 * MAP_HALF_HEIGHT / scale],
                bar.label_at,
            ],
            radii=np.array([MARKER, 0.0, 0.0, 0.0], dtype=np.float32),
            colors=[rgb("truth")],
            labels=[
                label,
                f"← radar at {np.hypot(*truth[0]) / 1e3:.0f} km from the start: {label}",
                f"end: {np.hypot(*end) / 1e3:.0f} km from the radar",
                bar.text,
            ],
            show_labels=True,
        ),
        static=True,
    )
    paths = [truth, bar.ends]
    paths += [track.x[:, [0, 2]] for track in scene.tracks.values()]
    tones = [rgb("truth"), rgb("truth")] + [rgb(m) for m in scene.tracks]
    rec.log(
        f"{base}/paths",
        rr.LineStrips2D(
            paths,
            colors=np.array(tones, dtype=np.uint8),
            radii=np.array([THIN_LINE, LINE] + [THIN_LINE] * len(scene.tracks), dtype=np.float32),
        ),
        static=True,
    )
    # Per scan, one entity: the displayed run's plots (converted naively), each method's
    # estimate, and the true target last (on top).
    tracks = [track.x[:, [0, 2]] for track in scene.tracks.values()]
    points = np.stack([scene.converted_xy_m["naive"], *tracks, truth], 1)  # (n, 2 + tracks, 2)
    tones = [rgb("measurement")] + [rgb(m) for m in scene.tracks] + [rgb("truth")]
    sizes = [SMALL_MARKER] * (1 + len(tracks)) + [MARKER]
    rec.send_columns(
        f"{base}/scan",
        indexes=idx,
        columns=rr.Points2D.columns(
            positions=points.reshape(-1, 2),
            radii=np.tile(np.asarray(sizes, dtype=np.float32), n),
            colors=np.tile(np.asarray(tones, dtype=np.uint8), (n, 1)),
        ).partition([points.shape[1]] * n),
    )


def log_target_frame(
    rec: rr.RecordingStream,
    scene: ProsovScene,
    frame: TargetFrame,
    cloud: ConversionCloud,
    shown: int = CLOUD_SHOWN,
) -> None:
    """Each method in the target frame: its 1σ ellipse, estimate, the scan's converted
    measurement, and the Monte Carlo cloud of converted points with its mean."""
    scans, times = _scan_axes(scene)
    idx = indexes(scans, times)
    n = len(scans)
    rec.log(
        ROOT + "/target",
        rr.Transform3D(
            mat3x3=np.diag(
                [1.0 / frame.cross_half_m, -frame.exaggeration / frame.cross_half_m, 1.0]
            )
        ),
        static=True,
    )
    k = frame.exaggeration
    stretch = f", down-range ×{k}" if k != 1 else ""
    # Centred at the top: a label as wide as half a small view stays inside it.
    scale_at = [0.0, 0.36 * frame.cross_half_m / k]
    scale_text = f"view ±{frame.cross_half_m / 1e3:g} km across{stretch}"
    note_at = [0.0, -0.3 * frame.cross_half_m / k]
    measured = {c: _to_frame(scene, scene.converted_xy_m[c]) for c in SHOWN_CONVERSIONS}
    clouds = {c: _to_frame(scene, cloud.points[c][:, :shown]) for c in SHOWN_CONVERSIONS}
    means = cloud.offset_mean_m
    for m, track in scene.tracks.items():
        base = f"{ROOT}/target/{m}"
        colour = rgb(m)
        own = m in SHOWN_CONVERSIONS
        # The same in every scan: the truth at the origin, the view's scale and, for a
        # conversion, the note on its points (labels of points of no size).
        fixed = _Fixed([[0.0, 0.0], scale_at], [rgb("truth"), plot2d.AXIS], [MARKER, 0.0])
        fixed.labels[1] = scale_text
        if own:
            fixed.add(
                note_at, pale(colour, 0.2), "pale: converted plots (Monte Carlo), × their mean"
            )
        est = _to_frame(scene, track.x[:, [0, 2]])
        cov = _frame_cov(scene, track.P)
        # Per scan, one entity (one chunk for the viewer): the ellipse (and the ×), the
        # estimate drawn last, over the cloud and the measurement.
        # Arrays per scan: (n, strips or points, ...).
        lines = [[e] for e in ellipse_outline(est, cov)]
        line_colours = colours(colour, n)[:, None]
        line_radii = radii(LINE, n)[:, None]
        points = est[:, None]
        point_colours = colours(colour, n)[:, None]
        point_radii = radii(MARKER, n)[:, None]
        if own:
            x, xc, xr, p, pc, pr = _measured_marks(measured[m], clouds[m], means[m], colour, frame)
            lines = [[*row, *strokes] for row, strokes in zip(lines, x, strict=True)]
            line_colours = np.concatenate([line_colours, xc], 1)
            line_radii = np.concatenate([line_radii, xr], 1)
            points = np.concatenate([p, points], 1)
            point_colours = np.concatenate([pc, point_colours], 1)
            point_radii = np.concatenate([pr, point_radii], 1)
        _send_scan(
            rec,
            f"{base}/scan",
            idx,
            lines,
            line_colours,
            line_radii,
            points,
            point_colours,
            point_radii,
            fixed,
        )
    # Filters fed polar plots (ducm, ekf, ukf) share one grey copy of the naive points.
    if any(m not in SHOWN_CONVERSIONS for m in scene.tracks):
        grey = rgb("measurement")
        polar = f"{ROOT}/target/polar"
        naive = (measured["naive"], clouds["naive"], means["naive"])
        x, lc, lr, p, pc, pr = _measured_marks(*naive, grey, frame)
        fixed = _Fixed([], [], [])
        fixed.add(note_at, grey, "grey: plots converted naively, × their mean (fed polar plots)")
        _send_scan(rec, f"{polar}/scan", idx, x, lc, lr, p, pc, pr, fixed)
    _log_bias(rec, cloud, frame, idx)


def _measured_marks(
    measured: NDArray[np.float64],
    pts: NDArray[np.float64],
    means: NDArray[np.float64],
    tone: tuple[int, int, int],
    frame: TargetFrame,
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray, NDArray]:
    """Per scan, the converted points' marks: the two strokes of the cloud mean's × (strips
    (n, 2, 2, 2), colours (n, 2, 3), radii (n, 2)), and the pale Monte Carlo cloud then the
    scan's converted measurement (points (n, shown + 1, 2), colours (n, shown + 1, 3), radii
    (n, shown + 1))."""
    n, shown = pts.shape[0], pts.shape[1]
    points = np.concatenate([pts, measured[:, None]], 1)
    per_scan_colours = np.r_[colours(pale(tone, 0.55), shown), colours(tone, 1)]
    per_scan_radii = np.r_[radii(CLOUD_MARKER, shown), radii(SMALL_MARKER, 1)]
    return (
        _crosses(means, frame),
        np.tile(colours(rgb("truth"), 2), (n, 1, 1)),
        np.tile(radii(LINE, 2), (n, 1)),
        points,
        np.tile(per_scan_colours, (n, 1, 1)),
        np.tile(per_scan_radii, (n, 1)),
    )


@dataclass
class _Fixed:
    """Points drawn at every scan before the scan's own (a view at a scan draws one row of an
    entity: marks that never change are repeated in each row rather than kept in a static
    entity of their own, which would be one more chunk for the viewer to take in)."""

    positions: list[list[float]]
    colours: list[tuple[int, int, int]]
    radii: list[float]
    labels: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.labels = self.labels or [""] * len(self.positions)

    def add(self, position: list[float], colour: tuple[int, int, int], label: str) -> None:
        """A label (a point of no size) at ``position``."""
        self.positions.append(position)
        self.colours.append(colour)
        self.radii.append(0.0)
        self.labels.append(label)


def _send_scan(
    rec: rr.RecordingStream,
    entity: str,
    idx: list[rr.TimeColumn],
    lines: Sequence,
    line_colours: NDArray,
    line_radii: NDArray,
    points: NDArray[np.float64],
    point_colours: NDArray,
    point_radii: NDArray,
    fixed: _Fixed,
) -> None:
    """Per scan ``k``, the strips ``lines[k]``, the ``fixed`` points then the points
    ``points[k]`` at ``entity``, in one chunk; colours and radii per scan, (n, strips or
    points, ...) (the points' instance order is the drawing order: the last on top)."""
    strips = [np.asarray(s, dtype=np.float64) for row in lines for s in row]
    per_scan = [len(row) for row in lines]
    columns = list(
        rr.LineStrips2D.columns(
            strips=strips,
            colors=np.asarray(line_colours, dtype=np.uint8).reshape(-1, 3),
            radii=np.asarray(line_radii, dtype=np.float32).ravel(),
        ).partition(per_scan)
    )
    n, f = points.shape[0], len(fixed.positions)
    if f:
        points = np.concatenate([np.tile(np.asarray(fixed.positions), (n, 1, 1)), points], 1)
        point_colours = np.concatenate(
            [np.tile(np.asarray(fixed.colours, dtype=np.uint8), (n, 1, 1)), point_colours], 1
        )
        point_radii = np.concatenate(
            [np.tile(np.asarray(fixed.radii, dtype=np.float32), (n, 1)), point_radii], 1
        )
    count = points.shape[1]
    labels = (fixed.labels + [""] * (count - f)) * n
    columns += list(
        rr.Points2D.columns(
            positions=points.reshape(-1, 2),
            colors=np.asarray(point_colours, dtype=np.uint8).reshape(-1, 3),
            radii=np.asarray(point_radii, dtype=np.float32).ravel(),
            labels=labels,
            show_labels=[True] * (n * count),
        ).partition([count] * n)
    )
    rec.send_columns(entity, indexes=idx, columns=columns)


def _crosses(centre: NDArray[np.float64], frame: TargetFrame) -> NDArray[np.float64]:
    """(N, 2, 2, 2): two strokes of an × at each centre, 3% of the view's width wide (the
    down-range stroke shortened by the exaggeration, so the × looks square)."""
    a = 0.03 * frame.cross_half_m
    b = a / frame.exaggeration
    d1 = np.array([[-a, -b], [a, b]])
    d2 = np.array([[-a, b], [a, -b]])
    return centre[:, None, None, :] + np.stack([d1, d2])[None]


#: Width of the bias forest plot's box (drawn units; its height is ``plot2d.HEIGHT``), for a
#: grid cell about 2.6 times wider than high, with room for the names and values beside it.
BIAS_WIDTH = 220.0


def _log_bias(
    rec: rr.RecordingStream,
    cloud: ConversionCloud,
    frame: TargetFrame,
    idx: list[rr.TimeColumn],
) -> None:
    """A forest plot per scan (``plot2d.forest_plot``): each conversion's mean down-range
    offset from the truth (m) with its 95% confidence interval, one row per conversion, the
    truth the line at 0, on an axis of ±``bias_half_m`` fixed over the run (true scale)."""
    rows = list(SHOWN_CONVERSIONS)
    plot2d.forest_plot(
        rec,
        f"{ROOT}/bias",
        rows,
        [rgb(c) for c in rows],
        np.stack([cloud.offset_mean_m[c][:, 1] for c in rows], 1),
        np.stack([cloud.offset_half_width95_m[c][:, 1] for c in rows], 1),
        plot2d.linear_axis(-frame.bias_half_m, frame.bias_half_m, 4),
        idx,
        width=BIAS_WIDTH,
        unit=" m",
        x_unit="m",
        reference="truth",
        reference_colour=rgb("truth"),
    )


def log_statistics(
    rec: rr.RecordingStream, scene: ProsovScene, root: str = ROOT, series: bool = True
) -> None:
    """Each method's per-scan Monte Carlo statistics, the NEES band and Prosov's Δx(n), under
    ``plots/{root}`` (the values; left out when not ``series``), and as charts (``log_charts``)."""
    if not series:
        log_charts(rec, scene, root)
        return
    scans, times = _scan_axes(scene)
    result = scene.result
    for name, m in result.metrics.items():
        for entity, attr, _ in SERIES:
            log_series(
                rec,
                f"plots/{root}/{entity}/{name}",
                scans,
                times,
                getattr(m, attr),
                rgb(name),
                name,
            )
    for tag, v in zip(("lo", "hi"), result.nees_pos_band95, strict=True):
        log_series(
            rec,
            f"plots/{root}/nees_pos/band95_{tag}",
            scans,
            times,
            np.full(len(scans), v),
            rgb("band"),
            f"95% band {tag}",
        )
    if "seed" in result.metrics and "naive" in result.metrics:
        # The 95% band of the RMSE reading (the paper's claim is judged on it).
        for tag, band in zip(("lo", "hi"), result.delta_x_ci95_percent()["rmse"], strict=True):
            log_series(
                rec,
                f"plots/{root}/delta_x_percent/rmse_band95_{tag}",
                scans,
                times,
                band,
                pale(READING_COLOURS["rmse"], 0.5),
                f"rmse reading, 95% band {tag}",
            )
        for reading, values in result.delta_x_percent().items():
            log_series(
                rec,
                f"plots/{root}/delta_x_percent/{reading}",
                scans,
                times,
                values,
                READING_COLOURS[reading],
                f"Δx, {reading} reading",
            )
    log_charts(rec, scene, root)


#: Width of the statistics charts' boxes (drawn units; their height is ``plot2d.HEIGHT``),
#: for views about 3.5 times wider than high.
CHART_WIDTH = 420.0


def log_charts(rec: rr.RecordingStream, scene: ProsovScene, root: str = ROOT) -> None:
    """The per-scan statistics as charts with their own axes (``plot2d``) at
    ``charts/{root}/{metric}``: bias and RMSE per method, the NEES on a log scale over its 95%
    band, Δx with the RMSE reading's band; a cursor gives each curve's value at the scan."""
    scans, times = _scan_axes(scene)
    result = scene.result
    cursor = indexes(scans, times)
    x = scans.astype(np.float64)
    for entity, attr, _ in SERIES:
        curves = [
            plot2d.Curve(name, x, getattr(m, attr), rgb(name)) for name, m in result.metrics.items()
        ]
        band = None
        if entity == "nees_pos":
            lo, hi = result.nees_pos_band95
            band = plot2d.Band(
                f"95% band {lo:.2f}–{hi:.2f}", x[[0, -1]], np.array([lo]), np.array([hi])
            )
        plot2d.log_plot(
            rec,
            f"charts/{root}/{entity}",
            curves,
            width=CHART_WIDTH,
            log_y=entity != "bias_range_m",
            robust=entity == "bias_range_m",
            include_zero=entity == "bias_range_m",
            band=band,
            cursor=cursor,
            cursor_x=x,
            unit=" m" if entity.endswith("_m") else "",
        )
    if "seed" in result.metrics and "naive" in result.metrics:
        lo, hi = result.delta_x_ci95_percent()["rmse"]
        plot2d.log_plot(
            rec,
            f"charts/{root}/delta_x_percent",
            [
                # Named by the reading alone (the view's title says "readings"): the labels
                # with their values must fit right of the box.
                plot2d.Curve(reading, x, v, READING_COLOURS[reading])
                for reading, v in result.delta_x_percent().items()
            ],
            width=CHART_WIDTH,
            include_zero=True,
            band=plot2d.Band("rmse 95%", x, lo, hi, pale(READING_COLOURS["rmse"], 0.3)),
            cursor=cursor,
            cursor_x=x,
            unit=" %",
        )


#: Δx's three readings of σ̂x (as in the Prosov figure).
READING_COLOURS: dict[str, tuple[int, int, int]] = {
    "filter": rgb("seed"),
    "rmse": rgb("naive"),
    "std": rgb("ucm"),
}


def radar_label(cfg: TrackingConfig) -> str:
    return f"radar  σr {cfg.sigma_r_m:g} m, σβ {cfg.sigma_beta_deg:g}°"


def log_prosov(
    rec: rr.RecordingStream,
    sigma_beta_deg: float = 2.0,
    runs: int = 500,
    seed: int = 1,
    cloud_points: int = CLOUD_POINTS,
) -> TargetFrame:
    """The Prosov scene (``core.experiments.prosov.prosov_scene``) at σβ, M runs.

    Returns the target frame the views need (``views``).
    """
    cfg = TrackingConfig(sigma_beta_deg=sigma_beta_deg, runs=runs, seed=seed)
    scene = prosov_scene(cfg)
    frame = log_scene(rec, scene, cloud_points)
    log_text(rec, f"Prosov: {runs} Monte Carlo runs, σβ = {sigma_beta_deg:g}°, seed {seed}")
    lo, hi = scene.result.nees_pos_band95
    for name, m in scene.result.metrics.items():
        if m.nees_pos[-1] > 2 * hi:
            log_text(
                rec,
                f"{name}: NEES {m.nees_pos[-1]:.1f} at the last scan, far above the "
                f"95% band [{lo:.2f}, {hi:.2f}]: its covariance is not credible",
                level="WARN",
                scan=len(scene.times_s),
                time_s=float(scene.times_s[-1]),
            )
    return frame


def log_scene(
    rec: rr.RecordingStream,
    scene: ProsovScene,
    cloud_points: int,
    cloud_shown: int = CLOUD_SHOWN,
    series: bool = True,
) -> TargetFrame:
    """Everything of one Prosov scene: the map, the target frame, the legend, the charts, and
    (``series``) the statistics' values under ``plots/`` (no view draws them: the panel,
    whose viewer must take in a run fast, leaves them out)."""
    cloud = conversion_cloud(scene.config, cloud_points, keep=min(cloud_shown, cloud_points))
    frame = target_frame(scene, cloud)
    log_map(rec, scene, frame, radar_label(scene.config))
    log_target_frame(rec, scene, frame, cloud, min(cloud_shown, cloud_points))
    log_legend(rec, f"{ROOT}/legend", list(scene.tracks), [rgb(m) for m in scene.tracks])
    log_statistics(rec, scene, series=series)
    return frame


# --- views -----------------------------------------------------------------------------------


def _space(name: str, contents: str, bounds: rrb.VisualBounds2D, **kw) -> rrb.Spatial2DView:
    return rrb.Spatial2DView(
        origin=ROOT, contents=[f"$origin/{contents}/**"], name=name, visual_bounds=bounds, **kw
    )


def method_view(method: str) -> rrb.Spatial2DView:
    """One method in the target frame at the current scan. The scene's transform scales the
    frame to ±1 across (``TargetFrame``), so one blueprint frames every configuration; the
    scale is written in the view."""
    bounds = rrb.VisualBounds2D(x_range=[-1.0, 1.0], y_range=[-1.0 / 2.3, 1.0 / 2.3])
    contents = [f"$origin/target/{method}/**"]
    if method not in SHOWN_CONVERSIONS:
        contents.append("$origin/target/polar/**")
    return rrb.Spatial2DView(
        origin=ROOT,
        contents=contents,
        name=f"{method}: target frame at the scan, 1σ ellipse",
        visual_bounds=bounds,
    )


#: The situation map's half width and height in units of the true path's length (the
#: path spans ±0.5), for a view about 3.3 times wider than high.
MAP_HALF_WIDTH, MAP_HALF_HEIGHT = 0.56, 0.17


def map_view() -> rrb.Spatial2DView:
    """The situation (north up), framed on the true path, every scan up to the cursor; a
    scale bar and the distances in its labels."""
    return _space(
        "situation: truth, plots and tracks (north up), framed on the path",
        "map",
        rrb.VisualBounds2D(
            x_range=[-MAP_HALF_WIDTH, MAP_HALF_WIDTH], y_range=[-MAP_HALF_HEIGHT, MAP_HALF_HEIGHT]
        ),
        time_ranges=rrb.VisibleTimeRange(
            "scan",
            start=rrb.TimeRangeBoundary.infinite(),
            end=rrb.TimeRangeBoundary.cursor_relative(),
        ),
    )


def bias_view() -> rrb.Spatial2DView:
    """The forest plot (``_log_bias``), framed with its numbers, names and values."""
    return plot2d.plot_view(
        f"{ROOT}/bias",
        "conversion bias along range, m: mean ± 95% CI",
        BIAS_WIDTH,
        plot2d.FOREST_MARGIN_LEFT,
    )


def method_legend_view() -> rrb.Spatial2DView:
    return legend_view(ROOT, "legend", len(METHODS_SHOWN), "methods")


def series_views(root: str = ROOT, dims: int = 2) -> list[rrb.Spatial2DView]:
    """The statistics charts (``log_charts``), one view each, titled with their units."""
    titles = {
        "bias_range_m": "track bias along range, m",
        "rmse_x_m": "track RMSE in x, m (log scale)",
        "nees_pos": f"position NEES ({dims} dof, log scale) over its 95% band",
    }
    views = [
        plot2d.plot_view(f"charts/{root}/{entity}", titles[entity], CHART_WIDTH)
        for entity, _, _ in SERIES
    ]
    views.append(
        plot2d.plot_view(
            f"charts/{root}/delta_x_percent",
            "Δx, seed against naive, %: three readings of σ̂x, and the rmse reading's 95% band",
            CHART_WIDTH,
        )
    )
    return views


def views(methods: Sequence[str]) -> rrb.Container:
    """The Prosov tab: one target-frame view per method, the bias forest plot, the situation
    map, the legend and the per-scan statistics."""
    cells = [method_view(m) for m in methods] + [bias_view()]
    return rrb.Horizontal(
        rrb.Vertical(method_legend_view(), rrb.Grid(*cells, grid_columns=2), row_shares=[1, 12]),
        rrb.Vertical(map_view(), *series_views(), row_shares=[2, 2, 2, 2, 2]),
        column_shares=[3, 2],
        name="Prosov: converted measurements",
    )


# --- the 3D reproduction (``record --preset prosov3d``) --------------------------------------

#: Entity root of the 3D scene::
#:
#:     prosov3d/target/{m}/estimate     the method's estimate minus the truth, per scan, km
#:     prosov3d/target/{m}/covariance   its 1σ position ellipsoid, per scan
#:     prosov3d/target/truth, /axes     the truth at the origin; down-range, cross-range, up
#:     plots/prosov3d/...               the statistics (as the 2D scene's, 3 dof)
#:
#: In the target frame (``core.geometry.range_cross_up_basis``): x down-range, y cross-range,
#: z up, in km, so the flat ellipsoids (σr along range, r σβ across, r σε up) show at true scale.
ROOT_3D = "prosov3d"


def log_prosov3d(
    rec: rr.RecordingStream,
    sigma_beta_deg: float = 2.0,
    sigma_elevation_deg: float = 1.0,
    elevation_deg: float = 30.0,
    runs: int = 300,
    seed: int = 1,
) -> float:
    """The 3D Prosov scene (``prosov_scene`` of a 3D config): every method's estimate of the
    displayed run and its 1σ ellipsoid in the target frame, and the Monte Carlo statistics.
    Returns the half-size (km) of the frame's views: 1.2 × the largest 1σ half axis of the
    run's second half."""
    from radarviz.core.experiments.prosov import prosov_configs
    from radarviz.core.geometry import range_cross_up_basis
    from radarviz.viz_app.rerun.recording import ellipsoid_axes

    (cfg,) = prosov_configs(
        [sigma_beta_deg],
        runs=runs,
        seed=seed,
        dims=3,
        elevation_deg=elevation_deg,
        sigma_elevation_deg=sigma_elevation_deg,
    )
    scene = prosov_scene(cfg)
    scans, times = _scan_axes(scene)
    idx = indexes(scans, times)
    pos = [0, 2, 4]
    B = range_cross_up_basis(np.zeros(3), scene.truth[:, pos])  # (N, 3, 3)
    n = len(scans)
    largest = 0.0
    for name, track in scene.tracks.items():
        err = np.einsum("nij,nj->ni", B, track.x[:, pos] - scene.truth[:, pos]) / 1e3
        cov = B @ track.P[:, pos][:, :, pos] @ np.swapaxes(B, -1, -2) / 1e6
        half, quat = ellipsoid_axes(cov)
        largest = max(largest, float(half[n // 2 :].max()))
        colour = rgb(name)
        rec.send_columns(
            f"{ROOT_3D}/target/{name}/estimate",
            indexes=idx,
            columns=rr.Points3D.columns(
                positions=err, colors=[colour] * n, radii=[-4.0] * n
            ).partition([1] * n),
        )
        rec.send_columns(
            f"{ROOT_3D}/target/{name}/covariance",
            indexes=idx,
            columns=rr.Ellipsoids3D.columns(
                centers=err,
                half_sizes=half,
                quaternions=quat,
                colors=[colour] * n,
                line_radii=[-1.5] * n,
                fill_mode=[rr.components.FillMode.MajorWireframe] * n,
            ).partition([1] * n),
        )
    reach = 1.2 * largest  # the views frame this
    axis = axis_length_km(reach)
    # The truth is the black dot at the origin (the legend's title says so): a label there
    # would sit on the axes' names and the ellipsoid's centre in a small view.
    rec.log(
        f"{ROOT_3D}/target/truth",
        rr.Points3D([[0.0, 0.0, 0.0]], radii=-6.0, colors=[rgb("truth")]),
        static=True,
    )
    rec.log(
        f"{ROOT_3D}/target/axes",
        rr.Arrows3D(
            vectors=[[axis, 0.0, 0.0], [0.0, axis, 0.0], [0.0, 0.0, axis]],
            colors=[(120, 120, 120)] * 3,
            radii=-1.0,
        ),
        static=True,
    )
    rec.log(
        f"{ROOT_3D}/target/axes/tips",
        rr.Points3D(
            np.eye(3) * axis,
            radii=[0.0],
            colors=[(120, 120, 120)],
            labels=list(AXIS_NAMES),
            show_labels=True,
        ),
        static=True,
    )
    log_legend(rec, f"{ROOT_3D}/legend", list(scene.tracks), [rgb(m) for m in scene.tracks])
    log_statistics(rec, scene, ROOT_3D)
    log_text(
        rec,
        f"Prosov 3D: {runs} Monte Carlo runs, σβ = {sigma_beta_deg:g}°, σε = "
        f"{sigma_elevation_deg:g}°, target at elevation {elevation_deg:g}°, seed {seed}",
    )
    return reach


#: The 3D frame's axes, named at their tips (their common length is in the legend's title).
AXIS_NAMES = ("down-range", "cross-range", "up")
#: The axes reach at most this share of what the views frame.
AXIS_REACH = 0.8


def axis_length_km(reach_km: float) -> float:
    """The axes' length for views framing ``reach_km``: the largest 1, 1.5, 2, 3, 5 or
    7 × 10ⁿ km at or below 0.8 × reach, so that the tips and their names stay inside every
    small view (``views_3d``'s camera shows about ±reach around the origin) and the length
    reads as a round number."""
    target = AXIS_REACH * reach_km
    exp = 10.0 ** np.floor(np.log10(target))
    steps = (1.0, 1.5, 2.0, 3.0, 5.0, 7.0)
    return float(max(m * exp for m in steps if m * exp <= target * 1.0001))


def camera_3d(reach_km: float) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(eye position, up) of the small multiples' common camera, looking at the origin from
    above the down-range, minus-cross-range side, close enough that the ellipsoids of
    ``reach_km`` fill a small view."""
    d = 1.7 * reach_km
    return (0.9 * d, -0.7 * d, 0.6 * d), (0.0, 0.0, 1.0)


def views_3d(reach_km: float, methods: Sequence[str] = METHODS_SHOWN) -> rrb.Container:
    """The 3D tab: small multiples, one 3D target frame per method (its estimate and 1σ
    ellipsoid, the truth and the axes; every camera the same, so sizes compare across
    views), the legend (which gives the axes' length), and the per-scan statistics.
    ``reach_km``: what ``log_prosov3d`` returned."""
    position, up = camera_3d(reach_km)
    eye = rrb.EyeControls3D(position=position, look_target=(0.0, 0.0, 0.0), eye_up=up)
    length = axis_length_km(reach_km)
    frames = [
        rrb.Spatial3DView(
            origin=ROOT_3D,
            contents=[
                f"$origin/target/{m}/**",
                "$origin/target/truth/**",
                "$origin/target/axes/**",
            ],
            name=f"{m}: 1σ ellipsoid, km",
            eye_controls=eye,
        )
        for m in methods
    ]
    return rrb.Horizontal(
        rrb.Vertical(
            legend_view(
                ROOT_3D,
                "legend",
                len(METHODS_SHOWN),
                f"methods; black: the truth; axes {length:g} km (target frame)",
            ),
            rrb.Grid(*frames, grid_columns=3),
            row_shares=[1, 12],
        ),
        rrb.Vertical(*series_views(ROOT_3D, 3)),
        column_shares=[3, 2],
        name="Prosov 3D: the target frame",
    )
