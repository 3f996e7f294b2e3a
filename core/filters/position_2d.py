"""The 2D position update (the converted-measurement Kalman update) written once, as plain
arithmetic over numbers or arrays alike.

The state is (x, ẋ, y, ẏ) as a 4-tuple and P as its ten upper entries
(``core.filters.state.UPPER_2D``); each entry is a number (one track, in numba-compiled
code: ``core.filters.kernels_2d`` compiles these functions) or an array (a batch, in the
numpy engine: ``core.filters.position.innovation_update``). The update, with H picking the
position and ν = z − H x⁻::

    S = H P Hᵀ + R,   K = P Hᵀ S⁻¹,   x⁺ = x⁻ + K ν
    P⁺ = Z Zᵀ + K R Kᵀ,   Z = L − K (H L),   L Lᵀ = P        (the Joseph form on a factor)

is ``core.filters.position``'s (why on a factor: ``core.filters.joseph``). The
semi-definite Cholesky factor is the recursion d_j = P_jj − Σ_{k<j} L_jk², L_jj = √d_j,
L_ij = (P_ij − Σ_{k<j} L_ik L_jk) / L_jj; a pivot d_j in [−tol, 0], tol = 10⁻⁹ P_jj
(``core.filters.state.SEMIDEFINITE_RTOL``, why that size: there), is a direction of zero
variance (its column 0, the exact factor of a semi-definite P) and one below −tol gives NaN
for that track only; with ``null_negative`` every pivot <= 0 is a null direction (the Kalman
updates' factor, ``core.filters.joseph``).

The branches of that factor are written with ``where`` and the roots with ``sqrt``, this
module's numpy functions; the compiled kernels compile a copy of these functions with the
scalar ones (``core.filters.rebind``), so numbers and arrays take one code.
"""

from __future__ import annotations

import math

import numpy as np

from radarviz.core.filters.state import SEMIDEFINITE_RTOL

#: The elementary functions, numpy's here; the kernels rebind them to scalar ones.
sqrt = np.sqrt
where = np.where
log = np.log
nan = math.nan


def _pivot(d, tol, null_negative: bool):
    # A pivot in [−tol, 0] (with null_negative: any pivot <= 0) is a null direction (0); below
    # −tol: NaN (indefinite beyond rounding: this track becomes NaN); above 0: a variance
    null = (d <= 0.0) if null_negative else (d <= 0.0) & (d >= -tol)
    return sqrt(where(null, 0.0, where(d < -tol, nan, d))), null


def _below(e, d, null):
    # L's entry below a pivot d: e / d, or 0 in a null direction's column
    return where(null, 0.0, e / where(null, 1.0, d))


def semidefinite_cholesky_2d(p, c: float, null_negative: bool = False):
    """The lower Cholesky factor of c·P (module docstring; ``null_negative``: every pivot
    <= 0 a null direction) as its columns (L[:, 0], …, L[:, 3]), 4-tuples each."""
    p00, p01, p02, p03, p11, p12, p13, p22, p23, p33 = p
    rt, nn = SEMIDEFINITE_RTOL, null_negative
    l00, n0 = _pivot(c * p00, rt * c * p00, nn)
    l10, l20, l30 = _below(c * p01, l00, n0), _below(c * p02, l00, n0), _below(c * p03, l00, n0)
    l11, n1 = _pivot(c * p11 - l10 * l10, rt * c * p11, nn)
    l21 = _below(c * p12 - l20 * l10, l11, n1)
    l31 = _below(c * p13 - l30 * l10, l11, n1)
    l22, n2 = _pivot(c * p22 - l20 * l20 - l21 * l21, rt * c * p22, nn)
    l32 = _below(c * p23 - l30 * l20 - l31 * l21, l22, n2)
    l33, _ = _pivot(c * p33 - l30 * l30 - l31 * l31 - l32 * l32, rt * c * p33, nn)
    return (l00, l10, l20, l30), (0.0, l11, l21, l31), (0.0, 0.0, l22, l32), (0.0, 0.0, 0.0, l33)


def _add_outer(p, w: float, e):
    # P + w e eᵀ (upper entries)
    e0, e1, e2, e3 = e
    return (
        p[0] + w * e0 * e0, p[1] + w * e0 * e1, p[2] + w * e0 * e2, p[3] + w * e0 * e3,
        p[4] + w * e1 * e1, p[5] + w * e1 * e2, p[6] + w * e1 * e3,
        p[7] + w * e2 * e2, p[8] + w * e2 * e3,
        p[9] + w * e3 * e3,
    )  # fmt: skip


def _z_col(col, k0, k1, h0: float, h1: float):
    # column k of Z = L − K (H L): L's column ``col`` less the gain's columns k0, k1 times
    # that column's (H L) entries h0, h1
    return (
        col[0] - (k0[0] * h0 + k1[0] * h1),
        col[1] - (k0[1] * h0 + k1[1] * h1),
        col[2] - (k0[2] * h0 + k1[2] * h1),
        col[3] - (k0[3] * h0 + k1[3] * h1),
    )


def _krk(ki0: float, ki1: float, kj0: float, kj1: float, r00: float, r01: float, r11: float):
    # (K R Kᵀ)_ij for a two-column gain
    return ki0 * (r00 * kj0 + r01 * kj1) + ki1 * (r01 * kj0 + r11 * kj1)


def position_update_2d(xt, p, nx: float, ny: float, r00: float, r01: float, r11: float):
    # core.filters.position: S = H P Hᵀ + R, K = P Hᵀ S⁻¹, x⁺ = x + K ν, and the Joseph form
    # on P's Cholesky factor L, P⁺ = Z Zᵀ + K R Kᵀ with Z = L − K (H L): a sum of squares,
    # never P − K S Kᵀ (``core.filters.joseph``).
    x0, x1, x2, x3 = xt
    p00, p01, p02, p03, _, p12, _, p22, p23, _ = p
    s00, s01, s11 = p00 + r00, p02 + r01, p22 + r11
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    # U's columns: P's x and y columns
    u00, u01, u10, u11, u20, u21, u30, u31 = p00, p02, p01, p12, p02, p22, p03, p23
    k00, k01 = u00 * i00 + u01 * i01, u00 * i01 + u01 * i11
    k10, k11 = u10 * i00 + u11 * i01, u10 * i01 + u11 * i11
    k20, k21 = u20 * i00 + u21 * i01, u20 * i01 + u21 * i11
    k30, k31 = u30 * i00 + u31 * i01, u30 * i01 + u31 * i11
    xn = (
        x0 + (k00 * nx + k01 * ny),
        x1 + (k10 * nx + k11 * ny),
        x2 + (k20 * nx + k21 * ny),
        x3 + (k30 * nx + k31 * ny),
    )
    L0, L1, L2, L3 = semidefinite_cholesky_2d(p, 1.0, True)
    k0, k1 = (k00, k10, k20, k30), (k01, k11, k21, k31)
    pn = (
        _krk(k00, k01, k00, k01, r00, r01, r11),
        _krk(k00, k01, k10, k11, r00, r01, r11),
        _krk(k00, k01, k20, k21, r00, r01, r11),
        _krk(k00, k01, k30, k31, r00, r01, r11),
        _krk(k10, k11, k10, k11, r00, r01, r11),
        _krk(k10, k11, k20, k21, r00, r01, r11),
        _krk(k10, k11, k30, k31, r00, r01, r11),
        _krk(k20, k21, k20, k21, r00, r01, r11),
        _krk(k20, k21, k30, k31, r00, r01, r11),
        _krk(k30, k31, k30, k31, r00, r01, r11),
    )
    # (H L)'s columns: L's x and y rows (L3 has neither)
    pn = _add_outer(pn, 1.0, _z_col(L0, k0, k1, L0[0], L0[2]))
    pn = _add_outer(pn, 1.0, _z_col(L1, k0, k1, 0.0, L1[2]))
    pn = _add_outer(pn, 1.0, _z_col(L2, k0, k1, 0.0, L2[2]))
    pn = _add_outer(pn, 1.0, L3)
    return xn, pn


def position_stats_2d(p00, p02, p22, nx, ny, r00, r01, r11):
    """(νᵀ S⁻¹ ν, log det S) of a position measurement on P's position entries p00, p02, p22
    (``core.filters.innovation``): S = H P Hᵀ + R = [[p00 + r00, p02 + r01], [·, p22 + r11]],

        νᵀ S⁻¹ ν = (s11 νx² − 2 s01 νx νy + s00 νy²) / det S,   det S = s00 s11 − s01²;

    both NaN unless S is positive definite (a broken track: the monitor counts it out of
    band, the IMM gives that model no weight)."""
    s00, s01, s11 = p00 + r00, p02 + r01, p22 + r11
    det = s00 * s11 - s01 * s01
    ok = (s00 > 0.0) & (det > 0.0)
    d = where(ok, det, 1.0)
    nis = (s11 * nx * nx - 2.0 * s01 * nx * ny + s00 * ny * ny) / d
    return where(ok, nis, nan), where(ok, log(d), nan)
