"""What each recording preset shows: core runs, then the logging calls, top to bottom."""

from __future__ import annotations

import numpy as np
import rerun as rr

from core.conversion import convert_parts
from core.doppler_tracking import DopplerTrackingConfig, run_doppler_tracking
from core.finite_memory import run_gorshkov
from core.prosov import TrackingConfig, run_tracking, track_history
from core.scenario import polar_measurements
from viz_app.recording import (
    colour,
    default_blueprint,
    log_cloud,
    log_points,
    log_radar_site,
    log_series,
    log_text,
    log_track,
    log_truth,
)

PROSOV_SERIES = ("bias_range", "rmse_x", "sigma_x_filter", "nees_pos", "delta_x")


def log_prosov(
    rec: rr.RecordingStream,
    sigma_beta_deg: float = 2.0,
    runs: int = 500,
    seed: int = 1,
    cloud_points: int = 2000,
) -> dict[str, float]:
    """The Prosov scene: one radar, truth, one run's tracks per method, MC statistics and cloud.

    Returns the key figures (bias and NEES at the last scan per method) for status lines.
    """
    cfg = TrackingConfig(sigma_beta_deg=sigma_beta_deg, runs=runs, seed=seed)
    result = run_tracking(cfg)
    target = cfg.target
    truth = target.truth()
    scans = np.arange(1, target.steps + 1)
    times = (scans - 1) * target.period_s
    sr, sb = cfg.sigma_r_m, cfg.sigma_beta_rad

    log_radar_site(
        rec, "radar", (0.0, 0.0, 0.0), f"radar  σr = {sr:g} m, σβ = {cfg.sigma_beta_deg:g}°"
    )
    log_truth(rec, scans, times, truth[:, [0, 2]])

    # One displayed run (its own seed stream, so it does not depend on ``runs``).
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7]))
    r_hat, b_hat = polar_measurements(truth, sr, sb, 1, rng)
    naive = convert_parts("naive", r_hat[0], b_hat[0], sr, sb)
    log_points(
        rec,
        "world/measurements/radar",
        scans,
        times,
        np.stack([naive.x, naive.y], -1),
        (0, 0, 0),
        radius=150.0,
    )
    for method in ("seed", "cmkf_d", "ucm"):
        c = convert_parts(method, r_hat[0], b_hat[0], sr, sb)
        log_points(
            rec,
            f"world/converted/{method}",
            scans,
            times,
            np.stack([c.x, c.y], -1),
            colour(method),
            radius=150.0,
        )
    for method in cfg.methods:
        xs, ps = track_history(method, r_hat, b_hat, cfg)
        log_track(rec, method, scans, times, xs[0], ps[0], target.period_s)

    # Monte Carlo cloud of converted points at the first scan.
    rng = np.random.default_rng(np.random.SeedSequence([seed, 11]))
    r_c, b_c = polar_measurements(truth[:1], sr, sb, cloud_points, rng)
    for method in ("naive", "seed", "cmkf_d", "ucm"):
        c = convert_parts(method, r_c[:, 0], b_c[:, 0], sr, sb)
        log_cloud(rec, method, np.stack([c.x, c.y], -1), truth[0, [0, 2]])

    for name, m in result.metrics.items():
        rgb = colour(name)
        log_series(rec, f"plots/bias_range/{name}", scans, times, m.bias_range, rgb, name)
        log_series(rec, f"plots/rmse_x/{name}", scans, times, m.rmse_x, rgb, name)
        log_series(rec, f"plots/sigma_x_filter/{name}", scans, times, m.sigma_x_filter, rgb, name)
        log_series(rec, f"plots/nees_pos/{name}", scans, times, m.nees_pos, rgb, name)
    lo, hi = result.nees_pos_band95
    log_series(
        rec,
        "plots/nees_pos/band95_lo",
        scans,
        times,
        np.full(len(scans), lo),
        (160, 160, 160),
        "95% band",
    )
    log_series(
        rec,
        "plots/nees_pos/band95_hi",
        scans,
        times,
        np.full(len(scans), hi),
        (160, 160, 160),
        "95% band",
    )
    if "seed" in result.metrics and "naive" in result.metrics:
        for reading, values in result.delta_x_percent().items():
            log_series(rec, f"plots/delta_x/{reading}", scans, times, values, None, f"Δx {reading}")
    log_text(rec, f"Prosov: {runs} Monte Carlo runs, σβ = {sigma_beta_deg:g}°, seed {seed}")
    for name, m in result.metrics.items():
        if m.nees_pos[-1] > 2 * hi:
            log_text(
                rec,
                f"{name}: NEES {m.nees_pos[-1]:.1f} at the last scan, far above the "
                f"95% band [{lo:.2f}, {hi:.2f}]: its covariance is not credible",
                level="WARN",
                scan=int(scans[-1]),
            )
    return {
        **{f"{n}.bias_range_m": float(m.bias_range[-1]) for n, m in result.metrics.items()},
        **{f"{n}.nees_pos": float(m.nees_pos[-1]) for n, m in result.metrics.items()},
    }


def log_gorshkov(
    rec: rr.RecordingStream, trials: int = 20_000, seed: int = 1, tracking_runs: int = 300
) -> None:
    """Finite-memory σ and gains against k (on the ``scan`` timeline: k scans in the window),
    and the Doppler-aided track start's radial-velocity errors per scan."""
    result = run_gorshkov(None, trials=trials, seed=seed)
    ks = result.ks
    for rad in result.radars:
        name = rad.preset.name
        T = rad.preset.period_s
        for var, stats in (("range_only", rad.range_only), ("range_doppler", rad.range_doppler)):
            for i, comp in enumerate(("r", "vr", "a")):
                log_series(
                    rec,
                    f"plots/finite_memory/sigma_{comp}/{name}/{var}",
                    ks,
                    (ks - 1) * T,
                    stats.sigma_mc[:, i],
                    None,
                    f"{name} {var}",
                )
        for i, comp in enumerate(("r", "vr", "a")):
            log_series(
                rec,
                f"plots/finite_memory/gain_{comp}/{name}",
                ks,
                (ks - 1) * T,
                rad.gain_mc[:, i],
                None,
                name,
            )
    tr = run_doppler_tracking(DopplerTrackingConfig(runs=tracking_runs, seed=seed))
    n = tr.n
    times = (n - 1) * 10.0
    for var in tr.rmse_vr:
        log_series(
            rec, f"plots/doppler_start/rmse_vr/{var}", n, times, tr.rmse_vr[var], colour(var), var
        )
        log_series(
            rec,
            f"plots/doppler_start/sigma_vr_filter/{var}",
            n,
            times,
            tr.sigma_vr_filter[var],
            colour(var),
            f"{var} filter σ",
        )
    log_text(rec, f"Gorshkov: {trials} trials per radar; Doppler start: {tracking_runs} runs")


def record_preset(rec: rr.RecordingStream, preset: str, seed: int = 1) -> None:
    """Fill ``rec`` with one of the presets (the demo combines them) and send its blueprint."""
    if preset in ("demo", "prosov"):
        log_prosov(rec, seed=seed)
    if preset in ("demo", "gorshkov"):
        log_gorshkov(rec, seed=seed)
    series: tuple[str, ...] = PROSOV_SERIES if preset in ("demo", "prosov") else ()
    if preset == "gorshkov":
        series = ("finite_memory/gain_r", "finite_memory/sigma_vr", "doppler_start/rmse_vr")
    rec.send_blueprint(default_blueprint(series, centre=(200e3, 0.0, 0.0), extent_m=250e3))
