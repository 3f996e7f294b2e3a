"""The parameter table, and the checks shared by ``core`` and the command line.

One quantity has one name from the command line to the kernel, and the name carries the unit:
``sigma_beta_deg`` is σβ in degrees wherever it appears (a flag ``--sigma-beta-deg``, a field of
``TrackingConfig``, a slider of the tuning panel). :data:`PARAMETERS` holds, for each such
name, its unit, kind, allowed interval, default and a one-line meaning; the experiment configs
take their defaults from it and validate through :func:`check`, the CLI builds its flags from it
(``viz_app.cli.params.add_parameter``) and the panel its controls.

Every check raises :class:`ParameterError` with one line that names the parameter, the allowed
range and the offending value, e.g. ``sigma_beta_deg must be a finite number in (0, 20] (got -1)``,
and records the name in ``ParameterError.parameter``. ``core`` never names a command-line flag:
the CLI maps ``parameter`` to the flag it registered for it, prints
``--sigma-beta-deg must be a finite number in (0, 20] (got -1)`` and exits with status 2; the
panel shows the line and keeps the last result.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Literal

import numpy as np


class ParameterError(ValueError):
    """A parameter is outside its allowed range. The message is one line, fit for a user.

    Attributes:
        parameter: the name the message starts with (a :data:`PARAMETERS` key when the value
            was checked against the table), or None for an error about no single parameter.
    """

    def __init__(self, message: str, parameter: str | None = None) -> None:
        super().__init__(message)
        self.parameter = parameter

    def renamed(self, label: str) -> str:
        """The message with the leading parameter name replaced by ``label`` (e.g. a flag)."""
        text = str(self)
        if self.parameter and text.startswith(self.parameter):
            return label + text[len(self.parameter) :]
        return text


def _fmt(value: object) -> str:
    return repr(value) if isinstance(value, str) else str(value)


def interval_text(
    low: float | None, high: float | None, *, low_open: bool = True, high_open: bool = False
) -> str:
    """The interval as the messages print it: ``in (0, 20]``, ``> 0``, ``>= 0``."""
    if low is not None and high is None:
        return f"> {low:g}" if low_open else f">= {low:g}"
    lo_s = "-inf" if low is None else f"{low:g}"
    hi_s = "inf" if high is None else f"{high:g}"
    return f"in {'(' if low_open else '['}{lo_s}, {hi_s}{')' if high_open else ']'}"


def check_real(
    name: str,
    value: object,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = True,
    high_open: bool = False,
    parameter: str | None = None,
) -> float:
    """Return ``value`` as float if it is a finite real in the interval, else raise.

    The default interval is ``(low, high]``: most of our parameters are strictly positive
    (σ, T) with an inclusive upper limit. ``parameter`` (default ``name``) is what the error
    records in ``ParameterError.parameter``.
    """
    rng = interval_text(low, high, low_open=low_open, high_open=high_open)
    err = ParameterError(
        f"{name} must be a finite number {rng} (got {_fmt(value)})", parameter or name
    )
    if isinstance(value, bool) or not isinstance(value, Real):
        raise err
    v = float(value)
    if not math.isfinite(v):
        raise err
    if low is not None and (v <= low if low_open else v < low):
        raise err
    if high is not None and (v >= high if high_open else v > high):
        raise err
    return v


def check_reals(
    name: str,
    values: object,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = True,
    high_open: bool = False,
) -> np.ndarray:
    """``values`` (a number or an array of numbers) as a float64 array if every one is a
    finite real in the interval (``check_real``'s), else raise ``ParameterError`` naming
    ``name``, the interval and the first value outside it (with its index for an array)."""
    rng = interval_text(low, high, low_open=low_open, high_open=high_open)
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(
            f"{name} must be finite numbers {rng} (got {_fmt(values)})", name
        ) from None
    bad = ~np.isfinite(a)
    if low is not None:
        bad |= (a <= low) if low_open else (a < low)
    if high is not None:
        bad |= (a >= high) if high_open else (a > high)
    if bad.any():
        where = np.unravel_index(int(np.argmax(bad)), a.shape) if a.ndim else ()
        at = f" at index {where[0] if len(where) == 1 else where}" if a.ndim else ""
        raise ParameterError(f"{name} must be finite numbers {rng} (got {a[where]:g}{at})", name)
    return a


def check_int(
    name: str,
    value: object,
    *,
    low: int,
    high: int | None = None,
    parameter: str | None = None,
) -> int:
    """Return ``value`` as int if it is an integer in ``[low, high]``, else raise."""
    rng = f">= {low}" if high is None else f"in [{low}, {high}]"
    err = ParameterError(f"{name} must be an integer {rng} (got {_fmt(value)})", parameter or name)
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise err
    v = int(value)
    if v < low or (high is not None and v > high):
        raise err
    return v


def check_distinct(name: str, values: tuple[str, ...]) -> None:
    """Refuse a list that names an item twice (``--methods ucm ucm``): results are keyed by
    the item, so a repeat would sum or overwrite the first one's."""
    repeated = sorted({v for v in values if values.count(v) > 1})
    if repeated:
        raise ParameterError(
            f"{name} must name each one once (got {', '.join(repeated)} more than once)", name
        )


def check_choice(
    name: str, value: object, choices: Iterable[str], *, parameter: str | None = None
) -> str:
    """Return ``value`` if it is one of ``choices``, else raise naming them all."""
    options = tuple(choices)
    if not isinstance(value, str) or value not in options:
        raise ParameterError(
            f"{name} must be one of {', '.join(options)} (got {_fmt(value)})", parameter or name
        )
    return value


_TABLE_DEFAULT: object = object()


@dataclass(frozen=True)
class Parameter:
    """One entry of the parameter table.

    Attributes:
        name: the one name of the quantity, with its unit suffix (``sigma_beta_deg``).
        symbol: how the papers write it (``σβ``).
        meaning: a few words (``azimuth noise std``).
        unit: ``deg``, ``m``, ``s`` … ('' for a count or a ratio).
        kind: ``real`` (a finite float) or ``int``.
        low, high: the allowed interval's ends (None: unbounded on that side).
        low_open, high_open: whether an end is excluded.
        default: the value used where none is given (None: the quantity has no default).
    """

    name: str
    symbol: str
    meaning: str
    unit: str
    kind: Literal["real", "int"]
    low: float | None
    high: float | None
    low_open: bool = True
    high_open: bool = False
    default: float | int | None = None

    def interval(self, high: float | None = None) -> str:
        """``in (0, 20]``, ``>= 2``, … (``high`` tightens the upper end for one use)."""
        hi = self.high if high is None else high
        if self.kind == "int":
            lo = int(self.low if self.low is not None else 0)
            return f">= {lo}" if hi is None else f"in [{lo}, {int(hi)}]"
        return interval_text(self.low, hi, low_open=self.low_open, high_open=self.high_open)

    def help(self, default: object = _TABLE_DEFAULT, *, high: float | None = None) -> str:
        """One line for a flag's help or a control's hint: symbol, meaning, unit, range, default.

        E.g. ``σβ, azimuth noise std (deg), in (0, 20], default 1``. ``default`` replaces the
        table's default in the line (a list prints as its values; None leaves it out); ``high``
        the upper end, for a use with its own (see :func:`check`).
        """
        unit = f" ({self.unit})" if self.unit else ""
        d = self.default if default is _TABLE_DEFAULT else default
        tail = "" if d is None else f", default {_fmt_default(d)}"
        return f"{self.symbol}, {self.meaning}{unit}, {self.interval(high)}{tail}"

    def check_all(self, values: object) -> np.ndarray:
        """Validate a number or an array of numbers against this entry's interval
        (``check_reals``): a float64 array."""
        return check_reals(
            self.name,
            values,
            low=self.low,
            high=self.high,
            low_open=self.low_open,
            high_open=self.high_open,
        )

    def check(self, value: object, *, high: float | None = None) -> float | int:
        """Validate ``value`` against this entry (``high`` tightens the upper end)."""
        hi = self.high if high is None else high
        if self.kind == "int":
            low = int(self.low if self.low is not None else 0)
            return check_int(self.name, value, low=low, high=None if hi is None else int(hi))
        return check_real(
            self.name,
            value,
            low=self.low,
            high=hi,
            low_open=self.low_open,
            high_open=self.high_open,
        )


def _fmt_default(value: object) -> str:
    if isinstance(value, list | tuple):
        return " ".join(_fmt_default(v) for v in value)
    if isinstance(value, float):
        return f"{value:g}"
    return _fmt(value)


def _real(
    name: str,
    symbol: str,
    meaning: str,
    unit: str,
    low: float | None,
    high: float | None,
    default: float | None,
    *,
    low_open: bool = True,
) -> Parameter:
    return Parameter(name, symbol, meaning, unit, "real", low, high, low_open, False, default)


def _int(
    name: str, symbol: str, meaning: str, low: int, high: int | None, default: int
) -> Parameter:
    return Parameter(name, symbol, meaning, "", "int", low, high, False, False, default)


#: Upper limit of an angle σ accepted anywhere: beyond it a Cartesian Gaussian is meaningless.
MAX_SIGMA_ANGLE_DEG = 20.0
#: Lower limit of an angle σ (3.6 milli-arcseconds, far finer than any radar): below it r σ²
#: underflows against r and the conversions' second-order terms lose every digit (negative
#: NEES, NaN).
MIN_SIGMA_ANGLE_DEG = 1e-6
#: Lower limit of the azimuth σβ, and :data:`MIN_SIGMA_R_M` of the range σr: the Prosov run's
#: converted position covariance has variances σr² along the line of sight and (r σβ)² across
#: it, and with σr = 10⁵ m against r σβ = 0.03 m (σβ = 10⁻⁵° at 150 km), or σr = 1 m against
#: 52 km (σβ = 20°), the 4 × 4 state covariance is singular to rounding after two plots: some
#: of 1000 runs got a NaN NEES (naive, ekf, ukf) or a negative one (ekf). Probed over the
#: corners of [σr, 10⁵ m] × [σβ, 20°] with every method at 1000 runs, 5·10⁻⁵° and 2 m are the
#: smallest limits (of 10⁻⁵, 5·10⁻⁵, 10⁻⁴; 1, 2, 3 m) at which every figure is finite.
MIN_SIGMA_BETA_DEG = 5e-5
MIN_SIGMA_R_M = 2.0

#: Fewest Monte Carlo runs (trials): every figure comes with its delete-a-group jackknife band
#: (``core.confidence``), whose leave-outs each drop a group of runs; a sample σ needs two runs
#: in every leave-out, so with two runs (one per group) every σ band was NaN. Three is the
#: fewest for which every band of every experiment exists.
MIN_MONTE_CARLO_RUNS = 3
#: Most Monte Carlo runs (trials) of one experiment: 10⁸ runs of the Prosov run are 6 · 10⁹
#: filter steps per method, hours of work; beyond it the list of blocks alone outgrew the
#: memory (10¹⁵ runs: MemoryError) or an index (10³⁰: OverflowError) before the first run.
MAX_MONTE_CARLO_RUNS = 100_000_000

#: Largest GOSPA order p: GOSPA's parts are p-th powers of distances up to the cut-off c, and
#: their Monte Carlo bands need the squares, so c^(2p) must stay a float at the largest
#: cut-off (10⁸ m): 10^(8 · 2 · 16) = 10²⁵⁶. At p = 100 even the default c = 2 km gave
#: c^p = 10³³⁰, an OverflowError.
MAX_GOSPA_ORDER = 16.0

#: The parameter table. Defaults are the Prosov experiment (one radar at the origin, target at
#: 150 km moving radially outward at 200 m/s, σr = 250 m, σβ = 1°, T = 10 s, 60 scans, Q = 0).
PARAMETERS: dict[str, Parameter] = {
    p.name: p
    for p in (
        _real("sigma_r_m", "σr", "range noise std", "m", MIN_SIGMA_R_M, 1e5, 250.0, low_open=False),
        _real(
            "sigma_beta_deg",
            "σβ",
            "azimuth noise std",
            "deg",
            MIN_SIGMA_BETA_DEG,
            MAX_SIGMA_ANGLE_DEG,
            1.0,
            low_open=False,
        ),
        _real(
            "sigma_elevation_deg",
            "σε",
            "elevation noise std",
            "deg",
            MIN_SIGMA_ANGLE_DEG,
            MAX_SIGMA_ANGLE_DEG,
            None,
            low_open=False,
        ),
        _real(
            "sigma_vr_mps",
            "σVr",
            "radial-velocity noise std",
            "m/s",
            1e-4,
            1e4,
            None,
            low_open=False,
        ),
        _real("period_s", "T", "scan period", "s", 1e-3, 3600.0, 10.0, low_open=False),
        _int("steps", "N", "scans per run", 2, 100_000, 60),
        _int("runs", "M", "Monte Carlo runs", MIN_MONTE_CARLO_RUNS, MAX_MONTE_CARLO_RUNS, 1000),
        _int(
            "trials", "M", "Monte Carlo trials", MIN_MONTE_CARLO_RUNS, MAX_MONTE_CARLO_RUNS, 100_000
        ),
        _int("seed", "seed", "root of numpy.random.SeedSequence", 0, None, 1),
        _real(
            "c0",
            "C0",
            "σr² / (T² σVr²), range vs Doppler accuracy",
            "",
            1e-8,
            1e8,
            1.0,
            low_open=False,
        ),
        _real(
            "sigma_a_mps2",
            "σa",
            "process-noise acceleration std",
            "m/s²",
            0.0,
            1e3,
            0.0,
            low_open=False,
        ),
        _real(
            "imm_sigma_a_mps2",
            "σa,j",
            "process-noise acceleration std of each IMM model",
            "m/s²",
            0.0,
            1e3,
            None,
            low_open=False,
        ),
        _real(
            "imm_turn_rate_degps",
            "ωj",
            "turn rate of each IMM model (0: constant velocity, else a coordinated turn)",
            "deg/s",
            -20.0,
            20.0,
            None,
            low_open=False,
        ),
        Parameter(
            "transition_prob",
            "πij",
            "IMM model transition probability per update",
            "",
            "real",
            0.0,
            1.0,
            True,
            True,
            None,
        ),
        _int("nis_window", "w", "updates in the NIS consistency window", 1, 10_000, 10),
        _real(
            "sigma_v0_mps",
            "σv0",
            "initial velocity std of a track",
            "m/s",
            1e-3,
            1e5,
            1000.0,
            low_open=False,
        ),
        _real("target_range_m", "r0", "initial target range", "m", 0.0, 1e8, 150e3),
        _real(
            "target_elevation_deg",
            "E",
            "target elevation seen from the radar",
            "deg",
            -80.0,
            80.0,
            0.0,
            low_open=False,
        ),
        _real("site_m", "x", "radar site coordinate", "m", -1e8, 1e8, None, low_open=False),
        _real("range_m", "r", "measured range", "m", 0.0, 1e8, None),
        _real(
            "radial_velocity_mps",
            "Vr",
            "measured radial velocity",
            "m/s",
            -1e5,
            1e5,
            None,
            low_open=False,
        ),
        _real("time_s", "t", "plot time", "s", -1e10, 1e10, None, low_open=False),
        _real(
            "target_speed_mps",
            "v",
            "target speed, radially outward",
            "m/s",
            0.0,
            1e5,
            200.0,
            low_open=False,
        ),
        # Association of unlabelled plots (``core.tracking.association``).
        Parameter(
            "gate_probability",
            "PG",
            "probability that a track's own plot falls inside its chi-square gate",
            "",
            "real",
            0.0,
            1.0,
            True,
            True,
            0.999,
        ),
        _int(
            "confirm_m",
            "M",
            "hits that confirm a tentative track (M of its first N expected detections)",
            1,
            100,
            3,
        ),
        _int(
            "confirm_n",
            "N",
            "expected detections in which a tentative track must get M hits",
            1,
            100,
            4,
        ),
        _int(
            "delete_misses",
            "Kdel",
            "consecutive missed expected detections that delete a confirmed track",
            1,
            1000,
            5,
        ),
        _real(
            "scan_window_s",
            "Δts",
            "consecutive plots of one radar within this time of the first form one batch "
            "(without it: batches by radar and azimuth sector)",
            "s",
            0.0,
            3600.0,
            None,
            low_open=False,
        ),
        _real(
            "batch_sector_deg",
            "Δβ",
            "azimuth sector of one radar whose consecutive plots are associated as one batch",
            "deg",
            0.0,
            360.0,
            22.5,
        ),
        _real(
            "max_speed_mps",
            "vmax",
            "fastest target: a track of one plot takes no plot it could only reach faster",
            "m/s",
            0.0,
            1e5,
            600.0,
        ),
        # A radar's coverage and rotation (radars file; estimated from its plots if absent).
        _real("rotation_period_s", "Trot", "antenna revolution period", "s", 0.0, 3600.0, None),
        _real(
            "min_range_m",
            "rmin",
            "smallest range the radar covers",
            "m",
            0.0,
            1e8,
            None,
            low_open=False,
        ),
        _real("max_range_m", "rmax", "largest range the radar covers", "m", 0.0, 1e8, None),
        _real(
            "min_elevation_deg",
            "εmin",
            "lowest elevation the radar covers",
            "deg",
            -90.0,
            90.0,
            None,
            low_open=False,
        ),
        _real(
            "max_elevation_deg",
            "εmax",
            "highest elevation the radar covers",
            "deg",
            -90.0,
            90.0,
            None,
            low_open=False,
        ),
        # The crossing scene (``core.scenarios.crossing``).
        _int("crossing_targets", "n", "targets crossing at one point", 2, 1000, 2),
        _real(
            "crossing_angle_deg", "θ", "angle between neighbouring paths", "deg", 0.0, 180.0, 20.0
        ),
        Parameter(
            "detection_prob",
            "PD",
            "detection probability per target and scan",
            "",
            "real",
            0.0,
            1.0,
            True,
            False,
            0.9,
        ),
        _real(
            "clutter_per_scan",
            "λ",
            "mean false plots per scan (Poisson, uniform over the region)",
            "",
            0.0,
            1e4,
            5.0,
            low_open=False,
        ),
        # GOSPA (``core.tracking.gospa``).
        _real("gospa_cutoff_m", "c", "GOSPA cut-off distance", "m", 0.0, 1e8, 2000.0),
        _real("gospa_order", "p", "GOSPA order", "", 1.0, MAX_GOSPA_ORDER, 2.0, low_open=False),
        # Scoring a track file against the truth (``core.tracking.scoring``).
        _real(
            "score_max_gap_s",
            "Δt_max",
            "longest time a track's last row is predicted over to a truth time",
            "s",
            0.0,
            1e6,
            10.0,
            low_open=False,
        ),
    )
}


def parameter(name: str) -> Parameter:
    """The table entry ``name`` (KeyError names the known ones)."""
    try:
        return PARAMETERS[name]
    except KeyError:
        raise KeyError(f"no parameter {name!r} (known: {', '.join(PARAMETERS)})") from None


def default(name: str) -> float | int:
    """The table default of ``name`` (for dataclass field defaults)."""
    d = parameter(name).default
    if d is None:
        raise KeyError(f"parameter {name!r} has no default")
    return d


def check(name: str, value: object, *, high: float | None = None) -> float | int:
    """Validate ``value`` against the table entry ``name``; raise ``ParameterError`` naming it.

    ``high`` tightens the upper end where one use needs less than the table allows (the tuning
    panel's run count); the error still names ``name``.
    """
    return parameter(name).check(value, high=high)
