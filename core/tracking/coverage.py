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


def _wrap(a: NDArray[np.float64] | float) -> NDArray[np.float64]:
    """Angles in [−π, π)."""
    return np.mod(np.asarray(a) + math.pi, TWO_PI) - math.pi


class RadarBeam:
    """One radar's coverage and beam, given or estimated from its plots (module docstring)."""

    def __init__(self, given: RadarCoverage | None = None):
        self.given = given or RadarCoverage()
        self._cells = np.full(AZIMUTH_CELLS, -np.inf)
        self._revisits: list[float] = []
        self._rates: list[float] = []
        self._close: list[tuple[float, float]] = []  # (Δt, |Δβ|) of close consecutive plots
        self._period: float | None = self.given.rotation_period_s
        self._measured = False  # the period came from the feed (``measured_period``)
        self._revisit_period: float | None = None  # the revisits' estimate, once known
        self._same = self._other = 0
        self._turns = [0, 0]  # pairs turning negative, positive
        self._range = [math.inf, -math.inf]
        self._elevation = [math.inf, -math.inf]
        self.last_s: float | None = None
        self.last_az = 0.0
        #: Time of the previous batch's end, for the sweep (None before the first batch).
        self.swept_to_s: float | None = None

    # -- estimates -------------------------------------------------------------------------

    @property
    def period_s(self) -> float | None:
        """T: given, else estimated (None until ``MIN_REVISITS`` revisits)."""
        return self._period

    @property
    def scan_stamped(self) -> bool:
        """Most consecutive plots of the radar share their time stamp (module docstring)."""
        return self._same > self._other

    @property
    def direction(self) -> float:
        """+1 when the beam turns towards increasing azimuth (counter-clockwise), −1 else."""
        return 1.0 if self._turns[1] >= self._turns[0] else -1.0

    def range_limits(self, estimated: bool = True) -> tuple[float, float]:
        """(min, max) range: given, else (``estimated``) the extremes of the plots seen, else
        unbounded (m)."""
        g = self.given
        lo, hi = self._range if estimated else (0.0, math.inf)
        return (
            lo if g.min_range_m is None else g.min_range_m,
            hi if g.max_range_m is None else g.max_range_m,
        )

    def elevation_limits(self, estimated: bool = True) -> tuple[float, float]:
        """(min, max) elevation: given, else (``estimated``) the extremes of the plots seen,
        else unbounded (rad)."""
        g = self.given
        lo, hi = self._elevation if estimated else (-math.pi / 2, math.pi / 2)
        return (
            lo if g.min_elevation_rad is None else g.min_elevation_rad,
            hi if g.max_elevation_rad is None else g.max_elevation_rad,
        )

    def estimated(self) -> dict[str, float | None]:
        """What was not given and has been estimated from the plots, by name (SI units)."""
        g = self.given
        out: dict[str, float | None] = {}
        if g.rotation_period_s is None and not self._measured and not self.scan_stamped:
            out["rotation_period_s"] = self._period
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
        """Learn from a batch of the radar's plots, (B,) each, in time order."""
        if not time_s.size:
            return
        self._range = [
            min(self._range[0], float(range_m.min())),
            max(self._range[1], float(range_m.max())),
        ]
        if elevation_rad is not None:
            self._elevation = [
                min(self._elevation[0], float(elevation_rad.min())),
                max(self._elevation[1], float(elevation_rad.max())),
            ]
        # np.concatenate, not np.r_: a batch is a few plots, and np.r_'s parsing of its
        # arguments cost more than the rest of this method.
        t = time_s if self.last_s is None else np.concatenate(([self.last_s], time_s))
        az = azimuth_rad if self.last_s is None else np.concatenate(([self.last_az], azimuth_rad))
        dt, daz = np.diff(t), _wrap(np.diff(az))
        same = dt == 0.0
        self._same += int(same.sum())
        self._other += int((~same).sum())
        quarter = (self._period or math.inf) / 4
        turning = (dt > 0) & (dt < quarter) & (np.abs(daz) < math.pi / 3)
        self._turns[0] += int((turning & (daz < 0)).sum())
        self._turns[1] += int((turning & (daz > 0)).sum())
        if self.given.rotation_period_s is None and not self._measured:
            if len(self._close) < REVISITS_KEPT:
                close = (dt > 0) & (dt <= MAX_RATE_PAIR_S)
                self._close.extend(
                    zip(dt[close].tolist(), np.abs(daz[close]).tolist(), strict=True)
                )
            if len(self._rates) < REVISITS_KEPT:
                pair = (dt >= MIN_RATE_PAIR_S) & (dt <= MAX_RATE_PAIR_S)
                self._rates.extend((daz[pair] / dt[pair]).tolist())
                span = t[-1] - t[0]  # the batch's ends: a rate where its plots come densely
                if MIN_RATE_PAIR_S <= span <= MAX_RATE_PAIR_S and not pair.any():
                    self._rates.append(float(_wrap(az[-1] - az[0])) / span)
            self._learn_period(time_s, azimuth_rad)
            self._period = self._estimate()
        self.last_s, self.last_az = float(time_s[-1]), float(azimuth_rad[-1])

    def _learn_period(self, time_s: NDArray[np.float64], azimuth_rad: NDArray[np.float64]) -> None:
        cell = (np.mod(azimuth_rad, TWO_PI) * (AZIMUTH_CELLS / TWO_PI)).astype(np.intp)
        cell = np.minimum(cell, AZIMUTH_CELLS - 1)
        c = self._cells
        for k, t in zip(cell.tolist(), time_s.tolist(), strict=True):
            prev = max(c[k - 1], c[k], c[(k + 1) % AZIMUTH_CELLS])
            if math.isfinite(prev) and t - prev >= MIN_REVISIT_S:
                self._revisits.append(t - prev)
            c[k] = t
        if len(self._revisits) > REVISITS_KEPT:
            del self._revisits[: len(self._revisits) - REVISITS_KEPT]
        if len(self._revisits) >= MIN_REVISITS:
            r = np.asarray(self._revisits)
            low = float(np.quantile(r, 0.1, method="lower"))  # a revisit seen, not between two
            near = r[(r >= 0.9 * low) & (r <= 1.1 * low)]
            # The shortest revisits must be a cluster (a tenth of them at least), not a stray.
            if near.size >= max(3, r.size // 10):
                self._revisit_period = float(np.median(near))

    def _estimate(self) -> float | None:
        """The period from the plots (module docstring): the revisits', else the beam
        rate's; None while neither is known, or when the rates of close plots disagree (their
        stamps are not a beam's, e.g. a scan's plots at random times, whose same-sweep
        neighbours look like short revisits)."""
        rate_period = None
        if len(self._rates) >= MIN_REVISITS:
            rates = np.asarray(self._rates)
            w = float(np.median(rates))
            if np.mean(np.abs(rates - w) <= 0.1 * abs(w)) < 0.5:
                return None
            rate_period = TWO_PI / abs(w)
        period = self._revisit_period if self._revisit_period is not None else rate_period
        if period is not None and len(self._close) >= MIN_REVISITS:
            # On a beam, close plots are no farther apart in azimuth than the beam turned
            # between them (and the noise); a scan's plots at random times are.
            dt, daz = np.asarray(self._close).T
            on_beam = daz <= 1.2 * TWO_PI * dt / period + BEAM_NOISE_RAD
            if np.mean(on_beam) < 0.5:
                return None
        return period

    def measured_period(self, period_s: float) -> None:
        """The period measured by the feed (a radar's north markers or service messages):
        used from now on instead of the estimate from the plots (a period in the radars file
        still comes first)."""
        if self.given.rotation_period_s is None:
            self._period, self._measured = period_s, True

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
        T = self._period
        if start is None or T is None:
            return np.zeros(k, dtype=bool), np.full(k, end_s)
        turned = TWO_PI * (end_s - start) / T
        delta = np.mod(self.direction * (self.last_az - azimuth_rad), TWO_PI)
        passed = end_s - delta * (T / TWO_PI)
        if turned >= TWO_PI:
            return delta > margin_rad, passed
        return (delta > margin_rad) & (delta <= margin_rad + turned), passed
