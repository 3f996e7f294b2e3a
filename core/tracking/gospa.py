"""GOSPA: the generalised optimal sub-pattern assignment metric between two finite sets, and
the track-swap and false-track counts of a tracker against the truth.

García-Fernández, Rahmathullah and Svensson (2017), "Generalized optimal sub-pattern
assignment metric", eq. (1) with α = 2 and their Proposition 1: for the truth X = {x₁ … x_m},
the estimates Y = {y₁ … y_n}, a base distance d (here Euclidean, m), a cut-off c > 0 and an
order 1 ≤ p < ∞,

    d_p^(c,2)(X, Y) = ( min_γ [ Σ_{(i,j)∈γ} d(x_i, y_j)^p + c^p/2 · (m + n − 2|γ|) ] )^(1/p)

over the assignments γ ⊂ {1…m} × {1…n} (each index used at most once) whose pairs all have
d(x_i, y_j) < c. The minimum splits into three parts, each a p-th power:

    localisation  Σ_{(i,j)∈γ*} d(x_i, y_j)^p,
    missed        c^p/2 · (m − |γ*|)     (truth with no estimate),
    false         c^p/2 · (n − |γ*|)     (estimates with no truth),

so d^p = localisation + missed + false. The minimising γ* is one
``scipy.optimize.linear_sum_assignment`` on the costs min(d, c)^p − c^p: a pair at d ≥ c
costs 0, as two unassigned points do (c^p/2 each, against c^p for a pair at the cut-off),
and is dropped.

Track swaps and false tracks (``TrackCounter``) follow the matching of the CLEAR MOT metrics
(Bernardin and Stiefelhagen 2008): at each scan a truth keeps the track it was matched to at
its last match if that track is still reported within the cut-off c of it; the truths and
tracks left are matched by the assignment above (GOSPA's, pairs closer than c). A truth's
*swap* is a match to another track than its last match (an identity switch; keeping a valid
match first stops two tracks that run close together at a crossing from counting as swapped
whenever the optimal assignment flickers between them). A *false track* is a reported track
matched to a truth at fewer than half of the scans it was reported.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.params import check


class Gospa(NamedTuple):
    """GOSPA between two sets and its decomposition (the parts are p-th powers, m^p).

    Attributes:
        distance: d_p^(c,2) (m).
        localisation, missed, false: the three parts; distance^p is their sum.
        assigned: (|γ*|, 2) the (truth, estimate) index pairs of the optimal assignment.
    """

    distance: float
    localisation: float
    missed: float
    false: float
    assigned: NDArray[np.intp]


def gospa(
    truth: ArrayLike,
    estimates: ArrayLike,
    cutoff_m: float,
    order: float = 2.0,
) -> Gospa:
    """GOSPA (α = 2) between ``truth`` (m, d) and ``estimates`` (n, d) (module docstring)."""
    from scipy.optimize import linear_sum_assignment

    c = float(check("gospa_cutoff_m", cutoff_m))
    p = float(check("gospa_order", order))
    X, Y = _points(truth), _points(estimates)
    if len(X) and len(Y) and X.shape[1] != Y.shape[1]:
        raise ValueError(f"gospa: truth has {X.shape[1]} coordinates, estimates {Y.shape[1]}")
    m, n = len(X), len(Y)
    half = c**p / 2.0
    pairs = np.zeros((0, 2), dtype=np.intp)
    local = 0.0
    if m and n:
        d = np.sqrt(((X[:, None, :] - Y[None, :, :]) ** 2).sum(axis=-1))
        cost = np.minimum(d, c) ** p - c**p
        rows, cols = linear_sum_assignment(cost)
        keep = d[rows, cols] < c
        rows, cols = rows[keep], cols[keep]
        pairs = np.stack([rows, cols], axis=1).astype(np.intp)
        local = float((d[rows, cols] ** p).sum())
    k = len(pairs)
    missed = half * (m - k)
    false = half * (n - k)
    return Gospa((local + missed + false) ** (1.0 / p), local, missed, false, pairs)


def _points(a: ArrayLike) -> NDArray[np.float64]:
    """Points (k, d); an empty sequence is (0, 0)."""
    out = np.asarray(a, dtype=np.float64)
    if out.size == 0:
        return out.reshape(0, out.shape[-1] if out.ndim == 2 else 0)
    if out.ndim != 2:
        raise ValueError(f"gospa: points must be (k, d) (got shape {out.shape})")
    return out


class TrackCounter:
    """Track swaps and false tracks of one run, fed each scan's truth and reported tracks
    (module docstring).

    Args:
        cutoff_m: c, the largest distance of a match (m).
    """

    def __init__(self, cutoff_m: float) -> None:
        self.cutoff_m = float(check("gospa_cutoff_m", cutoff_m))
        self.swaps = 0
        self._last: dict[object, str] = {}
        self._reported: dict[str, int] = {}
        self._on_truth: dict[str, int] = {}

    def add(
        self,
        truth_ids: Sequence[object],
        truth: ArrayLike,
        track_ids: Sequence[str],
        tracks: ArrayLike,
    ) -> NDArray[np.intp]:
        """One scan: truth positions (m, d) named ``truth_ids``, reported track positions
        (n, d) named ``track_ids``. Returns the matches (k, 2): (truth index, track index)."""
        from scipy.optimize import linear_sum_assignment

        X, Y = _points(truth), _points(tracks)
        c = self.cutoff_m
        for t in track_ids:
            self._reported[t] = self._reported.get(t, 0) + 1
        pairs: list[tuple[int, int]] = []
        if len(X) and len(Y):
            d = np.sqrt(((X[:, None, :] - Y[None, :, :]) ** 2).sum(axis=-1))
            column = {t: j for j, t in enumerate(track_ids)}
            taken: set[int] = set()
            for i, name in enumerate(truth_ids):  # a valid match is kept
                j = column.get(self._last.get(name, ""), -1)
                if j >= 0 and j not in taken and d[i, j] < c:
                    pairs.append((i, j))
                    taken.add(j)
            kept = {i for i, _ in pairs}
            rest_i = [i for i in range(len(X)) if i not in kept]
            rest_j = [j for j in range(len(Y)) if j not in taken]
            if rest_i and rest_j:
                sub = d[np.ix_(rest_i, rest_j)]
                rows, cols = linear_sum_assignment(np.minimum(sub, c) - c)
                pairs += [
                    (rest_i[r], rest_j[q])
                    for r, q in zip(rows.tolist(), cols.tolist(), strict=True)
                    if sub[r, q] < c
                ]
        for i, j in pairs:
            name, track = truth_ids[i], track_ids[j]
            self._on_truth[track] = self._on_truth.get(track, 0) + 1
            last = self._last.get(name)
            if last is not None and last != track:
                self.swaps += 1
            self._last[name] = track
        return np.array(pairs, dtype=np.intp).reshape(-1, 2)

    @property
    def tracks(self) -> int:
        """Tracks reported at least once."""
        return len(self._reported)

    @property
    def false_tracks(self) -> int:
        """Reported tracks matched to a truth at fewer than half of their reported scans."""
        return sum(2 * self._on_truth.get(t, 0) < n for t, n in self._reported.items())
