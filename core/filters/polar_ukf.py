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

The arithmetic is written once per dimension, for every engine: ``core.filters.ukf_2d``
(the 2D state as tuples of numbers or arrays) and ``core.filters.ukf_3d`` (in place on a
track's arrays or a batch's component-major views); this module applies them to a numpy
batch. Because the factor is lower triangular and only the position enters h, the points
along a column that moves no position component map to ζ₀.

P⁻ need only be positive semi-definite (``core.filters.position_2d``'s factor): a direction of zero
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
from numpy.typing import ArrayLike

from radarviz.core.filters.polar_ekf import polar_measurement_vectors
from radarviz.core.filters.state import (
    CVBatch,
    step_2d,
    step_3d,
)
from radarviz.core.filters.ukf_2d import ukf_update_2d
from radarviz.core.filters.ukf_3d import ukf_update_3d


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
    site_xyz = np.zeros(3) if site is None else np.asarray(site, dtype=np.float64)
    sites = (site_xyz[..., 0], site_xyz[..., 1], site_xyz[..., 2])
    args = (*meas, *var, *sites, params.weights(6))
    return step_3d(ukf_update_3d, state, args, SCRATCH_3D, out)


#: The scratch arrays of ``ukf_update_3d``: L (6, 6), Z (13, 3), K (6, 3), S, Si (3, 3), E (6,).
SCRATCH_3D = ((6, 6), (13, 3), (6, 3), (3, 3), (3, 3), (6,))
