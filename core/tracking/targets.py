"""Many targets at once: one track per target and method, every target on the batch axis.

A measurement file with a ``target`` column (the radar's own track number, or any label)
holds the plots of many targets, interleaved. ``TargetTracker`` keeps, for every method group
(``core.filters.methods.method_groups``), one batch whose *target axis* holds every target
seen so far: (M, K) for M converted methods × K targets, (K,) for ``ekf`` or ``ukf``; with the
IMM each has its trailing model axis too (``core.filters.imm``).

* **Waves.** A block of plots is cut into waves: wave w holds the w-th plot of every target
  that has one in the block. A wave has at most one plot per target and the waves run in
  order, so every target's plots are filtered in its own order, whatever the order across
  targets.
* **Sub-batches.** Within a wave, the plots that start a track and the plots that update one,
  with and without a Doppler stage, are each one sub-batch: their targets' rows are gathered
  from the target axis, advanced by the engine's own calls as for one target
  (``core.filters.step.cv_step`` or ``core.filters.imm.imm_step``, with one time step per
  target and the plot's radar as a site per target), and put back. A target may change radar
  from one plot to the next.
* **Per target, as alone.** Rows do not interact, so each target's tracks are those that
  ``core.tracking.stream.StreamTracker`` gives for that target's plots alone, to rounding
  (the batched arithmetic takes other, equivalent routes through the same formulas).
* **Start**: the first-plot start only (the finite-memory start and track fit a window of one
  radar's plots per target; they are ``StreamTracker``'s, for files of one target).

* **Engines.** The above is the numpy engine (``StreamOptions.engine="numpy"``, the
  reference). On the compiled engine (the default) a block goes through one compiled pass in
  plot order instead, or a large one through one per half of its targets on two threads
  (``core.tracking.compiled``; no waves), for the cv model and the IMM;
  the converted Doppler update runs on numpy whatever the option (``engine`` tells which
  ran). ``add_arrays`` takes a block as
  arrays (``PlotBlock``) and returns the states as arrays (``TrackBlock``), beside
  ``add_block``'s lists of ``Plot`` and rows.

Times must not decrease within a target (across targets they may). The consistency monitor
names a track ``track_name(target, method)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.imm import (
    IMMState,
    imm_combine,
    imm_mix,
    imm_predict,
    imm_start,
    imm_step,
)
from radarviz.core.filters.innovation import InnovationStats
from radarviz.core.filters.measurement import PlotMeasurement, doppler_measurement
from radarviz.core.filters.methods import MethodGroup, PolarNoise, PolarPlot, method_groups
from radarviz.core.filters.models import CVModel, IMMModel
from radarviz.core.filters.predict import cv_predict
from radarviz.core.filters.state import CVBatch
from radarviz.core.filters.step import Stage, cv_step, moves
from radarviz.core.params import ParameterError
from radarviz.core.tracking.compiled import CompiledTracks, OutOfOrderError, PlotBlock, TrackBlock
from radarviz.core.tracking.stream import (
    Plot,
    PlotError,
    StateRow,
    StreamOptions,
    as_6,
    block_plots,
    check_methods,
    plot_block,
    polar_arrays,
    state_rows,
)


def track_name(target: str, method: str) -> str:
    """The name of ``target``'s track of ``method`` (consistency monitor, recording, summary):
    ``method`` for a file of one target (target ""), ``target/method`` otherwise."""
    return f"{target}/{method}" if target else method


class _TargetBank:
    """One method group's tracks of every target: arrays with a target axis (``axis``).

    CV: x (*lead, K, n), P (*lead, K, n, n); IMM: the models' x (*lead, K, r, n), P and the
    probabilities μ (*lead, K, r); ``lead`` is (M,) for M converted methods, () for a polar one.
    """

    def __init__(
        self, methods: tuple[str, ...], dims: int, motion: CVModel | IMMModel, sigma_v0_mps: float
    ):
        self.group = MethodGroup(methods)
        self.methods = methods
        self.motion = motion
        self.sigma_v0 = sigma_v0_mps
        self.axis = 1 if self.group.converted else 0
        lead = (len(methods),) if self.group.converted else ()
        n = 2 * dims
        self.imm = isinstance(motion, IMMModel)
        tail: tuple[tuple[int, ...], ...]
        if isinstance(motion, IMMModel):
            r = motion.models
            tail = ((r, n), (r, n, n), (r,))
        else:
            tail = ((n,), (n, n))
        self.arrays = [np.zeros((*lead, 0, *t)) for t in tail]

    def grow(self, capacity: int) -> None:
        """Room for ``capacity`` targets on the target axis (new rows zero, never read)."""
        grown = []
        for a in self.arrays:
            shape = list(a.shape)
            shape[self.axis] = capacity - a.shape[self.axis]
            grown.append(np.concatenate([a, np.zeros(shape)], axis=self.axis))
        self.arrays = grown

    def _take(self, ids: NDArray[np.intp]) -> list[NDArray[np.float64]]:
        return [a[:, ids] if self.axis else a[ids] for a in self.arrays]

    def _put(self, ids: NDArray[np.intp], values: list[NDArray[np.float64]]) -> None:
        for a, v in zip(self.arrays, values, strict=True):
            if self.axis:
                a[:, ids] = v
            else:
                a[ids] = v

    def step(
        self,
        ids: NDArray[np.intp],
        new: bool,
        plot: PolarPlot,
        noise: PolarNoise,
        site: NDArray[np.float64],
        doppler: Stage | None,
        dt_s: NDArray[np.float64],
        with_stats: bool,
    ) -> tuple[CVBatch, InnovationStats | None]:
        """Start (``new``) or advance the tracks of targets ``ids`` (K,) with one plot each:
        plot and noise arrays (K,), ``site`` (K, d), ``dt_s`` (K,). Returns the posterior,
        (*lead, K), and with ``with_stats`` the innovation statistics (None at a start)."""
        parts = self.group.start_parts(plot, noise) if self.group.converted else None
        stages: list[Stage] = [PlotMeasurement(self.group, plot, noise, site, parts)]
        if doppler is not None:
            stages.append(doppler)
        stats = None
        if new:
            state = self.group.start(
                plot, noise, sigma_v0_mps=self.sigma_v0, site=site, parts=parts
            )
            for stage in stages[1:]:  # the start is the position stage; Doppler follows it
                state = stage.update(state)
            if isinstance(self.motion, IMMModel):
                imm = imm_start(state, self.motion)
                self._put(ids, [imm.models.x, imm.models.P, imm.probabilities])
            else:
                self._put(ids, [state.x, state.P])
            return state, None
        if isinstance(self.motion, IMMModel):
            mx, mP, mu = self._take(ids)
            imm, state, stats = imm_step(
                IMMState(CVBatch(mx, mP), mu), dt_s, self.motion, stages, with_stats
            )
            self._put(ids, [imm.models.x, imm.models.P, imm.probabilities])
        else:
            x, P = self._take(ids)
            state, stats = cv_step(
                CVBatch(x, P), dt_s, self.motion.sigma_a_mps2, stages, with_stats
            )
            self._put(ids, [state.x, state.P])
        return state, stats


class TargetTracker:
    """Every requested method's track of every target, fed blocks of labelled plots.

    Args:
        methods: from ``ALL_METHODS`` (2D) or ``METHODS_3D`` (3D).
        three_d: plots carry elevations (every plot must then have one).
        options: ``StreamOptions`` with the first-plot start and no finite-memory track.
        reported: how many of ``methods`` (the leading ones) the monitor sees; the rest are
            tracked for the caller's own use (the association's gating method when it is
            not a requested one). None: all.
    """

    def __init__(
        self,
        methods: tuple[str, ...],
        three_d: bool,
        options: StreamOptions,
        reported: int | None = None,
    ):
        check_methods(methods, three_d)
        if options.init != "first-plot":
            raise ParameterError(
                "init must be first-plot for plots of many targets (the finite-memory start "
                "fits one target's window; track each target's file alone for it)",
                "init",
            )
        if options.finite_memory_k:
            raise ParameterError(
                "finite_memory_k must be 0 for plots of many targets (the finite-memory "
                "track is one target's; track each target's file alone for it)",
                "finite_memory_k",
            )
        self.methods = tuple(methods)
        self.reported = len(self.methods) if reported is None else int(reported)
        self.three_d = three_d
        self.options = options
        self.dims = 3 if three_d else 2
        motion = options.motion()
        self._banks = [
            _TargetBank(g, self.dims, motion, options.sigma_v0_mps)
            for g in method_groups(self.methods)
        ]
        self._where = {
            m: (b, i) for b, bank in enumerate(self._banks) for i, m in enumerate(bank.methods)
        }
        self._slot: dict[str, int] = {}
        # Rows of the target axis given back by ``forget`` (reused by new targets), and how
        # many rows were ever handed out.
        self._free: list[int] = []
        self._rows_used = 0
        self._time_s = np.zeros(0)
        self._compiled: CompiledTracks | None = None
        if options.compiled(three_d):
            self._compiled = CompiledTracks(
                self.methods,
                self.dims,
                options.sigma_a_mps2,
                options.sigma_v0_mps,
                options.use_doppler,
                options.monitor,
                track_name,
                imm=motion if isinstance(motion, IMMModel) else None,
                reported=self.reported,
            )

    def retune(self, options: StreamOptions) -> None:
        """The motion model's σa of ``options`` from the next block on (``GNNTracker.retune``
        checks that nothing else changed): the tracks keep their states."""
        motion = options.motion()
        self.options = options
        for bank in self._banks:
            bank.motion = motion
        if self._compiled is not None:
            self._compiled.retune(options.sigma_a_mps2, motion)

    @property
    def targets(self) -> tuple[str, ...]:
        """The targets seen so far, in order of their first plot."""
        if self._compiled is not None:
            return self._compiled.targets
        return tuple(self._slot)

    @property
    def compiled(self) -> CompiledTracks | None:
        """The tracks on the compiled engine (``CompiledTracks``), or None (numpy)."""
        return self._compiled

    @property
    def engine(self) -> str:
        """The engine the tracks run on (``StreamOptions.engine``, or numpy for a track the
        compiled engine has no kernel for)."""
        return "numpy" if self._compiled is None else "compiled"

    def add_arrays(self, block: PlotBlock) -> TrackBlock:
        """Filter a block given as arrays (the fast path: no ``Plot`` per row); returns every
        method's posterior after each plot, x (B, M, n), P (B, M, n, n), n = 2·dims, in
        ``methods`` order. A ``PlotError`` carries ``index`` (the plot's position)."""
        if (block.elevation_rad is not None) != self.three_d:
            raise PlotError("elevation_deg", "every plot of a 3D track needs an elevation")
        if self._compiled is None:
            tb = _stacked(self.add_block(block_plots(block)), 2 * self.dims)
            slots = np.array([self._slot[t] for t in block.labels], dtype=np.intp)
            return tb._replace(target=slots[block.target])
        try:
            return self._compiled.add(block)
        except OutOfOrderError as exc:
            target = block.labels[block.target[exc.index]]
            raise PlotError(
                "time_s",
                f"target {target!r}: times must not decrease within a target (got "
                f"{exc.time_s!r} after {exc.previous_s!r})",
                index=exc.index,
            ) from None

    def add_block(self, plots: list[Plot]) -> list[list[StateRow]]:
        """Filter a block of plots; returns, per plot, (method, x (6,), P (6, 6)) per method
        in ``methods`` order (state rows in the 3D layout). A ``PlotError`` carries ``index``,
        the position in the block of the plot it is about."""
        waves: list[list[int]] = []
        seen: dict[str, int] = {}
        for i, p in enumerate(plots):
            if self.three_d != (p.elevation_rad is not None):
                raise PlotError(
                    "elevation_deg", "every plot of a 3D track needs an elevation", index=i
                )
        if self._compiled is not None:
            return state_rows(self.add_arrays(plot_block(plots)), self.methods)
        for i, p in enumerate(plots):
            w = seen.get(p.target, 0)
            seen[p.target] = w + 1
            if w == len(waves):
                waves.append([])
            waves[w].append(i)
        out: list[list[StateRow]] = [[] for _ in plots]
        for wave in waves:
            self._wave(plots, wave, out)
        return out

    def _wave(self, plots: list[Plot], wave: list[int], out: list[list[StateRow]]) -> None:
        """Filter plots ``wave`` of ``plots`` (at most one per target) into ``out``."""
        new = np.zeros(len(wave), dtype=bool)
        for j, i in enumerate(wave):
            target = plots[i].target
            if target not in self._slot:
                if self._free:
                    self._slot[target] = self._free.pop()
                else:
                    self._slot[target] = self._rows_used
                    self._rows_used += 1
                new[j] = True
        capacity = self._time_s.size
        if self._rows_used > capacity:
            capacity = max(self._rows_used, 2 * capacity, 16)
            for bank in self._banks:
                bank.grow(capacity)
            self._time_s = np.concatenate([self._time_s, np.zeros(capacity - self._time_s.size)])
        ids = np.array([self._slot[plots[i].target] for i in wave], dtype=np.intp)
        times = np.array([plots[i].time_s for i in wave])
        dt = times - self._time_s[ids]
        for j in np.flatnonzero(~new & (dt < 0)):
            p = plots[wave[j]]
            raise PlotError(
                "time_s",
                f"target {p.target!r}: times must not decrease within a target (got "
                f"{p.time_s!r} after {float(self._time_s[ids[j]])!r})",
                index=wave[j],
            )
        use_doppler = self.options.use_doppler
        doppler = np.array([use_doppler and plots[i].radial_velocity_mps is not None for i in wave])
        for start in (True, False):
            for dop in (False, True):
                sel = np.flatnonzero((new == start) & (doppler == dop))
                if sel.size:
                    self._run(plots, [wave[j] for j in sel], ids[sel], start, dop, dt[sel], out)
        self._time_s[ids] = times

    def _run(
        self,
        plots: list[Plot],
        which: list[int],
        ids: NDArray[np.intp],
        start: bool,
        with_doppler: bool,
        dt_s: NDArray[np.float64],
        out: list[list[StateRow]],
    ) -> None:
        """One sub-batch: plots ``which`` (one per target ``ids``), all starting or all
        updating, all with or all without a Doppler stage."""
        sub = [plots[i] for i in which]
        plot, noise = polar_arrays(sub, self.dims)
        site = np.array([p.site for p in sub], dtype=np.float64)[:, : self.dims]
        doppler = None
        if with_doppler:
            doppler = doppler_measurement(
                self.options.doppler_update,
                radial_velocity_mps=np.array([p.radial_velocity_mps for p in sub], dtype=float),
                range_m=plot.range_m,
                azimuth_rad=plot.azimuth_rad,
                elevation_rad=np.zeros(len(sub))
                if plot.elevation_rad is None
                else plot.elevation_rad,
                sigma_vr_mps=np.array([p.sigma_vr_mps for p in sub], dtype=float),
                sigma_r_m=noise.sigma_r_m,
                sigma_beta_rad=noise.sigma_beta_rad,
                sigma_elevation_rad=noise.sigma_elevation_rad,
                site=site,
            )
        monitor = self.options.monitor
        results = []
        for bank in self._banks:
            state, stats = bank.step(
                ids, start, plot, noise, site, doppler, dt_s, monitor is not None
            )
            results.append((as_6(state), stats))
        for j, m in enumerate(self.methods):
            b, row = self._where[m]
            (x6, P6), stats = results[b]
            converted = self._banks[b].axis == 1
            xs, Ps = (x6[row], P6[row]) if converted else (x6, P6)
            nis = None
            if stats is not None and monitor is not None and j < self.reported:
                nis = stats.nis[row] if converted else stats.nis
            for i, x, P in zip(which, xs, Ps, strict=True):
                out[i].append((m, x, P))
            if nis is not None:
                assert monitor is not None and stats is not None
                for p, v in zip(sub, nis.tolist(), strict=True):
                    monitor.add(track_name(p.target, m), p.time_s, v, stats.dof)

    def predicted(
        self, method: str, targets: list[str], time_s: float | NDArray[np.float64]
    ) -> CVBatch:
        """``method``'s tracks of ``targets`` (K,) predicted to ``time_s`` (one time, or one
        per target (K,); a target may be listed more than once), the tracks left as
        they are: x (K, n), P (K, n, n) (the IMM's moment-matched combined prediction, the one
        its consistency statistics use). A track last updated at ``time_s`` is returned as it
        is (dt = 0). Every target's last plot must be at or before ``time_s``. On the compiled
        engine the same steps run compiled (``core.tracking.compiled.CompiledTracks.predicted``;
        the same numbers to rounding)."""
        if self._compiled is not None:
            return CVBatch(*self._compiled.predicted(method, targets, time_s))
        b, row = self._where[method]
        bank = self._banks[b]
        ids = np.array([self._slot[t] for t in targets], dtype=np.intp)
        dt = time_s - self._time_s[ids]
        if dt.size and dt.min() < 0:
            raise ValueError(f"predicted: time {time_s!r} is before a track's last plot")
        arrays = [a[row][ids] if bank.axis else a[ids] for a in bank.arrays]
        if isinstance(bank.motion, IMMModel):
            mixed, c = imm_mix(
                IMMState(CVBatch(arrays[0], arrays[1]), arrays[2]), bank.motion.transition_matrix()
            )
            pred = imm_predict(mixed, dt, bank.motion) if moves(dt) else mixed
            return imm_combine(pred, c)
        state = CVBatch(arrays[0], arrays[1])
        return cv_predict(state, dt, bank.motion.sigma_a_mps2) if moves(dt) else state

    def gate_distances(
        self,
        method: str,
        targets: list[str],
        time_s: NDArray[np.float64],
        plot: PolarPlot,
        noise: PolarNoise,
        site: NDArray[np.float64],
    ) -> NDArray[np.float64] | None:
        """d² = νᵀ S⁻¹ ν of N (track, plot) pairs, ``method``'s track of targets[i]
        predicted to time_s[i] against plot i (plot, noise (N,) arrays, site (N, d)), in one
        compiled pass (``CompiledTracks.gate_nis``; NaN → ∞, outside every gate): on the
        compiled engine in 2D for a converted method that converts the plot alone (naive,
        seed, cmkf_d, ucm), the numbers of ``core.tracking.association.mahalanobis_pairs``
        to rounding. None elsewhere (the caller predicts and scores on numpy)."""
        if self._compiled is None or self.three_d or method not in _PLOT_CONVERSIONS:
            return None
        d2 = self._compiled.gate_nis(
            method, targets, time_s, plot.range_m, plot.azimuth_rad,
            np.broadcast_to(noise.sigma_r_m, time_s.shape),
            np.broadcast_to(noise.sigma_beta_rad, time_s.shape), site,
        )  # fmt: skip
        return np.where(np.isfinite(d2), d2, np.inf)

    def forget(self, targets: list[str]) -> None:
        """Drop the tracks of ``targets`` (a deleted track): their rows go to new targets, so
        memory follows the live tracks, not every track ever started. A label forgotten and
        seen again starts a new track. A consistency monitor that does not ``keep_deleted``
        drops their records too."""
        if self._compiled is not None:
            self._compiled.forget(targets)
        else:
            for t in targets:
                self._free.append(self._slot.pop(t))
        monitor = self.options.monitor
        if monitor is not None and not getattr(monitor, "keep_deleted", True):
            reported = self.methods[: self.reported]
            monitor.forget([track_name(t, m) for t in targets for m in reported])


#: The methods whose position measurement converts the plot alone (``gate_distances``).
_PLOT_CONVERSIONS = ("naive", "seed", "cmkf_d", "ucm")


def _stacked(rows: list[list[StateRow]], n: int) -> TrackBlock:
    """Rows of ``add_block`` as a ``TrackBlock`` of state size n (targets not filled in)."""
    x = np.array([[x6[:n] for _, x6, _ in r] for r in rows]).reshape(len(rows), -1, n)
    P = np.array([[P6[:n, :n] for _, _, P6 in r] for r in rows]).reshape(len(rows), -1, n, n)
    return TrackBlock(x, P, np.zeros(len(rows), dtype=np.intp))
