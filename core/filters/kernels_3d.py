"""The compiled (numba) 3D tracker kernel: the seven methods in 3D and the Doppler update as
scalar loops, the 6 × 6 state (x, ẋ, y, ẏ, z, ż) in small arrays, one plot at a time.

The updates are the ones every engine runs, written once (``core.filters.steps_3d``: the
position update, the EKF's measurement, the UKF, the Doppler update) and compiled here with
the scalar elementary functions; the prediction is ``core.filters.predict``'s; the 3D
conversions are ``core.conversion.elementwise_3d``'s. This module adds the innovation
statistics and the plot loop.

The numpy engine stays the reference (``tests/test_track_compiled.py`` holds every method, with
and without Doppler, to it at 1e-9 relative). Imported on first use only.
"""

from __future__ import annotations

from math import atan2, cos, log, sin, sqrt

import numpy as np

from radarviz.core.conversion.elementwise import Covariance
from radarviz.core.conversion.elementwise_3d import CONVERSION_FUNCTIONS_3D
from radarviz.core.filters.kernels_2d import (
    _exact,
    _inline,
    _jit,
    _select,
    add_process_noise_c,
    predict_components_c,
    white_acceleration_c,
    wrap,
)
from radarviz.core.filters.kernels_track import time_step
from radarviz.core.filters.methods import PLAN_COVARIANCE, PLAN_KIND, PLAN_START, Kind
from radarviz.core.filters.rebind import rebind
from radarviz.core.filters.steps_3d import bind_3d

# The 3D updates (position, the EKF's measurement, UKF, Doppler: ``core.filters.steps_3d``),
# written once as plain arithmetic (the numpy engine's too), compiled here with the scalar
# elementary functions.
_steps = bind_3d({"sqrt": sqrt, "where": _select, "atan2": atan2, "wrap": wrap}, _inline)
inverse_3 = _steps["inverse_3"]
position_update_3d = _steps["position_update_3d"]
ekf_measurement_3d_c = _steps["ekf_measurement_3d"]
ukf_update_3d = _steps["ukf_update_3d"]
doppler_terms_3d = _steps["doppler_terms_3d"]
doppler_update_3d = _steps["doppler_update_3d"]


# The 3D conversions (``core.conversion.elementwise_3d``, the numpy engine's too), compiled
# without reassociation (``kernels_2d._exact``): LLVM inlines them at each of their call
# sites (a track's start, the monitor's statistics, a model's update), and with "reassoc" it
# reordered their products and sums differently at each, so a target's results came to depend
# by rounding on which site converted its plot, and so on the other targets in its block (the
# bit-for-bit tests of ``tests/test_track_compiled.py``).
_conversions = rebind(CONVERSION_FUNCTIONS_3D, {}, _exact)
_noise_table = _conversions["noise_table"]
_converted_point_3d = _conversions["converted_point_3d"]


@_jit
def fill_noise_table(sb2: float, se2: float, out):
    # A radar's noise-only factors of the conversions into out (4, 5)
    # (``core.conversion.elementwise_3d.noise_table``; once per radar, not per plot, method
    # and model)
    t = _noise_table(sb2, se2)
    for a in range(4):
        row = t[a]
        for c in range(5):
            out[a, c] = row[c]


@_jit
def conversion_scratch(radars: int):
    # The conversions' per-kernel arrays: the noise table of every radar (radars, 4, 5) and
    # ``conv`` = (trig (4,), ex (4, 5)) that ``plot_factors`` fills per plot
    return np.empty((radars, 4, 5)), (np.empty(4), np.empty((4, 5)))


@_inline
def plot_factors(b: float, el: float, ex_g, conv):
    # A plot's factors of the conversions and the Doppler stage, once per plot for every
    # method and model: trig = (cos β̂, sin β̂, cos ε̂, sin ε̂), and its radar's noise table
    trig, ex = conv
    trig[0], trig[1], trig[2], trig[3] = cos(b), sin(b), cos(el), sin(el)
    for a in range(4):
        for c in range(5):
            ex[a, c] = ex_g[a, c]


@_inline
def convert_3d(form, k, r, sr2, sb2, se2, px, py, pz, z, R, conv):
    # The radar-centred point z (3,) and covariance R (3, 3) of (r̂, β̂, ε̂), whose cosines,
    # sines and radar's noise table ``plot_factors`` put in ``conv``, by the conversion of
    # covariance ``form`` and scales k = (κxy, κz) (a row of ``scale_table``); (px, py, pz):
    # the predicted position minus the site (read by ``EXACT_AT_PREDICTION`` only)
    # (``core.conversion.elementwise_3d.converted_point_3d``)
    trig, ex = conv
    t = _converted_point_3d(
        form, k[0], k[1], r, trig[0], trig[1], trig[2], trig[3], sr2, sb2, se2, ex, px, py, pz
    )
    z[0], z[1], z[2] = t[0], t[1], t[2]
    R[0, 0], R[0, 1], R[0, 2] = t[3], t[4], t[5]
    R[1, 0], R[1, 1], R[1, 2] = t[4], t[6], t[7]
    R[2, 0], R[2, 1], R[2, 2] = t[5], t[7], t[8]


# The per-plot stages below are inlined into the kernels (``_inline``): a compiled call with a
# dozen array arguments costs more than the 3D position update it makes (measured: 270 against
# 105 ns for a position stage).


@_inline
def start_3d(x, P, z, R, sx, sy, sz, sigma_v0_mps):
    # cv_init: position z + site with covariance R, velocity 0 with variance σv0²
    for i in range(6):
        x[i] = 0.0
        for j in range(6):
            P[i, j] = 0.0
    x[0], x[2], x[4] = z[0] + sx, z[1] + sy, z[2] + sz
    for a in range(3):
        for b in range(3):
            P[2 * a, 2 * b] = R[a, b]
        P[2 * a + 1, 2 * a + 1] = sigma_v0_mps * sigma_v0_mps


@_inline
def predict_3d(x, P, T: float, q: float):
    # cv_predict in 3D: x⁻ = F x, P⁻ = F P Fᵀ + Q, σa² = q, in place
    # (``core.filters.predict.predict_components``, ``add_process_noise``)
    predict_components_c(x, P, 6, T)
    add_process_noise_c(P, 6, white_acceleration_c(T, q))


@_inline
def nis_3(S, nu) -> float:
    # νᵀ S⁻¹ ν by the Cholesky factor (core.filters.state.quad_form_inv): NaN unless S is
    # positive definite
    l00 = S[0, 0]
    if not l00 > 0.0:
        return np.nan
    l00 = sqrt(l00)
    l10, l20 = S[1, 0] / l00, S[2, 0] / l00
    d1 = S[1, 1] - l10 * l10
    if not d1 > 0.0:
        return np.nan
    l11 = sqrt(d1)
    l21 = (S[2, 1] - l20 * l10) / l11
    d2 = S[2, 2] - l20 * l20 - l21 * l21
    if not d2 > 0.0:
        return np.nan
    l22 = sqrt(d2)
    y0 = nu[0] / l00
    y1 = (nu[1] - l10 * y0) / l11
    y2 = (nu[2] - l20 * y0 - l21 * y1) / l22
    return y0 * y0 + y1 * y1 + y2 * y2


@_inline
def doppler_stats_3d_c(x, P, vr_hat, trig, var_vr, sb2, se2, u):
    # (ν² / S, log S) of the Doppler stage (doppler_terms, linear_innovation); NaN unless S > 0
    r_e = doppler_terms_3d(x, P, trig, var_vr, sb2, se2, u)
    S = r_e
    for a in range(3):
        for c in range(3):
            S += u[a] * P[2 * a + 1, 2 * c + 1] * u[c]
    if not S > 0.0:
        return np.nan, np.nan
    nu = vr_hat - (u[0] * x[1] + u[1] * x[3] + u[2] * x[5])
    return nu * nu / S, log(S)


@_inline
def doppler_nis_3d(x, P, vr_hat, trig, var_vr, sb2, se2, u) -> float:
    # ν² / S of ``doppler_stats_3d_c``
    return doppler_stats_3d_c(x, P, vr_hat, trig, var_vr, sb2, se2, u)[0]


@_inline
def position_measurement_3d(
    plan, k, x, r, b, el, sr2, sb2, se2, sx, sy, sz, nu, R, z, conv, converted=False
):
    """The position stage of the method of ``plan`` (its row of ``method_plan``; k its
    update's scales, a row of ``scale_table``) on the prediction x (6,) as a position
    measurement (``MethodGroup.measurement``) into nu (3,) (m) and R (3, 3) (m²): converted
    methods ν = z + site − H x⁻ with the conversion's z (3,) and R; ``ekf`` and ``ukf`` the
    EKF's ν' = J ν, R' = J R Jᵀ at the prediction. ``conv`` (``conversion_scratch``, the
    plot's ``plot_factors`` in it) is scratch. ``converted``: z and R hold this plot's
    conversion already (one that does not read the prediction, made for another state of the
    same track)."""
    form = plan[PLAN_COVARIANCE]
    if plan[PLAN_KIND] != Kind.CONVERTED:
        ekf_measurement_3d_c(x[0] - sx, x[2] - sy, x[4] - sz, r, b, el, sr2, sb2, se2, nu, R)
    else:
        if not (converted and form != Covariance.EXACT_AT_PREDICTION):
            px, py, pz = x[0] - sx, x[2] - sy, x[4] - sz
            convert_3d(form, k, r, sr2, sb2, se2, px, py, pz, z, R, conv)
        nu[0], nu[1], nu[2] = z[0] + sx - x[0], z[1] + sy - x[2], z[2] + sz - x[4]


@_inline
def start_track_3d(plan, k, x, P, r, b, el, sr2, sb2, se2, sx, sy, sz, sigma_v0_mps, z, R, conv):
    """A track started at its first plot into x (6,), P (6, 6): the start conversion of the
    method of ``plan`` (k its scales), velocity 0 with std ``sigma_v0_mps`` (``Method.start``);
    z (3,), R (3, 3), ``conv``: scratch."""
    convert_3d(plan[PLAN_START], k, r, sr2, sb2, se2, 0.0, 0.0, 0.0, z, R, conv)
    start_3d(x, P, z, R, sx, sy, sz, sigma_v0_mps)


@_inline
def position_stats_3d_c(P, nu, R, S, Si):
    """(νᵀ S⁻¹ ν, log det S) of ``position_measurement_3d``'s (ν, R) on P (6, 6), S = H P Hᵀ + R
    into S (3, 3) (Si: scratch); both NaN unless S is positive definite."""
    for a in range(3):
        for c in range(3):
            S[a, c] = P[2 * a, 2 * c] + R[a, c]
    nis = nis_3(S, nu)
    det = inverse_3(S, Si)
    if not (nis == nis and det > 0.0):
        return np.nan, np.nan
    return nis, log(det)


@_inline
def position_stage_3d(plan, x, P, r, b, el, sr2, sb2, se2, sx, sy, sz, nu, R, prm, bufs):
    """The method's update of x (6,), P (6, 6) in place: the UKF (kind ``Kind.UKF``) or the
    position update by (ν, R); ``bufs`` the scratch (S, Si, K, U, L, Z, E) of ``scratch_3d``."""
    S, Si, K, U, L, Z, E = bufs
    if plan[PLAN_KIND] == Kind.UKF:
        ukf_update_3d(x, P, r, b, el, sr2, sb2, se2, sx, sy, sz, prm, L, Z, K, S, Si, E)
    else:
        position_update_3d(x, P, nu, R, S, Si, K, U, L)


@_jit
def scratch_3d():
    """The scratch arrays of ``position_stage_3d``: S, Si (3, 3), K (6, 6), U (6, 3),
    L (6, 6), Z (13, 3), E (6,)."""
    return (
        np.empty((3, 3)),
        np.empty((3, 3)),
        np.empty((6, 6)),
        np.empty((6, 3)),
        np.empty((6, 6)),
        np.empty((13, 3)),
        np.empty(6),
    )


@_jit
def track_plots_3d(plan, scales, plots, radars, options, tracks, outs):
    """``core.filters.kernels_track.track_plots_2d`` in 3D: the plots' elevations, sites
    (R, 3) and σε read, tracks x (K, M, 6), P (K, M, 6, 6), outputs (B, M, 6),
    (B, M, 6, 6), (B, M); the UKF's weights for n = 6; scales (R, M, 2, 2) the methods'
    ``scale_table`` in place of 2D's conversion scalars. Returns −1 or the index of the
    first plot before its slot's previous one."""
    slot, time_s, r_m, az_rad, el_rad, vr_mps, has_vr, radar = plots
    site, sigma_r_m, sigma_beta_rad, sigma_elevation_rad, sigma_vr_mps = radars
    sigma_a_mps2, sigma_v0_mps, prm = options
    xs, Ps, _, started, last_t = tracks
    out_x, out_P, out_nis = outs
    n_m = plan.shape[0]
    q = sigma_a_mps2 * sigma_a_mps2
    x, P = np.empty(6), np.empty((6, 6))
    z, nu, u, Uv, Kv = np.empty(3), np.empty(3), np.empty(3), np.empty(6), np.empty(6)
    R = np.empty((3, 3))
    bufs = scratch_3d()
    ex, conv = conversion_scratch(sigma_r_m.shape[0])
    for g in range(sigma_r_m.shape[0]):
        fill_noise_table(sigma_beta_rad[g] ** 2, sigma_elevation_rad[g] ** 2, ex[g])
    trig = conv[0]
    for i in range(slot.shape[0]):
        k, g = slot[i], radar[i]
        r, b, el = r_m[i], az_rad[i], el_rad[i]
        plot_factors(b, el, ex[g], conv)
        sx, sy, sz = site[g, 0], site[g, 1], site[g, 2]
        sr2, sb2, se2 = sigma_r_m[g] ** 2, sigma_beta_rad[g] ** 2, sigma_elevation_rad[g] ** 2
        new = not started[k]
        dt = time_step(started, last_t, k, time_s[i])
        if dt < 0.0:
            return i
        for j in range(n_m):
            pj, kj = plan[j], scales[g, j]
            nis = np.nan
            if new:
                start_track_3d(
                    pj, kj[1], x, P, r, b, el, sr2, sb2, se2, sx, sy, sz, sigma_v0_mps, z, R, conv
                )
            else:
                for a in range(6):
                    x[a] = xs[k, j, a]
                    for c in range(6):
                        P[a, c] = Ps[k, j, a, c]
                if dt > 0.0:
                    predict_3d(x, P, dt, q)
                position_measurement_3d(
                    pj, kj[0], x, r, b, el, sr2, sb2, se2, sx, sy, sz, nu, R, z, conv
                )
                nis = position_stats_3d_c(P, nu, R, bufs[0], bufs[1])[0]
                position_stage_3d(pj, x, P, r, b, el, sr2, sb2, se2, sx, sy, sz, nu, R, prm, bufs)
            if has_vr[i]:
                var_vr = sigma_vr_mps[g] * sigma_vr_mps[g]
                if not new:
                    nis += doppler_nis_3d(x, P, vr_mps[i], trig, var_vr, sb2, se2, u)
                doppler_update_3d(x, P, vr_mps[i], trig, var_vr, sb2, se2, u, Uv, Kv, bufs[4])
            out_nis[i, j] = nis
            for a in range(6):
                xs[k, j, a] = x[a]
                out_x[i, j, a] = x[a]
                for c in range(6):
                    Ps[k, j, a, c] = P[a, c]
                    out_P[i, j, a, c] = P[a, c]
        started[k] = True
        last_t[k] = time_s[i]
    return -1


@_jit
def predicted_3d(xs, Ps, slot, j: int, dt, q: float, out_x, out_P):
    """``core.filters.kernels_track.predicted_2d`` in 3D (``predict_3d``): xs (K, M, 6),
    Ps (K, M, 6, 6) into out_x (N, 6), out_P (N, 6, 6)."""
    x, P = np.empty(6), np.empty((6, 6))
    for i in range(slot.shape[0]):
        k = slot[i]
        x[:] = xs[k, j]
        P[:, :] = Ps[k, j]
        if dt[i] > 0.0:
            predict_3d(x, P, dt[i], q)
        out_x[i] = x
        out_P[i] = P
