"""The compiled (numba) IMM of the many-target tracker: the mixing, mode probabilities and
combination of ``core.filters.imm`` on one track's r model-conditioned estimates, and the
tracker kernels ``track_plots_imm_2d`` / ``track_plots_imm_3d`` that run them over a block of
plots in plot order (``core.tracking.compiled``).

Per plot of a started track, with μ its model probabilities and Π the transition matrix
(Bar-Shalom, Li and Kirubarajan 2001, sec. 11.6.6; ``core.filters.imm.imm_step``)::

    mixing        c̄ⱼ = Σᵢ πᵢⱼ μᵢ,   μᵢ|ⱼ = πᵢⱼ μᵢ / c̄ⱼ
                  x⁰ⱼ = Σᵢ μᵢ|ⱼ xᵢ,   P⁰ⱼ = Σᵢ μᵢ|ⱼ (Pᵢ + (xᵢ − x⁰ⱼ)(xᵢ − x⁰ⱼ)ᵀ)
    prediction    model j's prediction with σa,j: constant velocity, or the coordinated
                  turn at its rate ωj ≠ 0 (``core.filters.turn``, the numpy engine's code)
    each stage    Λⱼ = N(νⱼ; 0, Sⱼ) on model j's state, μⱼ ∝ Λⱼ c̄ⱼ (``mode_probabilities``),
                  then the stage's update of every model
    combination   x = Σⱼ μⱼ xⱼ,   P = Σⱼ μⱼ (Pⱼ + (xⱼ − x)(xⱼ − x)ᵀ)

The stages are the cv kernel's (``core.filters.kernels_track.position_measurement`` /
``position_stage`` and the Doppler update; ``core.filters.kernels_3d`` in 3D), so a stage's
innovation and likelihood are those the numpy engine uses: ν and S = H P⁻ Hᵀ + R of the
method's position measurement (for ``ekf`` and ``ukf`` the EKF's ν' = J ν, R' = J R Jᵀ in
metres), then the Doppler stage's ν² / S on the position posterior. The consistency
monitor's NIS is that of the combined prediction (``imm_step`` with_stats): each stage's
statistics on Σⱼ μⱼ N(xⱼ, Pⱼ) of the states it updates. A track's first plot starts every
model at the method's start (and its Doppler update), μ = the model's initial probabilities,
and the output is that start.

The numpy engine stays the reference (``tests/test_track_compiled.py``, 1e-9 relative).
Imported on first use only.
"""

from __future__ import annotations

import math
from math import exp, sin

import numpy as np

from radarviz.core.filters import imm_moments
from radarviz.core.filters.kernels_2d import (
    _add_outer,
    _inline,
    _jit,
    add_process_noise_c,
    doppler_update,
    load,
    load_3d,
    predict,
    store,
    store_3d,
    white_acceleration_c,
)
from radarviz.core.filters.kernels_3d import (
    conversion_scratch,
    doppler_stats_3d_c,
    doppler_update_3d,
    fill_noise_table,
    plot_factors,
    position_measurement_3d,
    position_stage_3d,
    position_stats_3d_c,
    predict_3d,
    scratch_3d,
    start_track_3d,
)
from radarviz.core.filters.kernels_track import (
    doppler_stats,
    position_measurement,
    position_nis,
    position_stage,
    position_stats,
    scratch_2d,
    start_track,
    time_step,
)
from radarviz.core.filters.rebind import rebind
from radarviz.core.filters.turn import turn_factors, turn_predict

_LOG_2PI = math.log(2.0 * math.pi)

# The coordinated turn at a model's fixed rate: ``core.filters.turn``'s arithmetic, shared
# with the numpy engine's ``core.filters.imm.imm_predict``, compiled here.
_turn_factors = _inline(turn_factors)
_turn_predict = _inline(turn_predict)


@_inline
def turn_model_predict(x, P, n: int, T: float, omega: float, q: float):
    """The coordinated-turn prediction over T at ω ≠ 0 (rad/s) of one model's x (n,),
    P (n, n) in place, σa² = q (``core.filters.turn.turn_predict``, then the process noise
    of ``core.filters.predict.add_process_noise``)."""
    theta = omega * T
    _turn_predict(x, P, n, T, _turn_factors(omega, sin(theta), sin(0.5 * theta)))
    add_process_noise_c(P, n, white_acceleration_c(T, q))


@_inline
def predict_models(x0, P0, n: int, dt: float, sigma_a_mps2, omega):
    """Each model's prediction over dt (> 0) of its x0[m] (n,), P0[m] (n, n) in place: the
    constant-velocity one of σa = sigma_a_mps2[m] where omega[m] is 0, else the coordinated turn
    at ω = omega[m] (rad/s): the one prediction step of the tracker kernels and of the
    association's gate (``combined_prediction``)."""
    for m in range(sigma_a_mps2.shape[0]):
        q = sigma_a_mps2[m] * sigma_a_mps2[m]
        if omega[m] != 0.0:
            turn_model_predict(x0[m], P0[m], n, dt, omega[m], q)
        elif n == 4:
            predict(x0[m], P0[m], dt, q)
        else:
            predict_3d(x0[m], P0[m], dt, q)


@_jit
def log_likelihood(nis: float, log_det: float, dof: int) -> float:
    # log N(ν; 0, S) = −½ (NIS + log det S + m log 2π) (core.filters.innovation)
    return -0.5 * (nis + log_det + dof * _LOG_2PI)


# The mixing and the combination (``core.filters.imm_moments``, the numpy engine's too),
# compiled here with the kernels' compiled tuple helpers.
_moments = rebind(
    imm_moments.STEP_FUNCTIONS,
    {
        "load_2d": load,
        "store_2d": store,
        "load_3d": load_3d,
        "store_3d": store_3d,
        "_add_outer": _add_outer,
    },
    _inline,
)
mix_2d = _moments["mix_2d"]
combine_2d = _moments["combine_2d"]
mix_3d = _moments["mix_3d"]
combine_3d = _moments["combine_3d"]


@_inline
def mode_probabilities(prior, ll, mu):
    """μⱼ ∝ Λⱼ c̄ⱼ (``core.filters.imm.mode_probabilities``) into mu (r,) (may be ``prior``):
    exp(log Λⱼ + log c̄ⱼ − max), the prior inside the shift; a model whose likelihood is not
    finite gets no weight; a track with no finite weight keeps its prior."""
    r = prior.shape[0]
    top = -np.inf
    for j in range(r):
        if prior[j] > 0.0 and math.isfinite(ll[j]):
            v = ll[j] + math.log(prior[j])
            if v > top:
                top = v
    ok = math.isfinite(top)
    total = 0.0
    for j in range(r):
        w = prior[j]
        if ok:
            w = exp(ll[j] + math.log(prior[j]) - top) if w > 0.0 and math.isfinite(ll[j]) else 0.0
        mu[j] = w
        total += w
    for j in range(r):
        mu[j] /= total


@_inline
def _store(xs, Ps, mus, k, j, xm, Pm, mu, x, P, out_x, out_P, i):
    """The models and μ into slot k, method j; the combined (or start) x, P into plot i."""
    r, n = xm.shape
    for m in range(r):
        mus[k, j, m] = mu[m]
        for a in range(n):
            xs[k, j, m, a] = xm[m, a]
            for c in range(n):
                Ps[k, j, m, a, c] = Pm[m, a, c]
    for a in range(n):
        out_x[i, j, a] = x[a]
        for c in range(n):
            out_P[i, j, a, c] = P[a, c]


@_inline
def _started(x, P, mu0, xm, Pm, mu):
    # imm_start: every model at the track's start, μ = the initial probabilities
    r, n = xm.shape
    for m in range(r):
        mu[m] = mu0[m]
        for a in range(n):
            xm[m, a] = x[a]
            for c in range(n):
                Pm[m, a, c] = P[a, c]


@_jit
def track_plots_imm_2d(plan, conversions, plots, radars, options, tracks, outs):
    """``core.filters.kernels_track.track_plots_2d`` with the IMM (module docstring): returns
    −1, or the index of the first plot before its slot's previous one (nothing from it on is
    filtered).

    Args:
        plan, conversions, plots, radars, outs: as ``track_plots_2d``.
        options: each model's σa and turn rate ω, Π, a new track's μ, σv0, the UKF's
            weights and whether to compute the monitor's NIS (else outs.nis is NaN)
            (``core.filters.kernel_args.IMMOptions``).
        tracks: every slot's model-conditioned tracks x (K, M, r, 4), P (K, M, r, 4, 4),
            μ (K, M, r), started, last_t (``TrackState``), updated in place.
        outs: each plot's combined posterior per method and the NIS of the combined
            prediction, NaN at a start.
    """
    slot, time_s, r_m, az_rad, _, vr_mps, has_vr, radar = plots
    site, sigma_r_m, sigma_beta_rad, _, sigma_vr_mps = radars
    sigma_a_mps2, omega, Pi, mu0, sigma_v0_mps, prm, with_stats = options
    xs, Ps, mus, started, last_t = tracks
    out_x, out_P, out_nis = outs
    n_m, r = plan.shape[0], sigma_a_mps2.shape[0]
    bufs = scratch_2d()
    K = bufs[0]
    x, P = np.empty(4), np.empty((4, 4))
    x0, P0 = np.empty((r, 4)), np.empty((r, 4, 4))  # the models, mixed then advanced
    mu, c, ll, w = np.empty(r), np.empty(r), np.empty(r), np.empty((r, r))
    for i in range(slot.shape[0]):
        k, g = slot[i], radar[i]
        rr, b = r_m[i], az_rad[i]
        sx, sy = site[g, 0], site[g, 1]
        sr2, s = sigma_r_m[g] * sigma_r_m[g], sigma_beta_rad[g] * sigma_beta_rad[g]
        var_vr = sigma_vr_mps[g] * sigma_vr_mps[g]
        new = not started[k]
        dt = time_step(started, last_t, k, time_s[i])
        if dt < 0.0:
            return i
        for j in range(n_m):
            pj, co = plan[j], conversions[g, j]
            nis = np.nan
            if new:
                start_track(pj, x, P, rr, b, sr2, s, sx, sy, co[1], sigma_v0_mps)
                if has_vr[i]:
                    doppler_update(x, P, vr_mps[i], b, var_vr, s, K)
                _started(x, P, mu0, x0, P0, mu)
            else:
                mu[:] = mus[k, j]
                mix_2d(xs[k, j], Ps[k, j], mu, Pi, x0, P0, c, w)
                if dt > 0.0:
                    predict_models(x0, P0, 4, dt, sigma_a_mps2, omega)
                if with_stats:
                    combine_2d(x0, P0, c, x, P)
                    meas = position_measurement(pj, x, rr, b, sr2, s, sx, sy, co[0])
                    nis = position_stats(P, *meas)[0]
                for m in range(r):
                    xj, Pj = x0[m], P0[m]
                    meas = position_measurement(pj, xj, rr, b, sr2, s, sx, sy, co[0])
                    ll[m] = log_likelihood(*position_stats(Pj, *meas), 2)
                    position_stage(pj, xj, Pj, rr, b, sr2, s, sx, sy, prm, meas, bufs)
                mode_probabilities(c, ll, mu)
                if has_vr[i]:
                    if with_stats:
                        combine_2d(x0, P0, mu, x, P)
                        nis += doppler_stats(x, P, vr_mps[i], b, var_vr, s)[0]
                    for m in range(r):
                        xj, Pj = x0[m], P0[m]
                        st = doppler_stats(xj, Pj, vr_mps[i], b, var_vr, s)
                        ll[m] = log_likelihood(st[0], st[1], 1)
                        doppler_update(xj, Pj, vr_mps[i], b, var_vr, s, K)
                    mode_probabilities(mu, ll, mu)
                combine_2d(x0, P0, mu, x, P)
            out_nis[i, j] = nis
            _store(xs, Ps, mus, k, j, x0, P0, mu, x, P, out_x, out_P, i)
        started[k] = True
        last_t[k] = time_s[i]
    return -1


@_jit
def track_plots_imm_3d(plan, scales, plots, radars, options, tracks, outs):
    """``track_plots_imm_2d`` in 3D (``core.filters.kernels_3d.track_plots_3d``'s stages):
    the plots' elevations, sites (R, 3) and σε read, models x (K, M, r, 6),
    P (K, M, r, 6, 6), outputs (B, M, 6), (B, M, 6, 6), (B, M); the UKF's weights for
    n = 6; scales (R, M, 2, 2) as ``track_plots_3d``'s."""
    slot, time_s, r_m, az_rad, el_rad, vr_mps, has_vr, radar = plots
    site, sigma_r_m, sigma_beta_rad, sigma_elevation_rad, sigma_vr_mps = radars
    sigma_a_mps2, omega, Pi, mu0, sigma_v0_mps, prm, with_stats = options
    xs, Ps, mus, started, last_t = tracks
    out_x, out_P, out_nis = outs
    n_m, r = plan.shape[0], sigma_a_mps2.shape[0]
    x, P = np.empty(6), np.empty((6, 6))
    x0, P0 = np.empty((r, 6)), np.empty((r, 6, 6))  # the models, mixed then advanced
    mu, c, ll, w = np.empty(r), np.empty(r), np.empty(r), np.empty((r, r))
    z, nu, u, Uv, Kv = np.empty(3), np.empty(3), np.empty(3), np.empty(6), np.empty(6)
    R = np.empty((3, 3))
    bufs = scratch_3d()
    ex, conv = conversion_scratch(sigma_r_m.shape[0])
    for g in range(sigma_r_m.shape[0]):
        fill_noise_table(sigma_beta_rad[g] ** 2, sigma_elevation_rad[g] ** 2, ex[g])
    trig = conv[0]
    for i in range(slot.shape[0]):
        k, g = slot[i], radar[i]
        rr, b, el = r_m[i], az_rad[i], el_rad[i]
        plot_factors(b, el, ex[g], conv)
        sx, sy, sz = site[g, 0], site[g, 1], site[g, 2]
        sr2, sb2, se2 = sigma_r_m[g] ** 2, sigma_beta_rad[g] ** 2, sigma_elevation_rad[g] ** 2
        var_vr = sigma_vr_mps[g] * sigma_vr_mps[g]
        vr = vr_mps[i]
        new = not started[k]
        dt = time_step(started, last_t, k, time_s[i])
        if dt < 0.0:
            return i
        for j in range(n_m):
            pj, kj = plan[j], scales[g, j]
            nis = np.nan
            if new:
                start_track_3d(
                    pj, kj[1], x, P, rr, b, el, sr2, sb2, se2, sx, sy, sz, sigma_v0_mps, z, R, conv
                )
                if has_vr[i]:
                    doppler_update_3d(x, P, vr, trig, var_vr, sb2, se2, u, Uv, Kv, bufs[4])
                _started(x, P, mu0, x0, P0, mu)
            else:
                mu[:] = mus[k, j]
                mix_3d(xs[k, j], Ps[k, j], mu, Pi, x0, P0, c, w)
                if dt > 0.0:
                    predict_models(x0, P0, 6, dt, sigma_a_mps2, omega)
                if with_stats:
                    combine_3d(x0, P0, c, x, P)
                    position_measurement_3d(
                        pj, kj[0], x, rr, b, el, sr2, sb2, se2, sx, sy, sz, nu, R, z, conv
                    )
                    nis = position_stats_3d_c(P, nu, R, bufs[0], bufs[1])[0]
                # From the first conversion on, z and R hold this plot's (for a conversion
                # that does not read the prediction, every model's is the same).
                converted = with_stats
                for m in range(r):
                    xj, Pj = x0[m], P0[m]
                    position_measurement_3d(
                        pj, kj[0], xj, rr, b, el, sr2, sb2, se2, sx, sy, sz, nu, R, z, conv,
                        converted,
                    )  # fmt: skip
                    converted = True
                    st = position_stats_3d_c(Pj, nu, R, bufs[0], bufs[1])
                    ll[m] = log_likelihood(st[0], st[1], 3)
                    position_stage_3d(
                        pj, xj, Pj, rr, b, el, sr2, sb2, se2, sx, sy, sz, nu, R, prm, bufs
                    )
                mode_probabilities(c, ll, mu)
                if has_vr[i]:
                    if with_stats:
                        combine_3d(x0, P0, mu, x, P)
                        nis += doppler_stats_3d_c(x, P, vr, trig, var_vr, sb2, se2, u)[0]
                    for m in range(r):
                        xj, Pj = x0[m], P0[m]
                        st = doppler_stats_3d_c(xj, Pj, vr, trig, var_vr, sb2, se2, u)
                        ll[m] = log_likelihood(st[0], st[1], 1)
                        doppler_update_3d(xj, Pj, vr, trig, var_vr, sb2, se2, u, Uv, Kv, bufs[4])
                    mode_probabilities(mu, ll, mu)
                combine_3d(x0, P0, mu, x, P)
            out_nis[i, j] = nis
            _store(xs, Ps, mus, k, j, x0, P0, mu, x, P, out_x, out_P, i)
        started[k] = True
        last_t[k] = time_s[i]
    return -1


@_inline
def combined_prediction(xm, Pm, mu_k, dt: float, sigma_a_mps2, omega, Pi, x0, P0, mu, c, w, x, P):
    """One track's IMM prediction over dt (≥ 0) into x (n,), P (n, n), the track's models
    xm (r, n), Pm (r, n, n) and μ mu_k (r,) left as they are: the tracker kernels' mixing,
    each model's prediction, and the combination with the predicted probabilities c̄ (the
    combined prediction their monitor's NIS is taken of). 2D (n = 4) or 3D (n = 6) by the
    state size; x0 (r, n), P0 (r, n, n), mu, c (r,), w (r, r) scratch."""
    n = xm.shape[1]
    mu[:] = mu_k
    if n == 4:
        mix_2d(xm, Pm, mu, Pi, x0, P0, c, w)
    else:
        mix_3d(xm, Pm, mu, Pi, x0, P0, c, w)
    if dt > 0.0:
        predict_models(x0, P0, n, dt, sigma_a_mps2, omega)
    if n == 4:
        combine_2d(x0, P0, c, x, P)
    else:
        combine_3d(x0, P0, c, x, P)


@_jit
def predicted_imm(xs, Ps, mus, slot, j: int, dt, sigma_a_mps2, omega, Pi, out_x, out_P):
    """Method j's IMM tracks of slots ``slot`` (N,) predicted over ``dt`` (N,) (s, ≥ 0), the
    stored tracks left as they are (the association's gate, ``CompiledTracks.predicted``):
    ``combined_prediction`` of each, as ``core.tracking.targets.TargetTracker.predicted``
    on the numpy engine. 2D or 3D: xs (K, M, r, n), Ps (K, M, r, n, n), mus (K, M, r) into
    out_x (N, n), out_P (N, n, n)."""
    r, n = sigma_a_mps2.shape[0], xs.shape[3]
    x0, P0 = np.empty((r, n)), np.empty((r, n, n))
    mu, c, w = np.empty(r), np.empty(r), np.empty((r, r))
    for i in range(slot.shape[0]):
        k = slot[i]
        combined_prediction(
            xs[k, j], Ps[k, j], mus[k, j], dt[i], sigma_a_mps2, omega, Pi, x0, P0, mu, c, w,
            out_x[i], out_P[i],
        )  # fmt: skip


@_jit
def gate_nis_imm_2d(
    xs, Ps, mus, slot, j: int, dt, sigma_a_mps2, omega, Pi, plan, co, r_m, az_rad, sigma_r_m,
    sigma_beta_rad, site, out,
):  # fmt: skip
    """d² = νᵀ S⁻¹ ν of N (track, plot) pairs, 2D: pair i's track (slot[i], method j, of
    ``plan``, its row of ``method_plan``; co[i] its update's scalars for pair i) predicted
    over dt[i] (``combined_prediction``) against its plot r_m[i], az_rad[i] with noise std
    sigma_r_m[i], sigma_beta_rad[i] at site[i] (N, 2): the method's position measurement
    and its NIS (``position_measurement``, ``position_nis``), the statistic of the tracker
    kernels' monitor, into out (N,) (NaN where S is not positive definite)."""
    r = sigma_a_mps2.shape[0]
    x0, P0 = np.empty((r, 4)), np.empty((r, 4, 4))
    mu, c, w = np.empty(r), np.empty(r), np.empty((r, r))
    x, P = np.empty(4), np.empty((4, 4))
    for i in range(slot.shape[0]):
        k = slot[i]
        out[i] = pair_nis_2d(
            xs[k, j], Ps[k, j], mus[k, j], dt[i], sigma_a_mps2, omega, Pi, plan, r_m[i], az_rad[i],
            sigma_r_m[i], sigma_beta_rad[i], site[i, 0], site[i, 1], co[i], x0, P0, mu, c, w, x, P,
        )  # fmt: skip


@_inline
def pair_nis_2d(xm, Pm, mu_k, dt, sigma_a_mps2, omega, Pi, plan, r, b, sigma_r_m, sigma_beta_rad,
                sx, sy, co, x0, P0, mu, c, w, x, P):  # fmt: skip
    """d² of one (track, plot) pair in 2D: the track's models xm, Pm, μ mu_k predicted over
    dt (``combined_prediction``) against the plot (r, b) with noise std sigma_r_m,
    sigma_beta_rad at site (sx, sy) and the conversion's scalars co (its row of
    ``conversion_table`` for the noise: the same for every plot of a radar, so a caller forms
    them once), by the position measurement of the method of ``plan`` and its NIS (NaN
    where S is not positive definite); x0 … P scratch as ``combined_prediction``'s."""
    combined_prediction(xm, Pm, mu_k, dt, sigma_a_mps2, omega, Pi, x0, P0, mu, c, w, x, P)
    sr2, s = sigma_r_m * sigma_r_m, sigma_beta_rad * sigma_beta_rad
    meas = position_measurement(plan, x, r, b, sr2, s, sx, sy, co)
    return position_nis(P, *meas)
