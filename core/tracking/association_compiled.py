"""The association's compiled route: ``GNNTracker``'s batches handed to one compiled call
(``core.tracking.kernels_associate.associate_2d``) many at a time.

``GNNTracker`` takes this route for the tracks the kernel has (``eligible``: 2D plots, the
compiled engine (``StreamOptions.compiled``: no monitor that wants each update as a call),
the IMM with the first-plot start and the line-of-sight Doppler update, a gating method
that converts the plot alone, the sparse assignment); the Python route
(``GNNTracker._add``) stays for the others and, on the numpy engine, is the reference the
compiled route is checked against (``tests/test_association_kernel.py``: the same track of
every plot). The kernel keeps the book's and the beams' arrays (``TrackBook``,
``BeamTable``) and every method's tracks, in the tracker's own arrays
(``core.tracking.compiled.CompiledTracks``, a row per book slot): each plot is filtered once,
by the association, and the gating method's update is the one the next batch gates with.
This class lays a call's plots out as arrays, keeps the tracker's rows as many as the book's
slots, and brings the book's ids (``TrackBook.slot``, ``label``) and the tracker's row names
(``CompiledTracks.bind``) up to date from the kernel's events.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.methods import conversion_table
from radarviz.core.tracking.compiled import CompiledTracks, TrackBlock
from radarviz.core.tracking.coverage import (
    EDGE_FRACTION,
    MAX_MARGIN_RAD,
    MIN_MARGIN_RAD,
    REVISITS_KEPT,
    SWEEP_BEAM_TOLERANCE_RAD,
    SWEEP_HORIZON,
    SWEEP_PERIOD_DRIFT,
    BeamTable,
    beam_constants,
)
from radarviz.core.tracking.management import TrackBook
from radarviz.core.tracking.stream import Plot, StreamOptions, plot_block


def eligible(options: StreamOptions, three_d: bool, boxed_gate: bool, dense: bool) -> bool:
    """Whether ``GNNTracker`` runs on the compiled route (module docstring)."""
    return (
        not three_d
        and not dense
        and boxed_gate
        and options.compiled(three_d)
        and options.model == "imm"
        and options.init == "first-plot"
        and options.doppler_update == "line_of_sight"
    )


class CallResult:
    """What one call did, per batch: the plots' track ids and statuses (codes), and the ids
    confirmed and deleted at each batch (``ScanResult``'s parts), and every method's
    posterior after each plot (``tracks``: x (B, M, 4), P (B, M, 4, 4), each plot's row)."""

    def __init__(self, batches: int):
        self.ids: NDArray[np.int64] = np.zeros(0, np.int64)
        self.status: NDArray[np.int8] = np.zeros(0, np.int8)
        self.confirmed: list[list[str]] = [[] for _ in range(batches)]
        self.deleted: list[list[str]] = [[] for _ in range(batches)]
        self.tracks: TrackBlock | None = None


class CompiledAssociation:
    """The call of the compiled association (module docstring).

    Args:
        method: the gating method; tracks: the tracker's ``CompiledTracks`` (the IMM, σv0,
            the Doppler, the methods, the gating one among them), whose rows the kernel
            updates; gate: γ; scale: γ times the prefilter's margin; q_max, omega_max: the
            prefilter's bounds (``GNNTracker.near``); max_speed_mps, confirm_m, confirm_n,
            delete_misses: ``AssociationOptions``; book: the tracker's ``TrackBook``; beams:
            its ``BeamTable``.
    """

    def __init__(
        self,
        method: str,
        tracks: CompiledTracks,
        gate: float,
        scale: float,
        q_max: float,
        omega_max: float,
        association: object,
        book: TrackBook,
        beams: BeamTable,
    ):
        from radarviz.core.tracking import kernels_associate as ka
        from radarviz.core.tracking import kernels_gate

        self._k = ka
        assert tracks.imm is not None and tracks.dims == 2
        self.tracks = tracks
        self.book, self.beams = book, beams
        self.gate_index = tracks.methods.index(method)
        a = association
        self.rules = ka.Rules(
            gate, scale, q_max, omega_max, float(a.max_speed_mps), int(a.confirm_m),  # type: ignore[attr-defined]
            int(a.confirm_n), int(a.delete_misses), MIN_MARGIN_RAD, MAX_MARGIN_RAD,  # type: ignore[attr-defined]
            EDGE_FRACTION, *beam_constants(), SWEEP_BEAM_TOLERANCE_RAD, SWEEP_PERIOD_DRIFT,
            SWEEP_HORIZON,
        )  # fmt: skip
        #: The live tracks in order of initiation, and their boxes and sweep bounds.
        self.live = ka.LiveArrays(
            np.zeros(0, np.int64), np.zeros(0, np.int64),
            np.zeros((kernels_gate.BOX_COLUMNS, 0)), np.zeros((1, 0)),
        )  # fmt: skip
        #: live positions, tracks started, batches, free slots, events, holes
        #: (``kernels_associate``).
        self.counters = np.zeros(ka.COUNTERS, np.int64)
        #: A lower bound of the live tracks' last plot times (the coasting pass's skip).
        self.since = np.full(1, -np.inf)

    def retune(self, gate: float, scale: float, q_max: float, association: object) -> None:
        """γ, the prefilter's scale and bound, the fastest target and the M-of-N and deletion
        rules of ``GNNTracker.retune``, from the next call on (the IMM's σa per model is the
        tracker's, ``CompiledTracks.retune``)."""
        a = association
        self.rules = self.rules._replace(
            gate=gate, scale=scale, q_max=q_max, max_speed_mps=float(a.max_speed_mps),  # type: ignore[attr-defined]
            confirm_m=int(a.confirm_m), confirm_n=int(a.confirm_n),  # type: ignore[attr-defined]
            delete_misses=int(a.delete_misses),  # type: ignore[attr-defined]
        )  # fmt: skip

    def reserve(self, tracks: int) -> None:
        """At least ``tracks`` free slots in the book now (``TrackBook.reserve``), and the
        tracker's rows and the live tracks' arrays as many (``GNNTracker.reserve``)."""
        self.book.reserve(tracks)
        self._fit(self.live.due_s.shape[0])

    def _fit(self, radars: int) -> None:
        """The tracker's rows and the live tracks' arrays as many as the book's slots, with a
        sweep bound per radar."""
        cap = self.book.alive.shape[0]
        self.tracks.reserve(cap)
        have = self.live.pos.shape[0]
        if cap > have:
            grow = cap - have

            def more(a: NDArray, fill: float = 0.0) -> NDArray:
                return np.concatenate([a, np.full((grow, *a.shape[1:]), fill, a.dtype)])

            def wider(a: NDArray, fill: float) -> NDArray:
                return np.concatenate([a, np.full((a.shape[0], grow), fill)], axis=1)

            lv = self.live
            # New positions: no box drawn yet, no bound yet.
            self.live = lv._replace(
                slot=more(lv.slot, -1), pos=more(lv.pos, -1),
                boxes=wider(lv.boxes, -math.inf), due_s=wider(lv.due_s, -math.inf),
            )  # fmt: skip
        due = self.live.due_s
        if radars > due.shape[0]:
            rows = np.full((radars - due.shape[0], due.shape[1]), -math.inf)
            self.live = self.live._replace(due_s=np.concatenate([due, rows]))

    def run(
        self,
        batches: Sequence[Sequence[Plot]],
        radar: NDArray[np.int64],
        sites: NDArray[np.float64],
        whole_scan: bool,
        measured_period_s: Sequence[float | None],
    ) -> tuple[CallResult, int]:
        """Associate ``batches`` (each of one radar, in time order; ``radar`` (B,) every
        plot's radar index, ``sites`` (R, 2) the radars'); returns the call's result and −1,
        or the index (into the call's plots) of a plot earlier than its track's previous
        one (the batches before its own are done)."""
        ka, book = self._k, self.book
        plots = [p for b in batches for p in b]
        n = len(plots)
        book.reserve(n)
        self._fit(sites.shape[0])
        longest = max((len(b) for b in batches), default=0)
        self.beams.grow(sites.shape[0], REVISITS_KEPT + longest + 1)
        block = plot_block(plots, one_target=True)
        vr = block.radial_velocity_mps
        if vr is None or not self.tracks.use_doppler:
            vr = np.full(n, np.nan)
        rd = block.radars
        starts = np.zeros(len(batches) + 1, np.int64)
        np.cumsum([len(b) for b in batches], out=starts[1:])
        pl = ka.PlotArrays(
            np.ascontiguousarray(block.time_s), np.ascontiguousarray(block.range_m),
            np.ascontiguousarray(block.azimuth_rad), np.ascontiguousarray(vr, dtype=np.float64),
            block.radar.astype(np.int64), np.ascontiguousarray(rd.site_m[:, :2]),
            rd.sigma_r_m, rd.sigma_beta_rad, rd.sigma_vr_mps,
            np.ascontiguousarray(radar, dtype=np.int64), starts,
            np.full(len(batches), whole_scan, np.bool_),
            np.array([math.nan if p is None else p for p in measured_period_s], np.float64),
        )  # fmt: skip
        arrays = ka.BookArrays(
            book.status, book.hits, book.expected, book.misses, book.born_s, book.last_s,
            book.x, book.P, book.sigma_m, book.sigma_v, book.alive, book.rank, book.hit_s,
            book.judged_s, book.plots, book.folded, book.free,
        )  # fmt: skip
        tk = self.tracks
        imm = tk.imm
        assert imm is not None
        tr = ka.TrackArrays(
            tk.plan, conversion_table(tk.methods, rd.sigma_r_m, rd.sigma_beta_rad),
            tk.imm_sigma_a_mps2, tk.turn_rates, tk.transition, tk.mu0,
            tk.sigma_v0_mps, tk.prm, tk.xs, tk.Ps, tk.mus, tk.started, tk.last_t,
            self.gate_index, tk.feed is not None,
        )  # fmt: skip
        c = self.counters
        c[ka.C_FREE], c[ka.C_EVENTS] = book.free_top, 0
        owner, row = np.zeros(n, np.int64), np.zeros(n, np.int64)
        status, start = np.zeros(n, np.int8), np.zeros(n, np.bool_)
        events = np.zeros((3 * n + c[ka.C_LIVE] + 1, 4), np.int64)
        m = tk.xs.shape[1]
        out_x, out_P, out_nis = np.empty((n, m, 4)), np.empty((n, m, 4, 4)), np.empty((n, m))
        bad = ka.associate_2d(
            pl, self.beams.arrays, np.ascontiguousarray(sites[:, :2]), arrays, tr, self.rules,
            self.live, c, self.since, owner, status, row, start, events, out_x, out_P, out_nis,
        )  # fmt: skip
        book.free_top = int(c[ka.C_FREE])
        out = CallResult(len(batches))
        out.ids, out.status = owner, status
        out.tracks = TrackBlock(out_x, out_P, row)
        label, slot = book.label, book.slot
        for b, kind, s, ident in events[: c[ka.C_EVENTS]].tolist():
            t = str(ident)
            if kind == ka.EV_START:
                label[s], slot[t] = t, s
                tk.bind(t, s)
                book._started += 1
            elif kind == ka.EV_CONFIRM:
                out.confirmed[b].append(t)
            else:
                del slot[t]
                out.deleted[b].append(t)
        # The monitor's updates of the batches done (before a deleted track's row is released
        # by ``GNNTracker``, so its last updates are its own).
        done = n if bad < 0 else int(starts[np.searchsorted(starts, bad, side="right") - 1])
        tk.feed_monitor(
            row[:done], pl.time_s[:done], out_nis[:done], ~np.isnan(vr[:done]), start[:done]
        )
        return out, int(bad)
