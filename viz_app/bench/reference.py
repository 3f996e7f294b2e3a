"""The reference Kalman filters: the textbook equations in matrix form, one track at a time.

``radarviz bench`` times the Monte Carlo engine (``core.filters.compiled``) against these,
and the tests hold the engine's final states to theirs (``tests/test_reference.py``). They
are written from the equations, not from the engine, and share none of its code: the
conversions below are the papers' formulas, the updates the textbook matrix products. Every
function's docstring writes the equation it implements.

The state is x = (x, ẋ, y, ẏ) with covariance P (4 × 4); the radar is at the origin and
measures range and bearing r̂ = r + v_r, β̂ = β + v_β with v_r ~ N(0, σr²), v_β ~ N(0, σβ²);
s = σβ² (rad²). Each scan is

* predict (constant velocity, white acceleration of std σa): x⁻ = F x, P⁻ = F P Fᵀ + Q, per
  axis F = [[1, T], [0, 1]] and Q = σa² [[T⁴/4, T³/2], [T³/2, T²]];
* update by a measurement z = h(x) + v, v ~ N(0, R), with H the (d × 4) matrix of h (or its
  Jacobian at the prediction): ν = z − h(x⁻), S = H P⁻ Hᵀ + R, K = P⁻ Hᵀ S⁻¹,
  x⁺ = x⁻ + K ν and Joseph's form P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ;

and the methods differ in their measurement:

* ``naive``, ``seed``, ``cmkf_d``, ``ucm``, ``ducm``: a converted measurement, the point z and
  covariance R of a polar-to-Cartesian conversion (Prosov eq. 8–11; Lerro & Bar-Shalom 1993;
  Mo, Song, Zhou, Sun & Bar-Shalom 1998; Bordonaro, Willett & Bar-Shalom 2014), H picking
  the position;
* ``ekf``: z = (r̂, β̂) itself, h(x) = (√(x² + y²), atan2(y, x)), H its Jacobian at x⁻,
  R = diag(σr², σβ²);
* ``ukf``: the same z and h through Van der Merwe's scaled unscented transform (2n + 1 = 9
  sigma points from a Cholesky factor), P⁺ = P⁻ − K S Kᵀ;
* ``ekf+doppler``: the EKF, then the measured radial velocity V̂r = û(β̂)·v + e along the
  measured line of sight, a scalar update.

A track starts at its first plot: position the method's start conversion (``ducm``, having no
prediction yet, starts like ``ucm``; the polar filters from the naive point), velocity 0 with
std σv0 per axis, no correlation between them; the following plots are filtered.

Compiled with numba, serial, for the bench's timing: each filter allocates its small
matrices once per call and its scan loop allocates nothing (``matmul_into`` and the other
helpers write into given arrays). Every function is compiled with ``inline="always"``: numba
inlines the helpers into the filter; compiled as calls, each passing its arrays with their
reference counts, the filters ran 5× slower (measured). fastmath is allowed: the reference
is the plain filter as fast as the compiler makes it, not a second copy of the engine's
rounding.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

#: Compiled and cached, inlined into each caller (module docstring).
_jit = numba.njit(cache=True, fastmath=True, error_model="numpy", inline="always")

#: Every method the reference filters (the bench times each).
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

#: The conversions' codes, which the compiled functions branch on, and the codes by name.
NAIVE, SEED, CMKF_D, UCM, DUCM = 0, 1, 2, 3, 4
CONVERSIONS: dict[str, int] = {
    "naive": NAIVE,
    "seed": SEED,
    "cmkf_d": CMKF_D,
    "ucm": UCM,
    "ducm": DUCM,
}


# --------------------------------------------------------------------------------------------
# Small matrix helpers: each writes its result into a given array (no allocation).
# --------------------------------------------------------------------------------------------


@_jit
def matmul_into(A: Array, B: Array, out: Array) -> None:
    """out = A B, (n × k)(k × m); out is neither A nor B."""
    n, k = A.shape
    m = B.shape[1]
    for i in range(n):
        for j in range(m):
            acc = 0.0
            for t in range(k):
                acc += A[i, t] * B[t, j]
            out[i, j] = acc


@_jit
def matvec_into(A: Array, v: Array, out: Array) -> None:
    """out = A v; out is not v."""
    n, k = A.shape
    for i in range(n):
        acc = 0.0
        for t in range(k):
            acc += A[i, t] * v[t]
        out[i] = acc


@_jit
def transpose_into(A: Array, out: Array) -> None:
    """out = Aᵀ."""
    n, m = A.shape
    for i in range(n):
        for j in range(m):
            out[j, i] = A[i, j]


@_jit
def add_into(A: Array, B: Array) -> None:
    """A += B."""
    n, m = A.shape
    for i in range(n):
        for j in range(m):
            A[i, j] += B[i, j]


@_jit
def subtract_into(A: Array, B: Array) -> None:
    """A −= B."""
    n, m = A.shape
    for i in range(n):
        for j in range(m):
            A[i, j] -= B[i, j]


@_jit
def identity_minus_into(A: Array, out: Array) -> None:
    """out = I − A (A square)."""
    n = A.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] = (1.0 if i == j else 0.0) - A[i, j]


@_jit
def inverse_into(S: Array, out: Array) -> None:
    """out = S⁻¹ for a 1 × 1 or 2 × 2 matrix: 1 / s, or [[d, −b], [−c, a]] / (a d − b c)."""
    if S.shape[0] == 1:
        out[0, 0] = 1.0 / S[0, 0]
        return
    a, b, c, d = S[0, 0], S[0, 1], S[1, 0], S[1, 1]
    det = a * d - b * c
    out[0, 0], out[0, 1] = d / det, -b / det
    out[1, 0], out[1, 1] = -c / det, a / det


@_jit
def cholesky_into(A: Array, L: Array) -> None:
    """The lower triangular L with L Lᵀ = A (A symmetric positive definite), Cholesky–
    Banachiewicz row by row: L_ii = √(A_ii − Σ_{k<i} L_ik²),
    L_ij = (A_ij − Σ_{k<j} L_ik L_jk) / L_jj for j < i."""
    n = A.shape[0]
    for i in range(n):
        for j in range(n):
            L[i, j] = 0.0
        for j in range(i + 1):
            acc = A[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            L[i, j] = math.sqrt(acc) if i == j else acc / L[j, j]


@_jit
def wrap_angle(a: float) -> float:
    """The angle a mapped to [−π, π)."""
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


# --------------------------------------------------------------------------------------------
# The Kalman filter's two steps
# --------------------------------------------------------------------------------------------


@_jit
def constant_velocity_model(period_s: float, sigma_a_mps2: float) -> tuple[Array, Array]:
    """F and Q of the constant-velocity model driven by a white acceleration of std σa held
    over each period (the discrete white-noise acceleration model of Bar-Shalom, Li &
    Kirubarajan 2001: Q = σa² Γ Γᵀ, Γ = (T²/2, T) per axis), for x = (x, ẋ, y, ẏ): per axis
    F = [[1, T], [0, 1]], Q = σa² [[T⁴/4, T³/2], [T³/2, T²]]."""
    T, q = period_s, sigma_a_mps2 * sigma_a_mps2
    F, Q = np.eye(4), np.zeros((4, 4))
    for i in (0, 2):
        F[i, i + 1] = T
        Q[i, i] = q * T**4 / 4.0
        Q[i, i + 1] = Q[i + 1, i] = q * T**3 / 2.0
        Q[i + 1, i + 1] = q * T**2
    return F, Q


class PredictScratch(NamedTuple):
    """F, Fᵀ, Q of the model and the work arrays of ``predict``."""

    F: Array
    Ft: Array
    Q: Array
    x: Array
    FP: Array


@_jit
def predict_scratch(period_s: float, sigma_a_mps2: float) -> PredictScratch:
    """The model's matrices and ``predict``'s work arrays, allocated once per call."""
    F, Q = constant_velocity_model(period_s, sigma_a_mps2)
    Ft = np.empty((4, 4))
    transpose_into(F, Ft)
    return PredictScratch(F, Ft, Q, np.empty(4), np.empty((4, 4)))


@_jit
def predict(x: Array, P: Array, w: PredictScratch) -> None:
    """The Kalman prediction, in place: x⁻ = F x, P⁻ = F P Fᵀ + Q."""
    matvec_into(w.F, x, w.x)
    for i in range(4):
        x[i] = w.x[i]
    matmul_into(w.F, P, w.FP)
    matmul_into(w.FP, w.Ft, P)
    add_into(P, w.Q)


class UpdateScratch(NamedTuple):
    """The work arrays of a Kalman update by a d-dimensional measurement (``kalman_update``):
    Hᵀ, P Hᵀ (4 × d); S, S⁻¹ (d × d); K, K R (4 × d); Kᵀ (d × 4); I − K H, its transpose,
    (I − K H) P and K R Kᵀ (4 × 4)."""

    Ht: Array
    PHt: Array
    S: Array
    Sinv: Array
    K: Array
    KR: Array
    Kt: Array
    A: Array
    At: Array
    AP: Array
    KRKt: Array


@_jit
def update_scratch(d: int) -> UpdateScratch:
    """``kalman_update``'s work arrays for a d-dimensional measurement, allocated once."""
    return UpdateScratch(
        np.empty((4, d)),
        np.empty((4, d)),
        np.empty((d, d)),
        np.empty((d, d)),
        np.empty((4, d)),
        np.empty((4, d)),
        np.empty((d, 4)),
        np.empty((4, 4)),
        np.empty((4, 4)),
        np.empty((4, 4)),
        np.empty((4, 4)),
    )


@_jit
def kalman_update(x: Array, P: Array, H: Array, R: Array, nu: Array, w: UpdateScratch) -> None:
    """The Kalman update by an innovation ν = z − h(x⁻) (d), in place, the covariance in
    Joseph's form (symmetric and positive semi-definite to rounding for any gain):

        S = H P Hᵀ + R,   K = P Hᵀ S⁻¹,   x⁺ = x + K ν,
        P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ

    H (d × 4), R (d × d), d = 1 or 2."""
    d = H.shape[0]
    transpose_into(H, w.Ht)
    matmul_into(P, w.Ht, w.PHt)  # P Hᵀ
    matmul_into(H, w.PHt, w.S)  # H P Hᵀ
    add_into(w.S, R)  # S = H P Hᵀ + R
    inverse_into(w.S, w.Sinv)
    matmul_into(w.PHt, w.Sinv, w.K)  # K = P Hᵀ S⁻¹
    for i in range(4):
        for j in range(d):
            x[i] += w.K[i, j] * nu[j]
    matmul_into(w.K, H, w.AP)  # K H
    identity_minus_into(w.AP, w.A)  # A = I − K H
    transpose_into(w.A, w.At)
    matmul_into(w.A, P, w.AP)  # A P
    matmul_into(w.AP, w.At, P)  # A P Aᵀ
    matmul_into(w.K, R, w.KR)
    transpose_into(w.K, w.Kt)
    matmul_into(w.KR, w.Kt, w.KRKt)  # K R Kᵀ
    add_into(P, w.KRKt)


@_jit
def start_track(z: Array, R: Array, sigma_v0_mps: float, x: Array, P: Array) -> None:
    """A track at its first plot's converted point z with covariance R, velocity 0 with std σv0:
    x = (z_x, 0, z_y, 0), P = [[R_xx, 0, R_xy, 0], [0, σv0², 0, 0], [R_xy, 0, R_yy, 0],
    [0, 0, 0, σv0²]]."""
    x[0], x[1], x[2], x[3] = z[0], 0.0, z[1], 0.0
    P[:, :] = 0.0
    P[0, 0], P[0, 2], P[2, 0], P[2, 2] = R[0, 0], R[0, 1], R[1, 0], R[1, 1]
    P[1, 1] = P[3, 3] = sigma_v0_mps * sigma_v0_mps


@_jit
def store(x: Array, P: Array, m: int, x_out: Array, P_out: Array) -> None:
    """Track m's final state into row m of x_out (m, 4) and P_out (m, 4, 4)."""
    for i in range(4):
        x_out[m, i] = x[i]
        for j in range(4):
            P_out[m, i, j] = P[i, j]


# --------------------------------------------------------------------------------------------
# The converted measurements (the papers' formulas, for the radar at the origin)
# --------------------------------------------------------------------------------------------


@_jit
def naive_conversion(r: float, b: float, var_r: float, s: float, z: Array, R: Array) -> None:
    """Prosov eq. 8 and 9: the point z = r̂ (cos β̂, sin β̂) with the first-order covariance
    J diag(σr², σβ²) Jᵀ (J the Jacobian of (r, β) ↦ r (cos β, sin β) at the measurement):

        R11 = σr² cos²β̂ + r̂² s sin²β̂,   R22 = σr² sin²β̂ + r̂² s cos²β̂,
        R12 = (σr² − r̂² s) sin β̂ cos β̂."""
    c, sn = math.cos(b), math.sin(b)
    rs = r * r * s
    z[0], z[1] = r * c, r * sn
    R[0, 0] = var_r * c * c + rs * sn * sn
    R[1, 1] = var_r * sn * sn + rs * c * c
    R[0, 1] = R[1, 0] = (var_r - rs) * sn * c


@_jit
def averaged_constants(var_r: float, s: float) -> tuple[float, float, float, float, float]:
    """The factors of Prosov's eq. 11 (Lerro & Bar-Shalom's 1993 averaged covariance) that
    depend on σr and σβ only: (e^(−2s)(cosh 2s − cosh s), e^(−2s)(sinh 2s − sinh s),
    σr² e^(−2s)(2 cosh 2s − cosh s), σr² e^(−2s)(2 sinh 2s − sinh s), e^(−4s)); the first two
    by cosh a − cosh b = 2 sinh((a+b)/2) sinh((a−b)/2) and sinh a − sinh b =
    2 cosh((a+b)/2) sinh((a−b)/2), which do not cancel at small s."""
    e2 = math.exp(-2.0 * s)
    h = math.sinh(0.5 * s)
    return (
        e2 * 2.0 * math.sinh(1.5 * s) * h,
        e2 * 2.0 * math.cosh(1.5 * s) * h,
        var_r * e2 * (2.0 * math.cosh(2.0 * s) - math.cosh(s)),
        var_r * e2 * (2.0 * math.sinh(2.0 * s) - math.sinh(s)),
        math.exp(-4.0 * s),
    )


@_jit
def averaged_conversion(
    r: float,
    b: float,
    var_r: float,
    s: float,
    kappa: float,
    k: tuple[float, float, float, float, float],
    z: Array,
    R: Array,
) -> None:
    """The point κ r̂ (cos β̂, sin β̂) (``seed``: Prosov's eq. 10, κ = 1 − s/2; ``cmkf_d``: Lerro
    & Bar-Shalom's debiasing, κ = 1 − (e^(−s) − e^(−s/2))) with Prosov's eq. 11a–c at the
    measurement, k = ``averaged_constants``:

        c11 = r̂² e^(−2s) [cos²β̂ (cosh 2s − cosh s) + sin²β̂ (sinh 2s − sinh s)]
            + σr² e^(−2s) [cos²β̂ (2 cosh 2s − cosh s) + sin²β̂ (2 sinh 2s − sinh s)]
        c22 = the same with sin and cos exchanged
        c12 = sin β̂ cos β̂ e^(−4s) [σr² + (r̂² + σr²)(1 − e^s)]"""
    c, sn = math.cos(b), math.sin(b)
    c2, s2, r2 = c * c, sn * sn, r * r
    a_c, a_s, b_c, b_s, e4 = k
    z[0], z[1] = kappa * r * c, kappa * r * sn
    R[0, 0] = r2 * (c2 * a_c + s2 * a_s) + c2 * b_c + s2 * b_s
    R[1, 1] = r2 * (s2 * a_c + c2 * a_s) + s2 * b_c + c2 * b_s
    R[0, 1] = R[1, 0] = sn * c * e4 * (var_r - (r2 + var_r) * math.expm1(s))


@_jit
def unbiased_constants(var_r: float, s: float) -> tuple[float, float, float, float, float, float]:
    """The factors of Mo et al.'s (1998) covariance that depend on σr and σβ only:

        e^s Cov(r̂ û(β̂) | r, β):  C11 = cos²β A + sin²β B,  C22 = sin²β A + cos²β B,
                                  C12 = sin β cos β C
        A = ½ e^s [σr² (1 + e^(−2s)) + r² (1 − e^(−s))²],  B = ½ e^s (σr² + r²)(1 − e^(−2s)),
        C = e^s [σr² e^(−2s) − r² e^(−s) (1 − e^(−s))]

    (the exact true-conditioned covariance of the naive point, E[r̂² û ûᵀ] − E[r̂ û] E[r̂ û]ᵀ,
    grouped by cos²β, sin²β and sin β cos β), returned as the coefficients of r² and of 1 in
    A, B, C: (A_r², A_1, B_r², B_1, C_r², C_1); 1 − e^(−s) by expm1."""
    es, e1, e2 = math.exp(s), math.exp(-s), math.exp(-2.0 * s)
    om1, om2 = -math.expm1(-s), -math.expm1(-2.0 * s)
    return (
        0.5 * es * om1 * om1,
        0.5 * es * var_r * (1.0 + e2),
        0.5 * es * om2,
        0.5 * es * var_r * om2,
        -es * e1 * om1,
        es * var_r * e2,
    )


@_jit
def unbiased_covariance(
    r: float,
    c: float,
    sn: float,
    k: tuple[float, float, float, float, float, float],
    R: Array,
) -> None:
    """Mo et al.'s covariance (``unbiased_constants``) at range r and bearing (cos, sin) =
    (c, sn): R11 = c² A + sn² B, R22 = sn² A + c² B, R12 = sn c C."""
    r2 = r * r
    A, B, C = r2 * k[0] + k[1], r2 * k[2] + k[3], r2 * k[4] + k[5]
    R[0, 0] = c * c * A + sn * sn * B
    R[1, 1] = sn * sn * A + c * c * B
    R[0, 1] = R[1, 0] = sn * c * C


@_jit
def unbiased_conversion(
    r: float,
    b: float,
    s: float,
    k: tuple[float, float, float, float, float, float],
    z: Array,
    R: Array,
) -> None:
    """Mo, Song, Zhou, Sun & Bar-Shalom's (1998) unbiased conversion (``ucm``): the point
    e^(s/2) r̂ (cos β̂, sin β̂), whose mean given (r, β) is the true position (E[cos v_β] =
    e^(−s/2)), with their covariance evaluated at the measured (r̂, β̂)."""
    c, sn = math.cos(b), math.sin(b)
    kr = math.exp(0.5 * s) * r
    z[0], z[1] = kr * c, kr * sn
    unbiased_covariance(r, c, sn, k, R)


@_jit
def decorrelated_conversion(
    r: float,
    b: float,
    s: float,
    k: tuple[float, float, float, float, float, float],
    px: float,
    py: float,
    z: Array,
    R: Array,
) -> None:
    """Bordonaro, Willett & Bar-Shalom's (2014) decorrelated unbiased conversion (``ducm``):
    ucm's point e^(s/2) r̂ (cos β̂, sin β̂), Mo et al.'s covariance evaluated at the predicted
    position (px, py) (range √(px² + py²), bearing (px, py) / range) instead of at the
    measurement, so the gain does not depend on this measurement's error."""
    c, sn = math.cos(b), math.sin(b)
    kr = math.exp(0.5 * s) * r
    z[0], z[1] = kr * c, kr * sn
    rp = math.sqrt(px * px + py * py)
    unbiased_covariance(rp, px / rp, py / rp, k, R)


@_jit
def convert(
    conversion: int,
    r: float,
    b: float,
    var_r: float,
    s: float,
    averaged: tuple[float, float, float, float, float],
    unbiased: tuple[float, float, float, float, float, float],
    px: float,
    py: float,
    z: Array,
    R: Array,
) -> None:
    """The point z and covariance R of ``conversion`` (``NAIVE`` … ``DUCM``) of (r̂, β̂) = (r, b);
    (px, py) the predicted position (``DUCM`` only)."""
    if conversion == NAIVE:
        naive_conversion(r, b, var_r, s, z, R)
    elif conversion == SEED:
        averaged_conversion(r, b, var_r, s, 1.0 - s / 2.0, averaged, z, R)
    elif conversion == CMKF_D:
        kappa = 1.0 - (math.exp(-s) - math.exp(-s / 2.0))
        averaged_conversion(r, b, var_r, s, kappa, averaged, z, R)
    elif conversion == UCM:
        unbiased_conversion(r, b, s, unbiased, z, R)
    else:
        decorrelated_conversion(r, b, s, unbiased, px, py, z, R)


# --------------------------------------------------------------------------------------------
# The filters, one track at a time
# --------------------------------------------------------------------------------------------


@_jit
def converted_filter(
    conversion: int,
    r_hat: Array,
    b_hat: Array,
    sigma_r_m: float,
    sigma_beta_rad: float,
    period_s: float,
    sigma_a_mps2: float,
    sigma_v0_mps: float,
    x_out: Array,
    P_out: Array,
) -> None:
    """The converted-measurement Kalman filter (CMKF) of each row of (r̂, β̂) (m, N): per scan
    the prediction, then the update by the converted point z with covariance R, where
    H = [[1, 0, 0, 0], [0, 0, 1, 0]] picks the position: ν = z − H x⁻, S = H P⁻ Hᵀ + R, ...
    (``kalman_update``). ``DUCM`` starts like ``UCM``."""
    var_r, s = sigma_r_m * sigma_r_m, sigma_beta_rad * sigma_beta_rad
    averaged, unbiased = averaged_constants(var_r, s), unbiased_constants(var_r, s)
    first = UCM if conversion == DUCM else conversion
    wp, w = predict_scratch(period_s, sigma_a_mps2), update_scratch(2)
    x, P, z, R, nu = np.empty(4), np.empty((4, 4)), np.empty(2), np.empty((2, 2)), np.empty(2)
    H = np.zeros((2, 4))
    H[0, 0] = H[1, 2] = 1.0
    for m in range(r_hat.shape[0]):
        convert(first, r_hat[m, 0], b_hat[m, 0], var_r, s, averaged, unbiased, 0.0, 0.0, z, R)
        start_track(z, R, sigma_v0_mps, x, P)
        for n in range(1, r_hat.shape[1]):
            predict(x, P, wp)
            r, b = r_hat[m, n], b_hat[m, n]
            convert(conversion, r, b, var_r, s, averaged, unbiased, x[0], x[2], z, R)
            nu[0], nu[1] = z[0] - x[0], z[1] - x[2]
            kalman_update(x, P, H, R, nu, w)
        store(x, P, m, x_out, P_out)


@_jit
def polar_jacobian_into(x: Array, H: Array) -> None:
    """The Jacobian of h(x) = (√(x² + y²), atan2(y, x)) at x, with r² = x² + y²:
    H = [[x/r, 0, y/r, 0], [−y/r², 0, x/r², 0]]."""
    r2 = x[0] * x[0] + x[2] * x[2]
    r = math.sqrt(r2)
    H[0, 0], H[0, 1], H[0, 2], H[0, 3] = x[0] / r, 0.0, x[2] / r, 0.0
    H[1, 0], H[1, 1], H[1, 2], H[1, 3] = -x[2] / r2, 0.0, x[0] / r2, 0.0


@_jit
def doppler_update(
    x: Array,
    P: Array,
    vr_hat: float,
    b: float,
    var_vr: float,
    s: float,
    h: Array,
    R: Array,
    nu: Array,
    w: UpdateScratch,
) -> None:
    """The update by a measured radial velocity V̂r along the measured line of sight
    û = (cos β̂, sin β̂): V̂r = û·v + e, so h = (0, cos β̂, 0, sin β̂) (1 × 4), ν = V̂r − û·v̂.
    The bearing error moves û by v_β g, g = (−sin β̂, cos β̂), so e carries v_β (g·v) besides
    the Doppler noise; its variance at the estimate (v̂, P_vv):

        R = σVr² + σβ² ((g·v̂)² + gᵀ P_vv g)."""
    c, sn = math.cos(b), math.sin(b)
    h[0, 0], h[0, 1], h[0, 2], h[0, 3] = 0.0, c, 0.0, sn
    gv = -sn * x[1] + c * x[3]
    gpg = sn * sn * P[1, 1] - 2.0 * sn * c * P[1, 3] + c * c * P[3, 3]
    R[0, 0] = var_vr + s * (gv * gv + gpg)
    nu[0] = vr_hat - (c * x[1] + sn * x[3])
    kalman_update(x, P, h, R, nu, w)


@_jit
def ekf_filter(
    r_hat: Array,
    b_hat: Array,
    vr_hat: Array,
    doppler: bool,
    sigma_r_m: float,
    sigma_beta_rad: float,
    sigma_vr_mps: float,
    period_s: float,
    sigma_a_mps2: float,
    sigma_v0_mps: float,
    x_out: Array,
    P_out: Array,
) -> None:
    """The polar extended Kalman filter from the naive start: per scan the prediction, then
    the update by z = (r̂, β̂) with h(x) = (√(x² + y²), atan2(y, x)), H its Jacobian at x⁻
    (``polar_jacobian_into``), R = diag(σr², σβ²), ν = (r̂ − h_r, β̂ − h_β wrapped to [−π, π));
    with ``doppler`` then the update by V̂r (``doppler_update``)."""
    var_r, s = sigma_r_m * sigma_r_m, sigma_beta_rad * sigma_beta_rad
    wp, w2, w1 = predict_scratch(period_s, sigma_a_mps2), update_scratch(2), update_scratch(1)
    x, P, z, R, nu = np.empty(4), np.empty((4, 4)), np.empty(2), np.empty((2, 2)), np.empty(2)
    H, h, Rd, nud = np.empty((2, 4)), np.empty((1, 4)), np.empty((1, 1)), np.empty(1)
    Rp = np.zeros((2, 2))
    Rp[0, 0], Rp[1, 1] = var_r, s
    var_vr = sigma_vr_mps * sigma_vr_mps
    for m in range(r_hat.shape[0]):
        naive_conversion(r_hat[m, 0], b_hat[m, 0], var_r, s, z, R)
        start_track(z, R, sigma_v0_mps, x, P)
        for n in range(1, r_hat.shape[1]):
            predict(x, P, wp)
            r, b = r_hat[m, n], b_hat[m, n]
            polar_jacobian_into(x, H)
            nu[0] = r - math.sqrt(x[0] * x[0] + x[2] * x[2])
            nu[1] = wrap_angle(b - math.atan2(x[2], x[0]))
            kalman_update(x, P, H, Rp, nu, w2)
            if doppler:
                doppler_update(x, P, vr_hat[m, n], b, var_vr, s, h, Rd, nud, w1)
        store(x, P, m, x_out, P_out)


@_jit
def ukf_filter(
    r_hat: Array,
    b_hat: Array,
    sigma_r_m: float,
    sigma_beta_rad: float,
    period_s: float,
    sigma_a_mps2: float,
    sigma_v0_mps: float,
    lambda_n: float,
    wm0: float,
    wc0: float,
    w_k: float,
    x_out: Array,
    P_out: Array,
) -> None:
    """The polar unscented Kalman filter from the naive start, with Van der Merwe's (2004) scaled
    sigma points (n = 4, λ = α²(n + κ) − n; the weights from ``UKFParams.weights``:
    lambda_n = n + λ, Wm₀ = λ/(n+λ), Wc₀ = Wm₀ + 1 − α² + β, W_k = 1/(2(n+λ))). Per scan the
    prediction, then:

        L L ᵀ = (n + λ) P⁻ (Cholesky),  χ₀ = x⁻,  χ_k = x⁻ + L_k,  χ_{n+k} = x⁻ − L_k
        ζ_j = h(χ_j) = (√(x² + y²), atan2(y, x)), each bearing taken within π of ζ₀'s
        z̄ = Σ Wm_j ζ_j,  S = Σ Wc_j (ζ_j − z̄)(ζ_j − z̄)ᵀ + R,  Pxz = Σ Wc_j (χ_j − x⁻)(ζ_j − z̄)ᵀ
        K = Pxz S⁻¹,  x⁺ = x⁻ + K ν (ν = (r̂, β̂) − z̄, its bearing wrapped),  P⁺ = P⁻ − K S Kᵀ

    with R = diag(σr², σβ²)."""
    var_r, s = sigma_r_m * sigma_r_m, sigma_beta_rad * sigma_beta_rad
    wp = predict_scratch(period_s, sigma_a_mps2)
    x, P, z, R = np.empty(4), np.empty((4, 4)), np.empty(2), np.empty((2, 2))
    cP, L = np.empty((4, 4)), np.empty((4, 4))
    chi, zeta, zbar = np.empty((9, 4)), np.empty((9, 2)), np.empty(2)
    S, Sinv, Pxz = np.empty((2, 2)), np.empty((2, 2)), np.empty((4, 2))
    K, KS, Kt, KSKt = np.empty((4, 2)), np.empty((4, 2)), np.empty((2, 4)), np.empty((4, 4))
    Wm, Wc = np.full(9, w_k), np.full(9, w_k)
    Wm[0], Wc[0] = wm0, wc0
    for m in range(r_hat.shape[0]):
        naive_conversion(r_hat[m, 0], b_hat[m, 0], var_r, s, z, R)
        start_track(z, R, sigma_v0_mps, x, P)
        for n in range(1, r_hat.shape[1]):
            predict(x, P, wp)
            # the sigma points χ (9 × 4) and their images ζ = h(χ) (9 × 2)
            for i in range(4):
                for j in range(4):
                    cP[i, j] = lambda_n * P[i, j]
            cholesky_into(cP, L)
            for i in range(4):
                chi[0, i] = x[i]
                for k in range(4):
                    chi[1 + k, i] = x[i] + L[i, k]
                    chi[5 + k, i] = x[i] - L[i, k]
            for j in range(9):
                zeta[j, 0] = math.sqrt(chi[j, 0] * chi[j, 0] + chi[j, 2] * chi[j, 2])
                zeta[j, 1] = math.atan2(chi[j, 2], chi[j, 0])
            b0 = zeta[0, 1]
            for j in range(1, 9):
                zeta[j, 1] = b0 + wrap_angle(zeta[j, 1] - b0)
            # z̄, S, Pxz
            zbar[0] = zbar[1] = 0.0
            for j in range(9):
                zbar[0] += Wm[j] * zeta[j, 0]
                zbar[1] += Wm[j] * zeta[j, 1]
            S[0, 0], S[0, 1], S[1, 0], S[1, 1] = var_r, 0.0, 0.0, s
            Pxz[:, :] = 0.0
            for j in range(9):
                d0, d1 = zeta[j, 0] - zbar[0], zeta[j, 1] - zbar[1]
                S[0, 0] += Wc[j] * d0 * d0
                S[0, 1] += Wc[j] * d0 * d1
                S[1, 1] += Wc[j] * d1 * d1
                for i in range(4):
                    e = chi[j, i] - x[i]
                    Pxz[i, 0] += Wc[j] * e * d0
                    Pxz[i, 1] += Wc[j] * e * d1
            S[1, 0] = S[0, 1]
            # K = Pxz S⁻¹, x⁺ = x⁻ + K ν, P⁺ = P⁻ − K S Kᵀ
            inverse_into(S, Sinv)
            matmul_into(Pxz, Sinv, K)
            nu0 = r_hat[m, n] - zbar[0]
            nu1 = wrap_angle(b_hat[m, n] - zbar[1])
            for i in range(4):
                x[i] += K[i, 0] * nu0 + K[i, 1] * nu1
            matmul_into(K, S, KS)
            transpose_into(K, Kt)
            matmul_into(KS, Kt, KSKt)
            subtract_into(P, KSKt)
        store(x, P, m, x_out, P_out)


def run_reference(
    method: str,
    r_hat: Array,
    b_hat: Array,
    *,
    sigma_r_m: float,
    sigma_beta_rad: float,
    period_s: float,
    sigma_a_mps2: float,
    sigma_v0_mps: float,
    radial_velocity_mps: Array | None = None,
    sigma_vr_mps: float = 1.0,
    ukf_weights: tuple[float, float, float, float] = (4.0, 0.0, 2.0, 0.125),
    out: tuple[Array, Array] | None = None,
) -> tuple[Array, Array]:
    """The final states x (m, 4), P (m, 4, 4) of m tracks filtered by the reference ``method``
    over r_hat, b_hat (m, N) (m, rad; one track a row), radar at the origin; ``ekf+doppler``
    also takes radial_velocity_mps (m, N) with std ``sigma_vr_mps``. ``ukf_weights``:
    ``UKFParams.weights(4)`` (the default is α = 1, β = 2, κ = 0). ``out``: arrays to write
    into (the bench reuses them)."""
    m = r_hat.shape[0]
    x, P = (np.empty((m, 4)), np.empty((m, 4, 4))) if out is None else out
    r, b = np.ascontiguousarray(r_hat, dtype=np.float64), np.ascontiguousarray(b_hat, np.float64)
    noise = (float(sigma_r_m), float(sigma_beta_rad))
    model = (float(period_s), float(sigma_a_mps2), float(sigma_v0_mps))
    if method in CONVERSIONS:
        converted_filter(CONVERSIONS[method], r, b, *noise, *model, x, P)
    elif method in ("ekf", "ekf+doppler"):
        doppler = method == "ekf+doppler"
        if doppler:
            if radial_velocity_mps is None:
                raise ValueError("ekf+doppler needs radial_velocity_mps")
            vr = np.ascontiguousarray(radial_velocity_mps, dtype=np.float64)
        else:
            vr = r  # not read
        ekf_filter(r, b, vr, doppler, *noise, float(sigma_vr_mps), *model, x, P)
    elif method == "ukf":
        ukf_filter(r, b, *noise, *model, *map(float, ukf_weights), x, P)
    else:
        raise ValueError(f"method must be one of {', '.join(REFERENCE_METHODS)} (got {method!r})")
    return x, P
