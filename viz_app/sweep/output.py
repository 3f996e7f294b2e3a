"""What ``radarviz sweep`` writes: a tidy Parquet table, heat-map figures, a Rerun recording.

The Parquet table has one row per (grid point, method, scan n), columns:

    point            grid point index, C order over the --grid axes (first axis slowest)
    sigma_beta_deg, sigma_r_m, range_km, period_s[, elevation_deg, sigma_elevation_deg]
                     the point's parameters (gridded or fixed); the target starts at
                     (range_km · 1000, 0) m and moves radially outward at 200 m/s; a 3D
                     sweep adds the target's elevation E and σε (the target starts at
                     range_km · 1000 · u(0, E) and moves outward along u(0, E))
    method           naive, seed, cmkf_d, ucm, ducm, ekf, ukf
    scan, time_s     n = 1 … N and (n − 1) T
    runs, seed       Monte Carlo runs M at the point and the root seed
    bias_x_m, rmse_x_m, std_x_m, sigma_x_filter_m, rmse_y_m, sigma_y_filter_m,
    bias_range_m, bias_cross_m, nees_pos, nees_state
                     the per-scan statistics of ``core.metrics`` (m, as their suffix says;
                     a NEES is dimensionless)
    nees_pos_lo95, nees_pos_hi95, nees_state_lo95, nees_state_hi95
                     95% χ² band of the run-averaged NEES of a consistent filter (2 and 4
                     degrees of freedom in 2D, 3 and 6 in 3D)

The schema metadata key ``radarviz.sweep`` holds a JSON description (axes, fixed values,
runs, seed, block, methods). Heat maps show the last scan over the last two grid axes.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from numpy.typing import NDArray

from radarviz.core.experiments.prosov import TrackingResult
from radarviz.core.experiments.sweep import AXES_OF_DIMS, GRID_AXES, SweepSpec
from radarviz.core.metrics import nees_dof
from radarviz.viz_app.io.atomic import atomic_write

#: The TrackMetrics fields written to the table, in column order.
METRIC_COLUMNS: tuple[str, ...] = (
    "bias_x_m",
    "rmse_x_m",
    "std_x_m",
    "sigma_x_filter_m",
    "rmse_y_m",
    "sigma_y_filter_m",
    "bias_range_m",
    "bias_cross_m",
    "nees_pos",
    "nees_state",
)


def table_columns(dims: int) -> tuple[str, ...]:
    """Every column of a ``dims``-D sweep's table, in order."""
    return (
        "point",
        *AXES_OF_DIMS[dims],
        "method",
        "scan",
        "time_s",
        "runs",
        "seed",
        *METRIC_COLUMNS,
        "nees_pos_lo95",
        "nees_pos_hi95",
        "nees_state_lo95",
        "nees_state_hi95",
    )


#: Every column of a 2D sweep's table, in order (``table_columns(3)`` for a 3D one).
COLUMNS: tuple[str, ...] = table_columns(2)
#: Heat-map metrics at the last scan: column, title, colour map.
HEATMAPS: tuple[tuple[str, str, str], ...] = (
    ("rmse_x_m", "RMSE of x at the last scan, m", "viridis"),
    ("bias_range_m", "range bias at the last scan, m", "RdBu_r"),
    ("nees_pos", "position NEES at the last scan", "RdBu_r"),
)


def sweep_metadata(spec: SweepSpec) -> dict[str, Any]:
    """The sweep's description stored with the table (and in the recording)."""
    b = spec.base
    return {
        "format": "radarviz.sweep/1",
        "dims": b.dims,
        "axes": [
            {"name": a.name, "unit": GRID_AXES[a.name].unit, "values": list(a.values)}
            for a in spec.axes
        ],
        "fixed": {
            name: getattr(b, name)
            for name in spec.axis_names
            if name not in {a.name for a in spec.axes}
        },
        "steps": b.steps,
        "speed_mps": b.speed_mps,
        "runs": b.runs,
        "seed": b.seed,
        "block": spec.block,
        "methods": list(b.methods),
        "columns": list(table_columns(b.dims)),
    }


def sweep_table(spec: SweepSpec, results: list[TrackingResult]) -> pa.Table:
    """The tidy table: one row per (grid point, method, scan)."""
    points = spec.points()
    columns = table_columns(spec.base.dims)
    cols: dict[str, list[NDArray]] = {c: [] for c in columns}
    for p, (point, res) in enumerate(zip(points, results, strict=True)):
        cfg = res.config
        steps = len(res.n)
        for method, m in res.metrics.items():
            cols["point"].append(np.full(steps, p, dtype=np.int32))
            for name in spec.axis_names:
                cols[name].append(np.full(steps, point[name], dtype=np.float64))
            cols["method"].append(np.full(steps, method, dtype=object))
            cols["scan"].append(res.n.astype(np.int32))
            cols["time_s"].append((res.n - 1) * cfg.target.period_s)
            cols["runs"].append(np.full(steps, cfg.runs, dtype=np.int64))
            cols["seed"].append(np.full(steps, cfg.seed, dtype=np.int64))
            for k in METRIC_COLUMNS:
                cols[k].append(np.asarray(getattr(m, k), dtype=np.float64))
            for k, band in (
                ("nees_pos", res.nees_pos_band95),
                ("nees_state", res.nees_state_band95),
            ):
                cols[f"{k}_lo95"].append(np.full(steps, band[0]))
                cols[f"{k}_hi95"].append(np.full(steps, band[1]))
    arrays = {}
    for c in columns:
        data = np.concatenate(cols[c])
        arrays[c] = pa.array(data, type=pa.string()) if c == "method" else pa.array(data)
    table = pa.table(arrays)
    meta = {b"radarviz.sweep": json.dumps(sweep_metadata(spec)).encode()}
    return table.replace_schema_metadata(meta)


def write_parquet(table: pa.Table, path: Path) -> None:
    """Write to a temporary file beside ``path``, then rename it onto ``path``."""
    with atomic_write(path) as fh:
        pq.write_table(table, fh)


def final_scan_grid(
    spec: SweepSpec, results: list[TrackingResult], metric: str, method: str
) -> NDArray[np.float64]:
    """``metric`` of ``method`` at the last scan, shaped like the grid (``spec.shape``)."""
    values = [float(getattr(r.metrics[method], metric)[-1]) for r in results]
    return np.asarray(values).reshape(spec.shape)


def _panels(spec: SweepSpec, grid: NDArray) -> list[tuple[str, NDArray]]:
    """Split a grid (spec.shape) into 2D (rows, columns) panels over its last two axes.

    Leading axes beyond two become separate panels, labelled by their values; one axis is
    one row; no axis is one cell.
    """
    axes = spec.axes
    if len(axes) == 0:
        return [("", grid.reshape(1, 1))]
    if len(axes) == 1:
        return [("", grid.reshape(1, -1))]
    lead = axes[:-2]
    out = []
    for idx in np.ndindex(*grid.shape[:-2]):
        label = ", ".join(f"{a.name}={a.values[i]:g}" for a, i in zip(lead, idx, strict=True))
        out.append((label, grid[idx]))
    return out


def figure_paths(spec: SweepSpec, directory: Path) -> list[Path]:
    """The files ``plot_sweep`` writes into ``directory``, in its order: ``sweep_METRIC.png``
    per heat map, or ``sweep_METRIC_SSS.png`` per slice when more than two axes are gridded.
    Known before computing, so the command line checks them first."""
    slices = int(np.prod(spec.shape[:-2], dtype=np.int64)) if len(spec.axes) > 2 else 0
    return [
        directory / f"sweep_{metric}{f'_{s:03d}' if slices else ''}.png"
        for metric, _, _ in HEATMAPS
        for s in range(max(slices, 1))
    ]


def plot_sweep(spec: SweepSpec, results: list[TrackingResult], directory: Path) -> list[Path]:
    """One figure per heat-map metric (and per slice of any axes beyond two), a panel per
    method, sharing one colour scale so panels compare. Returns the files written."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import colors
    from matplotlib.figure import Figure

    from radarviz.viz_app.figures.common import write_figure_atomically

    methods = spec.base.methods
    axes = spec.axes
    nominal = float(nees_dof(spec.base.dims)[0])  # a consistent filter's position NEES
    x_axis = axes[-1] if axes else None
    y_axis = axes[-2] if len(axes) >= 2 else None
    written = []
    paths = iter(figure_paths(spec, directory))
    for metric, title, cmap in HEATMAPS:
        grids = {m: _panels(spec, final_scan_grid(spec, results, metric, m)) for m in methods}
        for s, (label, _) in enumerate(grids[methods[0]]):
            data = {m: grids[m][s][1] for m in methods}
            finite = np.concatenate([d[np.isfinite(d)] for d in data.values()])
            if metric == "nees_pos":
                # Diverging around the nominal (2, or 3 in 3D) so inconsistent cells stand out
                # either way.
                lo = min(finite.min(), nominal - 0.1) if finite.size else nominal - 1.0
                hi = max(finite.max(), nominal + 0.1) if finite.size else nominal + 1.0
                norm: colors.Normalize = colors.TwoSlopeNorm(nominal, lo, hi)
            elif metric == "bias_range_m":
                lim = float(np.abs(finite).max()) if finite.size else 1.0
                norm = colors.Normalize(-lim or -1.0, lim or 1.0)
            else:
                lo = float(finite.min()) if finite.size else 0.0
                hi = float(finite.max()) if finite.size else 1.0
                norm = colors.Normalize(lo, hi if hi > lo else lo + 1.0)
            ncols = min(4, len(methods))
            nrows = -(-len(methods) // ncols)
            fig = Figure(figsize=(3.4 * ncols + 0.8, 2.9 * nrows + 0.6), layout="constrained")
            panels = fig.subplots(nrows, ncols, squeeze=False)
            image = None
            for k, ax in enumerate(panels.flat):
                if k >= len(methods):
                    ax.set_visible(False)
                    continue
                m = methods[k]
                d = data[m]
                image = ax.imshow(d, origin="lower", aspect="auto", cmap=cmap, norm=norm)
                ax.set_title(m)
                if x_axis is not None:
                    ax.set_xticks(range(d.shape[1]), [f"{v:g}" for v in x_axis.values])
                    ax.set_xlabel(f"{x_axis.name}")
                else:
                    ax.set_xticks([])
                if y_axis is not None:
                    ax.set_yticks(range(d.shape[0]), [f"{v:g}" for v in y_axis.values])
                    ax.set_ylabel(f"{y_axis.name}")
                else:
                    ax.set_yticks([])
                if d.size <= 64:  # few cells: print the numbers too
                    for (i, j), v in np.ndenumerate(d):
                        r, g, bl, _ = image.cmap(norm(v))
                        dark = 0.299 * r + 0.587 * g + 0.114 * bl < 0.5
                        ax.text(
                            j,
                            i,
                            f"{v:.3g}",
                            ha="center",
                            va="center",
                            fontsize=7,
                            color="white" if dark else "black",
                        )
            if image is not None:
                fig.colorbar(image, ax=panels, shrink=0.8)
            b = spec.base
            shown = f"{title} (consistent: {nominal:g})" if metric == "nees_pos" else title
            fig.suptitle(
                f"{shown} — {b.runs} runs per point, seed {b.seed}"
                + (f" ({label})" if label else "")
            )
            path = next(paths)
            write_figure_atomically(fig, path)
            written.append(path)
    return written


def record_sweep(spec: SweepSpec, results: list[TrackingResult], path: Path) -> None:
    """A Rerun recording of the sweep, written atomically (replacing ``path``).

    Entities:
        sweep/heatmap/{metric}/{method}   the last-scan metric over the whole grid, a tensor
                                          with one dimension per --grid axis (static)
        sweep/final/{metric}/{method}     the same values as a series on timeline grid_point
        plots/{metric}/{method}/p{point}  per-scan series of every point (sweeps of at most
                                          64 points), timelines scan and time
        sweep/description                 the sweep's JSON description (static)
    """
    import rerun as rr
    import rerun.blueprint as rrb

    from radarviz.viz_app.rerun.recording import colour, log_series, recording_file

    methods = spec.base.methods
    names = [a.name for a in spec.axes] or ["point"]
    shape = spec.shape or (1,)
    n_points = len(results)
    with recording_file(path, overwrite=True) as rec:
        rec.log(
            "sweep/description",
            rr.TextDocument(json.dumps(sweep_metadata(spec), indent=1)),
            static=True,
        )
        for metric, _, _ in HEATMAPS:
            for m in methods:
                grid = final_scan_grid(spec, results, metric, m).reshape(shape)
                rec.log(
                    f"sweep/heatmap/{metric}/{m}", rr.Tensor(grid, dim_names=names), static=True
                )
                rec.log(
                    f"sweep/final/{metric}/{m}",
                    rr.SeriesLines(colors=[colour(m)], names=[m]),
                    static=True,
                )
                rec.send_columns(
                    f"sweep/final/{metric}/{m}",
                    indexes=[rr.TimeColumn("grid_point", sequence=np.arange(n_points))],
                    columns=rr.Scalars.columns(scalars=grid.reshape(-1)),
                )
        if n_points <= 64:
            for p, res in enumerate(results):
                times = (res.n - 1) * res.config.target.period_s
                for metric, _, _ in HEATMAPS:
                    for m in methods:
                        log_series(
                            rec,
                            f"plots/{metric}/{m}/p{p}",
                            res.n,
                            times,
                            getattr(res.metrics[m], metric),
                            colour(m),
                            f"{m} p{p}",
                        )
        tabs = [
            rrb.Grid(
                *(rrb.TensorView(origin=f"sweep/heatmap/{metric}/{m}", name=m) for m in methods),
                name=metric,
            )
            for metric, _, _ in HEATMAPS
        ]
        series = [
            rrb.TimeSeriesView(
                origin=f"sweep/final/{metric}",
                name=f"{title}, against grid point",
                plot_legend=rrb.PlotLegend(corner="RightTop"),
            )
            for metric, title, _ in HEATMAPS
        ]
        # The heat maps are static; the series of the last-scan values live on grid_point.
        rec.send_blueprint(
            rrb.Blueprint(
                rrb.Horizontal(rrb.Tabs(*tabs), rrb.Vertical(*series), column_shares=[3, 2]),
                rrb.TimePanel(timeline="grid_point", state="collapsed"),
                collapse_panels=True,
            )
        )
