"""The polar EKF and the line-of-sight Doppler as one update, with their errors' correlation.

The line-of-sight update (``core.filters.doppler``) writes the Doppler measurement as
V̂r = û·v + e with û = u(β̂, ε̂) the *measured* line of sight. Its error::

    e = V̂r − û·v = e_v − (g_β·v) δβ − (g_ε·v) δε,     g = ∂u/∂β, ∂u/∂ε at the measurement

contains the same angle errors δβ, δε as the plot's polar measurement (r̂, β̂, ε̂), so the two
are correlated::

    Cov(δβ, e) = −(g_β·v) σβ²,     Cov(δε, e) = −(g_ε·v) σε²,     Cov(e_r, e) = 0

Applied one after the other (the EKF, then the Doppler) the updates treat them as
independent. Here they are one Kalman update of the stacked measurement: the EKF's in metres
(``core.filters.polar_ekf.ekf_pseudo_measurement``: ν' = J ν, R' = J R Jᵀ, J the
polar-to-Cartesian Jacobian at the prediction, H = the position rows) and the Doppler row
(``core.filters.doppler.doppler_terms``: ν_d, H_d, var e), with the cross-covariance mapped
through J::

    ν = (ν', ν_d),   H = [H_pos; H_d],   R = [[R', J c], [(J c)ᵀ, var e]],
    c = (0, −(g_β·v̂) σβ²[, −(g_ε·v̂) σε²])               (v̂ the predicted velocity)

in Joseph form (``core.filters.joseph.joseph_update``). The angle errors' share of e is
ρ² = (g·v)² σβ² / var e: small for the metre- and decimetre-band radars RLS1–RLS4 (1–5%),
0.92 for the centimetre-band RLS5–RLS6 at σβ = 1° (``docs/finite_memory.md``, section 7).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from radarviz.core.filters.doppler import doppler_terms, doppler_tilt_covariance
from radarviz.core.filters.joseph import joseph_update
from radarviz.core.filters.polar_ekf import ekf_pseudo_measurement, site_offsets
from radarviz.core.filters.state import CVBatch, position_index


def joint_doppler_update(
    state: CVBatch,
    measurement: Sequence[ArrayLike],
    radial_velocity_mps: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike = 0.0,
    sigma_vr_mps: ArrayLike,
    site: ArrayLike | None = None,
) -> CVBatch:
    """The polar EKF update and the Doppler update of one plot as one (module docstring).

    Args:
        state: predicted batch (...), 2D or 3D.
        measurement: (r̂, β̂) or (r̂, β̂, ε̂), each (...), m and rad.
        radial_velocity_mps: V̂r (...), m/s.
        sigma_r_m, sigma_beta_rad, sigma_elevation_rad, sigma_vr_mps: the noise std.
        site: the radar's position (d,) (None: the origin).
    """
    dims, n = state.dims, state.x.shape[-1]
    elevation = measurement[2] if dims == 3 else 0.0
    nu_p, Rp = ekf_pseudo_measurement(
        state,
        measurement,
        sigma_r_m=sigma_r_m,
        sigma_beta_rad=sigma_beta_rad,
        sigma_elevation_rad=sigma_elevation_rad,
        site=site,
    )
    angles = dict(
        sigma_vr_mps=sigma_vr_mps,
        sigma_beta_rad=sigma_beta_rad,
        sigma_elevation_rad=sigma_elevation_rad,
    )
    nu_d, H_d, var_d = doppler_terms(
        state, radial_velocity_mps, measurement[1], elevation, **angles
    )
    c_b, c_e = doppler_tilt_covariance(state, measurement[1], elevation, **angles)
    # Columns r ∂u/∂β and r ∂u/∂ε of J at the prediction (``core.filters.polar_ekf``).
    d = site_offsets(state, site)
    if dims == 2:
        jb, je = (-d[1], d[0]), None
    else:
        rho = np.hypot(d[0], d[1])
        jb, je = (-d[1], d[0], np.zeros_like(d[0])), (-d[2] * d[0] / rho, -d[2] * d[1] / rho, rho)
    shape = state.batch_shape
    k = dims + 1
    nu = np.empty((*shape, k))
    H = np.zeros((*shape, k, n))
    R = np.empty((*shape, k, k))
    for i, p in enumerate(position_index(dims)):
        nu[..., i] = nu_p[i]
        H[..., i, p] = 1.0
        cross = jb[i] * c_b + (0.0 if je is None else je[i] * c_e)
        R[..., i, dims] = R[..., dims, i] = cross
        for j in range(i, dims):
            R[..., i, j] = R[..., j, i] = Rp[(i, j)]
    nu[..., dims] = nu_d[..., 0]
    H[..., dims, :] = H_d[..., 0, :]
    R[..., dims, dims] = var_d[..., 0, 0]
    return joseph_update(state, nu, H, R)
