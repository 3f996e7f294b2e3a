"""Unscented Kalman filter update with a polar radar measurement, 2D (r, β) or 3D (r, β, ε).

filterpy's ``UnscentedKalmanFilter.update`` after a linear ``predict()`` (which leaves its
sigma points drawn from the predicted x⁻, P⁻), for a radar at ``site`` (``core.geometry``)::

    χ_i      sigma points of (x⁻, P⁻)        (``UKFParams``; Cholesky square root)
    ζ_i = h(χ_i)                             points through the polar map
    ẑ = Σ Wm_i ζ_i                           bearings averaged relative to ζ₀'s bearing
    S = Σ Wc_i d_i d_iᵀ + R,   d_i = ζ_i ⊖ ẑ   (⊖ wraps the bearing difference)
    Pxz = Σ Wc_i (χ_i − x⁻) d_iᵀ             cross covariance
    K = Pxz S⁻¹,   x⁺ = x⁻ + K (z ⊖ ẑ),   P⁺ = P⁻ − K S Kᵀ

P⁺ is evaluated in the Joseph form of the unscented update,
P⁺ = Σ Wc_i e_i e_iᵀ + K R Kᵀ with e_i = (χ_i − x⁻) − K d_i, which equals P⁻ − K S Kᵀ for
K = Pxz S⁻¹ (expand it: P⁻ − K Pzx − Pxz Kᵀ + K S Kᵀ) but is a sum of positive
semi-definite terms (no weight is negative, ``UKFParams``): no cancellation can leave it
indefinite, which the subtraction does when P⁺ is small against P⁻ in some direction.

Bearing mean: ẑ_β = wrap(β₀ + Σ Wm_i wrap(β_i − β₀)), with β₀ the bearing of the central
point; a plain weighted sum would put the mean of bearings straddling ±π near 0.

Batched without per-track matrices or a (..., 2n+1, n) sigma-point array: the Cholesky
factor is written out over the batch as (...) vectors, and because it is lower triangular and
only the position enters h, the two points along its last column (the last velocity
component alone) map to ζ₀ and drop out of Pxz. So 2(n − 1) distinct polar evaluations per
track, and the last factor column is never formed.

P⁻ need only be positive semi-definite (:func:`semidefinite_cholesky`): a direction of zero
variance to rounding is legitimate and does occur. A first-plot start at elevation ±90° (or
at range 0) has a singular position covariance (the azimuth column r cos ε ∂u/∂β of the
conversion Jacobian vanishes), that null direction survives the prediction up to the tiny
process noise, and the subtraction P⁻ − K S Kᵀ then leaves a pivot of −10⁻¹⁶ of its diagonal:
LAPACK's Cholesky (and filterpy) would raise. Such a pivot is taken as zero, so the sigma
points do not move along a direction that has no variance. A track whose P⁻ is indefinite
beyond rounding gets NaN and leaves the others alone.

The sigma points, hence the UKF estimate, depend on the orientation of the frame (the
Cholesky factor of a rotated P is not the rotated factor), unlike the EKF: with the Prosov
target rotated to β = 0.3 rad the mean cross-range error at scan 30 is ≈ +7 m (σβ = 1°, 10⁶
runs, SE 1.2 m), against ≈ 0 at β = 0. Small, and filterpy's filter does the same.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.filters.polar_ekf import polar_measurement_vectors, site_offsets
from radarviz.core.filters.state import (
    SEMIDEFINITE_RTOL,
    CVBatch,
    Vec,
    cov_components,
    mean_components,
    position_index,
    semidefinite_cholesky,
    step_2d,
    sym,
    symmetric_inverse,
    target_batch,
    use_dense,
)
from radarviz.core.filters.ukf_2d import ukf_update_2d
from radarviz.core.geometry import polar_coordinates, wrap_angle


class UKFParams(NamedTuple):
    """Van der Merwe's scaled sigma points (filterpy ``MerweScaledSigmaPoints(n, α, β, κ)``).

    With n state dimensions, λ = α²(n + κ) − n and 2n + 1 points::

        χ₀ = x,   χ_k = x + [√((n+λ)P)]_k,   χ_{n+k} = x − [√((n+λ)P)]_k      k = 1 … n
        Wm₀ = λ/(n+λ),   Wc₀ = Wm₀ + 1 − α² + β,   Wm_k = Wc_k = 1/(2(n+λ))

    where [·]_k is the k-th column of the lower Cholesky factor (the k-th row of filterpy's
    upper factor).

    Defaults α = 1, β = 2, κ = 0 give λ = 0: the points sit at x ± √n·(Cholesky column of P),
    Wm₀ = 0, Wc₀ = β = 2 (the Gaussian kurtosis correction) and Wm_k = Wc_k = 1/(2n). No
    weight is negative, so the unscented S is a non-negative combination of outer products
    plus R (positive definite), P − K S Kᵀ is the Schur complement of a positive
    semi-definite joint covariance, and its Joseph form a sum of positive semi-definite
    terms: P⁺ stays positive semi-definite to rounding. The popular small α (e.g.
    1e-3) makes Wm₀ ≈ −10⁶ and Wc₀ < 0; S can then lose definiteness, and the huge cancelling
    weights cost digits. Points at ±2σ are well inside the region where the polar map is
    smooth at radar ranges (2σ cross-range ≪ r).

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


def cholesky_columns(P: NDArray[np.float64], scale: float) -> dict[tuple[int, int], Vec]:
    """All but the last column of ``scale ·`` the lower Cholesky factor of every P (..., n, n)
    (:func:`semidefinite_cholesky`).

    Returns the entries (i, k), i >= k, k <= n − 2, as (...) vectors. The last column (only
    its (n−1, n−1) entry is nonzero) moves the sigma points along the last velocity component
    alone, which h ignores, so the UKF never needs it; the last pivot is never formed, so it
    is not checked.
    """
    L = semidefinite_cholesky(P, P.shape[-1] - 1)
    for v in L.values():
        v *= scale
    return L


def dense_cholesky(P: NDArray[np.float64]) -> NDArray[np.float64]:
    """The lower Cholesky factor (..., n, n) of positive semi-definite P (..., n, n).

    LAPACK's where every P of the batch is positive definite (filterpy's square root);
    otherwise :func:`semidefinite_cholesky`, which accepts a null direction and gives NaN only
    to a track whose P is indefinite beyond rounding.
    """
    try:
        return np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        pass
    L = np.zeros_like(P)
    for (i, k), v in semidefinite_cholesky(P).items():
        L[..., i, k] = v
    return L


def ukf_update(
    state: CVBatch,
    measurement: Sequence[ArrayLike],
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike = 0.0,
    site: ArrayLike | None = None,
    params: UKFParams = _DEFAULT_UKF,
    out: CVBatch | None = None,
) -> CVBatch:
    """UKF measurement update of every track with a polar measurement (module docstring).

    Args:
        state: predicted batch (output of ``cv_predict``), 2D or 3D.
        measurement: (r̂, β̂) in 2D or (r̂, β̂, ε̂) in 3D, each (...) in m and rad.
        sigma_r_m, sigma_beta_rad, sigma_elevation_rad: measurement noise std.
        site: the radar's position (d,) (None: the origin).
        params: sigma-point parameters (α, β, κ).
        out: optional preallocated batch to write into (must not alias ``state``).

    Returns:
        The posterior batch (``out`` if given, else a new one).
    """
    meas = polar_measurement_vectors(state, measurement)
    m = state.dims  # measurement size (one per position axis)
    var = [
        np.asarray(sigma_r_m, dtype=np.float64) ** 2,
        np.asarray(sigma_beta_rad, dtype=np.float64) ** 2,
        np.asarray(sigma_elevation_rad, dtype=np.float64) ** 2,
    ][:m]
    if m == 2:  # written once, for every engine (``core.filters.ukf_2d``)
        site_xy = np.zeros(2) if site is None else np.asarray(site, dtype=np.float64)
        args = (*meas, *var, site_xy[..., 0], site_xy[..., 1], *params.weights(4))
        return step_2d(ukf_update_2d, state, args, out)
    if use_dense(state):
        return _ukf_update_dense(state, meas, var, site, params, out)
    return _ukf_update_components(state, meas, var, site, params, out)


def _ukf_update_components(
    state: CVBatch,
    meas: list[NDArray[np.float64]],
    var: list[NDArray[np.float64]],
    site: ArrayLike | None,
    params: UKFParams,
    out: CVBatch | None,
) -> CVBatch:
    """``ukf_update`` of a 3D batch with the Cholesky factor written out over the batch as
    (...) vectors (module docstring)."""
    x, P = state.x, state.P
    n, m = x.shape[-1], state.dims  # state size; measurement size (one per position axis)
    pos = position_index(m)
    c, wm0, wc0, w = params.weights(n)
    col = cholesky_columns(P, np.sqrt(c))  # entries (i, k) of √((n+λ)P⁻), k <= n − 2

    # Sigma points through h. χ_{k±} = x⁻ ± column k moves position axis a only if 2a >= k.
    p0 = site_offsets(state, site)
    h0 = polar_coordinates(p0)
    Z: list[list[Vec]] = [[] for _ in range(m)]  # Z[c][2k], Z[c][2k+1]: component c of ζ_{k±}
    for k in range(n - 1):
        for sign in (1.0, -1.0):
            q = [p0[a] + sign * col[pa, k] if pa >= k else p0[a] for a, pa in enumerate(pos)]
            for comp, value in enumerate(polar_coordinates(q)):
                Z[comp].append(value)
    del q
    npts = 2 * (n - 1)
    # χ₀ and the two points along the last column all map to h0: weight Wm₀ + 2W in the
    # mean, Wc₀ + 2W in S. The bearing (component 1) is averaged relative to h0's.
    mean: list[Vec] = []
    for comp in range(m):
        if comp == 1:
            acc = wrap_angle(Z[1][0] - h0[1])
            for i in range(1, npts):
                acc += wrap_angle(Z[1][i] - h0[1])
            acc *= w
            acc += h0[1]
            mean.append(wrap_angle(acc))
        else:
            acc = Z[comp][0] + Z[comp][1]
            for i in range(2, npts):
                acc += Z[comp][i]
            acc *= w
            acc += (wm0 + 2.0 * w) * h0[comp]
            mean.append(acc)
    del acc

    def residual(comp: int, value: Vec) -> Vec:
        return wrap_angle(value - mean[1]) if comp == 1 else value - mean[comp]

    # Residuals d_i = ζ_i ⊖ ẑ, in place, and the unscented S = Σ Wc_i d_i d_iᵀ + R.
    d0 = [residual(comp, h0[comp]) for comp in range(m)]
    del h0, p0
    wcc = wc0 + 2.0 * w
    S = {(a, b): (wcc * d0[a]) * d0[b] for a in range(m) for b in range(a, m)}
    for comp in range(m):
        for i in range(npts):
            Z[comp][i] = residual(comp, Z[comp][i])
    for a in range(m):
        for b in range(a, m):
            acc = Z[a][0] * Z[b][0]
            for i in range(1, npts):
                acc += Z[a][i] * Z[b][i]
            S[a, b] += w * acc + var[a] if a == b else w * acc
    # Cross covariance: χ_{k±} − x⁻ = ±column k, so Pxz = W Σ_k column_k (d_{k+} − d_{k−})ᵀ.
    D = [[Z[comp][2 * k] - Z[comp][2 * k + 1] for k in range(n - 1)] for comp in range(m)]
    inv = symmetric_inverse(S, m, scale=w)  # folds the weight W of Pxz into S⁻¹
    del S
    inv = {(a, b): sym(inv, a, b) for a in range(m) for b in range(m)}
    K: list[list[Vec]] = [[] for _ in range(m)]  # K[e][i]: gain row i, column e
    for i in range(n):
        a_row = []
        for comp in range(m):
            a = col[i, 0] * D[comp][0]
            for k in range(1, min(i, n - 2) + 1):
                a += col[i, k] * D[comp][k]
            a_row.append(a)
        for e in range(m):
            g = a_row[0] * inv[0, e]
            for comp in range(1, m):
                g = g + a_row[comp] * inv[comp, e]
            K[e].append(g)
    del D, inv
    nu = [residual(comp, meas[comp]) for comp in range(m)]
    mean.clear()  # every residual is taken: free ẑ
    out = target_batch(state, out)
    xc, oxc = mean_components(x), mean_components(out.x)
    for i in range(n):
        acc = xc[i] + K[0][i] * nu[0]
        for e in range(1, m):
            acc = acc + K[e][i] * nu[e]
        oxc[i] = acc
    del nu, acc
    # P⁺ in Joseph form (module docstring): Σ_p Wc_p e_p e_pᵀ + K R Kᵀ, e_p = (χ_p − x⁻) − K d_p.
    # χ₀ and the two points along the last column share d_p = d₀ (weight Wc₀ + 2W, e = −K d₀,
    # their ± last-column parts cancelling in the cross terms); those two add 2W·(n+λ)·dₙ₋₁ =
    # dₙ₋₁, the last Cholesky pivot of P⁻, at (n−1, n−1).
    Pc, oPc = cov_components(P), cov_components(out.P)
    last = Pc[n - 1, n - 1] - sum_terms([col[n - 1, k] * col[n - 1, k] for k in range(n - 1)]) / c
    tol = SEMIDEFINITE_RTOL * Pc[n - 1, n - 1]
    last = np.where(last >= 0.0, last, np.where(last < -tol, np.nan, 0.0))
    del tol
    kd0 = [sum_terms([K[e][i] * d0[e] for e in range(m)]) for i in range(n)]
    for i in range(n):  # the accumulators are out's own P (no temporaries per entry)
        for j in range(i, n):
            acc = oPc[i, j]
            np.multiply(kd0[i], kd0[j], out=acc)
            acc *= wcc
            for e in range(m):
                acc += (var[e] * K[e][i]) * K[e][j]
    oPc[n - 1, n - 1] += last
    del kd0, d0, last
    for k in range(n - 1):
        for p, sign in ((2 * k, 1.0), (2 * k + 1, -1.0)):
            e_p = []  # −e_p (the sign drops out of the products)
            for i in range(n):
                v = sum_terms([K[e][i] * Z[e][p] for e in range(m)])
                if i >= k:
                    v -= sign * col[i, k]
                e_p.append(v)
            for i in range(n):
                we = w * e_p[i]
                for j in range(i, n):
                    oPc[i, j] += we * e_p[j]
                del we
            del e_p
            for e in range(m):
                Z[e][p] = None  # type: ignore[call-overload]  # each point freed once used
        for i in range(k, n):
            del col[i, k]
    del Z, col
    for i in range(n):
        for j in range(i + 1, n):
            oPc[j, i] = oPc[i, j]
    return out


def sum_terms(terms: list[Vec]) -> Vec:
    """t₀ + t₁ + … left to right (the order fixes the rounding)."""
    acc = terms[0]
    for t in terms[1:]:
        acc = acc + t
    return acc


def _ukf_update_dense(
    state: CVBatch,
    meas: list[NDArray[np.float64]],
    var: list[NDArray[np.float64]],
    site: ArrayLike | None,
    params: UKFParams,
    out: CVBatch | None,
) -> CVBatch:
    """``ukf_update`` for small 3D batches: the module docstring's equations with all 2n + 1
    sigma points as one (..., 2n+1, n) array and batched matrix products (the tests check it
    against the component-wise path)."""
    x, P = state.x, state.P
    n, m = x.shape[-1], state.dims
    pos = list(position_index(m))
    c, wm0, wc0, w = params.weights(n)
    cols = dense_cholesky(c * P).mT  # row k: column k of the factor
    chi = np.concatenate([x[..., None, :], x[..., None, :] + cols, x[..., None, :] - cols], -2)
    offsets = chi[..., pos]
    if site is not None:
        # A site per track (..., d) lines up with the tracks, not with the sigma points.
        offsets = offsets - np.asarray(site, dtype=np.float64)[..., None, :]
    zeta = np.stack(polar_coordinates([offsets[..., a] for a in range(m)]), -1)  # (..., 2n+1, m)
    wm = np.full(2 * n + 1, w)
    wm[0] = wm0
    wc = wm.copy()
    wc[0] = wc0
    b0 = zeta[..., :1, 1]
    zeta[..., 1] = b0 + wrap_angle(zeta[..., 1] - b0)  # bearings relative to the central one
    z_mean = np.einsum("p,...pm->...m", wm, zeta)
    dz = zeta - z_mean[..., None, :]
    dz[..., 1] = wrap_angle(dz[..., 1])
    dx = chi - x[..., None, :]
    R = np.zeros((*state.batch_shape, m, m))
    for a in range(m):
        R[..., a, a] = var[a]
    S = np.einsum("p,...pi,...pj->...ij", wc, dz, dz) + R
    Pxz = np.einsum("p,...pi,...pj->...ij", wc, dx, dz)
    K = np.linalg.solve(S, Pxz.mT).mT
    nu = np.stack(meas, -1) - z_mean
    nu[..., 1] = wrap_angle(nu[..., 1])
    # Joseph form: P⁺ = Σ Wc_i (dx_i − K dz_i)(dx_i − K dz_i)ᵀ + K R Kᵀ, equal to P − K S Kᵀ
    # but a sum of positive semi-definite terms, so no cancellation can make it indefinite.
    e = dx - dz @ K.mT
    P_new = np.einsum("p,...pi,...pj->...ij", wc, e, e) + K @ R @ K.mT
    out = target_batch(state, out)
    out.x[...] = x + (K @ nu[..., None])[..., 0]
    out.P[...] = 0.5 * (P_new + P_new.mT)
    return out
