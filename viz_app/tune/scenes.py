"""The panel's three scenes: simulate from ``TuneParams``, log, and summarise.

Each scene is the viewer's own scene module fed with the panel's values:

* ``prosov``: ``core.experiments.prosov.prosov_scene`` with σr, σβ, T, runs, seed, scans;
* ``gorshkov``: one radar with σr, T and σVr = σr / (T √C0): its finite-memory σ of r, Vr, a
  and Doppler's gains against k, analytic (√R_ii) and by ``GORSHKOV_TRIALS_PER_RUN`` × runs
  Monte Carlo trials, and the Doppler-aided track start of that radar (σβ, runs, scans);
* ``velocity``: the three baseline sites, every radar with σr, σβ (azimuth and elevation),
  σVr and T, over ``steps`` scans.

``figures`` are the headline numbers of the status line; ``alerts`` the figures far outside
their consistency band or flagged by the estimator. Before anything is logged or shown, a run
passes the same finite-result check as the command line (``core.finite``; the Prosov and
Gorshkov results with the reports' own checks): a NaN, or a negative NEES or σ, raises
``ResultError``, which the panel shows as its one error line while the last good run stays on
screen. A figure is left out only where it is undefined by construction (no scan of the
velocity scene has an estimate yet; no k where the range-only σVr falls below σVr).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import rerun as rr

from radarviz.core.experiments.doppler_start import (
    DopplerTrackingConfig,
    DopplerTrackingResult,
    run_doppler_tracking,
)
from radarviz.core.experiments.prosov import ProsovScene, TrackingConfig, prosov_scene
from radarviz.core.experiments.velocity_scans import VelocityScans, estimate_scans
from radarviz.core.finite import check_finite_figures
from radarviz.core.finite_memory.fit import GorshkovResult, RadarPreset, run_gorshkov
from radarviz.core.scenarios.multi_radar import fusion_scenario
from radarviz.core.scenarios.planar import prosov_target
from radarviz.core.velocity.estimate import M_WARN
from radarviz.viz_app.reports.gorshkov import check_gorshkov_result
from radarviz.viz_app.reports.prosov import check_tracking_result
from radarviz.viz_app.rerun import gorshkov_scene, velocity_scene
from radarviz.viz_app.rerun import prosov_scene as prosov_views
from radarviz.viz_app.tune.params import TuneParams

#: Finite-memory Monte Carlo trials per panel run (the fits are cheap; σ's χ² band ∝ 1/√M).
GORSHKOV_TRIALS_PER_RUN = 10
#: Converted points per scan behind each Prosov cloud mean the panel draws, and points shown.
TUNE_CLOUD_POINTS = 400
TUNE_CLOUD_SHOWN = 100
#: The panel's radar in the Gorshkov scene.
PANEL_RADAR = "panel"
#: NEES this many times outside its 95% band is flagged (a covariance not to be believed).
NEES_ALERT_FACTOR = 2.0


@dataclass(frozen=True)
class TuneResult:
    """One run of the panel: its parameters and what the chosen scene computed."""

    params: TuneParams
    prosov: ProsovScene | None = None
    gorshkov: GorshkovResult | None = None
    tracking: DopplerTrackingResult | None = None
    velocity: VelocityScans | None = None
    figures: dict[str, float] = field(default_factory=dict)
    alerts: tuple[str, ...] = ()

    @property
    def scene(self) -> ProsovScene:
        """The Prosov scene (for callers of the Prosov-only panel)."""
        if self.prosov is None:
            raise AttributeError("this run is not a Prosov run")
        return self.prosov


def panel_radar(p: TuneParams) -> RadarPreset:
    return RadarPreset(PANEL_RADAR, "panel", p.sigma_r_m, p.sigma_vr_mps, p.period_s)


def simulate(p: TuneParams) -> TuneResult:
    """Run the chosen scene of ``p`` (core only: nothing is logged)."""
    if p.scene == "prosov":
        cfg = TrackingConfig(
            sigma_r_m=p.sigma_r_m,
            sigma_beta_deg=p.sigma_beta_deg,
            runs=p.runs,
            seed=p.seed,
            target=prosov_target(p.period_s, p.steps),
            methods=p.methods,
        )
        scene = prosov_scene(cfg)
        check_tracking_result("tune prosov", scene.result)
        figures, alerts = _prosov_summary(scene)
        return TuneResult(p, prosov=scene, figures=figures, alerts=alerts)
    if p.scene == "gorshkov":
        radar = panel_radar(p)
        result = run_gorshkov([radar], trials=GORSHKOV_TRIALS_PER_RUN * p.runs, seed=p.seed)
        tracking = run_doppler_tracking(
            DopplerTrackingConfig(
                radar=radar,
                sigma_beta_deg=p.sigma_beta_deg,
                runs=p.runs,
                seed=p.seed,
                steps=max(p.steps, 4),
            )
        )
        check_gorshkov_result("tune gorshkov", result, tracking)
        figures, alerts = _gorshkov_summary(p, result, tracking)
        return TuneResult(p, gorshkov=result, tracking=tracking, figures=figures, alerts=alerts)
    scenario = fusion_scenario(
        p.period_s,
        sigma_r_m=p.sigma_r_m,
        # The panel's one σβ is every radar's azimuth and elevation noise.
        sigma_beta_rad=float(np.deg2rad(p.sigma_beta_deg)),
        sigma_elevation_rad=float(np.deg2rad(p.sigma_beta_deg)),
        sigma_vr_mps=p.sigma_vr_mps,
    )
    run = estimate_scans(scenario, p.steps, p.seed)
    figures, alerts = _velocity_summary(run)
    return TuneResult(p, velocity=run, figures=figures, alerts=alerts)


def log_result(rec: rr.RecordingStream, result: TuneResult, series: bool = True) -> None:
    """Log the run's scene with the viewer's scene module (no blueprint); ``series``: with
    the statistics' values under ``plots/``, which no view draws (the charts show them)."""
    if result.prosov is not None:
        prosov_views.log_scene(
            rec, result.prosov, TUNE_CLOUD_POINTS, TUNE_CLOUD_SHOWN, series=series
        )
    elif result.gorshkov is not None and result.tracking is not None:
        gorshkov_scene.log_gorshkov_results(
            rec, result.gorshkov, result.tracking, analytic=True, series=series
        )
    elif result.velocity is not None:
        velocity_scene.log_velocity_run(rec, result.velocity, series=series)


# --- headline figures ------------------------------------------------------------------------


#: Figures that are a NEES, a σ, an RMSE, a window length, m or a count: never negative
#: (".name": that figure of every method or variant). Biases and gains may be negative.
NONNEGATIVE_FIGURES = (
    ".nees_pos",
    "nees_band95_lo",
    "nees_band95_hi",
    "sigma_vr_mps",
    "peak_range_gain_k",
    "peak_range_gain_mc_k",
    "k_range_only_beats_doppler",
    ".rmse_vr_mps",
    "flagged_scans",
    "sigma_vx_mps",
    "sigma_vy_mps",
    "sigma_vz_mps",
    "m",
    "scan",
)


def _finite(scene: str, d: dict[str, float]) -> dict[str, float]:
    """The figures as floats, each a finite number (``core.finite.check_finite_figures``)."""
    figures = {k: float(v) for k, v in d.items()}
    check_finite_figures(f"tune {scene}", figures, NONNEGATIVE_FIGURES)
    return figures


def _prosov_summary(scene: ProsovScene) -> tuple[dict[str, float], tuple[str, ...]]:
    """Range bias (m) and position NEES at the last scan per method; alerts for a NEES
    ``NEES_ALERT_FACTOR`` times above (or below) its 95% band."""
    lo, hi = scene.result.nees_pos_band95
    figures: dict[str, float] = {"nees_band95_lo": lo, "nees_band95_hi": hi}
    alerts = []
    for name, m in scene.result.metrics.items():
        nees = float(m.nees_pos[-1])
        figures[f"{name}.bias_range_m"] = float(m.bias_range_m[-1])
        figures[f"{name}.nees_pos"] = nees
        if nees > NEES_ALERT_FACTOR * hi or nees < lo / NEES_ALERT_FACTOR:
            alerts.append(
                f"{name}: NEES {nees:.3g} is far outside its 95% band [{lo:.2f}, {hi:.2f}]: "
                "its covariance is not credible"
            )
    return _finite("prosov", figures), tuple(alerts)


def _gorshkov_summary(
    p: TuneParams, result: GorshkovResult, tracking: DopplerTrackingResult
) -> tuple[dict[str, float], tuple[str, ...]]:
    """The peak range gain (analytic, and Monte Carlo with its band) and its k; the first k
    where the range-only σVr falls below the Doppler σVr; the Doppler start's Vr RMSE at the
    last scan, both variants."""
    rad = result.radars[0]
    ks = result.ks
    gain = rad.gain_analytic[:, 0]
    i = int(np.nanargmax(gain))
    figures: dict[str, float] = {
        "sigma_vr_mps": p.sigma_vr_mps,
        "peak_range_gain_percent": float(gain[i]),
        "peak_range_gain_k": float(ks[i]),
    }
    mc = rad.gain_mc[:, 0]
    if np.isfinite(mc).any():
        j = int(np.nanargmax(mc))
        figures["peak_range_gain_mc_percent"] = float(mc[j])
        figures["peak_range_gain_mc_lo"] = float(rad.gain_mc_ci95_lo[j, 0])
        figures["peak_range_gain_mc_hi"] = float(rad.gain_mc_ci95_hi[j, 0])
        figures["peak_range_gain_mc_k"] = float(ks[j])
    below = np.flatnonzero(rad.range_only.sigma_analytic[:, 1] < p.sigma_vr_mps)
    if below.size:
        figures["k_range_only_beats_doppler"] = float(ks[below[0]])
    for var, rmse in tracking.rmse_vr_mps.items():
        figures[f"{var}.rmse_vr_mps"] = float(rmse[-1])
    return _finite("gorshkov", figures), ()


def _velocity_summary(run: VelocityScans) -> tuple[dict[str, float], tuple[str, ...]]:
    """σ of Vx, Vy, Vz (first order) and the geometry metric m at the last scan with an
    estimate; the number of flagged scans."""
    ok = np.flatnonzero(np.isfinite(run.m))
    figures: dict[str, float] = {"flagged_scans": float(run.flagged.sum())}
    alerts = []
    if ok.size:
        last = int(ok[-1])
        for a, axis in enumerate(("vx", "vy", "vz")):
            figures[f"sigma_{axis}_mps"] = float(np.sqrt(run.covariance[last, a, a]))
        figures["m"] = float(run.m[last])
        figures["scan"] = float(run.n[last])
        if run.flagged[last]:
            alerts.append(
                f"geometry metric m = {run.m[last]:.3g} above {M_WARN:g} at scan {run.n[last]}: "
                "the velocity ellipsoid is not to be trusted"
            )
    if run.flagged.any():
        alerts.append(f"{int(run.flagged.sum())} of {len(run.n)} scans flagged (m > {M_WARN:g})")
    return _finite("velocity", figures), tuple(alerts)


def status_lines(result: TuneResult) -> list[str]:
    """The scene's headline figures as markdown blocks (alerts first, a bold list), each
    element a paragraph, a list item or a table row."""
    f = result.figures
    p = result.params
    lines = [f"- **⚠ {a}**" for a in result.alerts]
    if lines:
        lines.append("")
    if result.prosov is not None:
        lines += ["| method | range bias (m) | NEES pos |", "|---|---:|---:|"]
        for m in result.prosov.result.metrics:
            nees = f.get(f"{m}.nees_pos")
            mark = " ⚠" if any(a.startswith(f"{m}:") for a in result.alerts) else ""
            lines.append(
                f"| {m} | {f.get(f'{m}.bias_range_m', float('nan')):.1f} | {nees:.3g}{mark} |"
                if nees is not None
                else f"| {m} | - | - |"
            )
        lines += [
            "",
            f"last scan; NEES 95% band [{f['nees_band95_lo']:.2f}, {f['nees_band95_hi']:.2f}]",
        ]
    elif result.gorshkov is not None:
        lines.append(f"σVr = {p.sigma_vr_mps:.4g} m/s (C0 = {p.c0:.4g})")
        lines.append(
            f"peak range gain K = {f['peak_range_gain_percent']:.1f}% at k = "
            f"{f['peak_range_gain_k']:.0f} (analytic)"
        )
        if "peak_range_gain_mc_percent" in f:
            lines.append(
                f"Monte Carlo: {f['peak_range_gain_mc_percent']:.1f}% "
                f"[{f['peak_range_gain_mc_lo']:.1f}, {f['peak_range_gain_mc_hi']:.1f}] at k = "
                f"{f['peak_range_gain_mc_k']:.0f} ({GORSHKOV_TRIALS_PER_RUN * p.runs} trials)"
            )
        k_star = f.get("k_range_only_beats_doppler")
        lines.append(
            f"range-only σVr falls below σVr at k = {k_star:.0f}"
            if k_star is not None
            else f"range-only σVr stays above σVr for k ≤ {int(result.gorshkov.ks[-1])}"
        )
        rd, ro = f.get("range_doppler.rmse_vr_mps"), f.get("range_only.rmse_vr_mps")
        if rd is not None and ro is not None:
            lines.append(
                f"Doppler start, Vr RMSE at the last scan: {rd:.3g} m/s (range + Doppler) vs "
                f"{ro:.3g} m/s (range only)"
            )
    elif result.velocity is not None:
        if "m" in f:
            lines.append(
                f"scan {f['scan']:.0f}: σ Vx {f['sigma_vx_mps']:.3g}, σ Vy {f['sigma_vy_mps']:.3g}"
                f", σ Vz {f['sigma_vz_mps']:.3g} m/s; geometry m = {f['m']:.3g} "
                f"(warning above {M_WARN:g})"
            )
        lines.append(f"σVr = {p.sigma_vr_mps:.4g} m/s (C0 = {p.c0:.4g})")
    return lines
