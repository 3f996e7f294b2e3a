"""Batched EKF and UKF that filter polar radar measurements directly (M runs at once).

Instead of converting each measurement to Cartesian coordinates (``core.conversion``), these
filters keep the constant-velocity state of ``core.kalman_cv`` and put the nonlinearity in the
measurement function. A radar at the origin measures range and azimuth, azimuth counted from
the x axis towards the y axis::

    z = h(x) + v,   h(x) = (r, β) = (sqrt(px² + py²), atan2(py, px)),   v ~ N(0, R)
    R = diag(σr², σβ²)                 state x = (px, ṗx, py, ṗy)

Prediction is linear and shared with the converted-measurement filters: use
``core.kalman_cv.cv_predict`` unchanged before either update. Both updates are pure functions
``(predicted batch, measurements) → posterior batch``; they follow the equations of filterpy's
``ExtendedKalmanFilter.update`` and ``UnscentedKalmanFilter.update`` (the reference
implementations, which the tests reproduce step by step to ~1e-9 relative) but work on all M
runs at once with vector operations over the run index.

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

from core.conversion import convert_naive
from core.kalman_cv import CVBatch, Vec, _target, cv_init, joseph_update_position

__all__ = ["UKFParams", "ekf_update", "init_from_polar", "ukf_update", "wrap_angle"]

_TWO_PI = 2.0 * np.pi


def wrap_angle(a: ArrayLike) -> NDArray[np.float64]:
    """Wrap angles (rad) to the interval (−π, π].  Elementwise, any shape.

    ``π − mod(π − a, 2π)``: ``mod`` lands in [0, 2π), so the result is in (−π, π], and an angle
    already in that interval comes back unchanged up to one rounding.
    """
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), _TWO_PI)


def _measurements(state: CVBatch, r: ArrayLike, beta: ArrayLike) -> tuple[Vec, Vec]:
    """``r`` and ``beta`` as float64 vectors of length M (the only validation done)."""
    r = np.asarray(r, dtype=np.float64)
    beta = np.asarray(beta, dtype=np.float64)
    m = state.runs
    if r.shape != (m,) or beta.shape != (m,):
        raise ValueError(
            f"r and beta must have shape ({m},) to match the batch "
            f"(got {r.shape} and {beta.shape})"
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

    Written with U = P⁻ H2ᵀ (columns 0 and 2 of P⁻) and A = U Gᵀ = P⁻ Hᵀ, so S = G (H2 A) + R
    and K = A S⁻¹; the Joseph form is evaluated by ``kalman_cv.joseph_update_position`` with
    L = K G. Each quantity is one vector of length M (component-wise over the batch, like
    ``cv_update``): a few hundred vector operations for all runs, no per-run matrices.

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
    # Predicted measurement h(x⁻) and the Jacobian G, entries g_ab (M,).
    r2 = px * px + py * py
    rp = np.sqrt(r2)
    g00 = px / rp
    g01 = py / rp
    g10 = -py / r2
    g11 = px / r2
    nu = (r_meas - rp, wrap_angle(b_meas - np.arctan2(py, px)))
    # A = P⁻ Hᵀ = U Gᵀ, row i: (A_i0, A_i1).
    A0: list[Vec] = []
    A1: list[Vec] = []
    for i in range(4):
        u0, u1 = P[:, i, 0], P[:, i, 2]
        A0.append(g00 * u0 + g01 * u1)
        A1.append(g10 * u0 + g11 * u1)
    # S = G (H2 A) + R; H2 A has rows A_0 and A_2.
    s00 = g00 * A0[0] + g01 * A0[2] + sigma_r**2
    s01 = g00 * A1[0] + g01 * A1[2]
    s11 = g10 * A1[0] + g11 * A1[2] + sigma_beta**2
    inv_det = 1.0 / (s00 * s11 - s01 * s01)
    i00, i01, i11 = s11 * inv_det, -s01 * inv_det, s00 * inv_det
    # K = A S⁻¹ and L = K G, component-major (4, 2, M) as joseph_update_position wants.
    m = state.runs
    K = np.empty((4, 2, m))
    L = np.empty((4, 2, m))
    for i in range(4):
        k0 = A0[i] * i00 + A1[i] * i01
        k1 = A0[i] * i01 + A1[i] * i11
        K[i, 0], K[i, 1] = k0, k1
        L[i, 0] = k0 * g00 + k1 * g10
        L[i, 1] = k0 * g01 + k1 * g11
    return joseph_update_position(state, nu, K, L, (s00, s01, s11), out)


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

    Batched without per-run matrices: the 4 × 4 Cholesky factor is written out over the batch
    (10 vectors of length M), and only the position enters h, so the lower-triangular factor
    means the points χ_{4}, χ_{8} (offsets along the last factor column, pure ẏ) map to ζ₀:
    7 distinct polar evaluations per run. Working memory is a few dozen (M,) vectors. A run
    whose P⁻ is not positive definite gets NaN (filterpy would raise for that one filter).

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
    # Lower Cholesky factor of P⁻ (column k = offset direction of χ_{k+1}), scaled by √(n+λ).
    Lc: dict[tuple[int, int], Vec] = {}
    for j in range(n):
        acc = P[:, j, j].copy()
        for k in range(j):
            acc -= Lc[j, k] * Lc[j, k]
        d = np.sqrt(acc)
        Lc[j, j] = d
        for i in range(j + 1, n):
            acc = P[:, i, j].copy()
            for k in range(j):
                acc -= Lc[i, k] * Lc[j, k]
            Lc[i, j] = acc / d
    scale = np.sqrt(c)
    col = {key: scale * v for key, v in Lc.items()}  # [√((n+λ)P)] entries (i, k), i >= k
    # Position offsets (dpx, dpy) of the columns that move the position: k = 0, 1, 2.
    px, py = x[:, 0], x[:, 2]
    zero = np.zeros(state.runs)
    offsets = [(col[0, 0], col[2, 0]), (zero, col[2, 1]), (zero, col[2, 2])]
    # ζ for the central point and for ±column k.
    r0 = np.hypot(px, py)
    b0 = np.arctan2(py, px)
    plus: list[tuple[Vec, Vec]] = []
    minus: list[tuple[Vec, Vec]] = []
    for dx, dy in offsets:
        for sign, store in ((1.0, plus), (-1.0, minus)):
            qx = px + sign * dx
            qy = py + sign * dy
            store.append((np.hypot(qx, qy), np.arctan2(qy, qx)))
    # Unscented mean; the k = 3 pair (and χ₀) contribute ζ₀: weight wm0 + 2w on ζ₀.
    w_center_m = wm0 + 2.0 * w
    r_sum = plus[0][0] + minus[0][0]
    b_sum = wrap_angle(plus[0][1] - b0) + wrap_angle(minus[0][1] - b0)
    for k in (1, 2):
        r_sum += plus[k][0] + minus[k][0]
        b_sum += wrap_angle(plus[k][1] - b0) + wrap_angle(minus[k][1] - b0)
    r_mean = w_center_m * r0 + w * r_sum
    b_mean = wrap_angle(b0 + w * b_sum)  # the central point's own wrapped difference is 0
    # Residuals d_i = ζ_i ⊖ ẑ and the unscented S (central point weight wc0 + 2w, as above).
    d0 = (r0 - r_mean, wrap_angle(b0 - b_mean))
    w_center_c = wc0 + 2.0 * w
    s00 = w_center_c * d0[0] * d0[0] + sigma_r**2
    s01 = w_center_c * d0[0] * d0[1]
    s11 = w_center_c * d0[1] * d0[1] + sigma_beta**2
    # Differences d_{k+} − d_{k−} feed the cross covariance: χ_{k±} − x⁻ = ±column k.
    diff0: list[Vec] = []
    diff1: list[Vec] = []
    for k in range(3):
        dp = (plus[k][0] - r_mean, wrap_angle(plus[k][1] - b_mean))
        dm = (minus[k][0] - r_mean, wrap_angle(minus[k][1] - b_mean))
        s00 += w * (dp[0] * dp[0] + dm[0] * dm[0])
        s01 += w * (dp[0] * dp[1] + dm[0] * dm[1])
        s11 += w * (dp[1] * dp[1] + dm[1] * dm[1])
        diff0.append(dp[0] - dm[0])
        diff1.append(dp[1] - dm[1])
    # Pxz row i = w Σ_{k ≤ min(i, 2)} col[i, k] (d_{k+} − d_{k−}); column 3 contributes 0.
    pxz0: list[Vec] = []
    pxz1: list[Vec] = []
    for i in range(n):
        a0 = col[i, 0] * diff0[0]
        a1 = col[i, 0] * diff1[0]
        for k in range(1, min(i, 2) + 1):
            a0 += col[i, k] * diff0[k]
            a1 += col[i, k] * diff1[k]
        pxz0.append(w * a0)
        pxz1.append(w * a1)
    inv_det = 1.0 / (s00 * s11 - s01 * s01)
    i00, i01, i11 = s11 * inv_det, -s01 * inv_det, s00 * inv_det
    K0 = [pxz0[i] * i00 + pxz1[i] * i01 for i in range(n)]
    K1 = [pxz0[i] * i01 + pxz1[i] * i11 for i in range(n)]
    nu0 = r_meas - r_mean
    nu1 = wrap_angle(b_meas - b_mean)
    out = _target(state, out)
    for i in range(n):
        out.x[:, i] = x[:, i] + K0[i] * nu0 + K1[i] * nu1
    # K S Kᵀ: row i times (S K_jᵀ); symmetrised as ½(M_ij + M_ji).
    W0 = [s00 * K0[j] + s01 * K1[j] for j in range(n)]
    W1 = [s01 * K0[j] + s11 * K1[j] for j in range(n)]
    oP = out.P
    for i in range(n):
        for j in range(i, n):
            if i == j:
                ksk = K0[i] * W0[i] + K1[i] * W1[i]
            else:
                ksk = 0.5 * (K0[i] * W0[j] + K1[i] * W1[j] + K0[j] * W0[i] + K1[j] * W1[i])
            oP[:, i, j] = P[:, i, j] - ksk
            if i != j:
                oP[:, j, i] = oP[:, i, j]
    return out
