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

from math import atan2, cos, hypot, sin

import numpy as np

from radarviz.core.filters.kernels_2d import (
    _jit,
    coefficients,
    convert,
    doppler_update,
    position_update,
    predict,
    start,
    ukf_update,
    wrap,
)


@_jit
def position_nis(P, nx: float, ny: float, r00: float, r01: float, r11: float) -> float:
    # νᵀ S⁻¹ ν, S = H P⁻ Hᵀ + R (core.filters.innovation.position_innovation); NaN unless S
    # is positive definite, as the numpy engine's Cholesky gives
    s00, s01, s11 = P[0, 0] + r00, P[0, 2] + r01, P[2, 2] + r11
    det = s00 * s11 - s01 * s01
    if not (s00 > 0.0 and det > 0.0):
        return np.nan
    return (s11 * nx * nx - 2.0 * s01 * nx * ny + s00 * ny * ny) / det


@_jit
def doppler_nis(x, P, vr_hat: float, b: float, var_vr: float, vb: float) -> float:
    # ν² / S of the Doppler stage on the state it updates (core.filters.doppler.doppler_terms,
    # linear_innovation): ν = V̂r − û·v, S = û P_vv ûᵀ + var e
    u0, u1 = cos(b), sin(b)
    g0, g1 = -u1, u0
    gv = g0 * x[1] + g1 * x[3]
    gpg = g0 * g0 * P[1, 1] + g1 * g1 * P[3, 3] + 2.0 * g1 * g0 * P[3, 1]
    S = u0 * u0 * P[1, 1] + 2.0 * u0 * u1 * P[1, 3] + u1 * u1 * P[3, 3]
    S += var_vr + vb * (gv * gv + gpg)
    if not S > 0.0:
        return np.nan
    nu = vr_hat - (u0 * x[1] + u1 * x[3])
    return nu * nu / S


@_jit
def track_plots_2d(
    codes, start_codes, slot, time_s, r_m, az_rad, vr_mps, has_vr, radar, site, sigma_r,
    sigma_b, sigma_vr, sigma_a, v0, prm, xs, Ps, started, last_t, out_x, out_P, out_nis,
):  # fmt: skip
    """Filter plots 0 … B − 1 in order; returns −1, or the index of the first plot whose
    time is before its slot's previous plot (nothing from it on is filtered).

    Args:
        codes, start_codes: (M,) ``core.filters.compiled.METHOD_CODES`` / ``START_CODES``.
        slot (B,): each plot's target slot; time_s, r_m, az_rad, vr_mps (B,): its time (s),
            range (m), azimuth (rad) and radial velocity (m/s, read where has_vr (B,)).
        radar (B,): index into the radar table site (R, 2) (m), sigma_r, sigma_b, sigma_vr
            (R,) (m, rad, m/s).
        sigma_a: process-noise acceleration std (m/s²); v0: start velocity std (m/s).
        prm: (4,) the UKF's (λ + n, Wm₀, Wc₀, W).
        xs (K, M, 4), Ps (K, M, 4, 4), started (K,), last_t (K,): every slot's tracks,
            updated in place.
        out_x (B, M, 4), out_P (B, M, 4, 4): each plot's posterior per method.
        out_nis (B, M): each update's NIS (``core.filters.innovation``: the position stage's
            plus the Doppler stage's when the plot has V̂r; ``ekf`` and ``ukf`` the EKF's
            linearised statistics, as the numpy engine); NaN at a start (no prediction).
    """
    n_m = codes.shape[0]
    n_r = sigma_r.shape[0]
    # The conversions' noise-only scalars, once per radar and method (not per plot).
    co = np.empty((n_r, n_m, 8))
    co_s = np.empty((n_r, n_m, 8))
    for g in range(n_r):
        s, sr2 = sigma_b[g] * sigma_b[g], sigma_r[g] * sigma_r[g]
        for j in range(n_m):
            co[g, j, :] = coefficients(codes[j], s, sr2)
            co_s[g, j, :] = coefficients(start_codes[j], s, sr2)
    q = sigma_a * sigma_a
    K = np.empty((4, 4))
    L = np.empty((4, 4))
    Z = np.empty((9, 2))
    E = np.empty(4)
    x, P = np.empty(4), np.empty((4, 4))
    for i in range(slot.shape[0]):
        k, g = slot[i], radar[i]
        r, b = r_m[i], az_rad[i]
        sx, sy = site[g, 0], site[g, 1]
        sr2, s = sigma_r[g] * sigma_r[g], sigma_b[g] * sigma_b[g]
        new = not started[k]
        dt = 0.0
        if not new:
            dt = time_s[i] - last_t[k]
            if dt < 0.0:
                return i
        for j in range(n_m):
            code = codes[j]
            nis = np.nan
            if new:
                zx, zy, r00, r01, r11 = convert(start_codes[j], r, b, sr2, s, 0.0, 0.0, co_s[g, j])
                start(x, P, zx + sx, zy + sy, r00, r01, r11, v0)
            else:
                for a in range(4):
                    x[a] = xs[k, j, a]
                    for c in range(4):
                        P[a, c] = Ps[k, j, a, c]
                if dt > 0.0:
                    predict(x, P, dt, q)
                px, py = x[0] - sx, x[2] - sy
                if code >= 5:  # ekf, ukf: ν' = J ν and R' = J R Jᵀ at the prediction
                    rp = hypot(px, py)
                    cb, sb_ = px / rp, py / rp
                    nr, nb = r - rp, wrap(b - atan2(py, px))
                    nx, ny = cb * nr - py * nb, sb_ * nr + px * nb
                    r00 = cb * cb * sr2 + py * py * s
                    r01 = cb * sb_ * sr2 - px * py * s
                    r11 = sb_ * sb_ * sr2 + px * px * s
                else:
                    zx, zy, r00, r01, r11 = convert(code, r, b, sr2, s, px, py, co[g, j])
                    nx, ny = zx + sx - x[0], zy + sy - x[2]
                nis = position_nis(P, nx, ny, r00, r01, r11)
                if code == 6:
                    ukf_update(x, P, r, b, sr2, s, sx, sy, prm, L, Z, K, E)
                else:
                    position_update(x, P, nx, ny, r00, r01, r11, K, L)
            if has_vr[i]:
                var_vr = sigma_vr[g] * sigma_vr[g]
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
