"""Extended Kalman filter update with a polar radar measurement, 2D (r, β) or 3D (r, β, ε).

A radar at ``site`` measures the offset d = p − site of the target's position p::

    z = h(x) + v,   h = (r, β) in 2D, (r, β, ε) in 3D   (see ``core.geometry``),
    v ~ N(0, R),    R = diag(σr², σβ²[, σε²])

The EKF linearises h at the prediction x⁻. Only the position enters h, so the Jacobian
factors as H = G·H_pos, with G = ∂h/∂p (square, invertible for r > 0 and ρ > 0). Then the
usual equations (filterpy's ``ExtendedKalmanFilter.update``)::

    ν = (r̂ − r, wrap(β̂ − β)[, ε̂ − ε])           bearing residual wrapped to (−π, π]
    S = H P⁻ Hᵀ + R,   K = P⁻ Hᵀ S⁻¹,   x⁺ = x⁻ + K ν
    P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ

How it is computed. With J = G⁻¹ = ∂p/∂(r, β, ε) = [u, r ∂u/∂β, r ∂u/∂ε] (the
polar-to-Cartesian Jacobian at the prediction, Prosov eq. 9 in 2D)::

    S = G S' Gᵀ,  S' = H_pos P⁻ H_posᵀ + J R Jᵀ,  K H = K' H_pos,  K R Kᵀ = K' (J R Jᵀ) K'ᵀ
    with K' = K G = P⁻ H_posᵀ S'⁻¹

so the EKF update *is* a position update (``core.filters.position``) with the
pseudo-innovation ν' = J ν (m) and covariance R' = J R Jᵀ, exactly. That is how it is
evaluated: in metres throughout. (Working with the polar gain K and K G instead is
algebraically equal but mixes m and m/rad, and the difference terms cancel quantities ≈ 10⁵
times larger than P⁺, losing ~5 digits: measured 4e-10 relative.)

The columns of J at the offset d = (dx, dy[, dz]), ρ = √(dx² + dy²), r = |d|::

    u = d / r,   r ∂u/∂β = (−dy, dx[, 0]),   r ∂u/∂ε = (−dz dx/ρ, −dz dy/ρ, ρ)

Because G is evaluated at the *prediction*, the gain does not depend on this scan's
measurement error (compare the converted ``naive`` filter, whose R uses the measured bearing;
see ``docs/conversion.md``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.filters.ekf_2d import ekf_measurement_2d
from radarviz.core.filters.ekf_3d import ekf_measurement_3d
from radarviz.core.filters.position import innovation_update
from radarviz.core.filters.state import CVBatch, Vec, position_index


def site_offsets(state: CVBatch, site: ArrayLike | None) -> list[Vec]:
    """The predicted offsets d = p − site, one (...) array per axis (site None: origin)."""
    pos = position_index(state.dims)
    if site is None:
        return [state.x[..., p] for p in pos]
    s = np.asarray(site, dtype=np.float64)
    return [state.x[..., p] - s[..., i] for i, p in enumerate(pos)]


def polar_measurement_vectors(
    state: CVBatch, measurement: Sequence[ArrayLike]
) -> list[NDArray[np.float64]]:
    """The measured (r̂, β̂[, ε̂]) as float arrays of the batch shape (the only check made)."""
    want = state.batch_shape
    out = [np.asarray(m, dtype=np.float64) for m in measurement]
    if len(out) != state.dims or any(m.shape != want for m in out):
        shapes = ", ".join(str(m.shape) for m in out)
        raise ValueError(
            f"a {state.dims}D polar measurement needs {state.dims} arrays of shape {want} to "
            f"match the batch (got {shapes})"
        )
    return out


def ekf_update(
    state: CVBatch,
    measurement: Sequence[ArrayLike],
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike = 0.0,
    site: ArrayLike | None = None,
    out: CVBatch | None = None,
) -> CVBatch:
    """EKF measurement update of every track with a polar measurement (module docstring).

    Args:
        state: predicted batch (output of ``cv_predict``), 2D or 3D; no track at the site.
        measurement: (r̂, β̂) in 2D or (r̂, β̂, ε̂) in 3D, each (...) in m and rad.
        sigma_r_m, sigma_beta_rad, sigma_elevation_rad: measurement noise std.
        site: the radar's position (d,) (None: the origin).
        out: optional preallocated batch to write into (must not alias ``state``).

    Returns:
        The posterior batch (``out`` if given, else a new one).
    """
    nu, Rp = ekf_pseudo_measurement(
        state,
        measurement,
        sigma_r_m=sigma_r_m,
        sigma_beta_rad=sigma_beta_rad,
        sigma_elevation_rad=sigma_elevation_rad,
        site=site,
    )
    # S' = H_pos P⁻ H_posᵀ + R', K' = P⁻ H_posᵀ S'⁻¹, Joseph: the position update.
    return innovation_update(state, nu, Rp, out)


def ekf_pseudo_measurement(
    state: CVBatch,
    measurement: Sequence[ArrayLike],
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike = 0.0,
    site: ArrayLike | None = None,
) -> tuple[tuple[Vec, ...], dict[tuple[int, int], Vec]]:
    """The EKF's measurement in metres: ν' = J ν (d components) and R' = J R Jᵀ (upper
    entries), J at the prediction (module docstring). The polar NIS νᵀ S⁻¹ ν equals
    ν'ᵀ S'⁻¹ ν' with S' = H_pos P⁻ H_posᵀ + R' (S = G S' Gᵀ, ν = G ν')."""
    meas = polar_measurement_vectors(state, measurement)
    var_r = np.asarray(sigma_r_m, dtype=np.float64) ** 2
    var_b = np.asarray(sigma_beta_rad, dtype=np.float64) ** 2
    if state.dims == 2:
        dx, dy = site_offsets(state, site)
        nx, ny, r00, r01, r11 = ekf_measurement_2d(dx, dy, meas[0], meas[1], var_r, var_b)
        return (nx, ny), {(0, 0): r00, (0, 1): r01, (1, 1): r11}
    var_e = np.asarray(sigma_elevation_rad, dtype=np.float64) ** 2
    dx, dy, dz = site_offsets(state, site)
    shape = state.batch_shape
    nu, Rp = np.empty((3, *shape)), np.empty((3, 3, *shape))
    ekf_measurement_3d(dx, dy, dz, *meas, var_r, var_b, var_e, nu, Rp)
    return tuple(nu), {(i, j): Rp[i, j] for i in range(3) for j in range(i, 3)}
