"""Where and when a radar looks: its coverage, its antenna's rotation, and which tracks its
beam has just swept (the expected detections of ``core.tracking.association``).

A rotating radar stamps each plot when its beam passes the target, so its plots come as a
sweep in azimuth, one revolution every T seconds; a miss is only a miss when the beam swept
the track's position inside the radar's coverage. This module keeps, per radar, what the
association needs to tell that:

* **Coverage** (``RadarCoverage``): minimum and maximum range, elevation limits (3D), and
  the rotation period T. Each may be given (the radars file); what is not given is estimated
  from the radar's own plots (``RadarBeam``): the range and elevation limits as the extremes
  seen so far (an early track outside them is then not expected, which errs towards keeping
  it), the period from the revisit times of azimuth cells (below).
* **Stamping.** A radar whose plots of one scan share one time stamp (a simulation, or a
  plot extractor that stamps the scan) sweeps everything at once: ``RadarBeam.scan_stamped``,
  true when most consecutive plot pairs of the radar share their time. Every other radar is
  taken as rotating, its plots stamped by the beam.
* **Period estimate.** A plot at azimuth β and time t falls in one of ``AZIMUTH_CELLS`` cells
  of azimuth; the time since the last plot in that cell or a neighbour is one revisit,
  T (1 − 3 · 360°/cells / 360°) at the least unless it is the same sweep (a few
  hundredths of a second, below ``MIN_REVISIT_S``), and a whole multiple of T after a missed
  detection. The shortest revisits are therefore the period: T̂ is the median of the
  revisits within ±10% of their 10th percentile, once ``MIN_REVISITS`` have been seen and
  if a tenth of them (three at least) are that close (else the period stays unknown).
* **Until then, the beam's rate.** Two consecutive plots of a rotating radar
  ``MIN_RATE_PAIR_S`` to ``MAX_RATE_PAIR_S`` apart (or a batch's first and last, where its
  plots come closer) lie on the beam at their two times, so wrap(β₂ − β₁)/(t₂ − t₁) is
  its angular rate ω (plus the azimuth noise over the interval); after ``MIN_REVISITS`` such
  pairs T = 2π / |median ω| serves while the revisits accumulate (a fraction of a revolution
  of plots instead of one or two revolutions: the tracks of a recording's first seconds are
  judged too). If fewer than half the rates are within 10% of their median, the plots are
  not stamped by a beam (a scan's plots at random times) and the radar's period stays
  unknown, whatever the revisits say; so too when fewer than half the consecutive plots less
  than ``MAX_RATE_PAIR_S`` apart are as close in azimuth as the beam's turn between them
  allows (plus ``BEAM_NOISE_RAD``). A radar with one plot per revolution gives no such
  pairs.
* **Rotation direction** (the sign of dβ/dt) by the majority of consecutive plot pairs less
  than a quarter revolution apart.

**The sweep** (``RadarBeam.swept``). After a batch of the radar's plots ending at time t₁
with beam azimuth β₁ (its last plot's), since its previous batch at t₀ the beam has turned
by s = 2π (t₁ − t₀) / T (a full turn or more: everything swept). A track at predicted azimuth
φ is behind the beam by δ = d (β₁ − φ) mod 2π (d the direction) and was passed at
t₁ − δ T / 2π. It is judged at this batch when m < δ ≤ m + s: the beam passed it during the
batch interval, ``m`` (the track's azimuth margin: its position σ over its range, at least
``MIN_MARGIN_RAD``) ago at least, so that the plot of a track a little ahead of its
prediction has arrived before the track is judged (plots come in time order). A
scan-stamped radar's batch is one whole scan: every track is judged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

#: Azimuth cells of the period estimate (1° each).
AZIMUTH_CELLS = 360
#: Revisits shorter than this are the same sweep (two plots close in azimuth), not a turn.
MIN_REVISIT_S = 0.3
#: Revisits seen before the period is taken as known.
MIN_REVISITS = 16
#: Revisits kept for the estimate (the most recent ones).
REVISITS_KEPT = 512
#: Longest interval of two consecutive plots that measures the beam's rate (s): well under a
#: revolution of any surveillance radar (1 s for the fastest, 4–12 s for most).
MAX_RATE_PAIR_S = 0.5
#: Azimuth difference allowed between two plots on the beam beyond its turn (rad): their
#: noise, 0.6°.
BEAM_NOISE_RAD = 0.01
#: Shortest interval that measures it: over a shorter one the azimuth noise (a few
#: milliradians) is not small against the beam's turn (π/2 rad/s · 0.05 s = 0.08 rad).
MIN_RATE_PAIR_S = 0.05
#: Smallest angle the beam must be past a track before it is judged (rad): plot azimuth
#: noise and the beam's own width.
MIN_MARGIN_RAD = math.radians(2.0)
#: Largest azimuth margin (rad): a track too uncertain for its azimuth to mean anything is
#: judged a quarter turn after its predicted azimuth.
MAX_MARGIN_RAD = math.pi / 2
TWO_PI = 2.0 * math.pi
#: A track is expected inside a coverage limit only this far inside it, relative to its
#: range, beside three of its position σ (``RadarBeam.inside``).
EDGE_FRACTION = 0.01
#: The compiled sweep's skip (``core.tracking.kernels_associate._swept``): a track is
#: tested against a radar's sweep only from the earliest time its beam can have passed it,
#: a bound worked out at its previous test from a model of the beam's azimuth,
#: β(t) = β₀ + d 2π (t − t₀) / T. The model holds while each batch's last azimuth is within
#: ``SWEEP_BEAM_TOLERANCE_RAD`` of it and the period estimate within ``SWEEP_PERIOD_DRIFT``
#: (relative) of its T; otherwise a new model starts and every track is tested. A bound
#: reaches at most ``SWEEP_HORIZON`` revolutions ahead.
SWEEP_BEAM_TOLERANCE_RAD = 0.03
SWEEP_PERIOD_DRIFT = 0.01
SWEEP_HORIZON = 0.75


@dataclass(frozen=True)
class RadarCoverage:
    """A radar's coverage and rotation, each None where not known (then estimated).

    Attributes:
        rotation_period_s: T, the antenna's revolution (s).
        min_range_m, max_range_m: the instrumented range (m).
        min_elevation_rad, max_elevation_rad: the elevation limits (rad; 3D plots only).
    """

    rotation_period_s: float | None = None
    min_range_m: float | None = None
    max_range_m: float | None = None
    min_elevation_rad: float | None = None
    max_elevation_rad: float | None = None


def beam_constants() -> tuple[int, float, int, int, float, float, float]:
    """The constants of the beam's estimates, in ``observe_beam``'s order after its state
    and plots: cells, min revisit, min revisits, kept, max and min rate pair, beam noise."""
    return (
        AZIMUTH_CELLS, MIN_REVISIT_S, MIN_REVISITS, REVISITS_KEPT, MAX_RATE_PAIR_S,
        MIN_RATE_PAIR_S, BEAM_NOISE_RAD,
    )  # fmt: skip


def _nan(v: float | None) -> float:
    return math.nan if v is None else float(v)


def _none(v: float) -> float | None:
    return None if math.isnan(v) else float(v)


class BeamTable:
    """The state of R radars' beams as stacked arrays (``core.tracking.kernels_associate.
    BeamArrays``): the rows ``RadarBeam`` reads and the compiled association changes in
    place. ``grow`` makes room for more radars, or for longer lists of beam rates and close
    pairs (up to ``REVISITS_KEPT`` plus a batch's plots are kept)."""

    def __init__(self, radars: int = 1, length: int = 2 * REVISITS_KEPT):
        from radarviz.core.tracking.kernels_associate import (
            B_EL_HI,
            B_EL_LO,
            B_RANGE_HI,
            B_RANGE_LO,
            BEAM_COUNTS,
            BEAM_FLOATS,
            BeamArrays,
        )

        self.radars, self.length = 0, 0
        f = np.full((0, BEAM_FLOATS), np.nan)
        self.arrays = BeamArrays(
            f,
            np.zeros((0, BEAM_COUNTS), np.int64),
            np.zeros((0, AZIMUTH_CELLS)),
            np.zeros((0, REVISITS_KEPT)),
            np.zeros((0, REVISITS_KEPT)),
            np.zeros((0, 0)),
            np.zeros((0, 0, 2)),
        )
        self._fresh = (B_RANGE_LO, B_RANGE_HI, B_EL_LO, B_EL_HI)
        self.grow(radars, length)

    def grow(self, radars: int, length: int) -> None:
        """Room for ``radars`` radars and lists of ``length``; new rows are fresh beams."""
        radars, length = max(radars, self.radars), max(length, self.length)
        if radars == self.radars and length == self.length:
            return
        a = self.arrays
        lo_r, hi_r, lo_e, hi_e = self._fresh
        f = np.full((radars, a.f.shape[1]), np.nan)
        f[:, [lo_r, lo_e]], f[:, [hi_r, hi_e]] = np.inf, -np.inf
        f[: self.radars] = a.f
        c = np.zeros((radars, a.c.shape[1]), np.int64)
        c[: self.radars] = a.c
        cells = np.full((radars, AZIMUTH_CELLS), -np.inf)
        cells[: self.radars] = a.cells
        revisits = np.zeros((radars, REVISITS_KEPT))
        revisits[: self.radars] = a.revisits
        ordered = np.zeros((radars, REVISITS_KEPT))
        ordered[: self.radars] = a.ordered
        rates = np.zeros((radars, length))
        rates[: self.radars, : self.length] = a.rates
        close = np.zeros((radars, length, 2))
        close[: self.radars, : self.length] = a.close
        self.arrays = type(a)(f, c, cells, revisits, ordered, rates, close)
        self.radars, self.length = radars, length


class RadarBeam:
    """One radar's coverage and beam, given or estimated from its plots (module docstring).

    Its state is row ``row`` of a ``BeamTable`` (its own table of one row by default), so
    that the compiled association (``core.tracking.kernels_associate``) and this class read
    and learn the same numbers by the same code (``observe_beam``)."""

    def __init__(
        self, given: RadarCoverage | None = None, table: BeamTable | None = None, row: int = 0
    ):
        from radarviz.core.tracking import kernels_associate as ka

        self._k = ka
        self.given = given or RadarCoverage()
        self.table = BeamTable() if table is None else table
        self.row = row
        g = self.given
        f = self._f
        f[ka.B_PERIOD] = f[ka.B_GIVEN_PERIOD] = _nan(g.rotation_period_s)
        f[ka.B_GIVEN_MIN_R], f[ka.B_GIVEN_MAX_R] = _nan(g.min_range_m), _nan(g.max_range_m)
        f[ka.B_GIVEN_MIN_EL] = _nan(g.min_elevation_rad)
        f[ka.B_GIVEN_MAX_EL] = _nan(g.max_elevation_rad)

    @property
    def _f(self) -> NDArray[np.float64]:
        return self.table.arrays.f[self.row]

    @property
    def _c(self) -> NDArray[np.int64]:
        return self.table.arrays.c[self.row]

    # -- estimates -------------------------------------------------------------------------

    @property
    def period_s(self) -> float | None:
        """T: given, else estimated (None until ``MIN_REVISITS`` revisits)."""
        return _none(self._f[self._k.B_PERIOD])

    @property
    def scan_stamped(self) -> bool:
        """Most consecutive plots of the radar share their time stamp (module docstring)."""
        return bool(self._c[self._k.B_SAME] > self._c[self._k.B_OTHER])

    @property
    def direction(self) -> float:
        """+1 when the beam turns towards increasing azimuth (counter-clockwise), −1 else."""
        c = self._c
        return 1.0 if c[self._k.B_TURN_POS] >= c[self._k.B_TURN_NEG] else -1.0

    @property
    def last_az(self) -> float:
        """The azimuth of the radar's latest plot (rad)."""
        return float(self._f[self._k.B_LAST_AZ])

    @property
    def swept_to_s(self) -> float | None:
        """Time of the previous batch's end, for the sweep (None before the first batch)."""
        return _none(self._f[self._k.B_SWEPT_TO])

    @swept_to_s.setter
    def swept_to_s(self, value: float) -> None:
        self._f[self._k.B_SWEPT_TO] = value

    def range_limits(self, estimated: bool = True) -> tuple[float, float]:
        """(min, max) range: given, else (``estimated``) the extremes of the plots seen, else
        unbounded (m)."""
        g, f = self.given, self._f
        lo, hi = (f[self._k.B_RANGE_LO], f[self._k.B_RANGE_HI]) if estimated else (0.0, math.inf)
        return (
            float(lo) if g.min_range_m is None else g.min_range_m,
            float(hi) if g.max_range_m is None else g.max_range_m,
        )

    def elevation_limits(self, estimated: bool = True) -> tuple[float, float]:
        """(min, max) elevation: given, else (``estimated``) the extremes of the plots seen,
        else unbounded (rad)."""
        g, f = self.given, self._f
        lo, hi = (
            (f[self._k.B_EL_LO], f[self._k.B_EL_HI]) if estimated else (-math.pi / 2, math.pi / 2)
        )
        return (
            float(lo) if g.min_elevation_rad is None else g.min_elevation_rad,
            float(hi) if g.max_elevation_rad is None else g.max_elevation_rad,
        )

    def estimated(self) -> dict[str, float | None]:
        """What was not given and has been estimated from the plots, by name (SI units)."""
        g = self.given
        out: dict[str, float | None] = {}
        measured = bool(self._c[self._k.B_MEASURED])
        if g.rotation_period_s is None and not measured and not self.scan_stamped:
            out["rotation_period_s"] = self.period_s
        lo, hi = self.range_limits()
        if g.min_range_m is None and math.isfinite(lo):
            out["min_range_m"] = lo
        if g.max_range_m is None and math.isfinite(hi):
            out["max_range_m"] = hi
        elo, ehi = self.elevation_limits()
        if g.min_elevation_rad is None and math.isfinite(elo):
            out["min_elevation_rad"] = elo
        if g.max_elevation_rad is None and math.isfinite(ehi):
            out["max_elevation_rad"] = ehi
        return out

    def observe(
        self,
        time_s: NDArray[np.float64],
        azimuth_rad: NDArray[np.float64],
        range_m: NDArray[np.float64],
        elevation_rad: NDArray[np.float64] | None,
    ) -> None:
        """Learn from a batch of the radar's plots, (B,) each, in time order
        (``core.tracking.kernels_associate.observe_beam``)."""
        if not time_s.size:
            return
        self.table.grow(self.table.radars, REVISITS_KEPT + time_s.size)
        a, r = self.table.arrays, self.row
        el = elevation_rad if elevation_rad is not None else time_s
        columns = (time_s, azimuth_rad, range_m, el)
        plots = (np.ascontiguousarray(v, dtype=np.float64) for v in columns)
        self._k.observe_beam(
            a.f[r], a.c[r], a.cells[r], a.revisits[r], a.ordered[r], a.rates[r], a.close[r], *plots,
            elevation_rad is not None, *beam_constants(),
        )  # fmt: skip

    def measured_period(self, period_s: float) -> None:
        """The period measured by the feed (a radar's north markers or service messages):
        used from now on instead of the estimate from the plots (a period in the radars file
        still comes first)."""
        if self.given.rotation_period_s is None:
            self._f[self._k.B_PERIOD] = period_s
            self._c[self._k.B_MEASURED] = 1

    # -- the sweep -------------------------------------------------------------------------

    def inside(
        self,
        range_m: NDArray[np.float64],
        elevation_rad: NDArray[np.float64] | None,
        edge_m: NDArray[np.float64],
        estimated: bool = True,
    ) -> NDArray[np.bool_]:
        """Which positions (by their range and elevation from the radar) the radar covers by
        at least ``edge_m`` (K,) inside its limits (given, and with ``estimated`` those
        estimated from the plots): a track near the edge may be on either side of it, and a
        detection there is a coin toss, not an expected detection."""
        lo, hi = self.range_limits(estimated)
        ok = (range_m >= lo + edge_m) & (range_m <= hi - edge_m)
        if elevation_rad is not None:
            elo, ehi = self.elevation_limits(estimated)
            if math.isfinite(elo) and math.isfinite(ehi):
                edge = edge_m / np.maximum(range_m, 1.0)
                ok &= (elevation_rad >= elo + edge) & (elevation_rad <= ehi - edge)
        return ok

    def swept(
        self,
        end_s: float,
        azimuth_rad: NDArray[np.float64],
        margin_rad: NDArray[np.float64],
        whole_scan: bool,
    ) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
        """Which tracks, at predicted azimuths (K,) from the radar with margins (K,), the beam
        passed during the batch that ends at ``end_s`` (module docstring), and when: (mask,
        pass times) (K,) each. ``whole_scan``: the batch is a whole scan (every track passed,
        at ``end_s``). Moves the sweep's start to ``end_s``."""
        start, self.swept_to_s = self.swept_to_s, end_s
        k = azimuth_rad.shape[0]
        if whole_scan:
            return np.ones(k, dtype=bool), np.full(k, end_s)
        T = self.period_s
        if start is None or T is None:
            return np.zeros(k, dtype=bool), np.full(k, end_s)
        turned = TWO_PI * (end_s - start) / T
        delta = np.mod(self.direction * (self.last_az - azimuth_rad), TWO_PI)
        passed = end_s - delta * (T / TWO_PI)
        if turned >= TWO_PI:
            return delta > margin_rad, passed
        return (delta > margin_rad) & (delta <= margin_rad + turned), passed
