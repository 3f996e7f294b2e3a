"""Parameter checks shared by ``core`` and the command line.

Every check raises :class:`ParameterError` with one line that names the parameter, the allowed
range and the offending value, e.g. ``sigma_beta_deg must be a finite number in (0, 20] (got -1)``.
The CLI prints that line and exits with status 2; the panel shows it and keeps the last result.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from numbers import Integral, Real


class ParameterError(ValueError):
    """A parameter is outside its allowed range. The message is one line, fit for a user."""


def _fmt(value: object) -> str:
    return repr(value) if isinstance(value, str) else str(value)


def check_real(
    name: str,
    value: object,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = True,
    high_open: bool = False,
) -> float:
    """Return ``value`` as float if it is a finite real in the interval, else raise.

    The default interval is ``(low, high]``: most of our parameters are strictly positive
    (σ, T) with an inclusive upper limit.
    """
    lo_b = "(" if low_open else "["
    hi_b = ")" if high_open else "]"
    lo_s = "-inf" if low is None else f"{low:g}"
    hi_s = "inf" if high is None else f"{high:g}"
    if low is not None and high is None:
        rng = f"> {lo_s}" if low_open else f">= {lo_s}"
    else:
        rng = f"in {lo_b}{lo_s}, {hi_s}{hi_b}"
    msg = f"{name} must be a finite number {rng} (got {_fmt(value)})"
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ParameterError(msg)
    v = float(value)
    if not math.isfinite(v):
        raise ParameterError(msg)
    if low is not None and (v <= low if low_open else v < low):
        raise ParameterError(msg)
    if high is not None and (v >= high if high_open else v > high):
        raise ParameterError(msg)
    return v


def check_int(name: str, value: object, *, low: int, high: int | None = None) -> int:
    """Return ``value`` as int if it is an integer in ``[low, high]``, else raise."""
    rng = f">= {low}" if high is None else f"in [{low}, {high}]"
    msg = f"{name} must be an integer {rng} (got {_fmt(value)})"
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise ParameterError(msg)
    v = int(value)
    if v < low or (high is not None and v > high):
        raise ParameterError(msg)
    return v


def check_choice(name: str, value: object, choices: Iterable[str]) -> str:
    """Return ``value`` if it is one of ``choices``, else raise naming them all."""
    options = tuple(choices)
    if not isinstance(value, str) or value not in options:
        raise ParameterError(f"{name} must be one of {', '.join(options)} (got {_fmt(value)})")
    return value
