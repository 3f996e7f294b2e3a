"""The compiled (numba) tracker kernel: a block of plots of many targets, filtered in plot
order, every method's state of every target in arrays (``core.tracking.compiled``).

Where the Monte Carlo kernel (``core.filters.kernels_2d.filter_scans_2d``) walks runs × scans
of one radar with one period, a measurement file is a stream of plots, each of its own target
(slot), radar (site and noise) and time step. This kernel takes the block as arrays and walks
it once, in order: the first plot of a slot starts every method's track there (the method's
start conversion, velocity 0 ± σv0), a later one predicts over dt = t − t_previous and
updates with the method, then, when the plot has a radial velocity, the Doppler update. Plot
order within a slot is the file's, so every target's tracks are those of its plots alone.

The per-step arithmetic is the Monte Carlo kernel's own functions (``start``, ``predict``,
``convert``, ``position_update``, ``ukf_update``, ``doppler_update``), so the two engines
cannot drift apart; the numpy engine remains the reference (``tests/test_track_compiled.py``).
Imported on first use only (numba and the cached machine code load then).
"""

from __future__ import annotations

from math import cos, log, sin

import numpy as np

from radarviz.core.filters.kernels_2d import (
    _inline,
    _jit,
    convert,
    doppler_update,
    ekf_measurement_s,
    position_update,
    predict,
    start,
    ukf_update,
)
from radarviz.core.filters.methods import PLAN_COVARIANCE, PLAN_KIND, PLAN_START, Kind


@_jit
def position_stats(P, nx: float, ny: float, r00: float, r01: float, r11: float):
    # (νᵀ S⁻¹ ν, log det S), S = H P⁻ Hᵀ + R (core.filters.innovation.position_innovation);
    # both NaN unless S is positive definite, as the numpy engine's Cholesky and slogdet give
    s00, s01, s11 = P[0, 0] + r00, P[0, 2] + r01, P[2, 2] + r11
    det = s00 * s11 - s01 * s01
    if not (s00 > 0.0 and det > 0.0):
        return np.nan, np.nan
    return (s11 * nx * nx - 2.0 * s01 * nx * ny + s00 * ny * ny) / det, log(det)


@_jit
def position_nis(P, nx: float, ny: float, r00: float, r01: float, r11: float) -> float:
    # νᵀ S⁻¹ ν of ``position_stats``
    return position_stats(P, nx, ny, r00, r01, r11)[0]


@_inline
def doppler_stats(x, P, vr_hat: float, b: float, var_vr: float, vb: float):
    # (ν² / S, log S) of the Doppler stage on the state it updates
    # (core.filters.doppler.doppler_terms, linear_innovation): ν = V̂r − û·v,
    # S = û P_vv ûᵀ + var e; both NaN unless S > 0
    u0, u1 = cos(b), sin(b)
    g0, g1 = -u1, u0
    gv = g0 * x[1] + g1 * x[3]
    gpg = g0 * g0 * P[1, 1] + g1 * g1 * P[3, 3] + 2.0 * g1 * g0 * P[3, 1]
    S = u0 * u0 * P[1, 1] + 2.0 * u0 * u1 * P[1, 3] + u1 * u1 * P[3, 3]
    S += var_vr + vb * (gv * gv + gpg)
    if not S > 0.0:
        return np.nan, np.nan
    nu = vr_hat - (u0 * x[1] + u1 * x[3])
    return nu * nu / S, log(S)


@_inline
def doppler_nis(x, P, vr_hat: float, b: float, var_vr: float, vb: float) -> float:
    # ν² / S of ``doppler_stats``
    return doppler_stats(x, P, vr_hat, b, var_vr, vb)[0]


@_inline
def time_step(started, last_t, k: int, t: float) -> float:
    """The time since slot k's previous plot (0 at its first plot); negative when t is before
    it, a plot out of order (every tracker kernel returns its index then)."""
    return t - last_t[k] if started[k] else 0.0


@_inline
def position_measurement(plan, x, r, b, sr2, s, sx, sy, co):
    """The position stage of the method of ``plan`` (its row of
    ``core.filters.methods.method_plan``) on the prediction x (4,) as a position measurement
    (``MethodGroup.measurement``): (νx, νy, R00, R01, R11) in m, m². Converted methods:
    ν = z + site − H x⁻ with the conversion's R (``co``: its scalars, a row of
    ``conversion_table``); ``ekf`` and ``ukf``: ν' = J ν and R' = J R Jᵀ at the prediction
    (the UKF's statistics are the EKF's, as the numpy engine's)."""
    px, py = x[0] - sx, x[2] - sy
    if plan[PLAN_KIND] != Kind.CONVERTED:
        return ekf_measurement_s(px, py, r, b, sr2, s)
    zx, zy, r00, r01, r11 = convert(plan[PLAN_COVARIANCE], r, b, sr2, s, px, py, co)
    return zx + sx - x[0], zy + sy - x[2], r00, r01, r11


@_inline
def position_stage(plan, x, P, r, b, sr2, s, sx, sy, prm, meas, bufs):
    """The method's update of x (4,), P (4, 4) in place: the UKF's sigma points (kind
    ``Kind.UKF``) or the position update by ``meas``, ``position_measurement``'s
    (νx, νy, R00, R01, R11); ``bufs`` the scratch of ``scratch_2d``."""
    K, L, Z, E = bufs
    if plan[PLAN_KIND] == Kind.UKF:
        ukf_update(x, P, r, b, sr2, s, sx, sy, prm, L, Z, K, E)
    else:
        position_update(x, P, meas[0], meas[1], meas[2], meas[3], meas[4], K, L)


@_inline
def start_track(plan, x, P, r, b, sr2, s, sx, sy, co, sigma_v0_mps):
    """A track started at its first plot into x (4,), P (4, 4): the start conversion of the
    method of ``plan`` (``co`` its scalars), velocity 0 with std ``sigma_v0_mps``
    (``Method.start``)."""
    zx, zy, r00, r01, r11 = convert(plan[PLAN_START], r, b, sr2, s, 0.0, 0.0, co)
    start(x, P, zx + sx, zy + sy, r00, r01, r11, sigma_v0_mps)


@_jit
def scratch_2d():
    """The scratch arrays of ``position_stage``: K, L (4, 4), Z (9, 2), E (4,)."""
    return np.empty((4, 4)), np.empty((4, 4)), np.empty((9, 2)), np.empty(4)


@_jit
def track_plots_2d(plan, conversions, plots, radars, options, tracks, outs):
    """Filter plots 0 … B − 1 in order; returns −1, or the index of the first plot whose
    time is before its slot's previous plot (nothing from it on is filtered).

    Args:
        plan (M, 3): the methods' ``core.filters.methods.method_plan``.
        conversions (R, M, 2, 8): their ``conversion_table`` for each radar's noise.
        plots: the block (``core.filters.kernel_args.PlotColumns``).
        radars: each radar's site (R, 2) and noise (``RadarArrays``).
        options: σa, σv0 and the UKF's weights (``CVOptions``).
        tracks: every slot's tracks, x (K, M, 4), P (K, M, 4, 4), started, last_t
            (``TrackState``), updated in place.
        outs: each plot's posterior per method, x (B, M, 4), P (B, M, 4, 4), and each
            update's NIS (B, M) (``PlotOutputs``; ``core.filters.innovation``: the position
            stage's plus the Doppler stage's when the plot has V̂r; ``ekf`` and ``ukf`` the
            EKF's linearised statistics, as the numpy engine); NaN at a start.
    """
    slot, time_s, r_m, az_rad, _, vr_mps, has_vr, radar = plots
    site, sigma_r_m, sigma_beta_rad, _, sigma_vr_mps = radars
    sigma_a_mps2, sigma_v0_mps, prm = options
    xs, Ps, _, started, last_t = tracks
    out_x, out_P, out_nis = outs
    n_m = plan.shape[0]
    q = sigma_a_mps2 * sigma_a_mps2
    bufs = scratch_2d()
    K = bufs[0]
    x, P = np.empty(4), np.empty((4, 4))
    for i in range(slot.shape[0]):
        k, g = slot[i], radar[i]
        r, b = r_m[i], az_rad[i]
        sx, sy = site[g, 0], site[g, 1]
        sr2, s = sigma_r_m[g] * sigma_r_m[g], sigma_beta_rad[g] * sigma_beta_rad[g]
        new = not started[k]
        dt = time_step(started, last_t, k, time_s[i])
        if dt < 0.0:
            return i
        for j in range(n_m):
            pj, co = plan[j], conversions[g, j]
            nis = np.nan
            if new:
                start_track(pj, x, P, r, b, sr2, s, sx, sy, co[1], sigma_v0_mps)
            else:
                for a in range(4):
                    x[a] = xs[k, j, a]
                    for c in range(4):
                        P[a, c] = Ps[k, j, a, c]
                if dt > 0.0:
                    predict(x, P, dt, q)
                meas = position_measurement(pj, x, r, b, sr2, s, sx, sy, co[0])
                nis = position_nis(P, *meas)
                position_stage(pj, x, P, r, b, sr2, s, sx, sy, prm, meas, bufs)
            if has_vr[i]:
                var_vr = sigma_vr_mps[g] * sigma_vr_mps[g]
                if not new:
                    nis += doppler_nis(x, P, vr_mps[i], b, var_vr, s)
                doppler_update(x, P, vr_mps[i], b, var_vr, s, K)
            out_nis[i, j] = nis
            for a in range(4):
                xs[k, j, a] = x[a]
                out_x[i, j, a] = x[a]
                for c in range(4):
                    Ps[k, j, a, c] = P[a, c]
                    out_P[i, j, a, c] = P[a, c]
        started[k] = True
        last_t[k] = time_s[i]
    return -1


@_jit
def predicted_2d(xs, Ps, slot, j: int, dt, q: float, out_x, out_P):
    """Method j's tracks of slots ``slot`` (N,) predicted over ``dt`` (N,) (s, ≥ 0), the
    stored tracks left as they are (the association's gate, ``CompiledTracks.predicted``):
    ``predict``, the tracker kernel's own step, into out_x (N, 4), out_P (N, 4, 4); dt = 0
    copies the track. xs (K, M, 4), Ps (K, M, 4, 4) as ``track_plots_2d``."""
    x, P = np.empty(4), np.empty((4, 4))
    for i in range(slot.shape[0]):
        k = slot[i]
        x[:] = xs[k, j]
        P[:, :] = Ps[k, j]
        if dt[i] > 0.0:
            predict(x, P, dt[i], q)
        out_x[i] = x
        out_P[i] = P


@_jit
def gate_nis_2d(
    xs, Ps, slot, j: int, dt, q: float, plan, co, r_m, az_rad, sigma_r_m, sigma_beta_rad, site, out
):
    """``core.filters.kernels_imm.gate_nis_imm_2d`` for the cv model: pair i's track
    predicted over dt[i] by ``predict`` (σa² = q), then the position measurement of the
    method of ``plan`` (its row of ``method_plan``; co[i] its update's scalars for pair i's
    noise) and its NIS against its plot, into out (N,)."""
    x, P = np.empty(4), np.empty((4, 4))
    for i in range(slot.shape[0]):
        k = slot[i]
        x[:] = xs[k, j]
        P[:, :] = Ps[k, j]
        if dt[i] > 0.0:
            predict(x, P, dt[i], q)
        sr2, s = sigma_r_m[i] * sigma_r_m[i], sigma_beta_rad[i] * sigma_beta_rad[i]
        meas = position_measurement(
            plan, x, r_m[i], az_rad[i], sr2, s, site[i, 0], site[i, 1], co[i]
        )
        out[i] = position_nis(P, *meas)
