"""Plot-by-plot tracking of one target for streamed measurements (no file I/O here).

``filter_block`` (``core.experiments.prosov``) runs one method over a whole (M, N) array of
scans with a fixed period. A measurement file is different: plots come one at a time, from radars
that need not sit at the origin, with any time step, optionally with elevation (3D) and Doppler
radial velocity. ``StreamTracker`` keeps one track per method and takes one ``Plot`` at a time,
with the same engine as the Monte Carlo (``core.filters``): a track is a batch of one.

* **Groups.** The converted-measurement methods share one batch (one row per method): the
  prediction and the position update are one set of vector operations for all of them, only
  the conversion is per method. ``ekf`` and ``ukf`` are a batch of one each. Rows do not
  interact: each row's result is that of a batch of one, to rounding.
* **2D** (no elevation) and **3D** (elevation on every plot): all methods of
  ``core.filters.methods`` (every one exists in both, ``METHODS_3D``).
* **First plot**: the method's start (``Method.start``), shifted by the radar site. Later plots:
  predict with dt = t − t_previous (dt = 0, equal times, skips the prediction), then update
  with the plot's radar as ``site`` (the polar updates and ``ducm`` linearise about the
  prediction as seen from that radar). A file from a radar at the origin gives
  ``filter_block``'s tracks.
* **Doppler**: a plot's radial velocity, when present and ``use_doppler``, is a second, scalar
  update after the position update, by ``StreamOptions.doppler_update``: ``"line_of_sight"``
  (the default; ``core.filters.doppler``, linear along the measured line of sight) or
  ``"converted"`` (the r̂ V̂r pseudo-measurement of ``core.filters.converted_doppler``, the
  Monte Carlo's ``range_converted_doppler`` update). On the first plot it follows the start.
* **Start** ``"finite-memory"`` (Gorshkov and Zavizhenets' remark): the first ``init_k`` plots
  of the first plot's radar, which must be equally spaced in time, are fitted by least squares
  for (r, Vr, a) (``core.finite_memory``; range only when they carry no Doppler) and every
  method starts at the k-th of them (``core.finite_memory.start``). No track exists before:
  the plots up to the start (other radars' included, which are not used) give no rows.

* **Motion model** (``StreamOptions.model``): ``"cv"``, the constant-velocity filter with
  white-noise acceleration σa (σa = 0: the papers' Q = 0), or ``"imm"``, the IMM of
  constant-velocity models (``core.filters.imm``): each group's batch then has a trailing
  model axis and its rows are the combined estimates. Either way a plot is the same stages
  (``core.filters.measurement``: the method's update, then Doppler), applied by
  ``core.filters.step.cv_step`` or ``core.filters.imm.imm_step``.
* **Consistency**: with ``StreamOptions.monitor`` every update's NIS (of the combined
  prediction for the IMM) goes to a ``core.tracking.consistency.ConsistencyMonitor``, track
  name = method.
* **Finite-memory track** (``StreamOptions.finite_memory_k`` = k > 0): beside the recursive
  tracks, at each plot of the first radar seen, the finite-memory fit over its last k equally
  spaced plots (the start's fit, slid along), as an extra row named ``FINITE_MEMORY_TRACK``.

State rows are always in the 3D layout (x, ẋ, y, ẏ, z, ż), z = ż = 0 for 2D tracks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import overload

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.compiled import ENGINES
from radarviz.core.filters.imm import IMMState, imm_start, imm_step
from radarviz.core.filters.innovation import InnovationStats
from radarviz.core.filters.measurement import (
    DOPPLER_UPDATES,
    PlotMeasurement,
    doppler_measurement,
)
from radarviz.core.filters.methods import (
    MethodGroup,
    Parts,
    PolarNoise,
    PolarPlot,
    method_groups,
    method_names,
)
from radarviz.core.filters.models import DEFAULT_IMM, MOTION_MODELS, CVModel, IMMModel
from radarviz.core.filters.state import CVBatch
from radarviz.core.filters.step import Stage, cv_step
from radarviz.core.finite_memory.fit import finite_memory_fit
from radarviz.core.finite_memory.start import finite_memory_start
from radarviz.core.params import ParameterError, check, check_choice, check_int
from radarviz.core.tracking.compiled import (
    COMPILED_DIMS,
    CompiledTracks,
    OutOfOrderError,
    PlotBlock,
    RadarTable,
    TrackBlock,
)
from radarviz.core.tracking.consistency import ConsistencyMonitor

INIT_MODES: tuple[str, ...] = ("first-plot", "finite-memory")
#: The method name of the sliding-window finite-memory track in the rows.
FINITE_MEMORY_TRACK = "finite-memory"

StateRow = tuple[str, NDArray[np.float64], NDArray[np.float64]]


@dataclass(frozen=True)
class Plot:
    """One measurement of the target and the accuracy of the radar that made it.

    Angles in rad, distances in m, speeds in m/s. ``elevation_rad`` is None for a 2D plot and
    ``radial_velocity_mps`` None for a plot without Doppler. ``target`` labels the target the
    plot belongs to in a file of many targets (``core.tracking.targets``); "" in a file of one.
    ``radar_track`` is the radar's own track number (ASTERIX I048/161) or None: a label the
    association (which sets ``target`` to its track id) keeps beside its own.
    """

    time_s: float
    range_m: float
    azimuth_rad: float
    sigma_r_m: float
    sigma_beta_rad: float
    site: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radar: str = ""
    elevation_rad: float | None = None
    sigma_elevation_rad: float = 0.0
    radial_velocity_mps: float | None = None
    sigma_vr_mps: float = 0.0
    target: str = ""
    radar_track: int | None = None


class PlotError(ParameterError):
    """A plot the tracker cannot use; ``column`` names the offending input column."""

    def __init__(self, column: str, message: str, index: int = 0):
        super().__init__(message)
        self.column = column
        self.index = index


def polar_arrays(plots: list[Plot], dims: int) -> tuple[PolarPlot, PolarNoise]:
    """A block's (r̂, β̂[, ε̂]) and noise std as (B,) arrays (ε̂ only when ``dims`` is 3)."""
    col = {
        name: np.array([getattr(p, name) for p in plots], dtype=np.float64)
        for name in (
            "range_m",
            "azimuth_rad",
            "sigma_r_m",
            "sigma_beta_rad",
            "sigma_elevation_rad",
        )
    }
    el = None
    if dims == 3:
        el = np.array([p.elevation_rad for p in plots], dtype=np.float64)
    return (
        PolarPlot(col["range_m"], col["azimuth_rad"], el),
        PolarNoise(col["sigma_r_m"], col["sigma_beta_rad"], col["sigma_elevation_rad"]),
    )


class TrackGroup:
    """The tracks of one target for methods that share an update kind, as one batch.

    ``methods`` is either one polar method (``ekf``, ``ukf``) or any number of converted-
    measurement methods (``core.filters.methods.MethodGroup``); ``dims`` is 2 or 3. The
    batch has one row per method; with an IMM ``motion`` each row carries its r models on a
    trailing axis (``core.filters.imm``) and ``state`` is the combined estimate.
    """

    def __init__(
        self,
        methods: tuple[str, ...],
        dims: int,
        motion: CVModel | IMMModel | None = None,
        sigma_v0_mps: float = 1000.0,
    ):
        for m in methods:
            check_choice("method", m, method_names(dims))
        self.group = MethodGroup(methods)
        self.methods = tuple(methods)
        self.dims = dims
        self.motion = CVModel() if motion is None else motion
        self.sigma_v0 = float(check("sigma_v0_mps", sigma_v0_mps))
        self.state: CVBatch | None = None
        self.imm: IMMState | None = None
        self.time_s: float | None = None

    def precompute(self, plots: list[Plot]) -> Parts | None:
        """Every converted method's radar-centred point and covariance for a block of plots,
        each (M, B); None for a polar group.

        The conversions do not depend on the track, so a block of plots is converted in one
        vectorised call per method (the per-plot calls dominated the time). ``ducm``, which
        needs the prediction, gets its start conversion here (``ucm``'s) and is converted
        again about the prediction by ``MethodGroup.update``.
        """
        if not self.group.converted:
            return None
        return self.group.start_parts(*polar_arrays(plots, self.dims))

    def start_from(self, x: NDArray[np.float64], P: NDArray[np.float64], time_s: float) -> None:
        """Start every method of the group at x (n,), P (n, n) (absolute frame)."""
        m = len(self.methods)
        self._started(CVBatch(np.tile(x, (m, 1)), np.tile(P, (m, 1, 1))), time_s)

    def _started(self, state: CVBatch, time_s: float) -> None:
        self.state, self.time_s = state, time_s
        if isinstance(self.motion, IMMModel):
            self.imm = imm_start(state, self.motion)

    def add(
        self,
        p: Plot,
        pre: Parts | None,
        use_doppler: bool = True,
        polar: tuple[PolarPlot, PolarNoise] | None = None,
        with_stats: bool = True,
        doppler_update: str = "line_of_sight",
    ) -> tuple[CVBatch, InnovationStats | None]:
        """Filter one plot; ``pre`` this plot's slice of ``precompute`` (z (M,), R (M,));
        ``polar``: the plot as (1,) arrays if the caller has them (every group shares them);
        ``doppler_update``: one of ``DOPPLER_UPDATES`` (``StreamOptions.doppler_update``).

        Returns the posterior (one row per method) and, with ``with_stats``, the plot's
        innovation statistics (None at the start, which has no prediction).
        """
        site = np.asarray(p.site[: self.dims], dtype=np.float64)
        plot, noise = polar if polar is not None else polar_arrays([p], self.dims)
        doppler = None
        if use_doppler and p.radial_velocity_mps is not None:
            doppler = doppler_measurement(
                doppler_update,
                radial_velocity_mps=p.radial_velocity_mps,
                range_m=p.range_m,
                azimuth_rad=p.azimuth_rad,
                elevation_rad=0.0 if p.elevation_rad is None else p.elevation_rad,
                sigma_vr_mps=p.sigma_vr_mps,
                sigma_r_m=p.sigma_r_m,
                sigma_beta_rad=p.sigma_beta_rad,
                sigma_elevation_rad=p.sigma_elevation_rad,
                site=site,
            )
        return self.add_arrays(p.time_s, plot, noise, site, pre, doppler, with_stats)

    def add_arrays(
        self,
        time_s: float,
        plot: PolarPlot,
        noise: PolarNoise,
        site: NDArray[np.float64],
        pre: Parts | None,
        doppler: Stage | None,
        with_stats: bool = True,
    ) -> tuple[CVBatch, InnovationStats | None]:
        """``add`` for one plot time given as arrays: the plot's values broadcast against the
        batch after its method axis, so a batch of runs (k, M) takes (M,) arrays (the Monte
        Carlo of ``core.experiments.manoeuvre``) and a single track (k,) takes (1,) ones."""
        stages: list[Stage] = [PlotMeasurement(self.group, plot, noise, site, pre)]
        if doppler is not None:
            stages.append(doppler)
        if self.state is None:
            state = self.group.start(plot, noise, sigma_v0_mps=self.sigma_v0, site=site, parts=pre)
            for stage in stages[1:]:  # the start is the position stage; Doppler follows it
                state = stage.update(state)
            self._started(state, time_s)
            return state, None
        assert self.time_s is not None
        dt = time_s - self.time_s
        if dt < 0:
            raise ValueError(f"times must not decrease (got {time_s} after {self.time_s})")
        if self.imm is not None:
            assert isinstance(self.motion, IMMModel)
            self.imm, state, stats = imm_step(self.imm, dt, self.motion, stages, with_stats)
        else:
            assert isinstance(self.motion, CVModel)
            state, stats = cv_step(self.state, dt, self.motion.sigma_a_mps2, stages, with_stats)
        self.state, self.time_s = state, time_s
        return state, stats


@dataclass(frozen=True)
class StreamOptions:
    """How ``StreamTracker`` filters.

    Attributes:
        sigma_a_mps2: process-noise acceleration std of the ``cv`` model (0: constant
            velocity exactly, the papers' Q = 0).
        sigma_v0_mps: velocity std of the start (the papers' 1000 m/s).
        use_doppler: use the plots' radial velocities (when they have them).
        doppler_update: how a radial velocity updates a track, one of
            ``core.filters.measurement.DOPPLER_UPDATES``: ``"line_of_sight"`` (default,
            ``core.filters.doppler``) or ``"converted"`` (r̂ V̂r,
            ``core.filters.converted_doppler``; numpy engine only, so a compiled fast path
            must hand such a tracker to the numpy one).
        init: ``"first-plot"`` (the papers' start) or ``"finite-memory"`` (Gorshkov and
            Zavizhenets' window fit, ``docs/finite_memory.md``).
        init_k: plots in the finite-memory window (≥ 2 with Doppler, ≥ 3 without).
        model: ``"cv"`` or ``"imm"`` (``core.filters.models``).
        imm_sigma_a_mps2, transition_prob, imm_turn_rate_degps: the IMM's σa per model, its
            transition matrix (rows) and each model's turn rate (°/s, 0: constant velocity;
            None: every model constant velocity), used with ``model="imm"`` and checked
            always.
        finite_memory_k: 0, or the window k of a sliding-window finite-memory track kept
            beside the recursive ones (rows named ``FINITE_MEMORY_TRACK``).
        monitor: a consistency monitor fed every update's NIS, track name = method
            (``core.tracking.consistency``), or None.
        engine: ``"compiled"`` (``core.tracking.compiled``: one compiled pass per block of
            plots, for the tracks it has a kernel for: 2D or 3D, ``cv`` or ``imm``, the
            line-of-sight Doppler update, the first-plot start, no finite-memory track; the
            others run on numpy) or
            ``"numpy"`` (the reference).
    """

    sigma_a_mps2: float = 0.0
    sigma_v0_mps: float = 1000.0
    use_doppler: bool = True
    doppler_update: str = "line_of_sight"
    init: str = "first-plot"
    init_k: int = 3
    model: str = "cv"
    imm_sigma_a_mps2: tuple[float, ...] = DEFAULT_IMM.sigma_a_mps2
    transition_prob: tuple[tuple[float, ...], ...] = DEFAULT_IMM.transition
    imm_turn_rate_degps: tuple[float, ...] | None = DEFAULT_IMM.turn_rate_degps
    finite_memory_k: int = 0
    monitor: ConsistencyMonitor | None = field(default=None, compare=False)
    engine: str = "compiled"

    def __post_init__(self) -> None:
        check_choice("engine", self.engine, ENGINES)
        check("sigma_a_mps2", self.sigma_a_mps2)
        check("sigma_v0_mps", self.sigma_v0_mps)
        check_choice("doppler_update", self.doppler_update, DOPPLER_UPDATES)
        check_choice("init", self.init, INIT_MODES)
        check_int("init_k", self.init_k, low=2, high=1000)
        check_choice("model", self.model, MOTION_MODELS)
        self.motion()
        if self.finite_memory_k:
            check_int("finite_memory_k", self.finite_memory_k, low=2, high=1000)

    def compiled(self, three_d: bool) -> bool:
        """Whether a track of many targets with these options runs on the compiled engine."""
        # A monitor that is not a ConsistencyMonitor (no keep_history) wants every add call,
        # which only the numpy engine makes.
        history = self.monitor is not None and getattr(self.monitor, "keep_history", True)
        return (
            self.engine == "compiled"
            and self.doppler_update == "line_of_sight"
            and (3 if three_d else 2) in COMPILED_DIMS
            and not history
        )

    def motion(self) -> CVModel | IMMModel:
        """The motion model these options ask for."""
        turns = self.imm_turn_rate_degps
        imm = IMMModel(
            tuple(self.imm_sigma_a_mps2),
            tuple(map(tuple, self.transition_prob)),
            turn_rate_degps=None if turns is None else tuple(turns),
        )
        if self.model == "imm":
            return imm
        # The IMM's parameters are checked even for a cv run: a bad value is an error either way.
        return CVModel(self.sigma_a_mps2)


def motion_fields(
    model: str | None = None,
    sigma_a_mps2: float | None = None,
    imm_sigma_a_mps2: tuple[float, ...] | list[float] | None = None,
    transition_prob: object = None,
    imm_turn_rate_degps: tuple[float, ...] | list[float] | None = None,
    names: dict[str, str] | None = None,
) -> dict[str, object]:
    """The motion-model fields of ``StreamOptions`` from what a caller gave, None for not
    given: the one rule of ``radarviz track`` and of ``radarviz.track``/``track_file``.

    * ``model`` None: ``cv`` if ``sigma_a_mps2`` is given, else ``imm`` (the IMM of
      ``DEFAULT_IMM``: a quiet, two turning and a manoeuvre model, consistent on
      manoeuvring aircraft). ``sigma_a_mps2`` None means 0 for ``cv`` (the papers' Q = 0).
    * A value of the other model is refused rather than ignored: ``sigma_a_mps2`` with
      ``imm``; ``imm_sigma_a_mps2``, ``transition_prob`` or ``imm_turn_rate_degps`` with
      ``cv``.
    * ``transition_prob``: rows, or r × r numbers row by row (r the number of models).
    * The default models' turn rates go with the default σa; models given by
      ``imm_sigma_a_mps2`` are constant velocity unless ``imm_turn_rate_degps`` says
      otherwise.

    ``names`` maps a parameter to what the caller calls it in its errors (the command line:
    its flags). Each value is then checked by ``StreamOptions``.
    """
    call = {k: k for k in ("model", "sigma_a_mps2", "imm_sigma_a_mps2", "transition_prob")}
    call |= {"imm_turn_rate_degps": "imm_turn_rate_degps"} | dict(names or {})
    if model is None:
        model = "cv" if sigma_a_mps2 is not None else "imm"
    if model == "imm" and sigma_a_mps2 is not None:
        raise ParameterError(
            f"{call['sigma_a_mps2']} is the cv model's; with {call['model']} imm use "
            f"{call['imm_sigma_a_mps2']}",
            "sigma_a_mps2",
        )
    if model == "cv":
        for name, value in (
            ("imm_sigma_a_mps2", imm_sigma_a_mps2),
            ("transition_prob", transition_prob),
            ("imm_turn_rate_degps", imm_turn_rate_degps),
        ):
            if value is not None:
                raise ParameterError(
                    f"{call[name]} is the imm model's; it needs {call['model']} imm", name
                )
    sigmas = tuple(DEFAULT_IMM.sigma_a_mps2 if imm_sigma_a_mps2 is None else imm_sigma_a_mps2)
    transition = DEFAULT_IMM.transition
    if transition_prob is not None:
        r = len(sigmas)
        rows = np.asarray(transition_prob, dtype=np.float64)
        if rows.ndim == 1 and rows.size == r * r:
            rows = rows.reshape(r, r)
        if rows.shape != (r, r):
            raise ParameterError(
                f"{call['transition_prob']} must give {r * r} probabilities ({r} rows of {r}, "
                f"one per model of {call['imm_sigma_a_mps2']}) (got {rows.size})",
                "transition_prob",
            )
        transition = tuple(tuple(float(v) for v in row) for row in rows)
    turns = DEFAULT_IMM.turn_rate_degps if imm_sigma_a_mps2 is None else None
    if imm_turn_rate_degps is not None:
        turns = tuple(imm_turn_rate_degps)
    return {
        "model": model,
        "sigma_a_mps2": 0.0 if sigma_a_mps2 is None else sigma_a_mps2,
        "imm_sigma_a_mps2": sigmas,
        "transition_prob": transition,
        "imm_turn_rate_degps": turns,
    }


def check_methods(methods: tuple[str, ...], three_d: bool) -> None:
    """``methods`` must be at least one of the methods that exist in 2D or in 3D."""
    allowed = method_names(3 if three_d else 2)
    if not methods:
        raise ParameterError(f"method must name at least one of {', '.join(allowed)}")
    for m in methods:
        check_choice("method", m, allowed)


class StreamTracker:
    """Every requested method's track of one target, fed one ``Plot`` at a time.

    Args:
        methods: from ``ALL_METHODS`` (2D) or ``METHODS_3D`` (3D).
        three_d: plots carry elevations (every plot must then have one).
        options: see ``StreamOptions``.
    """

    def __init__(self, methods: tuple[str, ...], three_d: bool, options: StreamOptions):
        check_methods(methods, three_d)
        self.methods = tuple(methods)
        self.three_d = three_d
        self.options = options
        o = options
        dims = 3 if three_d else 2
        self._groups = [
            TrackGroup(g, dims, o.motion(), o.sigma_v0_mps) for g in method_groups(self.methods)
        ]
        self._where = {
            m: (k, i) for k, tr in enumerate(self._groups) for i, m in enumerate(tr.methods)
        }
        self._window: list[Plot] | None = [] if o.init == "finite-memory" else None
        self._compiled = None
        if o.compiled(three_d) and o.init == "first-plot" and not o.finite_memory_k:
            motion = o.motion()
            self._compiled = CompiledTracks(
                self.methods,
                dims,
                o.sigma_a_mps2,
                o.sigma_v0_mps,
                o.use_doppler,
                o.monitor,
                imm=motion if isinstance(motion, IMMModel) else None,
            )
        self._started = False
        self._fm_window: list[Plot] = []
        self._fm_radar: str | None = None

    def add(self, p: Plot) -> list[StateRow]:
        """Filter one plot; returns (method, x (6,), P (6, 6)) per method in ``methods`` order,
        or [] while the finite-memory window fills."""
        return self.add_block([p])[0]

    def add_block(self, plots: list[Plot]) -> list[list[StateRow]]:
        """``add`` for each plot of a block, in order (conversions vectorised over the block).

        A ``PlotError`` carries ``index``, the position in the block of the plot it is about.
        """
        for i, p in enumerate(plots):
            if self.three_d != (p.elevation_rad is not None):
                raise PlotError(
                    "elevation_deg", "every plot of a 3D track needs an elevation", index=i
                )
        if self._compiled is not None:
            return self._compiled_block(plots)
        use_doppler = self.options.use_doppler
        pre = [g.precompute(plots) for g in self._groups]
        out: list[list[StateRow]] = []
        for i, p in enumerate(plots):
            if self._window is not None and not self._started:
                try:
                    self._fill_window(p)
                except PlotError as exc:
                    exc.index = i
                    raise
                out.append(self._rows() if self._started else [])
                continue
            polar = polar_arrays([p], 3 if self.three_d else 2)  # shared by all groups
            monitor = self.options.monitor
            for g, parts in zip(self._groups, pre, strict=True):
                row = None
                if parts is not None:
                    row = ([z[:, i] for z in parts[0]], {k: v[:, i] for k, v in parts[1].items()})
                _, stats = g.add(
                    p, row, use_doppler, polar, monitor is not None, self.options.doppler_update
                )
                if monitor is not None and stats is not None:
                    for j, m in enumerate(g.methods):
                        monitor.add(m, p.time_s, float(stats.nis[j]), stats.dof)
            self._started = True
            rows = self._rows()
            if self.options.finite_memory_k:
                try:
                    fm = self._finite_memory_row(p)
                except PlotError as exc:
                    exc.index = i
                    raise
                if fm is not None:
                    rows.append(fm)
            out.append(rows)
        return out

    def _compiled_block(self, plots: list[Plot]) -> list[list[StateRow]]:
        """``add_block`` on the compiled engine (``core.tracking.compiled``)."""
        assert self._compiled is not None
        try:
            tb = self._compiled.add(plot_block(plots, one_target=True))
        except OutOfOrderError as exc:
            raise ValueError(
                f"times must not decrease (got {exc.time_s} after {exc.previous_s})"
            ) from None
        return state_rows(tb, self.methods)

    def _rows(self) -> list[StateRow]:
        rows = []
        for m in self.methods:
            k, i = self._where[m]
            st = self._groups[k].state
            assert st is not None
            rows.append((m, *_rows_6(st, i)))
        return rows

    def _fill_window(self, p: Plot) -> None:
        """Collect the finite-memory window; start every track at its last plot."""
        assert self._window is not None
        win = self._window
        k = self.options.init_k
        if win:
            first = win[0]
            if p.radar != first.radar:
                return  # the window is the first radar's; other radars wait for the start
            if len(win) >= 2:
                period = win[1].time_s - first.time_s
                dt = p.time_s - win[-1].time_s
                if not math.isclose(dt, period, rel_tol=1e-6, abs_tol=1e-9):
                    raise PlotError(
                        "time_s",
                        f"the finite-memory start needs {k} equally spaced plots "
                        f"(step {period!r} s, then {dt!r} s)",
                    )
            elif p.time_s <= first.time_s:
                raise PlotError("time_s", "the finite-memory start needs increasing times")
        win.append(p)
        if len(win) < k:
            return
        start = self._window_fit(win, "the finite-memory start", "init_k")
        for g in self._groups:
            g.start_from(start.x.copy(), start.P.copy(), p.time_s)
        self._started = True
        self._window = None

    def _window_fit(self, win: list[Plot], what: str, flag: str) -> CVBatch:
        """The CV state at the newest of ``win`` (k equally spaced plots of one radar) from
        the finite-memory least-squares fit of their ranges (and radial velocities when every
        plot has one): ``core.finite_memory.fit`` and ``core.finite_memory.start``."""
        p, k = win[-1], len(win)
        doppler = self.options.use_doppler and all(q.radial_velocity_mps is not None for q in win)
        period = win[1].time_s - win[0].time_s
        try:
            fit = finite_memory_fit(
                k,
                sigma_r_m=p.sigma_r_m,
                sigma_vr_mps=p.sigma_vr_mps if doppler else None,
                period_s=period,
                with_doppler=doppler,
            )
        except ParameterError as exc:
            raise PlotError("time_s", f"{what}: {exc}") from None
        if fit.order < 2:
            raise PlotError(
                "range_m",
                f"{what} over k = {k} range-only plots fits only "
                f"{fit.order} parameter; {flag} must be 3 or more",
            )
        ranges = np.array([q.range_m for q in win])
        vrs = np.array([q.radial_velocity_mps for q in win], dtype=float) if doppler else None
        dims = 3 if self.three_d else 2
        return finite_memory_start(
            fit,
            ranges,
            vrs,
            p.azimuth_rad,
            p.elevation_rad if self.three_d else None,
            sigma_beta_rad=p.sigma_beta_rad,
            sigma_elevation_rad=p.sigma_elevation_rad,
            sigma_v0_mps=self.options.sigma_v0_mps,
            site=np.asarray(p.site[:dims], dtype=np.float64),
        )

    def _finite_memory_row(self, p: Plot) -> StateRow | None:
        """The sliding-window track's row at plot ``p``, or None (another radar's plot, or
        fewer than k equally spaced plots since the window last restarted).

        The window is the plots of the first radar seen; a step other than its period (a
        missed scan) restarts it, because the fit assumes equal spacing."""
        k = self.options.finite_memory_k
        win = self._fm_window
        if self._fm_radar is None:
            self._fm_radar = p.radar
        if p.radar != self._fm_radar:
            return None
        if len(win) >= 2:
            period = win[1].time_s - win[0].time_s
            if not math.isclose(p.time_s - win[-1].time_s, period, rel_tol=1e-6, abs_tol=1e-9):
                win.clear()
        elif win and p.time_s <= win[-1].time_s:
            win.clear()
        win.append(p)
        if len(win) > k:
            win.pop(0)
        if len(win) < k:
            return None
        st = self._window_fit(win, "the finite-memory track", "finite_memory_k")
        return FINITE_MEMORY_TRACK, *_rows_6(st, 0)


def plot_block(plots: list[Plot], one_target: bool = False) -> PlotBlock:
    """A list of ``Plot`` as a ``PlotBlock`` (radars: one per distinct site and noise);
    ``one_target``: every plot is of one target (labelled ""), whatever its label."""
    n = len(plots)
    index: dict[tuple, int] = {}
    radar = np.array(
        [
            index.setdefault(
                (p.site, p.sigma_r_m, p.sigma_beta_rad, p.sigma_elevation_rad,
                 p.sigma_vr_mps),
                len(index),
            )
            for p in plots
        ],
        dtype=np.intp,
    )  # fmt: skip
    rows = np.array([(*k[0], *k[1:]) for k in index], dtype=np.float64).reshape(-1, 7)
    radars = RadarTable(rows[:, :3].copy(), *(rows[:, c].copy() for c in range(3, 7)))
    labels: dict[str, int] = {"": 0} if one_target else {}
    if one_target:
        target = np.zeros(n, dtype=np.intp)
    else:
        target = np.array([labels.setdefault(p.target, len(labels)) for p in plots], np.intp)
    three_d = n > 0 and plots[0].elevation_rad is not None
    vr = [p.radial_velocity_mps for p in plots]
    doppler = any(v is not None for v in vr)
    return PlotBlock(
        np.array([p.time_s for p in plots], dtype=np.float64),
        np.array([p.range_m for p in plots], dtype=np.float64),
        np.array([p.azimuth_rad for p in plots], dtype=np.float64),
        np.array([p.elevation_rad for p in plots], dtype=np.float64) if three_d else None,
        np.array([np.nan if v is None else v for v in vr], dtype=np.float64) if doppler else None,
        radar,
        radars,
        target,
        tuple(labels),
    )


def block_plots(block: PlotBlock) -> list[Plot]:
    """A ``PlotBlock`` as a list of ``Plot`` (the inverse of ``plot_block``)."""
    rd = block.radars
    el, vr = block.elevation_rad, block.radial_velocity_mps
    out = []
    for i in range(block.size):
        g = int(block.radar[i])
        v = None if vr is None or np.isnan(vr[i]) else float(vr[i])
        out.append(
            Plot(
                float(block.time_s[i]),
                float(block.range_m[i]),
                float(block.azimuth_rad[i]),
                float(rd.sigma_r_m[g]),
                float(rd.sigma_beta_rad[g]),
                tuple(map(float, rd.site_m[g])),
                "",
                None if el is None else float(el[i]),
                float(rd.sigma_elevation_rad[g]),
                v,
                float(rd.sigma_vr_mps[g]),
                block.labels[int(block.target[i])],
            )
        )
    return out


def state_rows(tb: TrackBlock, methods: tuple[str, ...]) -> list[list[StateRow]]:
    """A ``TrackBlock`` as rows: per plot, (method, x (6,), P (6, 6)) per method (the 3D
    layout, z = ż = 0 for 2D), as ``TargetTracker.add_block`` returns them."""
    return list(StateRows(tb, methods))


class StateRows(Sequence[list[StateRow]]):
    """``state_rows`` of plots lo:hi of a ``TrackBlock``, each plot's row made when it is
    read: a caller that reads a few rows of a large block (or none) does not pay for the
    others. The 3D layout (``as_6``) is made once, at the first row read, for the block's
    rows that all its slices share."""

    def __init__(
        self, tb: TrackBlock, methods: tuple[str, ...], lo: int = 0, hi: int | None = None
    ):
        self._tb, self._methods = tb, methods
        self._lo, self._hi = lo, tb.x.shape[0] if hi is None else hi
        self._six: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = []

    def __len__(self) -> int:
        return self._hi - self._lo

    def slice(self, lo: int, hi: int) -> StateRows:
        """Rows lo:hi of these (sharing the 3D layout)."""
        out = StateRows(self._tb, self._methods, self._lo + lo, self._lo + hi)
        out._six = self._six
        return out

    @overload
    def __getitem__(self, i: int) -> list[StateRow]: ...

    @overload
    def __getitem__(self, i: slice) -> list[list[StateRow]]: ...

    def __getitem__(self, i: int | slice) -> list[StateRow] | list[list[StateRow]]:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        if not -len(self) <= i < len(self):
            raise IndexError("row index out of range")
        if not self._six:
            self._six.append(as_6(CVBatch(self._tb.x, self._tb.P)))
        x6, P6 = self._six[0]
        k = self._lo + i % len(self)
        return [(m, x6[k, j], P6[k, j]) for j, m in enumerate(self._methods)]


def as_6(st: CVBatch) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A batch (...) as x (..., 6), P (..., 6, 6) in the 3D layout (z = ż = 0 for 2D)."""
    n = st.x.shape[-1]
    x6 = np.zeros((*st.batch_shape, 6))
    P6 = np.zeros((*st.batch_shape, 6, 6))
    x6[..., :n] = st.x
    P6[..., :n, :n] = st.P
    return x6, P6


def _rows_6(st: CVBatch, i: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Row ``i`` of a batch as x (6,), P (6, 6) in the 3D layout (z = ż = 0 for 2D)."""
    n = st.x.shape[-1]
    return as_6(CVBatch(st.x.reshape(-1, n)[i], st.P.reshape(-1, n, n)[i]))
