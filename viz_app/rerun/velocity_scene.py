"""The multi-radar velocity scene in Rerun: the situation in km, the velocity in m/s.

Entity paths (``{r}`` a radar: R1, R2, R3)::

    velocity/map                        static transform: metres drawn as km
    velocity/map/radars/{r}             radar site (static, the radar's colour)
    velocity/map/truth/path             the true trajectory (static)
    velocity/map/scale                  the scale bar and its length (static)
    velocity/map/truth/position         the true target per scan
    velocity/map/fused/position         the fused position per scan
    velocity/map/lines_of_sight         radar → fused position per scan, every radar
    velocity/vector/truth               the true velocity V (m/s, from the origin) per scan
    velocity/vector/fused               the estimate V̂ per scan
    velocity/vector/radial              each radar's measured radial velocity along its line of
                                        sight, V̂r u: the projections V̂ is solved from
    velocity/vector/line_of_sight       that line of sight through the origin
    velocity/error/estimate             V̂ − V per scan (m/s), about the origin
    velocity/error/covariance           its 1σ ellipsoid (first order)
    velocity/error/axes                 reference axes ±1 m/s … (static)
    velocity/legend                     one labelled swatch per radar (static)
    plots/velocity/error_mps/{vx,vy,vz} V̂ − V per axis
    plots/velocity/sigma_mps/{vx,vy,vz} first-order 1σ per axis
    plots/velocity/geometry_metric/{m,m_warn} the geometry metric m and its warning level

Scans whose geometry is flagged (m above ``core.velocity.estimate.M_WARN``) are drawn grey,
left out of the plots and noted in the text log; a scan whose geometry is singular gets no
estimate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from numpy.typing import NDArray

from radarviz.core.experiments.velocity_scans import VelocityScans, estimate_scans
from radarviz.core.scenarios.multi_radar import Scenario3D, fusion_scenario
from radarviz.core.velocity.estimate import M_WARN
from radarviz.viz_app.palette import OKABE_ITO, radar_rgb, rgb
from radarviz.viz_app.rerun import plot2d
from radarviz.viz_app.rerun.recording import (
    ellipsoid_axes,
    indexes,
    log_series,
    log_text,
    log_texts,
)
from radarviz.viz_app.rerun.shapes import (
    LINE,
    MARKER,
    SMALL_MARKER,
    THIN_LINE,
    legend_view,
    log_legend,
)

ROOT = "velocity"
#: V̂'s arrow: wider than the truth's, which is drawn over it.
WIDE_LINE = rr.Radius.ui_points(3.0)
#: Colours of the velocity components (none is a radar's).
AXIS_COLOURS: dict[str, tuple[int, int, int]] = {
    "vx": OKABE_ITO["orange"],
    "vy": OKABE_ITO["sky_blue"],
    "vz": (90, 90, 90),
}


@dataclass(frozen=True)
class VelocityFrame:
    """What the views need to frame the scene.

    Attributes:
        map_centre_km, map_size_km: centre and largest extent of sites and path.
        radars: the radar names, in colour order.
        error_lim_mps: the error plot's y range ±error_lim_mps (None: the plot's own).
    """

    map_centre_km: tuple[float, float, float]
    map_size_km: float
    radars: tuple[str, ...]
    error_lim_mps: float | None


def log_velocity_scene(
    rec: rr.RecordingStream, seed: int = 1, scans: int = 50, scenario: Scenario3D | None = None
) -> VelocityFrame:
    """Several radars, one target (``fusion_scenario`` unless given): the fused position and
    the full velocity vector per scan (``core.experiments.velocity_scans.estimate_scans``)."""
    return log_velocity_run(rec, estimate_scans(scenario or fusion_scenario(), scans, seed))


def _send_radar_strips(
    rec: rr.RecordingStream,
    entity: str,
    idx: list[rr.TimeColumn],
    strips: NDArray[np.float64],
    tones: NDArray[np.uint8],
) -> None:
    """Per scan, one thin 2-point strip per radar in the radar's colour, as one entity:
    ``strips`` (scans, radars, 2, 3), ``tones`` (radars, 3)."""
    k, count = strips.shape[:2]
    rec.send_columns(
        entity,
        indexes=idx,
        columns=rr.LineStrips3D.columns(
            strips=list(strips.reshape(-1, 2, 3)),
            colors=np.tile(tones, (k, 1)),
            radii=[THIN_LINE] * (k * count),
        ).partition([count] * k),
    )


def log_velocity_run(
    rec: rr.RecordingStream, run: VelocityScans, series: bool = True
) -> VelocityFrame:
    """Log one ``VelocityScans``: flagged scans grey and in the text log. ``series``: also
    the charts' values under ``plots/`` (no view draws them)."""
    radars = run.scenario.radars
    names = tuple(r.name for r in radars)
    sites = run.sites
    n, t = run.n, run.t
    idx = indexes(n, t)
    k = len(n)
    radial_mps = run.stacked("radial_velocity")
    fused = run.fused
    vel, cov, m, flagged = run.velocity, run.covariance.copy(), run.m, run.flagged
    at_scan = dict(zip(n.tolist(), t.tolist(), strict=True))
    log_texts(rec, [(scan, at_scan[scan], text, "WARN") for scan, text in run.messages])
    # --- the situation, km ---
    base = f"{ROOT}/map"
    rec.log(base, rr.Transform3D(scale=1e-3), static=True)
    for j, r in enumerate(radars):
        rec.log(
            f"{base}/radars/{r.name}",
            rr.Points3D([r.position], radii=[MARKER], colors=[radar_rgb(j)], labels=[r.name]),
            static=True,
        )
    rec.log(
        f"{base}/truth/path",
        rr.LineStrips3D([run.true_position], colors=[rgb("truth")], radii=[THIN_LINE]),
        static=True,
    )
    plot2d.log_scale_bar_3d(rec, f"{base}/scale", np.concatenate([sites, run.true_position]))
    rec.send_columns(
        f"{base}/truth/position",
        indexes=idx,
        columns=rr.Points3D.columns(
            positions=run.true_position, radii=[MARKER] * k, colors=[rgb("truth")] * k
        ),
    )
    rec.send_columns(
        f"{base}/fused/position",
        indexes=idx,
        columns=rr.Points3D.columns(
            positions=fused.position, radii=[SMALL_MARKER] * k, colors=[rgb("fused")] * k
        ),
    )
    # Every radar's line of sight in one entity (few chunks for the viewer to take in).
    strips = np.stack(
        [
            np.broadcast_to(sites[None], (k, *sites.shape)),
            np.broadcast_to(fused.position[:, None], (k, *sites.shape)),
        ],
        2,
    )
    tones = np.array([radar_rgb(j) for j in range(len(radars))], dtype=np.uint8)
    per_scan = [len(radars)] * k
    _send_radar_strips(rec, f"{base}/lines_of_sight", idx, strips, tones)

    # --- the velocity vector, m/s ---
    base = f"{ROOT}/vector"
    zeros = np.zeros((k, 3))
    # V thin and black over a thick V̂, each labelled with its speed at its tip.
    true_speed = np.linalg.norm(run.true_velocity, axis=-1)
    rec.send_columns(
        f"{base}/truth",
        indexes=idx,
        columns=rr.Arrows3D.columns(
            origins=zeros,
            vectors=run.true_velocity,
            colors=[rgb("truth")] * k,
            radii=[THIN_LINE] * k,
            labels=[f"V {v:.0f} m/s" for v in true_speed],
        ),
    )
    # A flagged scan gets a row with no instance, so the last good estimate is not shown in
    # its place (views draw the latest value at the cursor).
    ok = np.all(np.isfinite(vel), axis=-1)
    rows = ok.astype(int).tolist()
    k_ok = int(ok.sum())
    tone = [rgb("band") if f else rgb("fused") for f in flagged[ok]]
    if k_ok:
        rec.send_columns(
            f"{base}/fused",
            indexes=idx,
            columns=rr.Arrows3D.columns(
                origins=zeros[ok],
                vectors=vel[ok],
                colors=tone,
                radii=[WIDE_LINE] * k_ok,
                labels=[f"V̂ {v:.0f} m/s" for v in np.linalg.norm(vel[ok], axis=-1)],
            ).partition(rows),
        )
    speed = float(true_speed.max())
    u = fused.position[:, None, :] - sites[None]  # (k, radars, 3)
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    radial = radial_mps[:, :, None] * u  # (k, radars, 3)
    line = np.stack([-1.2 * speed * u, 1.2 * speed * u], 2)  # (k, radars, 2, 3)
    rec.send_columns(
        f"{base}/radial",
        indexes=idx,
        columns=rr.Arrows3D.columns(
            origins=np.zeros((k * len(radars), 3)),
            vectors=radial.reshape(-1, 3),
            colors=np.tile(tones, (k, 1)),
            radii=[LINE] * (k * len(radars)),
        ).partition(per_scan),
    )
    _send_radar_strips(rec, f"{base}/line_of_sight", idx, line, tones)

    # --- the error V̂ − V, m/s ---
    err = vel - run.true_velocity
    base = f"{ROOT}/error"
    half_max = 1.0
    if k_ok:
        half, quat = ellipsoid_axes(cov[ok])
        good = ~flagged[ok]
        half_max = float(half[good].max()) if good.any() else float(half.max())
        rec.send_columns(
            f"{base}/estimate",
            indexes=idx,
            columns=rr.Points3D.columns(
                positions=err[ok], radii=[MARKER] * k_ok, colors=tone
            ).partition(rows),
        )
        rec.send_columns(
            f"{base}/covariance",
            indexes=idx,
            columns=rr.Ellipsoids3D.columns(
                centers=err[ok],
                half_sizes=half,
                quaternions=quat,
                colors=tone,
                line_radii=[THIN_LINE] * k_ok,
            ).partition(rows),
        )
    error_half = 1.6 * half_max
    # The views are framed in units of these scales (one blueprint for any accuracy): the
    # error view's ±1 is ±error_half m/s, the vector view's 1 is the largest true speed.
    rec.log(base, rr.Transform3D(scale=1.0 / error_half), static=True)
    rec.log(f"{ROOT}/vector", rr.Transform3D(scale=1.0 / speed), static=True)
    _log_axes(rec, f"{ROOT}/vector/axes", plot2d.nice_step(speed, 2))
    _log_axes(rec, f"{base}/axes", error_half)
    rec.log(
        f"{base}/truth",
        rr.Points3D([[0.0, 0.0, 0.0]], radii=[MARKER], colors=[rgb("truth")], labels=["V"]),
        static=True,
    )
    _log_legend(rec, names)

    # --- plots (flagged scans left out) ---
    err[flagged] = np.nan
    cov[flagged] = np.nan
    if series:
        for j, axis in enumerate(("vx", "vy", "vz")):
            c = AXIS_COLOURS[axis]
            log_series(
                rec,
                f"plots/{ROOT}/error_mps/{axis}",
                n,
                t,
                err[:, j],
                c,
                f"V̂{axis[1]} − V{axis[1]}",
            )
            log_series(
                rec, f"plots/{ROOT}/sigma_mps/{axis}", n, t, np.sqrt(cov[:, j, j]), c, f"σ {axis}"
            )
        log_series(
            rec, f"plots/{ROOT}/geometry_metric/m", n, t, m, rgb("fused"), "geometry metric m"
        )
        log_series(
            rec,
            f"plots/{ROOT}/geometry_metric/m_warn",
            n,
            t,
            np.full(k, M_WARN),
            rgb("band"),
            "warning level",
        )
    _log_charts(rec, n, t, err, cov, m)
    log_text(rec, f"velocity fusion: {len(radars)} radars, {k} scans", time_s=float(t[0]))
    return geometry_frame(
        run, float(1.1 * np.nanmax(np.abs(err))) if np.isfinite(err).any() else None
    )


#: Box width of the scene's charts (drawn units, height ``plot2d.HEIGHT``).
CHART_WIDTH = 220.0


def _log_charts(
    rec: rr.RecordingStream,
    n: NDArray,
    t: NDArray,
    err: NDArray[np.float64],
    cov: NDArray[np.float64],
    m: NDArray[np.float64],
) -> None:
    """V̂ − V and the first-order σ per axis and the geometry metric as charts (``plot2d``),
    flagged scans (NaN) left out, with a cursor labelling the values at the scan."""
    x = np.asarray(n, dtype=np.float64)
    cursor = indexes(n, t)
    names = ("vx", "vy", "vz")
    sigma = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    for entity, values, prefix, log_y in (
        ("error_mps", err, "V̂−V ", False),
        ("sigma_mps", sigma, "σ ", True),
    ):
        curves = [
            plot2d.Curve(f"{prefix}{a[1]}", x, values[:, j], AXIS_COLOURS[a])
            for j, a in enumerate(names)
        ]
        plot2d.log_plot(
            rec,
            f"charts/{ROOT}/{entity}",
            curves,
            width=CHART_WIDTH,
            log_y=log_y,
            robust=not log_y,
            include_zero=not log_y,
            cursor=cursor,
            cursor_x=x,
            unit=" m/s",
        )
    plot2d.log_plot(
        rec,
        f"charts/{ROOT}/geometry_metric",
        [
            plot2d.Curve("m", x, m, rgb("fused")),
            plot2d.Curve("warning", x, np.full(x.size, M_WARN), rgb("band")),
        ],
        width=CHART_WIDTH,
        log_y=True,
        cursor=cursor,
        cursor_x=x,
    )


def geometry_frame(run: VelocityScans, error_lim_mps: float | None = None) -> VelocityFrame:
    """The views' framing: the map from the sites and the true path; the vector and error
    views are in units their transforms set (``log_velocity_run``)."""
    pts = np.concatenate([run.sites, run.true_position]) * 1e-3
    lo, hi = pts.min(0), pts.max(0)
    return VelocityFrame(
        tuple(float(v) for v in (lo + hi) / 2),
        float((hi - lo).max()),
        tuple(r.name for r in run.scenario.radars),
        error_lim_mps,
    )


def panel_frame() -> VelocityFrame:
    """The framing of the baseline geometry (60 scans of 10 s), for a blueprint that serves
    every accuracy the tuning panel sets."""
    return geometry_frame(estimate_scans(fusion_scenario(), 60, None))


def _log_axes(rec: rr.RecordingStream, entity: str, half: float) -> None:
    """Three grey axes through the origin (of the error or the vector view), labelled with
    their length: the view's scale."""
    v = np.eye(3) * half
    rec.log(
        entity,
        rr.Arrows3D(origins=-v, vectors=2 * v, colors=[rgb("band")], radii=[THIN_LINE]),
        static=True,
    )
    rec.log(
        f"{entity}/ticks",
        rr.Points3D(
            v,
            radii=[SMALL_MARKER],
            colors=[rgb("band")],
            labels=[f"{a} +{half:.0f} m/s" for a in "xyz"],
            show_labels=True,
        ),
        static=True,
    )


def _log_legend(rec: rr.RecordingStream, names: tuple[str, ...]) -> None:
    entity = f"{ROOT}/legend"
    labels = [*names, "fused V̂", "truth V", "x", "y", "z"]
    colours = [radar_rgb(j) for j in range(len(names))] + [rgb("fused"), rgb("truth")]
    colours += list(AXIS_COLOURS.values())
    log_legend(rec, entity, labels, colours)


# --- views -----------------------------------------------------------------------------------


def _eye(target: NDArray | tuple, distance: float, direction: tuple[float, float, float]):
    d = np.asarray(direction, dtype=float)
    d /= np.linalg.norm(d)
    tgt = np.asarray(target, dtype=float)
    return rrb.EyeControls3D(
        position=tuple(tgt + distance * d), look_target=tuple(tgt), eye_up=(0.0, 0.0, 1.0)
    )


class VelocityViews(NamedTuple):
    """The scene's views, and the tab that arranges them."""

    vector: rrb.Spatial3DView
    error: rrb.Spatial3DView
    situation: rrb.Spatial3DView
    tab: rrb.Container


def radar_legend_view(frame: VelocityFrame) -> rrb.Spatial2DView:
    # The radars, then the five of ``_log_legend``: V̂, V and the three axes.
    return legend_view(ROOT, "legend", len(frame.radars) + 5, "radars, estimate, truth, axes")


def views(frame: VelocityFrame) -> VelocityViews:
    """The velocity tab: the situation, the vector and its error, the plots."""
    situation = rrb.Spatial3DView(
        origin=ROOT,
        contents=["$origin/map/**"],
        name="situation, km: radars, lines of sight, fused position",
        eye_controls=_eye(frame.map_centre_km, 1.6 * frame.map_size_km, (0.2, -0.9, 0.8)),
    )
    vector = rrb.Spatial3DView(
        origin=ROOT,
        contents=["$origin/vector/**"],
        name="velocity V̂ and each radar's radial velocity, m/s",
        eye_controls=_eye((0.0, 0.0, 0.0), 3.0, (0.5, -0.8, 0.6)),
    )
    error = rrb.Spatial3DView(
        origin=ROOT,
        contents=["$origin/error/**"],
        name="error V̂ − V with its 1σ ellipsoid, m/s (grey: geometry flagged)",
        eye_controls=_eye((0.0, 0.0, 0.0), 3.2, (0.5, -0.8, 0.5)),
    )
    legend = radar_legend_view(frame)
    plots = [
        plot2d.plot_view(
            f"charts/{ROOT}/error_mps",
            "V̂ − V per axis, m/s (flagged scans left out)",
            CHART_WIDTH,
        ),
        plot2d.plot_view(
            f"charts/{ROOT}/sigma_mps", "first-order 1σ per axis, m/s (log scale)", CHART_WIDTH
        ),
        plot2d.plot_view(
            f"charts/{ROOT}/geometry_metric",
            "geometry metric m (unitless, log scale) and its warning level",
            CHART_WIDTH,
        ),
    ]
    tab = rrb.Horizontal(
        rrb.Vertical(
            legend,
            rrb.Horizontal(vector, error),
            situation,
            row_shares=[1, 7, 6],
        ),
        rrb.Vertical(*plots),
        column_shares=[3, 2],
        name="Velocity: several radars' radial velocities",
    )
    return VelocityViews(vector, error, situation, tab)
