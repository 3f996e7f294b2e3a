"""The IMM's consistency in turns: position NEES in the turn segments and RMSE on the
straight legs, with their Monte Carlo uncertainty, for any motion model on two scenes.

* ``"airliner"``: the flights of ``core.scenarios.airliner`` seen by its one radar
  (σr = 50 m, σβ = 0.15°, σε = 0.3°, T = 4.5 s), tracked in 3D (dof 3) or, ``dims=2``, in
  the radar's plane: the same flights' ground-plane range and bearing with the same σr, σβ
  (a 2D radar whose plots were put on the ground by the aircraft's reported altitude),
  tracked in 2D (dof 2).
* ``"manoeuvre"``: the flights and three radars of ``core.scenarios.manoeuvre`` (3D, one
  with Doppler), ``reproduce manoeuvre``'s scene.

Each of M noise runs tracks every flight with the numpy engine's step
(``core.tracking.stream.TrackGroup``; the compiled engine is tested equal to it). After the
first ``burn_in_plots`` plots, a plot is a *turn* plot if it was taken inside a turn leg
(``core.scenarios.airliner.turn_mask``) and a *straight* plot otherwise. Per run m, over its
flights::

    NEES_turn(m)  = mean over turn plots of (x̂ − x)ᵀ P⁻¹ (x̂ − x)   (position only, dof d)
    MSE_str(m)    = mean over straight plots of |x̂ − x|²

The figures are the means over runs (equal counts per run, so the pooled means) with the
standard error of a mean of M independent runs, s/√M (the plots within a run are
correlated; the runs are not); an RMSE's is SE(MSE) / (2 RMSE) (delta method). The ratio of
two models' straight-leg RMSE is taken on the same runs and its standard error from the
per-run differences of their MSEs (paired). ``gate_miss_turn`` is the fraction of turn plots
whose position NIS exceeds the association gate γ = F⁻¹_χ²(d)(0.999): 0.001 for a
consistent filter; a plot outside its track's gate starts a new track.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.chi2 import chi2_quantile
from radarviz.core.filters.measurement import DopplerMeasurement
from radarviz.core.filters.methods import PolarNoise, PolarPlot
from radarviz.core.filters.models import CVModel, IMMModel
from radarviz.core.params import ParameterError, check, check_choice, check_int
from radarviz.core.scenarios.airliner import AIRLINER_FLIGHTS, AIRLINER_RADAR, turn_mask
from radarviz.core.scenarios.manoeuvre import (
    FLIGHTS,
    MANOEUVRE_RADARS,
    Flight,
    ManoeuvrePlots,
    manoeuvre_plots,
)
from radarviz.core.tracking.stream import TrackGroup

#: The scenes ``turn_figures`` runs on (module docstring).
TURN_SCENES: tuple[str, ...] = ("airliner", "manoeuvre")
#: The association gate's probability the gate-miss figure is counted against.
GATE_PROBABILITY = 0.999


class Estimate(NamedTuple):
    """A Monte Carlo mean and its standard error."""

    value: float
    se: float


class TurnFigures(NamedTuple):
    """One motion model on one scene (module docstring).

    Attributes:
        dof: position dimensions d.  runs: M.
        nees_turn, nees_straight: mean position NEES in the turn and straight plots.
        rmse_turn_m, rmse_straight_m: position RMSE there.
        gate_miss_turn, gate_miss_straight: fraction of plots outside the 0.999 gate.
        mse_straight_runs: per-run MSE on the straight plots (M,), for paired comparisons.
    """

    dof: int
    runs: int
    nees_turn: Estimate
    nees_straight: Estimate
    rmse_turn_m: Estimate
    rmse_straight_m: Estimate
    gate_miss_turn: float
    gate_miss_straight: float
    mse_straight_runs: NDArray[np.float64]


def _scene(
    scene: str, dims: int, runs: int, seed: int
) -> tuple[ManoeuvrePlots, tuple[Flight, ...], tuple[NDArray[np.float64], ...], NDArray]:
    """The plots (3D arrays of ``manoeuvre_plots``), the flights, the measured values the
    tracker gets ((r, β[, ε]) each (N, F, M)) and the truth positions (N, F, d)."""
    flights, radars = (
        (AIRLINER_FLIGHTS, (AIRLINER_RADAR,))
        if scene == "airliner"
        else (FLIGHTS, MANOEUVRE_RADARS)
    )
    mp = manoeuvre_plots(runs, seed, flights, radars)
    if dims == 3:
        return mp, flights, (mp.range_m, mp.azimuth_rad, mp.elevation_rad), mp.true_position_m
    # The radar's plane: ground-plane range and bearing of the same truths, the same σr, σβ,
    # the noise drawn from the seed's next child (independent of the 3D plots).
    sched = mp.schedule
    truth = mp.true_position_m[..., :2]
    sites = np.array([r.position for r in radars], dtype=np.float64)[sched.radar, None, :2]
    d = truth - sites
    r = np.hypot(d[..., 0], d[..., 1])
    b = np.arctan2(d[..., 1], d[..., 0])
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(runs + 1)[runs])
    sigma_r_m = np.array([radars[k].sigma_r_m for k in sched.radar])[:, None, None]
    sigma_beta_rad = np.array([radars[k].sigma_beta_rad for k in sched.radar])[:, None, None]
    shape = (*r.shape, runs)
    meas = (
        r[..., None] + sigma_r_m * rng.standard_normal(shape),
        b[..., None] + sigma_beta_rad * rng.standard_normal(shape),
    )
    return mp, flights, meas, truth


def _track(
    mp: ManoeuvrePlots,
    meas: tuple[NDArray[np.float64], ...],
    truth: NDArray[np.float64],
    motion: CVModel | IMMModel,
    dims: int,
    method: str,
    sigma_v0_mps: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Squared position errors, position NEES and position NIS of every plot, each (N, F·M)
    (NIS NaN at the start and at plots with Doppler, whose NIS has another dof)."""
    n_plots, f, m = meas[0].shape
    b = f * m
    sched = mp.schedule
    true = np.repeat(truth, m, axis=1)  # (N, B, d), B = flight-major
    group = TrackGroup((method,), dims, motion, sigma_v0_mps)
    e2 = np.empty((n_plots, b))
    nees = np.empty((n_plots, b))
    nis = np.full((n_plots, b), np.nan)
    n = 2 * dims
    for i in range(n_plots):
        radar = sched.radars[int(sched.radar[i])]
        plot = PolarPlot(*(v[i].reshape(b) for v in meas))
        sig = (radar.sigma_r_m, radar.sigma_beta_rad)
        noise = PolarNoise(*sig, *((radar.sigma_elevation_rad,) if dims == 3 else ()))
        pre = group.group.start_parts(plot, noise) if group.group.converted else None
        doppler = None
        if dims == 3 and mp.doppler[i]:
            doppler = DopplerMeasurement(
                mp.radial_velocity_mps[i].reshape(b),
                plot.azimuth_rad,
                plot.elevation_rad,
                radar.sigma_vr_mps,
                radar.sigma_beta_rad,
                radar.sigma_elevation_rad,
            )
        site = np.asarray(radar.position[:dims], dtype=np.float64)
        state, stats = group.add_arrays(float(sched.time_s[i]), plot, noise, site, pre, doppler)
        x = state.x.reshape(b, n)
        P = state.P.reshape(b, n, n)
        err = x[:, 0::2] - true[i]
        e2[i] = (err**2).sum(-1)
        nees[i] = np.einsum(
            "bi,bi->b", err, np.linalg.solve(P[:, 0::2, 0::2], err[..., None])[..., 0]
        )
        if stats is not None and doppler is None:
            nis[i] = stats.nis.reshape(b)
    return e2, nees, nis


def _per_run(v: NDArray[np.float64], mask: NDArray[np.bool_], f: int, m: int) -> NDArray:
    """The mean of v (N, F·M) over the plots of ``mask`` (N, F·M) of each run (M,)."""
    s = np.where(mask, v, 0.0).sum(0).reshape(f, m).sum(0)
    c = mask.sum(0).reshape(f, m).sum(0)
    return s / c


def _mean(per_run: NDArray[np.float64]) -> Estimate:
    return Estimate(float(per_run.mean()), float(per_run.std(ddof=1) / math.sqrt(per_run.size)))


def _rmse(mse: NDArray[np.float64]) -> Estimate:
    mean = _mean(mse)
    rmse = math.sqrt(mean.value)
    return Estimate(rmse, mean.se / (2.0 * rmse))


def turn_figures(
    motion: CVModel | IMMModel,
    scene: str = "airliner",
    dims: int = 3,
    runs: int = 32,
    seed: int = 1,
    method: str = "ucm",
    burn_in_plots: int = 20,
    sigma_v0_mps: float = 1000.0,
) -> TurnFigures:
    """``motion``'s figures on ``scene`` (module docstring); ``dims`` 2 on ``"airliner"``
    only (the manoeuvre scene's radars are 3D)."""
    check_choice("scene", scene, TURN_SCENES)
    if dims not in (2, 3) or (dims == 2 and scene != "airliner"):
        raise ParameterError(f"dims must be 3, or 2 on the airliner scene (got {dims} on {scene})")
    runs = check_int("runs", runs, low=2)
    check("seed", seed)
    check_int("burn_in_plots", burn_in_plots, low=0, high=500)
    mp, flights, meas, truth = _scene(scene, dims, runs, seed)
    e2, nees, nis = _track(mp, meas, truth, motion, dims, method, sigma_v0_mps)
    f = len(flights)
    turn = np.repeat(turn_mask(mp.schedule, flights), runs, axis=1)
    turn[:burn_in_plots] = False
    straight = ~np.repeat(turn_mask(mp.schedule, flights), runs, axis=1)
    straight[:burn_in_plots] = False
    gate = chi2_quantile(GATE_PROBABILITY, dims)

    def misses(mask: NDArray[np.bool_]) -> float:
        ok = mask & np.isfinite(nis)
        return float(np.mean(nis[ok] > gate))

    mse_s = _per_run(e2, straight, f, runs)
    return TurnFigures(
        dims,
        runs,
        _mean(_per_run(nees, turn, f, runs)),
        _mean(_per_run(nees, straight, f, runs)),
        _rmse(_per_run(e2, turn, f, runs)),
        _rmse(mse_s),
        misses(turn),
        misses(straight),
        mse_s,
    )


def rmse_ratio(new: TurnFigures, old: TurnFigures) -> Estimate:
    """new / old straight-leg RMSE on the same runs, with its paired standard error:
    ρ = √(MSE_new / MSE_old), SE(ρ) ≈ SE(mean of MSE_new − ρ² MSE_old) / (2 ρ MSE_old)
    (delta method on the per-run figures)."""
    a, b = new.mse_straight_runs, old.mse_straight_runs
    rho = math.sqrt(a.mean() / b.mean())
    d = a - rho * rho * b
    se = d.std(ddof=1) / math.sqrt(d.size) / (2.0 * rho * b.mean())
    return Estimate(rho, float(se))
