"""Plot-by-plot tracking of one target for streamed measurements (no file I/O here).

``filter_block`` (``core.experiments.prosov``) runs one method over a whole (M, N) array of
scans with a fixed period. A measurement file is different: plots come one at a time, from radars
that need not sit at the origin, with any time step, optionally with elevation (3D) and Doppler
radial velocity. ``StreamTracker`` keeps one track per method and takes one ``Plot`` at a time:

* **2D** (no elevation): ``MethodTrack`` runs the ``core.experiments.prosov`` filters on
  batches of one.
  First plot: the spec's start (``filter_block``'s): the method's converted point (``ducm``
  starts like ``ucm``; ``ekf``/``ukf`` from the naive point with its linearized covariance),
  velocity 0 with std ``sigma_v0``, shifted by the radar site. Later plots: predict with
  dt = t − t_previous (``cv_predict``; dt = 0, equal times, skips the prediction), then update
  radar-centred: the prediction is shifted by −site, updated with the same functions as
  ``filter_block`` (so ``ducm``, ``ekf`` and ``ukf`` linearise about the prediction as seen from
  the radar) and shifted back. A shift by a site at the origin is exact, so a file from a
  radar at the origin gives ``filter_block``'s tracks.
* **3D** (elevation on every plot): ``core.filters.track3d`` with the 3D conversions
  ``naive`` and ``ucm`` (``core.conversion.planar``), the 3D ``ekf`` and ``ukf``; the same
  start and radar-centred updates. ``seed``, ``cmkf_d`` and ``ducm`` are the 2D papers'
  conversions and have no 3D form here: asking for them with elevations is an error.
* **Doppler**: a plot's radial velocity, when present and ``use_doppler``, is a second, scalar
  update after the position update (``doppler_los_update`` /
  ``core.filters.track3d.doppler_update``: linear along the measured line of sight). On the
  first plot it follows the start.
* **Start** ``"finite-memory"`` (issue 3, Gorshkov and Zavizhenets' remark): the first
  ``init_k`` plots of the first plot's radar, which must be equally spaced in time, are fitted
  by least squares for (r, Vr, a) (``core.finite_memory.fit``; range only when they carry no
  Doppler) and every method starts at the k-th of them from ``finite_memory_start`` (2D) /
  ``finite_memory_start3`` (3D). No track exists before: the plots up to the start (other
  radars' included, which are not used) give no rows.

``add`` returns each method's state in the 3D layout x = (x, ẋ, y, ẏ, z, ż), P (6, 6); a 2D
track's z, ż and their covariance entries are 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from radarviz.core.conversion.planar import convert_naive_3d, convert_parts, convert_ucm_3d
from radarviz.core.experiments.doppler_start import doppler_los_update, finite_memory_start
from radarviz.core.experiments.prosov import ALL_METHODS, POLAR_METHODS, TrackingConfig
from radarviz.core.filters.cv import CVBatch, cv_init, cv_predict, cv_update_parts
from radarviz.core.filters.polar import ekf_update, init_from_polar, ukf_update
from radarviz.core.filters.track3d import (
    Track6,
    cv6_init,
    cv6_predict,
    doppler_update,
    ekf3_update,
    finite_memory_start3,
    position_update,
    ukf3_update,
)
from radarviz.core.finite_memory.fit import finite_memory_fit
from radarviz.core.params import ParameterError, check_choice, check_int, check_real
from radarviz.core.scenarios.planar import polar_measurements, prosov_target

#: Methods with a 3D form.
METHODS_3D: tuple[str, ...] = ("naive", "ucm", "ekf", "ukf")
INIT_MODES: tuple[str, ...] = ("first-plot", "finite-memory")

#: (6,) state of the 3D layout → index in the 2D state (x, ẋ, y, ẏ): the first four.
_TO_6 = np.array([0, 1, 2, 3])

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


class MethodTrack:
    """One 2D track (M = 1) per method of a group, updated plot by plot.

    ``methods`` is either one polar method (``ekf``, ``ukf``) or any number of converted-
    measurement methods (``METHODS_2D``): those share one batch of M = len(methods) runs, so the
    prediction and the Kalman update are one set of vector operations for all of them (only
    the conversion is per method). The batched arithmetic is elementwise, so each run's result
    is bit for bit that of a batch of one.
    """

    def __init__(
        self, methods: tuple[str, ...], sigma_a_mps2: float = 0.0, sigma_v0_mps: float = 1000.0
    ):
        for m in methods:
            check_choice("method", m, ALL_METHODS)
        if not methods or (any(m in POLAR_METHODS for m in methods) and len(methods) > 1):
            raise ValueError("methods must be one polar method or only converted methods")
        self.methods = tuple(methods)
        self.sigma_a = check_real("sigma_a_mps2", sigma_a_mps2, low=0.0, low_open=False)
        self.sigma_v0 = check_real("sigma_v0_mps", sigma_v0_mps, low=0.0)
        self.state: CVBatch | None = None
        self.time_s: float | None = None

    def precompute(self, plots: list[Plot]) -> NDArray[np.float64]:
        """Every method's converted point and covariance for a block of plots, (B, 5, M).

        The conversions do not depend on the track, so a block of plots is converted in one
        vectorised call per method (the per-plot calls dominated the time). ``ducm``, which
        needs the prediction, gets ``ucm``'s conversion: what it uses at the start.
        """
        r = np.array([p.range_m for p in plots])
        b = np.array([p.azimuth_rad for p in plots])
        sr = np.array([p.sigma_r_m for p in plots])
        sb = np.array([p.sigma_azimuth_rad for p in plots])
        out = np.empty((len(plots), 5, len(self.methods)))
        for i, m in enumerate(self.methods):
            if m in POLAR_METHODS:
                continue
            c = convert_parts("ucm" if m == "ducm" else m, r, b, sr, sb)
            out[:, :, i] = np.stack(np.broadcast_arrays(*c), -1)
        return out

    def _converted(
        self,
        r: NDArray[np.float64],
        b: NDArray[np.float64],
        sr: float,
        sb: float,
        rel: CVBatch | None,
        pre: NDArray[np.float64],
    ) -> tuple[NDArray[np.float64], ...]:
        """Every method's converted point and covariance as five (M,) vectors: ``pre`` (this
        plot's slice of ``precompute``) with ``ducm`` converted about the prediction ``rel``
        (at the start, ``rel`` None, ``ducm`` keeps ``ucm``'s conversion)."""
        parts = pre.copy()
        if rel is not None:
            for i, m in enumerate(self.methods):
                if m == "ducm":
                    c = convert_parts(m, r, b, sr, sb, (rel.x[i : i + 1, 0], rel.x[i : i + 1, 2]))
                    parts[:, i] = np.concatenate(c)
        return tuple(parts)

    def start_from(self, x: NDArray[np.float64], P: NDArray[np.float64], time_s: float) -> None:
        """Start every method of the group at x (4,), P (4, 4) (absolute frame)."""
        m = len(self.methods)
        self.state = CVBatch(np.tile(x, (m, 1)), np.tile(P, (m, 1, 1)))
        self.time_s = time_s

    def add(self, p: Plot, pre: NDArray[np.float64], use_doppler: bool = True) -> CVBatch:
        """Filter one plot; returns the updated states (x (M, 4), P (M, 4, 4)), absolute frame.

        ``pre``: this plot's (5, M) slice of ``precompute``."""
        r = np.array([p.range_m])
        b = np.array([p.azimuth_rad])
        sr, sb, m = p.sigma_r_m, p.sigma_azimuth_rad, self.methods[0]
        sx, sy = p.site[0], p.site[1]
        if self.state is None:
            if m in POLAR_METHODS:
                state = init_from_polar(r, b, sr, sb, self.sigma_v0)
            else:
                zx, zy, r00, r01, r11 = self._converted(r, b, sr, sb, None, pre)
                R = np.stack([np.stack([r00, r01], -1), np.stack([r01, r11], -1)], -2)
                state = cv_init(np.stack([zx, zy], -1), R, self.sigma_v0)
        else:
            assert self.time_s is not None
            dt = p.time_s - self.time_s
            if dt < 0:
                raise ValueError(f"times must not decrease (got {p.time_s} after {self.time_s})")
            pred = cv_predict(self.state, dt, self.sigma_a) if dt > 0 else self.state
            rel = CVBatch(pred.x.copy(), pred.P)
            rel.x[:, 0] -= sx
            rel.x[:, 2] -= sy
            if m == "ekf":
                state = ekf_update(rel, r, b, sr, sb)
            elif m == "ukf":
                state = ukf_update(rel, r, b, sr, sb)
            else:
                state = cv_update_parts(rel, *self._converted(r, b, sr, sb, rel, pre))
        state.x[:, 0] += sx
        state.x[:, 2] += sy
        if use_doppler and p.radial_velocity_mps is not None:
            # Linear in the velocity: the position frame does not matter.
            state = doppler_los_update(
                state,
                np.full(len(self.methods), p.radial_velocity_mps),
                b,
                p.sigma_radial_velocity_mps,
                sb,
            )
        self.state, self.time_s = state, p.time_s
        return state


class MethodTrack3D:
    """One 3D track of one method (``METHODS_3D``), updated plot by plot
    (``core.filters.track3d``)."""

    def __init__(self, method: str, sigma_a_mps2: float = 0.0, sigma_v0_mps: float = 1000.0):
        self.method = check_choice("method", method, METHODS_3D)
        # ucm converts with its own debiasing; naive, and ekf/ukf for their start, naively.
        self._convert = convert_ucm_3d if method == "ucm" else convert_naive_3d
        self.sigma_a = check_real("sigma_a_mps2", sigma_a_mps2, low=0.0, low_open=False)
        self.sigma_v0 = check_real("sigma_v0_mps", sigma_v0_mps, low=0.0)
        self.track: Track6 | None = None
        self.time_s: float | None = None

    def start_from(self, track: Track6, time_s: float) -> None:
        self.track, self.time_s = track, time_s

    def precompute(self, plots: list[Plot]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The method's radar-centred converted points z (B, 3) and R (B, 3, 3) for a block of
        plots, one vectorised call (``ekf``/``ukf`` use the naive point at the start only)."""
        cols = np.array(
            [
                (
                    p.range_m,
                    p.azimuth_rad,
                    p.elevation_rad,
                    p.sigma_r_m,
                    p.sigma_azimuth_rad,
                    p.sigma_elevation_rad,
                )
                for p in plots
            ]
        ).T
        c = self._convert(*cols)
        return c.z, c.R

    def add(
        self,
        p: Plot,
        pre: tuple[NDArray[np.float64], NDArray[np.float64]],
        use_doppler: bool = True,
    ) -> Track6:
        """Filter one plot; ``pre`` its radar-centred (z, R) from ``precompute``."""
        assert p.elevation_rad is not None
        site = np.asarray(p.site, dtype=np.float64)
        z = np.array([p.range_m, p.azimuth_rad, p.elevation_rad])
        sigmas = np.array([p.sigma_r_m, p.sigma_azimuth_rad, p.sigma_elevation_rad])
        m = self.method
        if self.track is None:
            track = cv6_init(pre[0] + site, pre[1], self.sigma_v0)
        else:
            assert self.time_s is not None
            dt = p.time_s - self.time_s
            if dt < 0:
                raise ValueError(f"times must not decrease (got {p.time_s} after {self.time_s})")
            pred = cv6_predict(self.track, dt, self.sigma_a) if dt > 0 else self.track
            if m == "ekf":
                track = ekf3_update(pred, site, z, sigmas)
            elif m == "ukf":
                track = ukf3_update(pred, site, z, sigmas)
            else:
                track = position_update(pred, pre[0] + site, pre[1])
        if use_doppler and p.radial_velocity_mps is not None:
            track = doppler_update(
                track,
                p.radial_velocity_mps,
                p.azimuth_rad,
                p.elevation_rad,
                p.sigma_radial_velocity_mps,
                p.sigma_azimuth_rad,
                p.sigma_elevation_rad,
            )
        self.track, self.time_s = track, p.time_s
        return track


def track_groups(methods: tuple[str, ...]) -> list[tuple[str, ...]]:
    """Split methods into ``MethodTrack`` groups: the converted ones together, each polar alone."""
    converted = tuple(m for m in methods if m not in POLAR_METHODS)
    return ([converted] if converted else []) + [(m,) for m in methods if m in POLAR_METHODS]


@dataclass(frozen=True)
class StreamOptions:
    """How ``StreamTracker`` filters.

    Attributes:
        sigma_a_mps2: process-noise acceleration std (0: constant velocity exactly).
        sigma_v0_mps: velocity std of the start (the spec's 1000 m/s).
        use_doppler: use the plots' radial velocities (when they have them).
        init: ``"first-plot"`` (the spec's start) or ``"finite-memory"`` (issue 3's).
        init_k: plots in the finite-memory window (≥ 2 with Doppler, ≥ 3 without).
    """

    sigma_a_mps2: float = 0.0
    sigma_v0_mps: float = 1000.0
    use_doppler: bool = True
    init: str = "first-plot"
    init_k: int = 3

    def __post_init__(self) -> None:
        check_real("sigma_a_mps2", self.sigma_a_mps2, low=0.0, low_open=False)
        check_real("sigma_v0_mps", self.sigma_v0_mps, low=0.0)
        check_choice("init", self.init, INIT_MODES)
        check_int("init_k", self.init_k, low=2, high=1000)


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
            if three_d and m in ALL_METHODS and m not in METHODS_3D:
                raise ParameterError(
                    f"method {m} is a 2D conversion and the plots have elevations "
                    f"(3D methods: {', '.join(METHODS_3D)})"
                )
            check_choice("method", m, allowed)
        self.methods = tuple(methods)
        self.three_d = three_d
        self.options = options
        o = options
        if three_d:
            self._tracks3 = {m: MethodTrack3D(m, o.sigma_a_mps2, o.sigma_v0_mps) for m in methods}
        else:
            self._groups = [
                MethodTrack(g, o.sigma_a_mps2, o.sigma_v0_mps) for g in track_groups(self.methods)
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
        if self.three_d:
            pre3 = {m: tr.precompute(plots) for m, tr in self._tracks3.items()}
        else:
            pre2 = [g.precompute(plots) for g in self._groups]
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
            if self.three_d:
                for m, tr in self._tracks3.items():
                    tr.add(p, (pre3[m][0][i], pre3[m][1][i]), use_doppler)
            else:
                for g, pre in zip(self._groups, pre2, strict=True):
                    g.add(p, pre[i], use_doppler)
            self._started = True
            out.append(self._rows())
        return out

    def _rows(self) -> list[StateRow]:
        rows = []
        for m in self.methods:
            if self.three_d:
                t = self._tracks3[m].track
                assert t is not None
                rows.append((m, t.x, t.P))
            else:
                k, i = self._where[m]
                st = self._groups[k].state
                assert st is not None
                x6 = np.zeros(6)
                P6 = np.zeros((6, 6))
                x6[_TO_6] = st.x[i]
                P6[:4, :4] = st.P[i]
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
                k, p.sigma_r_m, p.sigma_radial_velocity_mps if doppler else None, period, doppler
            )
        except ParameterError as exc:
            raise PlotError("time_s", f"finite-memory start: {exc}") from None
        if fit.order < 2:
            raise PlotError(
                "range_m",
                f"the finite-memory start over k = {k} range-only plots fits only "
                f"{fit.order} parameter; use --init-k 3 or more",
            )
        ranges = np.array([q.range_m for q in win])
        vrs = np.array([q.radial_velocity_mps for q in win], dtype=float) if doppler else None
        site = np.asarray(p.site, dtype=np.float64)
        o = self.options
        if self.three_d:
            assert p.elevation_rad is not None
            start = finite_memory_start3(
                fit,
                ranges,
                vrs,
                p.azimuth_rad,
                p.elevation_rad,
                p.sigma_azimuth_rad,
                p.sigma_elevation_rad,
                o.sigma_v0_mps,
                site,
            )
            for tr in self._tracks3.values():
                tr.start_from(Track6(start.x.copy(), start.P.copy()), p.time_s)
        else:
            s = finite_memory_start(
                fit,
                ranges[None],
                None if vrs is None else vrs[None],
                np.array([p.azimuth_rad]),
                p.sigma_azimuth_rad,
                o.sigma_v0_mps,
            )
            x = s.x[0].copy()
            x[0] += site[0]
            x[2] += site[1]
            for g in self._groups:
                g.start_from(x, s.P[0].copy(), p.time_s)
        self._started = True
        self._window = None


def prosov_single_run(
    seed: int = 1, sigma_beta_deg: float = 1.0
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], TrackingConfig]:
    """The Prosov scenario's one displayed run (the viewer's seed stream ``[seed, 7]``).

    Returns times (N,) in s, r̂ (1, N) in m, β̂ (1, N) in rad and the configuration, ready for
    ``core.experiments.prosov.track_history``.
    """
    check_int("seed", seed, low=0)
    config = TrackingConfig(sigma_beta_deg=sigma_beta_deg, seed=seed, target=prosov_target())
    truth = config.target.truth()
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7]))
    r_hat, b_hat = polar_measurements(truth, config.sigma_r_m, config.sigma_beta_rad, 1, rng)
    times = np.arange(truth.shape[0]) * config.target.period_s
    return times, r_hat, b_hat, config
