"""The 3D position update written once, as plain arithmetic over numbers or arrays alike.

The update of ``core.filters.position`` with H picking the position (x, y, z) out of the
state (x, ẋ, y, ẏ, z, ż) and ν = z − H x⁻::

    S = H P Hᵀ + R,   K = P Hᵀ S⁻¹,   x⁺ = x⁻ + K ν
    P⁺ = Z Zᵀ + K R Kᵀ,   Z = L − K (H L),   L Lᵀ = P        (the Joseph form on a factor)

(why on a factor: ``core.filters.joseph``). The functions update their
arguments in place and index them as ``x[i]``, ``P[i, j]``: (6,) and (6, 6) arrays of one
track in numba-compiled code (``core.filters.kernels_3d`` compiles these functions), or the
component-major views (6, ...) and (6, 6, ...) of a batch in the numpy engine
(``core.filters.state.step_3d``), each entry then a (...) array. Scratch arrays come from
the caller, shaped like them. An accumulator is updated in place (``+=``) only when it is
a fresh value, never a view of an argument, so numpy and compiled code compute the same.

The semi-definite factor's pivots and the entries below them are ``core.filters.position_2d``'s
(``_pivot``, ``_below``), so a null direction is handled by one rule in 2D and 3D. The roots
and branches are ``sqrt`` and ``where``, numpy's here; the kernels re-bind them
(``core.filters.rebind``).
"""

from __future__ import annotations

import numpy as np

from radarviz.core.filters.position_2d import _below, _pivot
from radarviz.core.filters.state import SEMIDEFINITE_RTOL

#: The elementary functions, numpy's here; the kernels re-bind them.
sqrt = np.sqrt
where = np.where
log = np.log
nan = np.nan


def semidefinite_cholesky_3d(P, c, L, null_negative=False):
    """The lower Cholesky factor of c·P (6, 6) into L, semi-definite
    (``core.filters.position_2d``'s rule): a pivot in [−tol, 0] (with
    ``null_negative``: any pivot <= 0) is a null direction, its column 0; below −tol the
    track becomes NaN. L's upper triangle is written 0."""
    for j in range(6):
        d = c * P[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        ljj, null = _pivot(d, SEMIDEFINITE_RTOL * c * P[j, j], null_negative)
        L[j, j] = ljj
        for i in range(j + 1, 6):
            e = c * P[i, j]
            for k in range(j):
                e -= L[i, k] * L[j, k]
            L[i, j] = _below(e, ljj, null)
        for i in range(j):
            L[i, j] = 0.0


def inverse_3(S, Si):
    """The inverse of a symmetric 3 × 3 S into Si, by cofactors; returns the determinant."""
    a, b, c = S[0, 0], S[0, 1], S[0, 2]
    d, e, f = S[1, 1], S[1, 2], S[2, 2]
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    det = a * c00 + b * c01 + c * c02
    Si[0, 0], Si[0, 1], Si[0, 2] = c00 / det, c01 / det, c02 / det
    Si[1, 1], Si[1, 2] = (a * f - c * c) / det, (b * c - a * e) / det
    Si[2, 2] = (a * d - b * b) / det
    Si[1, 0], Si[2, 0], Si[2, 1] = Si[0, 1], Si[0, 2], Si[1, 2]
    return det


def factored_joseph_3d(P, L, K, m, R, KR):
    """P⁺ = Z Zᵀ + K R Kᵀ into P (6, 6), with Z = L − K (H L) already in L, K's first m
    columns the gain and R (m, m) the noise; KR (6, ≥ m): scratch, K R."""
    for i in range(6):
        for b in range(m):
            acc = K[i, 0] * R[0, b]
            for a in range(1, m):
                acc += K[i, a] * R[a, b]
            KR[i, b] = acc
    for i in range(6):
        for j in range(i, 6):
            acc = KR[i, 0] * K[j, 0]
            for b in range(1, m):
                acc += KR[i, b] * K[j, b]
            for k in range(6):
                acc += L[i, k] * L[j, k]
            P[i, j] = acc
            P[j, i] = acc


def position_update_3d(x, P, nu, R, S, Si, K, U, L):
    """The position update of x (6,), P (6, 6) in place by the innovation ν (3,) with noise
    R (3, 3) (module docstring); S, Si (3, 3), K (6, ≥ 3), U (6, 3), L (6, 6): scratch."""
    for a in range(3):
        for b in range(3):
            S[a, b] = P[2 * a, 2 * b] + R[a, b]
    inverse_3(S, Si)
    for i in range(6):
        for a in range(3):
            U[i, a] = P[i, 2 * a]
    for i in range(6):
        for a in range(3):
            K[i, a] = U[i, 0] * Si[0, a] + U[i, 1] * Si[1, a] + U[i, 2] * Si[2, a]
    for i in range(6):
        x[i] += K[i, 0] * nu[0] + K[i, 1] * nu[1] + K[i, 2] * nu[2]
    semidefinite_cholesky_3d(P, 1.0, L, True)
    for k in range(6):  # H L into U: U[k, a] = L[2a, k]
        for a in range(3):
            U[k, a] = L[2 * a, k]
    for i in range(6):  # Z = L − K (H L), in place
        for k in range(6):
            L[i, k] -= K[i, 0] * U[k, 0] + K[i, 1] * U[k, 1] + K[i, 2] * U[k, 2]
    factored_joseph_3d(P, L, K, 3, R, U)  # U free again: K R


def position_stats_3d(P, nu, R):
    """(νᵀ S⁻¹ ν, log det S) of a position measurement (ν (3,), R (3, 3), its upper entries
    read) on P (6, 6) (``core.filters.innovation``), S = H P Hᵀ + R, by S's Cholesky factor:
    νᵀ S⁻¹ ν = |L⁻¹ ν|², det S = the product of the pivots d₀ d₁ d₂ (each Lⱼⱼ²); both NaN
    unless S is positive definite (every pivot > 0)."""
    s00, s01, s02 = P[0, 0] + R[0, 0], P[0, 2] + R[0, 1], P[0, 4] + R[0, 2]
    s11, s12, s22 = P[2, 2] + R[1, 1], P[2, 4] + R[1, 2], P[4, 4] + R[2, 2]
    ok = s00 > 0.0
    l00 = sqrt(where(ok, s00, 1.0))
    l10, l20 = s01 / l00, s02 / l00
    d1 = s11 - l10 * l10
    ok = ok & (d1 > 0.0)
    l11 = sqrt(where(ok, d1, 1.0))
    l21 = (s12 - l20 * l10) / l11
    d2 = s22 - l20 * l20 - l21 * l21
    ok = ok & (d2 > 0.0)
    l22 = sqrt(where(ok, d2, 1.0))
    y0 = nu[0] / l00
    y1 = (nu[1] - l10 * y0) / l11
    y2 = (nu[2] - l20 * y0 - l21 * y1) / l22
    nis = y0 * y0 + y1 * y1 + y2 * y2
    return where(ok, nis, nan), where(ok, log(where(ok, s00 * d1 * d2, 1.0)), nan)
