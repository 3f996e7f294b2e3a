"""Doppler in the converted measurement: the range × range-rate pseudo-measurement η = r̂ V̂r.

A radar measuring range r̂ = r + e_r and radial velocity V̂r = Vr + e_v (independent, zero
mean, std σr and σVr) gives the product η̂ = r̂ V̂r. Since r Vr = d·v for the offset d = p − s
of the target from the site, η's expectation is a function of the state alone — no angle
enters it (Duan, Han, Li 2004; Bar-Shalom, Li, Kirubarajan 2001 on pseudo-measurements)::

    η̂ = r Vr + r e_v + Vr e_r + e_r e_v
    E[η̂ | truth]   = d·v                                 (no bias: the errors are independent)
    var[η̂ | truth] = r² σVr² + Vr² σr² + σr² σVr²
    R_η = r̂² σVr² + V̂r² σr² − σr² σVr²                   (unbiased for that variance, since
                                                          E r̂² = r² + σr², E V̂r² = Vr² + σVr²)

(R_η is positive whenever r̂ > σr; it is floored at σr² σVr², its value at r̂ = σr.)

The state function h(x) = d·v is quadratic. Its linear-in-state form about the estimate
x̂ = (d̂, v̂) is h ≈ d̂·v̂ + H (x − x̂) with H = (v̂ on the position components, d̂ on the
velocity ones); for a Gaussian state the quadratic's exact mean and variance add the
second-order terms (the same bookkeeping as ``core.conversion.second_order``)::

    E[d·v]   = d̂·v̂ + tr P_pv
    var[d·v] = H P Hᵀ + tr(P_pv P_pv) + tr(P_pp P_vv)

so the update is the scalar Kalman update with ν = η̂ − d̂·v̂ − tr P_pv and
S = H P Hᵀ + R_η + tr(P_pv P_pv) + tr(P_pp P_vv), in Joseph form
(``core.filters.joseph.joseph_update``).

Used after the plot's position update (sequential processing), η̂'s error shares e_r with the
range the position update used: their correlation is Vr σr / √(r² σVr² + Vr² σr²), under 0.05
for the radars RLS1–RLS6 at 100 km, and it is neglected here.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.filters.joseph import joseph_update
from radarviz.core.filters.state import (
    CVBatch,
    position_index,
    velocity_index,
)


def converted_doppler_moments(
    range_m: ArrayLike,
    radial_velocity_mps: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_vr_mps: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The pseudo-measurement η̂ = r̂ V̂r (m²/s) and its variance R_η (m⁴/s²), each (...),
    from measured r̂ (m) and V̂r (m/s) (module docstring)."""
    r = np.asarray(range_m, dtype=np.float64)
    vr = np.asarray(radial_velocity_mps, dtype=np.float64)
    var_r = np.asarray(sigma_r_m, dtype=np.float64) ** 2
    var_v = np.asarray(sigma_vr_mps, dtype=np.float64) ** 2
    floor = var_r * var_v
    return r * vr, np.maximum(r * r * var_v + vr * vr * var_r - floor, floor)


def converted_doppler_terms(
    state: CVBatch,
    range_m: ArrayLike,
    radial_velocity_mps: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_vr_mps: ArrayLike,
    site: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The converted Doppler measurement as a linear one about the estimate: ν (..., 1),
    H (..., 1, n) and R (..., 1, 1) = R_η + tr(P_pv P_pv) + tr(P_pp P_vv) (module docstring),
    so that S = H P Hᵀ + R; for the update and the innovation statistics
    (``core.filters.innovation``). Arguments as ``converted_doppler_update``."""
    x, P = state.x, state.P
    dims, n = state.dims, x.shape[-1]
    pos, vel = list(position_index(dims)), list(velocity_index(dims))
    d = x[..., pos]
    if site is not None:
        d = d - np.asarray(site, dtype=np.float64)
    v = x[..., vel]
    eta, r_eta = converted_doppler_moments(
        range_m, radial_velocity_mps, sigma_r_m=sigma_r_m, sigma_vr_mps=sigma_vr_mps
    )
    p_pp = P[..., pos, :][..., pos]
    p_pv = P[..., pos, :][..., vel]
    p_vv = P[..., vel, :][..., vel]
    shape = state.batch_shape
    H = np.zeros((*shape, 1, n))
    H[..., 0, pos] = v
    H[..., 0, vel] = d
    mean = np.sum(d * v, axis=-1) + np.trace(p_pv, axis1=-2, axis2=-1)
    second = np.sum(p_pv * p_pv.mT, axis=(-2, -1)) + np.sum(p_pp * p_vv.mT, axis=(-2, -1))
    nu = np.empty((*shape, 1))
    nu[..., 0] = eta - mean
    R = np.empty((*shape, 1, 1))
    R[..., 0, 0] = r_eta + second
    return nu, H, R


def converted_doppler_update(
    state: CVBatch,
    range_m: ArrayLike,
    radial_velocity_mps: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_vr_mps: ArrayLike,
    site: ArrayLike | None = None,
    out: CVBatch | None = None,
) -> CVBatch:
    """Update every track of a 2D or 3D batch with η̂ = r̂ V̂r (module docstring).

    Args:
        state: (..., n) states, n = 4 or 6, after this plot's position update.
        range_m, radial_velocity_mps: the plot's measured r̂ (m) and V̂r (m/s), (...) or scalar.
        sigma_r_m, sigma_vr_mps: their noise std.
        site: the radar's position (d,) or (..., d), m; the origin if None.
        out: optional preallocated batch to write into (must not alias ``state``).
    """
    nu, H, R = converted_doppler_terms(
        state,
        range_m,
        radial_velocity_mps,
        sigma_r_m=sigma_r_m,
        sigma_vr_mps=sigma_vr_mps,
        site=site,
    )
    return joseph_update(state, nu, H, R, out)
