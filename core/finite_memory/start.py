"""The finite-memory track start: Gorshkov and Zavizhenets' window fit as a Kalman state.

Gorshkov and Zavizhenets (2016) end with the remark that the first finite-memory estimates
(state and covariance R) should initialise the Kalman filter that follows. The fit over the
k plots of one radar (``core.finite_memory.fit``; range only or range + Doppler) gives r̂ and
V̂r at the newest plot with covariance R. In the frame of the newest measured line of sight
(unit vector u, and the unit vectors e_β = (∂u/∂β)/cos ε across it in azimuth and
e_ε = ∂u/∂ε in elevation; ``core.geometry``)::

    position = site + r̂ u,   var along = R11,  across: (r̂ cos ε σβ)², (r̂ σε)²
    velocity = V̂r u,         var along = R22,  across: σv0² each (nothing observed)
    cov(position along, velocity along) = R12

then rotated into the state (x, ẋ, y, ẏ[, z, ż]). The acceleration is dropped: the filter
that follows is constant velocity. In 2D (no elevation) the ε axis is absent.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from radarviz.core.filters.state import CVBatch, as_batch
from radarviz.core.finite_memory.fit import FiniteMemoryFit
from radarviz.core.geometry import direction_cosines, unit_vector_partials


class StartError(ValueError):
    """The fit cannot start a track (it does not estimate the radial velocity)."""


def finite_memory_start(
    fit: FiniteMemoryFit,
    ranges_m: ArrayLike,
    radial_velocities_mps: ArrayLike | None,
    azimuth_rad: ArrayLike,
    elevation_rad: ArrayLike | None = None,
    *,
    sigma_beta_rad: float,
    sigma_elevation_rad: float = 0.0,
    sigma_v0_mps: float,
    site: ArrayLike | None = None,
) -> CVBatch:
    """CV track states at the newest of k plots from the finite-memory fit (module docstring).

    Args:
        fit: a fit of at least 2 parameters (range and radial velocity) over k plots.
        ranges_m: (..., k) oldest first.  radial_velocities_mps: (..., k) or None (range only).
        azimuth_rad, elevation_rad: (...) angles of the newest plot (elevation None: 2D).
        sigma_beta_rad, sigma_elevation_rad: their noise std.
        sigma_v0_mps: std of the unobserved cross-range velocity.
        site: the radar's position (d,) (None: the origin).

    Returns:
        A batch of shape (...), 2D or 3D.
    """
    if fit.order < 2:
        raise StartError(
            f"a track start needs range and radial velocity; k = {fit.k} plots fit only "
            f"{fit.order} parameter"
        )
    ranges = np.asarray(ranges_m, dtype=np.float64)
    z = ranges
    if radial_velocities_mps is not None:
        z = np.concatenate([ranges, np.asarray(radial_velocities_mps, dtype=np.float64)], -1)
    theta = z @ fit.W[:2].T  # (..., 2): r̂, V̂r at the newest plot
    r_hat, vr_hat = theta[..., 0], theta[..., 1]
    dims = 2 if elevation_rad is None else 3
    el = 0.0 if elevation_rad is None else elevation_rad
    u = direction_cosines(azimuth_rad, el)
    g_b, g_e = unit_vector_partials(azimuth_rad, el)
    cos_el = np.cos(np.asarray(el, dtype=np.float64))
    e_b = g_b / cos_el[..., None]
    # Frame axes (columns) in the state's position space, and the variances along them.
    axes = [u, e_b] if dims == 2 else [u, e_b, g_e]
    var_p = [np.full(r_hat.shape, fit.R[0, 0]), (r_hat * cos_el * sigma_beta_rad) ** 2]
    if dims == 3:
        var_p.append((r_hat * sigma_elevation_rad) ** 2)
    var_v = [fit.R[1, 1]] + [sigma_v0_mps**2] * (dims - 1)
    G = np.stack([a[..., :dims] for a in axes], -1)  # (..., d, d): columns = frame axes
    shape = r_hat.shape
    Lp = np.zeros((*shape, dims, dims))
    Lv = np.zeros((*shape, dims, dims))
    for i in range(dims):
        Lp[..., i, i] = var_p[i]
        Lv[..., i, i] = var_v[i]
    Lpv = np.zeros((*shape, dims, dims))
    Lpv[..., 0, 0] = fit.R[0, 1]
    Gt = np.swapaxes(G, -1, -2)
    n = 2 * dims
    x = np.zeros((*shape, n))
    P = np.zeros((*shape, n, n))
    s = np.zeros(dims) if site is None else np.asarray(site, dtype=np.float64)
    x[..., 0::2] = s + r_hat[..., None] * u[..., :dims]
    x[..., 1::2] = vr_hat[..., None] * u[..., :dims]
    P[..., 0::2, 0::2] = G @ Lp @ Gt
    P[..., 1::2, 1::2] = G @ Lv @ Gt
    P[..., 0::2, 1::2] = G @ Lpv @ Gt
    P[..., 1::2, 0::2] = np.swapaxes(P[..., 0::2, 1::2], -1, -2)
    return as_batch(x, 0.5 * (P + np.swapaxes(P, -1, -2)))
