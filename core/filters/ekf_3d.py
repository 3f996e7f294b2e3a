"""The 3D polar EKF measurement written once, as plain arithmetic over numbers or arrays alike.

As in 2D (``core.filters.ekf_2d``), the EKF's update by a plot (r̂, β̂, ε̂) is exactly the
position update (``core.filters.position_3d``) by the pseudo-innovation ν' = J ν with
covariance R' = J R Jᵀ, J = ∂p/∂(r, β, ε) at the predicted offset d = (dx, dy, dz) from the
radar (derivation: ``core.filters.polar_ekf``). With ρ = √(dx² + dy²), r = |d|::

    u = d / r,   r ∂u/∂β = (−dy, dx, 0),   r ∂u/∂ε = (−dz dx/ρ, −dz dy/ρ, ρ)
    ν = (r̂ − r, wrap(β̂ − atan2(dy, dx)), ε̂ − atan2(dz, ρ))

The elementary functions (``sqrt``, ``atan2``, ``wrap``) are numpy's here; numba-compiled
code (``core.filters.kernels_3d``) re-binds them (``core.filters.rebind``).
"""

from __future__ import annotations

import numpy as np

from radarviz.core.geometry import wrap_angle

#: The elementary functions, numpy's here; the kernels re-bind them.
sqrt = np.sqrt
atan2 = np.arctan2
wrap = wrap_angle


def ekf_measurement_3d(dx, dy, dz, r, b, el, var_r, var_b, var_e, nu, R):
    """The EKF's measurement in metres into ν' (3,) and the symmetric R' (3, 3) (module
    docstring): (dx, dy, dz) the predicted offset (m), (r, b, el) the plot (m, rad),
    var_r, var_b, var_e = σr², σβ², σε²."""
    rho = sqrt(dx * dx + dy * dy)
    rp = sqrt(rho * rho + dz * dz)
    u = (dx / rp, dy / rp, dz / rp)
    jb = (-dy, dx, 0.0)
    je = (-dz * dx / rho, -dz * dy / rho, rho)
    nr, nb, ne = r - rp, wrap(b - atan2(dy, dx)), el - atan2(dz, rho)
    for i in range(3):
        nu[i] = u[i] * nr + jb[i] * nb + je[i] * ne
        for j in range(i, 3):
            R[i, j] = u[i] * u[j] * var_r + jb[i] * jb[j] * var_b + je[i] * je[j] * var_e
            R[j, i] = R[i, j]
