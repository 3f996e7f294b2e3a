"""The compiled kernels' method codes, derived from the method registry.

numba branches fastest on small integers, so each method reaches a kernel as a code: a
converted method as its conversion's code (``core.conversion.elementwise``: ``NAIVE`` …
``DUCM``), a polar filter as ``EKF`` or ``UKF``. The tables below are made from
``core.filters.methods.METHODS`` (each method's kind and start conversion), and the kernels
test a code only through the names here (``EKF``, ``UKF``, ``DUCM``, ``is_polar``), so a
method's code is declared once, by its entry in the registry.
"""

from __future__ import annotations

from radarviz.core.conversion.elementwise import CODES, DUCM
from radarviz.core.filters.methods import METHODS

#: The polar filters' codes, after the conversions'.
EKF, UKF = 5, 6
#: Each conversion's code, by its name (``Method.start_conversion``).
CONVERSION_CODES: dict[str, int] = CODES
#: A polar filter's code, by its kind (``Method.kind``).
POLAR_CODES: dict[str, int] = {"ekf": EKF, "ukf": UKF}

#: Each 2D method's kernel code: a converted method's conversion, or its polar filter.
METHOD_CODES: dict[str, int] = {
    name: CONVERSION_CODES[name] if method.kind == "converted" else POLAR_CODES[method.kind]
    for name, method in METHODS.items()
    if 2 in method.dims
}
#: Each method's start conversion (``Method.start_conversion``): ducm starts like ucm, the
#: polar filters from the naive point.
START_CODES: dict[str, int] = {
    name: CONVERSION_CODES[METHODS[name].start_conversion] for name in METHOD_CODES
}


def is_polar(code: int) -> bool:
    """Whether ``code`` is a polar filter's (it updates on (r, β[, ε]) itself, not on a
    converted point)."""
    return code >= EKF


def reads_prediction(code: int) -> bool:
    """Whether conversion ``code`` depends on the prediction (ducm's covariance is taken at
    the predicted position), so it cannot be shared between states of one track."""
    return code == DUCM
