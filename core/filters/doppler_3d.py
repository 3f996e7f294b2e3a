"""The 3D Doppler update written once, as plain arithmetic over numbers or arrays alike.

``core.filters.doppler`` states the measurement: V̂r = û·v + e along the measured line of
sight û = u(β̂, ε̂) = (cos ε̂ cos β̂, cos ε̂ sin β̂, sin ε̂), the angle errors' tilt of û folded
into the variance::

    var e = σVr² + σβ² ((g_β·v̂)² + g_βᵀ P_vv g_β) + σε² ((g_ε·v̂)² + g_εᵀ P_vv g_ε)
    g_β = ∂u/∂β = cos ε̂ (−sin β̂, cos β̂, 0),   g_ε = ∂u/∂ε = (−sin ε̂ cos β̂, −sin ε̂ sin β̂, cos ε̂)
    U = P hᵀ,  S = h U + var e,  k = U / S,  x⁺ = x⁻ + k (V̂r − û·v̂)
    P⁺ = Z Zᵀ + var e k kᵀ,   Z = L − k (h L),   L Lᵀ = P               (the Joseph form)

with h = û on the velocity components (ẋ, ẏ, ż). The functions index their arguments as
``x[i]``, ``P[i, j]`` and update them in place: one track's (6,), (6, 6) arrays in
numba-compiled code (``core.filters.kernels_3d`` compiles them) or a batch's component-major
views in the numpy engine (``core.filters.state.step_3d``); scratch comes from the caller.
The angles come as ``trig`` = (cos β̂, sin β̂, cos ε̂, sin ε̂), formed once per plot.
"""

from __future__ import annotations

import numpy as np

from radarviz.core.filters.position_3d import semidefinite_cholesky_3d

#: The elementary functions, numpy's here; the kernels re-bind them.
where = np.where
log = np.log
nan = np.nan


def doppler_terms_3d(x, P, trig, var_vr, var_b, var_e, u):
    """û into u (3,); returns var e (module docstring)."""
    ca, sa, ce, se = trig[0], trig[1], trig[2], trig[3]
    u[0], u[1], u[2] = ce * ca, ce * sa, se
    gb0, gb1 = -ce * sa, ce * ca
    ge0, ge1, ge2 = -se * ca, -se * sa, ce
    v0, v1, v2 = x[1], x[3], x[5]
    gv = gb0 * v0 + gb1 * v1
    gpg = gb0 * gb0 * P[1, 1] + gb1 * gb1 * P[3, 3] + 2.0 * gb1 * gb0 * P[3, 1]
    r_e = var_vr + var_b * (gv * gv + gpg)
    gv = ge0 * v0 + ge1 * v1 + ge2 * v2
    gpg = ge0 * ge0 * P[1, 1] + ge1 * ge1 * P[3, 3] + ge2 * ge2 * P[5, 5]
    gpg += 2.0 * ge1 * ge0 * P[3, 1] + 2.0 * ge2 * ge0 * P[5, 1] + 2.0 * ge2 * ge1 * P[5, 3]
    return r_e + var_e * (gv * gv + gpg)


def doppler_update_3d(x, P, vr_hat, trig, var_vr, var_b, var_e, u, U, K, L):
    """The Doppler update of x (6,), P (6, 6) in place by the measured radial velocity
    ``vr_hat`` (m/s) (module docstring); u (3,), U, K (6,), L (6, 6): scratch."""
    r_e = doppler_terms_3d(x, P, trig, var_vr, var_b, var_e, u)
    for i in range(6):
        U[i] = P[i, 1] * u[0] + P[i, 3] * u[1] + P[i, 5] * u[2]
    S = u[0] * U[1] + u[1] * U[3] + u[2] * U[5] + r_e
    nu = vr_hat - (u[0] * x[1] + u[1] * x[3] + u[2] * x[5])
    inv_s = 1.0 / S
    for i in range(6):
        K[i] = U[i] * inv_s
        x[i] += K[i] * nu
    semidefinite_cholesky_3d(P, 1.0, L, True)
    for k in range(6):  # h L into U
        U[k] = u[0] * L[1, k] + u[1] * L[3, k] + u[2] * L[5, k]
    for i in range(6):  # Z = L − k (h L), in place
        for k in range(6):
            L[i, k] -= K[i] * U[k]
    for i in range(6):
        for j in range(i, 6):
            acc = r_e * K[i] * K[j]
            for k in range(6):
                acc += L[i, k] * L[j, k]
            P[i, j] = acc
            P[j, i] = acc


def doppler_stats_3d(x, P, vr_hat, trig, var_vr, var_b, var_e, u):
    """(ν² / S, log S) of the Doppler measurement on the state x (6,), P (6, 6) it would
    update (``core.filters.innovation``): ν = V̂r − û·v̂, S = û P_vv ûᵀ + var e (as
    ``doppler_update_3d`` forms it); both NaN unless S > 0; u (3,): scratch."""
    r_e = doppler_terms_3d(x, P, trig, var_vr, var_b, var_e, u)
    U1 = P[1, 1] * u[0] + P[1, 3] * u[1] + P[1, 5] * u[2]
    U3 = P[3, 1] * u[0] + P[3, 3] * u[1] + P[3, 5] * u[2]
    U5 = P[5, 1] * u[0] + P[5, 3] * u[1] + P[5, 5] * u[2]
    S = u[0] * U1 + u[1] * U3 + u[2] * U5 + r_e
    nu = vr_hat - (u[0] * x[1] + u[1] * x[3] + u[2] * x[5])
    ok = S > 0.0
    s = where(ok, S, 1.0)
    return where(ok, nu * nu / s, nan), where(ok, log(s), nan)
