"""The tracker on the compiled engine: blocks of plots as arrays, every target's tracks in
arrays, one compiled pass per block, or per half of its targets on two threads
(``core.filters.kernels_track``).

``core.tracking.targets.TargetTracker`` and ``core.tracking.stream.StreamTracker`` run here
when their options ask for ``engine="compiled"`` (the default) and the track is one the
kernels have: 2D (``core.filters.kernels_track``) or 3D (``core.filters.kernels_3d``), every
method, the line-of-sight Doppler update, the constant-velocity model or the IMM
(``core.filters.kernels_imm``), the first-plot start, no finite-memory track. The rest (the
finite-memory start and track, the converted Doppler update) stays on the numpy engine,
which is also the reference these tracks are checked against (``tests/test_track_compiled.py``,
to 1e-9 relative).

A block is a ``PlotBlock``: per plot its target (an index into the block's labels), its radar
(an index into a ``RadarTable``: site and noise std), time and polar measurement. The kernel
walks the block in plot order, so a target's plots are filtered in its own order however the
targets interleave (no waves, no per-target grouping). On a machine of two cores or more a
large block (``SPLIT_STEPS``) is split into two groups of disjoint targets, each kept in plot
order and filtered by the same kernel on its own thread (the kernels release the GIL); as a
target's track depends on its own plots alone, the outputs are the one-thread ones bit for
bit (``tests/test_track_compiled.py``).

For the association of unlabelled plots (``core.tracking.association``) the tracks are also
read without being changed: ``predicted`` (a list of tracks, each to its own time: the
kernels' prediction, and for the IMM their mixing and combination) and ``gate_nis`` (those
predictions scored against plots by the method's position measurement and its NIS), and
deleted tracks are dropped (``forget``, their rows reused). Each calls the step functions the
tracker kernels use, so a gate sees what the next update will predict
(``tests/test_association_engines.py`` against the numpy engine).
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.cores import available_cores
from radarviz.core.filters.kernel_args import (
    CVOptions,
    IMMOptions,
    PlotColumns,
    PlotOutputs,
    RadarArrays,
    TrackState,
)
from radarviz.core.filters.methods import (
    conversion_table,
    method_plan,
    scale_table,
    update_coefficients,
)
from radarviz.core.filters.models import IMMModel
from radarviz.core.filters.polar_ukf import UKFParams
from radarviz.core.tracking.consistency import ConsistencyMonitor, nis_band

#: The dimensions the compiled tracker has a kernel for.
COMPILED_DIMS: tuple[int, ...] = (2, 3)


class RadarTable(NamedTuple):
    """The radars a block's plots refer to, R of them: site_m (R, 3) (m), and noise std
    sigma_r_m, sigma_beta_rad, sigma_elevation_rad (R,) (m, rad) and
    sigma_vr_mps (R,) (m/s; 0 where the radar has no Doppler)."""

    site_m: NDArray[np.float64]
    sigma_r_m: NDArray[np.float64]
    sigma_beta_rad: NDArray[np.float64]
    sigma_elevation_rad: NDArray[np.float64]
    sigma_vr_mps: NDArray[np.float64]


class PlotBlock(NamedTuple):
    """B plots as arrays (the columnar form of a list of ``core.tracking.stream.Plot``).

    Attributes:
        time_s: (B,) s.  range_m, azimuth_rad: (B,) m, rad.
        elevation_rad: (B,) rad, or None (2D).
        radial_velocity_mps: (B,) m/s, NaN where a plot has no Doppler; or None (none has).
        radar: (B,) indices into ``radars``.  radars: the ``RadarTable``.
        target: (B,) indices into ``labels``; labels: the block's target labels ("" for a
            file of one target).
    """

    time_s: NDArray[np.float64]
    range_m: NDArray[np.float64]
    azimuth_rad: NDArray[np.float64]
    elevation_rad: NDArray[np.float64] | None
    radial_velocity_mps: NDArray[np.float64] | None
    radar: NDArray[np.intp]
    radars: RadarTable
    target: NDArray[np.intp]
    labels: tuple[str, ...]

    @property
    def size(self) -> int:
        """B, the plots of the block (``len`` is the tuple's, as for any NamedTuple)."""
        return int(self.time_s.shape[0])


class TrackBlock(NamedTuple):
    """Every method's posterior after each plot of a block: x (B, M, n), P (B, M, n, n) in the
    tracker's own dimensions (n = 2·dims, state (x, ẋ, y, ẏ[, z, ż])), and ``target`` (B,),
    each plot's slot in the tracker's ``targets``."""

    x: NDArray[np.float64]
    P: NDArray[np.float64]
    target: NDArray[np.intp]


class OutOfOrderError(Exception):
    """A plot earlier than its target's previous one: ``index`` in the block, the times."""

    def __init__(self, index: int, time_s: float, previous_s: float):
        super().__init__(index)
        self.index, self.time_s, self.previous_s = index, time_s, previous_s


class CompiledTracks:
    """Every method's track of every target on the compiled engine (module docstring).

    Args:
        methods: from ``core.filters.compiled.COMPILED_METHODS`` (every method, 2D and 3D).
        dims: 2 or 3 (``COMPILED_DIMS``).
        sigma_a_mps2, sigma_v0_mps, use_doppler: as ``StreamOptions``.
        monitor: fed every update's NIS (track names ``name(target, method)``), or None.
        name: the monitor's track name of (target, method).
        imm: the IMM (``core.filters.models.IMMModel``) instead of the cv model of
            ``sigma_a_mps2``, or None: each (target, method) then holds its r models' x, P and
            μ (``core.filters.kernels_imm``) and the output is their combined estimate.
    """

    def __init__(
        self,
        methods: tuple[str, ...],
        dims: int,
        sigma_a_mps2: float,
        sigma_v0_mps: float,
        use_doppler: bool,
        monitor: ConsistencyMonitor | None = None,
        name: Callable[[str, str], str] | None = None,
        imm: IMMModel | None = None,
        reported: int | None = None,
    ):
        self.methods = tuple(methods)
        #: The leading methods the monitor sees (the rest are kept for a caller's own use:
        #: the association's gating method when it is not a requested one).
        self.reported = len(self.methods) if reported is None else int(reported)
        #: What the kernels branch on, a row per method (``core.filters.methods.method_plan``).
        self.plan = method_plan(self.methods)
        self.sigma_a_mps2, self.sigma_v0_mps = float(sigma_a_mps2), float(sigma_v0_mps)
        self.use_doppler = bool(use_doppler)
        self.dims = int(dims)
        ns = 2 * self.dims  # the state size
        self.prm = np.array(UKFParams().weights(ns), dtype=np.float64)
        self.slots: dict[str, int] = {}
        #: Each row's label, in order of the rows (a row freed by ``forget`` keeps its old
        #: label here until it is reused); rows given back by ``forget``, reused by new labels.
        self._labels: list[str] = []
        self._free: list[int] = []
        m = len(methods)
        self.imm = imm
        # The IMM's models on an axis after the method's (``_slots`` grows any trailing shape).
        models = () if imm is None else (imm.models,)
        self.xs = np.zeros((0, m, *models, ns))
        self.Ps = np.zeros((0, m, *models, ns, ns))
        self.mus = np.zeros((0, m, *models))
        if imm is not None:
            self.imm_sigma_a_mps2 = np.array(imm.sigma_a_mps2, dtype=np.float64)
            self.turn_rates = imm.turn_rates_radps()
            self.transition = imm.transition_matrix()
            self.mu0 = imm.initial_probabilities()
        self.started = np.zeros(0, dtype=np.bool_)
        self.last_t = np.zeros(0)
        self.feed = None if monitor is None else MonitorFeed(monitor, self.reported)
        self.name = name or (lambda target, method: method)
        self._track_names: list[str] = []
        #: Rows numbered by the caller (``bind``) instead of by ``add``.
        self._bound = False

    def retune(self, sigma_a_mps2: float, motion: object) -> None:
        """The cv model's σa, or (``motion`` an IMM of as many models) each model's σa, from
        the next block on; the tracks keep their states."""
        self.sigma_a_mps2 = float(sigma_a_mps2)
        if self.imm is not None and isinstance(motion, IMMModel):
            self.imm = motion
            self.imm_sigma_a_mps2 = np.array(motion.sigma_a_mps2, dtype=np.float64)

    @property
    def _accel_variance(self) -> float:
        """σa² (m²/s⁴), the cv model's ``q`` in the kernels' Q = q g gᵀ, g = (T²/2, T)
        (``core.filters.predict.white_acceleration``)."""
        return self.sigma_a_mps2 * self.sigma_a_mps2

    @property
    def targets(self) -> tuple[str, ...]:
        return tuple(self.slots)

    def _names(self) -> list[str]:
        """The monitor's name of every reported track t·M + j (extended as targets come)."""
        m = self.reported
        have = len(self._track_names) // max(1, m)
        for t in self._labels[have:]:
            self._track_names.extend(self.name(t, method) for method in self.methods[:m])
        return self._track_names

    def _label_row(self, label: str, k: int) -> None:
        """Row ``k`` holds ``label``'s tracks from now on (a freed row's monitor state went
        to the monitor's records at ``forget``)."""
        self.slots[label] = k
        if k >= len(self._labels):
            self._labels.extend([""] * (k + 1 - len(self._labels)))
        self._labels[k] = label
        m = self.reported
        if len(self._track_names) > k * m:
            self._track_names[k * m : (k + 1) * m] = [
                self.name(label, method) for method in self.methods[:m]
            ]

    def _slots(self, labels: tuple[str, ...]) -> NDArray[np.intp]:
        """Each label's slot, new targets added (the state arrays grow by doubling)."""
        assert not self._bound, "rows numbered by the caller (bind)"
        slots = self.slots
        for t in labels:
            if t not in slots:
                self._label_row(t, self._free.pop() if self._free else len(self._labels))
        ids = np.array([slots[t] for t in labels], np.intp)
        self.reserve(len(self._labels))
        return ids

    def reserve(self, rows: int) -> None:
        """Room for ``rows`` targets' tracks (the state arrays grow by doubling)."""
        have = self.started.shape[0]
        if rows <= have:
            return
        cap = max(rows, 2 * have, 16)
        grow = cap - have

        def more(a: NDArray[Any]) -> NDArray[Any]:
            return np.concatenate([a, np.zeros((grow, *a.shape[1:]), a.dtype)])

        self.xs, self.Ps, self.started, self.last_t = map(
            more, (self.xs, self.Ps, self.started, self.last_t)
        )
        if self.imm is not None:
            self.mus = more(self.mus)
        if self.feed is not None:
            self.feed.grow(cap)

    def bind(self, label: str, row: int) -> None:
        """``label``'s tracks are in row ``row`` (``reserve`` made it), numbered by the
        caller: the compiled association (``core.tracking.association_compiled``) updates
        the rows itself, by its book's slots, and names them here for ``predicted``,
        ``forget`` and the monitor. A caller that binds never calls ``add``."""
        self._bound = True
        self._label_row(label, row)

    def add(self, block: PlotBlock) -> TrackBlock:
        """Filter a block in order; raises ``OutOfOrderError`` at a plot earlier than its
        target's previous one (the plots before it are filtered and fed to the monitor, it
        and later ones not; in a block split between two threads the other half's later
        plots may be in the tracks' state too, which no caller reads after the error)."""
        slot = self._slots(block.labels)[block.target]
        n, m = block.size, len(self.methods)
        vr = block.radial_velocity_mps
        has_vr = np.zeros(n, dtype=np.bool_) if vr is None else ~np.isnan(vr)
        if not self.use_doppler:
            has_vr[:] = False
        vr = np.zeros(n) if vr is None else vr
        rd = block.radars
        ns = 2 * self.dims
        out_x = np.empty((n, m, ns))
        out_P = np.empty((n, m, ns, ns))
        out_nis = np.empty((n, m))
        new = ~self.started[slot] if self.feed is not None else None
        none = np.zeros(0)  # a 2D block's elevations
        three_d = self.dims == 3
        if three_d:
            assert block.elevation_rad is not None
        # The block's plots (split between the threads), then what they share: the radar
        # table, the methods' conversions of each radar's noise (``conversion_table``; in 3D
        # the scales, ``scale_table``), the options and the tracks.
        rows = PlotColumns(
            slot,
            _f(block.time_s),
            _f(block.range_m),
            _f(block.azimuth_rad),
            _f(block.elevation_rad) if three_d else none,
            _f(vr),
            has_vr,
            np.ascontiguousarray(block.radar, dtype=np.intp),
        )
        radars = RadarArrays(
            np.ascontiguousarray(rd.site_m[:, : self.dims], dtype=np.float64),
            _f(rd.sigma_r_m),
            _f(rd.sigma_beta_rad),
            _f(rd.sigma_elevation_rad) if three_d else none,
            _f(rd.sigma_vr_mps),
        )
        if three_d:
            conversions = scale_table(self.methods, rd.sigma_beta_rad, rd.sigma_elevation_rad)
        else:
            conversions = conversion_table(self.methods, rd.sigma_r_m, rd.sigma_beta_rad)
        options: CVOptions | IMMOptions
        if self.imm is None:
            options = CVOptions(self.sigma_a_mps2, self.sigma_v0_mps, self.prm)
        else:
            options = IMMOptions(
                self.imm_sigma_a_mps2,
                self.turn_rates,
                self.transition,
                self.mu0,
                self.sigma_v0_mps,
                self.prm,
                self.feed is not None,
            )
        mus = self.mus if self.imm is not None else np.zeros((0, 0))
        tracks = TrackState(self.xs, self.Ps, mus, self.started, self.last_t)
        kernel = _track_kernel(self.dims, self.imm is not None)

        def run(rows: PlotColumns, outs: tuple[NDArray[np.float64], ...]) -> int:
            return int(
                kernel(self.plan, conversions, rows, radars, options, tracks, PlotOutputs(*outs))
            )

        split = n * m >= SPLIT_STEPS and _cores() > 1
        halves = _halves(slot) if split else None
        if halves is None:
            bad = run(rows, (out_x, out_P, out_nis))
        else:
            bad = _run_split(run, rows, halves, (out_x, out_P, out_nis))
        done = n if bad < 0 else int(bad)
        if self.feed is not None and new is not None:
            # A slot's first plot in the block is its start only if it had none before and no
            # earlier plot of the block started it.
            first = np.zeros(n, dtype=np.bool_)
            _, idx = np.unique(slot, return_index=True)
            first[idx] = True
            starts = new & first
            self.feed_monitor(
                slot[:done], block.time_s[:done], out_nis[:done], has_vr[:done], starts[:done]
            )
        if bad >= 0:
            k = slot[bad]
            raise OutOfOrderError(int(bad), float(block.time_s[bad]), float(self.last_t[k]))
        return TrackBlock(out_x, out_P, slot)

    def feed_monitor(
        self,
        slot: NDArray[np.intp],
        time_s: NDArray[np.float64],
        nis: NDArray[np.float64],
        has_vr: NDArray[np.bool_],
        start: NDArray[np.bool_],
    ) -> None:
        """The monitor's updates of B filtered plots: each plot's row slot (B,), time (B,),
        every method's NIS (B, M) (the reported columns read), whether it had a Doppler
        (B,) and whether it started its track (B,: no update). Nothing without a monitor."""
        if self.feed is None:
            return
        self.feed.add(
            slot, time_s, nis[:, : self.reported], self.dims + has_vr.astype(np.int64),
            ~start, self._names(),
        )  # fmt: skip

    def predicted(
        self, method: str, labels: list[str], time_s: float | NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``method``'s tracks of ``labels`` (N,) (each started, a label may repeat)
        predicted to ``time_s`` (one time, or (N,)), the stored tracks left as they are:
        x (N, n), P (N, n, n), n = 2·dims; with the IMM the combined prediction (mixing, each
        model's prediction, the combination with the predicted probabilities c̄). The steps
        are the tracker kernels' own (``predicted_2d`` / ``predicted_3d``,
        ``core.filters.kernels_imm.predicted_imm``), so a gate scored on these predictions
        sees what the next update will predict. Raises ``ValueError`` for a time before a
        track's last plot."""
        j = self.methods.index(method)
        slot = np.array([self.slots[t] for t in labels], dtype=np.intp)
        dt = np.asarray(time_s, dtype=np.float64) - self.last_t[slot]
        dt = np.ascontiguousarray(np.broadcast_to(dt, slot.shape))
        if dt.size and (dt.min() < 0 or not self.started[slot].all()):
            raise ValueError(f"predicted: time {time_s!r} is before a track's last plot")
        ns = 2 * self.dims
        out_x, out_P = np.empty((slot.size, ns)), np.empty((slot.size, ns, ns))
        if self.imm is not None:
            from radarviz.core.filters.kernels_imm import predicted_imm

            predicted_imm(
                self.xs, self.Ps, self.mus, slot, j, dt, self.imm_sigma_a_mps2, self.turn_rates,
                self.transition, out_x, out_P,
            )  # fmt: skip
        else:
            _predicted_kernel(self.dims)(
                self.xs, self.Ps, slot, j, dt, self._accel_variance, out_x, out_P
            )
        return out_x, out_P

    def gate_nis(
        self,
        method: str,
        labels: list[str],
        time_s: NDArray[np.float64],
        range_m: NDArray[np.float64],
        azimuth_rad: NDArray[np.float64],
        sigma_r_m: NDArray[np.float64],
        sigma_beta_rad: NDArray[np.float64],
        site: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        """d² = νᵀ S⁻¹ ν of N (track, plot) pairs in 2D: ``method``'s track of labels[i]
        predicted to time_s[i] (as ``predicted``) against plot i (range, azimuth, their noise
        std, site (N, 2)), by the method's position measurement (``position_measurement``,
        ``position_nis``: the statistic of the kernels' monitor; for the converted methods
        ν = z + s − H x⁻, S = H P⁻ Hᵀ + R). (N,); NaN where S is not positive definite.
        Raises ``ValueError`` for a time before a track's last plot."""
        if self.dims != 2:
            raise ValueError("gate_nis: 2D tracks only")
        j = self.methods.index(method)
        slot = np.array([self.slots[t] for t in labels], dtype=np.intp)
        dt = _f(time_s - self.last_t[slot])
        if dt.size and (dt.min() < 0 or not self.started[slot].all()):
            raise ValueError("gate_nis: a time before a track's last plot")
        out = np.empty(slot.size)
        plot = (_f(range_m), _f(azimuth_rad), _f(sigma_r_m), _f(sigma_beta_rad), _f(site))
        plan = self.plan[j]
        co = update_coefficients(method, sigma_r_m, sigma_beta_rad)
        if self.imm is not None:
            from radarviz.core.filters.kernels_imm import gate_nis_imm_2d

            model = (self.imm_sigma_a_mps2, self.turn_rates, self.transition)
            gate_nis_imm_2d(self.xs, self.Ps, self.mus, slot, j, dt, *model, plan, co, *plot, out)
        else:
            from radarviz.core.filters.kernels_track import gate_nis_2d

            q = self._accel_variance
            gate_nis_2d(self.xs, self.Ps, slot, j, dt, q, plan, co, *plot, out)
        return out

    def forget(self, labels: list[str]) -> None:
        """Drop the tracks of ``labels``: a label seen again starts a new track, and the rows
        go to new labels (the monitor's state of their tracks written into its records
        first), so memory follows the live tracks."""
        rows = []
        for t in labels:
            k = self.slots.pop(t)
            self.started[k] = False
            rows.append(k)
        if self.feed is not None and rows:
            self.feed.release(rows)
        if not self._bound:  # a binding caller numbers (and reuses) the rows itself
            self._free.extend(rows)


@functools.cache
def _predicted_kernel(dims: int) -> Callable[..., None]:
    """The cv model's ``predicted`` kernel of ``dims``, compiled on first use."""
    if dims == 3:
        from radarviz.core.filters.kernels_3d import predicted_3d

        return predicted_3d
    from radarviz.core.filters.kernels_track import predicted_2d

    return predicted_2d


def _f(a: NDArray[Any]) -> NDArray[np.float64]:
    return np.ascontiguousarray(a, dtype=np.float64)


#: The plot-method steps (plots × methods) a block needs before ``CompiledTracks.add`` splits
#: it between two threads. The split costs a few tenths of a millisecond of CPU a block (the
#: hand-over, the gathered inputs and the scattered outputs), so the kernel must have about a
#: millisecond of work to gain wall time. Measured on the cheapest kernel, 2D cv (about
#: 0.15 µs a step): splitting was slower at 512 plots of 7 methods and 2 048 of one, faster
#: at 768 of 7 and 5 000 of one. The 3D kernel costs about 4× as much a step and the 3D
#: IMM's 10×, so the threshold is conservative for them.
SPLIT_STEPS = 6000

_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


@functools.cache
def _cores() -> int:
    """``available_cores``, asked once (a system call)."""
    return available_cores()


def _executor() -> ThreadPoolExecutor:
    """The one worker thread that filters the second half of split blocks (created on first
    use, shared by every tracker; each ``add`` waits for its own half)."""
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="radarviz-track")
        return _pool


def _halves(slot: NDArray[np.intp]) -> tuple[NDArray[np.intp], NDArray[np.intp]] | None:
    """A block's plot indices in two groups of disjoint targets, each in block order, with
    about half the plots each: slots in index order, a slot in the first group when the
    middle of its plots falls in the first half of the block (so the groups differ by at
    most one target's plots). None when one group would be empty (one target, or one that
    has most of the plots): the block then stays on one thread."""
    counts = np.bincount(slot)
    below = np.cumsum(counts) - counts  # the block's plots of the slots before each
    first = (2 * below + counts <= slot.shape[0])[slot]
    a, b = np.flatnonzero(first), np.flatnonzero(~first)
    return None if a.size == 0 or b.size == 0 else (a, b)


def _run_split(
    run: Callable[[PlotColumns, tuple[NDArray[np.float64], ...]], int],
    rows: PlotColumns,
    halves: tuple[NDArray[np.intp], NDArray[np.intp]],
    outs: tuple[NDArray[np.float64], ...],
) -> int:
    """``run`` (the kernel over per-plot ``rows`` into ``outs``) on each half's plots, the
    second half on the worker thread while this one filters the first; returns the block's
    first bad plot, or −1. Each half's outputs are scattered into ``outs`` at its indices.

    The halves share the state arrays but no slot, and a target's track depends on its own
    plots alone, so every output is the one-thread kernel's bit for bit. A plot is bad
    (earlier than its target's previous plot) by its own target's plots alone, so the
    one-thread kernel stops at the earlier of the halves' first bad plots; the outputs
    before it are filled either way (the caller reads ``outs`` only up to it). The other
    half's kernel may have gone on past that plot, so the state of its slots is then ahead
    of the one-thread kernel's: that does not matter, as the error ends the run.
    """

    def half(idx: NDArray[np.intp]) -> int:
        sub = tuple(np.empty((idx.size, *o.shape[1:])) for o in outs)
        bad = run(rows.take(idx), sub)
        done = idx if bad < 0 else idx[:bad]
        for o, s in zip(outs, sub, strict=True):
            o[done] = s[: done.size]
        return -1 if bad < 0 else int(idx[bad])

    second = _executor().submit(half, halves[1])
    try:
        bad_a = half(halves[0])
    finally:
        bad_b = second.result()  # never leave the worker filtering past this call
    bads = [b for b in (bad_a, bad_b) if b >= 0]
    return min(bads) if bads else -1


class MonitorFeed:
    """A ``ConsistencyMonitor`` fed by the compiled loop (``core.tracking.kernels_monitor``):
    the monitor state of every (target, method) track in arrays, track t·M + j, written back
    into the monitor's records after each block (so its results and events are the ones
    ``ConsistencyMonitor.add`` would give, in the same order)."""

    def __init__(self, monitor: ConsistencyMonitor, methods: int):
        self.monitor = monitor
        self.m = methods
        w = monitor.window
        self.w = w
        # dof per update ≤ 4 (a 3D position and a Doppler): D ≤ 4 w.
        bands = [nis_band(d, monitor.level) if d else (np.nan, np.nan) for d in range(4 * w + 1)]
        self.lo = np.array([b[0] for b in bands])
        self.hi = np.array([b[1] for b in bands])
        self.arrays: dict[str, NDArray[Any]] = {}
        #: Tracks with a record in the monitor, in order of their first update.
        self.order: dict[int, None] = {}
        self.names: list[str] = []
        self.dirty = False
        # Tracks updated since the last ``store`` (first-updated ones in order), as arrays.
        self._touched: list[NDArray[np.intp]] = []
        self.grow(0)
        monitor.feeds.append(self)

    _FLOAT = ("nis_sum", "total_nis", "first_exit")
    _INT = ("count", "dof_sum", "total_dof", "updates", "windows", "above", "below", "run_out")

    def grow(self, targets: int) -> None:
        t = targets * self.m
        old = self.arrays
        new: dict[str, NDArray[Any]] = {
            "ring_nis": np.zeros((t, self.w)),
            "ring_dof": np.zeros((t, self.w), dtype=np.int64),
            "left": np.zeros(t, dtype=np.bool_),
            "seen": np.zeros(t, dtype=np.bool_),
            **{k: np.zeros(t) for k in self._FLOAT},
            **{k: np.zeros(t, dtype=np.int64) for k in self._INT},
        }
        new["first_exit"][:] = np.nan
        for k, a in old.items():
            new[k][: a.shape[0]] = a
        self.arrays = new

    def add(
        self,
        slot: NDArray[np.intp],
        time_s: NDArray[np.float64],
        nis: NDArray[np.float64],
        dof: NDArray[np.int64],
        update: NDArray[np.bool_],
        names: list[str],
    ) -> None:
        """The updates (plots where ``update``) of a block's (B, M) NIS, in plot then method
        order; ``names`` the monitor's name of every track t·M + j. Events go to the monitor
        at once; the tracks' records when it is next read (``store``)."""
        from radarviz.core.tracking.kernels_monitor import monitor_updates

        m = self.m
        rows = np.flatnonzero(update)
        track = (slot[rows, None] * m + np.arange(m)).ravel()
        times = np.repeat(time_s[rows], m)
        dofs = np.repeat(dof[rows], m)
        vals = np.ascontiguousarray(nis[rows].ravel())
        self.names = names
        a = self.arrays
        # Tracks new to this feed, in order of their first update (the monitor lists them so).
        fresh = ~a["seen"][track]
        if fresh.any():
            uniq, first = np.unique(track[fresh], return_index=True)
            new = uniq[np.argsort(first, kind="stable")]
            a["seen"][new] = True
            self._load(new, names)
            self.order.update(dict.fromkeys(new.tolist()))
            self._touched.append(new)
        self._touched.append(track)
        u = track.size
        ev = (np.empty(u, np.int64), np.empty(u), np.empty(u, np.int64), np.empty(u))
        ev = (*ev, np.empty(u), np.empty(u))
        n_ev = monitor_updates(
            track, _f(times), vals, dofs, self.w, self.monitor.sustain, self.lo, self.hi,
            a["ring_nis"], a["ring_dof"], a["count"], a["nis_sum"], a["dof_sum"],
            a["total_nis"], a["total_dof"], a["updates"], a["windows"], a["above"], a["below"],
            a["run_out"], a["left"], a["first_exit"], *ev,
        )  # fmt: skip
        self.dirty = True
        if n_ev:
            self._events(ev, n_ev)

    def _load(self, tracks: NDArray[np.intp], names: list[str]) -> None:
        """Tracks the monitor knows (from before this feed) start from its records."""
        self.monitor._sync()
        known = self.monitor._tracks
        if not known:
            return
        a = self.arrays
        for t in tracks.tolist():
            rec = known.get(names[t])
            if rec is None:
                continue
            win = list(rec.window)
            a["count"][t] = len(win)
            for i, (v, d) in enumerate(win):
                a["ring_nis"][t, i], a["ring_dof"][t, i] = v, d
            for k in ("nis_sum", "dof_sum", "total_nis", "total_dof", "updates", "windows"):
                a[k][t] = getattr(rec, k)
            for k in ("above", "below", "run_out", "left"):
                a[k][t] = getattr(rec, k)
            a["first_exit"][t] = np.nan if rec.first_exit_s is None else rec.first_exit_s

    def _events(self, ev: tuple, n_ev: int) -> None:
        from radarviz.core.tracking.consistency import ConsistencyEvent

        mon = self.monitor
        for e in range(n_ev):
            kind = "leaves" if ev[2][e] else "returns"
            event = ConsistencyEvent(
                self.names[int(ev[0][e])],
                float(ev[1][e]),
                kind,
                float(ev[3][e]),
                float(ev[4][e]),
                float(ev[5][e]),
            )
            mon.record(event)

    def release(self, targets: list[int]) -> None:
        """The rows of ``targets`` (deleted) go to new targets: their tracks' state is written
        into the monitor's records first, then the rows start empty."""
        self.store()
        m, a = self.m, self.arrays
        tracks = (np.asarray(targets, np.intp)[:, None] * m + np.arange(m)).ravel()
        for k, v in a.items():
            v[tracks] = np.nan if k == "first_exit" else 0
        for t in tracks.tolist():
            self.order.pop(t, None)

    def store(self) -> None:
        """Write the state of every track updated since the last call into the monitor's
        records (``ConsistencyMonitor`` calls this before it reads them): the cost follows
        the tracks updated, not every track the feed has seen."""
        from collections import deque

        from radarviz.core.tracking.consistency import _Track

        if not self.dirty:
            return
        self.dirty = False
        mon, a, names = self.monitor, self.arrays, self.names
        # New records first, in order of first update (the monitor lists its tracks so).
        rows = np.concatenate(self._touched) if self._touched else np.zeros(0, np.intp)
        self._touched = []
        _, first = np.unique(rows, return_index=True)
        touched = rows[np.sort(first)].tolist()
        cols = {k: a[k][touched].tolist() for k in self._FLOAT + self._INT + ("left",)}
        for i, t in enumerate(touched):
            rec = mon._tracks.setdefault(names[t], _Track())
            c = cols["count"][i]
            rec.window = deque(
                zip(a["ring_nis"][t, :c].tolist(), a["ring_dof"][t, :c].tolist(), strict=True)
            )
            for k in ("nis_sum", "total_nis", "dof_sum", "total_dof", "updates", "windows"):
                setattr(rec, k, cols[k][i])
            for k in ("above", "below", "run_out"):
                setattr(rec, k, cols[k][i])
            rec.left = bool(cols["left"][i])
            fe = cols["first_exit"][i]
            rec.first_exit_s = None if fe != fe else fe


@functools.cache
def _track_kernel(dims: int, imm: bool = False) -> Callable[..., int]:
    """The compiled tracker kernel of ``dims`` (2 or 3), of the cv model or (``imm``) the IMM,
    compiled (or loaded from numba's cache) on first use."""
    if imm:
        from radarviz.core.filters.kernels_imm import track_plots_imm_2d, track_plots_imm_3d

        return track_plots_imm_3d if dims == 3 else track_plots_imm_2d
    if dims == 3:
        from radarviz.core.filters.kernels_3d import track_plots_3d

        return track_plots_3d
    from radarviz.core.filters.kernels_track import track_plots_2d

    return track_plots_2d
