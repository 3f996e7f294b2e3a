"""The 3D steps written once, gathered for the engines that compile them.

Each 3D update is plain arithmetic over one track's arrays or a batch's component-major
views alike, in a module of its own: the position update (``core.filters.position_3d``), the
polar EKF's measurement (``core.filters.ekf_3d``), the polar UKF (``core.filters.ukf_3d``) and
the Doppler update (``core.filters.doppler_3d``); the prediction is
``core.filters.predict``'s. The numpy engine calls them as they are
(``core.filters.state.step_3d``); ``bind_3d`` gives copies calling another set of elementary
functions, which numba-compiled code (``core.filters.kernels_3d``) binds to the scalar ones
and compiles.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from radarviz.core.filters import doppler_3d, ekf_3d, position_2d, position_3d, ukf_3d
from radarviz.core.filters.rebind import rebind_modules

#: The steps' functions, one group per module, each group after the modules it calls (the
#: semi-definite factor's pivot rule is the 2D module's).
STEP_FUNCTIONS_3D = (
    (position_2d._pivot, position_2d._below),
    (
        position_3d.semidefinite_cholesky_3d,
        position_3d.inverse_3,
        position_3d.factored_joseph_3d,
        position_3d.position_update_3d,
    ),
    (ekf_3d.ekf_measurement_3d,),
    (ukf_3d.polar_3, ukf_3d.ukf_update_3d),
    (doppler_3d.doppler_terms_3d, doppler_3d.doppler_update_3d),
)

#: The elementary functions the steps call by name.
ELEMENTARY = ("sqrt", "where", "atan2", "wrap")


def bind_3d(elementary: dict[str, Any], wrap: Callable[[Any], Any] = lambda f: f) -> dict[str, Any]:
    """``{name: wrap(copy)}`` of every function of ``STEP_FUNCTIONS_3D``, the copies calling
    ``elementary`` (every name of ``ELEMENTARY``) and one another's wrapped copies."""
    return rebind_modules(STEP_FUNCTIONS_3D, elementary, wrap, ELEMENTARY)
