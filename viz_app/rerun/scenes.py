"""What each recording preset shows: core runs, then the logging calls, top to bottom."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import rerun as rr

from radarviz.core.experiments.doppler_start import DopplerTrackingConfig, run_doppler_tracking
from radarviz.core.experiments.prosov import (
    SHOWN_CONVERSIONS,
    ProsovScene,
    TrackingConfig,
    conversion_cloud,
    prosov_scene,
)
from radarviz.core.finite_memory.fit import run_gorshkov
from radarviz.core.scenarios.multi_radar import (
    SIGMA_FIELDS,
    fusion_scenario,
    generate_measurements,
)
from radarviz.core.velocity.estimate import (
    M_WARN,
    GeometryError,
    estimate_velocity,
    fuse_positions,
)
from radarviz.viz_app.rerun.recording import (
    colour,
    default_blueprint,
    log_cloud,
    log_points,
    log_radar_site,
    log_series,
    log_text,
    log_track,
    log_truth,
    log_velocity,
)

PROSOV_SERIES = ("bias_range", "rmse_x", "sigma_x_filter", "nees_pos", "delta_x")
#: The per-scan statistics ``log_prosov`` draws, each at ``plots/<metric>/<method>``.
PROSOV_METRICS = ("bias_range", "rmse_x", "sigma_x_filter", "nees_pos")


def log_scene_run(rec: rr.RecordingStream, scene: ProsovScene) -> None:
    """The scene's displayed run: truth, its measurements (naive points) and one track per
    method, at ``world/truth``, ``world/measurements/radar`` and ``world/tracks/<method>``."""
    scans = np.arange(1, len(scene.times_s) + 1)
    times = scene.times_s
    log_truth(rec, scans, times, scene.truth[:, [0, 2]])
    log_points(
        rec,
        "world/measurements/radar",
        scans,
        times,
        scene.converted_xy_m["naive"],
        (0, 0, 0),
        radius=150.0,
    )
    for method, track in scene.tracks.items():
        log_track(rec, method, scans, times, track.x, track.P, scene.config.target.period_s)


def log_scene_series(rec: rr.RecordingStream, scene: ProsovScene, metrics: Sequence[str]) -> None:
    """Each method's per-scan ``metrics`` at ``plots/<metric>/<method>``; with ``nees_pos``
    also its 95% band at ``plots/nees_pos/band95_lo`` and ``band95_hi``."""
    times = scene.times_s
    scans = np.arange(1, len(times) + 1)
    for name, m in scene.result.metrics.items():
        rgb = colour(name)
        for metric in metrics:
            log_series(rec, f"plots/{metric}/{name}", scans, times, getattr(m, metric), rgb, name)
    if "nees_pos" in metrics:
        for tag, v in zip(("lo", "hi"), scene.result.nees_pos_band95, strict=True):
            log_series(
                rec,
                f"plots/nees_pos/band95_{tag}",
                scans,
                times,
                np.full(len(scans), v),
                (160, 160, 160),
                "95% band",
            )


def scene_figures(scene: ProsovScene) -> dict[str, float]:
    """Key figures for status lines: bias in range (m) and position NEES at the last scan."""
    metrics = scene.result.metrics
    return {
        **{f"{n}.bias_range_m": float(m.bias_range[-1]) for n, m in metrics.items()},
        **{f"{n}.nees_pos": float(m.nees_pos[-1]) for n, m in metrics.items()},
    }


def log_prosov(
    rec: rr.RecordingStream,
    sigma_beta_deg: float = 2.0,
    runs: int = 500,
    seed: int = 1,
    cloud_points: int = 2000,
) -> dict[str, float]:
    """The Prosov scene (``core.experiments.prosov.prosov_scene``): one radar, truth, the
    displayed run's converted points and tracks per method, MC statistics and the cloud.

    Returns the key figures (bias and NEES at the last scan per method) for status lines.
    """
    cfg = TrackingConfig(sigma_beta_deg=sigma_beta_deg, runs=runs, seed=seed)
    scene = prosov_scene(cfg)
    result = scene.result
    times = scene.times_s
    scans = np.arange(1, len(times) + 1)

    log_radar_site(
        rec,
        "radar",
        (0.0, 0.0, 0.0),
        f"radar  σr = {cfg.sigma_r_m:g} m, σβ = {cfg.sigma_beta_deg:g}°",
    )
    log_scene_run(rec, scene)
    for method in SHOWN_CONVERSIONS:
        if method != "naive":  # the naive points are the measurements
            log_points(
                rec,
                f"world/converted/{method}",
                scans,
                times,
                scene.converted_xy_m[method],
                colour(method),
                radius=150.0,
            )
    for method, points in conversion_cloud(cfg, cloud_points).items():
        log_cloud(rec, method, points, scene.truth[0, [0, 2]])

    log_scene_series(rec, scene, PROSOV_METRICS)
    lo, hi = result.nees_pos_band95
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
    return scene_figures(scene)


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


def log_fusion(rec: rr.RecordingStream, seed: int = 1, scans: int = 60) -> None:
    """Several radars, one target: fused position and the full velocity vector per scan.

    Each scan the radars' (r, β, ε) are fused into one position and their radial velocities
    give the velocity vector (``core.velocity.estimate``); its 1σ ellipsoid is drawn unless the
    geometry metric m says the linear statistics do not hold, which goes to the text log.
    """
    scenario = fusion_scenario()
    period = scenario.radars[0].period_s
    meas = generate_measurements(scenario, (scans - 1) * period, seed=seed)
    radars = scenario.radars
    sites = np.array([r.position for r in radars])
    first = meas[radars[0].name]
    n = np.arange(1, len(first.t) + 1)
    t = first.t
    for r in radars:
        log_radar_site(
            rec,
            r.name,
            r.position,
            f"{r.name}  σr {r.sigma_r_m:g} m, σβ {np.rad2deg(r.sigma_azimuth_rad):g}°, "
            f"σε {np.rad2deg(r.sigma_elevation_rad):g}°, σVr {r.sigma_vr_mps:g} m/s, "
            f"T {r.period_s:g} s",
        )
    log_truth(rec, n, t, first.true_position, root="world/fusion/truth")
    stack = {
        k: np.stack([meas[r.name].__dict__[k] for r in radars], axis=-1)
        for k in ("range", "azimuth", "elevation", "radial_velocity")
    }
    sig = {k: np.array([getattr(r, k) for r in radars]) for k in SIGMA_FIELDS}
    angle_sigmas = {k: sig[k] for k in ("sigma_azimuth_rad", "sigma_elevation_rad")}
    fused = fuse_positions(
        sites,
        stack["range"],
        stack["azimuth"],
        stack["elevation"],
        sigma_r_m=sig["sigma_r_m"],
        **angle_sigmas,
    )
    for k, r in enumerate(radars):
        log_points(
            rec,
            f"world/fusion/measurements/{r.name}",
            n,
            t,
            fused.points[:, k],
            (90, 90, 90),
            radius=150.0,
        )
    vel = np.full((len(n), 3), np.nan)
    cov = np.full((len(n), 3, 3), np.nan)
    m = np.full(len(n), np.nan)
    for i in range(len(n)):
        try:
            est = estimate_velocity(
                sites,
                stack["radial_velocity"][i],
                stack["azimuth"][i],
                stack["elevation"][i],
                sigma_vr_mps=sig["sigma_vr_mps"],
                **angle_sigmas,
            )
        except GeometryError as exc:
            log_text(rec, f"velocity at scan {n[i]}: {exc}", level="WARN", scan=int(n[i]))
            continue
        m[i] = est.m
        if est.warning:
            log_text(rec, f"velocity at scan {n[i]}: {est.warning}", level="WARN", scan=int(n[i]))
            continue
        vel[i], cov[i] = est.velocity, est.covariance
    log_velocity(rec, n, t, fused.position, fused.covariance, vel, cov, period)
    err = vel - first.true_velocity
    for j, axis in enumerate(("vx", "vy", "vz")):
        log_series(
            rec,
            f"plots/fused_velocity/error_{axis}",
            n,
            t,
            err[:, j],
            None,
            f"V̂{axis[1]} − V{axis[1]}",
        )
        log_series(
            rec,
            f"plots/fused_velocity/sigma_{axis}",
            n,
            t,
            np.sqrt(cov[:, j, j]),
            None,
            f"σ {axis}",
        )
    log_series(rec, "plots/fused_velocity/m", n, t, m, None, "geometry metric m")
    log_series(
        rec,
        "plots/fused_velocity/m_warn",
        n,
        t,
        np.full(len(n), M_WARN),
        (160, 160, 160),
        "m warning level",
    )
    log_text(rec, f"velocity fusion: {len(radars)} radars, {len(n)} scans, seed {seed}")


def record_preset(rec: rr.RecordingStream, preset: str, seed: int = 1) -> None:
    """Fill ``rec`` with one of the presets (the demo combines them) and send its blueprint."""
    if preset in ("demo", "prosov"):
        log_prosov(rec, seed=seed)
    if preset in ("demo", "gorshkov"):
        log_gorshkov(rec, seed=seed)
    if preset in ("demo", "velocity"):
        log_fusion(rec, seed=seed)
    series: tuple[str, ...] = {
        "demo": ("rmse_x", "nees_pos", "delta_x", "finite_memory/gain_r", "fused_velocity"),
        "prosov": PROSOV_SERIES,
        "gorshkov": ("finite_memory/gain_r", "finite_memory/sigma_vr", "doppler_start/rmse_vr"),
        "velocity": ("fused_velocity",),
    }[preset]
    centre, extent = ((40e3, 30e3, 0.0), 150e3) if preset == "velocity" else ((120e3, 0, 0), 300e3)
    rec.send_blueprint(default_blueprint(series, centre=centre, extent_m=extent))
