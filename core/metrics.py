"""Monte Carlo tracking metrics, accumulated as the filter runs.

Per scan n the accumulator keeps running sums over the runs (errors, squared errors, reported
variances, NEES), never the states themselves, so 10⁵ runs × 60 scans need a few kilobytes.
Sums are added block by block in a fixed order, so a result depends only on the seed and the
block size, not on how the work was scheduled.

Definitions, with e = x̂ − x the estimation error of run m at scan n and M runs:

    bias_x      = mean e_x                      rmse_x = sqrt(mean e_x²)
    std_x       = sqrt(Σ (e_x − bias_x)² / (M − 1))
    sigma_x_filter = sqrt(mean P_xx)            (what the filter believes)
    bias_range, bias_cross: mean of e projected on the true line of sight u = (cos β, sin β)
                 and on its left normal (−sin β, cos β)
    nees_pos    = mean e_posᵀ P_pos⁻¹ e_pos     (2 dof)
    nees_state  = mean eᵀ P⁻¹ e                 (4 dof)

For a consistent filter M · nees ~ χ²(M·dof), which gives the two-sided 95% band
``nees_band(dof, M)``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.state import CVBatch, quad_form_inv
from radarviz.core.geometry import polar_coordinates

#: Names of the running sums, in the row order of ``MetricsAccumulator.to_arrays``.
SUM_NAMES: tuple[str, ...] = (
    "ex",
    "ex2",
    "ey",
    "ey2",
    "er",
    "ec",
    "pxx",
    "pyy",
    "nees_pos",
    "nees_state",
)


class TrackMetrics(NamedTuple):
    """Per-scan statistics of one method over M runs; every field is (N,)."""

    sigma_x_filter: NDArray[np.float64]
    rmse_x: NDArray[np.float64]
    std_x: NDArray[np.float64]
    bias_x: NDArray[np.float64]
    rmse_y: NDArray[np.float64]
    sigma_y_filter: NDArray[np.float64]
    bias_range: NDArray[np.float64]
    bias_cross: NDArray[np.float64]
    nees_pos: NDArray[np.float64]
    nees_state: NDArray[np.float64]


class MetricsAccumulator:
    """Running sums of tracking errors per scan for one method.

    Args:
        steps: number of scans N.
    """

    def __init__(self, steps: int) -> None:
        self.steps = steps
        self.runs = np.zeros(steps, dtype=np.int64)
        self.sums: dict[str, NDArray[np.float64]] = {k: np.zeros(steps) for k in SUM_NAMES}

    def add(self, n: int, state: CVBatch, truth: NDArray[np.float64]) -> None:
        """Add one block of runs at scan index n (0-based); ``truth`` is the (4,) true state."""
        x, P = state.x, state.P
        ex = x[:, 0] - truth[0]
        ey = x[:, 2] - truth[2]
        bearing = polar_coordinates([truth[0], truth[2]])[1]
        c, s = np.cos(bearing), np.sin(bearing)
        # Position NEES from the 2 × 2 block written out: (Pyy ex² − 2 Pxy ex ey + Pxx ey²) / det
        pxx, pxy, pyy = P[:, 0, 0], P[:, 0, 2], P[:, 2, 2]
        nees_pos = (pyy * ex * ex - 2.0 * pxy * ex * ey + pxx * ey * ey) / (pxx * pyy - pxy * pxy)
        e = x - truth
        add = self.sums
        add["ex"][n] += ex.sum()
        add["ex2"][n] += (ex * ex).sum()
        add["ey"][n] += ey.sum()
        add["ey2"][n] += (ey * ey).sum()
        add["er"][n] += (c * ex + s * ey).sum()
        add["ec"][n] += (c * ey - s * ex).sum()
        add["pxx"][n] += pxx.sum()
        add["pyy"][n] += pyy.sum()
        add["nees_pos"][n] += nees_pos.sum()
        add["nees_state"][n] += quad_form_inv(P, e).sum()
        self.runs[n] += x.shape[0]

    def to_arrays(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """The state as plain arrays: runs (N,) and sums (len(SUM_NAMES), N), copies.

        This is what a sweep chunk ships between processes and stores on disk; the arrays
        round-trip exactly, so ``from_arrays(*a.to_arrays())`` merges bit for bit like ``a``.
        """
        return self.runs.copy(), np.stack([self.sums[k] for k in SUM_NAMES])

    @classmethod
    def from_arrays(cls, runs: NDArray[np.int64], sums: NDArray[np.float64]) -> MetricsAccumulator:
        """The accumulator whose state is ``runs`` (N,) and ``sums`` (len(SUM_NAMES), N)."""
        runs = np.asarray(runs)
        sums = np.asarray(sums)
        steps = runs.shape[0]
        if runs.shape != (steps,) or sums.shape != (len(SUM_NAMES), steps):
            raise ValueError(
                f"accumulator arrays must be runs ({steps},) and sums ({len(SUM_NAMES)}, {steps}),"
                f" got {runs.shape} and {sums.shape}"
            )
        acc = cls(steps)
        acc.runs[:] = runs
        for i, k in enumerate(SUM_NAMES):
            acc.sums[k][:] = sums[i]
        return acc

    def merge(self, other: MetricsAccumulator) -> None:
        """Add another accumulator's sums (same N) into this one."""
        for k in SUM_NAMES:
            self.sums[k] += other.sums[k]
        self.runs += other.runs

    def result(self) -> TrackMetrics:
        """The per-scan statistics; NaN at scans no run reached (e.g. before a track start)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return self._result()

    def _result(self) -> TrackMetrics:
        m = self.runs.astype(np.float64)
        m[m == 0] = np.nan
        s = self.sums
        bias_x = s["ex"] / m
        # Sample variance from the sums; clip tiny negative values left by rounding.
        var_x = np.maximum(s["ex2"] - s["ex"] * bias_x, 0.0) / (m - 1.0)
        return TrackMetrics(
            sigma_x_filter=np.sqrt(s["pxx"] / m),
            rmse_x=np.sqrt(s["ex2"] / m),
            std_x=np.sqrt(var_x),
            bias_x=bias_x,
            rmse_y=np.sqrt(s["ey2"] / m),
            sigma_y_filter=np.sqrt(s["pyy"] / m),
            bias_range=s["er"] / m,
            bias_cross=s["ec"] / m,
            nees_pos=s["nees_pos"] / m,
            nees_state=s["nees_state"] / m,
        )


def nees_band(dof: int, runs: int, level: float = 0.95) -> tuple[float, float]:
    """Two-sided probability-``level`` band of the run-averaged NEES of a consistent filter.

    M · NEES_avg ~ χ²(M · dof)  (Bar-Shalom, Li, Kirubarajan 2001, sec. 5.4.2).

    ``scipy.stats`` is imported here, not at module level: it costs most of a command's
    start-up (0.4 s) and only this quantile needs it.
    """
    from scipy import stats

    tail = (1.0 - level) / 2.0
    lo, hi = stats.chi2.ppf([tail, 1.0 - tail], runs * dof) / runs
    return float(lo), float(hi)


def delta_percent(
    candidate: NDArray[np.float64], reference: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Prosov's Δx(n) = (σ̂_candidate − σ̂_reference) / σ̂_reference, in percent."""
    return 100.0 * (candidate - reference) / reference
