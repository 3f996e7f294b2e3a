"""The compiled scalar reference of ``radarviz bench``: the plain textbook filter, one track at
a time, as tight as scalar code gets.

The Monte Carlo engine (``core.filters.compiled``) is timed against this: the same filter
written independently and without any of the engine's generality (no chunks, no metric
terms, no start from a given state, no site, no null-direction handling), one small numba
function per method, serial, ``fastmath`` allowed. Each track's state lives in local scalars
(x0 … x3 and the ten entries of the symmetric P) for all its scans, and each scan is the
textbook step:

* predict: x⁻ = F x, P⁻ = F P Fᵀ + Q (constant velocity, per axis F = [[1, T], [0, 1]],
  Q = σa² [[T⁴/4, T³/2], [T³/2, T²]]);
* convert: the method's converted point and covariance (Prosov's eq. 8–11, Mo et al.'s
  unbiased conversion, Bordonaro et al.'s decorrelated one), or the polar model;
* update: S = H P⁻ Hᵀ + R, K = P⁻ Hᵀ S⁻¹, x⁺ = x⁻ + K ν, and the Joseph form
  P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ (the engine's covariance update, so the work is
  the same); the polar EKF with the Jacobian H of (r, β) at the prediction; the UKF with
  Van der Merwe's 2n + 1 points and P⁺ = P⁻ − K S Kᵀ; the Doppler update of V̂r = û·v along
  the measured line of sight after the EKF's.

Tracks start from the first plot (the method's start conversion, velocity 0 with std σv0),
as the engine's do. Each function writes the final state of every track, x (m, 4) and P
(m, 4, 4); ``tests/test_scalar_reference.py`` checks it equals the engine's to rounding (a
like-for-like comparison needs the same numbers).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba
import numpy as np
from numpy.typing import NDArray

_jit = numba.njit(cache=True, fastmath=True, error_model="numpy")
_TWO_PI = 2.0 * math.pi

#: The references, by ``core.filters.compiled.COMPILED_METHODS`` name, and ``ekf+doppler``.
REFERENCE_METHODS: tuple[str, ...] = (
    "naive",
    "seed",
    "cmkf_d",
    "ucm",
    "ducm",
    "ekf",
    "ukf",
    "ekf+doppler",
)


@_jit
def _wrap(a):
    # the angle a mapped to [−π, π)
    return a - _TWO_PI * math.floor((a + math.pi) / _TWO_PI)


@_jit
def _predict(x, p, T, q):
    """x⁻ = F x and P⁻ = F P Fᵀ + Q with P as its upper entries
    (p00, p01, p02, p03, p11, p12, p13, p22, p23, p33)."""
    x0, x1, x2, x3 = x
    p00, p01, p02, p03, p11, p12, p13, p22, p23, p33 = p
    T2 = T * T
    qa, qb, qc = q * T2 * T2 / 4.0, q * T2 * T / 2.0, q * T2
    return (x0 + T * x1, x1, x2 + T * x3, x3), (
        p00 + 2.0 * T * p01 + T2 * p11 + qa,
        p01 + T * p11 + qb,
        p02 + T * (p03 + p12) + T2 * p13,
        p03 + T * p13,
        p11 + qc,
        p12 + T * p13,
        p13,
        p22 + 2.0 * T * p23 + T2 * p33 + qa,
        p23 + T * p33 + qb,
        p33 + qc,
    )


@_jit
def _position_update(x, p, zx, zy, r00, r01, r11):
    """The Kalman update by a measured position z with covariance R (H picks x and y):
    S = P_pos + R, K = P Hᵀ S⁻¹, x + K (z − H x), Joseph (I − KH) P (I − KH)ᵀ + K R Kᵀ."""
    x0, x1, x2, x3 = x
    p00, p01, p02, p03, _, p12, _, p22, p23, _ = p  # the x, y rows
    s00, s01, s11 = p00 + r00, p02 + r01, p22 + r11
    d = 1.0 / (s00 * s11 - s01 * s01)
    i00, i01, i11 = s11 * d, -s01 * d, s00 * d
    # K = [P Hᵀ] S⁻¹, P Hᵀ = columns 0 and 2 of P
    k00, k01 = p00 * i00 + p02 * i01, p00 * i01 + p02 * i11
    k10, k11 = p01 * i00 + p12 * i01, p01 * i01 + p12 * i11
    k20, k21 = p02 * i00 + p22 * i01, p02 * i01 + p22 * i11
    k30, k31 = p03 * i00 + p23 * i01, p03 * i01 + p23 * i11
    n0, n1 = zx - x0, zy - x2
    xn = (
        x0 + k00 * n0 + k01 * n1,
        x1 + k10 * n0 + k11 * n1,
        x2 + k20 * n0 + k21 * n1,
        x3 + k30 * n0 + k31 * n1,
    )
    return xn, _joseph2(p, k00, k01, k10, k11, k20, k21, k30, k31, r00, r01, r11)


@_jit
def _joseph2(p, k00, k01, k10, k11, k20, k21, k30, k31, r00, r01, r11):
    """(I − K H) P (I − K H)ᵀ + K R Kᵀ for H picking x and y (columns 0 and 2)."""
    p00, p01, p02, p03, p11, p12, p13, p22, p23, p33 = p
    # B = (I − K H) P: row i is P's row i − K_i0 · P's row 0 − K_i1 · P's row 2
    b00 = p00 - k00 * p00 - k01 * p02
    b02 = p02 - k00 * p02 - k01 * p22
    b01 = p01 - k00 * p01 - k01 * p12
    b03 = p03 - k00 * p03 - k01 * p23
    b10 = p01 - k10 * p00 - k11 * p02
    b11 = p11 - k10 * p01 - k11 * p12
    b12 = p12 - k10 * p02 - k11 * p22
    b13 = p13 - k10 * p03 - k11 * p23
    b20 = p02 - k20 * p00 - k21 * p02
    b22 = p22 - k20 * p02 - k21 * p22
    b23 = p23 - k20 * p03 - k21 * p23
    b30 = p03 - k30 * p00 - k31 * p02
    b32 = p23 - k30 * p02 - k31 * p22
    b33 = p33 - k30 * p03 - k31 * p23

    def krk(ai, bi, aj, bj):
        return ai * (r00 * aj + r01 * bj) + bi * (r01 * aj + r11 * bj)

    # (B (I − K H)ᵀ)_ij = B_ij − B_i0 K_j0 − B_i2 K_j1, then + (K R Kᵀ)_ij
    return (
        b00 - b00 * k00 - b02 * k01 + krk(k00, k01, k00, k01),
        b01 - b00 * k10 - b02 * k11 + krk(k00, k01, k10, k11),
        b02 - b00 * k20 - b02 * k21 + krk(k00, k01, k20, k21),
        b03 - b00 * k30 - b02 * k31 + krk(k00, k01, k30, k31),
        b11 - b10 * k10 - b12 * k11 + krk(k10, k11, k10, k11),
        b12 - b10 * k20 - b12 * k21 + krk(k10, k11, k20, k21),
        b13 - b10 * k30 - b12 * k31 + krk(k10, k11, k30, k31),
        b22 - b20 * k20 - b22 * k21 + krk(k20, k21, k20, k21),
        b23 - b20 * k30 - b22 * k31 + krk(k20, k21, k30, k31),
        b33 - b30 * k30 - b32 * k31 + krk(k30, k31, k30, k31),
    )


@_jit
def _start(zx, zy, r00, r01, r11, sigma_v0_mps):
    v = sigma_v0_mps * sigma_v0_mps
    return (zx, 0.0, zy, 0.0), (r00, 0.0, r01, 0.0, v, 0.0, 0.0, r11, 0.0, v)


@_jit
def _store(x, p, m, x_out, P_out):
    for i in range(4):
        x_out[m, i] = x[i]
    p00, p01, p02, p03, p11, p12, p13, p22, p23, p33 = p
    P_out[m, 0, 0], P_out[m, 0, 1], P_out[m, 0, 2], P_out[m, 0, 3] = p00, p01, p02, p03
    P_out[m, 1, 0], P_out[m, 1, 1], P_out[m, 1, 2], P_out[m, 1, 3] = p01, p11, p12, p13
    P_out[m, 2, 0], P_out[m, 2, 1], P_out[m, 2, 2], P_out[m, 2, 3] = p02, p12, p22, p23
    P_out[m, 3, 0], P_out[m, 3, 1], P_out[m, 3, 2], P_out[m, 3, 3] = p03, p13, p23, p33


@_jit
def _naive_point(r, b, sr2, s):
    # eq. 8 (r̂ cos β̂, r̂ sin β̂) with the linearised covariance of eq. 9
    c, sn = math.cos(b), math.sin(b)
    rs = r * r * s
    return (
        r * c,
        r * sn,
        sr2 * c * c + rs * sn * sn,
        (sr2 - rs) * sn * c,
        sr2 * sn * sn + rs * c * c,
    )


@_jit
def naive(r_hat, b_hat, sigma_r_m, sigma_beta_rad, T, q, sigma_v0_mps, x_out, P_out):
    """The naive converted-measurement filter (eq. 8, 9)."""
    sr2, s = sigma_r_m * sigma_r_m, sigma_beta_rad * sigma_beta_rad
    for m in range(r_hat.shape[0]):
        x, p = _start(*_naive_point(r_hat[m, 0], b_hat[m, 0], sr2, s), sigma_v0_mps)
        for n in range(1, r_hat.shape[1]):
            x, p = _predict(x, p, T, q)
            x, p = _position_update(x, p, *_naive_point(r_hat[m, n], b_hat[m, n], sr2, s))
        _store(x, p, m, x_out, P_out)


@_jit
def _averaged_constants(s, sr2):
    """eq. 11's factors: e^(−2s) (cosh 2s − cosh s), e^(−2s) (sinh 2s − sinh s), σr² e^(−2s)
    (2 cosh 2s − cosh s), σr² e^(−2s) (2 sinh 2s − sinh s), e^(−4s), e^s − 1; the first two
    by cosh a − cosh b = 2 sinh((a+b)/2) sinh((a−b)/2) and sinh a − sinh b = 2 cosh((a+b)/2)
    sinh((a−b)/2), which do not cancel at small s."""
    e2 = math.exp(-2.0 * s)
    h = math.sinh(0.5 * s)
    return (
        e2 * 2.0 * math.sinh(1.5 * s) * h,
        e2 * 2.0 * math.cosh(1.5 * s) * h,
        sr2 * e2 * (2.0 * math.cosh(2.0 * s) - math.cosh(s)),
        sr2 * e2 * (2.0 * math.sinh(2.0 * s) - math.sinh(s)),
        math.exp(-4.0 * s),
        math.expm1(s),
    )


@_jit
def _averaged_point(r, b, kappa, sr2, k):
    # κ r̂ (cos β̂, sin β̂) with Prosov's eq. 11a–c at the measurement
    c, sn = math.cos(b), math.sin(b)
    c2, s2, r2 = c * c, sn * sn, r * r
    ac, as_, bc, bs, e4, em1 = k
    c11 = r2 * (c2 * ac + s2 * as_) + c2 * bc + s2 * bs
    c22 = r2 * (s2 * ac + c2 * as_) + s2 * bc + c2 * bs
    c12 = sn * c * e4 * (sr2 - (r2 + sr2) * em1)
    return kappa * r * c, kappa * r * sn, c11, c12, c22


@_jit
def _averaged(r_hat, b_hat, sigma_r_m, sigma_beta_rad, T, q, sigma_v0_mps, kappa, x_out, P_out):
    sr2, s = sigma_r_m * sigma_r_m, sigma_beta_rad * sigma_beta_rad
    k = _averaged_constants(s, sr2)
    for m in range(r_hat.shape[0]):
        x, p = _start(*_averaged_point(r_hat[m, 0], b_hat[m, 0], kappa, sr2, k), sigma_v0_mps)
        for n in range(1, r_hat.shape[1]):
            x, p = _predict(x, p, T, q)
            z = _averaged_point(r_hat[m, n], b_hat[m, n], kappa, sr2, k)
            x, p = _position_update(x, p, *z)
        _store(x, p, m, x_out, P_out)


@_jit
def seed(r_hat, b_hat, sigma_r_m, sigma_beta_rad, T, q, sigma_v0_mps, x_out, P_out):
    """Prosov's correction as printed: κ = 1 − σβ²/2 (eq. 10), covariance eq. 11."""
    s = sigma_beta_rad * sigma_beta_rad
    _averaged(
        r_hat, b_hat, sigma_r_m, sigma_beta_rad, T, q, sigma_v0_mps, 1.0 - s / 2.0, x_out, P_out
    )


@_jit
def cmkf_d(r_hat, b_hat, sigma_r_m, sigma_beta_rad, T, q, sigma_v0_mps, x_out, P_out):
    """Lerro and Bar-Shalom's debiasing κ = 1 − (e^(−s) − e^(−s/2)), covariance eq. 11."""
    s = sigma_beta_rad * sigma_beta_rad
    _averaged(
        r_hat,
        b_hat,
        sigma_r_m,
        sigma_beta_rad,
        T,
        q,
        sigma_v0_mps,
        1.0 - (math.exp(-s) - math.exp(-s / 2.0)),
        x_out,
        P_out,
    )


@_jit
def _ucm_constants(s, sr2):
    """Mo et al.'s covariance e^s Cov(naive point | r, β) = R(φ) diag(a, b) R(φ)ᵀ + c-term with
    a = ½ e^s (σr² (1 + e^(−2s)) + r² (1 − e^(−s))²), b = ½ e^s (σr² + r²)(1 − e^(−2s)),
    c = e^s (σr² e^(−2s) − r² e^(−s) (1 − e^(−s))): their coefficients of r² and 1."""
    es, e1, e2 = math.exp(s), math.exp(-s), math.exp(-2.0 * s)
    om1, om2 = -math.expm1(-s), -math.expm1(-2.0 * s)
    return (
        math.sqrt(es),
        0.5 * es * om1 * om1,
        0.5 * es * sr2 * (1.0 + e2),
        0.5 * es * om2,
        0.5 * es * om2 * sr2,
        -es * e1 * om1,
        es * sr2 * e2,
    )


@_jit
def _ucm_cov(r2, c, sn, k):
    a = r2 * k[1] + k[2]
    b = r2 * k[3] + k[4]
    cc = r2 * k[5] + k[6]
    return c * c * a + sn * sn * b, sn * c * cc, sn * sn * a + c * c * b


@_jit
def _ucm_point(r, b, k):
    c, sn = math.cos(b), math.sin(b)
    c11, c12, c22 = _ucm_cov(r * r, c, sn, k)
    return k[0] * r * c, k[0] * r * sn, c11, c12, c22


@_jit
def ucm(r_hat, b_hat, sigma_r_m, sigma_beta_rad, T, q, sigma_v0_mps, x_out, P_out):
    """Mo et al.'s unbiased conversion e^(s/2) r̂ û(β̂), its covariance at the measurement."""
    k = _ucm_constants(sigma_beta_rad * sigma_beta_rad, sigma_r_m * sigma_r_m)
    for m in range(r_hat.shape[0]):
        x, p = _start(*_ucm_point(r_hat[m, 0], b_hat[m, 0], k), sigma_v0_mps)
        for n in range(1, r_hat.shape[1]):
            x, p = _predict(x, p, T, q)
            x, p = _position_update(x, p, *_ucm_point(r_hat[m, n], b_hat[m, n], k))
        _store(x, p, m, x_out, P_out)


@_jit
def ducm(r_hat, b_hat, sigma_r_m, sigma_beta_rad, T, q, sigma_v0_mps, x_out, P_out):
    """Bordonaro et al.'s decorrelated conversion: ucm's point, the covariance at the
    predicted position (ucm's start: there is no prediction at the first plot)."""
    k = _ucm_constants(sigma_beta_rad * sigma_beta_rad, sigma_r_m * sigma_r_m)
    for m in range(r_hat.shape[0]):
        x, p = _start(*_ucm_point(r_hat[m, 0], b_hat[m, 0], k), sigma_v0_mps)
        for n in range(1, r_hat.shape[1]):
            x, p = _predict(x, p, T, q)
            r, b = r_hat[m, n], b_hat[m, n]
            px, py = x[0], x[2]
            r2 = px * px + py * py
            rp = math.sqrt(r2)
            c11, c12, c22 = _ucm_cov(r2, px / rp, py / rp, k)
            kr = k[0] * r
            x, p = _position_update(x, p, kr * math.cos(b), kr * math.sin(b), c11, c12, c22)
        _store(x, p, m, x_out, P_out)


@_jit
def _ekf_update(x, p, r, b, vr, vb):
    """The polar EKF: h(x) = (|p|, atan2(y, x)), H its Jacobian at the prediction, R =
    diag(σr², σβ²), S = H P Hᵀ + R, K = P Hᵀ S⁻¹, Joseph form with K H in place of H."""
    x0, x1, x2, x3 = x
    p00, p01, p02, p03, _, p12, _, p22, p23, _ = p  # the x, y rows
    r2 = x0 * x0 + x2 * x2
    rp = math.sqrt(r2)
    # H = [[x/r, 0, y/r, 0], [−y/r², 0, x/r², 0]]
    h00, h02 = x0 / rp, x2 / rp
    h10, h12 = -x2 / r2, x0 / r2
    # U = P Hᵀ (4 × 2)
    u00, u01 = p00 * h00 + p02 * h02, p00 * h10 + p02 * h12
    u10, u11 = p01 * h00 + p12 * h02, p01 * h10 + p12 * h12
    u20, u21 = p02 * h00 + p22 * h02, p02 * h10 + p22 * h12
    u30, u31 = p03 * h00 + p23 * h02, p03 * h10 + p23 * h12
    s00 = h00 * u00 + h02 * u20 + vr
    s01 = h00 * u01 + h02 * u21
    s11 = h10 * u01 + h12 * u21 + vb
    d = 1.0 / (s00 * s11 - s01 * s01)
    i00, i01, i11 = s11 * d, -s01 * d, s00 * d
    k00, k01 = u00 * i00 + u01 * i01, u00 * i01 + u01 * i11
    k10, k11 = u10 * i00 + u11 * i01, u10 * i01 + u11 * i11
    k20, k21 = u20 * i00 + u21 * i01, u20 * i01 + u21 * i11
    k30, k31 = u30 * i00 + u31 * i01, u30 * i01 + u31 * i11
    n0, n1 = r - rp, _wrap(b - math.atan2(x2, x0))
    xn = (
        x0 + k00 * n0 + k01 * n1,
        x1 + k10 * n0 + k11 * n1,
        x2 + k20 * n0 + k21 * n1,
        x3 + k30 * n0 + k31 * n1,
    )
    # K H has non-zero columns 0 and 2 only: the Joseph form of a position update with
    # gain columns G_i0 = (K H)_i0, G_i2 = (K H)_i2 and R' = H⁻¹ R H⁻ᵀ is the same matrix;
    # written directly: (I − K H) P (I − K H)ᵀ + K R Kᵀ.
    a = (
        (k00 * h00 + k01 * h10, k00 * h02 + k01 * h12),
        (k10 * h00 + k11 * h10, k10 * h02 + k11 * h12),
        (k20 * h00 + k21 * h10, k20 * h02 + k21 * h12),
        (k30 * h00 + k31 * h10, k30 * h02 + k31 * h12),
    )
    pn = _joseph_kh(p, a)
    pn = (
        pn[0] + vr * k00 * k00 + vb * k01 * k01,
        pn[1] + vr * k00 * k10 + vb * k01 * k11,
        pn[2] + vr * k00 * k20 + vb * k01 * k21,
        pn[3] + vr * k00 * k30 + vb * k01 * k31,
        pn[4] + vr * k10 * k10 + vb * k11 * k11,
        pn[5] + vr * k10 * k20 + vb * k11 * k21,
        pn[6] + vr * k10 * k30 + vb * k11 * k31,
        pn[7] + vr * k20 * k20 + vb * k21 * k21,
        pn[8] + vr * k20 * k30 + vb * k21 * k31,
        pn[9] + vr * k30 * k30 + vb * k31 * k31,
    )
    return xn, pn


@_jit
def _joseph_kh(p, a):
    """(I − A) P (I − A)ᵀ for A = K H with non-zero columns 0 and 2 (a[i] = (A_i0, A_i2))."""
    p00, p01, p02, p03, p11, p12, p13, p22, p23, p33 = p
    (a00, a02), (a10, a12), (a20, a22), (a30, a32) = a
    b00 = p00 - a00 * p00 - a02 * p02
    b02 = p02 - a00 * p02 - a02 * p22
    b01 = p01 - a00 * p01 - a02 * p12
    b03 = p03 - a00 * p03 - a02 * p23
    b10 = p01 - a10 * p00 - a12 * p02
    b11 = p11 - a10 * p01 - a12 * p12
    b12 = p12 - a10 * p02 - a12 * p22
    b13 = p13 - a10 * p03 - a12 * p23
    b20 = p02 - a20 * p00 - a22 * p02
    b22 = p22 - a20 * p02 - a22 * p22
    b23 = p23 - a20 * p03 - a22 * p23
    b30 = p03 - a30 * p00 - a32 * p02
    b32 = p23 - a30 * p02 - a32 * p22
    b33 = p33 - a30 * p03 - a32 * p23
    return (
        b00 - b00 * a00 - b02 * a02,
        b01 - b00 * a10 - b02 * a12,
        b02 - b00 * a20 - b02 * a22,
        b03 - b00 * a30 - b02 * a32,
        b11 - b10 * a10 - b12 * a12,
        b12 - b10 * a20 - b12 * a22,
        b13 - b10 * a30 - b12 * a32,
        b22 - b20 * a20 - b22 * a22,
        b23 - b20 * a30 - b22 * a32,
        b33 - b30 * a30 - b32 * a32,
    )


@_jit
def ekf(r_hat, b_hat, sigma_r_m, sigma_beta_rad, T, q, sigma_v0_mps, x_out, P_out):
    """The polar EKF from the naive start."""
    sr2, s = sigma_r_m * sigma_r_m, sigma_beta_rad * sigma_beta_rad
    for m in range(r_hat.shape[0]):
        x, p = _start(*_naive_point(r_hat[m, 0], b_hat[m, 0], sr2, s), sigma_v0_mps)
        for n in range(1, r_hat.shape[1]):
            x, p = _predict(x, p, T, q)
            x, p = _ekf_update(x, p, r_hat[m, n], b_hat[m, n], sr2, s)
        _store(x, p, m, x_out, P_out)


@_jit
def _doppler_update(x, p, vr_hat, b, var_vr, s):
    """V̂r = û·v + e, û = (cos β̂, sin β̂), var e = σVr² + σβ² ((g·v)² + gᵀ P_vv g) with g =
    (−sin β̂, cos β̂): the scalar Kalman update, h = (0, û_x, 0, û_y), Joseph form."""
    x0, x1, x2, x3 = x
    p00, p01, p02, p03, p11, p12, p13, p22, p23, p33 = p
    c, sn = math.cos(b), math.sin(b)
    gv = -sn * x1 + c * x3
    re = var_vr + s * (gv * gv + sn * sn * p11 + c * c * p33 - 2.0 * sn * c * p13)
    u0, u1 = p01 * c + p03 * sn, p11 * c + p13 * sn
    u2, u3 = p12 * c + p23 * sn, p13 * c + p33 * sn
    sv = c * u1 + sn * u3 + re
    k0, k1, k2, k3 = u0 / sv, u1 / sv, u2 / sv, u3 / sv
    nu = vr_hat - (c * x1 + sn * x3)
    xn = (x0 + k0 * nu, x1 + k1 * nu, x2 + k2 * nu, x3 + k3 * nu)
    # (I − k h) P (I − k h)ᵀ + re k kᵀ = P − k uᵀ − u kᵀ + (h P hᵀ + re) k kᵀ
    return xn, (
        p00 - 2.0 * k0 * u0 + sv * k0 * k0,
        p01 - k0 * u1 - u0 * k1 + sv * k0 * k1,
        p02 - k0 * u2 - u0 * k2 + sv * k0 * k2,
        p03 - k0 * u3 - u0 * k3 + sv * k0 * k3,
        p11 - 2.0 * k1 * u1 + sv * k1 * k1,
        p12 - k1 * u2 - u1 * k2 + sv * k1 * k2,
        p13 - k1 * u3 - u1 * k3 + sv * k1 * k3,
        p22 - 2.0 * k2 * u2 + sv * k2 * k2,
        p23 - k2 * u3 - u2 * k3 + sv * k2 * k3,
        p33 - 2.0 * k3 * u3 + sv * k3 * k3,
    )


@_jit
def ekf_doppler(
    r_hat, b_hat, vr_hat, sigma_r_m, sigma_beta_rad, sigma_vr_mps, T, q, sigma_v0_mps, x_out, P_out
):
    """The polar EKF, then the Doppler update of each plot's V̂r."""
    sr2, s = sigma_r_m * sigma_r_m, sigma_beta_rad * sigma_beta_rad
    var_vr = sigma_vr_mps * sigma_vr_mps
    for m in range(r_hat.shape[0]):
        x, p = _start(*_naive_point(r_hat[m, 0], b_hat[m, 0], sr2, s), sigma_v0_mps)
        for n in range(1, r_hat.shape[1]):
            x, p = _predict(x, p, T, q)
            b = b_hat[m, n]
            x, p = _ekf_update(x, p, r_hat[m, n], b, sr2, s)
            x, p = _doppler_update(x, p, vr_hat[m, n], b, var_vr, s)
        _store(x, p, m, x_out, P_out)


@_jit
def _ukf_update(x, p, r, b, vr, vb, c, wm0, wc0, w, X, Z):
    """The UKF: the 2n + 1 = 9 points χ = x⁻, x⁻ ± (√(c P⁻))_k (Cholesky columns), through
    h(χ) = (|χ_pos|, atan2), bearings relative to the central point's; z̄ = Σ Wm h(χ),
    S = Σ Wc (h − z̄)(h − z̄)ᵀ + R, Pxz = Σ Wc (χ − x⁻)(h − z̄)ᵀ, K = Pxz S⁻¹,
    x⁺ = x⁻ + K ν, P⁺ = P⁻ − K S Kᵀ. X (9, 4) and Z (9, 2) are scratch."""
    p00, p01, p02, p03, p11, p12, p13, p22, p23, p33 = p
    # lower Cholesky factor L of c P
    l00 = math.sqrt(c * p00)
    l10, l20, l30 = c * p01 / l00, c * p02 / l00, c * p03 / l00
    l11 = math.sqrt(c * p11 - l10 * l10)
    l21, l31 = (c * p12 - l20 * l10) / l11, (c * p13 - l30 * l10) / l11
    l22 = math.sqrt(c * p22 - l20 * l20 - l21 * l21)
    l32 = (c * p23 - l30 * l20 - l31 * l21) / l22
    l33 = math.sqrt(c * p33 - l30 * l30 - l31 * l31 - l32 * l32)
    cols = (
        (l00, l10, l20, l30),
        (0.0, l11, l21, l31),
        (0.0, 0.0, l22, l32),
        (0.0, 0.0, 0.0, l33),
    )
    for i in range(4):
        X[0, i] = x[i]
    for k in range(4):
        col = cols[k]
        for i in range(4):
            X[1 + k, i] = x[i] + col[i]
            X[5 + k, i] = x[i] - col[i]
    for j in range(9):
        Z[j, 0] = math.hypot(X[j, 0], X[j, 2])
        Z[j, 1] = math.atan2(X[j, 2], X[j, 0])
    b0 = Z[0, 1]
    zr, zb = wm0 * Z[0, 0], 0.0
    for j in range(1, 9):
        Z[j, 1] = b0 + _wrap(Z[j, 1] - b0)
        zr += w * Z[j, 0]
        zb += w * (Z[j, 1] - b0)
    zb = b0 + zb
    s00, s01, s11 = vr, 0.0, vb
    t00 = t01 = t10 = t11 = t20 = t21 = t30 = t31 = 0.0
    for j in range(9):
        wj = wc0 if j == 0 else w
        dr, db = Z[j, 0] - zr, Z[j, 1] - zb
        s00 += wj * dr * dr
        s01 += wj * dr * db
        s11 += wj * db * db
        e0, e1, e2, e3 = X[j, 0] - x[0], X[j, 1] - x[1], X[j, 2] - x[2], X[j, 3] - x[3]
        t00 += wj * e0 * dr
        t01 += wj * e0 * db
        t10 += wj * e1 * dr
        t11 += wj * e1 * db
        t20 += wj * e2 * dr
        t21 += wj * e2 * db
        t30 += wj * e3 * dr
        t31 += wj * e3 * db
    d = 1.0 / (s00 * s11 - s01 * s01)
    i00, i01, i11 = s11 * d, -s01 * d, s00 * d
    k00, k01 = t00 * i00 + t01 * i01, t00 * i01 + t01 * i11
    k10, k11 = t10 * i00 + t11 * i01, t10 * i01 + t11 * i11
    k20, k21 = t20 * i00 + t21 * i01, t20 * i01 + t21 * i11
    k30, k31 = t30 * i00 + t31 * i01, t30 * i01 + t31 * i11
    n0, n1 = r - zr, _wrap(b - zb)
    xn = (
        x[0] + k00 * n0 + k01 * n1,
        x[1] + k10 * n0 + k11 * n1,
        x[2] + k20 * n0 + k21 * n1,
        x[3] + k30 * n0 + k31 * n1,
    )

    def kskt(ai, bi, aj, bj):
        return ai * (s00 * aj + s01 * bj) + bi * (s01 * aj + s11 * bj)

    return xn, (
        p00 - kskt(k00, k01, k00, k01),
        p01 - kskt(k00, k01, k10, k11),
        p02 - kskt(k00, k01, k20, k21),
        p03 - kskt(k00, k01, k30, k31),
        p11 - kskt(k10, k11, k10, k11),
        p12 - kskt(k10, k11, k20, k21),
        p13 - kskt(k10, k11, k30, k31),
        p22 - kskt(k20, k21, k20, k21),
        p23 - kskt(k20, k21, k30, k31),
        p33 - kskt(k30, k31, k30, k31),
    )


@_jit
def ukf(r_hat, b_hat, sigma_r_m, sigma_beta_rad, T, q, sigma_v0_mps, c, wm0, wc0, w, x_out, P_out):
    """The polar UKF from the naive start; (c, wm0, wc0, w) = ``UKFParams.weights(4)``."""
    sr2, s = sigma_r_m * sigma_r_m, sigma_beta_rad * sigma_beta_rad
    X, Z = np.empty((9, 4)), np.empty((9, 2))
    for m in range(r_hat.shape[0]):
        x, p = _start(*_naive_point(r_hat[m, 0], b_hat[m, 0], sr2, s), sigma_v0_mps)
        for n in range(1, r_hat.shape[1]):
            x, p = _predict(x, p, T, q)
            x, p = _ukf_update(x, p, r_hat[m, n], b_hat[m, n], sr2, s, c, wm0, wc0, w, X, Z)
        _store(x, p, m, x_out, P_out)


def reference_filter(method: str) -> Callable[..., None]:
    """The reference of a ``REFERENCE_METHODS`` name, called as ``run_reference`` does."""
    return {
        "naive": naive,
        "seed": seed,
        "cmkf_d": cmkf_d,
        "ucm": ucm,
        "ducm": ducm,
        "ekf": ekf,
        "ukf": ukf,
        "ekf+doppler": ekf_doppler,
    }[method]


def run_reference(
    method: str,
    r_hat: NDArray[np.float64],
    b_hat: NDArray[np.float64],
    *,
    sigma_r_m: float,
    sigma_beta_rad: float,
    period_s: float,
    sigma_a_mps2: float,
    sigma_v0_mps: float,
    radial_velocity_mps: NDArray[np.float64] | None = None,
    sigma_vr_mps: float = 1.0,
    ukf_weights: tuple[float, float, float, float] = (4.0, 0.0, 2.0, 0.125),
    out: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The final states x (m, 4), P (m, 4, 4) of m tracks filtered by the reference ``method``
    over r_hat, b_hat (m, N) (m, rad; C order, one run a row), radar at the origin;
    ``ekf+doppler`` also takes radial_velocity_mps (m, N) with σVr ``sigma_vr_mps``.
    ``out``: arrays to write into (the bench reuses them)."""
    m = r_hat.shape[0]
    x, P = (np.empty((m, 4)), np.empty((m, 4, 4))) if out is None else out
    args = (float(sigma_r_m), float(sigma_beta_rad))
    rest = (float(period_s), float(sigma_a_mps2) ** 2, float(sigma_v0_mps))
    if method == "ekf+doppler":
        assert radial_velocity_mps is not None
        ekf_doppler(r_hat, b_hat, radial_velocity_mps, *args, float(sigma_vr_mps), *rest, x, P)
    elif method == "ukf":
        ukf(r_hat, b_hat, *args, *rest, *map(float, ukf_weights), x, P)
    else:
        reference_filter(method)(r_hat, b_hat, *args, *rest, x, P)
    return x, P
