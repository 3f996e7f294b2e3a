"""The papers' experiments and estimators as functions of plain values.

Every function validates its arguments once, by the core configuration or estimator it calls
(bounds in ``radarviz.core.params``); a bad value raises
:class:`radarviz.core.params.ParameterError` naming the parameter and its allowed range.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.conversion.planar import METHODS_2D, Converted
from radarviz.core.conversion.planar import convert as _convert
from radarviz.core.experiments.doppler_start import (
    DopplerTrackingConfig,
    DopplerTrackingResult,
    run_doppler_tracking,
)
from radarviz.core.experiments.prosov import (
    ALL_METHODS,
    TrackingResult,
    prosov_configs,
    run_tracking,
)
from radarviz.core.finite_memory.fit import (
    PRESETS,
    FiniteMemoryFit,
    GorshkovResult,
    RadarPreset,
    finite_memory_fit,
)
from radarviz.core.finite_memory.fit import preset as _preset
from radarviz.core.finite_memory.fit import run_gorshkov as _run_gorshkov
from radarviz.core.geometry import direction_cosines as _direction_cosines
from radarviz.core.params import (
    ParameterError,
    check,
    check_choice,
    check_int,
    check_reals,
    default,
    parameter,
)
from radarviz.core.velocity.estimate import (
    VelocityEstimate,
    VelocityExperiment,
    run_velocity_experiment,
)
from radarviz.core.velocity.estimate import estimate_velocity as _estimate_velocity

#: Called as ``progress(done, total)`` while a Monte Carlo runs.
Progress = Callable[[int, int], None]


def convert(
    method: str,
    range_m: ArrayLike,
    azimuth_rad: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    predicted_xy_m: ArrayLike | None = None,
) -> Converted:
    """Convert polar radar measurements to a Cartesian point and its covariance.

    Args:
        method: one of ``naive``, ``seed``, ``cmkf_d``, ``ucm``, ``ducm``
            (``docs/conversion.md``).
        range_m: measured ranges r̂, shape (...,), m.
        azimuth_rad: measured azimuths β̂, shape (...,), rad.
        sigma_r_m: range noise σr, scalar or (...,), m.
        sigma_beta_rad: azimuth noise σβ, scalar or (...,), rad.
        predicted_xy_m: the filter's predicted position, shape (..., 2), m; ``ducm`` only
            (its covariance is evaluated there).

    Returns:
        ``Converted``: ``z`` the converted points (..., 2) in m and ``R`` their covariances
        (..., 2, 2) in m².

    Raises:
        ParameterError: an unknown method, or a value outside its range (the bounds of
            ``radarviz track``'s plots: range (0, 10⁸] m, σr [10⁻³, 10⁵] m, σβ within the
            σβ bounds of ``sigma_beta_deg``, in rad; every value finite).
    """
    check_choice("method", method, METHODS_2D)
    r = parameter("range_m").check_all(range_m)
    sigma_r_m = parameter("sigma_r_m").check_all(sigma_r_m)
    beta = parameter("sigma_beta_deg")  # the σβ bounds, here in rad
    sigma_beta_rad = check_reals(
        "sigma_beta_rad",
        sigma_beta_rad,
        low=math.radians(beta.low),
        high=math.radians(beta.high),
        low_open=beta.low_open,
    )
    az = check_reals("azimuth_rad", azimuth_rad)
    xy = None if predicted_xy_m is None else check_reals("predicted_xy_m", predicted_xy_m)
    if method == "ducm" and xy is None:
        raise ParameterError("predicted_xy_m is needed by ducm (its R is at the prediction)")
    return _convert(
        method,
        r,
        az,
        sigma_r_m=sigma_r_m,
        sigma_beta_rad=sigma_beta_rad,
        predicted_xy=xy,
    )


def run_prosov(
    sigma_beta_deg: float | Sequence[float] = (1.0, 2.0),
    *,
    runs: int = default("runs"),
    seed: int = default("seed"),
    period_s: float = default("period_s"),
    steps: int = default("steps"),
    sigma_r_m: float = default("sigma_r_m"),
    methods: Sequence[str] = ALL_METHODS,
    dims: int = 2,
    elevation_deg: float = default("target_elevation_deg"),
    sigma_elevation_deg: float | None = None,
    progress: Callable[[float], Progress | None] | None = None,
) -> list[TrackingResult]:
    """Prosov's Monte Carlo: every converted-measurement filter on the same measurements.

    One radar at the origin, a target at 150 km moving radially outward at 200 m/s; each
    method is a constant-velocity Kalman filter started from the first converted point.
    ``dims=3`` runs the same range and radial motion at an elevation, every method in its 3D
    form, with 3D metrics (bias along the line of sight, NEES with 3 and 6 degrees of freedom).

    Args:
        sigma_beta_deg: azimuth noise σβ, degrees; one case per value (the paper: 1 and 2).
        runs: Monte Carlo runs M per case.
        seed: root seed; the same seed gives the same numbers bit for bit.
        period_s: scan period T, s.
        steps: scans N per run.
        sigma_r_m: range noise σr, m.
        methods: filters to run, from ``ALL_METHODS``.
        dims: 2 (the paper's plane) or 3.
        elevation_deg: the target's elevation, degrees (``dims=3`` only).
        sigma_elevation_deg: elevation noise σε, degrees (``dims=3`` only; required there).
        progress: given a case's σβ (degrees), returns the ``progress(done, total)`` callback
            of that case's Monte Carlo (or None).

    Returns:
        One ``TrackingResult`` per σβ: per-scan (N,) bias, RMSE, NEES and their 95% bands for
        every method (``to_table`` turns it into a table).
    """
    values = [sigma_beta_deg] if isinstance(sigma_beta_deg, int | float) else sigma_beta_deg
    for m in methods:
        if m not in ALL_METHODS:
            raise ParameterError(
                f"methods must be among {', '.join(ALL_METHODS)} (got {m!r})", "methods"
            )
    configs = prosov_configs(
        sigma_beta_deg=values,
        runs=runs,
        seed=seed,
        period_s=period_s,
        steps=steps,
        sigma_r_m=sigma_r_m,
        methods=methods,
        dims=dims,
        elevation_deg=elevation_deg,
        sigma_elevation_deg=sigma_elevation_deg,
    )
    return [
        run_tracking(cfg, progress=None if progress is None else progress(cfg.sigma_beta_deg))
        for cfg in configs
    ]


class GorshkovRun(NamedTuple):
    """The finite-memory experiment and, if asked, its Doppler track-start comparison.

    Attributes:
        fits: the window-length curves of every radar preset (``GorshkovResult``).
        tracking: the Doppler-aided track start's Monte Carlo, or None when skipped.
    """

    fits: GorshkovResult
    tracking: DopplerTrackingResult | None


def run_gorshkov(
    radars: Iterable[RadarPreset | str] | None = None,
    *,
    trials: int = default("trials"),
    seed: int = default("seed"),
    k_max: int = 20,
    tracking_radar: str = "RLS3",
    tracking_runs: int = 1000,
    sigma_beta_deg: float = default("sigma_beta_deg"),
) -> GorshkovRun:
    """Gorshkov and Zavizhenets' sliding-window least squares, Monte Carlo against analysis.

    Args:
        radars: presets (``RadarPreset`` or names ``RLS1`` … ``RLS6``; default all six).
        trials: Monte Carlo trials per radar.
        seed: root seed.
        k_max: largest window length k, 1 … 20.
        tracking_radar: preset of the Doppler-aided track-start comparison.
        tracking_runs: runs of that comparison (0 skips it, otherwise ≥ 2).
        sigma_beta_deg: azimuth noise σβ of the comparison, degrees.

    Returns:
        ``GorshkovRun``: per radar and k = 1 … k_max the analytic and Monte Carlo σ of range
        (m), radial velocity (m/s) and acceleration (m/s²), range only and with Doppler.
    """
    k_max = check_int("k_max", k_max, low=1, high=20)
    names = list(PRESETS) if radars is None else list(radars)
    for r in names:
        if isinstance(r, str) and r not in PRESETS:
            raise ParameterError(f"radars must be among {', '.join(PRESETS)} (got {r!r})", "radars")
    if tracking_radar not in PRESETS:
        raise ParameterError(
            f"tracking_radar must be one of {', '.join(PRESETS)} (got {tracking_radar!r})",
            "tracking_radar",
        )
    check_int("tracking_runs", tracking_runs, low=0)
    if tracking_runs == 1:
        raise ParameterError(
            "tracking_runs must be 0 (skip) or an integer >= 2 (got 1)", "tracking_runs"
        )
    # Built (and so checked) before the long Monte Carlo; σβ is checked even when skipped.
    config = None
    if tracking_runs:
        config = DopplerTrackingConfig(
            radar=tracking_radar, sigma_beta_deg=sigma_beta_deg, runs=tracking_runs, seed=seed
        )
    else:
        check("sigma_beta_deg", sigma_beta_deg)
    fits = _run_gorshkov(names, trials=trials, seed=seed, ks=range(1, k_max + 1))
    return GorshkovRun(fits, None if config is None else run_doppler_tracking(config))


def finite_memory(
    k: int,
    *,
    sigma_r_m: float,
    sigma_vr_mps: float | None,
    period_s: float,
    with_doppler: bool = True,
) -> FiniteMemoryFit:
    """The finite-memory fit of the last k scans: its covariance R and weights W.

    Args:
        k: window length, scans (≥ 1; below the number of parameters the fit drops order).
        sigma_r_m: range noise σr, m.
        sigma_vr_mps: radial-velocity noise σVr, m/s (ignored, may be None, range only).
        period_s: scan period T, s.
        with_doppler: fit ranges and radial velocities (True) or ranges only.

    Returns:
        ``FiniteMemoryFit``: ``R`` (n, n) the covariance of (r, Vr, a) in m², m²/s, …, ``W``
        the weights, (n, k) range only or (n, 2k) with Doppler, ``sigma`` the (n,) standard
        deviations; n ≤ 3 is the order the window allows.
    """
    return finite_memory_fit(
        k,
        sigma_r_m=sigma_r_m,
        sigma_vr_mps=sigma_vr_mps,
        period_s=period_s,
        with_doppler=with_doppler,
    )


def radar_preset(preset: str) -> RadarPreset:
    """One radar of the finite-memory paper's table, for ``finite_memory`` or ``run_gorshkov``.

    Args:
        preset: ``RLS1`` … ``RLS6``.

    Returns:
        ``RadarPreset``: ``name``, ``band``, ``sigma_r_m`` (m), ``sigma_vr_mps`` (m/s) and
        ``period_s`` (s), e.g. ``finite_memory(5, sigma_r_m=p.sigma_r_m, …)``.

    Raises:
        ParameterError: an unknown name (the message lists the known ones).
    """
    return _preset(preset)


def direction_cosines(azimuth_rad: ArrayLike, elevation_rad: ArrayLike) -> NDArray[np.float64]:
    """The unit vectors u = (cos ε cos β, cos ε sin β, sin ε) from a site towards a target.

    The radial velocity a radar measures is u · v, so ``direction_cosines(az, el) @ v`` gives
    the noise-free Vr of a velocity v (3,) seen from N sites: the truth ``estimate_velocity``
    inverts.

    Args:
        azimuth_rad: azimuths β, shape (...,), rad (from x towards y).
        elevation_rad: elevations ε, shape (...,) (broadcast with ``azimuth_rad``), rad.

    Returns:
        Unit vectors, shape (..., 3).

    Raises:
        ParameterError: a value that is not a finite number.
    """
    return _direction_cosines(
        check_reals("azimuth_rad", azimuth_rad), check_reals("elevation_rad", elevation_rad)
    )


def estimate_velocity(
    sites_m: ArrayLike,
    radial_velocity_mps: ArrayLike,
    azimuth_rad: ArrayLike,
    elevation_rad: ArrayLike,
    *,
    sigma_vr_mps: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> VelocityEstimate:
    """The full velocity vector from N ≥ 3 radars' radial velocities.

    Args:
        sites_m: radar sites, shape (N, 3), m.
        radial_velocity_mps: measured radial velocities Vr, shape (N,), m/s.
        azimuth_rad: measured azimuths β of the target from each site, shape (N,), rad.
        elevation_rad: measured elevations ε, shape (N,), rad.
        sigma_vr_mps: radial-velocity noise, scalar or (N,), m/s.
        sigma_beta_rad: azimuth noise, scalar or (N,), rad.
        sigma_elevation_rad: elevation noise, scalar or (N,), rad.

    Returns:
        ``VelocityEstimate``: the velocity (3,) in m/s, its first-order covariance (3, 3) in
        m²/s², the condition number of the direction cosines, the geometry metric m and a
        warning when m > 0.2.

    Raises:
        GeometryError: fewer than 3 distinct sites or coplanar lines of sight.
    """
    return _estimate_velocity(
        sites_m,
        radial_velocity_mps,
        azimuth_rad,
        elevation_rad,
        sigma_vr_mps=sigma_vr_mps,
        sigma_beta_rad=sigma_beta_rad,
        sigma_elevation_rad=sigma_elevation_rad,
    )


def run_velocity(trials: int = 200_000, seed: int = default("seed")) -> VelocityExperiment:
    """The velocity experiment: the three-radar baseline and the distance/altitude sweep.

    Args:
        trials: Monte Carlo trials of the baseline (the sweep uses at most 20 000 a point).
        seed: root seed.

    Returns:
        ``VelocityExperiment``: first-order and Monte Carlo σ (m/s), biases and the sweep.
    """
    return run_velocity_experiment(trials, seed)
