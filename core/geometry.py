"""Radar geometry: lines of sight, their unit vectors and derivatives, radial velocity, angles.

A radar at ``site`` sees a point p along the offset d = p − site. Azimuth β is counted in the
x–y plane from +x towards +y, elevation ε above that plane::

    r = |d|,   β = atan2(d_y, d_x),   ε = atan2(d_z, ρ),   ρ = √(d_x² + d_y²)
    d = r u(β, ε),   u = (cos ε cos β, cos ε sin β, sin ε)       (the direction cosines)

Derivatives of the unit vector, used by every linearisation in the project (the first-order
covariance of a converted point, the EKF, the Doppler update, the velocity solve)::

    ∂u/∂β = cos ε (−sin β, cos β, 0),     ∂u/∂ε = (−sin ε cos β, −sin ε sin β, cos ε)

so ∂d/∂(r, β, ε) = [u, r ∂u/∂β, r ∂u/∂ε] (the columns of the polar-to-Cartesian Jacobian).
In 2D (no elevation) the same formulas hold with ε = 0 and the z component dropped.

Every function broadcasts over any leading batch shape ``(...)``; angles are radians.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

_TWO_PI = 2.0 * np.pi


def _f(a: ArrayLike) -> NDArray[np.float64]:
    return np.asarray(a, dtype=np.float64)


def wrap_angle(a: ArrayLike) -> NDArray[np.float64]:
    """Wrap angles (rad) to the interval (−π, π].  Elementwise, any shape.

    ``a − 2π·ceil(a/(2π) − ½)``: subtract the whole turns that bring ``a`` nearest to 0, ties
    (±π) going to +π. An angle already in (−π, π] is returned exactly (k = 0), tiny angles
    included; and it is several times faster than ``np.mod``, which matters because every
    update wraps a few (M,) vectors.
    """
    a = np.asarray(a, dtype=np.float64)
    return a - _TWO_PI * np.ceil(a * (1.0 / _TWO_PI) - 0.5)


class LineOfSight(NamedTuple):
    """Range (m), azimuth and elevation (rad) of a target from each site, each (..., N)."""

    range: NDArray[np.float64]
    azimuth: NDArray[np.float64]
    elevation: NDArray[np.float64]


def polar_coordinates(offset: Sequence[ArrayLike]) -> list[NDArray[np.float64]]:
    """(r, β) of 2D offsets (dx, dy), or (r, β, ε) of 3D offsets (dx, dy, dz), componentwise.

    The one place where a radar's polar coordinates of a point are computed: measurement
    generation, the EKF's predicted measurement and the UKF's sigma points all call it, so
    they agree to the last bit. Each component is a (...) array.
    """
    dx, dy = _f(offset[0]), _f(offset[1])
    rho = np.hypot(dx, dy)
    azimuth = np.arctan2(dy, dx)
    if len(offset) == 2:
        return [rho, azimuth]
    dz = _f(offset[2])
    return [np.sqrt(rho * rho + dz * dz), azimuth, np.arctan2(dz, rho)]


def line_of_sight(sites: ArrayLike, target: ArrayLike) -> LineOfSight:
    """(r, β, ε) of ``target`` (..., 3) seen from ``sites`` (N, 3); shapes (..., N)."""
    d = _f(target)[..., None, :] - _f(sites)
    return LineOfSight(*polar_coordinates([d[..., 0], d[..., 1], d[..., 2]]))


def direction_cosines(azimuth: ArrayLike, elevation: ArrayLike) -> NDArray[np.float64]:
    """u = (cos ε cos β, cos ε sin β, sin ε): (...) angles → (..., 3) unit vectors."""
    az, el = _f(azimuth), _f(elevation)
    ce = np.cos(el)
    return np.stack(np.broadcast_arrays(ce * np.cos(az), ce * np.sin(az), np.sin(el)), axis=-1)


class UnitVectorPartials(NamedTuple):
    """∂u/∂β and ∂u/∂ε of the direction cosines, each (..., 3)."""

    d_azimuth: NDArray[np.float64]
    d_elevation: NDArray[np.float64]


def unit_vector_partials(azimuth: ArrayLike, elevation: ArrayLike) -> UnitVectorPartials:
    """∂u/∂β = cos ε (−sin β, cos β, 0) and ∂u/∂ε = (−sin ε cos β, −sin ε sin β, cos ε)."""
    az, el = _f(azimuth), _f(elevation)
    ca, sa, ce, se = np.cos(az), np.sin(az), np.cos(el), np.sin(el)
    d_az = np.stack(np.broadcast_arrays(-ce * sa, ce * ca, np.zeros_like(ce * ca)), axis=-1)
    d_el = np.stack(np.broadcast_arrays(-se * ca, -se * sa, ce), axis=-1)
    return UnitVectorPartials(d_az, d_el)


def radial_velocity(
    position: ArrayLike, velocity: ArrayLike, site: ArrayLike = 0.0
) -> NDArray[np.float64]:
    """Vr = u·v = (d·v)/|d| with d = position − site: (..., D) vectors → (...), D = 2 or 3."""
    d = _f(position) - _f(site)
    v = _f(velocity)
    return np.sum(d * v, axis=-1) / np.sqrt(np.sum(d * d, axis=-1))


def range_cross_basis(site: ArrayLike, target: ArrayLike) -> NDArray[np.float64]:
    """Rows (cross-range unit, range unit) of the planar frame of ``target`` seen from ``site``.

    u = (target − site) / |target − site| points away from the radar (down-range); c = (−u_y,
    u_x) is u turned 90° counter-clockwise (cross-range, the direction of increasing azimuth).
    For an offset d from the target, ``B @ d`` is (cross-range, down-range) in m, and a
    covariance P of positions becomes B P Bᵀ in that frame. Shapes: site (2,) or (..., 2),
    target (..., 2); result (..., 2, 2).
    """
    d = _f(target) - _f(site)
    u = d / np.linalg.norm(d, axis=-1, keepdims=True)
    c = np.stack([-u[..., 1], u[..., 0]], axis=-1)
    return np.stack([c, u], axis=-2)


def range_cross_up_basis(site: ArrayLike, target: ArrayLike) -> NDArray[np.float64]:
    """Rows (down-range, cross-range, up) of the 3D frame of ``target`` seen from ``site``.

    u = (target − site) / |target − site| (down-range); c = (−sin β, cos β, 0), the horizontal
    direction of increasing azimuth (cross-range); w = u × c, perpendicular to both and
    pointing up (the direction of increasing elevation). For an offset d from the target,
    ``B @ d`` is (down-range, cross-range, up) in m; a covariance P becomes B P Bᵀ. Shapes:
    site (3,) or (..., 3), target (..., 3); result (..., 3, 3). Not defined straight overhead.
    """
    d = _f(target) - _f(site)
    u = d / np.linalg.norm(d, axis=-1, keepdims=True)
    az = np.arctan2(d[..., 1], d[..., 0])
    c = np.stack([-np.sin(az), np.cos(az), np.zeros_like(az)], axis=-1)
    return np.stack([u, c, np.cross(u, c)], axis=-2)
