"""The association's compiled route: ``GNNTracker``'s batches handed to one compiled call
(``core.tracking.kernels_associate.associate_2d``) many at a time.

``GNNTracker`` takes this route for the tracks the kernel has (``eligible``: 2D plots, the
compiled engine, the IMM with the first-plot start and the line-of-sight Doppler update, a
gating method that converts the plot alone, the sparse assignment); the Python route
(``GNNTracker._add``) stays for the others and, on the numpy engine, is the reference the
compiled route is checked against (``tests/test_association_kernel.py``: the same track of
every plot). The kernel keeps the book's and the beams' arrays (``TrackBook``,
``BeamTable``) and the gating method's own tracks; this class lays a call's plots out as
arrays, keeps the gating tracks' arrays as large as the book, and brings the book's ids
(``TrackBook.slot``, ``label``) up to date from the kernel's events.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.compiled import METHOD_CODES, START_CODES
from radarviz.core.filters.models import IMMModel
from radarviz.core.filters.polar_ukf import UKFParams
from radarviz.core.tracking.compiled import PlotBlock
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
        and options.engine == "compiled"
        and options.model == "imm"
        and options.init == "first-plot"
        and options.doppler_update == "line_of_sight"
    )


class CallResult:
    """What one call did, per batch: the plots' track ids and statuses (codes), and the ids
    confirmed and deleted at each batch (``ScanResult``'s parts), and the call's plots as a
    ``PlotBlock`` (of one target: the caller labels it with the ids)."""

    def __init__(self, batches: int):
        self.block: PlotBlock | None = None
        self.ids: NDArray[np.int64] = np.zeros(0, np.int64)
        self.status: NDArray[np.int8] = np.zeros(0, np.int8)
        self.confirmed: list[list[str]] = [[] for _ in range(batches)]
        self.deleted: list[list[str]] = [[] for _ in range(batches)]


class CompiledAssociation:
    """The gating tracks and the call of the compiled association (module docstring).

    Args:
        method: the gating method; options: the filters' ``StreamOptions`` (the IMM, σv0,
            Doppler); gate: γ; scale: γ times the prefilter's margin; q_max, omega_max: the
            prefilter's bounds (``GNNTracker.near``); max_speed_mps, confirm_m, confirm_n,
            delete_misses: ``AssociationOptions``; book: the tracker's ``TrackBook``;
            beams: its ``BeamTable``.
    """

    def __init__(
        self,
        method: str,
        options: StreamOptions,
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
        imm = options.motion()
        assert isinstance(imm, IMMModel)
        self.imm = imm
        self.use_doppler = options.use_doppler
        self.book, self.beams = book, beams
        self.method = method
        self._model = (
            np.array([METHOD_CODES[method]], np.int64),
            np.array([START_CODES[method]], np.int64),
            np.array(imm.sigma_a_mps2, dtype=np.float64),
            imm.turn_rates_radps(),
            imm.transition_matrix(),
            imm.initial_probabilities(),
            float(options.sigma_v0_mps),
            np.array(UKFParams().weights(4), dtype=np.float64),
        )
        r = imm.models
        self._xs, self._Ps = np.zeros((0, 1, r, 4)), np.zeros((0, 1, r, 4, 4))
        self._mus = np.zeros((0, 1, r))
        self._started, self._last_t = np.zeros(0, np.bool_), np.zeros(0)
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

    def retune(
        self, options: StreamOptions, gate: float, scale: float, q_max: float, association: object
    ) -> None:
        """The IMM's σa per model, γ, the prefilter's scale and bound, the fastest target and
        the M-of-N and deletion rules of ``GNNTracker.retune``, from the next call on."""
        imm = options.motion()
        assert isinstance(imm, IMMModel) and imm.models == self.imm.models
        self.imm = imm
        sigma_a_mps2 = np.array(imm.sigma_a_mps2, dtype=np.float64)
        self._model = (*self._model[:2], sigma_a_mps2, *self._model[3:])
        a = association
        self.rules = self.rules._replace(
            gate=gate, scale=scale, q_max=q_max, max_speed_mps=float(a.max_speed_mps),  # type: ignore[attr-defined]
            confirm_m=int(a.confirm_m), confirm_n=int(a.confirm_n),  # type: ignore[attr-defined]
            delete_misses=int(a.delete_misses),  # type: ignore[attr-defined]
        )  # fmt: skip

    def _fit(self, radars: int) -> None:
        """The gating tracks' and the live tracks' arrays as large as the book's, with a
        sweep bound per radar."""
        cap = self.book.alive.shape[0]
        have = self._started.shape[0]
        if cap > have:
            grow = cap - have

            def more(a: NDArray, fill: float = 0.0) -> NDArray:
                return np.concatenate([a, np.full((grow, *a.shape[1:]), fill, a.dtype)])

            def wider(a: NDArray, fill: float) -> NDArray:
                return np.concatenate([a, np.full((a.shape[0], grow), fill)], axis=1)

            self._xs, self._Ps, self._mus = more(self._xs), more(self._Ps), more(self._mus)
            self._started, self._last_t = more(self._started, False), more(self._last_t)
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
        if vr is None or not self.use_doppler:
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
        gf = ka.GateFilter(*self._model, self._xs, self._Ps, self._mus, self._started, self._last_t)
        c = self.counters
        c[ka.C_FREE], c[ka.C_EVENTS] = book.free_top, 0
        owner = np.zeros(n, np.int64)
        status = np.zeros(n, np.int8)
        events = np.zeros((3 * n + c[ka.C_LIVE] + 1, 4), np.int64)
        bad = ka.associate_2d(
            pl, self.beams.arrays, np.ascontiguousarray(sites[:, :2]), arrays, gf, self.rules,
            self.live, c, self.since, owner, status, events,
        )  # fmt: skip
        book.free_top = int(c[ka.C_FREE])
        out = CallResult(len(batches))
        out.ids, out.status, out.block = owner, status, block
        label, slot = book.label, book.slot
        for b, kind, s, ident in events[: c[ka.C_EVENTS]].tolist():
            t = str(ident)
            if kind == ka.EV_START:
                label[s], slot[t] = t, s
                book._started += 1
            elif kind == ka.EV_CONFIRM:
                out.confirmed[b].append(t)
            else:
                del slot[t]
                out.deleted[b].append(t)
        return out, int(bad)
