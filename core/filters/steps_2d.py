"""The 2D steps written once, gathered for the engines that compile or re-bind them.

Each 2D update is plain arithmetic over numbers or arrays alike, in a module of its own:
the position update (``core.filters.position_2d``), the polar EKF (``core.filters.ekf_2d``),
the polar UKF (``core.filters.ukf_2d``) and the Doppler update (``core.filters.doppler_2d``);
the prediction is ``core.filters.predict``'s. The numpy engine calls them as they are, on a
batch's component arrays. ``bind_2d`` gives copies of them calling another set of elementary
functions: numba-compiled code (``core.filters.kernels_2d``) binds the scalar ones and
compiles each copy; the array-API path (``core.filters.array_api``) binds its namespace's.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from radarviz.core.filters import doppler_2d, ekf_2d, position_2d, ukf_2d
from radarviz.core.filters.rebind import rebind_modules

#: The steps' functions, one group per module, each group after the modules it calls.
STEP_FUNCTIONS_2D = (
    (
        position_2d._pivot,
        position_2d._below,
        position_2d.semidefinite_cholesky_2d,
        position_2d._add_outer,
        position_2d._z_col,
        position_2d._krk,
        position_2d.position_update_2d,
    ),
    (ekf_2d.ekf_measurement_2d, ekf_2d.ekf_update_2d),
    (ukf_2d._norm, ukf_2d._point_error, ukf_2d._gain_row, ukf_2d.ukf_update_2d),
    (doppler_2d.doppler_terms_2d, doppler_2d.doppler_update_2d),
)

#: The elementary functions the steps call by name: ``sqrt``, ``where``, ``atan2``, ``wrap``
#: (an angle to (−π, π]), ``cos``, ``sin``. (The innovation statistics beside the updates,
#: which call ``log``, are the numpy engine's only: the kernels keep their own for now.)
ELEMENTARY = ("sqrt", "where", "atan2", "wrap", "cos", "sin")


def bind_2d(elementary: dict[str, Any], wrap: Callable[[Any], Any] = lambda f: f) -> dict[str, Any]:
    """``{name: wrap(copy)}`` of every function of ``STEP_FUNCTIONS_2D``, the copies calling
    ``elementary`` (every name of ``ELEMENTARY``) and one another's wrapped copies."""
    return rebind_modules(STEP_FUNCTIONS_2D, elementary, wrap, ELEMENTARY)
