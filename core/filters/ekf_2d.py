"""The 2D polar EKF update written once, as plain arithmetic over numbers or arrays alike.

The EKF linearises the polar map h(p) = (r, β) at the prediction; because only the position
enters h, its update is exactly a position update (``core.filters.position_2d``) with the
pseudo-innovation ν' = J ν and covariance R' = J R Jᵀ, J = ∂p/∂(r, β) the polar-to-Cartesian
Jacobian at the predicted offset d = (dx, dy) from the radar (Prosov eq. 9; the derivation
and why it is evaluated in metres: ``core.filters.polar_ekf``)::

    r⁻ = |d|,  u = d / r⁻ = (c, s),  r⁻ ∂u/∂β = (−dy, dx)
    ν = (r̂ − r⁻, wrap(β̂ − atan2(dy, dx)))
    ν' = (c ν_r − dy ν_β, s ν_r + dx ν_β)
    R' = [[c² σr² + dy² σβ², c s σr² − dx dy σβ²], [·, s² σr² + dx² σβ²]]

The elementary functions (``sqrt``, ``atan2``, ``wrap``) are numpy's here; numba-compiled
code (``core.filters.kernels_2d``) and the array-API path (``core.filters.array_api``)
re-bind them (``core.filters.rebind``), so every engine runs these lines.
"""

from __future__ import annotations

import numpy as np

from radarviz.core.filters.position_2d import position_update_2d
from radarviz.core.geometry import wrap_angle

#: The elementary functions, numpy's here; the kernels and the array-API path rebind them.
sqrt = np.sqrt
atan2 = np.arctan2
wrap = wrap_angle


def ekf_measurement_2d(dx, dy, r, b, var_r, var_b):
    """The EKF's measurement in metres: (ν'x, ν'y, R'00, R'01, R'11) (module docstring).

    Args:
        dx, dy: the predicted offset from the radar (m).
        r, b: the measured range (m) and bearing (rad).
        var_r, var_b: σr² (m²) and σβ² (rad²).
    """
    rp = sqrt(dx * dx + dy * dy)
    c, s = dx / rp, dy / rp
    nr, nb = r - rp, wrap(b - atan2(dy, dx))
    return (
        c * nr - dy * nb,
        s * nr + dx * nb,
        c * c * var_r + dy * dy * var_b,
        c * s * var_r - dx * dy * var_b,
        s * s * var_r + dx * dx * var_b,
    )


def ekf_update_2d(xt, p, r, b, var_r, var_b, sx, sy):
    """The EKF update of the state (xt, p) (``core.filters.position_2d``'s tuples) by the
    plot (r, b) of the radar at (sx, sy): ``ekf_measurement_2d`` at the prediction, then the
    position update."""
    nx, ny, r00, r01, r11 = ekf_measurement_2d(xt[0] - sx, xt[2] - sy, r, b, var_r, var_b)
    return position_update_2d(xt, p, nx, ny, r00, r01, r11)
