"""Doppler radial velocity as a linear velocity measurement along the measured line of sight.

A radar measuring V̂r (and, in the same plot, β̂ and ε̂) sees the target's velocity v
projected on the line of sight u(β, ε) (``core.geometry``). Using the *measured* direction
û = u(β̂, ε̂) makes the measurement linear in the state::

    V̂r = û·v + e,   H = û on the velocity components (0 on the position),
    var e = σVr² + σβ² ((g_β·v̂)² + g_βᵀ P_vv g_β) + σε² ((g_ε·v̂)² + g_εᵀ P_vv g_ε),
    g_β = ∂u/∂β,  g_ε = ∂u/∂ε                  (a small angle error δ tilts u by g δ, so
                                                V̂r moves by g·v δ)

In 2D (no elevation) ε = 0 and the σε term is absent. The Kalman update is then exact given
that variance; it needs no predicted position, which is what makes the textbook EKF row
∂Vr/∂x fail when σVr is small (its position derivative is (tangential speed)/r, taken as 0
at a start where the cross-range velocity is unobserved; see ``docs/finite_memory.md``).
Joseph form, for the scalar measurement::

    U = P hᵀ,  S = h U + var e,  K = U / S,  x⁺ = x + K (V̂r − û·v̂),
    P⁺ = (I − K h) P (I − K h)ᵀ + K var e Kᵀ

evaluated on a Cholesky factor of P (``core.filters.joseph``): never
P − K S Kᵀ, whose subtraction leaves rounding of either sign when P_vv is large against
var e.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.filters.doppler_2d import doppler_stats_2d, doppler_update_2d
from radarviz.core.filters.doppler_3d import doppler_stats_3d, doppler_update_3d
from radarviz.core.filters.innovation import InnovationStats, innovation_stats
from radarviz.core.filters.state import (
    CVBatch,
    components,
    cov_components,
    mean_components,
    step_2d,
    step_3d,
    tuples_2d,
    velocity_index,
)


def _values(
    radial_velocity_mps: ArrayLike,
    azimuth_rad: ArrayLike,
    sigma_vr_mps: ArrayLike,
    sigma_beta_rad: ArrayLike,
) -> tuple[NDArray[np.float64], ...]:
    """V̂r, β̂, σVr² and σβ² as arrays, as the update and its statistics take them."""
    f = np.float64
    return (
        np.asarray(radial_velocity_mps, dtype=f),
        np.asarray(azimuth_rad, dtype=f),
        np.asarray(sigma_vr_mps, dtype=f) ** 2,
        np.asarray(sigma_beta_rad, dtype=f) ** 2,
    )


def doppler_update(
    state: CVBatch,
    radial_velocity_mps: ArrayLike,
    azimuth_rad: ArrayLike,
    elevation_rad: ArrayLike = 0.0,
    *,
    sigma_vr_mps: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike = 0.0,
    out: CVBatch | None = None,
) -> CVBatch:
    """Doppler update of every track of a 2D or 3D batch (module docstring).

    Args:
        state: the batch after this plot's position update (or its prediction).
        radial_velocity_mps: measured V̂r, (...) or scalar.
        azimuth_rad, elevation_rad: the plot's measured angles (elevation 0 in 2D).
        sigma_vr_mps, sigma_beta_rad, sigma_elevation_rad: the plot's noise std.
        out: optional preallocated batch to write into (must not alias ``state``).
    """
    vr, az, var_vr, var_b = _values(radial_velocity_mps, azimuth_rad, sigma_vr_mps, sigma_beta_rad)
    if state.dims == 2:  # written once, for every engine (``core.filters.doppler_2d``)
        return step_2d(doppler_update_2d, state, (vr, az, var_vr, var_b), out)
    # in 3D, ``core.filters.doppler_3d``, û's angles as (cos β̂, sin β̂, cos ε̂, sin ε̂)
    el = np.asarray(elevation_rad, dtype=np.float64)
    var_e = np.asarray(sigma_elevation_rad, dtype=np.float64) ** 2
    trig = components((np.cos(az), np.sin(az), np.cos(el), np.sin(el)), state.batch_shape)
    args = (vr, trig, var_vr, var_b, var_e)
    return step_3d(doppler_update_3d, state, args, SCRATCH_3D, out)


#: The scratch arrays of ``doppler_update_3d``: u (3,), U, K (6,), L (6, 6).
SCRATCH_3D = ((3,), (6,), (6,), (6, 6))


def doppler_innovation(
    state: CVBatch,
    radial_velocity_mps: ArrayLike,
    azimuth_rad: ArrayLike,
    elevation_rad: ArrayLike = 0.0,
    *,
    sigma_vr_mps: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike = 0.0,
) -> InnovationStats:
    """The innovation statistics of the Doppler update of every track (``doppler_update``'s
    arguments): ν = V̂r − û·v̂, S = û P_vv ûᵀ + var e, one degree of freedom. Written once for
    every engine (``doppler_stats_2d``, ``doppler_stats_3d``), on the batch's components."""
    vr, az, var_vr, var_b = _values(radial_velocity_mps, azimuth_rad, sigma_vr_mps, sigma_beta_rad)
    with np.errstate(invalid="ignore", divide="ignore"):
        if state.dims == 2:
            stats = doppler_stats_2d(*tuples_2d(state), vr, az, var_vr, var_b)
        else:
            el = np.asarray(elevation_rad, dtype=np.float64)
            var_e = np.asarray(sigma_elevation_rad, dtype=np.float64) ** 2
            trig = (np.cos(az), np.sin(az), np.cos(el), np.sin(el))
            xc, Pc = mean_components(state.x), cov_components(state.P)
            stats = doppler_stats_3d(xc, Pc, vr, trig, var_vr, var_b, var_e, [0.0, 0.0, 0.0])
    return innovation_stats(stats, state.batch_shape, 1)


def doppler_terms(
    state: CVBatch,
    radial_velocity_mps: ArrayLike,
    azimuth_rad: ArrayLike,
    elevation_rad: ArrayLike = 0.0,
    *,
    sigma_vr_mps: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The Doppler measurement as a linear one: ν (..., 1), H (..., 1, n) and var e (..., 1, 1)
    (module docstring), for the innovation statistics (``core.filters.innovation``)."""
    geometry = _geometry(
        state.dims, azimuth_rad, elevation_rad, sigma_vr_mps, sigma_beta_rad, sigma_elevation_rad
    )
    return _dense_terms(state, radial_velocity_mps, *geometry)


def doppler_tilt_covariance(
    state: CVBatch,
    azimuth_rad: ArrayLike,
    elevation_rad: ArrayLike = 0.0,
    *,
    sigma_vr_mps: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Cov(δβ, e) = −(g_β·v̂) σβ² and Cov(δε, e) = −(g_ε·v̂) σε², each (...): the covariance of
    the plot's angle errors with this update's error e (module docstring), at the estimate's
    velocity v̂ (``core.filters.joint_doppler``). ``sigma_vr_mps`` is not used (e_v is
    independent of the angles); it is accepted so the keywords match ``doppler_terms``."""
    dims = state.dims
    _, g_b, g_e, _, var_b, var_e = _geometry(
        dims, azimuth_rad, elevation_rad, sigma_vr_mps, sigma_beta_rad, sigma_elevation_rad
    )
    v = [state.x[..., i] for i in velocity_index(dims)]
    gv_b = sum(g_b[a] * v[a] for a in range(min(dims, 2)))
    gv_e = sum(g_e[a] * v[a] for a in range(dims))
    return -gv_b * var_b, -gv_e * var_e


def _geometry(
    dims: int,
    azimuth_rad: ArrayLike,
    elevation_rad: ArrayLike,
    sigma_vr_mps: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> tuple:
    """u, ∂u/∂β, ∂u/∂ε (first ``dims`` axes) and the variances σVr², σβ², σε²."""
    az = np.asarray(azimuth_rad, dtype=np.float64)
    el = np.asarray(elevation_rad, dtype=np.float64)
    ca, sa, ce, se = np.cos(az), np.sin(az), np.cos(el), np.sin(el)
    # u = (cos ε cos β, cos ε sin β, sin ε), ∂u/∂β = cos ε (−sin β, cos β, 0),
    # ∂u/∂ε = (−sin ε cos β, −sin ε sin β, cos ε)  (``core.geometry``), first ``dims`` axes.
    u = (ce * ca, ce * sa, se)[:dims]
    g_b = (-ce * sa, ce * ca)
    g_e = (-se * ca, -se * sa, ce)
    var_vr = np.asarray(sigma_vr_mps, dtype=np.float64) ** 2
    var_b = np.asarray(sigma_beta_rad, dtype=np.float64) ** 2
    var_e = np.asarray(sigma_elevation_rad, dtype=np.float64) ** 2
    return u, g_b, g_e, var_vr, var_b, var_e


def _dense_terms(
    state: CVBatch,
    radial_velocity_mps: ArrayLike,
    u: tuple,
    g_b: tuple,
    g_e: tuple,
    var_vr: NDArray[np.float64],
    var_b: NDArray[np.float64],
    var_e: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """ν (..., 1), H (..., 1, n), var e (..., 1, 1) as arrays (the dense path's terms)."""
    dims, n = state.dims, state.x.shape[-1]
    shape = state.batch_shape
    vel = list(velocity_index(dims))
    v = state.x[..., vel]  # (..., d)
    Pvv = state.P[..., vel, :][..., vel]  # (..., d, d)

    def vectors(g: tuple) -> NDArray[np.float64]:
        """The first ``dims`` components of g as one (..., dims) array (a missing one is 0)."""
        comps = [g[a] if a < len(g) else 0.0 for a in range(dims)]
        if all(np.ndim(c) == 0 for c in comps):  # one direction for the whole batch
            return np.broadcast_to(np.array(comps, dtype=np.float64), (*shape, dims))
        arr = np.zeros((*shape, dims))
        for a in range(dims):
            arr[..., a] = comps[a]
        return arr

    def angle_term(g: NDArray[np.float64]) -> NDArray[np.float64]:
        gv = (g[..., None, :] @ v[..., :, None])[..., 0, 0]
        return gv * gv + (g[..., None, :] @ Pvv @ g[..., :, None])[..., 0, 0]

    u_v = vectors(u)
    r_e = var_vr + var_b * angle_term(vectors(g_b))
    if dims == 3:
        r_e = r_e + var_e * angle_term(vectors(g_e))
    H = np.zeros((*shape, 1, n))
    H[..., 0, vel] = u_v
    nu = np.empty((*shape, 1))
    nu[..., 0] = radial_velocity_mps - (u_v[..., None, :] @ v[..., :, None])[..., 0, 0]
    R = np.empty((*shape, 1, 1))
    R[..., 0, 0] = r_e
    return nu, H, R
