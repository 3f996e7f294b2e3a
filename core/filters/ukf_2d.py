"""The 2D polar UKF update written once, as plain arithmetic over numbers or arrays alike.

``core.filters.polar_ukf`` states the filter (filterpy's ``UnscentedKalmanFilter.update``
after a linear predict, Van der Merwe's scaled points) and why P⁺ is taken in its Joseph form.
In 2D, with L the lower semi-definite Cholesky factor of (n + λ) P⁻ (columns L0 … L3) and the
radar at (sx, sy)::

    χ₀ = x⁻,  χ_k± = x⁻ ± L_k                         the 2n + 1 = 9 sigma points
    ζ = (|d|, atan2(dy, dx)) of each point's offset d from the radar
    ẑ_r = Wm₀ ζ₀_r + W Σ ζ_r,  ẑ_β = wrap(β₀ + W Σ wrap(ζ_β − β₀))    (bearings about β₀)
    S = Σ Wc d dᵀ + R,  Pxz = W Σ_k L_k (d_k+ − d_k−)ᵀ,  d = ζ ⊖ ẑ
    K = Pxz S⁻¹,  x⁺ = x⁻ + K (z ⊖ ẑ)
    P⁺ = Σ Wc_p e_p e_pᵀ + K R Kᵀ,  e_p = (χ_p − x⁻) − K d_p

Only the position enters h, and L is lower triangular: column k moves the position by
(L0[0], L0[2]), (0, L1[2]), (0, L2[2]) and (0, 0), so column 3's two points map to ζ₀, and
columns 1 and 2 move y alone. Six distinct polar evaluations besides ζ₀.

The elementary functions (``sqrt``, ``atan2``, ``wrap``, and ``where`` in the factor) are
numpy's here; numba-compiled code (``core.filters.kernels_2d``) and the array-API path
(``core.filters.array_api``) re-bind them (``core.filters.rebind``), so every engine runs
these lines.
"""

from __future__ import annotations

import numpy as np

from radarviz.core.filters.position_2d import _add_outer, semidefinite_cholesky_2d
from radarviz.core.geometry import wrap_angle

#: The elementary functions, numpy's here; the kernels and the array-API path rebind them.
sqrt = np.sqrt
atan2 = np.arctan2
wrap = wrap_angle


def _norm(x, y):
    # √(x² + y²): hypot's guard against overflow is not needed at radar ranges, and costs
    # several times the square root
    return sqrt(x * x + y * y)


def _point_error(f, col, k0, k1, d0, d1):
    # e = f L[:, k] − K d for the point ±column k with residual d
    return (
        f * col[0] - (k0[0] * d0 + k1[0] * d1),
        f * col[1] - (k0[1] * d0 + k1[1] * d1),
        f * col[2] - (k0[2] * d0 + k1[2] * d1),
        f * col[3] - (k0[3] * d0 + k1[3] * d1),
    )


def _gain_row(l0, l1, l2, e0r, e1r, e2r, e0b, e1b, e2b, w, i00, i01, i11):
    # row i of K = Pxz S⁻¹, Pxz's row W Σ_k L[i, k] (d_k+ − d_k−) (column 3's difference is 0)
    a0 = w * (l0 * e0r + l1 * e1r + l2 * e2r)
    a1 = w * (l0 * e0b + l1 * e1b + l2 * e2b)
    return a0 * i00 + a1 * i01, a0 * i01 + a1 * i11


def ukf_update_2d(xt, p, r, b, var_r, var_b, sx, sy, c, wm0, wc0, w):
    """The UKF update of the state (xt, p) (``core.filters.position_2d``'s tuples) by the
    plot (r, b) of the radar at (sx, sy) (module docstring).

    Args:
        var_r, var_b: σr² (m²) and σβ² (rad²).
        c, wm0, wc0, w: ``UKFParams.weights(4)``: n + λ, Wm₀, Wc₀ and W.
    """
    L0, L1, L2, L3 = semidefinite_cholesky_2d(p, c)
    px, py = xt[0] - sx, xt[2] - sy
    r0, b0 = _norm(px, py), atan2(py, px)
    ra, ba = _norm(px + L0[0], py + L0[2]), atan2(py + L0[2], px + L0[0])
    rb, bb = _norm(px - L0[0], py - L0[2]), atan2(py - L0[2], px - L0[0])
    rc, bc = _norm(px, py + L1[2]), atan2(py + L1[2], px)
    rd, bd = _norm(px, py - L1[2]), atan2(py - L1[2], px)
    re, be = _norm(px, py + L2[2]), atan2(py + L2[2], px)
    rf, bf = _norm(px, py - L2[2]), atan2(py - L2[2], px)
    # the unscented mean: z̄r = Wm0 r0 + W Σ r_p, z̄β = β0 + W Σ wrap(β_p − β0)
    zr = wm0 * r0 + w * (ra + rb + rc + rd + re + rf + 2.0 * r0)
    acc = wrap(ba - b0) + wrap(bb - b0) + wrap(bc - b0) + wrap(bd - b0)
    zb = wrap(b0 + w * (acc + wrap(be - b0) + wrap(bf - b0)))
    # residuals d_p = (r_p − z̄r, wrap(β_p − z̄β)): central (g), ±column 0 (a, b), 1 (c, d),
    # 2 (e, f); column 3's are the central one
    gr, gb = r0 - zr, wrap(b0 - zb)
    dar, dab = ra - zr, wrap(ba - zb)
    dbr, dbb = rb - zr, wrap(bb - zb)
    dcr, dcb = rc - zr, wrap(bc - zb)
    ddr, ddb = rd - zr, wrap(bd - zb)
    der, deb = re - zr, wrap(be - zb)
    dfr, dfb = rf - zr, wrap(bf - zb)
    wg = wc0 + 2.0 * w
    s00 = dar * dar + dbr * dbr + dcr * dcr + ddr * ddr + der * der + dfr * dfr
    s01 = dar * dab + dbr * dbb + dcr * dcb + ddr * ddb + der * deb + dfr * dfb
    s11 = dab * dab + dbb * dbb + dcb * dcb + ddb * ddb + deb * deb + dfb * dfb
    s00 = var_r + wg * gr * gr + w * s00
    s01 = wg * gr * gb + w * s01
    s11 = var_b + wg * gb * gb + w * s11
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    e0r, e1r, e2r = dar - dbr, dcr - ddr, der - dfr
    e0b, e1b, e2b = dab - dbb, dcb - ddb, deb - dfb
    k00, k01 = _gain_row(L0[0], L1[0], L2[0], e0r, e1r, e2r, e0b, e1b, e2b, w, i00, i01, i11)
    k10, k11 = _gain_row(L0[1], L1[1], L2[1], e0r, e1r, e2r, e0b, e1b, e2b, w, i00, i01, i11)
    k20, k21 = _gain_row(L0[2], L1[2], L2[2], e0r, e1r, e2r, e0b, e1b, e2b, w, i00, i01, i11)
    k30, k31 = _gain_row(L0[3], L1[3], L2[3], e0r, e1r, e2r, e0b, e1b, e2b, w, i00, i01, i11)
    k0, k1 = (k00, k10, k20, k30), (k01, k11, k21, k31)
    nr, nb = r - zr, wrap(b - zb)
    xn = (
        xt[0] + (k00 * nr + k01 * nb),
        xt[1] + (k10 * nr + k11 * nb),
        xt[2] + (k20 * nr + k21 * nb),
        xt[3] + (k30 * nr + k31 * nb),
    )
    # P⁺: the central point (e = −K d₀), K R Kᵀ, then the points ± column k: e = ±L[:, k] − K d
    zero = (0.0, 0.0, 0.0, 0.0)
    pn = _add_outer((0.0,) * 10, wc0, _point_error(0.0, zero, k0, k1, gr, gb))
    pn = _add_outer(pn, var_r, k0)
    pn = _add_outer(pn, var_b, k1)
    pn = _add_outer(pn, w, _point_error(1.0, L0, k0, k1, dar, dab))
    pn = _add_outer(pn, w, _point_error(-1.0, L0, k0, k1, dbr, dbb))
    pn = _add_outer(pn, w, _point_error(1.0, L1, k0, k1, dcr, dcb))
    pn = _add_outer(pn, w, _point_error(-1.0, L1, k0, k1, ddr, ddb))
    pn = _add_outer(pn, w, _point_error(1.0, L2, k0, k1, der, deb))
    pn = _add_outer(pn, w, _point_error(-1.0, L2, k0, k1, dfr, dfb))
    pn = _add_outer(pn, w, _point_error(1.0, L3, k0, k1, gr, gb))
    pn = _add_outer(pn, w, _point_error(-1.0, L3, k0, k1, gr, gb))
    return xn, pn
