"""The Gorshkov scene in Rerun: the finite-memory filter against its window length k.

The curves are functions of the window length, not of time: they are charts drawn once
(``plot2d``), which show whichever timeline is active; the Doppler-aided track start is a
function of time, with a cursor on ``scan``.

Entity paths (``{p}`` a radar preset RLS1 … RLS6, ``{v}`` range_only or range_doppler)::

    charts/gorshkov/sigma_r_m_{v}            Monte Carlo σ of the range estimate against k, m
    charts/gorshkov/sigma_vr_mps_{v}         … of the radial velocity, m/s
    charts/gorshkov/sigma_a_mps2_{v}         … of the radial acceleration, m/s²
    charts/gorshkov/gain_{r,vr,a}_percent    Doppler's gain K(k), %
    charts/doppler_start/{rmse_vr_mps, sigma_vr_filter_mps}   the start's charts per scan
    plots/doppler_start/rmse_vr_mps/{v}      RMSE of the tracked radial velocity per scan
    plots/doppler_start/sigma_vr_filter_mps/{v}   the filter's own σ of it
    gorshkov/legend                          one labelled swatch per radar (static)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from radarviz.core.experiments.doppler_start import (
    DopplerTrackingConfig,
    DopplerTrackingResult,
    run_doppler_tracking,
)
from radarviz.core.finite_memory.fit import GorshkovResult, run_gorshkov
from radarviz.viz_app.palette import radar_rgb, rgb
from radarviz.viz_app.rerun import plot2d
from radarviz.viz_app.rerun.recording import log_series, log_text
from radarviz.viz_app.rerun.shapes import legend_view, log_legend, pale

ROOT = "gorshkov"
#: (component, entity name, title) of the fitted parameters.
COMPONENTS: tuple[tuple[str, str, str], ...] = (
    ("r", "sigma_r_m", "σ range, m"),
    ("vr", "sigma_vr_mps", "σ radial velocity, m/s"),
    ("a", "sigma_a_mps2", "σ radial acceleration, m/s²"),
)
VARIANTS: dict[str, str] = {"range_only": "range only", "range_doppler": "range + Doppler"}


def log_gorshkov(
    rec: rr.RecordingStream, trials: int = 20_000, seed: int = 1, tracking_runs: int = 300
) -> tuple[str, ...]:
    """The paper's six radars: finite-memory σ and gains against k, and the Doppler-aided
    track start of RLS3. Returns the radar names in colour order."""
    result = run_gorshkov(None, trials=trials, seed=seed)
    tracking = run_doppler_tracking(DopplerTrackingConfig(runs=tracking_runs, seed=seed))
    log_gorshkov_results(rec, result, tracking)
    log_text(rec, f"Gorshkov: {trials} trials per radar; Doppler start: {tracking_runs} runs")
    return tuple(rad.preset.name for rad in result.radars)


def log_gorshkov_results(
    rec: rr.RecordingStream,
    result: GorshkovResult,
    tracking: DopplerTrackingResult,
    analytic: bool = False,
    series: bool = True,
) -> None:
    """Finite-memory σ and gains against k per radar and variant as charts (Monte Carlo;
    with ``analytic`` also √R_ii and the analytic gain, pale: ``log_k_charts``), and the
    Doppler-aided track start's radial-velocity errors per scan (as charts, and with
    ``series`` their values under ``plots/``, which no view draws)."""
    names = tuple(rad.preset.name for rad in result.radars)
    log_legend(rec, f"{ROOT}/legend", list(names), [radar_rgb(j) for j in range(len(names))])
    log_k_charts(rec, result, analytic)
    n = tracking.n
    times = (n - 1) * tracking.config.scenario().period_s
    for var in tracking.rmse_vr_mps if series else ():
        label = VARIANTS.get(var, var)
        for entity, values, what in (
            ("rmse_vr_mps", tracking.rmse_vr_mps[var], "RMSE"),
            ("sigma_vr_filter_mps", tracking.sigma_vr_filter_mps[var], "filter σ"),
        ):
            log_series(
                rec,
                f"plots/doppler_start/{entity}/{var}",
                n,
                times,
                values,
                rgb(var),
                f"{label}: {what}",
            )
    log_start_charts(rec, tracking)


#: Box widths of the k charts (a 3 × 3 grid) and of the Doppler start's charts (drawn units,
#: height ``plot2d.HEIGHT``).
K_CHART_WIDTH = 150.0
START_CHART_WIDTH = 330.0


def log_k_charts(rec: rr.RecordingStream, result: GorshkovResult, analytic: bool = False) -> None:
    """The finite-memory curves against k as charts (``plot2d``), static, so they show
    whichever timeline is active: ``charts/gorshkov/{entity}_{variant}`` (σ, log scale) and
    ``charts/gorshkov/gain_{comp}_percent``, one curve per radar of the Monte Carlo values;
    with ``analytic`` also the analytic √R_ii and gain, pale, named "{radar} analytic"."""
    ks = np.asarray(result.ks, dtype=np.float64)

    def curves(values) -> list[plot2d.Curve]:
        # The pale analytic curves first: a chart draws its curves in order, so the Monte
        # Carlo values lie on top where the two meet.
        pale_curves, out = [], []
        for j, rad in enumerate(result.radars):
            mc, exact = values(rad)
            out.append(plot2d.Curve(rad.preset.name, ks, mc, radar_rgb(j)))
            if analytic:
                tone = pale(radar_rgb(j), 0.5)
                pale_curves.append(plot2d.Curve(f"{rad.preset.name} analytic", ks, exact, tone))
        return pale_curves + out

    for var in VARIANTS:
        for i, (_, entity, _) in enumerate(COMPONENTS):
            plot2d.log_plot(
                rec,
                f"charts/{ROOT}/{entity}_{var}",
                curves(
                    lambda rad, v=var, i=i: (
                        getattr(rad, v).sigma_mc[:, i],
                        getattr(rad, v).sigma_analytic[:, i],
                    )
                ),
                width=K_CHART_WIDTH,
                x_label="k",
                log_y=True,
                label_values=analytic,
            )
    for i, (comp, _, _) in enumerate(COMPONENTS):
        plot2d.log_plot(
            rec,
            f"charts/{ROOT}/gain_{comp}_percent",
            curves(lambda rad, i=i: (rad.gain_mc[:, i], rad.gain_analytic[:, i])),
            width=K_CHART_WIDTH,
            x_label="k",
            include_zero=True,
            label_values=analytic,
        )


def log_start_charts(rec: rr.RecordingStream, tracking: DopplerTrackingResult) -> None:
    """The Doppler-aided start's radial-velocity RMSE and filter σ per scan as charts (log
    scale), with a cursor that labels each variant's value at the scan."""
    n = np.asarray(tracking.n)
    times = (n - 1) * tracking.config.scenario().period_s
    x = n.astype(np.float64)
    for entity, values in (
        ("rmse_vr_mps", tracking.rmse_vr_mps),
        ("sigma_vr_filter_mps", tracking.sigma_vr_filter_mps),
    ):
        curves = [plot2d.Curve(VARIANTS.get(var, var), x, v, rgb(var)) for var, v in values.items()]
        plot2d.log_plot(
            rec,
            f"charts/doppler_start/{entity}",
            curves,
            width=START_CHART_WIDTH,
            log_y=True,
            cursor=[
                rr.TimeColumn("scan", sequence=n.astype(np.int64)),
                rr.TimeColumn("time", duration=times),
            ],
            cursor_x=x,
            unit=" m/s",
        )


# --- views -----------------------------------------------------------------------------------


def views(radars: Sequence[str]) -> rrb.Container:
    """The finite-memory tab: a 3 × 3 grid of charts against k, one per quantity (static:
    they show on every timeline)."""
    cells = []
    for var, label in VARIANTS.items():
        cells += [
            plot2d.plot_view(
                f"charts/{ROOT}/{entity}_{var}", f"{title}, {label}; log scale", K_CHART_WIDTH
            )
            for _, entity, title in COMPONENTS
        ]
    cells += [
        plot2d.plot_view(
            f"charts/{ROOT}/gain_{comp}_percent",
            f"Doppler's gain K for {comp}, %, against k",
            K_CHART_WIDTH,
        )
        for comp, _, _ in COMPONENTS
    ]
    legend = legend_view(ROOT, "legend", len(radars), "radars (k: scans in the window)")
    return rrb.Vertical(
        legend,
        rrb.Grid(*cells, grid_columns=3),
        row_shares=[1, 12],
        name="Gorshkov: finite memory against k",
    )


def start_view(entity: str, name: str) -> rrb.Spatial2DView:
    """One of the Doppler start's charts."""
    return plot2d.plot_view(f"charts/doppler_start/{entity}", name, START_CHART_WIDTH)


def start_views() -> rrb.Container:
    """The Doppler-aided track start: its RMSE and the filter's own σ per scan."""
    return rrb.Vertical(
        start_view("rmse_vr_mps", "radial-velocity RMSE of the track, m/s (log scale), per scan"),
        start_view("sigma_vr_filter_mps", "the filter's σ of the radial velocity, m/s (log scale)"),
        name="Gorshkov: Doppler-aided track start",
    )
