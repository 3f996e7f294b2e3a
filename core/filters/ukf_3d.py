"""The 3D polar UKF update written once, as plain arithmetic over numbers or arrays alike.

``core.filters.polar_ukf`` states the filter and its Joseph form; ``core.filters.ukf_2d``
the 2D case. In 3D, 2n + 1 = 13 sigma points χ₀ = x⁻, χ_k± = x⁻ ± L_k (L the semi-definite
Cholesky factor of (n + λ) P⁻) go through the polar map ζ = (r, β, ε) of their offset from
the radar; bearings are averaged about the central point's, ẑ_β = wrap(β₀ + W Σ wrap(ζ_β − β₀));
S = Σ Wc d dᵀ + R, Pxz = W Σ_k L_k (d_k+ − d_k−)ᵀ, K = Pxz S⁻¹, x⁺ = x⁻ + K (z ⊖ ẑ) and
P⁺ = Σ Wc_p e_p e_pᵀ + K R Kᵀ with e_p = (χ_p − x⁻) − K d_p.

The functions index their arguments as ``x[i]``, ``P[i, j]`` and update them in place: one
track's (6,), (6, 6) arrays in numba-compiled code (``core.filters.kernels_3d`` compiles
them) or a batch's component-major views in the numpy engine
(``core.filters.state.step_3d``); scratch comes from the caller. The elementary functions
(``sqrt``, ``atan2``, ``wrap``) are numpy's here; the kernels re-bind them
(``core.filters.rebind``). An accumulator is updated in place (``+=``) only when it is a
fresh value, never a view of an argument, so numpy and compiled code compute the same.
"""

from __future__ import annotations

import numpy as np

from radarviz.core.filters.position_3d import inverse_3, semidefinite_cholesky_3d
from radarviz.core.geometry import wrap_angle

#: The elementary functions, numpy's here; the kernels re-bind them.
sqrt = np.sqrt
atan2 = np.arctan2
wrap = wrap_angle


def polar_3(qx, qy, qz, Z, p):
    """(r, β, ε) of the offset (qx, qy, qz) into Z[p] (``core.geometry.polar_coordinates``;
    ρ by sqrt, not hypot: its guard against overflow is not needed at radar ranges)."""
    rho = sqrt(qx * qx + qy * qy)
    Z[p, 0] = sqrt(rho * rho + qz * qz)
    Z[p, 1] = atan2(qy, qx)
    Z[p, 2] = atan2(qz, rho)


def ukf_update_3d(x, P, r, b, el, var_r, var_b, var_e, sx, sy, sz, prm, L, Z, K, S, Si, E):
    """The UKF update of x (6,), P (6, 6) in place by the plot (r, b, el) of the radar at
    (sx, sy, sz) (module docstring); var_r, var_b, var_e = σr², σβ², σε²; ``prm`` =
    ``UKFParams.weights(6)`` = (n + λ, Wm₀, Wc₀, W). L (6, 6), Z (13, 3), K (6, ≥ 3),
    S, Si (3, 3), E (6,): scratch."""
    c, wm0, wc0, w = prm[0], prm[1], prm[2], prm[3]
    semidefinite_cholesky_3d(P, c, L)
    px, py, pz = x[0] - sx, x[2] - sy, x[4] - sz
    polar_3(px, py, pz, Z, 0)
    for k in range(5):  # Z[1 + 2k] = +column k, Z[2 + 2k] = −column k
        for sgn in range(2):
            f = 1.0 if sgn == 0 else -1.0
            polar_3(px + f * L[0, k], py + f * L[2, k], pz + f * L[4, k], Z, 1 + 2 * k + sgn)
    for a in range(3):  # column 5 moves ż alone, which h ignores: both its points are ζ₀
        Z[11, a] = Z[0, a]
        Z[12, a] = Z[0, a]
    r0, b0, e0 = Z[0, 0], Z[0, 1], Z[0, 2]
    zr, ze = wm0 * r0, wm0 * e0
    acc = 0.0
    for p in range(1, 13):
        zr += w * Z[p, 0]
        ze += w * Z[p, 2]
        acc += wrap(Z[p, 1] - b0)
    zb = wrap(b0 + w * acc)
    for a in range(3):
        for bb in range(3):
            S[a, bb] = 0.0
    S[0, 0], S[1, 1], S[2, 2] = var_r, var_b, var_e
    for p in range(13):
        wp = wc0 if p == 0 else w
        Z[p, 0] -= zr
        Z[p, 1] = wrap(Z[p, 1] - zb)
        Z[p, 2] -= ze
        for a in range(3):
            for bb in range(a, 3):
                S[a, bb] += wp * Z[p, a] * Z[p, bb]
    S[1, 0], S[2, 0], S[2, 1] = S[0, 1], S[0, 2], S[1, 2]
    inverse_3(S, Si)
    nu0, nu1, nu2 = r - zr, wrap(b - zb), el - ze
    for i in range(6):  # Pxz = W Σ_k L[:, k] (d_k+ − d_k−)ᵀ, then K = Pxz S⁻¹
        a0, a1, a2 = 0.0, 0.0, 0.0
        for k in range(6):
            a0 += L[i, k] * (Z[1 + 2 * k, 0] - Z[2 + 2 * k, 0])
            a1 += L[i, k] * (Z[1 + 2 * k, 1] - Z[2 + 2 * k, 1])
            a2 += L[i, k] * (Z[1 + 2 * k, 2] - Z[2 + 2 * k, 2])
        a0, a1, a2 = a0 * w, a1 * w, a2 * w
        for e in range(3):
            K[i, e] = a0 * Si[0, e] + a1 * Si[1, e] + a2 * Si[2, e]
    for i in range(6):
        x[i] += K[i, 0] * nu0 + K[i, 1] * nu1 + K[i, 2] * nu2
    for i in range(6):  # the central point (e = −K d₀) and K R Kᵀ
        E[i] = K[i, 0] * Z[0, 0] + K[i, 1] * Z[0, 1] + K[i, 2] * Z[0, 2]
    for i in range(6):
        for j in range(i, 6):
            P[i, j] = (
                wc0 * E[i] * E[j]
                + var_r * K[i, 0] * K[j, 0]
                + var_b * K[i, 1] * K[j, 1]
                + var_e * K[i, 2] * K[j, 2]
            )
    for k in range(6):  # the points ± column k: e = ±L[:, k] − K d
        for sgn in range(2):
            p, f = 1 + 2 * k + sgn, 1.0 if sgn == 0 else -1.0
            for i in range(6):
                E[i] = f * L[i, k] - (K[i, 0] * Z[p, 0] + K[i, 1] * Z[p, 1] + K[i, 2] * Z[p, 2])
            for i in range(6):
                we = w * E[i]
                for j in range(i, 6):
                    P[i, j] += we * E[j]
    for i in range(6):
        for j in range(i):
            P[i, j] = P[j, i]
