"""3D polar-to-Cartesian converted measurements: range r, azimuth β, elevation ε.

    x = r cos ε cos β,   y = r cos ε sin β,   z = r sin ε      (``core.geometry``)

With independent errors v_r ~ N(0, σr²), v_β ~ N(0, σβ²), v_ε ~ N(0, σε²), each angle's
cosine and sine are biased by e^(−s/2) as in 2D (``core.conversion.planar``), so the naive
point is pulled towards the radar. Two conversions exist in 3D:

* ``naive``: r̂ u(β̂, ε̂) with the first-order covariance J diag(σr², σβ², σε²) Jᵀ, J the
  polar-to-Cartesian Jacobian [u, r ∂u/∂β, r ∂u/∂ε] at the measurement;
* ``ucm`` (Mo et al. 1998, in 3D): one factor e^(s/2) per angle in each coordinate and the
  exact true-conditioned covariance, evaluated at the measurement.

All functions broadcast over any leading batch shape ``(...)``. Angles are radians.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.conversion.planar import Converted, _angle_moments, _f
from radarviz.core.geometry import direction_cosines, unit_vector_partials


def _point_3d(r: NDArray, az: NDArray, el: NDArray) -> NDArray[np.float64]:
    return r[..., None] * direction_cosines(az, el)


def convert_naive_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_azimuth_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> Converted:
    """Naive 3D conversion with the first-order covariance J diag(σr², σβ², σε²) Jᵀ.

    J = [u, r ∂u/∂β, r ∂u/∂ε] (``core.geometry``) at the measured (r̂, β̂, ε̂).
    """
    r, az, el = np.broadcast_arrays(_f(r), _f(azimuth), _f(elevation))
    u = direction_cosines(az, el)
    g_b, g_e = unit_vector_partials(az, el)
    j_b = r[..., None] * g_b
    j_e = r[..., None] * g_e
    var_r = _f(sigma_r_m) ** 2
    var_b = _f(sigma_azimuth_rad) ** 2
    var_e = _f(sigma_elevation_rad) ** 2
    cov = (
        var_r[..., None, None] * u[..., :, None] * u[..., None, :]
        + var_b[..., None, None] * j_b[..., :, None] * j_b[..., None, :]
        + var_e[..., None, None] * j_e[..., :, None] * j_e[..., None, :]
    )
    return Converted(r[..., None] * u, cov)


def naive_cov_given_truth_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_azimuth_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> NDArray[np.float64]:
    """Exact covariance (..., 3, 3) of the naive 3D point given the true (r, β, ε).

    With a = cos ε̂ cos β̂, b = cos ε̂ sin β̂, c = sin ε̂ and independent angle errors,
    E[p pᵀ] = (r² + σr²) E[(a, b, c)(a, b, c)ᵀ], each entry a product of the one-angle moments.

    Numerics: evaluated as σr² E[u uᵀ] + r² Cov(u), u = (a, b, c), with each entry of Cov(u)
    from Cov(XY, X'Y') = Cov(X, X') E[YY'] + E[X] E[X'] Cov(Y, Y') for the independent
    elevation (X) and azimuth (Y) factors, so no O(r²) terms cancel.
    """
    r = _f(r)
    r2, sr2 = r * r, _f(sigma_r_m) ** 2
    b = _angle_moments(_f(azimuth), _f(sigma_azimuth_rad) ** 2)
    e = _angle_moments(_f(elevation), _f(sigma_elevation_rad) ** 2)
    mc_e2 = e.mc * e.mc
    # (second moment E[u_i u_j], covariance Cov(u_i, u_j)) for the upper triangle.
    xx = (e.ecc * b.ecc, e.vcc * b.ecc + mc_e2 * b.vcc)
    xy = (e.ecc * b.esc, e.vcc * b.esc + mc_e2 * b.csc)
    yy = (e.ecc * b.ess, e.vcc * b.ess + mc_e2 * b.vss)
    xz = (e.esc * b.mc, e.csc * b.mc)
    yz = (e.esc * b.ms, e.csc * b.ms)
    zz = (e.ess, e.vss)
    entries = [sr2 * m2 + r2 * cv for m2, cv in (xx, xy, xz, yy, yz, zz)]
    cxx, cxy, cxz, cyy, cyz, czz = np.broadcast_arrays(*entries)
    rows = [[cxx, cxy, cxz], [cxy, cyy, cyz], [cxz, cyz, czz]]
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def ucm_scale_3d(sigma_azimuth_rad: ArrayLike, sigma_elevation_rad: ArrayLike) -> NDArray:
    """κ (..., 3) = (e^((sβ+sε)/2), e^((sβ+sε)/2), e^(sε/2)): the unbiasing factor per axis."""
    sb, se = _f(sigma_azimuth_rad) ** 2, _f(sigma_elevation_rad) ** 2
    kxy = np.exp((sb + se) / 2.0)
    kz = np.exp(se / 2.0) * np.ones_like(kxy)
    return np.stack([kxy, kxy, kz], axis=-1)


def ucm_cov_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_azimuth_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> NDArray[np.float64]:
    """Covariance D C D of the unbiased 3D point, C = ``naive_cov_given_truth_3d`` at the given
    (r, β, ε) (the measurement for ``ucm``, or any better estimate of the line of sight)."""
    sig = {
        "sigma_r_m": sigma_r_m,
        "sigma_azimuth_rad": sigma_azimuth_rad,
        "sigma_elevation_rad": sigma_elevation_rad,
    }
    kappa = ucm_scale_3d(sigma_azimuth_rad, sigma_elevation_rad)
    cov = naive_cov_given_truth_3d(r, azimuth, elevation, **sig)
    return kappa[..., :, None] * cov * kappa[..., None, :]


def convert_ucm_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_azimuth_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> Converted:
    """Unbiased 3D conversion: one factor e^(s/2) per angle in each coordinate.

    κ = ``ucm_scale_3d``; the covariance is the exact true-conditioned one, D C D with
    D = diag(κ), evaluated at the measurement (``ucm_cov_3d``).
    """
    r, az, el = np.broadcast_arrays(_f(r), _f(azimuth), _f(elevation))
    kappa = ucm_scale_3d(sigma_azimuth_rad, sigma_elevation_rad)
    cov = ucm_cov_3d(
        r,
        az,
        el,
        sigma_r_m=sigma_r_m,
        sigma_azimuth_rad=sigma_azimuth_rad,
        sigma_elevation_rad=sigma_elevation_rad,
    )
    return Converted(kappa * _point_3d(r, az, el), cov)
