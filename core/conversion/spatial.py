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

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.conversion.planar import _SCALES, Converted, _angle_moments, _f
from radarviz.core.conversion.second_order import second_order_correction, spherical_hessians
from radarviz.core.geometry import direction_cosines, polar_coordinates, unit_vector_partials

#: The 3D conversions, with the names of their 2D forms.
CONVERSIONS_3D: tuple[str, ...] = ("naive", "seed", "cmkf_d", "ucm", "ducm")


def _point_3d(r: NDArray, az: NDArray, el: NDArray) -> NDArray[np.float64]:
    return r[..., None] * direction_cosines(az, el)


def convert_naive_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
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
    var_b = _f(sigma_beta_rad) ** 2
    var_e = _f(sigma_elevation_rad) ** 2
    cov = (
        var_r[..., None, None] * u[..., :, None] * u[..., None, :]
        + var_b[..., None, None] * j_b[..., :, None] * j_b[..., None, :]
        + var_e[..., None, None] * j_e[..., :, None] * j_e[..., None, :]
    )
    return Converted(r[..., None] * u, cov)


class _Moments(NamedTuple):
    """What a 3D covariance needs of one angle's (cos θ̂, sin θ̂): second moments, covariances,
    first moments and the square of the mean of the cosine (each (...))."""

    ecc: NDArray[np.float64]  # E[cos² θ̂]
    ess: NDArray[np.float64]  # E[sin² θ̂]
    esc: NDArray[np.float64]  # E[sin θ̂ cos θ̂]
    vcc: NDArray[np.float64]  # Var(cos θ̂)
    vss: NDArray[np.float64]  # Var(sin θ̂)
    csc: NDArray[np.float64]  # Cov(sin θ̂, cos θ̂)
    mc: NDArray[np.float64]  # E[cos θ̂]
    ms: NDArray[np.float64]  # E[sin θ̂]
    mc2: NDArray[np.float64]  # E[cos θ̂]²


def _given_truth(theta: NDArray, s: NDArray) -> _Moments:
    """The moments of θ̂ ~ N(θ, s) (``planar._angle_moments``)."""
    m = _angle_moments(theta, s)
    return _Moments(m.ecc, m.ess, m.esc, m.vcc, m.vss, m.csc, m.mc, m.ms, m.mc * m.mc)


def _posterior_average(theta_hat: NDArray, s: NDArray) -> _Moments:
    """``_given_truth``'s moments averaged over the truth θ ~ N(θ̂, s) (flat-prior posterior).

    Averaging twice over N(0, s) is one average over N(0, 2s), so the second moments are those
    of variance 2s at θ̂; the others are linear in cos²θ, sin²θ, sin θ cos θ, cos θ, sin θ:

        E[e^(−s/2) cos θ] = e^(−s) cos θ̂,         E[(e^(−s/2) cos θ)²] = e^(−s) E[cos² θ̂]
        E[Var cos] = ½ (1 − e^(−s))² E[cos² θ̂] + ½ (1 − e^(−2s)) E[sin² θ̂]   (sin: exchanged)
        E[Cov(sin, cos)] = −e^(−s) (1 − e^(−s)) E[sin θ̂ cos θ̂]

    with E[·²] the one-angle moments at variance s (each term non-negative or a product, so
    nothing cancels).
    """
    m, m2 = _angle_moments(theta_hat, s), _angle_moments(theta_hat, 2.0 * s)
    e1, om1, om2 = np.exp(-s), -np.expm1(-s), -np.expm1(-2.0 * s)
    half1, half2 = 0.5 * om1 * om1, 0.5 * om2
    return _Moments(
        ecc=m2.ecc,
        ess=m2.ess,
        esc=m2.esc,
        vcc=half1 * m.ecc + half2 * m.ess,
        vss=half1 * m.ess + half2 * m.ecc,
        csc=-e1 * om1 * m.esc,
        mc=e1 * np.cos(theta_hat),
        ms=e1 * np.sin(theta_hat),
        mc2=e1 * m.ecc,
    )


def _combined_cov(range_sq: NDArray, var_r: NDArray, e: _Moments, b: _Moments) -> NDArray:
    """σr² E[u uᵀ] + range_sq · Cov(u), u = (a, b, c) = (cos ε̂ cos β̂, cos ε̂ sin β̂, sin ε̂),
    from elevation moments ``e`` and azimuth moments ``b``.  (..., 3, 3).

    Each entry of Cov(u) is Cov(XY, X'Y') = Cov(X, X') E[YY'] + E[X] E[X'] Cov(Y, Y') for the
    independent elevation (X) and azimuth (Y) factors, so no O(r²) terms cancel. With the
    moments given the truth and range_sq = r² this is the naive point's exact covariance; with
    their posterior averages and range_sq = r̂² + σr² (E[r²] under the posterior) it is that
    covariance averaged over the posterior, Lerro and Bar-Shalom's averaged covariance.
    """
    # (second moment E[u_i u_j], covariance Cov(u_i, u_j)) for the upper triangle.
    xx = (e.ecc * b.ecc, e.vcc * b.ecc + e.mc2 * b.vcc)
    xy = (e.ecc * b.esc, e.vcc * b.esc + e.mc2 * b.csc)
    yy = (e.ecc * b.ess, e.vcc * b.ess + e.mc2 * b.vss)
    xz = (e.esc * b.mc, e.csc * b.mc)
    yz = (e.esc * b.ms, e.csc * b.ms)
    zz = (e.ess, e.vss)
    entries = [var_r * m2 + range_sq * cv for m2, cv in (xx, xy, xz, yy, yz, zz)]
    cxx, cxy, cxz, cyy, cyz, czz = np.broadcast_arrays(*entries)
    rows = [[cxx, cxy, cxz], [cxy, cyy, cyz], [cxz, cyz, czz]]
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


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
    evaluated as σr² E[u uᵀ] + r² Cov(u) (``_combined_cov``).
    """
    r = _f(r)
    b = _given_truth(_f(azimuth), _f(sigma_beta_rad) ** 2)
    e = _given_truth(_f(elevation), _f(sigma_elevation_rad) ** 2)
    return _combined_cov(r * r, _f(sigma_r_m) ** 2, e, b)


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
    r = _f(r)
    var_r = _f(sigma_r_m) ** 2
    b = _posterior_average(_f(azimuth), _f(sigma_beta_rad) ** 2)
    e = _posterior_average(_f(elevation), _f(sigma_elevation_rad) ** 2)
    return _combined_cov(r * r + var_r, var_r, e, b)


def scale_3d(method: str, sigma_beta_rad: ArrayLike, sigma_elevation_rad: ArrayLike) -> NDArray:
    """κ (..., 3): the 2D method's scale κ(s) (``planar``) per axis, s = sβ + sε on x and y,
    s = sε on z (the angle variances that enter each direction cosine)."""
    var_beta, var_elevation = _f(sigma_beta_rad) ** 2, _f(sigma_elevation_rad) ** 2
    kappa = _SCALES[method]
    kxy, kz = np.broadcast_arrays(kappa(var_beta + var_elevation), kappa(var_elevation))
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
    sig = {
        "sigma_r_m": sigma_r_m,
        "sigma_beta_rad": sigma_beta_rad,
        "sigma_elevation_rad": sigma_elevation_rad,
    }
    kappa = ucm_scale_3d(sigma_beta_rad, sigma_elevation_rad)
    cov = naive_cov_given_truth_3d(r, azimuth, elevation, **sig)
    return kappa[..., :, None] * cov * kappa[..., None, :]


def convert_ucm_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> Converted:
    """Unbiased 3D conversion: one factor e^(s/2) per angle in each coordinate.

    κ = ``ucm_scale_3d``; the covariance is the exact true-conditioned one, D C D with
    D = diag(κ), evaluated at the measurement (``ucm_cov_3d``).
    """
    r, az, el = np.broadcast_arrays(_f(r), _f(azimuth), _f(elevation))
    kappa = ucm_scale_3d(sigma_beta_rad, sigma_elevation_rad)
    cov = ucm_cov_3d(
        r,
        az,
        el,
        sigma_r_m=sigma_r_m,
        sigma_beta_rad=sigma_beta_rad,
        sigma_elevation_rad=sigma_elevation_rad,
    )
    return Converted(kappa * _point_3d(r, az, el), cov)


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
    """
    r, az, el = np.broadcast_arrays(_f(r), _f(azimuth), _f(elevation))
    variances = (_f(sigma_r_m) ** 2, _f(sigma_beta_rad) ** 2, _f(sigma_elevation_rad) ** 2)
    cov = np.zeros((*np.broadcast_shapes(r.shape, *(v.shape for v in variances)), 3, 3))
    for k, v in enumerate(variances):
        cov[..., k, k] = v
    H = spherical_hessians(np.stack([r, az, el], axis=-1))
    return second_order_correction(H, cov, sign="printed")


def convert_seed_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> Converted:
    """Prosov's conversion in 3D: the naive point plus the second-order term as printed
    (``seed_correction_3d``), with eq. 11's covariance in 3D (``averaged_cov_3d``), as the 2D
    ``seed`` pairs them."""
    sig = {
        "sigma_r_m": sigma_r_m,
        "sigma_beta_rad": sigma_beta_rad,
        "sigma_elevation_rad": sigma_elevation_rad,
    }
    r, az, el = np.broadcast_arrays(_f(r), _f(azimuth), _f(elevation))
    point = _point_3d(r, az, el) + seed_correction_3d(r, az, el, **sig)
    return Converted(point, averaged_cov_3d(r, az, el, **sig))


def convert_cmkf_d_3d(
    r: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> Converted:
    """Lerro and Bar-Shalom's debiased conversion in 3D: the naive point minus its average bias.

    The bias given the truth is r u_i (L_i − 1), L = (e^(−(sβ+sε)/2), e^(−(sβ+sε)/2), e^(−sε/2))
    the product of the angles' e^(−s/2); averaged over the posterior of the truth, r u_i
    becomes r̂ û_i L_i, so the point is r̂ û_i (1 − (L_i² − L_i)): the 2D κ per axis
    (``scale_3d``). Covariance: the averaged one (``averaged_cov_3d``).
    """
    sig = {
        "sigma_r_m": sigma_r_m,
        "sigma_beta_rad": sigma_beta_rad,
        "sigma_elevation_rad": sigma_elevation_rad,
    }
    r, az, el = np.broadcast_arrays(_f(r), _f(azimuth), _f(elevation))
    kappa = scale_3d("cmkf_d", sigma_beta_rad, sigma_elevation_rad)
    return Converted(kappa * _point_3d(r, az, el), averaged_cov_3d(r, az, el, **sig))


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
    sig = {
        "sigma_r_m": sigma_r_m,
        "sigma_beta_rad": sigma_beta_rad,
        "sigma_elevation_rad": sigma_elevation_rad,
    }
    r, az, el = np.broadcast_arrays(_f(r), _f(azimuth), _f(elevation))
    p = _f(predicted_xyz)
    r_p, az_p, el_p = polar_coordinates([p[..., 0], p[..., 1], p[..., 2]])
    kappa = ucm_scale_3d(sigma_beta_rad, sigma_elevation_rad)
    return Converted(kappa * _point_3d(r, az, el), ucm_cov_3d(r_p, az_p, el_p, **sig))


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
    """Any of ``CONVERSIONS_3D``; ``ducm`` needs ``predicted_xyz`` (..., 3), radar-centred.

    Args:
        r, azimuth, elevation: (...) measured range (m) and angles (rad).
        sigma_r_m, sigma_beta_rad, sigma_elevation_rad: σr, σβ, σε, scalars or (...).
    """
    sig = {
        "sigma_r_m": sigma_r_m,
        "sigma_beta_rad": sigma_beta_rad,
        "sigma_elevation_rad": sigma_elevation_rad,
    }
    if method not in CONVERSIONS_3D:
        raise ValueError(f"method must be one of {', '.join(CONVERSIONS_3D)} (got {method!r})")
    if method == "ducm":
        if predicted_xyz is None:
            raise ValueError("method ducm needs predicted_xyz (the filter's predicted position)")
        return convert_ducm_3d(r, azimuth, elevation, **sig, predicted_xyz=predicted_xyz)
    return _CONVERSIONS_3D[method](r, azimuth, elevation, **sig)


_CONVERSIONS_3D = {
    "naive": convert_naive_3d,
    "seed": convert_seed_3d,
    "cmkf_d": convert_cmkf_d_3d,
    "ucm": convert_ucm_3d,
}
