"""Track management in expected detections: M-of-N confirmation, deletion after misses, per
radar and its coverage.

``TrackBook`` keeps, per track (a slot of its arrays), what the association's management
needs; the association (``core.tracking.association.GNNTracker``) decides the hits (its
assignment) and the misses (a radar's beam swept the track inside its coverage without a
plot of it, ``core.tracking.coverage``), and the book counts them:

* An **expected detection** is a hit, or a miss: a sweep of a radar that covers the track's
  predicted position and brought no plot of it. Sweeps of radars that do not cover the track,
  and times between sweeps, are not expected detections: a target seen by one radar of four
  is confirmed and held by that radar alone.
* **Confirmation, M of N.** A tentative track is confirmed at its M-th hit if that comes within
  its first N expected detections (the initiating plot is the first, and a hit); it is
  deleted as soon as that has become impossible, hits + (N − expected) < M.
* **Deletion.** A confirmed track is deleted after ``delete_misses`` consecutive misses.
* **Coasting.** A track no radar has updated for longer than ``coast_s`` is deleted: a
  target that left every coverage has no expected detection left to miss.

Per track and radar the book also keeps the time of the last hit (a track takes at most one
plot per sweep of a radar) and of the last judgement (a sweep judges a track once), and the
plots each radar gave it, folded at its deletion into the per-radar counts of plots in
confirmed tracks and of plots that never reached one (``plot_counts``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

TENTATIVE_CODE, CONFIRMED_CODE = 0, 1


class TrackBook:
    """Hits, expected detections, misses and per-radar times of every live track (module
    docstring).

    Args:
        confirm_m, confirm_n: M of the first N expected detections confirm a track.
        delete_misses: consecutive misses that delete a confirmed track.
        state_size: n of the gating method's state (x, ẋ, y, ẏ[, z, ż]) kept per track.
    """

    def __init__(self, confirm_m: int, confirm_n: int, delete_misses: int, state_size: int):
        self.m, self.n, self.kdel = confirm_m, confirm_n, delete_misses
        self.slot: dict[str, int] = {}  # id → slot, in order of initiation
        #: The free slots, a stack (its top ``free_top``; the lowest slot on top first).
        self.free = np.zeros(0, np.int64)
        self.free_top = 0
        self._cap, self._radars = 0, 0
        self._n = state_size
        self.status = np.zeros(0, np.int8)
        self.hits = np.zeros(0, np.int64)
        self.expected = np.zeros(0, np.int64)
        self.misses = np.zeros(0, np.int64)
        self.born_s = np.zeros(0)
        self.last_s = np.zeros(0)
        self.x = np.zeros((0, state_size))
        #: (K, n, n) the gating method's latest posterior covariance (the gate's prefilter
        #: bounds each track's predicted position from x and P, ``GNNTracker.near``).
        self.P = np.zeros((0, state_size, state_size))
        self.sigma_m = np.zeros(0)
        self.sigma_v = np.zeros(0)
        #: Per slot: live, the track's id, and its rank in order of initiation (the live
        #: tracks without a Python loop over ``slot``).
        self.alive = np.zeros(0, np.bool_)
        self.label: list[str] = []
        self.rank = np.zeros(0, np.int64)
        self._started = 0
        self.hit_s = np.zeros((0, 0))
        self.judged_s = np.zeros((0, 0))
        self.plots = np.zeros((0, 0), np.int64)
        #: (R, 2) plots of deleted tracks: [never confirmed, confirmed] per radar.
        self.folded = np.zeros((0, 2), np.int64)

    # -- storage ---------------------------------------------------------------------------

    def _grow(self, capacity: int, radars: int) -> None:
        cap, rad = max(capacity, self._cap), max(radars, self._radars)
        if cap == self._cap and rad == self._radars:
            return
        grow = cap - self._cap

        def rows(a: NDArray, fill: float) -> NDArray:
            return np.concatenate([a, np.full((grow, *a.shape[1:]), fill, a.dtype)])

        def table(a: NDArray, fill: float) -> NDArray:
            out = np.full((cap, rad), fill, a.dtype)
            out[: a.shape[0], : a.shape[1]] = a
            return out

        self.status = rows(self.status, 0)
        self.hits, self.expected, self.misses = (
            rows(a, 0) for a in (self.hits, self.expected, self.misses)
        )
        self.born_s, self.last_s, self.sigma_m, self.sigma_v = (
            rows(a, 0.0) for a in (self.born_s, self.last_s, self.sigma_m, self.sigma_v)
        )
        self.x = rows(self.x, 0.0)
        self.P = rows(self.P, 0.0)
        self.alive = rows(self.alive, False)
        self.rank = rows(self.rank, 0)
        self.label.extend([""] * grow)
        self.hit_s = table(self.hit_s, -np.inf)
        self.judged_s = table(self.judged_s, -np.inf)
        self.plots = table(self.plots, 0)
        folded = np.zeros((rad, 2), np.int64)
        folded[: self.folded.shape[0]] = self.folded
        self.folded = folded
        # The new slots go on top of the free stack, the lowest handed out first.
        new = np.arange(cap - 1, self._cap - 1, -1)
        free = np.zeros(cap, np.int64)
        free[: self.free_top] = self.free[: self.free_top]
        free[self.free_top : self.free_top + new.size] = new
        self.free, self.free_top = free, self.free_top + new.size
        self._cap, self._radars = cap, rad

    def radars(self, count: int) -> None:
        """Make room for ``count`` radars."""
        self._grow(self._cap, count)

    def live_slots(self, status: int | None = None) -> NDArray[np.intp]:
        """The live tracks' slots (of one status code, or all), in order of initiation."""
        mask = self.alive if status is None else self.alive & (self.status == status)
        slots = np.flatnonzero(mask)
        return slots[np.argsort(self.rank[slots], kind="stable")]

    # -- events ----------------------------------------------------------------------------

    def start(self, track: str, time_s: float, radar: int) -> int:
        """A new tentative track from one plot of ``radar`` at ``time_s`` (its first hit)."""
        if not self.free_top:
            self._grow(max(16, 2 * self._cap), self._radars)
        self.free_top -= 1
        s = int(self.free[self.free_top])
        self.slot[track] = s
        self.alive[s], self.label[s], self.rank[s] = True, track, self._started
        self._started += 1
        self.status[s], self.hits[s], self.expected[s], self.misses[s] = TENTATIVE_CODE, 1, 1, 0
        self.born_s[s] = self.last_s[s] = time_s
        self.hit_s[s] = self.judged_s[s] = -np.inf
        self.hit_s[s, radar] = time_s
        self.plots[s] = 0
        self.plots[s, radar] = 1
        return s

    def hit(self, slots: NDArray[np.intp], time_s: NDArray[np.float64], radar: int) -> None:
        """Hits of ``slots`` by plots of ``radar`` at ``time_s`` (each slot once)."""
        self.hits[slots] += 1
        self.expected[slots] += 1
        self.misses[slots] = 0
        self.last_s[slots] = time_s
        self.hit_s[slots, radar] = time_s
        self.plots[slots, radar] += 1

    def miss(self, slots: NDArray[np.intp]) -> None:
        """Misses of ``slots`` (each slot once): an expected detection without a plot."""
        self.expected[slots] += 1
        self.misses[slots] += 1

    def settle(self, slots: NDArray[np.intp]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Confirm and mark for deletion among ``slots`` after their hits and misses (module
        docstring): (confirmed, to delete) slots."""
        tent = self.status[slots] == TENTATIVE_CODE
        confirm = slots[tent & (self.hits[slots] >= self.m)]
        hopeless = tent & (self.hits[slots] + (self.n - self.expected[slots]) < self.m)
        hopeless &= self.hits[slots] < self.m
        lost = ~tent & (self.misses[slots] >= self.kdel)
        self.status[confirm] = CONFIRMED_CODE
        return confirm, slots[hopeless | lost]

    def remove(self, track: str) -> None:
        """Delete a track: its plots folded into the per-radar counts, its slot freed."""
        s = self.slot.pop(track)
        self.alive[s] = False
        self.folded[: self._radars, int(self.status[s])] += self.plots[s, : self._radars]
        self.free[self.free_top] = s
        self.free_top += 1

    def reserve(self, slots: int) -> None:
        """Make sure at least ``slots`` slots are free (the compiled association starts up
        to one track per plot of a call without growing the arrays)."""
        if self.free_top < slots:
            self._grow(max(2 * self._cap, self._cap + slots - self.free_top, 16), self._radars)

    def plot_counts(self) -> NDArray[np.int64]:
        """(R, 3) plots per radar: [in confirmed tracks, in tracks still tentative, in tracks
        deleted without ever being confirmed]."""
        live = self.live_slots()
        out = np.zeros((self._radars, 3), np.int64)
        out[:, 0] = self.folded[:, 1]
        out[:, 2] = self.folded[:, 0]
        if live.size:
            conf = self.status[live] == CONFIRMED_CODE
            out[:, 0] += self.plots[live[conf], : self._radars].sum(0)
            out[:, 1] += self.plots[live[~conf], : self._radars].sum(0)
        return out
