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
  update after the position update (``core.filters.doppler``: linear along the measured line
  of sight). On the first plot it follows the start.
* **Start** ``"finite-memory"`` (Gorshkov and Zavizhenets' remark): the first ``init_k`` plots
  of the first plot's radar, which must be equally spaced in time, are fitted by least squares
  for (r, Vr, a) (``core.finite_memory``; range only when they carry no Doppler) and every
  method starts at the k-th of them (``core.finite_memory.start``). No track exists before:
  the plots up to the start (other radars' included, which are not used) give no rows.

State rows are always in the 3D layout (x, ẋ, y, ẏ, z, ż), z = ż = 0 for 2D tracks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.converted_doppler import converted_doppler_update
from radarviz.core.filters.doppler import doppler_update
from radarviz.core.filters.methods import (
    ALL_METHODS,
    METHODS_3D,
    MethodGroup,
    Parts,
    PolarNoise,
    PolarPlot,
    method_groups,
)
from radarviz.core.filters.predict import cv_predict
from radarviz.core.filters.state import CVBatch
from radarviz.core.finite_memory.fit import finite_memory_fit
from radarviz.core.finite_memory.start import finite_memory_start
from radarviz.core.params import ParameterError, check, check_choice, check_int

INIT_MODES: tuple[str, ...] = ("first-plot", "finite-memory")

StateRow = tuple[str, NDArray[np.float64], NDArray[np.float64]]


@dataclass(frozen=True)
class Plot:
    """One measurement of the target and the accuracy of the radar that made it.

    Angles in rad, distances in m, speeds in m/s. ``elevation_rad`` is None for a 2D plot and
    ``radial_velocity_mps`` None for a plot without Doppler.
    """

    time_s: float
    range_m: float
    azimuth_rad: float
    sigma_r_m: float
    sigma_azimuth_rad: float
    site: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radar: str = ""
    elevation_rad: float | None = None
    sigma_elevation_rad: float = 0.0
    radial_velocity_mps: float | None = None
    sigma_radial_velocity_mps: float = 0.0


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
            "sigma_azimuth_rad",
            "sigma_elevation_rad",
        )
    }
    el = None
    if dims == 3:
        el = np.array([p.elevation_rad for p in plots], dtype=np.float64)
    return (
        PolarPlot(col["range_m"], col["azimuth_rad"], el),
        PolarNoise(col["sigma_r_m"], col["sigma_azimuth_rad"], col["sigma_elevation_rad"]),
    )


class TrackGroup:
    """The tracks of one target for methods that share an update kind, as one batch.

    ``methods`` is either one polar method (``ekf``, ``ukf``) or any number of converted-
    measurement methods (``core.filters.methods.MethodGroup``); ``dims`` is 2 or 3. The
    batch has one row per method.
    """

    def __init__(
        self,
        methods: tuple[str, ...],
        dims: int,
        sigma_a_mps2: float = 0.0,
        sigma_v0_mps: float = 1000.0,
    ):
        for m in methods:
            check_choice("method", m, ALL_METHODS)
        self.group = MethodGroup(methods)
        self.methods = tuple(methods)
        self.dims = dims
        self.sigma_a = float(check("sigma_a_mps2", sigma_a_mps2))
        self.sigma_v0 = float(check("sigma_v0_mps", sigma_v0_mps))
        self.state: CVBatch | None = None
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
        self.state = CVBatch(np.tile(x, (m, 1)), np.tile(P, (m, 1, 1)))
        self.time_s = time_s

    def add(
        self,
        p: Plot,
        pre: Parts | None,
        use_doppler: bool = True,
        polar: tuple[PolarPlot, PolarNoise] | None = None,
        doppler: str = "line_of_sight",
    ) -> CVBatch:
        """Filter one plot; ``pre`` this plot's slice of ``precompute`` (z (M,), R (M,));
        ``polar``: the plot as (1,) arrays if the caller has them (every group shares them)."""
        m = len(self.methods)
        site = np.asarray(p.site[: self.dims], dtype=np.float64)
        plot, noise = polar if polar is not None else polar_arrays([p], self.dims)
        if self.state is None:
            state = self.group.start(plot, noise, sigma_v0_mps=self.sigma_v0, site=site, parts=pre)
        else:
            assert self.time_s is not None
            dt = p.time_s - self.time_s
            if dt < 0:
                raise ValueError(f"times must not decrease (got {p.time_s} after {self.time_s})")
            pred = cv_predict(self.state, dt, self.sigma_a) if dt > 0 else self.state
            state = self.group.update(pred, plot, noise, site=site, parts=pre)
        if use_doppler and p.radial_velocity_mps is not None and doppler == "converted":
            state = converted_doppler_update(
                state,
                np.full(m, p.range_m),
                np.full(m, p.radial_velocity_mps),
                sigma_r_m=p.sigma_r_m,
                sigma_vr_mps=p.sigma_radial_velocity_mps,
                site=site,
            )
        elif use_doppler and p.radial_velocity_mps is not None:
            # Linear in the velocity: the position frame does not matter.
            state = doppler_update(
                state,
                np.full(m, p.radial_velocity_mps),
                p.azimuth_rad,
                0.0 if p.elevation_rad is None else p.elevation_rad,
                sigma_vr_mps=p.sigma_radial_velocity_mps,
                sigma_azimuth_rad=p.sigma_azimuth_rad,
                sigma_elevation_rad=p.sigma_elevation_rad,
            )
        self.state, self.time_s = state, p.time_s
        return state


@dataclass(frozen=True)
class StreamOptions:
    """How ``StreamTracker`` filters.

    Attributes:
        sigma_a_mps2: process-noise acceleration std (0: constant velocity exactly).
        sigma_v0_mps: velocity std of the start (the papers' 1000 m/s).
        use_doppler: use the plots' radial velocities (when they have them).
        init: ``"first-plot"`` (the papers' start) or ``"finite-memory"`` (Gorshkov and
            Zavizhenets' window fit, ``docs/finite_memory.md``).
        init_k: plots in the finite-memory window (≥ 2 with Doppler, ≥ 3 without).
        doppler_update: ``"line_of_sight"`` (``core.filters.doppler``) or ``"converted"``
            (the r̂·V̂r pseudo-measurement, ``core.filters.converted_doppler``).
    """

    sigma_a_mps2: float = 0.0
    sigma_v0_mps: float = 1000.0
    use_doppler: bool = True
    init: str = "first-plot"
    init_k: int = 3
    doppler_update: str = "line_of_sight"

    def __post_init__(self) -> None:
        check("sigma_a_mps2", self.sigma_a_mps2)
        check("sigma_v0_mps", self.sigma_v0_mps)
        check_choice("init", self.init, INIT_MODES)
        check_int("init_k", self.init_k, low=2, high=1000)
        check_choice("doppler_update", self.doppler_update, ("line_of_sight", "converted"))


class StreamTracker:
    """Every requested method's track of one target, fed one ``Plot`` at a time.

    Args:
        methods: from ``ALL_METHODS`` (2D) or ``METHODS_3D`` (3D).
        three_d: plots carry elevations (every plot must then have one).
        options: see ``StreamOptions``.
    """

    def __init__(self, methods: tuple[str, ...], three_d: bool, options: StreamOptions):
        allowed = METHODS_3D if three_d else ALL_METHODS
        if not methods:
            raise ParameterError(f"method must name at least one of {', '.join(allowed)}")
        for m in methods:
            check_choice("method", m, allowed)
        self.methods = tuple(methods)
        self.three_d = three_d
        self.options = options
        o = options
        dims = 3 if three_d else 2
        self._groups = [
            TrackGroup(g, dims, o.sigma_a_mps2, o.sigma_v0_mps) for g in method_groups(self.methods)
        ]
        self._where = {
            m: (k, i) for k, tr in enumerate(self._groups) for i, m in enumerate(tr.methods)
        }
        self._window: list[Plot] | None = [] if o.init == "finite-memory" else None
        self._started = False

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
            for g, parts in zip(self._groups, pre, strict=True):
                row = None
                if parts is not None:
                    row = ([z[:, i] for z in parts[0]], {k: v[:, i] for k, v in parts[1].items()})
                g.add(p, row, use_doppler, polar, self.options.doppler_update)
            self._started = True
            out.append(self._rows())
        return out

    def _rows(self) -> list[StateRow]:
        rows = []
        for m in self.methods:
            k, i = self._where[m]
            st = self._groups[k].state
            assert st is not None
            n = st.x.shape[-1]
            x6 = np.zeros(6)
            P6 = np.zeros((6, 6))
            x6[:n] = st.x[i]
            P6[:n, :n] = st.P[i]
            rows.append((m, x6, P6))
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
        doppler = self.options.use_doppler and all(q.radial_velocity_mps is not None for q in win)
        period = win[1].time_s - win[0].time_s
        try:
            fit = finite_memory_fit(
                k,
                sigma_r_m=p.sigma_r_m,
                sigma_vr_mps=p.sigma_radial_velocity_mps if doppler else None,
                period_s=period,
                with_doppler=doppler,
            )
        except ParameterError as exc:
            raise PlotError("time_s", f"finite-memory start: {exc}") from None
        if fit.order < 2:
            raise PlotError(
                "range_m",
                f"the finite-memory start over k = {k} range-only plots fits only "
                f"{fit.order} parameter; init_k must be 3 or more",
            )
        ranges = np.array([q.range_m for q in win])
        vrs = np.array([q.radial_velocity_mps for q in win], dtype=float) if doppler else None
        dims = 3 if self.three_d else 2
        start = finite_memory_start(
            fit,
            ranges,
            vrs,
            p.azimuth_rad,
            p.elevation_rad if self.three_d else None,
            sigma_azimuth_rad=p.sigma_azimuth_rad,
            sigma_elevation_rad=p.sigma_elevation_rad,
            sigma_v0_mps=self.options.sigma_v0_mps,
            site=np.asarray(p.site[:dims], dtype=np.float64),
        )
        for g in self._groups:
            g.start_from(start.x.copy(), start.P.copy(), p.time_s)
        self._started = True
        self._window = None
