"""Monte Carlo tracking metrics, accumulated as the filter runs.

Per scan n the accumulator keeps running sums over the runs (errors, squared errors, reported
variances, NEES), never more states than a small stage (``STAGE_ROWS`` runs × scans), so
10⁵ runs × 60 scans need well under a megabyte.
Sums are added block by block in a fixed order, so a result depends only on the seed and the
block size, not on how the work was scheduled.

Definitions, with e = x̂ − x the estimation error of run m at scan n and M runs:

    bias_x_m         = mean e_x                 rmse_x_m = sqrt(mean e_x²)
    std_x_m          = sqrt(Σ (e_x − bias_x_m)² / (M − 1))
    sigma_x_filter_m = sqrt(mean P_xx)          (what the filter believes)
    bias_range_m, bias_cross_m: mean of e projected on the true line of sight
                       u = (cos β, sin β) and on its left normal (−sin β, cos β)
    nees_pos         = mean e_posᵀ P_pos⁻¹ e_pos   (2 dof)
    nees_state       = mean eᵀ P⁻¹ e               (4 dof)

In 3D (states (x, ẋ, y, ẏ, z, ż)) the same sums mean: bias_range_m along the 3D line of sight
u = (cos ε cos β, cos ε sin β, sin ε), bias_cross_m along the horizontal cross-range
(−sin β, cos β, 0), nees_pos with 3 dof and nees_state with 6 (``nees_dof``); ex, ey, pxx,
pyy are the x and y axes as in 2D. The 2D sums are formed by the 2D code, unchanged.

For a consistent filter M · nees ~ χ²(M·dof), which gives the two-sided 95% band
``nees_band(dof, M)``: where the run average of a consistent filter falls.

The Monte Carlo error of every statistic (how far it is from its M → ∞ value) is a different
band: the accumulator also keeps the sums per group of runs (run j of a scan in group
j mod G, ``core.confidence.BAND_GROUPS``), and ``band95`` / ``leave_one_out`` give the
delete-a-group jackknife band of any field (``core.confidence``). Ratios of two methods' fields
(Prosov's Δx) take their leave-outs from both methods' ``leave_one_out``: the runs are dealt to
the groups in the same order for every method, so group g holds the same runs everywhere.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.confidence import (
    BAND_GROUPS,
    chi2_ppf,
    group_counts,
    group_sums,
    jackknife_band,
)
from radarviz.core.filters.state import CVBatch, quad_form_inv
from radarviz.core.filters.terms import SUM_NAMES
from radarviz.core.geometry import polar_coordinates


class TrackMetrics(NamedTuple):
    """Per-scan statistics of one method over M runs; every field is (N,)."""

    sigma_x_filter_m: NDArray[np.float64]
    rmse_x_m: NDArray[np.float64]
    std_x_m: NDArray[np.float64]
    bias_x_m: NDArray[np.float64]
    rmse_y_m: NDArray[np.float64]
    sigma_y_filter_m: NDArray[np.float64]
    bias_range_m: NDArray[np.float64]
    bias_cross_m: NDArray[np.float64]
    nees_pos: NDArray[np.float64]
    nees_state: NDArray[np.float64]


#: The ``TrackMetrics`` fields that cannot be negative (a σ, an RMSE, a NEES): their Monte Carlo
#: bands are cut at 0 (``core.experiments.prosov.TrackingResult.band95``), and a negative value
#: is a failed computation (``viz_app.reports.prosov.check_metrics``).
NONNEGATIVE_METRICS: frozenset[str] = frozenset(
    {
        "sigma_x_filter_m",
        "rmse_x_m",
        "std_x_m",
        "rmse_y_m",
        "sigma_y_filter_m",
        "nees_pos",
        "nees_state",
    }
)


def metric_band(
    name: str, value: NDArray[np.float64], leave_out: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The 95% Monte Carlo band (lo, hi) of a ``TrackMetrics`` field ``name``: the
    delete-a-group jackknife of ``value`` from its leave-one-out values, cut at 0 for a
    field in ``NONNEGATIVE_METRICS`` (the jackknife band is symmetric; a heavy-tailed NEES,
    at σβ = 20° values ≥ 1.4 with half-widths of 10⁴, put its lower end far below 0, where
    no NEES can be)."""
    lo, hi = jackknife_band(value, leave_out)
    if name in NONNEGATIVE_METRICS:
        lo = np.maximum(lo, 0.0)
    return lo, hi


#: Most rows (runs × scans) ``MetricsAccumulator`` stages before forming their sums. At the
#: tuning panel's few hundred runs per scan, 20 scans are then one pass of ~70 vector
#: operations instead of 20 (per-call overhead dominates there: 200 runs cost 4 ms a method
#: instead of 9 ms); a block of ``STAGE_ROWS`` or more runs is summed as it arrives, without
#: a copy. 4096 rows keep the pass's temporaries in cache: 16384 made 5000-run blocks slower.
STAGE_ROWS = 4096


def scan_sums(
    x: NDArray[np.float64], P: NDArray[np.float64], truth: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The running sums of K scans of m runs each: (len(SUM_NAMES), K).

    ``scan_terms`` summed over the runs of each scan (one pairwise sum).
    """
    return scan_terms(x, P, truth).sum(axis=-1)


def truth_line_of_sight(
    truth: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """cos β and sin β (K, 1) of the true bearing at each of K scans, truth (K, 4).

    From each scan's scalar truth exactly as a single scan would (a vectorised arctan2 may
    round differently), so sums do not depend on how scans are grouped. Callers adding many
    chunks of the same scans form it once and pass it to ``scan_terms`` as ``los``.
    """
    k = truth.shape[0]
    c, s = np.empty((k, 1)), np.empty((k, 1))
    for i in range(k):
        bearing = polar_coordinates([truth[i, 0], truth[i, 2]])[1]
        c[i], s[i] = np.cos(bearing), np.sin(bearing)
    return c, s


def scan_terms(
    x: NDArray[np.float64],
    P: NDArray[np.float64],
    truth: NDArray[np.float64],
    los: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> NDArray[np.float64]:
    """The per-run terms of the running sums of K scans of m runs: (len(SUM_NAMES), K, m).

    Args:
        x: (K, m, 4) filtered states (x, ẋ, y, ẏ); P: (K, m, 4, 4) their covariances.
        truth: (K, 4) the true state at each of the K scans.
        los: ``truth_line_of_sight(truth)`` if the caller has it.

    Every number is formed by the same operations in the same order whatever K and m are
    (element-wise IEEE arithmetic, then one pairwise sum over the m runs of each scan), so a
    scan's sums do not depend on how many scans are formed together: staging does not change
    a result by one bit.
    """
    k, m = x.shape[:2]
    if x.shape[-1] == 6:
        return _scan_terms_3d(x, P, truth)
    c, s = truth_line_of_sight(truth) if los is None else los
    t = truth[:, None, :]
    terms = np.empty((len(SUM_NAMES), k, m))
    ex, ex2, ey, ey2, er, ec, pxx, pyy, nees_pos, nees_state = terms
    np.subtract(x[..., 0], t[..., 0], out=ex)
    np.subtract(x[..., 2], t[..., 2], out=ey)
    np.multiply(ex, ex, out=ex2)
    np.multiply(ey, ey, out=ey2)
    np.add(c * ex, s * ey, out=er)
    np.subtract(c * ey, s * ex, out=ec)
    pxx[...], pyy[...] = P[..., 0, 0], P[..., 2, 2]
    pxy = P[..., 0, 2].copy()
    # Position NEES from the 2 × 2 block written out: (Pyy ex² − 2 Pxy ex ey + Pxx ey²) / det
    np.divide(
        pyy * ex * ex - 2.0 * pxy * ex * ey + pxx * ey * ey, pxx * pyy - pxy * pxy, out=nees_pos
    )
    e = x - t
    nees_state[...] = quad_form_inv(P.reshape(k * m, 4, 4), e.reshape(k * m, 4)).reshape(k, m)
    return terms


def _scan_terms_3d(
    x: NDArray[np.float64], P: NDArray[np.float64], truth: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``scan_terms`` of 3D states: x (K, m, 6), P (K, m, 6, 6), truth (K, 6) (module
    docstring: bias along the 3D line of sight, NEES with 3 and 6 dof)."""
    k, m = x.shape[:2]
    u, c = np.empty((k, 1, 3)), np.empty((k, 1, 2))
    for i in range(k):  # from each scan's scalar truth, as in 2D
        _, az, el = polar_coordinates([truth[i, 0], truth[i, 2], truth[i, 4]])
        u[i, 0] = np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)
        c[i, 0] = -np.sin(az), np.cos(az)
    e = x - truth[:, None, :]
    terms = np.empty((len(SUM_NAMES), k, m))
    ex, ex2, ey, ey2, er, ec, pxx, pyy, nees_pos, nees_state = terms
    ex[...], ey[...] = e[..., 0], e[..., 2]
    ez = e[..., 4]
    np.multiply(ex, ex, out=ex2)
    np.multiply(ey, ey, out=ey2)
    er[...] = u[..., 0] * ex + u[..., 1] * ey + u[..., 2] * ez
    ec[...] = c[..., 0] * ex + c[..., 1] * ey
    pxx[...], pyy[...] = P[..., 0, 0], P[..., 2, 2]
    pos = [0, 2, 4]
    p_pos = P[..., pos, :][..., pos]
    e_pos = e[..., pos].reshape(k * m, 3)
    nees_pos[...] = quad_form_inv(p_pos.reshape(k * m, 3, 3), e_pos).reshape(k, m)
    nees_state[...] = quad_form_inv(P.reshape(k * m, 6, 6), e.reshape(k * m, 6)).reshape(k, m)
    return terms


def nees_dof(dims: int) -> tuple[int, int]:
    """Degrees of freedom of (position NEES, state NEES) of a ``dims``-D track: (2, 4), (3, 6)."""
    if dims not in (2, 3):
        raise ValueError(f"dims must be 2 or 3 (got {dims})")
    return dims, 2 * dims


class MetricsAccumulator:
    """Running sums of tracking errors per scan for one method.

    ``add`` stages copies of the states (up to ``STAGE_ROWS`` rows) and ``scan_sums`` turns
    them into sums in one pass when the sums are needed (``merge``, ``to_arrays``,
    ``result``) or the stage is full. The sums are the ones adding each scan on its own gives,
    bit for bit, added in the order the scans came.

    Args:
        steps: number of scans N.
    """

    def __init__(self, steps: int) -> None:
        self.steps = steps
        self.runs = np.zeros(steps, dtype=np.int64)
        self._sums = np.zeros((len(SUM_NAMES), steps))
        self._stage: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] = (
            np.empty((0, 0, 4)),
            np.empty((0, 0, 4, 4)),
            np.empty((0, 4)),
        )
        self._staged: list[int] = []  # scan index of each staged slot, in arrival order
        self._offsets: list[int] = []  # runs already at that scan before the slot's block
        # Per-group runs (G, N) and sums (len(SUM_NAMES), G, N) for the jackknife bands
        # (``core.confidence``): run j of a scan, in arrival order, is in group j mod G.
        self.group_runs = np.zeros((BAND_GROUPS, steps), dtype=np.int64)
        self._group_sums = np.zeros((len(SUM_NAMES), BAND_GROUPS, steps))

    def add(self, n: int, state: CVBatch, truth: NDArray[np.float64]) -> None:
        """Add one block of runs at scan index n (0-based); ``truth`` is the (4,) or (6,) true
        state (2D or 3D, as the block's states)."""
        x, P = state.x, state.P
        m = x.shape[0]
        offset = int(self.runs[n])
        self.runs[n] += m
        self.group_runs[:, n] += group_counts(offset, m)
        if m >= STAGE_ROWS:  # big enough to be one efficient pass on its own
            self._flush()
            terms = scan_terms(x[None], P[None], np.asarray(truth)[None])
            self._add_sums([n], terms.sum(axis=-1))
            self._add_group_sums([n], [offset], terms)
            return
        staged = self._staged
        xs, ps, ts = self._stage
        d = x.shape[-1]  # 4 (2D) or 6 (3D)
        if xs.shape[1] != m or xs.shape[-1] != d or not len(ts):  # a new block size: stage anew
            self._flush()
            depth = max(1, STAGE_ROWS // max(m, 1))
            self._stage = xs, ps, ts = (
                np.empty((depth, m, d)),
                np.empty((depth, m, d, d)),
                np.empty((depth, d)),
            )
            staged = self._staged
        k = len(staged)
        xs[k] = x
        ps[k] = P
        ts[k] = truth
        staged.append(n)
        self._offsets.append(offset)
        if k + 1 == len(ts):
            self._flush()

    def add_scans(
        self,
        first: int,
        x: NDArray[np.float64],
        P: NDArray[np.float64],
        truth: NDArray[np.float64],
        los: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
    ) -> None:
        """Add one block of runs at K consecutive scans ``first … first + K − 1`` at once.

        Args:
            x: (K, m, 4) states; P: (K, m, 4, 4) covariances; truth: (K, 4) true states.
            los: ``truth_line_of_sight(truth)``, if the caller has it.

        The sums are those of K ``add`` calls, bit for bit (``scan_terms`` does not depend
        on how many scans are formed together), for one pass instead of K.
        """
        self.add_terms(first, scan_terms(x, P, np.asarray(truth), los))

    def add_terms(self, first: int, terms: NDArray[np.float64]) -> None:
        """``add_scans`` given the per-run terms (len(SUM_NAMES), K, m) of ``scan_terms``."""
        self._flush()
        k, m = terms.shape[1:]
        scans = list(range(first, first + k))
        offsets = [int(self.runs[n]) for n in scans]
        counts: dict[int, NDArray[np.int64]] = {}  # usually one offset for all the scans
        for n, offset in zip(scans, offsets, strict=True):
            if offset not in counts:
                counts[offset] = group_counts(offset, m)
            self.group_runs[:, n] += counts[offset]
        self.runs[first : first + k] += m
        self._add_sums(scans, terms.sum(axis=-1))
        self._add_group_sums(scans, offsets, terms)

    def add_group_sums(
        self, first: int, runs: int, sums: NDArray[np.float64], offset: int = 0
    ) -> None:
        """Add ``runs`` runs at K consecutive scans ``first … first + K − 1`` given the sums of
        their terms per group: sums (G, K, len(SUM_NAMES)) with run j (0 … runs − 1) in group
        (offset + j) mod G, as the compiled kernel forms them (``core.filters.compiled``'s
        ``TermsRequest``). ``offset`` must be the runs already counted at each of these scans
        (so the runs are dealt to the groups as ``add`` deals them). The scan's totals are
        the group sums added up."""
        self._flush()
        k = sums.shape[1]
        if sums.shape != (BAND_GROUPS, k, len(SUM_NAMES)) or first + k > self.steps:
            raise ValueError(
                f"group sums must be ({BAND_GROUPS}, K, {len(SUM_NAMES)}) for scans within "
                f"0 … {self.steps - 1}, got {sums.shape} from scan {first}"
            )
        span = slice(first, first + k)
        if np.any(self.runs[span] != offset):
            raise ValueError(
                f"offset {offset} is not the runs counted at scans {first} … {first + k - 1}"
            )
        self.group_runs[:, span] += group_counts(offset, runs)[:, None]
        self.runs[span] += runs
        part = np.moveaxis(sums, 2, 0)  # (len(SUM_NAMES), G, K)
        self._group_sums[:, :, span] += part
        self._sums[:, span] += part.sum(axis=1)

    def _flush(self) -> None:
        """Turn the staged scans into sums."""
        k = len(self._staged)
        if k:
            xs, ps, ts = self._stage
            terms = scan_terms(xs[:k], ps[:k], ts[:k])
            self._add_sums(self._staged, terms.sum(axis=-1))
            self._add_group_sums(self._staged, self._offsets, terms)
            self._staged = []
            self._offsets = []

    def _add_sums(self, scans: list[int], sums: NDArray[np.float64]) -> None:
        for i, n in enumerate(scans):  # one scan at a time: the order of the additions is kept
            self._sums[:, n] += sums[:, i]

    def _add_group_sums(
        self, scans: list[int], offsets: list[int], terms: NDArray[np.float64]
    ) -> None:
        # One ``group_sums`` per distinct offset mod G (one in all, for a single block).
        residues = np.asarray(offsets) % BAND_GROUPS
        where = np.asarray(scans)
        for r in np.unique(residues):
            idx = np.flatnonzero(residues == r)
            part = group_sums(terms[:, idx], int(r))  # (G, len(SUM_NAMES), len(idx))
            np.add.at(self._group_sums, (slice(None), slice(None), where[idx]), part.swapaxes(0, 1))

    def to_arrays(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """The state as plain arrays: runs (N,) and sums (len(SUM_NAMES), N), copies.

        This is what a sweep chunk ships between processes and stores on disk; the arrays
        round-trip exactly, so ``from_arrays(*a.to_arrays())`` merges bit for bit like ``a``.
        """
        self._flush()
        return self.runs.copy(), self._sums.copy()

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
        acc._sums[:] = sums
        acc.group_runs[:] = 0  # the group sums are not shipped: no bands (``has_groups``)
        return acc

    @property
    def has_groups(self) -> bool:
        """Whether every run is in the group sums (false after ``from_arrays``), so that
        ``leave_one_out`` is defined."""
        return bool(np.array_equal(self.group_runs.sum(axis=0), self.runs))

    def merge(self, other: MetricsAccumulator) -> None:
        """Add another accumulator's sums (same N) into this one."""
        self._flush()
        other._flush()
        self._sums += other._sums
        self.runs += other.runs
        self.group_runs += other.group_runs
        self._group_sums += other._group_sums

    def result(self) -> TrackMetrics:
        """The per-scan statistics; NaN at scans no run reached (e.g. before a track start)."""
        self._flush()
        return metrics_from_sums(self.runs, self._sums)

    def leave_one_out(self) -> TrackMetrics:
        """The statistics with each group left out in turn: every field (G, N), NaN where the
        group holds no run (or the sums hold no groups, see ``has_groups``). With ``result()``
        this is what ``core.confidence.jackknife_band`` needs."""
        self._flush()
        runs = self.runs[None, :] - self.group_runs
        if not self.has_groups:
            runs = np.zeros_like(runs)
        loo = metrics_from_sums(runs, self._sums[:, None, :] - self._group_sums)
        empty = self.group_runs == 0
        return TrackMetrics(*(np.where(empty, np.nan, f) for f in loo))

    def band95(self, name: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The 95% Monte Carlo band (lo, hi) per scan of the ``TrackMetrics`` field ``name``
        (e.g. ``"rmse_x_m"``, ``"bias_range_m"``, ``"nees_pos"``): the delete-a-group jackknife
        (``core.confidence``). NaN where it is undefined."""
        return jackknife_band(getattr(self.result(), name), getattr(self.leave_one_out(), name))


def metrics_from_sums(runs: NDArray[np.int64], sums: NDArray[np.float64]) -> TrackMetrics:
    """``TrackMetrics`` from run counts (..., N) and running sums (len(SUM_NAMES), ..., N)
    (module docstring); NaN where no run counted."""
    m = runs.astype(np.float64)
    m[m == 0] = np.nan
    s = dict(zip(SUM_NAMES, sums, strict=True))
    with np.errstate(invalid="ignore", divide="ignore"):
        bias_x_m = s["ex"] / m
        # Sample variance from the sums; clip tiny negative values left by rounding.
        var_x = np.maximum(s["ex2"] - s["ex"] * bias_x_m, 0.0) / (m - 1.0)
        return TrackMetrics(
            sigma_x_filter_m=np.sqrt(s["pxx"] / m),
            rmse_x_m=np.sqrt(s["ex2"] / m),
            std_x_m=np.sqrt(var_x),
            bias_x_m=bias_x_m,
            rmse_y_m=np.sqrt(s["ey2"] / m),
            sigma_y_filter_m=np.sqrt(s["pyy"] / m),
            bias_range_m=s["er"] / m,
            bias_cross_m=s["ec"] / m,
            nees_pos=s["nees_pos"] / m,
            nees_state=s["nees_state"] / m,
        )


def nees_band(dof: int, runs: int, level: float = 0.95) -> tuple[float, float]:
    """Two-sided probability-``level`` band of the run-averaged NEES of a consistent filter.

    M · NEES_avg ~ χ²(M · dof)  (Bar-Shalom, Li, Kirubarajan 2001, sec. 5.4.2).

    The quantiles are ``scipy.stats.chi2.ppf``'s arithmetic without importing scipy.stats
    (``core.confidence.chi2_ppf``).
    """
    tail = (1.0 - level) / 2.0
    lo, hi = chi2_ppf([tail, 1.0 - tail], runs * dof) / runs
    return float(lo), float(hi)


def delta_percent(
    candidate: NDArray[np.float64], reference: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Prosov's Δx(n) = (σ̂_candidate − σ̂_reference) / σ̂_reference, in percent."""
    return 100.0 * (candidate - reference) / reference
