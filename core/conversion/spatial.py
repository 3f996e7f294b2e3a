"""3D polar-to-Cartesian converted measurements: range r, azimuth β, elevation ε.

    x = r cos ε cos β,   y = r cos ε sin β,   z = r sin ε      (``core.geometry``)

With independent errors v_r ~ N(0, σr²), v_β ~ N(0, σβ²), v_ε ~ N(0, σε²), each angle's
cosine and sine are biased by e^(−s/2) as in 2D (``core.conversion.planar``; sβ = σβ²,
sε = σε²), so the naive point is pulled towards the radar: E[x̂] = r cos ε cos β e^(−(sβ+sε)/2),
E[ŷ] likewise, E[ẑ] = r sin ε e^(−sε/2). The 2D conversions carry over with the same names:

=========  ====================================================  ================================
name       point                                                 covariance
=========  ====================================================  ================================
naive      r̂ u(β̂, ε̂)                                              J diag(σr², sβ, sε) Jᵀ
seed       + ½ tr(H_i Σ) (Prosov eq. 7 with eq. 10's sign,       averaged (eq. 11 in 3D)
           ``core.conversion.second_order``)
cmkf_d     × κ(s) = 1 − (e^(−s) − e^(−s/2))                       averaged (eq. 11 in 3D)
ucm        × κ(s) = e^(s/2)                                       exact, at the measurement
ducm       × κ(s) = e^(s/2)                                       exact, at the prediction
=========  ====================================================  ================================

A 3D scale is the 2D one per axis with s the summed variance of the angles in that axis:
s = sβ + sε for x and y (cos ε cos β, cos ε sin β) and s = sε for z (sin ε). The seed point is
the scale 1 − s/2 in the same sense. "Averaged" is Lerro and Bar-Shalom's covariance in 3D,
the true-conditioned covariance of the naive point averaged over the (flat-prior) posterior of
the truth given the measurement; at zero elevation with sε = 0 every form is the 2D one with
z = 0 (docs/conversion.md, section 4).

All functions broadcast over any leading batch shape ``(...)``. Angles are radians.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.conversion import elementwise_3d
from radarviz.core.conversion.elementwise_3d import converted_point_3d, noise_table
from radarviz.core.conversion.planar import Converted, _f
from radarviz.core.conversion.registry import CONVERSIONS, conversion_named
from radarviz.core.conversion.second_order import second_order_correction, spherical_hessians
from radarviz.core.geometry import direction_cosines

#: The 3D conversions, with the names of their 2D forms.
CONVERSIONS_3D: tuple[str, ...] = tuple(CONVERSIONS)
#: The (i, j) of the covariance entries of ``convert_parts_3d``, in their order.
UPPER_3D: tuple[tuple[int, int], ...] = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def _point_3d(r: NDArray, az: NDArray, el: NDArray) -> NDArray[np.float64]:
    return r[..., None] * direction_cosines(az, el)


def _sym3(upper: tuple) -> NDArray[np.float64]:
    """(..., 3, 3) symmetric matrices from the six (...) upper entries (xx, xy, xz, yy, yz,
    zz)."""
    xx, xy, xz, yy, yz, zz = np.broadcast_arrays(*upper)
    rows = [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def _plot(r: ArrayLike, azimuth: ArrayLike, elevation: ArrayLike) -> tuple[NDArray, ...]:
    """(r, cos β, sin β, cos ε, sin ε) as arrays."""
    az, el = _f(azimuth), _f(elevation)
    return _f(r), np.cos(az), np.sin(az), np.cos(el), np.sin(el)


def _variances(
    sigma_r_m: ArrayLike, sigma_beta_rad: ArrayLike, sigma_elevation_rad: ArrayLike
) -> tuple[NDArray, ...]:
    """(σr², σβ², σε²) and the radar's ``noise_table``."""
    sr2, sb2, se2 = _f(sigma_r_m) ** 2, _f(sigma_beta_rad) ** 2, _f(sigma_elevation_rad) ** 2
    return sr2, sb2, se2, noise_table(sb2, se2)


def convert_parts_3d(
    method: str,
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
    predicted_xyz: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], ...]:
    """Any of ``CONVERSIONS_3D`` as components (x, y, z, Rxx, Rxy, Rxz, Ryy, Ryz, Rzz), each
    (...), radar-centred (``core.conversion.elementwise_3d.converted_point_3d``); ``ducm``
    needs ``predicted_xyz`` (..., 3), radar-centred.

    Args:
        r, azimuth, elevation: (...) measured range (m) and angles (rad).
        sigma_r_m, sigma_beta_rad, sigma_elevation_rad: σr, σβ, σε, scalars or (...).
    """
    conversion = conversion_named(method)
    px = py = pz = 0.0
    if conversion.about_prediction:
        if predicted_xyz is None:
            raise ValueError(
                f"method {method} needs predicted_xyz (the filter's predicted position)"
            )
        p = _f(predicted_xyz)
        px, py, pz = p[..., 0], p[..., 1], p[..., 2]
    sr2, sb2, se2, table = _variances(sigma_r_m, sigma_beta_rad, sigma_elevation_rad)
    kxy, kz = conversion.scales(_f(sigma_beta_rad), _f(sigma_elevation_rad))
    parts = converted_point_3d(
        conversion.covariance, kxy, kz, *_plot(r, azimuth, elevation), sr2, sb2, se2, table,
        px, py, pz,
    )  # fmt: skip
    return tuple(np.broadcast_arrays(*parts))


def convert_3d(
    method: str,
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
    predicted_xyz: ArrayLike | None = None,
) -> Converted:
    """``convert_parts_3d`` stacked: z (..., 3) and R (..., 3, 3)."""
    parts = convert_parts_3d(
        method,
        r,
        azimuth,
        elevation,
        sigma_r_m=sigma_r_m,
        sigma_beta_rad=sigma_beta_rad,
        sigma_elevation_rad=sigma_elevation_rad,
        predicted_xyz=predicted_xyz,
    )
    return Converted(np.stack(parts[:3], axis=-1), _sym3(parts[3:]))


def _converter(method: str, doc: str):
    """``convert_3d`` of one method, named ``convert_<method>_3d``, documented by ``doc``."""

    def convert(
        r: ArrayLike,
        azimuth: ArrayLike,
        elevation: ArrayLike,
        *,
        sigma_r_m: ArrayLike,
        sigma_beta_rad: ArrayLike,
        sigma_elevation_rad: ArrayLike,
    ) -> Converted:
        return convert_3d(
            method,
            r,
            azimuth,
            elevation,
            sigma_r_m=sigma_r_m,
            sigma_beta_rad=sigma_beta_rad,
            sigma_elevation_rad=sigma_elevation_rad,
        )

    convert.__name__ = convert.__qualname__ = f"convert_{method}_3d"
    convert.__doc__ = doc
    return convert


convert_naive_3d = _converter(
    "naive",
    """Naive 3D conversion r̂ u(β̂, ε̂) with the first-order covariance
J diag(σr², σβ², σε²) Jᵀ, J = [u, r ∂u/∂β, r ∂u/∂ε] (``core.geometry``) at the measured
(r̂, β̂, ε̂).""",
)
convert_seed_3d = _converter(
    "seed",
    """Prosov's conversion in 3D: the naive point plus the second-order
term as printed (the scale 1 − s/2 per axis, which ``seed_correction_3d`` derives), with eq.
11's covariance in 3D (``averaged_cov_3d``), as the 2D ``seed`` pairs them.""",
)
convert_cmkf_d_3d = _converter(
    "cmkf_d",
    """Lerro and Bar-Shalom's debiased conversion in 3D: the naive point
minus its average bias.

The bias given the truth is r u_i (L_i − 1), L = (e^(−(sβ+sε)/2), e^(−(sβ+sε)/2), e^(−sε/2))
the product of the angles' e^(−s/2); averaged over the posterior of the truth, r u_i becomes
r̂ û_i L_i, so the point is r̂ û_i (1 − (L_i² − L_i)): the 2D κ per axis (``scale_3d``).
Covariance: the averaged one (``averaged_cov_3d``).""",
)
convert_ucm_3d = _converter(
    "ucm",
    """Unbiased 3D conversion: one factor e^(s/2) per angle in each
coordinate. κ = ``ucm_scale_3d``; the covariance is the exact true-conditioned one, D C D with
D = diag(κ), evaluated at the measurement (``ucm_cov_3d``).""",
)


def convert_ducm_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
    predicted_xyz: ArrayLike,
) -> Converted:
    """Decorrelated unbiased conversion (Bordonaro, Willett, Bar-Shalom 2014) in 3D: ucm's
    point, its covariance (``ucm_cov_3d``) evaluated at the range and angles of the filter's
    predicted position (radar-centred, (..., 3)), so the gain does not depend on this
    measurement's error."""
    return convert_3d(
        "ducm",
        r,
        azimuth,
        elevation,
        sigma_r_m=sigma_r_m,
        sigma_beta_rad=sigma_beta_rad,
        sigma_elevation_rad=sigma_elevation_rad,
        predicted_xyz=predicted_xyz,
    )


def naive_cov_given_truth_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> NDArray[np.float64]:
    """Exact covariance (..., 3, 3) of the naive 3D point given the true (r, β, ε).

    With a = cos ε̂ cos β̂, b = cos ε̂ sin β̂, c = sin ε̂ and independent angle errors,
    E[p pᵀ] = (r² + σr²) E[(a, b, c)(a, b, c)ᵀ], each entry a product of the one-angle moments;
    evaluated as σr² E[u uᵀ] + r² Cov(u) (``core.conversion.elementwise_3d.true_entries_3d``).
    """
    sr2, _, _, table = _variances(sigma_r_m, sigma_beta_rad, sigma_elevation_rad)
    return _sym3(elementwise_3d.true_entries_3d(*_plot(r, azimuth, elevation), sr2, table))


def averaged_cov_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> NDArray[np.float64]:
    """Prosov's eq. 11 in 3D, at the measurement (r, β, ε) = (r̂, β̂, ε̂).  (..., 3, 3).

    Lerro and Bar-Shalom's averaged covariance: ``naive_cov_given_truth_3d`` averaged over the
    truth r ~ N(r̂, σr²), β ~ N(β̂, σβ²), ε ~ N(ε̂, σε²) (independent; the posterior under a
    flat prior). At ε̂ = 0 and σε = 0 its x–y block is eq. 11 (``planar.averaged_cov``).
    """
    sr2, _, _, table = _variances(sigma_r_m, sigma_beta_rad, sigma_elevation_rad)
    return _sym3(elementwise_3d.averaged_entries_3d(*_plot(r, azimuth, elevation), sr2, table))


def scale_3d(method: str, sigma_beta_rad: ArrayLike, sigma_elevation_rad: ArrayLike) -> NDArray:
    """κ (..., 3): the conversion's scale κ(s) per axis (``Conversion.scales``), s = sβ + sε
    on x and y, s = sε on z (the angle variances that enter each direction cosine)."""
    scales = conversion_named(method).scales(_f(sigma_beta_rad), _f(sigma_elevation_rad))
    kxy, kz = np.broadcast_arrays(*scales)
    return np.stack([kxy, kxy, kz], axis=-1)


def ucm_scale_3d(sigma_beta_rad: ArrayLike, sigma_elevation_rad: ArrayLike) -> NDArray:
    """κ (..., 3) = (e^((sβ+sε)/2), e^((sβ+sε)/2), e^(sε/2)): the unbiasing factor per axis."""
    return scale_3d("ucm", sigma_beta_rad, sigma_elevation_rad)


def ucm_cov_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> NDArray[np.float64]:
    """Covariance D C D of the unbiased 3D point, C = ``naive_cov_given_truth_3d`` at the given
    (r, β, ε) (the measurement for ``ucm``, or any better estimate of the line of sight)."""
    parts = convert_parts_3d(
        "ucm",
        r,
        azimuth,
        elevation,
        sigma_r_m=sigma_r_m,
        sigma_beta_rad=sigma_beta_rad,
        sigma_elevation_rad=sigma_elevation_rad,
    )
    return _sym3(parts[3:])


def seed_correction_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> NDArray[np.float64]:
    """Prosov's second-order term added to the naive 3D point, with eq. 10's sign.  (..., 3).

    ``second_order_correction`` (eq. 7, +½ tr(H_i Σ)) of the spherical map at the measurement,
    Σ = diag(σr², σβ², σε²). With ∂²/∂r² = 0, ∂²/∂β² = −r cos ε (cos β, sin β, 0) and
    ∂²/∂ε² = −r u it is −½ r̂ [sβ cos ε̂ (cos β̂, sin β̂, 0) + sε u]: the naive point scaled by
    (1 − (sβ+sε)/2, 1 − (sβ+sε)/2, 1 − sε/2), twice the naive bias in the other direction.
    This is the derivation of ``convert_seed_3d``'s scale, computed by the general tool (the
    tests hold the two to each other).
    """
    r, az, el = np.broadcast_arrays(_f(r), _f(azimuth), _f(elevation))
    variances = (_f(sigma_r_m) ** 2, _f(sigma_beta_rad) ** 2, _f(sigma_elevation_rad) ** 2)
    cov = np.zeros((*np.broadcast_shapes(r.shape, *(v.shape for v in variances)), 3, 3))
    for k, v in enumerate(variances):
        cov[..., k, k] = v
    H = spherical_hessians(np.stack([r, az, el], axis=-1))
    return second_order_correction(H, cov, sign="printed")
