"""The Gorshkov scene in Rerun: the finite-memory filter against its window length k.

The curves are functions of the window length, not of time, so they live on a timeline of
their own, ``window_k`` (sequence k = number of scans in the window); the Doppler-aided track
start is a function of time and stays on ``scan``.

Entity paths (``{p}`` a radar preset RLS1 … RLS6, ``{v}`` range_only or range_doppler)::

    plots/gorshkov/sigma_r_m_{v}/{p}         Monte Carlo σ of the range estimate, m
    plots/gorshkov/sigma_vr_mps_{v}/{p}      … of the radial velocity, m/s
    plots/gorshkov/sigma_a_mps2_{v}/{p}      … of the radial acceleration, m/s²
    plots/gorshkov/gain_{r,vr,a}_percent/{p} Doppler's gain K(k), %
    plots/doppler_start/rmse_vr_mps/{v}      RMSE of the tracked radial velocity per scan
    plots/doppler_start/sigma_vr_filter_mps/{v}   the filter's own σ of it
    gorshkov/legend                          one labelled swatch per radar (static)
"""

from __future__ import annotations

from collections.abc import Sequence

import rerun as rr
import rerun.blueprint as rrb

from radarviz.core.experiments.doppler_start import (
    DopplerTrackingConfig,
    DopplerTrackingResult,
    run_doppler_tracking,
)
from radarviz.core.finite_memory.fit import GorshkovResult, run_gorshkov
from radarviz.viz_app.palette import radar_rgb, rgb
from radarviz.viz_app.rerun.recording import log_series, log_text
from radarviz.viz_app.rerun.shapes import legend_view, log_legend, pale

ROOT = "gorshkov"
#: The timeline of the window length.
WINDOW_TIMELINE = "window_k"
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
) -> None:
    """Finite-memory σ and gains against k per radar and variant (Monte Carlo; with
    ``analytic`` also √R_ii and the analytic gain, pale, at ``…/{p}_analytic``), and the
    Doppler-aided track start's radial-velocity errors per scan."""
    ks = result.ks
    names = tuple(rad.preset.name for rad in result.radars)
    for j, rad in enumerate(result.radars):
        name, colour = rad.preset.name, radar_rgb(j)
        curves = [("", colour, "Monte Carlo")]
        if analytic:
            curves.append(("_analytic", pale(colour, 0.5), "analytic"))
        for suffix, tone, what in curves:
            for var in VARIANTS:
                stats = getattr(rad, var)
                sigma = stats.sigma_analytic if suffix else stats.sigma_mc
                for i, (_, entity, _) in enumerate(COMPONENTS):
                    log_series(
                        rec,
                        f"plots/{ROOT}/{entity}_{var}/{name}{suffix}",
                        ks,
                        None,
                        sigma[:, i],
                        tone,
                        f"{name} {what}",
                        WINDOW_TIMELINE,
                    )
            gain = rad.gain_analytic if suffix else rad.gain_mc
            for i, (comp, _, _) in enumerate(COMPONENTS):
                log_series(
                    rec,
                    f"plots/{ROOT}/gain_{comp}_percent/{name}{suffix}",
                    ks,
                    None,
                    gain[:, i],
                    tone,
                    f"{name} {what}",
                    WINDOW_TIMELINE,
                )
    log_legend(rec, f"{ROOT}/legend", list(names), [radar_rgb(j) for j in range(len(names))])
    n = tracking.n
    times = (n - 1) * tracking.config.scenario().period_s
    for var in tracking.rmse_vr:
        label = VARIANTS.get(var, var)
        for entity, values, what in (
            ("rmse_vr_mps", tracking.rmse_vr[var], "RMSE"),
            ("sigma_vr_filter_mps", tracking.sigma_vr_filter[var], "filter σ"),
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


# --- views -----------------------------------------------------------------------------------


def _plot(origin: str, name: str) -> rrb.TimeSeriesView:
    return rrb.TimeSeriesView(origin=origin, name=name, plot_legend=rrb.PlotLegend(visible=False))


def views(radars: Sequence[str]) -> rrb.Container:
    """The finite-memory tab (timeline ``window_k``): a 3 × 3 grid, one plot per quantity."""
    cells = []
    for var, label in VARIANTS.items():
        cells += [
            _plot(f"plots/{ROOT}/{entity}_{var}", f"{title}, {label}, against k")
            for _, entity, title in COMPONENTS
        ]
    cells += [
        _plot(f"plots/{ROOT}/gain_{comp}_percent", f"Doppler gain K for {comp}, %, against k")
        for comp, _, _ in COMPONENTS
    ]
    legend = legend_view(
        ROOT, "legend", len(radars), "radars (timeline window_k: k scans in the window)"
    )
    return rrb.Vertical(
        legend,
        rrb.Grid(*cells, grid_columns=3),
        row_shares=[1, 12],
        name="Gorshkov: finite memory against k",
    )


def start_views() -> rrb.Container:
    """The Doppler-aided track start (timeline ``scan``)."""
    return rrb.Vertical(
        rrb.TimeSeriesView(
            origin="plots/doppler_start/rmse_vr_mps",
            name="radial-velocity RMSE of the track, m/s",
            plot_legend=rrb.PlotLegend(corner="RightTop"),
        ),
        rrb.TimeSeriesView(
            origin="plots/doppler_start/sigma_vr_filter_mps",
            name="the filter's σ of the radial velocity, m/s",
            plot_legend=rrb.PlotLegend(corner="RightTop"),
        ),
        name="Gorshkov: Doppler-aided track start",
    )
