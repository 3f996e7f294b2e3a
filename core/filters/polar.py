"""Batched EKF and UKF that filter polar radar measurements directly (M runs at once).

Instead of converting each measurement to Cartesian coordinates (``core.conversion.planar``), these
filters keep the constant-velocity state of ``core.filters.cv`` and put the nonlinearity in the
measurement function. A radar at the origin measures range and azimuth, azimuth counted from
the x axis towards the y axis::

    z = h(x) + v,   h(x) = (r, β) = (sqrt(px² + py²), atan2(py, px)),   v ~ N(0, R)
    R = diag(σr², σβ²)                 state x = (px, ṗx, py, ṗy)

Prediction is linear and shared with the converted-measurement filters: use
``core.filters.cv.cv_predict`` unchanged before either update. Both updates are pure functions
``(predicted batch, measurements) → posterior batch``; they follow the equations of filterpy's
``ExtendedKalmanFilter.update`` and ``UnscentedKalmanFilter.update`` (the reference
implementations; over 30 scans the tests find agreement to ~1e-13 relative and assert 1e-9)
but work on all M runs at once with vector operations over the run index.

Angles. A bearing difference is only meaningful modulo 2π. Every innovation (residual) wraps
its bearing component to (−π, π] with ``wrap_angle``, and the UKF averages sigma-point
bearings relative to a reference bearing, so targets near β = ±π are filtered correctly.

Shapes (run index leading, as everywhere in ``core``): state ``x`` (M, 4), ``P`` (M, 4, 4) in
the component-major layout of ``kalman_cv.empty_batch``; measurements ``r``, ``beta`` (M,).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.conversion.planar import convert_naive
from radarviz.core.filters.cv import CVBatch, Vec, _target, cv_init, joseph_update_position

__all__ = ["UKFParams", "ekf_update", "init_from_polar", "ukf_update", "wrap_angle"]

_TWO_PI = 2.0 * np.pi


def wrap_angle(a: ArrayLike) -> NDArray[np.float64]:
    """Wrap angles (rad) to the interval (−π, π].  Elementwise, any shape.

    ``a − 2π·ceil(a/(2π) − ½)``: subtract the whole turns that bring ``a`` nearest to 0, ties
    (±π) going to +π. An angle already in (−π, π] is returned exactly (k = 0), tiny angles
    included; and it is several times faster than ``np.mod``, which matters because every
    update wraps a few (M,) vectors.
    """
    a = np.asarray(a, dtype=np.float64)
    return a - _TWO_PI * np.ceil(a * (1.0 / _TWO_PI) - 0.5)


def _measurements(state: CVBatch, r: ArrayLike, beta: ArrayLike) -> tuple[Vec, Vec]:
    """``r`` and ``beta`` as float64 vectors of length M (the only validation done)."""
    r = np.asarray(r, dtype=np.float64)
    beta = np.asarray(beta, dtype=np.float64)
    m = state.runs
    if r.shape != (m,) or beta.shape != (m,):
        raise ValueError(
            f"r and beta must have shape ({m},) to match the batch (got {r.shape} and {beta.shape})"
        )
    return r, beta


# --------------------------------------------------------------------------------------------
# Initialisation
# --------------------------------------------------------------------------------------------


def init_from_polar(
    r: ArrayLike,
    beta: ArrayLike,
    sigma_r: float,
    sigma_beta: float,
    sigma_v: float = 1000.0,
) -> CVBatch:
    """Start M tracks from their first polar measurement (the spec's initialisation).

    Position = the naive converted point ``r̂ (cos β̂, sin β̂)`` (Prosov eq. 8) with its
    linearized covariance ``J diag(σr², σβ²) Jᵀ`` (eq. 9); velocity = 0 with variance σv² on
    each axis and no correlation with position. Both the EKF and the UKF start this way, so
    they differ from the converted-measurement filters only from the second scan on.

    Args:
        r, beta: (M,) first measured range (m) and azimuth (rad).
        sigma_r, sigma_beta: measurement noise std, m and rad.
        sigma_v: initial velocity std, m/s.

    Returns:
        A new ``CVBatch`` of M runs.
    """
    first = convert_naive(r, beta, sigma_r, sigma_beta)
    return cv_init(first.z, first.R, sigma_v)


# --------------------------------------------------------------------------------------------
# Extended Kalman filter
# --------------------------------------------------------------------------------------------


def ekf_update(
    state: CVBatch,
    r: ArrayLike,
    beta: ArrayLike,
    sigma_r: float,
    sigma_beta: float,
    out: CVBatch | None = None,
) -> CVBatch:
    """EKF measurement update with a polar measurement (r̂, β̂) for every run.

    Linearise h at the predicted state x⁻. Only the position enters h, so the 2 × 4 Jacobian
    factors as H = G·H2, with H2 picking (px, py) and G the 2 × 2 Jacobian of the polar map::

        G = ∂(r, β)/∂(px, py) = [[ px/r,   py/r ],
                                 [−py/r², px/r²]]          r = |p⁻|

    Then the usual (filterpy ``ExtendedKalmanFilter.update``) equations::

        ν = (r̂ − r,  wrap(β̂ − β))              innovation, bearing wrapped to (−π, π]
        S = H P⁻ Hᵀ + R                           innovation covariance, R = diag(σr², σβ²)
        K = P⁻ Hᵀ S⁻¹                             gain
        x⁺ = x⁻ + K ν
        P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ     Joseph form

    How it is computed. G is invertible (r > 0) with inverse J = G⁻¹ = [[px/r, −py],
    [py/r, px]], the Jacobian of the polar-to-Cartesian map (eq. 8) at the prediction. Then
    S = G S' Gᵀ with S' = H2 P⁻ H2ᵀ + J R Jᵀ, and K H = K' H2, K R Kᵀ = K' (J R Jᵀ) K'ᵀ with
    K' = K G = P⁻ H2ᵀ S'⁻¹. So the EKF update *is* a position update (``cv_update``) with

        pseudo-innovation  ν' = J ν   (m)          covariance  R' = J R Jᵀ   (eq. 9 at x⁻)

    and that is how it is evaluated: exactly the same equations, in metres throughout, by
    ``kalman_cv.joseph_update_position`` with gain K'. (Working with the polar gain K and
    K G instead is algebraically equal but mixes m and m/rad, and the difference terms
    cancel quantities ≈ 10⁵ times larger than P⁺, losing ~5 digits: measured 4e-10 relative.)
    Each quantity is one vector of length M, like ``cv_update``: no per-run matrices.

    Because G is evaluated at the *prediction*, the gain does not depend on this scan's
    measurement error (compare the converted ``naive`` filter, whose R uses the measured
    bearing; see ``shared/spec/conversion.md``).

    Args:
        state: predicted batch (output of ``cv_predict``), M runs; must not have r = 0.
        r, beta: (M,) measured range (m) and azimuth (rad).
        sigma_r, sigma_beta: measurement noise std, m and rad.
        out: optional preallocated batch to write into (must not alias ``state``).

    Returns:
        The posterior batch (``out`` if given, else a new one).
    """
    r_meas, b_meas = _measurements(state, r, beta)
    x, P = state.x, state.P
    px, py = x[:, 0], x[:, 2]
    # Predicted measurement h(x⁻) and the entries of J = G⁻¹ = [[px/r, −py], [py/r, px]].
    rp = np.sqrt(px * px + py * py)
    c = px / rp
    sn = py / rp
    nu_r = r_meas - rp
    nu_b = wrap_angle(b_meas - np.arctan2(py, px))
    # Innovation mapped to metres, ν' = J ν.
    nu = (c * nu_r - py * nu_b, sn * nu_r + px * nu_b)
    # S' = H2 P⁻ H2ᵀ + J R Jᵀ (J R Jᵀ is Prosov eq. 9 at the predicted r, β).
    var_r, var_b = sigma_r**2, sigma_beta**2
    s00 = P[:, 0, 0] + (c * c * var_r + py * py * var_b)
    s01 = P[:, 0, 2] + (c * sn * var_r - px * py * var_b)
    s11 = P[:, 2, 2] + (sn * sn * var_r + px * px * var_b)
    inv_det = 1.0 / (s00 * s11 - s01 * s01)
    i00, i01, i11 = s11 * inv_det, -s01 * inv_det, s00 * inv_det
    # K' = P⁻ H2ᵀ S'⁻¹, component-major (4, 2, M) as joseph_update_position wants.
    K = np.empty((4, 2, state.runs))
    for i in range(4):
        u0, u1 = P[:, i, 0], P[:, i, 2]
        K[i, 0] = u0 * i00 + u1 * i01
        K[i, 1] = u0 * i01 + u1 * i11
    return joseph_update_position(state, nu, K, (s00, s01, s11), out)


# --------------------------------------------------------------------------------------------
# Unscented Kalman filter
# --------------------------------------------------------------------------------------------


class UKFParams(NamedTuple):
    """Van der Merwe's scaled sigma points (filterpy ``MerweScaledSigmaPoints(4, α, β, κ)``).

    With n = 4 state dimensions, λ = α²(n + κ) − n and 2n + 1 = 9 points::

        χ₀ = x,   χ_k = x + [√((n+λ)P)]_k,   χ_{n+k} = x − [√((n+λ)P)]_k      k = 1 … n
        Wm₀ = λ/(n+λ),   Wc₀ = Wm₀ + 1 − α² + β,   Wm_k = Wc_k = 1/(2(n+λ))

    where [·]_k is the k-th column of the lower Cholesky factor (the k-th row of filterpy's
    upper factor).

    Defaults α = 1, β = 2, κ = 0 give λ = 0: the points sit at x ± 2·(Cholesky column of P),
    i.e. at ±2σ along each factor direction, Wm₀ = 0, Wc₀ = β = 2 (the Gaussian kurtosis
    correction) and Wm_k = Wc_k = 1/8. No weight is negative, so the unscented S is a
    non-negative combination of outer products plus R (positive definite), and P − K S Kᵀ is the
    Schur complement of a positive semi-definite joint covariance: P⁺ stays positive definite.
    The popular small α (e.g. 1e-3) makes Wm₀ ≈ −10⁶ and Wc₀ < 0; S can then lose
    definiteness, and the huge cancelling weights cost digits. Points at ±2σ are well inside
    the region where the polar map is smooth at radar ranges (2σ cross-range ≪ r).

    Attributes:
        alpha: spread α of the points around the mean (> 0).
        beta: prior-knowledge term β in Wc₀ (2 is optimal for Gaussians).
        kappa: secondary scaling κ.
    """

    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0

    def weights(self, n: int = 4) -> tuple[float, float, float, float]:
        """(λ + n, Wm₀, Wc₀, W) with W = Wm_k = Wc_k the weight of each non-central point."""
        lam = self.alpha**2 * (n + self.kappa) - n
        c = n + lam
        wm0 = lam / c
        return c, wm0, wm0 + 1.0 - self.alpha**2 + self.beta, 0.5 / c


_DEFAULT_UKF = UKFParams()


def ukf_update(
    state: CVBatch,
    r: ArrayLike,
    beta: ArrayLike,
    sigma_r: float,
    sigma_beta: float,
    params: UKFParams = _DEFAULT_UKF,
    out: CVBatch | None = None,
) -> CVBatch:
    """UKF measurement update with a polar measurement (r̂, β̂) for every run.

    The filterpy ``UnscentedKalmanFilter.update`` equations, after a linear ``predict()``
    (which leaves its sigma points drawn from the predicted x⁻, P⁻)::

        χ_i      sigma points of (x⁻, P⁻)        (``UKFParams``; Cholesky square root)
        ζ_i = h(χ_i)                             points through the polar map
        ẑ = Σ Wm_i ζ_i                           bearings averaged relative to ζ₀'s bearing
        S = Σ Wc_i d_i d_iᵀ + R,   d_i = ζ_i ⊖ ẑ   (⊖ wraps the bearing difference)
        Pxz = Σ Wc_i (χ_i − x⁻) d_iᵀ             cross covariance
        K = Pxz S⁻¹
        x⁺ = x⁻ + K (z ⊖ ẑ)
        P⁺ = P⁻ − K S Kᵀ                         (symmetrised: average with its transpose)

    Bearing mean: ẑ_β = wrap(β₀ + Σ Wm_i wrap(β_i − β₀)), with β₀ the bearing of the central
    point. A plain weighted sum would put the mean of bearings straddling ±π near 0.

    Batched without per-run matrices or an (M, 9, 4) sigma-point array: the Cholesky factor is
    written out over the batch as (M,) vectors, and because it is lower triangular and only the
    position enters h, the points χ₄, χ₈ (offsets along the last factor column: ẏ alone) map
    to ζ₀ and drop out of Pxz. So 7 distinct polar evaluations per run, the last factor column
    is never formed, and the peak working memory is about 36 floats per run (measured; about
    0.5 µs per run at M = 8192, dominated by the 7 ``arctan2``). A run whose P⁻ is not positive
    definite gets NaN (see ``_cholesky_columns3``) and leaves the other runs alone (filterpy
    would raise).

    The sigma points, hence the UKF estimate, depend on the orientation of the x–y frame (the
    Cholesky factor of a rotated P is not the rotated factor), unlike the EKF: with the
    ``prosov`` target rotated to β = 0.3 rad the mean cross-range error at scan 30 is ≈ +7 m
    (σβ = 1°, 10⁶ runs, SE 1.2 m), against ≈ 0 at β = 0. Small, but it is not a bug of the
    batching: filterpy's filter does the same.

    Args:
        state: predicted batch (output of ``cv_predict``), M runs.
        r, beta: (M,) measured range (m) and azimuth (rad).
        sigma_r, sigma_beta: measurement noise std, m and rad.
        params: sigma-point parameters (α, β, κ).
        out: optional preallocated batch to write into (must not alias ``state``).

    Returns:
        The posterior batch (``out`` if given, else a new one).
    """
    r_meas, b_meas = _measurements(state, r, beta)
    x, P = state.x, state.P
    n = 4
    c, wm0, wc0, w = params.weights(n)
    col = _cholesky_columns3(P, np.sqrt(c))  # entries (i, k) of √((n+λ)P⁻), k <= min(i, 2)

    # Sigma points through h. Offsets of χ_{k+1}, χ_{n+k+1} are ±column k; the position
    # (components 0 and 2) moves only for k = 0 (both) and k = 1, 2 (py only).
    px, py = x[:, 0], x[:, 2]
    r0 = np.sqrt(px * px + py * py)
    b0 = np.arctan2(py, px)
    zr: list[Vec] = []  # ranges of χ_{+0}, χ_{−0}, χ_{+1}, χ_{−1}, χ_{+2}, χ_{−2}
    zb: list[Vec] = []  # their bearings
    for k in range(3):
        for sign in (1.0, -1.0):
            qx = px + sign * col[0, 0] if k == 0 else px
            qy = py + sign * col[2, k]
            zr.append(np.sqrt(qx * qx + qy * qy))
            zb.append(np.arctan2(qy, qx))
    del qx, qy
    # χ₀ and χ_{±3} all map to (r0, b0): weight Wm₀ + 2W on it in the mean, Wc₀ + 2W in S.
    # Unscented mean ẑ; bearings relative to b0 (a wrapped difference of b0 itself is 0).
    r_mean = zr[0] + zr[1]
    b_rel = wrap_angle(zb[0] - b0)
    for i in range(1, 6):
        if i > 1:
            r_mean += zr[i]
        b_rel += wrap_angle(zb[i] - b0)
    r_mean *= w
    r_mean += (wm0 + 2.0 * w) * r0
    b_rel *= w
    b_rel += b0
    b_mean = wrap_angle(b_rel)
    del b_rel
    # Residuals d_i = ζ_i ⊖ ẑ, in place, and the unscented S = Σ Wc_i d_i d_iᵀ + R.
    d_r = r0 - r_mean
    d_b = wrap_angle(b0 - b_mean)
    wcc = wc0 + 2.0 * w
    s00 = (wcc * d_r) * d_r
    s01 = (wcc * d_r) * d_b
    s11 = (wcc * d_b) * d_b
    del d_r, d_b
    acc00 = np.zeros_like(r0)
    acc01 = np.zeros_like(r0)
    acc11 = np.zeros_like(r0)
    for i in range(6):
        zr[i] -= r_mean
        zb[i] = wrap_angle(zb[i] - b_mean)
        acc00 += zr[i] * zr[i]
        acc01 += zr[i] * zb[i]
        acc11 += zb[i] * zb[i]
    s00 += w * acc00 + sigma_r**2
    s01 += w * acc01
    s11 += w * acc11 + sigma_beta**2
    del acc00, acc01, acc11
    # Cross covariance: χ_{k±} − x⁻ = ±column k, so Pxz = W Σ_k column_k (d_{k+} − d_{k−})ᵀ
    # (k = 3 adds nothing: its two points share ζ₀).
    for k in range(3):
        zr[2 * k] -= zr[2 * k + 1]
        zb[2 * k] -= zb[2 * k + 1]
    zr, zb = zr[0::2], zb[0::2]  # d_{k+} − d_{k−}, k = 0, 1, 2; the rest is released
    del r0, b0
    K0: list[Vec] = []
    K1: list[Vec] = []
    inv_det = w / (s00 * s11 - s01 * s01)  # folds the weight W of Pxz into S⁻¹
    i00, i01, i11 = s11 * inv_det, -s01 * inv_det, s00 * inv_det
    for i in range(n):
        a0 = col[i, 0] * zr[0]
        a1 = col[i, 0] * zb[0]
        for k in range(1, min(i, 2) + 1):
            a0 += col[i, k] * zr[k]
            a1 += col[i, k] * zb[k]
        # K = Pxz S⁻¹, row i.
        K0.append(a0 * i00 + a1 * i01)
        K1.append(a0 * i01 + a1 * i11)
    del zr, zb, col, a0, a1, i00, i01, i11
    nu0 = r_meas - r_mean
    nu1 = wrap_angle(b_meas - b_mean)
    out = _target(state, out)
    for i in range(n):
        out.x[:, i] = x[:, i] + K0[i] * nu0 + K1[i] * nu1
    # P⁺ = P⁻ − K S Kᵀ with (K S Kᵀ)_ij = K_i · (S K_jᵀ), averaged with its transpose.
    W0 = [s00 * K0[j] + s01 * K1[j] for j in range(n)]
    W1 = [s01 * K0[j] + s11 * K1[j] for j in range(n)]
    oP = out.P
    for i in range(n):
        for j in range(i, n):
            if i == j:
                ksk = K0[i] * W0[i] + K1[i] * W1[i]
            else:
                ksk = K0[i] * W0[j] + K1[i] * W1[j] + K0[j] * W0[i] + K1[j] * W1[i]
                ksk *= 0.5
            oP[:, i, j] = P[:, i, j] - ksk
            if i != j:
                oP[:, j, i] = oP[:, i, j]
    return out


def _cholesky_columns3(P: NDArray[np.float64], scale: float) -> dict[tuple[int, int], Vec]:
    """First three columns of ``scale ·`` the lower Cholesky factor of every P (M, 4, 4).

    Returns the entries (i, k), i >= k, k <= 2, as (M,) vectors. The last column (only its
    (3, 3) entry is nonzero) moves the sigma points along ẏ alone, which h ignores and the
    cross covariance weights by a zero residual difference, so the UKF never needs it.
    A negative pivot among the three gives NaN for that run (numpy warns "invalid value");
    the fourth pivot is never formed, so it is not checked.
    """
    L: dict[tuple[int, int], Vec] = {}
    for j in range(3):
        d = P[:, j, j].copy()
        for k in range(j):
            d -= L[j, k] * L[j, k]
        np.sqrt(d, out=d)
        L[j, j] = d
        for i in range(j + 1, 4):
            e = P[:, i, j].copy()
            for k in range(j):
                e -= L[i, k] * L[j, k]
            e /= d
            L[i, j] = e
    for v in L.values():
        v *= scale
    return L
