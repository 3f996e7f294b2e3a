"""The modified unbiased conversion (Duan, Han and Li 2004), 2D and 3D.

``ucm``'s covariance (Mo et al. 1998) is the covariance of the unbiased point *given the
truth*, evaluated at the measurement. What the filter needs of a measurement it already holds
is the error's covariance *given that measurement*: with the truth distributed as its
flat-prior posterior, r ~ N(r̂, σr²) and each angle ~ N(θ̂, s),

    R = E[(z_u − p)(z_u − p)ᵀ | θ̂] = Cov(p | θ̂) + (z_u − E[p | θ̂])(z_u − E[p | θ̂])ᵀ

where z_u = κ ∘ r̂ û is ucm's point (κ = e^(s/2) per angle) and p = r u the true position.
Under the posterior p has the distribution the naive point has given a truth at θ̂, so

    Cov(p | θ̂) = ``naive_cov_given_truth`` at the measurement,
    E[p | θ̂] = κ⁻¹ ∘ r̂ û,   z_u − E[p | θ̂] = (κ − κ⁻¹) ∘ r̂ û = 2 sinh(s/2) ∘ r̂ û.

In 2D this is Duan, Han and Li's (2004) covariance, e.g. R11 = (e^s − 2) r̂² cos²β̂
+ ½ (r̂² + σr²)(1 + e^(−2s) cos 2β̂); the 3D form follows with s = sβ + sε on x, y and sε on z
(``core.conversion.spatial.scale_3d``). ``mucm`` keeps ucm's point; only the covariance changes,
and it is larger than ucm's by the rank-one term. All functions broadcast over leading axes.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.conversion.planar import Converted, _f, naive_cov_given_truth
from radarviz.core.conversion.spatial import _point_3d, naive_cov_given_truth_3d, ucm_scale_3d

Arr = NDArray[np.float64]


def _with_offset(cov: Arr, offset: Arr) -> Arr:
    """cov + d dᵀ: (..., d, d) and (..., d)."""
    return cov + offset[..., :, None] * offset[..., None, :]


def convert_mucm(
    r: ArrayLike, beta: ArrayLike, *, sigma_r_m: ArrayLike, sigma_beta_rad: ArrayLike
) -> Converted:
    """2D modified unbiased conversion: ucm's point e^(s/2) r̂ (cos β̂, sin β̂) and the
    measurement-conditioned covariance (module docstring).  z (..., 2), R (..., 2, 2)."""
    r, beta = np.broadcast_arrays(_f(r), _f(beta))
    s = _f(sigma_beta_rad) ** 2
    naive = np.stack([r * np.cos(beta), r * np.sin(beta)], axis=-1)
    kappa = np.exp(s / 2.0)[..., None]
    gap = (2.0 * np.sinh(s / 2.0))[..., None] * naive  # κ − κ⁻¹ without cancellation
    cov = naive_cov_given_truth(r, beta, sigma_r_m=sigma_r_m, sigma_beta_rad=sigma_beta_rad)
    return Converted(kappa * naive, _with_offset(cov, gap))


def convert_mucm_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> Converted:
    """3D modified unbiased conversion: ucm's 3D point, covariance
    ``naive_cov_given_truth_3d`` at the measurement + d dᵀ, d = 2 sinh(s/2) ∘ r̂ û with
    s = (sβ + sε, sβ + sε, sε).  z (..., 3), R (..., 3, 3)."""
    r, az, el = np.broadcast_arrays(_f(r), _f(azimuth), _f(elevation))
    var_beta, var_elevation = _f(sigma_beta_rad) ** 2, _f(sigma_elevation_rad) ** 2
    s_xy, s_z = np.broadcast_arrays(var_beta + var_elevation, var_elevation)
    s = np.stack([s_xy, s_xy, s_z], axis=-1)
    naive = _point_3d(r, az, el)
    cov = naive_cov_given_truth_3d(
        r,
        az,
        el,
        sigma_r_m=sigma_r_m,
        sigma_beta_rad=sigma_beta_rad,
        sigma_elevation_rad=sigma_elevation_rad,
    )
    kappa = ucm_scale_3d(sigma_beta_rad, sigma_elevation_rad)  # ucm's point, to the last bit
    return Converted(kappa * naive, _with_offset(cov, 2.0 * np.sinh(s / 2.0) * naive))
