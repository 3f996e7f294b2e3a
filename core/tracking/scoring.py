"""Scoring a tracker's output against the truth: GOSPA, purity, fragmentation, swaps, RMSE and
NEES, from arrays (``viz_app.io.score_files`` reads the files; ``radarviz score`` prints).

**Estimates at a truth time.** The truth is sampled at times t₁ < … < t_K, with the targets
present at t_k. A track's rows (one per update) are at its own times; at t_k the track is
*reported* when its last row at or before t_k, at time s with state (x, v), is no older than
Δt_max (``score_max_gap_s``):

    x̂(t_k) = x + v (t_k − s),   v̂(t_k) = v,       reported iff 0 ≤ t_k − s ≤ Δt_max,

the constant-velocity prediction (of rows at one time, the last in file order). Only
confirmed tracks are reported when the rows carry a status (the status of that last row),
unless every track is asked for. Positions are compared in 3D when both the truth and the
tracks are 3D, else in the x–y plane.

**Assignment.** At each t_k the truth X (m points) and the reported tracks Y (n points) are
assigned by GOSPA's optimal assignment γ*_k (``core.tracking.gospa``: one linear assignment,
pairs closer than the cut-off c). Every pair-based figure below uses these pairs.

**GOSPA** (α = 2, order p, cut-off c): d_k = (L_k + M_k + F_k)^(1/p) with the localisation
L_k = Σ_{γ*_k} d(x_i, y_j)^p, the missed part M_k = c^p/2 (m − |γ*_k|) and the false part
F_k = c^p/2 (n − |γ*_k|); reported as the time means d̄ = (1/K) Σ_k d_k, L̄, M̄, F̄ (the parts
in m^p).

**Purity.** Track j is reported at n_j truth times and assigned to truth target i at n_ij of
them; its purity is max_i n_ij / n_j (its dominant target's share; a track never assigned
has purity 0), and the file's is the weighted Σ_j max_i n_ij / Σ_j n_j.

**Fragmentation.** Along target i's truth times, a *segment* is a maximal run of consecutive
times assigned to one and the same track (an unassigned time ends it); the target's
fragmentation is (segments − 1)⁺ and the file's the sum over targets.

**Swaps.** Target i *swaps* at t_k when it is assigned to track j, its previous assignment
(at any earlier time) was to a track j' ≠ j, and j was already reported before t_k: an
identity switch onto an existing track (a handover to a new track after a loss is
fragmentation, not a swap). The optimal assignment can flicker between two tracks close
together at a crossing; the CLEAR MOT count of ``TrackCounter`` (a target keeps a valid
match) is reported beside it, with its false tracks.

**RMSE.** Over the N assigned pairs, √((1/N) Σ |x̂ − x|²) for the position and, when the truth
has velocities, √((1/N) Σ |v̂ − v|²) for the velocity.

**NEES.** ε = e^T P^(−1) e of the position error e with the row's position covariance P, over
the assigned pairs whose row is at the truth time (within ``SAME_TIME_S``: a file carries no
process noise to predict P with) and whose P is positive definite. A consistent filter's
mean ε̄ over N such pairs of dimension D has N ε̄ ~ χ²(N D) (independent pairs: Bar-Shalom,
Li and Kirubarajan 2001, sec. 5.4.2), so ε̄ is in [χ²_{ND, 0.025}, χ²_{ND, 0.975}]/N with
probability 0.95; the pairs of one track are correlated in time, so read it as a check.

**Bands over time.** GOSPA and the RMSEs come from one run: their 95% bands are the
delete-a-group jackknife (``core.confidence.jackknife_band``, Student's t with G − 1 degrees
of freedom) over G = min(10, ⌊K/2⌋) *contiguous* blocks of truth times, so that errors
correlated over neighbouring times stay inside a block; fewer than 4 truth times give no
band. The lower end is clipped at 0 (each figure is ≥ 0). Counts (purity, fragmentation,
swaps) describe this file exactly and carry no band.

Pure numpy/scipy: no file I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.chi2 import chi2_quantile
from radarviz.core.confidence import jackknife_band
from radarviz.core.params import check, default
from radarviz.core.tracking.gospa import TrackCounter, gospa

#: Contiguous blocks of truth times of the jackknife bands (at most; module docstring).
BLOCKS = 10
#: Fewest truth times that give a band (two blocks of two).
MIN_BAND_TIMES = 4
#: A track row this close to a truth time is at it: its covariance is the filter's own there.
SAME_TIME_S = 1e-6
#: Two-sided probability of every band.
BAND_LEVEL = 0.95


class Truth(NamedTuple):
    """The truth, one entry per truth time and target (any order).

    Attributes:
        times_s: (K,) times.
        targets: (K,) target labels.
        position_m: (K, d) positions, d = 2 (x, y) or 3 (x, y, z).
        velocity_mps: (K, dv) velocities (dv = 2 or 3), or None.
    """

    times_s: NDArray[np.float64]
    targets: NDArray[np.str_]
    position_m: NDArray[np.float64]
    velocity_mps: NDArray[np.float64] | None = None


class TrackRows(NamedTuple):
    """One method's track rows (any order; rows at one time keep their order).

    Attributes:
        times_s: (R,) row times.
        tracks: (R,) track labels.
        position_m: (R, 3) x, y, z (z = 0 for a 2D track).
        velocity_mps: (R, 3) vx, vy, vz, or None (then a track is held still between rows).
        position_cov_m2: (R, 3, 3) position covariance, or None.
        confirmed: (R,) the track is confirmed after the row, or None (every row counts).
    """

    times_s: NDArray[np.float64]
    tracks: NDArray[np.str_]
    position_m: NDArray[np.float64]
    velocity_mps: NDArray[np.float64] | None = None
    position_cov_m2: NDArray[np.float64] | None = None
    confirmed: NDArray[np.bool_] | None = None


@dataclass(frozen=True)
class ScoreOptions:
    """The scoring's parameters (``core.params``; module docstring).

    Attributes:
        gospa_cutoff_m, gospa_order: GOSPA's c (m) and p.
        score_max_gap_s: Δt_max, the longest prediction from a track's last row (s).
        confirmed_only: report only confirmed tracks (where the rows carry a status).
    """

    gospa_cutoff_m: float = default("gospa_cutoff_m")
    gospa_order: float = default("gospa_order")
    score_max_gap_s: float = default("score_max_gap_s")
    confirmed_only: bool = True

    def __post_init__(self) -> None:
        check("gospa_cutoff_m", self.gospa_cutoff_m)
        check("gospa_order", self.gospa_order)
        check("score_max_gap_s", self.score_max_gap_s)


class Band(NamedTuple):
    """A figure and its 95% band; ``value`` None with ``reason`` where it is undefined, the
    band None with ``reason`` where only the band is."""

    value: float | None
    lo: float | None = None
    hi: float | None = None
    reason: str = ""


class Nees(NamedTuple):
    """The mean position NEES over ``pairs`` pairs of dimension ``dof`` and the 95% band a
    consistent filter's mean falls in; ``verdict``: "within", "above" or "below" the band.
    ``excluded``: assigned pairs left out (their row not at the truth time, or P singular)."""

    mean: float
    lo: float
    hi: float
    pairs: int
    dof: int
    verdict: str
    excluded: int


class Reported(NamedTuple):
    """The tracks reported at the truth times, sorted by time index then track.

    Attributes:
        time_index: (Q,) index k of the truth time.
        track: (Q,) index into the track names.
        row: (Q,) the track's row the estimate is predicted from.
        gap_s: (Q,) t_k − the row's time (≥ 0).
        position_m, velocity_mps: (Q, 3) the predicted estimate (velocity None as the rows').
    """

    time_index: NDArray[np.intp]
    track: NDArray[np.intp]
    row: NDArray[np.intp]
    gap_s: NDArray[np.float64]
    position_m: NDArray[np.float64]
    velocity_mps: NDArray[np.float64] | None


class TrackPurity(NamedTuple):
    """One track: its purity, the truth times it was reported at, its dominant target
    (None: never assigned)."""

    purity: float
    times: int
    target: str | None


class MethodScore(NamedTuple):
    """Every figure of one method against the truth (module docstring).

    Attributes:
        dims: 2 or 3, the position's coordinates compared.
        times, targets: truth times K and truth targets.
        tracks: tracks reported at one truth time or more.
        gospa, localisation, missed, false: time means and bands (distance m, parts m^p).
        gospa_per_time: (K, 4) distance and parts per truth time.
        purity: the weighted purity (value None: no track reported).
        track_purity: per reported track.
        fragmentation, target_segments: the file's fragmentation; segments per target.
        swaps, target_swaps: identity switches onto existing tracks, in all and per target.
        clear_mot_swaps, clear_mot_false_tracks: ``TrackCounter``'s counts.
        pairs: assigned (truth, track) pairs over all times.
        position_rmse, velocity_rmse: RMSE bands (velocity None: the truth has none, or the
            tracks).
        nees: the position NEES, or None with ``nees_reason``.
    """

    dims: int
    times: int
    targets: int
    tracks: int
    gospa: Band
    localisation: Band
    missed: Band
    false: Band
    gospa_per_time: NDArray[np.float64]
    purity: Band
    track_purity: dict[str, TrackPurity]
    fragmentation: int
    target_segments: dict[str, int]
    swaps: int
    target_swaps: dict[str, int]
    clear_mot_swaps: int
    clear_mot_false_tracks: int
    pairs: int
    position_rmse: Band
    velocity_rmse: Band | None
    nees: Nees | None
    nees_reason: str


def rows_are_3d(rows: TrackRows) -> bool:
    """Whether the tracks are 3D: a z or a z variance that is not 0 (a 2D track file writes
    z = 0 and every z covariance 0)."""
    if np.any(rows.position_m[:, 2] != 0.0):
        return True
    return rows.position_cov_m2 is not None and bool(np.any(rows.position_cov_m2[:, 2, 2] > 0))


def scoring_dims(truth: Truth, rows: TrackRows) -> int:
    """3 when both the truth and the tracks are 3D, else 2 (the x–y plane)."""
    return 3 if truth.position_m.shape[1] == 3 and rows_are_3d(rows) else 2


def report_tracks(
    rows: TrackRows, times_s: NDArray[np.float64], max_gap_s: float, confirmed_only: bool
) -> tuple[NDArray[np.str_], Reported]:
    """The tracks reported at each of ``times_s`` (sorted) and their constant-velocity
    estimates (module docstring); returns the track names and the reported entries."""
    names, code = np.unique(np.asarray(rows.tracks), return_inverse=True)
    n_rows = len(rows.times_s)
    order = np.lexsort((np.arange(n_rows), rows.times_s, code))  # track, time, file order
    starts = np.searchsorted(code[order], np.arange(len(names) + 1))
    k_all, j_all, r_all = [], [], []
    for j in range(len(names)):
        seg = order[starts[j] : starts[j + 1]]
        idx = np.searchsorted(rows.times_s[seg], times_s, side="right") - 1
        ok = idx >= 0
        r = seg[np.maximum(idx, 0)]
        ok &= times_s - rows.times_s[r] <= max_gap_s
        if confirmed_only and rows.confirmed is not None:
            ok &= rows.confirmed[r]
        k = np.flatnonzero(ok)
        k_all.append(k)
        j_all.append(np.full(len(k), j, dtype=np.intp))
        r_all.append(r[k])
    k = np.concatenate(k_all) if k_all else np.zeros(0, dtype=np.intp)
    j = np.concatenate(j_all) if j_all else np.zeros(0, dtype=np.intp)
    r = np.concatenate(r_all) if r_all else np.zeros(0, dtype=np.intp)
    sort = np.lexsort((j, k))
    k, j, r = k[sort].astype(np.intp), j[sort], r[sort].astype(np.intp)
    gap = times_s[k] - rows.times_s[r]
    pos = rows.position_m[r].copy()
    vel = None
    if rows.velocity_mps is not None:
        vel = rows.velocity_mps[r]
        pos += vel * gap[:, None]
    return names, Reported(k, j, r, gap, pos, vel)


def _starts(index: NDArray[np.intp], n: int) -> NDArray[np.intp]:
    """Where each of 0 … n − 1 starts in the sorted ``index`` (n + 1 entries)."""
    return np.searchsorted(index, np.arange(n + 1)).astype(np.intp)


def _blocks(k: int) -> list[NDArray[np.intp]]:
    """The contiguous blocks of truth time indices of the bands (none below 4 times)."""
    if k < MIN_BAND_TIMES:
        return []
    return np.array_split(np.arange(k), min(BLOCKS, k // 2))


def _no_band_reason(k: int) -> str:
    return f"no band: {k} truth time(s), a band needs {MIN_BAND_TIMES}"


def mean_band(per_time: NDArray[np.float64]) -> Band:
    """The time mean of ``per_time`` (K,) and its block-jackknife band (module docstring)."""
    k = len(per_time)
    if k == 0:
        return Band(None, reason="no truth times")
    value = float(per_time.mean())
    blocks = _blocks(k)
    if not blocks:
        return Band(value, reason=_no_band_reason(k))
    total = per_time.sum()
    leave = np.array([(total - per_time[b].sum()) / (k - len(b)) for b in blocks])
    lo, hi = jackknife_band(value, leave, BAND_LEVEL)
    return Band(value, max(float(lo), 0.0), float(hi))


def rmse_band(sq_sum: NDArray[np.float64], count: NDArray[np.int64]) -> Band:
    """√(Σ_k S_k / Σ_k N_k) of per-time squared-error sums S_k over N_k pairs, and its
    block-jackknife band (module docstring)."""
    n = int(count.sum())
    if n == 0:
        return Band(None, reason="no assigned pairs")
    value = math.sqrt(float(sq_sum.sum()) / n)
    blocks = _blocks(len(sq_sum))
    if not blocks:
        return Band(value, reason=_no_band_reason(len(sq_sum)))
    s_tot = float(sq_sum.sum())
    leave = []
    for b in blocks:
        rest = n - int(count[b].sum())
        leave.append(math.sqrt((s_tot - float(sq_sum[b].sum())) / rest) if rest else math.nan)
    lo, hi = jackknife_band(value, np.array(leave), BAND_LEVEL)
    if not (math.isfinite(float(lo)) and math.isfinite(float(hi))):
        return Band(value, reason="no band: fewer than two blocks of times with pairs")
    return Band(value, max(float(lo), 0.0), float(hi))


def nees_band(pairs: int, dof: int, level: float = BAND_LEVEL) -> tuple[float, float]:
    """The band of a consistent filter's mean NEES over ``pairs`` pairs of dimension ``dof``:
    [χ²_{N D, (1 − level)/2}, χ²_{N D, (1 + level)/2}] / N (``core.chi2``)."""
    nd = pairs * dof
    tail = (1.0 - level) / 2.0
    return chi2_quantile(tail, nd) / pairs, chi2_quantile(1.0 - tail, nd) / pairs


def position_nees(
    errors: NDArray[np.float64], covariances: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """ε = eᵀ P⁻¹ e of errors (N, D) with covariances (N, D, D), and which P are positive
    definite (ε of the others is 0 and must not be used)."""
    if len(errors) == 0:
        return np.zeros(0), np.zeros(0, dtype=bool)
    sym = 0.5 * (covariances + np.swapaxes(covariances, 1, 2))
    ok = np.linalg.eigvalsh(sym)[:, 0] > 0.0
    eps = np.zeros(len(errors))
    if ok.any():
        sol = np.linalg.solve(sym[ok], errors[ok][..., None])[..., 0]
        eps[ok] = np.einsum("nd,nd->n", errors[ok], sol)
    return eps, ok


def _nees(eps: NDArray[np.float64], dof: int, excluded: int) -> Nees:
    n = len(eps)
    mean = float(eps.mean())
    lo, hi = nees_band(n, dof)
    verdict = "within" if lo <= mean <= hi else ("above" if mean > hi else "below")
    return Nees(mean, lo, hi, n, dof, verdict, excluded)


def score_tracks(truth: Truth, rows: TrackRows, options: ScoreOptions) -> MethodScore:
    """Score one method's track rows against the truth (module docstring)."""
    c, p = options.gospa_cutoff_m, options.gospa_order
    d = scoring_dims(truth, rows)
    times, t_index = np.unique(truth.times_s, return_inverse=True)
    target_names, t_code = np.unique(np.asarray(truth.targets), return_inverse=True)
    order = np.lexsort((t_code, t_index))
    t_index, t_code = t_index[order], t_code[order]
    x_true = truth.position_m[order][:, :d]
    dv = 0
    v_true = None
    if truth.velocity_mps is not None and rows.velocity_mps is not None:
        dv = min(truth.velocity_mps.shape[1], d)
        v_true = truth.velocity_mps[order][:, :dv]
    K = len(times)
    names, rep = report_tracks(rows, times, options.score_max_gap_s, options.confirmed_only)
    y_all = rep.position_m[:, :d]
    t_start, r_start = _starts(t_index, K), _starts(rep.time_index, K)

    per_time = np.zeros((K, 4))
    pos_sq, vel_sq = np.zeros(K), np.zeros(K)
    n_pairs = np.zeros(K, dtype=np.int64)
    assigned = np.full(len(t_code), -1, dtype=np.intp)  # truth entry → reported entry
    counter = TrackCounter(c)
    track_names = [str(s) for s in names]
    for k in range(K):
        a, b = t_start[k], t_start[k + 1]
        q, r = r_start[k], r_start[k + 1]
        g = gospa(x_true[a:b], y_all[q:r], c, p)
        per_time[k] = (g.distance, g.localisation, g.missed, g.false)
        i, j = g.assigned[:, 0] + a, g.assigned[:, 1] + q
        assigned[i] = j
        n_pairs[k] = len(i)
        pos_sq[k] = float(((y_all[j] - x_true[i]) ** 2).sum())
        if v_true is not None and rep.velocity_mps is not None:
            vel_sq[k] = float(((rep.velocity_mps[j, :dv] - v_true[i]) ** 2).sum())
        counter.add(
            [int(x) for x in t_code[a:b]],
            x_true[a:b],
            [track_names[x] for x in rep.track[q:r]],
            y_all[q:r],
        )

    pairs = assigned >= 0
    i_pair = np.flatnonzero(pairs)
    j_pair = assigned[i_pair]
    track_of_truth = np.where(pairs, rep.track[np.maximum(assigned, 0)], -1)
    purity, track_purity = _purity(track_names, target_names, rep, t_code[i_pair], j_pair)
    segments, fragmentation = _fragmentation(target_names, t_code, track_of_truth)
    target_swaps = _swaps(target_names, t_code, t_index, track_of_truth, rep, len(names))

    nees, reason = None, "the track file has no position covariance"
    if rows.position_cov_m2 is not None:
        exact = np.abs(rep.gap_s[j_pair]) <= SAME_TIME_S
        ie, je = i_pair[exact], j_pair[exact]
        cov = rows.position_cov_m2[rep.row[je]][:, :d, :d]
        eps, ok = position_nees(y_all[je] - x_true[ie], cov)
        excluded = len(i_pair) - int(ok.sum())
        if ok.any():
            nees, reason = _nees(eps[ok], d, excluded), ""
        else:
            reason = (
                "no assigned pair at a track row's own time with a positive-definite "
                "covariance (a covariance is not predicted: the file has no process noise)"
            )
    vel_rmse = None if v_true is None else rmse_band(vel_sq, n_pairs)
    return MethodScore(
        dims=d,
        times=K,
        targets=len(target_names),
        tracks=len(np.unique(rep.track)),
        gospa=mean_band(per_time[:, 0]),
        localisation=mean_band(per_time[:, 1]),
        missed=mean_band(per_time[:, 2]),
        false=mean_band(per_time[:, 3]),
        gospa_per_time=per_time,
        purity=purity,
        track_purity=track_purity,
        fragmentation=fragmentation,
        target_segments=segments,
        swaps=sum(target_swaps.values()),
        target_swaps=target_swaps,
        clear_mot_swaps=counter.swaps,
        clear_mot_false_tracks=counter.false_tracks,
        pairs=len(i_pair),
        position_rmse=rmse_band(pos_sq, n_pairs),
        velocity_rmse=vel_rmse,
        nees=nees,
        nees_reason=reason,
    )


def _purity(
    track_names: list[str],
    target_names: NDArray[np.str_],
    rep: Reported,
    pair_target: NDArray[np.intp],
    pair_entry: NDArray[np.intp],
) -> tuple[Band, dict[str, TrackPurity]]:
    """The weighted purity and each reported track's (module docstring)."""
    n_tracks, n_targets = len(track_names), len(target_names)
    reported = np.bincount(rep.track, minlength=n_tracks)
    counts = np.zeros((n_tracks, n_targets), dtype=np.int64)
    np.add.at(counts, (rep.track[pair_entry], pair_target), 1)
    per: dict[str, TrackPurity] = {}
    for j in np.flatnonzero(reported):
        best = int(counts[j].max()) if n_targets else 0
        target = str(target_names[int(counts[j].argmax())]) if best else None
        per[track_names[j]] = TrackPurity(best / int(reported[j]), int(reported[j]), target)
    total = int(reported.sum())
    if total == 0:
        return Band(None, reason="no track reported at any truth time"), per
    dominant = int(counts.max(axis=1).sum()) if n_targets else 0
    return Band(dominant / total, reason="an exact count of this file: no band"), per


def _fragmentation(
    target_names: NDArray[np.str_], t_code: NDArray[np.intp], track_of: NDArray[np.intp]
) -> tuple[dict[str, int], int]:
    """Segments per target and the file's fragmentation Σ (segments − 1)⁺ (module docstring);
    the truth entries are in time order."""
    segments: dict[str, int] = {}
    for i, name in enumerate(target_names):
        seq = track_of[t_code == i]
        start = (seq >= 0) & np.concatenate([[True], seq[1:] != seq[:-1]])
        segments[str(name)] = int(start.sum())
    return segments, sum(max(s - 1, 0) for s in segments.values())


def _swaps(
    target_names: NDArray[np.str_],
    t_code: NDArray[np.intp],
    t_index: NDArray[np.intp],
    track_of: NDArray[np.intp],
    rep: Reported,
    n_tracks: int,
) -> dict[str, int]:
    """Identity switches per target onto a track reported before (module docstring)."""
    first = np.full(n_tracks, np.iinfo(np.intp).max, dtype=np.intp)
    np.minimum.at(first, rep.track, rep.time_index)
    out: dict[str, int] = {}
    for i, name in enumerate(target_names):
        mine = t_code == i
        last, swaps = -1, 0
        for k, j in zip(t_index[mine].tolist(), track_of[mine].tolist(), strict=True):
            if j < 0:
                continue
            if last >= 0 and j != last and first[j] < k:
                swaps += 1
            last = j
        out[str(name)] = swaps
    return out
