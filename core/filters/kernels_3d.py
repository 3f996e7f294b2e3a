"""The compiled (numba) 3D tracker kernel: the seven methods in 3D and the Doppler update as
scalar loops, the 6 × 6 state (x, ẋ, y, ẏ, z, ż) in small arrays, one plot at a time.

It mirrors the numpy engine's 3D route line by line:

=========  =========================================================================
kind       the lines it mirrors
=========  =========================================================================
predict    ``core.filters.predict.cv_predict`` in 3D (per axis [[1, T], [0, 1]], Q)
converted  ``core.conversion.spatial`` (the five conversions: moments of each angle,
           ``_combined_cov``, the per-axis scales) → ``core.filters.position``
ekf        ``core.filters.polar_ekf.ekf_pseudo_measurement`` (ν' = J ν, R' = J R Jᵀ) →
           the position update
ukf        ``core.filters.polar_ukf.ukf_update`` (13 sigma points, bearing averaged
           relative to the central point, Joseph form as a sum over the points)
doppler    ``core.filters.doppler.doppler_update`` with the elevation terms
=========  =========================================================================

The numpy engine stays the reference (``tests/test_track_compiled.py`` holds every method, with
and without Doppler, to it at 1e-9 relative). Imported on first use only.
"""

from __future__ import annotations

import math
from math import atan2, cos, exp, expm1, hypot, log, sin, sqrt

import numpy as np

from radarviz.core.conversion.elementwise import CMKF_D, NAIVE, SEED, UCM
from radarviz.core.filters.codes import UKF
from radarviz.core.filters.kernels_2d import (
    _inline,
    _jit,
    add_process_noise_c,
    is_polar_c,
    predict_components_c,
    reads_prediction_c,
    white_acceleration_c,
    wrap,
)
from radarviz.core.filters.kernels_track import time_step
from radarviz.core.filters.polar_ukf import SEMIDEFINITE_RTOL


@_jit
def exponentials(s: float, out):
    # The noise-only factors of ``moments`` for an angle variance s: out = (e^(−s/2), e^(−s),
    # e^(−2s), 1 − e^(−s), 1 − e^(−2s)) (once per radar, not per plot, method and model)
    out[0], out[1], out[2] = exp(-s / 2.0), exp(-s), exp(-2.0 * s)
    out[3], out[4] = -expm1(-s), -expm1(-2.0 * s)


@_jit
def noise_table(sb2: float, se2: float, out):
    # A radar's noise-only factors of the conversions, out (5, 5): rows 0–3 the
    # ``exponentials`` of σβ², σε², 2σβ², 2σε²; row 4 the scales (cmkf_d's κ_xy, κ_z, then
    # ucm's and ducm's κ_xy, κ_z, 0) of ``convert_3d`` with s_xy = σβ² + σε², s_z = σε²
    exponentials(sb2, out[0])
    exponentials(se2, out[1])
    exponentials(2.0 * sb2, out[2])
    exponentials(2.0 * se2, out[3])
    s_xy, s_z = sb2 + se2, se2
    out[4, 0] = 1.0 - (exp(-s_xy) - exp(-s_xy / 2.0))
    out[4, 1] = 1.0 - (exp(-s_z) - exp(-s_z / 2.0))
    out[4, 2], out[4, 3], out[4, 4] = exp(s_xy / 2.0), exp(s_z / 2.0), 0.0


@_jit
def conversion_scratch(radars: int):
    # The conversions' per-kernel arrays: the noise table of every radar (radars, 5, 5) and
    # ``conv`` = (mb, me, tmp (9,) scratch, trig (4,), ex (5, 5)) that ``plot_factors`` fills
    # per plot
    return np.empty((radars, 5, 5)), (
        np.empty(9),
        np.empty(9),
        np.empty(9),
        np.empty(4),
        np.empty((5, 5)),
    )


@_inline
def plot_factors(b: float, el: float, ex_g, conv):
    # A plot's factors of the conversions and the Doppler stage, once per plot for every
    # method and model: trig = (cos β̂, sin β̂, cos ε̂, sin ε̂), and its radar's noise table
    trig, ex = conv[3], conv[4]
    trig[0], trig[1], trig[2], trig[3] = cos(b), sin(b), cos(el), sin(el)
    for a in range(5):
        for c in range(5):
            ex[a, c] = ex_g[a, c]


# The per-plot stages below are inlined into the kernels (``_inline``): a compiled call with a
# dozen array arguments costs more than the 3D position update it makes (measured: 270 against
# 105 ns for a position stage). The angle moments and ``combined_cov`` stay calls: inlined, the
# results of one target came to depend by rounding on the other targets' in the block (the
# bit-for-bit test of a target of many against its plots alone failed), and a call is only
# made by the converted methods, once per plot.


@_jit
def moments(c: float, sn: float, ex, out):
    # core.conversion.planar._angle_moments_cs, then spatial._given_truth: out = (ecc, ess,
    # esc, vcc, vss, csc, mc, ms, mc²) of θ̂ ~ N(θ, s), (c, sn) = (cos θ, sin θ), ex the
    # ``exponentials`` of s
    cc, ss, sc = c * c, sn * sn, sn * c
    e_half, e1, e2, om1, om2 = ex[0], ex[1], ex[2], ex[3], ex[4]
    out[0] = 0.5 * (cc * (1.0 + e2) + ss * om2)
    out[1] = 0.5 * (ss * (1.0 + e2) + cc * om2)
    out[2] = e2 * sc
    out[3] = 0.5 * (cc * om1 * om1 + ss * om2)
    out[4] = 0.5 * (ss * om1 * om1 + cc * om2)
    out[5] = -e1 * om1 * sc
    out[6] = e_half * c
    out[7] = e_half * sn
    out[8] = out[6] * out[6]


@_jit
def posterior_moments(c: float, sn: float, ex, ex2, out, tmp):
    # spatial._posterior_average: the moments averaged over the truth θ ~ N(θ̂, s); ex, ex2
    # the ``exponentials`` of s and 2s
    moments(c, sn, ex2, out)  # ecc, ess, esc of variance 2s
    moments(c, sn, ex, tmp)
    e1, om1, om2 = ex[1], ex[3], ex[4]
    half1, half2 = 0.5 * om1 * om1, 0.5 * om2
    out[3] = half1 * tmp[0] + half2 * tmp[1]
    out[4] = half1 * tmp[1] + half2 * tmp[0]
    out[5] = -e1 * om1 * tmp[2]
    out[6] = e1 * c
    out[7] = e1 * sn
    out[8] = e1 * tmp[0]


@_jit
def combined_cov(range_sq: float, var_r: float, e, b, R):
    # spatial._combined_cov: σr² E[u uᵀ] + range_sq Cov(u), from elevation moments e and
    # azimuth moments b (indices as ``moments``)
    xx = var_r * (e[0] * b[0]) + range_sq * (e[3] * b[0] + e[8] * b[3])
    xy = var_r * (e[0] * b[2]) + range_sq * (e[3] * b[2] + e[8] * b[5])
    yy = var_r * (e[0] * b[1]) + range_sq * (e[3] * b[1] + e[8] * b[4])
    xz = var_r * (e[2] * b[6]) + range_sq * (e[5] * b[6])
    yz = var_r * (e[2] * b[7]) + range_sq * (e[5] * b[7])
    zz = var_r * e[1] + range_sq * e[4]
    R[0, 0], R[0, 1], R[0, 2] = xx, xy, xz
    R[1, 0], R[1, 1], R[1, 2] = xy, yy, yz
    R[2, 0], R[2, 1], R[2, 2] = xz, yz, zz


@_jit
def given_truth_cov(r, cos_b, sin_b, cos_e, sin_e, sr2: float, ex, R, mb, me):
    # spatial.naive_cov_given_truth_3d at (r, β, ε), (cos_b, sin_b, cos_e, sin_e) =
    # (cos β, sin β, cos ε, sin ε); ex the radar's ``noise_table``
    moments(cos_b, sin_b, ex[0], mb)
    moments(cos_e, sin_e, ex[1], me)
    combined_cov(r * r, sr2, me, mb, R)


@_inline
def convert_3d(code, r, sr2, sb2, se2, px, py, pz, z, R, conv):
    # spatial.convert_3d: the radar-centred point z (3,) and covariance R (3, 3) of
    # (r̂, β̂, ε̂), whose cosines, sines and radar's noise table ``plot_factors`` put in
    # ``conv``; (px, py, pz): the predicted position minus the site (ducm only)
    mb, me, tmp, trig, ex = conv
    cos_b, sin_b, cos_e, sin_e = trig[0], trig[1], trig[2], trig[3]
    u0, u1, u2 = cos_e * cos_b, cos_e * sin_b, sin_e
    s_xy, s_z = sb2 + se2, se2
    if code == NAIVE:  # naive: J diag(σr², sβ, sε) Jᵀ, J = [u, r ∂u/∂β, r ∂u/∂ε]
        z[0], z[1], z[2] = r * u0, r * u1, r * u2
        jb0, jb1 = r * (-cos_e * sin_b), r * (cos_e * cos_b)
        je0, je1, je2 = r * (-sin_e * cos_b), r * (-sin_e * sin_b), r * cos_e
        jb = (jb0, jb1, 0.0)
        je = (je0, je1, je2)
        uu = (u0, u1, u2)
        for i in range(3):
            for j in range(i, 3):
                R[i, j] = sr2 * uu[i] * uu[j] + sb2 * jb[i] * jb[j] + se2 * je[i] * je[j]
                R[j, i] = R[i, j]  # exactly symmetric (products in one order)
        return
    if code == SEED or code == CMKF_D:
        if code == SEED:  # seed: the naive point + Prosov's second-order term (eq. 10's sign)
            k_xy, k_z = 1.0 - s_xy / 2.0, 1.0 - s_z / 2.0
        else:  # cmkf_d: κ(s) = 1 − (e^(−s) − e^(−s/2)) per axis (``noise_table``)
            k_xy, k_z = ex[4, 0], ex[4, 1]
        z[0], z[1], z[2] = k_xy * (r * u0), k_xy * (r * u1), k_z * (r * u2)
        # averaged_cov_3d: the posterior-averaged moments, E[r²] = r̂² + σr²
        posterior_moments(cos_b, sin_b, ex[0], ex[2], mb, tmp)
        posterior_moments(cos_e, sin_e, ex[1], ex[3], me, tmp)
        combined_cov(r * r + sr2, sr2, me, mb, R)
        return
    # ucm / ducm: κ = e^(s/2) per axis, covariance D C D with C the true-conditioned one,
    # at the measurement (ucm) or at the prediction (ducm)
    k_xy, k_z = ex[4, 2], ex[4, 3]  # e^(s/2) (``noise_table``)
    z[0], z[1], z[2] = k_xy * (r * u0), k_xy * (r * u1), k_z * (r * u2)
    if code == UCM:
        given_truth_cov(r, cos_b, sin_b, cos_e, sin_e, sr2, ex, R, mb, me)
    else:
        rho = hypot(px, py)
        rp = sqrt(rho * rho + pz * pz)
        bp, ep = atan2(py, px), atan2(pz, rho)
        given_truth_cov(rp, cos(bp), sin(bp), cos(ep), sin(ep), sr2, ex, R, mb, me)
    kap = (k_xy, k_xy, k_z)
    for i in range(3):
        for j in range(i, 3):
            R[i, j] = kap[i] * R[i, j] * kap[j]
            R[j, i] = R[i, j]


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
def inverse_3(S, Si) -> float:
    # The inverse of a symmetric 3 × 3 by cofactors; returns the determinant
    a, b, c = S[0, 0], S[0, 1], S[0, 2]
    d, e, f = S[1, 1], S[1, 2], S[2, 2]
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    det = a * c00 + b * c01 + c * c02
    Si[0, 0], Si[0, 1], Si[0, 2] = c00 / det, c01 / det, c02 / det
    Si[1, 1], Si[1, 2] = (a * f - c * c) / det, (b * c - a * e) / det
    Si[2, 2] = (a * d - b * b) / det
    Si[1, 0], Si[2, 0], Si[2, 1] = Si[0, 1], Si[0, 2], Si[1, 2]
    return det


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
def semidefinite_cholesky_3d(P, c: float, L, null_negative: bool = False):
    # The lower Cholesky factor of c·P (6, 6) into L, semi-definite
    # (``core.filters.state.semidefinite_cholesky``): a pivot in [−tol, 0] (with
    # null_negative: any pivot <= 0) is a null direction (its column 0), below −tol the track
    # becomes NaN
    for j in range(6):
        d = c * P[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        tol = SEMIDEFINITE_RTOL * c * P[j, j]
        # a pivot above 0 is a variance, however small
        null = d <= 0.0 if null_negative else -tol <= d <= 0.0
        if null:
            d = 0.0
        elif d < -tol:
            d = math.nan  # indefinite beyond rounding: this track becomes NaN
        d = sqrt(d)
        L[j, j] = d
        for i in range(j + 1, 6):
            e = c * P[i, j]
            for k in range(j):
                e -= L[i, k] * L[j, k]
            L[i, j] = 0.0 if null else e / d
        for i in range(j):
            L[i, j] = 0.0


@_inline
def factored_joseph_3d(P, L, K, m: int, R):
    # core.filters.state.factored_joseph: P⁺ = Z Zᵀ + K R Kᵀ into P (6, 6), Z = L − K (H L)
    # already in L, K's first m columns the gain, R (m, m) the noise
    for i in range(6):
        for j in range(i, 6):
            acc = 0.0
            for a in range(m):
                for b in range(m):
                    acc += K[i, a] * R[a, b] * K[j, b]
            for k in range(6):
                acc += L[i, k] * L[j, k]
            P[i, j] = acc
            P[j, i] = acc


@_inline
def position_update_3d(x, P, nu, R, S, Si, K, U, L):
    # core.filters.position in 3D: S = H P Hᵀ + R, K = P Hᵀ S⁻¹, x⁺ = x + K ν, and the
    # Joseph form on P's Cholesky factor L, P⁺ = Z Zᵀ + K R Kᵀ with Z = L − K (H L)
    # (``core.filters.state.factored_joseph``); L (6, 6) scratch
    for a in range(3):
        for b in range(3):
            S[a, b] = P[2 * a, 2 * b] + R[a, b]
    inverse_3(S, Si)
    for i in range(6):
        for a in range(3):
            U[i, a] = P[i, 2 * a]
    for i in range(6):
        for a in range(3):
            acc = 0.0
            for b in range(3):
                acc += U[i, b] * Si[b, a]
            K[i, a] = acc
    for i in range(6):
        for a in range(3):
            x[i] += K[i, a] * nu[a]
    semidefinite_cholesky_3d(P, 1.0, L, True)
    for k in range(6):  # H L into U: U[k, a] = L[2a, k]
        for a in range(3):
            U[k, a] = L[2 * a, k]
    for i in range(6):  # Z = L − K (H L), in place
        for k in range(6):
            L[i, k] -= K[i, 0] * U[k, 0] + K[i, 1] * U[k, 1] + K[i, 2] * U[k, 2]
    factored_joseph_3d(P, L, K, 3, R)


@_inline
def ekf_measurement_3d(x, r, b, el, sr2, sb2, se2, sx, sy, sz, nu, R):
    # polar_ekf.ekf_pseudo_measurement in 3D: ν' = J ν, R' = J R Jᵀ at the prediction
    dx, dy, dz = x[0] - sx, x[2] - sy, x[4] - sz
    rho = hypot(dx, dy)
    rp = sqrt(rho * rho + dz * dz)
    bp, ep = atan2(dy, dx), atan2(dz, rho)
    u = (dx / rp, dy / rp, dz / rp)
    jb = (-dy, dx, 0.0)
    je = (-dz * dx / rho, -dz * dy / rho, rho)
    nr, nb, ne = r - rp, wrap(b - bp), el - ep
    for i in range(3):
        nu[i] = u[i] * nr + jb[i] * nb + je[i] * ne
        for j in range(i, 3):
            R[i, j] = u[i] * u[j] * sr2 + jb[i] * jb[j] * sb2 + je[i] * je[j] * se2
            R[j, i] = R[i, j]


@_inline
def polar_3(qx: float, qy: float, qz: float, Z, p):
    # core.geometry.polar_coordinates: (r, β, ε) of an offset into Z[p] (ρ by sqrt, not
    # hypot: its guard against overflow costs 13 points × every plot, and a radar's offsets
    # are far from 1e154 m; the two differ in the last bit at most)
    rho = sqrt(qx * qx + qy * qy)
    Z[p, 0] = sqrt(rho * rho + qz * qz)
    Z[p, 1] = atan2(qy, qx)
    Z[p, 2] = atan2(qz, rho)


@_inline
def ukf_update_3d(x, P, r, b, el, sr2, sb2, se2, sx, sy, sz, prm, L, Z, K, S, Si, E):
    # core.filters.polar_ukf.ukf_update in 3D: 2n + 1 = 13 points of (x⁻, P⁻) through the
    # polar map, unscented S and Pxz, K = Pxz S⁻¹, x⁺ = x + K ν, and P⁺ in Joseph form
    # Σ_p Wc_p e_p e_pᵀ + K R Kᵀ with e_p = (χ_p − x⁻) − K d_p.
    c, wm0, wc0, w = prm[0], prm[1], prm[2], prm[3]
    semidefinite_cholesky_3d(P, c, L)
    px, py, pz = x[0] - sx, x[2] - sy, x[4] - sz
    polar_3(px, py, pz, Z, 0)
    for k in range(6):  # Z[1 + 2k] = +column k, Z[2 + 2k] = −column k
        for sgn in range(2):
            f = 1.0 if sgn == 0 else -1.0
            polar_3(px + f * L[0, k], py + f * L[2, k], pz + f * L[4, k], Z, 1 + 2 * k + sgn)
    r0, b0, e0 = Z[0, 0], Z[0, 1], Z[0, 2]
    zr, ze = wm0 * r0, wm0 * e0
    acc = 0.0
    for p in range(1, 13):
        zr += w * Z[p, 0]
        ze += w * Z[p, 2]
        acc += wrap(Z[p, 1] - b0)
    zb = wrap(b0 + w * acc)
    for a in range(3):
        for bb in range(3):
            S[a, bb] = 0.0
    S[0, 0], S[1, 1], S[2, 2] = sr2, sb2, se2
    for p in range(13):
        wp = wc0 if p == 0 else w
        Z[p, 0] -= zr
        Z[p, 1] = wrap(Z[p, 1] - zb)
        Z[p, 2] -= ze
        for a in range(3):
            for bb in range(3):
                S[a, bb] += wp * Z[p, a] * Z[p, bb]
    inverse_3(S, Si)
    nu0, nu1, nu2 = r - zr, wrap(b - zb), el - ze
    for i in range(6):  # Pxz = W Σ_k L[:, k] (d_k+ − d_k−)ᵀ, then K = Pxz S⁻¹
        a0, a1, a2 = 0.0, 0.0, 0.0
        for k in range(6):
            a0 += L[i, k] * (Z[1 + 2 * k, 0] - Z[2 + 2 * k, 0])
            a1 += L[i, k] * (Z[1 + 2 * k, 1] - Z[2 + 2 * k, 1])
            a2 += L[i, k] * (Z[1 + 2 * k, 2] - Z[2 + 2 * k, 2])
        a0 *= w
        a1 *= w
        a2 *= w
        for e in range(3):
            K[i, e] = a0 * Si[0, e] + a1 * Si[1, e] + a2 * Si[2, e]
    for i in range(6):
        x[i] += K[i, 0] * nu0 + K[i, 1] * nu1 + K[i, 2] * nu2
    for i in range(6):  # the central point (e = −K d₀) and K R Kᵀ
        E[i] = K[i, 0] * Z[0, 0] + K[i, 1] * Z[0, 1] + K[i, 2] * Z[0, 2]
    for i in range(6):
        for j in range(i, 6):
            P[i, j] = (
                wc0 * E[i] * E[j]
                + sr2 * K[i, 0] * K[j, 0]
                + sb2 * K[i, 1] * K[j, 1]
                + se2 * K[i, 2] * K[j, 2]
            )
    for k in range(6):  # the points ± column k: e = ±L[:, k] − K d
        for sgn in range(2):
            p, f = 1 + 2 * k + sgn, 1.0 if sgn == 0 else -1.0
            for i in range(6):
                E[i] = f * L[i, k] - (K[i, 0] * Z[p, 0] + K[i, 1] * Z[p, 1] + K[i, 2] * Z[p, 2])
            for i in range(6):
                for j in range(i, 6):
                    P[i, j] += w * E[i] * E[j]
    for i in range(6):
        for j in range(i):
            P[i, j] = P[j, i]


@_inline
def doppler_terms_3d(x, P, trig, var_vr: float, sb2: float, se2: float, u):
    # core.filters.doppler: û = u(β̂, ε̂) into u; returns var e = σVr² + σβ² ((g_β·v)² +
    # g_βᵀ P_vv g_β) + σε² ((g_ε·v)² + g_εᵀ P_vv g_ε), g_β on the first two axes
    ca, sa, ce, se = trig[0], trig[1], trig[2], trig[3]  # ``plot_factors``
    u[0], u[1], u[2] = ce * ca, ce * sa, se
    gb0, gb1 = -ce * sa, ce * ca
    ge0, ge1, ge2 = -se * ca, -se * sa, ce
    v0, v1, v2 = x[1], x[3], x[5]
    gv = gb0 * v0 + gb1 * v1
    gpg = gb0 * gb0 * P[1, 1] + gb1 * gb1 * P[3, 3] + 2.0 * gb1 * gb0 * P[3, 1]
    r_e = var_vr + sb2 * (gv * gv + gpg)
    gv = ge0 * v0 + ge1 * v1 + ge2 * v2
    gpg = ge0 * ge0 * P[1, 1] + ge1 * ge1 * P[3, 3] + ge2 * ge2 * P[5, 5]
    gpg += 2.0 * ge1 * ge0 * P[3, 1] + 2.0 * ge2 * ge0 * P[5, 1] + 2.0 * ge2 * ge1 * P[5, 3]
    return r_e + se2 * (gv * gv + gpg)


@_inline
def doppler_stats_3d(x, P, vr_hat, trig, var_vr, sb2, se2, u):
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
    # ν² / S of ``doppler_stats_3d``
    return doppler_stats_3d(x, P, vr_hat, trig, var_vr, sb2, se2, u)[0]


@_inline
def position_measurement_3d(
    code, x, r, b, el, sr2, sb2, se2, sx, sy, sz, nu, R, z, conv, converted=False
):
    """The position stage of method ``code`` on the prediction x (6,) as a position
    measurement (``MethodGroup.measurement``) into nu (3,) (m) and R (3, 3) (m²): converted
    methods ν = z + site − H x⁻ with the conversion's z (3,) and R; ``ekf`` and ``ukf`` the
    EKF's ν' = J ν, R' = J R Jᵀ at the prediction. ``conv`` (``conversion_scratch``, the
    plot's ``plot_factors`` in it) is
    scratch. ``converted``: z and R hold this plot's conversion already (a conversion that
    does not read the prediction, not ducm, made for another state of the same track)."""
    if is_polar_c(code):
        ekf_measurement_3d(x, r, b, el, sr2, sb2, se2, sx, sy, sz, nu, R)
    else:
        if not (converted and not reads_prediction_c(code)):
            px, py, pz = x[0] - sx, x[2] - sy, x[4] - sz
            convert_3d(code, r, sr2, sb2, se2, px, py, pz, z, R, conv)
        nu[0], nu[1], nu[2] = z[0] + sx - x[0], z[1] + sy - x[2], z[2] + sz - x[4]


@_inline
def start_track_3d(start_code, x, P, r, b, el, sr2, sb2, se2, sx, sy, sz, sigma_v0_mps, z, R, conv):
    """A track started at its first plot into x (6,), P (6, 6): the method's start conversion
    about no prediction, velocity 0 with std ``sigma_v0_mps`` (``Method.start``); z (3,), R (3, 3),
    ``conv``: scratch."""
    convert_3d(start_code, r, sr2, sb2, se2, 0.0, 0.0, 0.0, z, R, conv)
    start_3d(x, P, z, R, sx, sy, sz, sigma_v0_mps)


@_inline
def position_stats_3d(P, nu, R, S, Si):
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
def position_stage_3d(code, x, P, r, b, el, sr2, sb2, se2, sx, sy, sz, nu, R, prm, bufs):
    """The method's update of x (6,), P (6, 6) in place: the UKF (``code`` ``UKF``) or the position
    update by (ν, R); ``bufs`` the scratch (S, Si, K, U, L, Z, E) of ``scratch_3d``."""
    S, Si, K, U, L, Z, E = bufs
    if code == UKF:
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


@_inline
def doppler_update_3d(x, P, vr_hat, trig, var_vr, sb2, se2, u, U, K, L):
    # core.filters.doppler.doppler_update in 3D: U = P hᵀ, S = h U + var e, K = U / S,
    # x⁺ = x + K ν, and the Joseph form on P's Cholesky factor L (6, 6 scratch),
    # P⁺ = Z Zᵀ + var e K Kᵀ with Z = L − K (h L) (``core.filters.state.factored_joseph``)
    r_e = doppler_terms_3d(x, P, trig, var_vr, sb2, se2, u)
    for i in range(6):
        U[i] = P[i, 1] * u[0] + P[i, 3] * u[1] + P[i, 5] * u[2]
    S = u[0] * U[1] + u[1] * U[3] + u[2] * U[5] + r_e
    nu = vr_hat - (u[0] * x[1] + u[1] * x[3] + u[2] * x[5])
    inv_s = 1.0 / S
    for i in range(6):
        K[i] = U[i] * inv_s
        x[i] += K[i] * nu
    semidefinite_cholesky_3d(P, 1.0, L, True)
    for k in range(6):  # h L into U
        U[k] = u[0] * L[1, k] + u[1] * L[3, k] + u[2] * L[5, k]
    for i in range(6):  # Z = L − K (h L), in place
        for k in range(6):
            L[i, k] -= K[i] * U[k]
    for i in range(6):
        for j in range(i, 6):
            acc = r_e * K[i] * K[j]
            for k in range(6):
                acc += L[i, k] * L[j, k]
            P[i, j] = acc
            P[j, i] = acc


@_jit
def track_plots_3d(
    codes, start_codes, slot, time_s, r_m, az_rad, el_rad, vr_mps, has_vr, radar, site,
    sigma_r_m, sigma_beta_rad, sigma_elevation_rad, sigma_vr_mps, sigma_a_mps2, sigma_v0_mps, prm,
    xs, Ps, started, last_t, out_x, out_P, out_nis,
):  # fmt: skip
    """``core.filters.kernels_track.track_plots_2d`` in 3D: plots with elevations el_rad
    (B,), sites (R, 3), σε sigma_elevation_rad (R,), states xs (K, M, 6), Ps (K, M, 6, 6), outputs
    (B, M, 6), (B, M, 6, 6), (B, M); ``prm`` the UKF's weights for n = 6. Returns −1 or the
    index of the first plot before its slot's previous one."""
    n_m = codes.shape[0]
    q = sigma_a_mps2 * sigma_a_mps2
    x, P = np.empty(6), np.empty((6, 6))
    z, nu, u, Uv, Kv = np.empty(3), np.empty(3), np.empty(3), np.empty(6), np.empty(6)
    R = np.empty((3, 3))
    bufs = scratch_3d()
    ex, conv = conversion_scratch(sigma_r_m.shape[0])
    for g in range(sigma_r_m.shape[0]):
        noise_table(sigma_beta_rad[g] ** 2, sigma_elevation_rad[g] ** 2, ex[g])
    trig = conv[3]
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
            code = codes[j]
            nis = np.nan
            if new:
                start_track_3d(
                    start_codes[j], x, P, r, b, el, sr2, sb2, se2, sx, sy, sz, sigma_v0_mps, z,
                    R, conv,
                )  # fmt: skip
            else:
                for a in range(6):
                    x[a] = xs[k, j, a]
                    for c in range(6):
                        P[a, c] = Ps[k, j, a, c]
                if dt > 0.0:
                    predict_3d(x, P, dt, q)
                position_measurement_3d(
                    code, x, r, b, el, sr2, sb2, se2, sx, sy, sz, nu, R, z, conv
                )
                nis = position_stats_3d(P, nu, R, bufs[0], bufs[1])[0]
                position_stage_3d(code, x, P, r, b, el, sr2, sb2, se2, sx, sy, sz, nu, R, prm, bufs)
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
