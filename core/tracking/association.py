"""Association of unlabelled plots: global nearest neighbour (GNN) with M-of-N confirmation.

The scheme of Blackman and Popoli (1999): a χ² gate, one optimal assignment per scan, M-of-N
confirmation of tentative tracks and deletion after consecutive misses.

A measurement file without a ``target`` column may still hold many targets, and clutter.
``GNNTracker`` decides, scan by scan, which plot belongs to which track, and hands the plots,
labelled with their track ids, to a ``core.tracking.targets.TargetTracker``: the filters are
the engine's own (prediction, update, IMM), nothing is filtered here.

* **Scans.** A scan is a run of consecutive plots (in file order) of one radar whose times lie
  within ``scan_window_s`` of the run's first plot (``scan_groups``); the default window 0
  groups the plots of one radar that share a time stamp. A track takes at most one plot per
  scan, and a track with none in a scan has missed it. A radar whose plots carry each its own
  time stamp needs a window of about one revolution, else every plot is a scan of its own and
  every track misses most scans.
* **Gate.** Each live track is predicted to each plot's time by the *gating method*
  (``AssociationOptions.method``, default ``ucm``: a converted-measurement method whose
  covariance is consistent at the measurement) and the plot is scored by the Mahalanobis
  distance of its innovation,

      d² = νᵀ S⁻¹ ν,   S = H P⁻ Hᵀ + R,

  exactly the statistic the consistency monitor takes of the method's update
  (``core.filters.measurement.PlotMeasurement.innovation``; for ``ekf``/``ukf`` the polar
  innovation; for the IMM the combined prediction). The position alone gates (Doppler, when
  present, is used by the update but not by the gate), so d² ~ χ²(d) for the track's own
  plot, d = 2 or 3, and the gate is d² < γ with γ = F⁻¹_χ²(d)(P_G) (``gate_threshold``): the
  track's own plot is inside it with probability P_G.
* **Assignment.** Per scan, the assignment of plots to tracks maximises Σ (γ − d²) over the
  assigned pairs, pairs outside the gate excluded (``gnn_assign``: one
  ``scipy.optimize.linear_sum_assignment`` on the costs d² − γ; a pair of cost 0 is "not
  assigned", so leaving a track unassigned costs γ, the gate's edge). Confirmed tracks are
  assigned first, then tentative tracks on the plots left: a fresh track's wide gate (its
  velocity is still ±σv0) would otherwise take a confirmed track's plot whenever its d² is
  the smaller one, since d² does not penalise a wide S.
* **Sparse route** (the default; ``GNNTracker(dense=True)`` is the dense one, the same
  assignment). Only pairs that can pass the gate are scored: d² ≥ ν_i² / S_ii on every
  axis, so a coarse box around each track's predicted position, ν_i² < γ S_ii, holds
  every pair inside the gate (exact for the converted methods whose conversion is of the
  plot alone, ``boxed``; ``ducm``, ``ekf`` and ``ukf`` score every pair). A batch of a few
  plots (``NEAR_MAX_PAIRS``) tests each (track, plot) pair against a bound of that box taken
  from the track's posterior at its last plot, without predicting it (``GNNTracker.near``,
  one compiled pass: the mean x + T ẋ and P_pp + 2T P_pv + T² P_vv + q̄ T⁴/4 ≥ P⁻_ii, T the
  time to the plot), so that a batch's cost follows its candidates, not the live tracks. A
  whole scan of many targets instead boxes every track between its predictions to the
  scan's first and last times (the prediction is affine in the mean and convex in P_ii over
  time) and finds the pairs in the boxes with a k-d tree of the plots (``gate_box_pairs``).
  Either way each candidate is predicted to its plot's own time (``TargetTracker.predicted``)
  and scored (``mahalanobis_pairs``). The pairs inside the gate form a bipartite graph;
  Σ (γ − d²) is a sum over its connected components and no feasible assignment links two of
  them, so the global optimum is each component's own: one dense assignment per
  component, none for a pair that shares no track and no plot (``sparse_gnn_assign``, the
  compiled route's own function), the same optimum as the dense matrix's.
* **Engines.** The filters and the gate's predictions run on the engine the options ask
  for (``StreamOptions.engine``): the compiled one by default, whose
  ``core.tracking.compiled.CompiledTracks`` predicts a list of tracks with the tracker
  kernels' own steps (``predicted``) and drops deleted ones (``forget``), or
  ``engine="numpy"``, the reference; the two make the same association
  (``tests/test_association_engines.py``).
* **Initiation.** Every plot left unassigned starts a tentative track (the first-plot start).
* **Confirmation, M of N.** A tentative track is confirmed at the scan of its M-th hit if
  that comes within its first N scans (the initiating scan counts as the first, and a hit);
  it is deleted as soon as that has become impossible, hits + scans left < M. No separate
  miss count is needed for tentative tracks: M-of-N deletes them after N − M + 1 misses.
* **Deletion.** A confirmed track is deleted after ``delete_misses`` consecutive misses.

Every requested method's tracks follow the one assignment the gating method made, so the
methods are compared on identical plot-to-track data; the gating method's own tracks are kept
beside them (in a tracker of their own, unmonitored, when it is not among the methods).
Track ids are "1", "2", … in order of initiation, never reused.

Cost: the dense route scores K × P pairs per scan for K live tracks and P plots (one
broadcast batch per distinct plot time, each track predicted to each time) and runs one
assignment, O((K + P)³) at worst. The sparse route tests K × P pairs in compiled code for a
small batch (a few nanoseconds each), or predicts every track twice and builds one k-d tree
(O((K + P) log P)) for a whole scan, then scores and predicts only the candidates, a few
per track when the targets are apart, and assigns the small components; the per-batch
bookkeeping (the sweep, M of N) is numpy over the live tracks, no Python loop over them.
``radarviz bench --only association`` measures both layouts: the grid of targets seen by
one radar in whole scans (``viz_app.bench.association``), and four rotating radars whose
plots come a few at a time (the ``rotating_*`` figures, plots per CPU-second).

* **The compiled route.** For 2D plots, the IMM, a ``boxed`` gating method and the sparse
  assignment on the compiled engine (``core.tracking.association_compiled.eligible``), the
  whole batch loop above runs in one compiled call over many batches
  (``core.tracking.kernels_associate``, ``add_batches``: a batch of a few plots costs no
  Python), on the same book and beam arrays; the requested methods' tracks then filter the
  call's labelled plots in one block. The Python route (``_add``) is the reference on the
  numpy engine, and the two give every plot the same track
  (``tests/test_association_kernel.py``).
"""

from __future__ import annotations

import contextlib
import gc
import heapq
import math
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple, TypeVar

import numpy as np
from numpy.typing import NDArray

from radarviz.core.chi2 import chi2_quantile
from radarviz.core.filters.innovation import position_innovation
from radarviz.core.filters.methods import (
    METHODS,
    PLAN_COVARIANCE,
    Kind,
    MethodGroup,
    PolarNoise,
    PolarPlot,
    method_names,
    method_plan,
    stack_parts,
    update_coefficients,
)
from radarviz.core.filters.state import CVBatch, position_index
from radarviz.core.geometry import direction_cosines
from radarviz.core.params import ParameterError, check, check_choice, default
from radarviz.core.tracking.association_compiled import CompiledAssociation, eligible
from radarviz.core.tracking.coverage import (
    EDGE_FRACTION,
    MAX_MARGIN_RAD,
    MIN_MARGIN_RAD,
    BeamTable,
    RadarBeam,
    RadarCoverage,
)
from radarviz.core.tracking.management import CONFIRMED_CODE, TENTATIVE_CODE, TrackBook
from radarviz.core.tracking.stream import (
    Plot,
    PlotError,
    StateRow,
    StateRows,
    StreamOptions,
    polar_arrays,
)
from radarviz.core.tracking.targets import TargetTracker

#: ``track --associate``: none (today's: one target, or the file's target labels) or gnn.
ASSOCIATE_MODES: tuple[str, ...] = ("none", "gnn")
TENTATIVE = "tentative"
CONFIRMED = "confirmed"

T = TypeVar("T")


@dataclass(frozen=True)
class AssociationOptions:
    """How ``GNNTracker`` associates (module docstring; parameters of ``core.params``).

    Attributes:
        method: the gating method, whose prediction scores the plots.
        gate_probability: P_G, in (0, 1).
        confirm_m, confirm_n: M of the first N scans confirm a tentative track (M ≤ N).
        delete_misses: consecutive misses that delete a confirmed track.
        scan_window_s: plots of one radar within this time of a batch's first plot join it
            (s); None: batches by radar and azimuth sector (``plot_batches``).
        batch_sector_deg: the azimuth sector of a batch without ``scan_window_s`` (deg).
        max_speed_mps: the fastest target: a track of one plot takes no plot it could only
            reach faster (``GNNTracker._too_fast``), m/s.
    """

    method: str = "ucm"
    gate_probability: float = default("gate_probability")
    confirm_m: int = default("confirm_m")
    confirm_n: int = default("confirm_n")
    delete_misses: int = default("delete_misses")
    scan_window_s: float | None = None
    batch_sector_deg: float = default("batch_sector_deg")
    max_speed_mps: float = default("max_speed_mps")

    def __post_init__(self) -> None:
        check_choice("associate_method", self.method, method_names())
        check("gate_probability", self.gate_probability)
        check("confirm_m", self.confirm_m)
        check("confirm_n", self.confirm_n)
        check("delete_misses", self.delete_misses)
        if self.scan_window_s is not None:
            check("scan_window_s", self.scan_window_s)
        check("batch_sector_deg", self.batch_sector_deg)
        check("max_speed_mps", self.max_speed_mps)
        if self.confirm_m > self.confirm_n:
            raise ParameterError(
                f"confirm_m must be at most confirm_n = {self.confirm_n} (M of N scans; got "
                f"{self.confirm_m})",
                "confirm_m",
            )


#: A status code's name (``_add_batches``).
_STATUS_NAMES = np.array([TENTATIVE, CONFIRMED], dtype=object)


@contextlib.contextmanager
def cycle_collector_paused() -> Iterator[None]:
    """Python's cycle collector paused for the block, and restored after it.

    A call of ``add_batches`` builds and drops tens of thousands of small acyclic objects (a
    plot's rows, a batch's results), which reference counting frees as they go; each of them
    also counts towards the collector's next pass, and its passes over the older generations
    walk every object the process holds (the modules of numba, scipy, Rerun): a third of the
    association's time at 1000 targets, for no garbage.
    """
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def gate_threshold(gate_probability: float, dof: int) -> float:
    """γ with P(χ²(dof) < γ) = P_G: the gate of a d-dimensional position innovation."""
    return chi2_quantile(gate_probability, dof)


def scan_groups(items: Iterable[tuple[T, Plot]], window_s: float) -> Iterator[list[tuple[T, Plot]]]:
    """Cut (key, plot) pairs, in file order, into scans: runs of consecutive plots of one
    radar whose times are within ``window_s`` of the run's first plot (module docstring)."""
    scan: list[tuple[T, Plot]] = []
    for item in items:
        p = item[1]
        if scan and (p.radar != scan[0][1].radar or p.time_s - scan[0][1].time_s > window_s):
            yield scan
            scan = []
        scan.append(item)
    if scan:
        yield scan


#: How late a plot may come in a feed and still be put back in time order (s): a merged feed
#: of several radars (packets of each radar in order, the radars interleaved as the network
#: delivers them) is out of order by a packet or two, well under a second.
REORDER_S = 5.0


class LatePlotError(PlotError):
    """A plot too late to be put back in time order (``time_ordered``); ``key`` is its
    pair's key (the reader's position of the plot)."""

    def __init__(self, key: object, message: str):
        super().__init__("time_s", message)
        self.key = key


def time_ordered(
    items: Iterable[tuple[T, Plot]], horizon_s: float | Callable[[], float] = REORDER_S
) -> Iterator[tuple[T, Plot]]:
    """(key, plot) pairs put back in time order: each is held until a plot ``horizon_s``
    later has come, then released earliest first (ties in arrival order). A plot earlier
    than one already released is a ``LatePlotError``: it came more than ``horizon_s`` late.
    ``horizon_s`` may be a function, read at every plot (a horizon that adapts to the feed,
    ``radarviz live``'s; it must never shrink, or a plot let in could be refused)."""
    horizon = horizon_s if callable(horizon_s) else lambda: horizon_s
    heap: list[tuple[float, int, tuple[T, Plot]]] = []
    released = -math.inf
    for n, item in enumerate(items):
        t = item[1].time_s
        if t < released:
            raise LatePlotError(
                item[0],
                f"a plot {released - t:.3g} s earlier than one already tracked: more than "
                f"{horizon():g} s out of time order",
            )
        heapq.heappush(heap, (t, n, item))
        h = horizon()
        while heap and heap[0][0] <= t - h:
            released, _, out = heapq.heappop(heap)
            yield out
    while heap:
        yield heapq.heappop(heap)[2]


#: Longest time span of a batch cut by sector (s): one radar's sector is swept in a fraction
#: of a revolution, and a plot in the same sector a revolution later starts a new batch.
MAX_BATCH_SPAN_S = 0.5


def plot_batches(
    items: Iterable[tuple[T, Plot]], sector_deg: float
) -> Iterator[list[tuple[T, Plot]]]:
    """Cut (key, plot) pairs, in time order, into the association's batches: runs of
    consecutive plots of one radar in one azimuth sector of ``sector_deg`` (sectors counted
    from azimuth 0) within ``MAX_BATCH_SPAN_S`` of the batch's first plot, or sharing its time
    stamp (a scan-stamped radar's scan is one batch). Within a batch a track takes at most
    one plot, and the assignment is optimal (module docstring)."""
    width = math.radians(sector_deg)
    batch: list[tuple[T, Plot]] = []
    first: Plot | None = None
    sector = 0
    for item in items:
        p = item[1]
        s = int((p.azimuth_rad % (2 * math.pi)) // width)
        if first is not None and (
            p.radar != first.radar
            or (
                p.time_s != first.time_s
                and (s != sector or p.time_s - first.time_s > MAX_BATCH_SPAN_S)
            )
        ):
            yield batch
            batch, first = [], None
        if first is None:
            first, sector = p, s
        batch.append(item)
    if batch:
        yield batch


def mahalanobis_matrix(
    method: str,
    predicted: CVBatch,
    plot: PolarPlot,
    noise: PolarNoise,
    site: NDArray[np.float64],
) -> NDArray[np.float64]:
    """d² = νᵀ S⁻¹ ν of every plot against every predicted track: (K, P).

    Args:
        method: the gating method (its measurement: ``MethodGroup.measurement``).
        predicted: K tracks predicted to the plots' time, x (K, n), P (K, n, n).
        plot, noise: P plots' polar values and noise std, (P,) arrays.
        site: (P, d) each plot's radar.

    The K × P pairs are one batch of shape (K, P): each track's prediction broadcast along
    the plots, each plot along the tracks (``_mahalanobis``). A broken track's d² (NaN) is
    outside every gate.
    """
    k, n = predicted.x.shape
    p = np.size(plot.range_m)
    x = np.broadcast_to(predicted.x[:, None, :], (k, p, n))
    P = np.broadcast_to(predicted.P[:, None, :, :], (k, p, n, n))
    return _mahalanobis(method, CVBatch(x, P), plot, noise, site)


def mahalanobis_pairs(
    method: str,
    predicted: CVBatch,
    plot: PolarPlot,
    noise: PolarNoise,
    site: NDArray[np.float64],
) -> NDArray[np.float64]:
    """d² = νᵀ S⁻¹ ν of N (track, plot) pairs, pair i the i-th prediction and the i-th plot:
    (N,) (the statistic of ``mahalanobis_matrix``, elementwise the same numbers).

    Args:
        method: the gating method.
        predicted: the pairs' tracks predicted to their plots' times, x (N, n), P (N, n, n).
        plot, noise: the pairs' plots, (N,) arrays.
        site: (N, d) each pair's radar.
    """
    return _mahalanobis(method, predicted, plot, noise, site)


def _mahalanobis(
    method: str,
    state: CVBatch,
    plot: PolarPlot,
    noise: PolarNoise,
    site: NDArray[np.float64],
) -> NDArray[np.float64]:
    """d² of a batch of predictions, x (*B, n), against plots broadcastable to B.

    ν and R are the method's measurement (``MethodGroup.measurement``, what its update and
    ``PlotMeasurement.innovation`` use), d² its NIS (``core.filters.innovation.
    position_innovation``); d² ≥ γ, or NaN → ∞, for an S not positive definite.
    """
    group = MethodGroup((method,))
    shape = state.x.shape[:-1]
    parts = None
    x, P = state.x, state.P
    if group.converted:
        x, P = x[None], P[None]  # the group's method axis
        if not METHODS[method].about_prediction:
            # One conversion per plot, broadcast over the tracks (``ducm`` converts per pair).
            parts = stack_parts([group.kinds[0].convert(plot, noise)])
    if parts is None:
        plot = PolarPlot(*(None if v is None else np.broadcast_to(v, shape) for v in plot))
    batch = CVBatch(x, P)
    nu, R = group.measurement(batch, plot, noise, site=site, parts=parts)
    d2 = position_innovation(batch, nu, R).nis.reshape(shape)  # NaN: S not positive definite
    return np.where(np.isfinite(d2), d2, np.inf)


def boxed(method: str) -> bool:
    """Whether the gating method's gate has an exact coarse box (``gate_box_pairs``): a
    converted method whose conversion is of the plot alone, so that ν = z + s − H x⁻ with z
    and R the plot's own (``ducm``'s R and the polar methods' ν', R' depend on the pair)."""
    m = METHODS[method]
    return m.kind == Kind.CONVERTED and not m.about_prediction


#: Motion models (``StreamOptions.model``; the IMM when its models are all constant-velocity
#: ones, no turn rate) whose prediction has a mean affine and a P⁻_ii
#: convex in the time (``gate_box_pairs``): one box per scan, from its first and last time.
#: Any other model is boxed at each distinct plot time (``GNNTracker.pairs``).
INTERVAL_MODELS: tuple[str, ...] = ("cv", "imm")

#: Track × plot pairs up to which a batch's candidates come from ``GNNTracker.near`` (one
#: compiled test per pair, a few ns each); a larger batch (a whole scan of 10³ targets)
#: takes ``GNNTracker.pairs``' k-d tree, O((K + P) log P). The same pairs inside the gate.
NEAR_MAX_PAIRS = 1 << 18

#: Relative widening of ``GNNTracker.near``'s bound on the gate's box (on γ): its bound
#: takes another route through the arithmetic than the prediction (and the IMM's is not
#: tight), so it is widened well beyond rounding; the exact box follows it.
PREFILTER_MARGIN = 1.01

#: Plots below which ``gate_box_pairs`` tests every pair's box at once instead of querying a
#: k-d tree once per track (a small batch against many tracks).
TREE_MIN_PLOTS = 64

#: Relative widening of the coarse box: d² is computed in floating point, the box's bound
#: d² ≥ ν_i² / S_ii holds for exact numbers; 1e-6 covers rounding many times over.
BOX_MARGIN = 1e-6


def gate_box_pairs(
    method: str,
    early: CVBatch,
    late: CVBatch,
    plot: PolarPlot,
    noise: PolarNoise,
    site: NDArray[np.float64],
    gate: float,
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The (track, plot) pairs (rows into the tracks, columns into ``plot``) that can pass
    the gate d² < γ, each track predicted to its plot's time: every pair that does, and
    usually few more.

    Args:
        method: a gating method with ``boxed(method)``.
        early, late: K tracks predicted to the first and the last of the plots' times
            (the same batch when the plots share one time), x (K, n), P (K, n, n).
        plot, noise: P plots' polar values and noise std, (P,) arrays.
        site: (P, d) each plot's radar.
        gate: γ.

    For any symmetric positive definite S and any axis i, νᵀ S⁻¹ ν ≥ ν_i² / S_ii (the
    minimum of νᵀ S⁻¹ ν over ν with a given ν_i), so d² < γ implies ν_i² < γ S_ii on every
    axis. With ν = z + s − H x⁻(t) (the plot's converted point z at its site s, ``boxed``) and
    S_ii = P⁻_ii(t) + R_ii, the pair is inside the box (z_i + s_i − x⁻_i(t))² < γ (P⁻_ii(t)
    + R_ii). Between the first and the last plot time the prediction of the engine's motion
    models (constant velocity, and the IMM's combination of constant-velocity models,
    ``core.filters.models``) has a mean affine in the time and a P⁻_ii convex in it (T ≥ 0:
    P_pp + 2T P_pv + T² P_vv + q T⁴/4, and the IMM's spread of means, squares of affine
    functions), so over the scan x⁻_i(t) lies between its two end values and P⁻_ii(t) is at
    most the larger of its two: the box around the segment between the two predicted
    positions, of half-width √(γ (max P⁻_ii + R_ii)), holds every pair inside the gate at
    its own time. Exact: no pair the dense ``mahalanobis_matrix`` would accept is lost.

    The pairs are found by a ``scipy.spatial.cKDTree`` of the plots' points queried per track
    (Chebyshev norm) with the box's largest half-reach over the largest R_ii of the plots,
    then the box itself with each plot's own R_ii. Cost O((K + P) log P + candidates).
    """
    from scipy.spatial import cKDTree

    empty = np.zeros(0, dtype=np.intp)
    k = early.x.shape[0]
    if not k or not np.size(plot.range_m):
        return empty, empty
    z, R = METHODS[method].convert(plot, noise)
    dims = len(z)
    pos = position_index(dims)
    points = np.stack([np.asarray(z[i]) + site[..., i] for i in range(dims)], -1)  # (P, d)
    r_ii = np.stack([np.broadcast_to(R[i, i], points.shape[:1]) for i in range(dims)], -1)
    lo = np.minimum(early.x[:, pos], late.x[:, pos])  # (K, d)
    hi = np.maximum(early.x[:, pos], late.x[:, pos])
    p_ii = np.maximum(early.P[:, pos, pos], late.P[:, pos, pos])  # (K, d)
    scale = gate * (1.0 + BOX_MARGIN) ** 2
    centre = 0.5 * (lo + hi)
    with np.errstate(invalid="ignore"):
        reach = (0.5 * (hi - lo) + np.sqrt(scale * (p_ii + r_ii.max(axis=0)))).max(axis=1)
    ok = np.flatnonzero(np.isfinite(reach) & np.all(np.isfinite(centre), axis=1))
    good = np.flatnonzero(np.all(np.isfinite(points), axis=1))
    if not ok.size or not good.size:
        return empty, empty
    if good.size <= TREE_MIN_PLOTS:
        # A few plots against many tracks: every pair's Chebyshev distance at once (the
        # pairs the tree would find, without a query per track).
        far = np.abs(points[good][None, :, :] - centre[ok][:, None, :]).max(axis=2)
        r_i, c_i = np.nonzero(far <= reach[ok][:, None])
        rows, cols = ok[r_i], good[c_i]
    else:
        found = cKDTree(points[good]).query_ball_point(centre[ok], reach[ok], p=np.inf)
        counts = np.fromiter((len(f) for f in found), dtype=np.intp, count=ok.size)
        rows = np.repeat(ok, counts)
        if not rows.size:
            return empty, empty
        cols = good[np.concatenate([np.asarray(f, dtype=np.intp) for f in found])]
    if not rows.size:
        return empty, empty
    zc = points[cols]
    outside = np.maximum(np.maximum(lo[rows] - zc, zc - hi[rows]), 0.0)  # beyond the segment
    inside = np.all(outside * outside < scale * (p_ii[rows] + r_ii[cols]), axis=1)
    return rows[inside], cols[inside]


def gnn_assign(d2: NDArray[np.float64], gate: float) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The global-nearest-neighbour assignment: (track rows, plot columns) of the pairs that
    maximise Σ (γ − d²) over pairs inside the gate d² < γ (module docstring).

    One ``linear_sum_assignment`` on the costs min(d² − γ, 0): every pair outside the gate
    costs 0, the same as leaving both unassigned, and is dropped from the result.
    """
    from scipy.optimize import linear_sum_assignment

    if d2.size == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    cost = np.minimum(d2 - gate, 0.0)
    rows, cols = linear_sum_assignment(cost)
    keep = cost[rows, cols] < 0.0
    return rows[keep], cols[keep]


def sparse_gnn_assign(
    rows: NDArray[np.intp],
    cols: NDArray[np.intp],
    d2: NDArray[np.float64],
    gate: float,
    shape: tuple[int, int],
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """``gnn_assign`` of a sparse d² matrix: (track rows, plot columns) of the assignment,
    in increasing row order.

    Args:
        rows, cols, d2: (N,) the scored pairs, each (track, plot) at most once; a pair not
            listed is outside the gate (d² = ∞).
        gate: γ.
        shape: (K, P), the dense matrix's shape.

    The pairs inside the gate are the edges of a bipartite graph of K tracks and P plots.
    The objective Σ (γ − d²) over the assigned pairs is a sum over the graph's connected
    components, and an assignment is feasible if and only if it is feasible within each
    component (no edge joins two), so the global optimum is the union of each component's
    own optimum: one assignment on each component's small dense matrix (a missing pair
    costs 0, as in ``gnn_assign``), and none for a component of one edge (its pair is
    assigned). The optimum is ``gnn_assign``'s; where the optimum is not unique (ties) the
    two may pick different optimal assignments. Computed by the compiled route's own
    function (``core.tracking.kernels_associate.sparse_assign``: the components by a
    union-find, each one's assignment by ``lsap``), so that both routes assign alike.
    """
    from radarviz.core.tracking.kernels_associate import sparse_assign

    n = int(rows.size)
    out_r, out_c = np.empty(n, np.int64), np.empty(n, np.int64)
    found = sparse_assign(
        np.ascontiguousarray(rows, dtype=np.int64), np.ascontiguousarray(cols, dtype=np.int64),
        np.ascontiguousarray(d2, dtype=np.float64), float(gate), int(shape[0]),
        int(shape[1]), out_r, out_c,
    )  # fmt: skip
    order = np.argsort(out_r[:found], kind="stable")
    return out_r[:found][order].astype(np.intp), out_c[:found][order].astype(np.intp)


class ScanResult(NamedTuple):
    """What one batch (or scan) did.

    Attributes:
        track_ids: (P,) per plot of the batch, the id of the track it went to.
        statuses: (P,) that track's status after the batch.
        rows: per plot, (method, x (6,), P (6, 6)) for every requested method (each plot's
            row made when read, ``core.tracking.stream.StateRows``).
        confirmed: ids of the tracks confirmed at this batch.
        deleted: ids of the tracks deleted at this batch.
    """

    track_ids: list[str]
    statuses: list[str]
    rows: Sequence[list[StateRow]]
    confirmed: list[str]
    deleted: list[str]


class AssociationReport(NamedTuple):
    """The association's account of a run.

    Attributes:
        plots: per radar (by name, in order of its first plot) its plots in tracks confirmed
            (now or before their deletion), in tracks still tentative, and in tracks deleted
            without ever being confirmed (keys ``confirmed``, ``tentative``, ``never``).
        estimated: per radar, what the radars file did not give and was estimated from its
            plots (``core.tracking.coverage.RadarBeam.estimated``; SI units).
        scan_stamped: per radar, whether its plots of a scan share one time stamp.
        started, confirmed: tracks started and confirmed in all.
    """

    plots: dict[str, dict[str, int]]
    estimated: dict[str, dict[str, float | None]]
    scan_stamped: dict[str, bool]
    started: int
    confirmed: int


@dataclass
class _Gate:
    method: str
    threshold: float
    tracker: TargetTracker = field(repr=False)


class GNNTracker:
    """Tracks of many targets from unlabelled plots: GNN association, M-of-N confirmation.

    Args:
        methods: the filters whose tracks are returned (every one follows the association).
        three_d: plots carry elevations.
        options: the filters' ``StreamOptions`` (first-plot start; the monitor sees the
            requested methods' tracks, named ``track_name(id, method)``).
        association: ``AssociationOptions``.
        dense: score every track against every plot and assign on the whole matrix
            (``distances``, ``gnn_assign``: the reference route, the same assignment) instead
            of the coarse box and the per-component assignment (``pairs``,
            ``sparse_gnn_assign``).
        coverage: each radar's coverage (``core.tracking.coverage``), by name.
        keep_confirmed: keep the id of every track confirmed (``ever_confirmed``), for a
            file's account; False for a session that runs for hours (``radarviz live``),
            whose memory must not grow with the tracks it confirms: it keeps their number
            (``tracks_confirmed``) only.
    """

    def __init__(
        self,
        methods: tuple[str, ...],
        three_d: bool,
        options: StreamOptions,
        association: AssociationOptions,
        dense: bool = False,
        coverage: Mapping[str, RadarCoverage] | None = None,
        keep_confirmed: bool = True,
    ):
        self.methods = tuple(methods)
        self.dense = dense
        # A turn model's predicted mean follows an arc, not a segment: no box between times.
        rates = options.imm_turn_rate_degps or () if options.model == "imm" else ()
        self._interval = options.model in INTERVAL_MODELS and not any(rates)
        motion = options.motion()
        # q̄ and ω̄ of ``near``: the largest σa² of the motion model('s models), and the
        # largest turn rate of the IMM's models (rad/s).
        self._q_max = float(np.max(np.square(motion.sigma_a_mps2)))
        self.model = options.model
        self._omega_max = math.radians(max((abs(float(w)) for w in rates), default=0.0))
        self.association = a = association
        dims = 3 if three_d else 2
        self.dims = dims
        compiled = eligible(options, three_d, boxed(a.method), dense)
        # The gate reads predictions and deletes tracks (TargetTracker.predicted, forget) on
        # either engine: the compiled one (the default) runs the kernels' own prediction,
        # ``engine="numpy"`` the reference. On the compiled route the association filters
        # every plot itself, once, in the tracker's rows: the gating method is one of the
        # tracker's methods (after the requested ones, unreported, when not requested).
        if a.method in self.methods:
            self.tracker = gate_tracker = TargetTracker(self.methods, three_d, options)
        elif compiled:
            self.tracker = gate_tracker = TargetTracker(
                (*self.methods, a.method), three_d, options, reported=len(self.methods)
            )
        else:
            self.tracker = TargetTracker(self.methods, three_d, options)
            gate_tracker = TargetTracker((a.method,), three_d, _without_monitor(options))
        self._gate = _Gate(a.method, gate_threshold(a.gate_probability, dims), gate_tracker)
        self.book = TrackBook(a.confirm_m, a.confirm_n, a.delete_misses, 2 * dims)
        self._coverage = dict(coverage or {})
        #: Each radar's beam and coverage (``core.tracking.coverage``), by name, in order of
        #: first plot; their state rows in one table.
        self.beams: dict[str, RadarBeam] = {}
        self._table = BeamTable(0)
        self._sites: list[NDArray[np.float64]] = []
        self._started = 0
        #: Batches (and scans) associated so far.
        self.batches = 0
        #: Ids of every track confirmed so far, in order of confirmation (``keep_confirmed``;
        #: empty otherwise), and their number.
        self.ever_confirmed: list[str] = []
        self.tracks_confirmed = 0
        self.keep_confirmed = keep_confirmed
        #: The compiled route (``core.tracking.association_compiled``), or None: the Python
        #: route of ``_add``.
        self._compiled: CompiledAssociation | None = None
        if compiled:
            tracks = self.tracker.compiled
            assert tracks is not None
            self._compiled = CompiledAssociation(
                a.method, tracks, self.gate, self.gate * PREFILTER_MARGIN, self._q_max,
                self._omega_max, a, self.book, self._table,
            )  # fmt: skip

    def retune(self, options: StreamOptions, association: AssociationOptions) -> None:
        """Take ``options`` and ``association`` from the next batch on, every track kept.

        What can change so: the gate probability P_G (γ and the prefilter's scale follow),
        the M-of-N confirmation and the deletion rule (a track's counts so far are kept and
        judged by the new rule), the fastest target, and the motion model's σa (``cv``: its
        σa; ``imm``: each model's σa, as many models as before: the tracks' states keep their
        shapes, the next prediction uses the new process noise). Anything else (another
        motion model, another number of IMM models, their turn rates or transitions, the
        gating method, the batches, σv0, the Doppler, the engine) changes what a track holds
        or how plots are batched: ParameterError naming it, nothing changed (a new tracker
        is then the way).
        """
        old, a = self.tracker.options, self.association
        if options.model != old.model:
            raise ParameterError(
                f"model: the tracks of {old.model!r} cannot continue as {options.model!r} "
                "(a new tracker starts them again)",
                "model",
            )
        if len(options.imm_sigma_a_mps2) != len(old.imm_sigma_a_mps2):
            raise ParameterError(
                f"imm_sigma_a_mps2: the IMM has {len(old.imm_sigma_a_mps2)} models; a σa per "
                "model keeps its tracks (another number of models starts them again)",
                "imm_sigma_a_mps2",
            )
        same = replace(
            options, sigma_a_mps2=old.sigma_a_mps2, imm_sigma_a_mps2=old.imm_sigma_a_mps2
        )
        for name in ("method", "scan_window_s", "batch_sector_deg"):
            if getattr(association, name) != getattr(a, name):
                raise ParameterError(f"{name}: cannot change while tracking", name)
        if same != old:
            raise ParameterError(
                "options: only σa changes while tracking (the rest of the filters' options "
                "is what the tracks hold)",
                "options",
            )
        threshold = gate_threshold(association.gate_probability, self.dims)
        q_max = float(np.max(np.square(options.motion().sigma_a_mps2)))
        self.tracker.retune(options)
        if self._gate.tracker is not self.tracker:
            self._gate.tracker.retune(_without_monitor(options))
        self._gate.threshold, self._q_max, self.association = threshold, q_max, association
        book = self.book
        book.m, book.n = association.confirm_m, association.confirm_n
        book.kdel = association.delete_misses
        if self._compiled is not None:
            scale = threshold * PREFILTER_MARGIN
            self._compiled.retune(threshold, scale, q_max, association)

    def reserve(self, tracks: int) -> None:
        """Room for ``tracks`` more tracks, made now: the book's slots and, on the compiled
        route, the tracker's rows (the monitor's with them). They otherwise grow by doubling
        when a call needs more (``TrackBook.reserve``: a call may start a track from every
        one of its plots), which in a session that runs for hours comes with its first
        large run, minutes in: a step of megabytes at a random time, where memory taken at
        the start stays the same. (The Python route's filters still grow with the tracks.)"""
        if self._compiled is not None:
            self._compiled.reserve(tracks)
        else:
            self.book.reserve(tracks)

    @property
    def gate(self) -> float:
        """γ, the gate on d²."""
        return self._gate.threshold

    def live(self, status: str | None = None) -> list[str]:
        """Ids of the live tracks (of one status, or all), in order of initiation."""
        if status is None:
            return list(self.book.slot)
        code = CONFIRMED_CODE if status == CONFIRMED else TENTATIVE_CODE
        label = self.book.label
        return [label[s] for s in self.book.live_slots(code).tolist()]

    def gate_points(
        self, plots: list[Plot]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The gating method's conversion of ``plots`` for ``near``: each plot's point
        z + s (P, d), its R_ii (P, d) and its time (P,) (C-contiguous); in 2D by the
        tracker kernels' conversion in one compiled pass (``plot_points_2d``), in 3D by
        ``Method.convert`` (the prefilter's margin covers the two routes' rounding)."""
        d = self.dims
        plot, noise = polar_arrays(plots, d)
        site = np.array([p.site for p in plots], dtype=np.float64)[:, :d]
        times = np.array([p.time_s for p in plots], dtype=np.float64)
        n_p = site.shape[0]
        if d == 2:  # one compiled pass, the tracker kernels' conversion
            from radarviz.core.tracking.kernels_gate import plot_points_2d

            points, r_ii = np.empty((n_p, 2)), np.empty((n_p, 2))
            sigma_r_m, sigma_beta_rad = (
                np.ascontiguousarray(np.broadcast_to(v, (n_p,))) for v in noise[:2]
            )
            method = self._gate.method
            form = int(method_plan([method])[0, PLAN_COVARIANCE])
            co = update_coefficients(method, sigma_r_m, sigma_beta_rad)
            # Contiguous arrays throughout: one compiled specialisation of the kernel.
            site_c = np.ascontiguousarray(site)
            plot_points_2d(
                form,
                co,
                plot.range_m,
                plot.azimuth_rad,
                sigma_r_m,
                sigma_beta_rad,
                site_c,
                points,
                r_ii,
            )
            return points, r_ii, times
        z, R = METHODS[self._gate.method].convert(plot, noise)
        points = np.stack([np.asarray(z[i]) + site[:, i] for i in range(d)], -1)
        r_ii = np.stack([np.broadcast_to(R[i, i], (n_p,)) for i in range(d)], -1)
        return np.ascontiguousarray(points), np.ascontiguousarray(r_ii), times

    def near(
        self,
        slots: NDArray[np.intp],
        plots: list[Plot],
        points: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] | None = None,
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """The (track, plot) pairs, rows into ``slots``, columns into ``plots``, (N,) each in
        row then column order, that may pass the gate: a conservative prefilter of the
        gate, from the book's state alone (each track's gating posterior x, P at its last
        plot, ``TrackBook``), without predicting a track. Every pair inside the gate is among
        them (``pairs`` returns no other pair inside it), and usually little else. For a
        gating method with ``boxed`` and a model in ``INTERVAL_MODELS`` (``prefiltered``).

        The bound. A track is predicted T ≥ 0 after its last plot. For the cv model the
        position on axis i is U_i = p_i + T v_i with mean c_i = x_i + T ẋ_i and variance
        Var U_i = P_pp + 2T P_pv + T² P_vv, plus the noise's q T⁴/4. For the IMM, the mixed
        initial conditions (weights c̄ⱼ) are a mixture with the combined posterior's mean and
        covariance (x, P: what the book holds), and the combined prediction is that
        mixture's moments after each component's own motion: a constant-velocity model
        moves the horizontal position by T v, a turn at ωⱼ by Aⱼ v with
        Aⱼ = ∫₀ᵀ R(ωⱼ s) ds, R the rotation. As |R(θ) − I| ≤ |θ|, |Aⱼ − T I| ≤ |ωⱼ| T²/2, so
        the predicted position is U + G + W with G = (A_J − T I) v, J the model, so
        E G_i² ≤ E|G|² ≤ δ², δ = ω̄ T²/2 · √E|v_h|² (E|v_h|² = |ẋ_h|² + tr P_vv over the
        two horizontal axes, ω̄ the largest |ωⱼ|; G = 0 on z), and W the noise, zero-mean
        given the model and the state, E W_i² ≤ q̄ T⁴/4 (q̄ the largest σa²). Hence the
        predicted mean is within |E G_i| ≤ δ of c_i, and
        P⁻_ii = Var(U_i + G_i) + E W_i² ≤ (√Var U_i + δ)² + q̄ T⁴/4 = V_i(T) (the variance
        of a sum is at most (σ₁ + σ₂)², and Var G_i ≤ E G_i² ≤ δ²). With no
        turn model δ = 0 and V_i is exact for the cv model.

        As d² ≥ ν_i² / S_ii on every axis (``gate_box_pairs``), with ν = z + s − H x⁻
        (``boxed``) and S_ii = P⁻_ii + R_ii, a pair inside the gate has
        |z_i + s_i − x⁻_i| < √(γ (P⁻_ii + R_ii)), so (|z_i + s_i − c_i| − δ)₊² < γ (V_i(T) +
        R_ii) on every axis, at its plot's own time; ``PREFILTER_MARGIN`` widens γ well
        past rounding. One compiled pass (``core.tracking.kernels_gate.near_pairs``), O(K P)
        for K tracks and P plots, no Python loop over the tracks. ``points``:
        ``gate_points(plots)``, when the caller has it.
        """
        from radarviz.core.tracking.kernels_gate import near_pairs

        g = self._gate
        points, r_ii, times = self.gate_points(plots) if points is None else points
        n_p = times.size
        book = self.book
        rows = np.empty(slots.size * n_p, dtype=np.intp)
        cols = np.empty(slots.size * n_p, dtype=np.intp)
        found = near_pairs(
            slots, book.x, book.P, book.last_s, times, self._q_max, self._omega_max,
            points, r_ii, g.threshold * PREFILTER_MARGIN, rows, cols,
        )  # fmt: skip
        return rows[:found], cols[:found]

    @property
    def prefiltered(self) -> bool:
        """Whether the sparse route's candidates come from ``near`` (a boxed gating method,
        a model in ``INTERVAL_MODELS``, turn models included) rather than ``pairs``' coarse
        box of every track."""
        return boxed(self._gate.method) and self.model in INTERVAL_MODELS

    def scored(
        self,
        slots: NDArray[np.intp],
        plots: list[Plot],
        points: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] | None = None,
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
        """``pairs`` of the tracks in the book's ``slots`` by way of ``near``: the same pairs
        inside the gate, each pair's track predicted to its plot's own time
        (``TargetTracker.predicted``) and scored (``mahalanobis_pairs``), the same numbers.
        (rows into slots, columns into plots, d²), (N,) each."""
        g = self._gate
        r, c = self.near(slots, plots, points)
        if not r.size:
            return r, c, np.zeros(0)
        sub = [plots[j] for j in c.tolist()]
        plot, noise = polar_arrays(sub, self.dims)
        site = np.array([p.site for p in sub], dtype=np.float64)[:, : self.dims]
        times = np.array([p.time_s for p in sub], dtype=np.float64)
        label = self.book.label
        ids = [label[s] for s in slots[r].tolist()]
        # The compiled engine predicts and scores in one pass (the same numbers to rounding).
        d2 = g.tracker.gate_distances(g.method, ids, times, plot, noise, site)
        if d2 is None:
            pred = g.tracker.predicted(g.method, ids, times)
            d2 = mahalanobis_pairs(g.method, pred, plot, noise, site)
        return r, c, d2

    def status(self, track: str) -> str:
        """A live track's status."""
        return CONFIRMED if self.book.status[self.book.slot[track]] == CONFIRMED_CODE else TENTATIVE

    def plot_counts(self) -> dict[str, dict[str, int]]:
        """Per radar, its plots so far: in tracks confirmed (now or before their deletion),
        in tracks still tentative, in tracks deleted without ever being confirmed
        (``TrackBook.plot_counts``)."""
        counts = self.book.plot_counts()
        return {
            name: dict(zip(("confirmed", "tentative", "never"), map(int, counts[i]), strict=True))
            for i, name in enumerate(self.beams)
        }

    def distances(self, ids: list[str], plots: list[Plot]) -> NDArray[np.float64]:
        """d² (len(ids), len(plots)) of ``plots`` against tracks ``ids``, each track predicted
        to each plot's own time (one batch per distinct time)."""
        g = self._gate
        out = np.full((len(ids), len(plots)), np.inf)
        if not ids or not plots:
            return out
        times = np.array([p.time_s for p in plots])
        for t in np.unique(times):
            cols = np.flatnonzero(times == t)
            sub = [plots[j] for j in cols]
            plot, noise = polar_arrays(sub, self.dims)
            site = np.array([p.site for p in sub], dtype=np.float64)[:, : self.dims]
            pred = g.tracker.predicted(g.method, ids, float(t))
            out[:, cols] = mahalanobis_matrix(g.method, pred, plot, noise, site)
        return out

    def pairs(
        self, ids: list[str], plots: list[Plot]
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
        """The gate's candidate pairs of ``plots`` and tracks ``ids``: (rows into ids, columns
        into plots, d²), (N,) each, every pair inside the gate among them.

        For a ``boxed`` gating method, every track is predicted to the first and the last plot
        time, the pairs in the coarse box (``gate_box_pairs``) are found, and each of them is
        predicted to its plot's own time and scored (``mahalanobis_pairs``): the cost follows
        the candidates, not K × P (a motion model not in ``INTERVAL_MODELS``: one box per
        distinct plot time). For the others, as ``distances``: every pair, each track
        predicted to each distinct plot time.
        """
        g = self._gate
        times = np.array([p.time_s for p in plots])
        if not boxed(g.method):
            found = []
            for t in np.unique(times):
                cols = np.flatnonzero(times == t)
                d2_all = self.distances(ids, [plots[j] for j in cols])
                r, c = np.nonzero(d2_all < g.threshold)
                found.append((r, cols[c], d2_all[r, c]))
            rows, cols_all, d2s = (np.concatenate(v) for v in zip(*found, strict=True))
            return rows.astype(np.intp), cols_all.astype(np.intp), d2s
        plot, noise = polar_arrays(plots, self.dims)
        site = np.array([p.site for p in plots], dtype=np.float64)[:, : self.dims]
        spans = [(float(times.min()), float(times.max()))]
        if not self._interval:  # no bound between two times: one box per distinct time
            spans = [(float(t), float(t)) for t in np.unique(times)]
        found = []
        for first, last in spans:
            cols = np.flatnonzero((times >= first) & (times <= last))
            early = g.tracker.predicted(g.method, ids, first)
            late = early if last == first else g.tracker.predicted(g.method, ids, last)
            sub = PolarPlot(*(None if v is None else v[cols] for v in plot))
            sub_noise = PolarNoise(*(np.broadcast_to(v, times.shape)[cols] for v in noise))
            r, c = gate_box_pairs(g.method, early, late, sub, sub_noise, site[cols], g.threshold)
            if last == first:
                pred = CVBatch(early.x[r], early.P[r])
            else:  # each pair's track at its plot's own time
                pred = g.tracker.predicted(g.method, [ids[i] for i in r.tolist()], times[cols[c]])
            d2 = mahalanobis_pairs(
                g.method,
                pred,
                PolarPlot(*(None if v is None else v[c] for v in sub)),
                PolarNoise(*(v[c] for v in sub_noise)),
                site[cols[c]],
            )
            found.append((r, cols[c], d2))
        rows, cols_all, d2s = (np.concatenate(v) for v in zip(*found, strict=True))
        return rows.astype(np.intp), cols_all.astype(np.intp), d2s

    def add_batches(
        self,
        batches: Sequence[list[Plot]],
        measured_period_s: Sequence[float | None] | None = None,
        whole_scan: bool = False,
    ) -> list[ScanResult]:
        """``add_batch`` of each of ``batches`` in order, on the compiled route in one call
        (``core.tracking.association_compiled``): the same association, without a batch's
        fixed cost. ``measured_period_s``: per batch, its radar's antenna period as the feed
        measured it before the batch (``measured_period``), or None. A ``PlotError`` carries
        ``batch`` and ``index`` (the plot's position in it)."""
        with cycle_collector_paused():
            return self._add_batches(batches, measured_period_s, whole_scan)

    def _add_batches(
        self,
        batches: Sequence[list[Plot]],
        measured_period_s: Sequence[float | None] | None,
        whole_scan: bool,
    ) -> list[ScanResult]:
        measured = list(measured_period_s or [None] * len(batches))
        if self._compiled is None:
            out = []
            for b, (plots, period) in enumerate(zip(batches, measured, strict=True)):
                if period is not None and plots:
                    self.measured_period(plots[0].radar, period)
                try:
                    out.append(self._add(plots, whole_scan))
                except PlotError as exc:
                    exc.batch = b  # type: ignore[attr-defined]
                    raise
            return out
        index = {name: i for i, name in enumerate(self.beams)}
        radar = np.zeros(len(batches), np.int64)  # each batch's radar
        # Every plot's radar name, and whether all are 2D, once for the call.
        names = [p.radar for plots in batches for p in plots]
        flat_2d = [p.elevation_rad for plots in batches for p in plots].count(None) == len(names)
        lo = 0
        for b, plots in enumerate(batches):
            hi = lo + len(plots)
            if not plots:
                measured[b] = None
                continue
            name = names[lo]
            i = index.get(name)
            one_radar = names[lo:hi].count(name) == hi - lo
            lo = hi
            # A 2D batch of one radar already seen (the compiled route is 2D): the checks of
            # ``_check_batch`` and ``_radar`` without a call a batch.
            if i is None or not one_radar or not flat_2d:
                measured[b] = measured[b] if i is not None else None  # ``measured_period``
                try:
                    self._check_batch(plots)
                    reg = self._radar(plots)
                except PlotError as exc:
                    exc.batch = b  # type: ignore[attr-defined]
                    raise
                assert reg is not None
                i = index[name] = reg[0]
            radar[b] = i
        sizes = np.fromiter(map(len, batches), np.int64, len(batches))
        starts = np.concatenate([[0], np.cumsum(sizes)])
        res, bad = self._compiled.run(
            batches, np.repeat(radar, sizes), np.array(self._sites).reshape(-1, 2),
            whole_scan, measured,
        )  # fmt: skip
        if bad >= 0:  # the gating track's kernel found a plot out of order
            b = int(np.searchsorted(starts, bad, side="right")) - 1
            exc = PlotError(
                "time_s", "times must not decrease within a track", index=int(bad - starts[b])
            )
            exc.batch = b  # type: ignore[attr-defined]
            raise exc
        self.batches += len(batches)
        self._started = self.book._started
        # Each plot's track id, one str per track; the requested methods' rows, filtered by
        # the call itself.
        u, inv = np.unique(res.ids, return_inverse=True)
        ids = np.array([str(t) for t in u.tolist()], dtype=object)[inv.reshape(-1)].tolist()
        assert res.tracks is not None
        rows = StateRows(res.tracks, self.methods)
        deleted = [t for d in res.deleted for t in d]
        if deleted:
            self.tracker.forget(deleted)
        status = _STATUS_NAMES[res.status].tolist()
        out = []
        bounds = starts.tolist()
        for confirmed in res.confirmed:
            self._count_confirmed(confirmed)
        for b in range(len(batches)):
            lo, hi = bounds[b], bounds[b + 1]
            out.append(
                ScanResult(
                    ids[lo:hi], status[lo:hi], rows.slice(lo, hi), res.confirmed[b],
                    res.deleted[b],
                )
            )  # fmt: skip
        return out

    def add_scan(self, plots: list[Plot]) -> ScanResult:
        """Associate and filter one whole scan of one radar (its plots, or none): every live
        track inside the radar's coverage without a plot in the scan has missed it (an
        empty scan: every live track). A ``PlotError`` carries ``index``, the plot's position
        in the scan."""
        if self._compiled is not None:
            return self.add_batches([plots], whole_scan=True)[0]
        return self._add(plots, whole_scan=True)

    def add_batch(self, plots: list[Plot]) -> ScanResult:
        """Associate and filter a batch of one radar's plots as they come (``plot_batches``):
        the tracks the radar's beam swept since its previous batch, inside its coverage,
        without a plot are missed (``core.tracking.coverage``); a scan-stamped radar's batch
        is a whole scan. A ``PlotError`` carries ``index``, the plot's position in the
        batch."""
        if self._compiled is not None:
            return self.add_batches([plots])[0]
        return self._add(plots, whole_scan=False)

    def _too_fast(
        self,
        track_slots: NDArray[np.intp],
        plots: list[Plot],
        rows: NDArray[np.intp],
        cols: NDArray[np.intp],
    ) -> NDArray[np.bool_]:
        """Which (track, plot) pairs, rows into ``track_slots`` (the book's) and columns into
        ``plots``, pair a
        track of a single plot with a plot it could only reach faster than
        ``AssociationOptions.max_speed_mps`` (the speed gate of two-plot initiation): its
        velocity is still 0 ± σv0, so the χ² gate alone admits any plot within a few σv0 Δt,
        and a first plot joined to a far one starts a track at an impossible speed."""
        book = self.book
        slots = track_slots[rows]
        single = book.hits[slots] == 1
        if not single.any():
            return single
        sub = [plots[j] for j in cols.tolist()]
        r = np.array([p.range_m for p in sub])
        b = np.array([p.azimuth_rad for p in sub])
        e = np.array([p.elevation_rad or 0.0 for p in sub])
        site = np.array([p.site for p in sub], dtype=np.float64)
        xyz = site + r[:, None] * direction_cosines(b, e)
        gap = np.linalg.norm(xyz[:, : self.dims] - book.x[slots][:, 0::2], axis=1)
        dt = np.array([p.time_s for p in sub]) - book.last_s[slots]
        sigma = np.array([p.sigma_r_m + p.range_m * p.sigma_beta_rad for p in sub])
        reach = self.association.max_speed_mps * dt + 3.0 * (sigma + book.sigma_m[slots])
        return single & (gap > reach)

    def _radar(self, plots: list[Plot]) -> tuple[int, RadarBeam] | None:
        """The batch's radar (index, beam), registered at its first plot; None for no plots."""
        if not plots:
            return None
        name = plots[0].radar
        for i, p in enumerate(plots):
            if p.radar != name:
                raise PlotError("radar", "a batch holds the plots of one radar", index=i)
        if name not in self.beams:
            row = len(self.beams)
            self._table.grow(row + 1, self._table.length)
            self.beams[name] = RadarBeam(self._coverage.get(name), self._table, row)
            self._sites.append(np.asarray(plots[0].site, dtype=np.float64)[: self.dims])
            self.book.radars(len(self.beams))
        return list(self.beams).index(name), self.beams[name]

    def _check_batch(self, plots: list[Plot]) -> None:
        for i, p in enumerate(plots):
            if (self.dims == 3) != (p.elevation_rad is not None):
                raise PlotError(
                    "elevation_deg", "every plot of a 3D track needs an elevation", index=i
                )

    def _add(self, plots: list[Plot], whole_scan: bool) -> ScanResult:
        self._check_batch(plots)
        radar = self._radar(plots)
        self.batches += 1
        times = np.array([p.time_s for p in plots], dtype=np.float64)
        period = None
        if radar is not None:
            beam = radar[1]
            elev = (
                np.array([p.elevation_rad for p in plots], dtype=np.float64)
                if self.dims == 3
                else None
            )
            beam.observe(
                times,
                np.array([p.azimuth_rad for p in plots], dtype=np.float64),
                np.array([p.range_m for p in plots], dtype=np.float64),
                elev,
            )
            period = beam.period_s
        book = self.book
        owner: list[str | None] = [None] * len(plots)
        free = np.arange(len(plots))
        live = book.live_slots()
        points = None  # the gate's conversion of the batch, made once (``gate_points``)
        for code in (CONFIRMED_CODE, TENTATIVE_CODE):  # confirmed tracks choose first
            slots = live[book.status[live] == code]
            if radar is not None and period is not None and slots.size:
                # A track takes at most one plot per sweep of a radar.
                slots = slots[book.hit_s[slots, radar[0]] <= times[0] - period / 2]
            if not slots.size or not free.size:
                continue
            scan = [plots[j] for j in free]
            shape = (slots.size, len(scan))
            if self.dense:
                ids = [book.label[s] for s in slots.tolist()]
                d2_all = self.distances(ids, scan)
                if code == TENTATIVE_CODE:
                    r, c = np.indices(d2_all.shape).reshape(2, -1)
                    too_fast = self._too_fast(slots, scan, r, c)
                    d2_all[r, c] = np.where(too_fast, np.inf, d2_all[r, c])
                rows, cols = gnn_assign(d2_all, self._gate.threshold)
            else:
                if self.prefiltered and slots.size * len(scan) <= NEAR_MAX_PAIRS:
                    # No Python loop over the live tracks, no prediction of every one.
                    if points is None:
                        points = self.gate_points(plots)
                    pts, r_ii, t_s = points
                    sub = (np.ascontiguousarray(pts[free]), np.ascontiguousarray(r_ii[free]))
                    r, c, d2 = self.scored(slots, scan, (*sub, t_s[free]))
                else:
                    r, c, d2 = self.pairs([book.label[s] for s in slots.tolist()], scan)
                if code == TENTATIVE_CODE:
                    d2 = np.where(self._too_fast(slots, scan, r, c), np.inf, d2)
                rows, cols = sparse_gnn_assign(r, c, d2, self._gate.threshold, shape)
            for r, c in zip(slots[rows].tolist(), cols.tolist(), strict=True):
                owner[int(free[c])] = book.label[r]
            free = np.delete(free, cols)
        hit = [j for j, t in enumerate(owner) if t is not None]
        for j in free.tolist():  # unassigned plots start tentative tracks
            self._started += 1
            owner[j] = str(self._started)
        labelled = [_label(p, t) for p, t in zip(plots, owner, strict=True)]
        rows_out = self.tracker.add_block(labelled)
        gate_rows = rows_out
        if self._gate.tracker is not self.tracker:
            gate_rows = self._gate.tracker.add_block(labelled)
        confirmed, deleted = self._manage(
            radar, times, owner, hit, free.tolist(), gate_rows, whole_scan, live
        )
        statuses = [self.status(t) if t in book.slot else TENTATIVE for t in owner]
        # A track deleted at this batch cannot have a plot in it (it was missed): statuses hold.
        return ScanResult([str(t) for t in owner], statuses, rows_out, confirmed, deleted)

    def _manage(
        self,
        radar: tuple[int, RadarBeam] | None,
        times: NDArray[np.float64],
        owner: list[str | None],
        hit: list[int],
        started: list[int],
        gate_rows: list[list[StateRow]],
        whole_scan: bool,
        live: NDArray[np.intp],
    ) -> tuple[list[str], list[str]]:
        """Hits, starts, the sweep's misses, confirmation and deletion after a batch
        (``core.tracking.management``); ``live`` the slots live before it."""
        book = self.book
        gi = (
            next(i for i, (m, _, _) in enumerate(gate_rows[0]) if m == self._gate.method)
            if gate_rows
            else 0
        )
        n = 2 * self.dims
        before = live  # the tracks that existed before this batch
        ri = radar[0] if radar is not None else 0
        if hit:
            slots = np.array([book.slot[str(owner[j])] for j in hit], dtype=np.intp)
            book.hit(slots, times[hit], ri)
        for j in started:
            s = book.start(str(owner[j]), float(times[j]), ri)
            if self.association.confirm_m <= 1:  # 1 of N: the initiating plot confirms
                book.status[s] = CONFIRMED_CODE
        for j, t in enumerate(owner):  # each track's latest state, for its sweeps
            s = book.slot[str(t)]
            _, x6, P6 = gate_rows[j][gi]
            book.x[s] = x6[:n]
            book.P[s] = P6[:n, :n]
            book.sigma_m[s] = math.sqrt(max(float(P6[k, k]) for k in range(0, n, 2)))
            book.sigma_v[s] = math.sqrt(max(float(P6[k, k]) for k in range(1, n, 2)))
        hit_slots = {book.slot[str(owner[j])] for j in hit}
        judged = self._swept(radar, times, before, whole_scan)
        missed = np.array([s for s in judged.tolist() if s not in hit_slots], dtype=np.intp)
        book.miss(missed)
        started_slots = [book.slot[str(owner[j])] for j in started]
        touched = np.unique(
            np.concatenate([missed, np.array([*hit_slots, *started_slots], dtype=np.intp)])
        )
        confirm, delete = book.settle(touched)
        # A track started in this batch has not coasted: the tracks from before suffice.
        delete = np.concatenate([delete, self._coasted(times, before)]).astype(np.intp)
        label = book.label
        confirmed = [label[s] for s in sorted(confirm.tolist(), key=lambda s: int(label[s]))]
        if self.association.confirm_m <= 1:
            confirmed += [str(owner[j]) for j in started]
        deleted = sorted({label[s] for s in delete.tolist()}, key=int)
        for t in deleted:
            book.remove(t)
        if deleted:
            self.tracker.forget(deleted)
            if self._gate.tracker is not self.tracker:
                self._gate.tracker.forget(deleted)
        self._count_confirmed(confirmed)
        return confirmed, deleted

    def _count_confirmed(self, ids: list[str]) -> None:
        """Tracks ``ids`` confirmed: counted, and kept if ``keep_confirmed``."""
        self.tracks_confirmed += len(ids)
        if self.keep_confirmed:
            self.ever_confirmed.extend(ids)

    def _swept(
        self,
        radar: tuple[int, RadarBeam] | None,
        times: NDArray[np.float64],
        slots: NDArray[np.intp],
        whole_scan: bool,
    ) -> NDArray[np.intp]:
        """The slots among ``slots`` that this batch's sweep judges: passed by the beam inside
        the radar's coverage, not judged by it in this sweep already
        (``core.tracking.coverage``). An empty whole scan (no radar): every one."""
        if not slots.size:
            return slots
        if radar is None:
            return slots if whole_scan else slots[:0]
        ri, beam = radar
        book = self.book
        end = float(times[-1])
        whole = whole_scan or (beam.scan_stamped and times[0] == times[-1])
        period = beam.period_s
        if period is not None and not whole:
            # A pass is at most ``end`` (passed_s = end − δT/2π, δ ≥ 0), so a track judged
            # or hit by this radar within half a period of ``end`` fails the two tests at
            # the end whatever its pass time: dropped before its geometry (the sweep below
            # is still taken, with no track if none is left: it moves the beam's start).
            half = period / 2
            slots = slots[
                (book.judged_s[slots, ri] + half < end) & (book.hit_s[slots, ri] <= end - half)
            ]
        x = book.x[slots]
        ahead = end - book.last_s[slots]
        pos = x[:, 0::2] + x[:, 1::2] * ahead[:, None]
        # The predicted position's σ (the velocity's σ carried over the time since the last
        # plot): a fresh track, its velocity still ±σv0, may be anywhere in a wide arc.
        sigma = np.sqrt(book.sigma_m[slots] ** 2 + (book.sigma_v[slots] * ahead) ** 2)
        rel = pos - self._sites[ri]
        ground = np.sqrt(rel[:, 0] ** 2 + rel[:, 1] ** 2)
        rng = np.sqrt(np.sum(rel**2, axis=1))
        elev = np.arctan2(rel[:, 2], ground) if self.dims == 3 else None
        az = np.arctan2(rel[:, 1], rel[:, 0])
        margin = np.clip(3.0 * sigma / np.maximum(ground, 1.0), MIN_MARGIN_RAD, MAX_MARGIN_RAD)
        passed_mask, passed_s = beam.swept(end, az, margin, whole)
        # The edge by the σ of the last estimate: by the predicted σ, a fresh track (a false
        # plot's among them) would be too uncertain ever to be expected, and never missed.
        edge = 3.0 * book.sigma_m[slots] + EDGE_FRACTION * rng
        # Whole scans handed in by the caller are judged in the coverage given (the caller
        # knows the scan saw all it covers); batches also in the coverage estimated.
        covered = beam.inside(rng, elev, edge, estimated=not whole_scan)
        ok = passed_mask & covered & (book.born_s[slots] < passed_s)
        if period is not None and not whole:
            ok &= passed_s > book.judged_s[slots, ri] + period / 2
            # A plot of this sweep already came (the beam passed it a little early).
            ok &= book.hit_s[slots, ri] <= passed_s - period / 2
        book.judged_s[slots[ok], ri] = passed_s[ok]
        return slots[ok]

    def report(self) -> AssociationReport:
        """The account so far (``AssociationReport``)."""
        return AssociationReport(
            self.plot_counts(),
            {n: b.estimated() for n, b in self.beams.items()},
            {n: b.scan_stamped for n, b in self.beams.items()},
            self._started,
            self.tracks_confirmed,
        )

    def measured_period(self, radar: str, period_s: float) -> None:
        """``radar``'s antenna period as measured by the feed itself (its north markers or
        service messages), replacing the estimate from its plots from now on."""
        if radar in self.beams:
            self.beams[radar].measured_period(period_s)

    def coast_s(self) -> float | None:
        """How long a track lives without a plot: ``delete_misses`` + 1 revolutions of the
        slowest radar whose period is known (None: no radar's is)."""
        periods = [b.period_s for b in self.beams.values() if b.period_s is not None]
        if not periods:
            return None
        return (self.association.delete_misses + 1) * max(periods)

    def _coasted(
        self, times: NDArray[np.float64], slots: NDArray[np.intp] | None = None
    ) -> NDArray[np.intp]:
        """Live slots without a plot for longer than ``coast_s`` at the batch's end."""
        coast = self.coast_s()
        slots = self.book.live_slots() if slots is None else slots
        if coast is None or not times.size or not slots.size:
            return slots[:0]
        return slots[self.book.last_s[slots] < float(times[-1]) - coast]

    def states(
        self, method: str, time_s: float, status: str = CONFIRMED
    ) -> tuple[list[str], CVBatch]:
        """The live tracks of ``status`` and ``method``'s estimates of them at ``time_s``
        (predicted from their last plot; a track updated at ``time_s`` as it is)."""
        ids = self.live(status)
        tracker = self.tracker if method in self.methods else self._gate.tracker
        if not ids:
            n = 2 * self.dims
            return ids, CVBatch(np.zeros((0, n)), np.zeros((0, n, n)))
        return ids, tracker.predicted(method, ids, time_s)


def _without_monitor(options: StreamOptions) -> StreamOptions:
    """``options`` without the consistency monitor (the gating method's own tracks, when it
    is not a requested method, are not reported)."""
    return replace(options, monitor=None)


def _label(p: Plot, track_id: str | None) -> Plot:
    """``replace(p, target=track_id)``, done as a copy of the fields: ``dataclasses.replace``
    re-runs a frozen dataclass's ``__init__`` (one ``object.__setattr__`` per field), a third
    of a scan's association time at 10³ plots."""
    assert track_id is not None
    q = object.__new__(Plot)
    q.__dict__.update(p.__dict__, target=track_id)
    return q
