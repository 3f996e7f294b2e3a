"""The 2D Doppler update written once, as plain arithmetic over numbers or arrays alike.

``core.filters.doppler`` states the measurement: the radial velocity V̂r along the *measured*
line of sight û = (cos β̂, sin β̂), linear in the state, with the bearing error's tilt of û
folded into its variance::

    V̂r = û·v + e,   var e = σVr² + σβ² ((g·v̂)² + gᵀ P_vv g),   g = ∂û/∂β = (−sin β̂, cos β̂)
    U = P hᵀ,  S = h U + var e,  k = U / S,  x⁺ = x⁻ + k (V̂r − û·v̂)
    P⁺ = Z Zᵀ + var e k kᵀ,   Z = L − k (h L),   L Lᵀ = P               (the Joseph form)

with h = û on the velocity components (ẋ, ẏ) and L the semi-definite Cholesky factor of P
(``core.filters.position_2d``; why on a factor: ``core.filters.joseph``).

The elementary functions (``cos``, ``sin``, and ``sqrt``, ``where`` in the factor) are
numpy's here; numba-compiled code (``core.filters.kernels_2d``) and the array-API path
(``core.filters.array_api``) re-bind them (``core.filters.rebind``), so every engine runs
these lines.
"""

from __future__ import annotations

import numpy as np

from radarviz.core.filters.position_2d import _add_outer, _z_col, semidefinite_cholesky_2d

#: The elementary functions, numpy's here; the kernels and the array-API path rebind them.
cos = np.cos
sin = np.sin
where = np.where
log = np.log
nan = np.nan


def doppler_terms_2d(xt, p, b, var_vr, var_b):
    """(û₀, û₁, var e) of a plot at bearing ``b`` on the state (xt, p) (module docstring)."""
    x1, x3 = xt[1], xt[3]
    p11, p13, p33 = p[4], p[6], p[9]
    u0, u1 = cos(b), sin(b)
    g0, g1 = -u1, u0
    gv = g0 * x1 + g1 * x3
    gpg = g0 * g0 * p11 + g1 * g1 * p33 + 2.0 * g1 * g0 * p13
    return u0, u1, var_vr + var_b * (gv * gv + gpg)


def doppler_stats_2d(xt, p, vr_hat, b, var_vr, var_b):
    """(ν² / S, log S) of the Doppler measurement on the state (xt, p) it would update
    (``core.filters.innovation``): ν = V̂r − û·v̂, S = û P_vv ûᵀ + var e (as
    ``doppler_update_2d`` forms it); both NaN unless S > 0."""
    u0, u1, r_e = doppler_terms_2d(xt, p, b, var_vr, var_b)
    _, _, _, _, p11, _, p13, _, _, p33 = p
    S = u0 * (p11 * u0 + p13 * u1) + u1 * (p13 * u0 + p33 * u1) + r_e
    nu = vr_hat - (u0 * xt[1] + u1 * xt[3])
    ok = S > 0.0
    s = where(ok, S, 1.0)
    return where(ok, nu * nu / s, nan), where(ok, log(s), nan)


def doppler_update_2d(xt, p, vr_hat, b, var_vr, var_b):
    """The Doppler update of the state (xt, p) (``core.filters.position_2d``'s tuples) by
    the measured radial velocity ``vr_hat`` (m/s) of a plot at bearing ``b`` (rad)
    (module docstring); var_vr = σVr² (m²/s²), var_b = σβ² (rad²)."""
    x0, x1, x2, x3 = xt
    _, p01, _, p03, p11, p12, p13, _, p23, p33 = p
    u0, u1, r_e = doppler_terms_2d(xt, p, b, var_vr, var_b)
    U0, U1 = p01 * u0 + p03 * u1, p11 * u0 + p13 * u1
    U2, U3 = p12 * u0 + p23 * u1, p13 * u0 + p33 * u1
    S = u0 * U1 + u1 * U3 + r_e
    nu = vr_hat - (u0 * x1 + u1 * x3)
    f = 1.0 / S
    k0, k1, k2, k3 = U0 * f, U1 * f, U2 * f, U3 * f
    xn = (x0 + k0 * nu, x1 + k1 * nu, x2 + k2 * nu, x3 + k3 * nu)
    L0, L1, L2, L3 = semidefinite_cholesky_2d(p, 1.0, True)
    kk, zero = (k0, k1, k2, k3), (0.0, 0.0, 0.0, 0.0)
    # Z = L − k (h L), h L's entries u0 L[1, c] + u1 L[3, c]; P⁺ = Z Zᵀ + var e k kᵀ
    pn = _add_outer((0.0,) * 10, r_e, kk)
    pn = _add_outer(pn, 1.0, _z_col(L0, kk, zero, u0 * L0[1] + u1 * L0[3], 0.0))
    pn = _add_outer(pn, 1.0, _z_col(L1, kk, zero, u0 * L1[1] + u1 * L1[3], 0.0))
    pn = _add_outer(pn, 1.0, _z_col(L2, kk, zero, u1 * L2[3], 0.0))
    pn = _add_outer(pn, 1.0, _z_col(L3, kk, zero, u1 * L3[3], 0.0))
    return xn, pn
