"""The association as one compiled loop (numba): GNN over many batches of plots in one call.

``core.tracking.association.GNNTracker`` associates a rotating radar's plots a batch at a
time, and a batch holds two or three plots: a Python and numpy batch costs milliseconds, the
labelled filtering of the same plots microseconds. Here the whole batch loop runs compiled:
per batch the beam's estimates (``observe_beam``), the prefilter of every live track
(``core.tracking.kernels_gate.near_pairs``), each candidate predicted to its plot's own time
and scored by the gating method's position NIS (``core.filters.kernels_imm``'s
``combined_prediction``, the tracker kernels' own steps), the speed gate of two-plot
initiation, the optimal assignment (``sparse_assign``), hits and starts, every method's
update of every plot's track (``core.filters.kernels_imm.track_plots_imm_2d``, on the
tracker's own rows: each plot is filtered once, the gating method's update being the one the
next batch gates with), the sweep's misses, M-of-N confirmation and deletion
(``core.tracking.management``'s rules on its arrays).

What each step computes is written, with its reasons, in ``core.tracking.association``,
``core.tracking.coverage`` and ``core.tracking.management``; the code below follows them step
by step, on the same arrays (``TrackBook``'s, and ``RadarBeam``'s state rows), so that the
compiled route makes the same association as the Python one on the numpy engine
(``tests/test_association_kernel.py``). The route covers 2D plots, a gating method that
converts the plot alone (``boxed``) and the IMM; the rest takes the Python route.

Imported on first use only.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.kernel_args import (
    IMMOptions,
    PlotColumns,
    PlotOutputs,
    RadarArrays,
    TrackState,
)
from radarviz.core.filters.kernels_2d import _inline, _jit
from radarviz.core.filters.kernels_imm import pair_nis_2d, track_plots_imm_2d
from radarviz.core.filters.methods import PLAN_COVARIANCE
from radarviz.core.tracking.kernels_gate import (
    BOX_FROM_S,
    BOX_UNTIL_S,
    BOX_X_HI,
    BOX_X_LO,
    BOX_Y_HI,
    BOX_Y_LO,
    boxes_near,
    near_pairs,
    plot_points_2d,
)

TWO_PI = 2.0 * math.pi

# -- a radar beam's state: one row of floats and one of counts per radar ------------------
# Floats (NaN: not known). The given coverage is kept beside the estimates.
B_PERIOD, B_GIVEN_PERIOD, B_REVISIT_PERIOD = 0, 1, 2
B_RANGE_LO, B_RANGE_HI, B_EL_LO, B_EL_HI = 3, 4, 5, 6
B_LAST_S, B_LAST_AZ, B_SWEPT_TO = 7, 8, 9
B_GIVEN_MIN_R, B_GIVEN_MAX_R, B_GIVEN_MIN_EL, B_GIVEN_MAX_EL = 10, 11, 12, 13
B_RATE_MEDIAN = 14  # the median of the beam rates, as of B_RATES_AT of them
# The sweep's beam model (``_swept``): its time t₀, azimuth β₀, period T and direction d.
B_MODEL_S, B_MODEL_AZ, B_MODEL_PERIOD, B_MODEL_DIR = 15, 16, 17, 18
BEAM_FLOATS = 19
# Counts.
B_SAME, B_OTHER, B_TURN_NEG, B_TURN_POS, B_MEASURED = 0, 1, 2, 3, 4
B_N_REVISITS, B_REVISIT_HEAD, B_N_RATES, B_N_CLOSE, B_SEEN = 5, 6, 7, 8, 9
B_RATES_AT, B_RATES_AGREE = 10, 11  # the rates B_RATE_MEDIAN is of, and how many agree
BEAM_COUNTS = 12


class BeamArrays(NamedTuple):
    """One radar's beam state (``core.tracking.coverage.RadarBeam``), or R radars' stacked
    on a first axis: f (BEAM_FLOATS,), c (BEAM_COUNTS,) int64, cells (AZIMUTH_CELLS,) the
    last plot time per azimuth cell, revisits (REVISITS_KEPT,) a ring of the latest
    revisits and ordered (REVISITS_KEPT,) the same in increasing order (its quantile and
    median without a sort), rates (L,) the beam rates seen, close (L, 2) the (Δt, |Δβ|) of close
    consecutive plots (L ≥ REVISITS_KEPT plus a call's plots: a batch's pairs are all kept
    while fewer than REVISITS_KEPT were)."""

    f: NDArray[np.float64]
    c: NDArray[np.int64]
    cells: NDArray[np.float64]
    revisits: NDArray[np.float64]
    ordered: NDArray[np.float64]
    rates: NDArray[np.float64]
    close: NDArray[np.float64]


@_jit
def _wrap(a: float) -> float:
    return (a + math.pi) % TWO_PI - math.pi


@_jit
def _median(a):
    return np.median(a)


@_jit
def _sorted_median(a, lo: int, hi: int) -> float:
    """``np.median`` of a[lo:hi], a in increasing order (hi > lo)."""
    n, mid = hi - lo, lo + (hi - lo) // 2
    return a[mid] if n % 2 else (a[mid - 1] + a[mid]) / 2.0


@_jit
def observe_beam(
    f, c, cells, revisits, ordered, rates, close, time_s, azimuth_rad, range_m, elevation_rad,
    has_elevation, cells_n, min_revisit_s, min_revisits, kept, max_pair_s, min_pair_s,
    beam_noise_rad,
):  # fmt: skip
    """``RadarBeam.observe``: learn from a batch of one radar's plots, (B,) each, in time
    order, into the beam's state f, c, cells, revisits, ordered, rates, close
    (``BeamArrays``).
    The constants are ``core.tracking.coverage``'s (passed in: one definition)."""
    n = time_s.shape[0]
    if n == 0:
        return
    for i in range(n):
        f[B_RANGE_LO] = min(f[B_RANGE_LO], range_m[i])
        f[B_RANGE_HI] = max(f[B_RANGE_HI], range_m[i])
        if has_elevation:
            f[B_EL_LO] = min(f[B_EL_LO], elevation_rad[i])
            f[B_EL_HI] = max(f[B_EL_HI], elevation_rad[i])
    period = f[B_PERIOD]
    quarter = period / 4.0 if math.isfinite(period) else math.inf
    learn = math.isnan(f[B_GIVEN_PERIOD]) and c[B_MEASURED] == 0
    take_close = learn and c[B_N_CLOSE] < kept
    take_rates = learn and c[B_N_RATES] < kept
    any_pair = False
    prev_t, prev_az = f[B_LAST_S], f[B_LAST_AZ]
    first = 0 if math.isfinite(prev_t) else 1
    for i in range(first, n):
        t0 = prev_t if i == 0 else time_s[i - 1]
        a0 = prev_az if i == 0 else azimuth_rad[i - 1]
        dt, daz = time_s[i] - t0, _wrap(azimuth_rad[i] - a0)
        if dt == 0.0:
            c[B_SAME] += 1
        else:
            c[B_OTHER] += 1
        if dt > 0 and dt < quarter and abs(daz) < math.pi / 3 and daz != 0.0:
            c[B_TURN_POS if daz > 0 else B_TURN_NEG] += 1
        if take_close and dt > 0 and dt <= max_pair_s:
            close[c[B_N_CLOSE], 0], close[c[B_N_CLOSE], 1] = dt, abs(daz)
            c[B_N_CLOSE] += 1
        if take_rates and dt >= min_pair_s and dt <= max_pair_s:
            rates[c[B_N_RATES]] = daz / dt
            c[B_N_RATES] += 1
            any_pair = True
    if learn:
        if take_rates and not any_pair:
            # The batch's ends: a rate where its plots come densely.
            t0 = prev_t if first == 0 else time_s[0]
            a0 = prev_az if first == 0 else azimuth_rad[0]
            span = time_s[n - 1] - t0
            if min_pair_s <= span and span <= max_pair_s:
                rates[c[B_N_RATES]] = _wrap(azimuth_rad[n - 1] - a0) / span
                c[B_N_RATES] += 1
        _learn_period(f, c, cells, revisits, ordered, time_s, azimuth_rad, cells_n,
                      min_revisit_s, min_revisits, kept)  # fmt: skip
        f[B_PERIOD] = _estimate(f, c, rates, close, min_revisits, beam_noise_rad)
    f[B_LAST_S], f[B_LAST_AZ] = time_s[n - 1], azimuth_rad[n - 1]


@_jit
def _learn_period(f, c, cells, revisits, ordered, time_s, azimuth_rad, cells_n, min_revisit_s,
                  min_revisits, kept):  # fmt: skip
    """``RadarBeam._learn_period``: revisits of azimuth cells into the ring (and its ordered
    copy), and the revisits' period estimate: the median of those within ±10% of their
    10th percentile (``np.quantile``'s "lower": the value at floor(0.1 (n − 1)) in order)."""
    for i in range(time_s.shape[0]):
        k = int((azimuth_rad[i] % TWO_PI) * (cells_n / TWO_PI))
        if k > cells_n - 1:
            k = cells_n - 1
        prev = max(cells[k - 1 if k > 0 else cells_n - 1], cells[k], cells[(k + 1) % cells_n])
        t = time_s[i]
        if math.isfinite(prev) and t - prev >= min_revisit_s:
            m = c[B_N_REVISITS]
            if m == kept:  # the oldest leaves the ordered copy
                gone = np.searchsorted(ordered[:m], revisits[c[B_REVISIT_HEAD]])
                for q in range(gone, m - 1):  # element loops: no temporary array
                    ordered[q] = ordered[q + 1]
                m -= 1
            at = np.searchsorted(ordered[:m], t - prev)
            for q in range(m, at, -1):
                ordered[q] = ordered[q - 1]
            ordered[at] = t - prev
            revisits[c[B_REVISIT_HEAD]] = t - prev
            c[B_REVISIT_HEAD] = (c[B_REVISIT_HEAD] + 1) % kept
            c[B_N_REVISITS] = m + 1
        cells[k] = t
    m = c[B_N_REVISITS]
    if m >= min_revisits:
        r = ordered[:m]
        low = r[int(0.1 * (m - 1))]  # 0.1 (m − 1) ≥ 0: truncation is the floor
        lo = np.searchsorted(r, 0.9 * low, side="left")
        hi = np.searchsorted(r, 1.1 * low, side="right")
        # The shortest revisits must be a cluster (a tenth of them at least), not a stray.
        if hi - lo >= max(3, m // 10):
            f[B_REVISIT_PERIOD] = _sorted_median(r, lo, hi)


@_jit
def _estimate(f, c, rates, close, min_revisits, beam_noise_rad) -> float:
    """``RadarBeam._estimate``: the revisits' period, else the beam rate's; NaN while
    neither is known or when close plots are not on a beam."""
    rate_period = np.nan
    nr = c[B_N_RATES]
    if nr >= min_revisits:
        if c[B_RATES_AT] != nr:  # the rates stop changing once REVISITS_KEPT are kept
            w = _median(rates[:nr])
            agree = 0
            for i in range(nr):
                if abs(rates[i] - w) <= 0.1 * abs(w):
                    agree += 1
            f[B_RATE_MEDIAN], c[B_RATES_AT], c[B_RATES_AGREE] = w, nr, agree
        w, agree = f[B_RATE_MEDIAN], c[B_RATES_AGREE]
        if agree / nr < 0.5:
            return np.nan
        rate_period = TWO_PI / abs(w)
    period = f[B_REVISIT_PERIOD]
    if math.isnan(period):
        period = rate_period
    nc = c[B_N_CLOSE]
    if math.isfinite(period) and nc >= min_revisits:
        on = 0
        for i in range(nc):
            if close[i, 1] <= 1.2 * TWO_PI * close[i, 0] / period + beam_noise_rad:
                on += 1
        if on / nc < 0.5:
            return np.nan
    return period


# -- the optimal assignment of a small component ----------------------------------------


@_jit
def lsap(cost):
    """The minimum-cost assignment of a dense (nr, nc) matrix: (rows, cols) of min(nr, nc)
    pairs, rows increasing: the shortest augmenting path algorithm (Jonker and Volgenant
    1987, in the form of Crouse 2016, as ``scipy.optimize.linear_sum_assignment``)."""
    nr, nc = cost.shape
    tr = nr > nc
    a = cost.T.copy() if tr else cost
    n, m = a.shape  # n ≤ m
    u, v = np.zeros(n), np.zeros(m)
    col4row = np.full(n, -1, np.int64)
    row4col = np.full(m, -1, np.int64)
    path = np.full(m, -1, np.int64)
    short = np.empty(m)
    sr = np.zeros(n, np.bool_)
    sc = np.zeros(m, np.bool_)
    remaining = np.empty(m, np.int64)
    for cur in range(n):
        min_val = 0.0
        i = cur
        num_rem = m
        for j in range(m):
            remaining[j] = m - j - 1
        sr[:] = False
        sc[:] = False
        short[:] = np.inf
        sink = -1
        while sink == -1:
            index = -1
            lowest = np.inf
            sr[i] = True
            for it in range(num_rem):
                j = remaining[it]
                r = min_val + a[i, j] - u[i] - v[j]
                if r < short[j]:
                    path[j] = i
                    short[j] = r
                if short[j] < lowest or (short[j] == lowest and row4col[j] == -1):
                    lowest = short[j]
                    index = it
            min_val = lowest
            j = remaining[index]
            if row4col[j] == -1:
                sink = j
            else:
                i = row4col[j]
            sc[j] = True
            num_rem -= 1
            remaining[index] = remaining[num_rem]
        u[cur] += min_val
        for i2 in range(n):
            if sr[i2] and i2 != cur:
                u[i2] += min_val - short[col4row[i2]]
        for j2 in range(m):
            if sc[j2]:
                v[j2] -= min_val - short[j2]
        j = sink
        while True:
            i = path[j]
            row4col[j] = i
            j, col4row[i] = col4row[i], j
            if i == cur:
                break
    rows = np.empty(n, np.int64)
    cols = np.empty(n, np.int64)
    if tr:
        # rows of the transposed problem are the columns: sort by the original rows
        order = np.argsort(col4row)
        for q in range(n):
            rows[q] = col4row[order[q]]
            cols[q] = order[q]
    else:
        for q in range(n):
            rows[q], cols[q] = q, col4row[q]
    return rows, cols


@_jit
def _root(parent, a):
    while parent[a] != a:
        parent[a] = parent[parent[a]]  # path halving
        a = parent[a]
    return a


@_jit
def sparse_assign(rows, cols, d2, gate, n_tracks, n_plots, out_r, out_c):
    """The sparse GNN assignment of N scored pairs (rows into the tracks, columns into the
    plots, d²; ``core.tracking.association.sparse_gnn_assign`` calls it, and has the
    reasoning): the pairs inside the gate form a bipartite graph,
    each connected component's assignment is solved on its own (``lsap`` on its small dense
    matrix of d² − γ, a missing pair costing 0), a component of one edge is assigned.
    Writes the assigned pairs into out_r, out_c; returns how many."""
    n = rows.shape[0]
    parent = np.arange(n_tracks + n_plots)
    inside = np.empty(n, np.int64)
    ne = 0
    for e in range(n):
        if d2[e] < gate:
            inside[ne] = e
            ne += 1
            a, b = _root(parent, rows[e]), _root(parent, n_tracks + cols[e])
            if a != b:
                parent[a] = b
    if ne == 0:
        return 0
    comp = np.empty(ne, np.int64)
    for q in range(ne):
        comp[q] = _root(parent, rows[inside[q]])
    order = np.argsort(comp, kind="mergesort")
    found = 0
    s = 0
    while s < ne:
        e = s
        while e < ne and comp[order[e]] == comp[order[s]]:
            e += 1
        if e - s == 1:
            q = inside[order[s]]
            out_r[found], out_c[found] = rows[q], cols[q]
            found += 1
        else:
            idx = inside[order[s:e]]
            r_u = np.unique(rows[idx])
            c_u = np.unique(cols[idx])
            m = np.zeros((r_u.shape[0], c_u.shape[0]))
            for q in idx:
                m[np.searchsorted(r_u, rows[q]), np.searchsorted(c_u, cols[q])] = d2[q] - gate
            a, b = lsap(m)
            for q in range(a.shape[0]):
                if m[a[q], b[q]] < 0.0:
                    out_r[found], out_c[found] = r_u[a[q]], c_u[b[q]]
                    found += 1
        s = e
    return found


# -- the batch loop ----------------------------------------------------------------------


class BookArrays(NamedTuple):
    """``core.tracking.management.TrackBook``'s arrays (K slots, R radars), changed in
    place; free (K,) the stack of free slots (its top in ``counters``)."""

    status: NDArray[np.int8]
    hits: NDArray[np.int64]
    expected: NDArray[np.int64]
    misses: NDArray[np.int64]
    born_s: NDArray[np.float64]
    last_s: NDArray[np.float64]
    x: NDArray[np.float64]
    P: NDArray[np.float64]
    sigma_m: NDArray[np.float64]
    sigma_v: NDArray[np.float64]
    alive: NDArray[np.bool_]
    rank: NDArray[np.int64]
    hit_s: NDArray[np.float64]
    judged_s: NDArray[np.float64]
    plots: NDArray[np.int64]
    folded: NDArray[np.int64]
    free: NDArray[np.int64]


class TrackArrays(NamedTuple):
    """Every method's IMM tracks, one row per book slot: the arrays of the tracker's
    ``core.tracking.compiled.CompiledTracks`` (its rows bound to the book's slots), M methods:
    xs (K, M, r, 4), Ps (K, M, r, 4, 4), mus (K, M, r), started (K,), last_t (K,); their
    model: plan (M, 3) the methods' ``core.filters.methods.method_plan``, conversions
    (T, M, 2, 8) their ``conversion_table`` of each noise row, sigma_a_mps2, omega (r,), Pi (r, r),
    mu0 (r,), sigma_v0_mps (σv0, m/s), prm (the UKF's weights); gate, the gating method's
    index among the M; with_stats, whether to compute the monitor's NIS."""

    plan: NDArray[np.int64]
    conversions: NDArray[np.float64]
    sigma_a_mps2: NDArray[np.float64]
    omega: NDArray[np.float64]
    Pi: NDArray[np.float64]
    mu0: NDArray[np.float64]
    sigma_v0_mps: float
    prm: NDArray[np.float64]
    xs: NDArray[np.float64]
    Ps: NDArray[np.float64]
    mus: NDArray[np.float64]
    started: NDArray[np.bool_]
    last_t: NDArray[np.float64]
    gate: int
    with_stats: bool


class PlotArrays(NamedTuple):
    """B plots in time order, cut into batches: time_s, range_m, azimuth_rad (B,);
    radial_velocity_mps (B,), NaN where none (or Doppler unused); noise (B,) rows of the
    noise table site (T, 2), sigma_r_m, sigma_beta_rad, sigma_vr_mps (T,);
    radar (B,) the association's radar of each plot; batch_start (nb + 1,) each batch's
    first plot; whole_scan (nb,) a batch handed in as a whole scan; measured_period_s (nb,)
    the feed's period of the batch's radar, NaN where none."""

    time_s: NDArray[np.float64]
    range_m: NDArray[np.float64]
    azimuth_rad: NDArray[np.float64]
    radial_velocity_mps: NDArray[np.float64]
    noise: NDArray[np.int64]
    site: NDArray[np.float64]
    sigma_r_m: NDArray[np.float64]
    sigma_beta_rad: NDArray[np.float64]
    sigma_vr_mps: NDArray[np.float64]
    radar: NDArray[np.int64]
    batch_start: NDArray[np.int64]
    whole_scan: NDArray[np.bool_]
    measured_period_s: NDArray[np.float64]


class Rules(NamedTuple):
    """The association's numbers: gate γ; scale (γ times ``PREFILTER_MARGIN``); q_max and
    omega_max (``GNNTracker.near``); max_speed_mps; confirm_m, confirm_n, delete_misses;
    the sweep's min_margin_rad, max_margin_rad, edge_fraction; the beam's cells,
    min_revisit_s, min_revisits, kept, max_pair_s, min_pair_s, beam_noise_rad; the sweep's
    skip: model_tolerance_rad, period_drift, horizon (``core.tracking.coverage``)."""

    gate: float
    scale: float
    q_max: float
    omega_max: float
    max_speed_mps: float
    confirm_m: int
    confirm_n: int
    delete_misses: int
    min_margin_rad: float
    max_margin_rad: float
    edge_fraction: float
    cells: int
    min_revisit_s: float
    min_revisits: int
    kept: int
    max_pair_s: float
    min_pair_s: float
    beam_noise_rad: float
    model_tolerance_rad: float
    period_drift: float
    horizon: float


class LiveArrays(NamedTuple):
    """The live tracks in order of initiation, at positions 0 … n − 1 (n in ``counters``),
    and what the per-batch passes over every live track read, laid out by position so that
    each pass reads its rows in order: slot (L,) the book's slot at each position (−1: a
    hole, a track deleted since the positions were last closed up, ``_close_up``); pos (K,)
    each book slot's position (−1: not live); boxes (``BOX_COLUMNS``, L) the prefilter's box
    (``core.tracking.kernels_gate.track_box``; times −∞: drawn when next needed; a hole's
    holds always and meets nothing); due_s (R, L) the earliest time each radar's sweep can
    judge the track (``_swept``; −∞: at the radar's next batch; a hole's +∞)."""

    slot: NDArray[np.int64]
    pos: NDArray[np.int64]
    boxes: NDArray[np.float64]
    due_s: NDArray[np.float64]


#: ``counters`` of ``associate_2d``: live positions (``LiveArrays``, holes included), tracks
#: started (the last id), batches, free slots (the top of ``BookArrays.free``), events
#: written, holes among the live positions.
C_LIVE, C_STARTED, C_BATCHES, C_FREE, C_EVENTS, C_HOLES = 0, 1, 2, 3, 4, 5
COUNTERS = 6
#: Event kinds (``associate_2d``'s events rows: batch, kind, slot, id).
EV_START, EV_CONFIRM, EV_DELETE = 0, 1, 2
TENTATIVE_CODE, CONFIRMED_CODE = 0, 1


@_jit
def associate_2d(pl, beams, radar_site, book, tr, rules, live, counters, since, owner,
                 status_out, row_out, start_out, events, out_x, out_P, out_nis):  # fmt: skip
    """Associate every batch of ``pl`` (``PlotArrays``) in order (module docstring): the
    beams (``BeamArrays``, R rows), the radars' sites (R, 2), the book (``BookArrays``),
    the tracks (``TrackArrays``) and the live tracks (``LiveArrays``, their number in
    counters) changed in place; since (1,) a lower bound of their last plot
    times. Writes per plot the id of its track (owner (B,)), that track's status after its
    batch (status_out (B,)), its slot (row_out (B,)), whether it started the track
    (start_out (B,)) and every method's posterior and NIS after the plot (out_x
    (B, M, 4), out_P (B, M, 4, 4), out_nis (B, M), ``track_plots_imm_2d``'s), and the events
    in order (events (E, 4): batch, kind, slot, id). Returns −1, or the index of a plot
    earlier than its track's previous one (nothing from its batch on is done). The book
    must have a free slot per plot (``C_FREE`` ≥ B); a slot freed by a deletion is reused
    from the next call on, so that a row holds one track's plots within a call (the caller
    names the rows and feeds the monitor once a call)."""
    n_plots = pl.time_s.shape[0]
    n_batches = pl.whole_scan.shape[0]
    nx = book.x.shape[1]
    # The gating method's conversion of every plot (z + s, R_ii), as the prefilter takes it.
    points, r_ii = np.empty((n_plots, 2)), np.empty((n_plots, 2))
    g = pl.noise
    # The gating conversion's scalars of each noise row (``pair_nis_2d``), and of each plot.
    co = tr.conversions[:, tr.gate, 0]
    co_plot = np.empty((n_plots, 8))
    for j in range(n_plots):
        co_plot[j] = co[g[j]]
    plot_points_2d(
        tr.plan[tr.gate, PLAN_COVARIANCE], co_plot, pl.range_m, pl.azimuth_rad, pl.sigma_r_m[g],
        pl.sigma_beta_rad[g], pl.site[g], points, r_ii,
    )  # fmt: skip
    r = tr.sigma_a_mps2.shape[0]
    x0, P0 = np.empty((r, 4)), np.empty((r, 4, 4))
    mu, cc, w = np.empty(r), np.empty(r), np.empty((r, r))
    xp, Pp = np.empty(4), np.empty((4, 4))
    # Slots freed in this call, handed to the free stack at its end (docstring).
    freed = np.empty(book.alive.shape[0], np.int64)
    n_freed = np.zeros(1, np.int64)
    bad = -1
    for b in range(n_batches):
        lo, hi = pl.batch_start[b], pl.batch_start[b + 1]
        bad = _batch(pl, beams, radar_site, book, tr, rules, live, counters, since, owner,
                     status_out, row_out, start_out, events, out_x, out_P, out_nis, freed,
                     n_freed, b, lo, hi, points, r_ii, co, nx, x0, P0, mu, cc, w, xp,
                     Pp)  # fmt: skip
        if bad >= 0:
            break
    for e in range(n_freed[0]):
        book.free[counters[C_FREE]] = freed[e]
        counters[C_FREE] += 1
    return bad


# _batch is inlined into the batch loop: a call passes some sixty arrays, each costing a
# reference count in and out, and inlined the whole association ran about 6% faster at 1000
# targets (docs/performance.md, section 5).
@_inline
def _batch(pl, beams, radar_site, book, tr, rules, live, counters, since, owner, status_out,
           row_out, start_out, events, out_x, out_P, out_nis, freed, n_freed, b, lo, hi, points,
           r_ii, co, nx, x0, P0, mu, cc, w, xp, Pp):  # fmt: skip
    """One batch, plots lo:hi (``GNNTracker._add`` and ``_manage``)."""
    n = hi - lo
    counters[C_BATCHES] += 1
    if counters[C_LIVE] + n > live.slot.shape[0]:  # room for a start per plot
        _close_up(live, counters)
    g = pl.radar[lo] if n else -1
    times = pl.time_s[lo:hi]
    if g >= 0:
        f = beams.f[g]
        beams.c[g, B_SEEN] = 1
        if math.isfinite(pl.measured_period_s[b]) and math.isnan(f[B_GIVEN_PERIOD]):
            # ``RadarBeam.measured_period``: the feed's period, from now on.
            f[B_PERIOD] = pl.measured_period_s[b]
            beams.c[g, B_MEASURED] = 1
        observe_beam(
            f, beams.c[g], beams.cells[g], beams.revisits[g], beams.ordered[g], beams.rates[g],
            beams.close[g],
            times, pl.azimuth_rad[lo:hi], pl.range_m[lo:hi], times, False, rules.cells,
            rules.min_revisit_s, rules.min_revisits, rules.kept, rules.max_pair_s,
            rules.min_pair_s, rules.beam_noise_rad,
        )  # fmt: skip
    period = beams.f[g, B_PERIOD] if g >= 0 else np.nan
    n_live = counters[C_LIVE]
    # The tracks that existed before this batch (starts append to ``live`` after them; the
    # deletions compact it at the batch's end).
    before = live.slot[:n_live]
    own = np.full(n, -1, np.int64)  # each plot's slot
    free = np.arange(n)  # plots (of the batch) not yet assigned
    n_free = n
    # The tracks that may gate one of the batch's plots, in order of initiation: a few
    # comparisons a track against its box (``boxes_near``), so that the rest below visits
    # only those.
    near = np.empty(n_live, np.int64)
    n_near = 0
    if n:
        n_near = boxes_near(
            before, book.x, book.P, book.last_s, times[0], times[n - 1], rules.q_max,
            rules.omega_max, points[lo:hi], r_ii[lo:hi], rules.scale, live.boxes, near,
        )  # fmt: skip
    for code in (CONFIRMED_CODE, TENTATIVE_CODE):  # confirmed tracks choose first
        if n_free == 0:
            continue
        slots = np.empty(n_near, np.int64)
        k = 0
        for q in range(n_near):
            s = near[q]
            if book.status[s] != code:
                continue
            # A track takes at most one plot per sweep of a radar.
            if math.isfinite(period) and not book.hit_s[s, g] <= times[0] - period / 2:
                continue
            slots[k] = s
            k += 1
        if k == 0:
            continue
        slots = slots[:k]
        fr = free[:n_free]
        cols_pl = fr + lo  # the free plots' indices in pl
        rows = np.empty(k * n_free, np.int64)
        cols = np.empty(k * n_free, np.int64)
        found = near_pairs(
            slots, book.x, book.P, book.last_s, pl.time_s[cols_pl], rules.q_max,
            rules.omega_max, points[cols_pl], r_ii[cols_pl], rules.scale, rows, cols,
        )  # fmt: skip
        d2 = np.empty(found)
        for e in range(found):
            s, j = slots[rows[e]], cols_pl[cols[e]]
            d2[e] = _gate_d2(pl, tr, s, j, co, x0, P0, mu, cc, w, xp, Pp)
            if code == TENTATIVE_CODE and book.hits[s] == 1 and _too_fast(pl, book, rules, s, j):
                d2[e] = np.inf
        out_r, out_c = np.empty(found, np.int64), np.empty(found, np.int64)
        m = sparse_assign(rows[:found], cols[:found], d2, rules.gate, k, n_free, out_r, out_c)
        taken = np.zeros(n_free, np.bool_)
        for e in range(m):
            own[fr[out_c[e]]] = slots[out_r[e]]
            taken[out_c[e]] = True
        n_keep = 0
        for q in range(n_free):
            if not taken[q]:
                free[n_keep] = fr[q]
                n_keep += 1
        n_free = n_keep
    # Hits, then starts (``_manage``).
    for j in range(n):
        s = own[j]
        if s >= 0:  # ``TrackBook.hit``
            book.hits[s] += 1
            book.expected[s] += 1
            book.misses[s] = 0
            book.last_s[s] = times[j]
            book.hit_s[s, g] = times[j]
            book.plots[s, g] += 1
            q = live.pos[s]
            live.boxes[BOX_UNTIL_S, q] = -np.inf  # its box is of its previous state
            live.due_s[:, q] = -np.inf  # so are its sweep bounds
    for q in range(n_free):  # unassigned plots start tentative tracks (``TrackBook.start``)
        j = free[q]
        counters[C_FREE] -= 1
        s = book.free[counters[C_FREE]]
        counters[C_STARTED] += 1
        ident = counters[C_STARTED]
        own[j] = s
        start_out[lo + j] = True
        book.alive[s], book.rank[s] = True, ident - 1
        book.status[s] = CONFIRMED_CODE if rules.confirm_m <= 1 else TENTATIVE_CODE
        book.hits[s], book.expected[s], book.misses[s] = 1, 1, 0
        book.born_s[s] = book.last_s[s] = times[j]
        book.hit_s[s, :] = -np.inf
        book.judged_s[s, :] = -np.inf
        book.hit_s[s, g] = times[j]
        book.plots[s, :] = 0
        book.plots[s, g] = 1
        tr.started[s] = False  # a reused slot's old track is gone
        q = counters[C_LIVE]
        live.slot[q], live.pos[s] = s, q
        live.boxes[BOX_UNTIL_S, q] = -np.inf
        live.due_s[:, q] = -np.inf
        counters[C_LIVE] += 1
        _event(events, counters, b, EV_START, s, ident)
    for j in range(n):  # the track ids: "1", "2", … in order of initiation
        owner[lo + j] = book.rank[own[j]] + 1
        row_out[lo + j] = own[j]
    # Every method's update of every plot's track, in plot order.
    if n:
        vr, none = pl.radial_velocity_mps[lo:hi], np.empty(0)
        plots = PlotColumns(
            own, times, pl.range_m[lo:hi], pl.azimuth_rad[lo:hi], none, vr, ~np.isnan(vr),
            pl.noise[lo:hi],
        )  # fmt: skip
        radars = RadarArrays(pl.site, pl.sigma_r_m, pl.sigma_beta_rad, none, pl.sigma_vr_mps)
        options = IMMOptions(
            tr.sigma_a_mps2, tr.omega, tr.Pi, tr.mu0, tr.sigma_v0_mps, tr.prm, tr.with_stats
        )
        tracks = TrackState(tr.xs, tr.Ps, tr.mus, tr.started, tr.last_t)
        outs = PlotOutputs(out_x[lo:hi], out_P[lo:hi], out_nis[lo:hi])
        bad = track_plots_imm_2d(tr.plan, tr.conversions, plots, radars, options, tracks, outs)
        if bad >= 0:
            return lo + bad
        a = tr.gate
        for j in range(n):  # each track's latest state by the gating method, for its sweeps
            s, i = own[j], lo + j
            book.x[s] = out_x[i, a, :nx]
            book.P[s] = out_P[i, a, :nx, :nx]
            book.sigma_m[s] = math.sqrt(max(out_P[i, a, 0, 0], out_P[i, a, 2, 2]))
            book.sigma_v[s] = math.sqrt(max(out_P[i, a, 1, 1], out_P[i, a, 3, 3]))
    # The sweep's misses, then confirmation and deletion, on the tracks they touch.
    due = live.due_s[max(g, 0)]  # (a batch without plots judges nothing by its bounds)
    judged = _swept(pl, beams, radar_site, book, rules, g, times, before, pl.whole_scan[b], due)
    touched = np.empty(judged.shape[0] + n, np.int64)
    nt = 0
    for s in judged:
        hit = False
        for j in range(n):
            hit = hit or own[j] == s
        if not hit:  # ``TrackBook.miss``
            book.expected[s] += 1
            book.misses[s] += 1
            touched[nt] = s
            nt += 1
    for j in range(n):
        touched[nt] = own[j]
        nt += 1
    touched = touched[:nt][np.argsort(book.rank[touched[:nt]])]  # in order of id
    doomed = np.empty(nt + n_live, np.int64)
    nd = 0
    for s in touched:  # ``TrackBook.settle``
        if book.status[s] == TENTATIVE_CODE:
            if book.hits[s] >= rules.confirm_m:
                book.status[s] = CONFIRMED_CODE
                _event(events, counters, b, EV_CONFIRM, s, book.rank[s] + 1)
            elif book.hits[s] + (rules.confirm_n - book.expected[s]) < rules.confirm_m:
                doomed[nd] = s
                nd += 1
        elif book.misses[s] >= rules.delete_misses:
            doomed[nd] = s
            nd += 1
    coast = _coast_s(beams, rules, radar_site.shape[0])
    if math.isfinite(coast) and n and times[n - 1] - coast > since[0]:
        # Some track may have coasted (``since`` bounds the live tracks' last plot times
        # from below, so the pass is skipped until one can have).
        end = times[n - 1]
        lowest = math.inf
        for s in before:  # a track started in this batch has not coasted
            if s < 0:
                continue  # a hole
            if book.last_s[s] < end - coast:
                doomed[nd] = s
                nd += 1
            else:
                lowest = min(lowest, book.last_s[s])
        since[0] = min(lowest, times[0])
    if rules.confirm_m <= 1:
        for q in range(n_free):
            s = own[free[q]]
            _event(events, counters, b, EV_CONFIRM, s, book.rank[s] + 1)
    if nd:  # deletions in order of id (``TrackBook.remove``)
        doomed = doomed[:nd][np.argsort(book.rank[doomed[:nd]])]
        for s in doomed:
            if not book.alive[s]:
                continue  # doomed twice
            book.alive[s] = False
            st = book.status[s]
            for a in range(book.folded.shape[0]):
                book.folded[a, st] += book.plots[s, a]
            freed[n_freed[0]] = s  # to the free stack at the call's end
            n_freed[0] += 1
            _event(events, counters, b, EV_DELETE, s, book.rank[s] + 1)
            # Its position becomes a hole, closed up with the others once they are many.
            q = live.pos[s]
            live.slot[q], live.pos[s] = -1, -1
            live.boxes[BOX_X_LO, q], live.boxes[BOX_X_HI, q] = np.inf, -np.inf
            live.boxes[BOX_Y_LO, q], live.boxes[BOX_Y_HI, q] = np.inf, -np.inf
            live.boxes[BOX_FROM_S, q], live.boxes[BOX_UNTIL_S, q] = -np.inf, np.inf
            live.due_s[:, q] = np.inf
            counters[C_HOLES] += 1
        if counters[C_HOLES] > max(16, counters[C_LIVE] // 4):
            _close_up(live, counters)
    for j in range(n):
        s = own[j]
        # A track deleted at this batch cannot have a plot in it (it was missed).
        status_out[lo + j] = book.status[s] if book.alive[s] else TENTATIVE_CODE
    return -1


@_jit
def _close_up(live, counters):
    """Close up the holes of the live positions (``LiveArrays``), in order."""
    keep = 0
    for q in range(counters[C_LIVE]):
        s = live.slot[q]
        if s < 0:
            continue
        if keep != q:
            live.slot[keep], live.pos[s] = s, keep
            live.boxes[:, keep] = live.boxes[:, q]
            live.due_s[:, keep] = live.due_s[:, q]
        keep += 1
    counters[C_LIVE], counters[C_HOLES] = keep, 0


@_jit
def _event(events, counters, b, kind, slot, ident):
    e = counters[C_EVENTS]
    events[e, 0], events[e, 1], events[e, 2], events[e, 3] = b, kind, slot, ident
    counters[C_EVENTS] = e + 1


@_jit
def _coast_s(beams, rules, n_radars) -> float:
    """``GNNTracker.coast_s``: ``delete_misses`` + 1 revolutions of the slowest radar seen
    whose period is known; NaN when none is."""
    top = np.nan
    for a in range(n_radars):
        p = beams.f[a, B_PERIOD]
        if beams.c[a, B_SEEN] and math.isfinite(p) and not p <= top:
            top = p
    return (rules.delete_misses + 1) * top


@_jit
def _gate_d2(pl, tr, s, j, co, x0, P0, mu, cc, w, xp, Pp) -> float:
    """d² of plot j against slot s's gating track predicted to the plot's time
    (``core.filters.kernels_imm.pair_nis_2d``, the statistic of ``gate_nis_imm_2d``; co
    (T, 8) the conversion's scalars of each noise row); ∞ for a NaN."""
    g, a = pl.noise[j], tr.gate
    d2 = pair_nis_2d(
        tr.xs[s, a], tr.Ps[s, a], tr.mus[s, a], pl.time_s[j] - tr.last_t[s], tr.sigma_a_mps2,
        tr.omega, tr.Pi, tr.plan[a], pl.range_m[j], pl.azimuth_rad[j], pl.sigma_r_m[g],
        pl.sigma_beta_rad[g], pl.site[g, 0], pl.site[g, 1], co[g], x0, P0, mu, cc, w, xp, Pp,
    )  # fmt: skip
    return d2 if math.isfinite(d2) else np.inf


@_jit
def _too_fast(pl, book, rules, s, j) -> bool:
    """``GNNTracker._too_fast`` of one pair (slot s holds one plot): plot j only reachable
    faster than ``max_speed_mps``."""
    g = pl.noise[j]
    r, b = pl.range_m[j], pl.azimuth_rad[j]
    px = pl.site[g, 0] + r * math.cos(b)
    py = pl.site[g, 1] + r * math.sin(b)
    dx, dy = px - book.x[s, 0], py - book.x[s, 2]
    gap = math.sqrt(dx * dx + dy * dy)
    dt = pl.time_s[j] - book.last_s[s]
    sigma = pl.sigma_r_m[g] + r * pl.sigma_beta_rad[g]
    reach = rules.max_speed_mps * dt + 3.0 * (sigma + book.sigma_m[s])
    return gap > reach


@_jit
def _swept(pl, beams, radar_site, book, rules, g, times, slots, whole_scan, due):
    """``GNNTracker._swept``: the slots among ``slots`` this batch's sweep judges (passed by
    the beam inside the radar's coverage, not judged in this sweep already), their
    ``judged_s`` set; the beam's sweep start moved (``RadarBeam.swept``).

    A rotating radar's batch sweeps a degree or two, so most tracks cannot be judged by it;
    slots[q] is tested only once the batch's end reaches due[q] (``LiveArrays.due_s`` of
    the radar), the earliest time the test can pass (``_due``), set at its previous test and
    reset by a hit. The bounds hold under the radar's beam model (``core.tracking.coverage``,
    ``SWEEP_BEAM_TOLERANCE_RAD``): a batch that leaves the model starts a new one and tests
    every slot, so the slots judged are those of testing every slot at every batch."""
    if slots.shape[0] == 0:
        return slots
    if g < 0:
        return slots if whole_scan else slots[:0]
    f, c = beams.f[g], beams.c[g]
    n = times.shape[0]
    end = times[n - 1]
    whole = whole_scan or (c[B_SAME] > c[B_OTHER] and times[0] == times[n - 1])
    period = f[B_PERIOD]
    known = math.isfinite(period)
    start = f[B_SWEPT_TO]
    f[B_SWEPT_TO] = end
    direction = 1.0 if c[B_TURN_POS] >= c[B_TURN_NEG] else -1.0
    # The coverage: given, else (unless a whole scan handed in) the extremes seen.
    lo_r = f[B_RANGE_LO] if not whole_scan else 0.0
    hi_r = f[B_RANGE_HI] if not whole_scan else math.inf
    if not math.isnan(f[B_GIVEN_MIN_R]):
        lo_r = f[B_GIVEN_MIN_R]
    if not math.isnan(f[B_GIVEN_MAX_R]):
        hi_r = f[B_GIVEN_MAX_R]
    out = np.empty(slots.shape[0], np.int64)
    k = 0
    if not whole and (math.isnan(start) or not known):
        return out[:0]  # no sweep to judge by yet (``RadarBeam.swept``)
    half = period / 2
    turned = TWO_PI * (end - start) / period if not whole else 0.0
    # The beam's direction, for a test that needs no arctangent: a track more than its
    # margin plus the turn away from the beam cannot be in the swept window.
    bx, by = math.cos(f[B_LAST_AZ]), math.sin(f[B_LAST_AZ])
    window = not whole and turned < TWO_PI
    # The beam model of the skip: kept while this batch agrees with it, else started anew
    # here (and every slot tested, its bounds worked out under the new model).
    skip = False
    model_az = 0.0
    if not whole:
        t0, p0 = f[B_MODEL_S], f[B_MODEL_PERIOD]
        model_az = f[B_MODEL_AZ] + direction * TWO_PI * (end - t0) / p0
        skip = (
            f[B_MODEL_DIR] == direction
            and abs(period - p0) <= rules.period_drift * p0
            and abs(_wrap(f[B_LAST_AZ] - model_az)) <= rules.model_tolerance_rad
        )  # NaN (no model yet): False
        if not skip:
            f[B_MODEL_S], f[B_MODEL_AZ], f[B_MODEL_PERIOD] = end, f[B_LAST_AZ], period
            f[B_MODEL_DIR] = direction
            model_az = f[B_MODEL_AZ]
    # A slot judged or hit within half a period is not judged before then.
    half_low = (1.0 - rules.period_drift) * f[B_MODEL_PERIOD] / 2
    for q in range(slots.shape[0]):
        s = slots[q]
        if (skip and end < due[q]) or s < 0:  # not yet, or a hole
            continue
        if known and not whole:
            # Judged or hit by this radar within half a period of the end: not this sweep's.
            if not (book.judged_s[s, g] + half < end and book.hit_s[s, g] <= end - half):
                due[q] = max(book.judged_s[s, g], book.hit_s[s, g]) + half_low
                continue
        ahead = end - book.last_s[s]
        px = book.x[s, 0] + book.x[s, 1] * ahead
        py = book.x[s, 2] + book.x[s, 3] * ahead
        sv = book.sigma_v[s] * ahead
        sigma = math.sqrt(book.sigma_m[s] * book.sigma_m[s] + sv * sv)
        rx, ry = px - radar_site[g, 0], py - radar_site[g, 1]
        rng = math.sqrt(rx * rx + ry * ry)
        margin = _margin(sigma, max(rng, 1.0), rules)
        if not whole:
            due[q] = end + _due(
                rx, ry, rng, book.x[s, 1], book.x[s, 3], sigma, book.sigma_m[s],
                book.sigma_v[s], ahead, model_az, direction, f[B_MODEL_PERIOD], rules,
            )  # fmt: skip
        if window:
            # The angle θ to the beam exceeds φ = margin + turn when cos θ < 1 − φ²/2 ≤ cos φ
            # (less a rounding allowance): outside the window whatever the exact angle.
            phi = margin + turned
            if rx * bx + ry * by < (1.0 - 0.5 * phi * phi - 1e-9) * rng:
                continue
        if whole:
            passed, passed_s = True, end
        else:
            az = math.atan2(ry, rx)
            delta = (direction * (f[B_LAST_AZ] - az)) % TWO_PI
            passed_s = end - delta * (period / TWO_PI)
            passed = delta > margin and (turned >= TWO_PI or delta <= margin + turned)
        edge = 3.0 * book.sigma_m[s] + rules.edge_fraction * rng
        ok = passed and rng >= lo_r + edge and rng <= hi_r - edge
        ok = ok and book.born_s[s] < passed_s
        if known and not whole:
            ok = ok and passed_s > book.judged_s[s, g] + half
            # A plot of this sweep already came (the beam passed it a little early).
            ok = ok and book.hit_s[s, g] <= passed_s - half
        if ok:
            book.judged_s[s, g] = passed_s
            out[k] = s
            k += 1
    return out[:k]


@_inline
def _margin(sigma, rng, rules) -> float:
    """A track's azimuth margin (``core.tracking.coverage``): 3σ of its position over its
    range, within [``min_margin_rad``, ``max_margin_rad``]."""
    return min(max(3.0 * sigma / rng, rules.min_margin_rad), rules.max_margin_rad)


@_jit
def _due(rx, ry, rng, vx, vy, sigma, sigma_m, sigma_v, ahead, model_az, direction, model_period,
         rules) -> float:  # fmt: skip
    """How long after now (τ ≥ 0, s) a radar's sweep can first judge a track, at (rx, ry)
    from the radar (range rng), moving at (vx, vy), its predicted position σ now ``sigma``
    (from σ_m, σ_v and ``ahead``, ``_swept``), under the beam model (``_swept``):
    β(now + τ) = model_az + d ω τ + e, |e| ≤ ε (``model_tolerance_rad``), ω = 2π / T.

    The sweep judges at τ only if δ = (d (β − φ)) mod 2π, φ the track's predicted azimuth,
    lies in (m, m + s], m its margin and s ≤ ω' τ the beam's turn since the previous batch
    (ω' = ω (1 + ρ), the period estimate within ρ of T). Over τ ≤ H (``horizon``
    revolutions) the range stays within r ± |v| H, so φ moves at most a τ with
    a = |v| / (r − |v| H), and m (3σ over the range, σ growing with the time ahead, clamped)
    stays within [m₋, m₊]; take a' = a + ω ρ. With u = d (β₀ − φ₀) mod 2π,
    δ + 2πk = u + ω τ ± (ε + a' τ) for some integer k, and the window needs
    u + ω τ + ε + a' τ − 2πk > m₋ and u − ε − a' τ − 2πk ≤ m₊. The earliest τ for k = 0, 1
    and −1 (any other k comes later) is the bound, at most H; 0 where a track may move too
    fast about the radar (near it) for one."""
    omega = TWO_PI / model_period
    eps = rules.model_tolerance_rad
    horizon = rules.horizon * model_period
    speed = math.sqrt(vx * vx + vy * vy)
    least = rng - speed * horizon
    if least <= 1.0:
        return 0.0
    sv = sigma_v * (ahead + horizon)
    sigma_hi = math.sqrt(sigma_m * sigma_m + sv * sv)
    lo, hi = _margin(sigma, rng + speed * horizon, rules), _margin(sigma_hi, least, rules)
    a = speed / least + omega * rules.period_drift
    u = (direction * (model_az - math.atan2(ry, rx))) % TWO_PI
    closing = omega + a
    tau0 = max((lo - u - eps) / closing, (u - eps - hi) / a, 0.0)  # k = 0
    tau1 = (TWO_PI + lo - u - eps) / closing  # k = 1
    tau_1 = (u + TWO_PI - eps - hi) / a  # k = −1
    return max(min(tau0, tau1, tau_1, horizon), 0.0)
