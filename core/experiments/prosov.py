"""The Prosov experiment: converted-measurement Kalman filters by Monte Carlo.

One radar at the origin, a target starting at 150 km on the x axis moving radially outward at
200 m/s, σr = 250 m, σβ = 1° or 2°, T = 10 s, 60 scans (``docs/conversion.md``). Every
method filters the *same* noisy measurements (common random numbers), so differences between
methods are not Monte Carlo noise of the measurements.

Runs are processed in blocks of ``BLOCK_RUNS``; block b draws its noise from the b-th child of
``numpy.random.SeedSequence(seed)``, so a result is reproducible bit for bit for the same seed
and the first runs of a long experiment are the runs of a short one.

``prosov_scene`` is the picture every viewer draws (``radarviz demo``, ``record --preset
prosov``, ``tune``): the Monte Carlo statistics and one displayed run with every method's
filtered states.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.confidence import Verdict, claim_verdict, jackknife_band
from radarviz.core.conversion.planar import convert_parts
from radarviz.core.conversion.spatial import convert_3d
from radarviz.core.cores import available_cores
from radarviz.core.filters.compiled import (
    COMPILED_METHODS,
    ENGINES,
    FilterSettings,
    TermsRequest,
    filter_scans,
)
from radarviz.core.filters.methods import (
    ALL_METHODS,
    MethodGroup,
    PolarNoise,
    PolarPlot,
    method_groups,
)
from radarviz.core.filters.run import run_scans
from radarviz.core.filters.state import CVBatch, position_index
from radarviz.core.geometry import range_cross_basis
from radarviz.core.metrics import (
    MetricsAccumulator,
    TrackMetrics,
    delta_percent,
    metric_band,
    nees_band,
    nees_dof,
    truth_line_of_sight,
)
from radarviz.core.params import (
    MAX_SIGMA_ANGLE_DEG,
    ParameterError,
    check,
    check_choice,
    check_distinct,
    check_int,
    default,
)
from radarviz.core.scenarios.planar import (
    ConstantVelocityTarget2D,
    polar_measurements,
    prosov_target,
)
from radarviz.core.scenarios.spatial import (
    ConstantVelocityTarget3D,
    prosov_target_3d,
    spherical_measurements,
)

#: Scans per pass of the compiled kernel when it sums the metric terms: the prosov run's 60 scans
#: in one pass, as the filter alone runs them. A pass's per-group sums (BAND_GROUPS × scans × 10
#: doubles, 160 kB at 64 scans) stay in the second-level cache, and each run's state goes
#: through memory once instead of once per few scans (eight passes of 8 scans cost ~4 % of the
#: filter's time, ``radarviz bench``). Longer runs take several passes.
TERMS_SCANS = 64
#: Runs per block: large enough that vector operations dominate Python overhead, small enough
#: that a block's working set stays in cache.
BLOCK_RUNS = 16384
#: Upper limit of σβ accepted anywhere (``core.params.PARAMETERS["sigma_beta_deg"].high``).
MAX_SIGMA_BETA_DEG = MAX_SIGMA_ANGLE_DEG
#: Bounds of σr / (r σβ), the range σ over the cross-range σ, anywhere along the run (likewise
#: with σε in 3D). The converted position covariance has these two σ on its axes; far apart,
#: the 4 × 4 state covariance is singular to rounding after two plots, and some of 1000 runs
#: got a NaN or negative NEES (naive, ekf, ukf). Probed with every method at 1000 runs on the
#: Prosov run (r from 150 to 268 km): σr = 2 m against σβ = 20° (ratio 2.14·10⁻⁵) is finite,
#: σr = 1 m (1.1·10⁻⁵) is not; σr = 10⁵ m against σβ = 5·10⁻⁵° (7.6·10⁵) is finite, 10⁻⁵°
#: (3.8·10⁶) is not; the bounds are those two corners. The ranges σr, σβ and r0 allow one by
#: one (a sweep's r0 from 1 m to 10⁵ km, T up to an hour) reach far past both.
MIN_RANGE_CROSS_RATIO = 2.13e-5
MAX_RANGE_CROSS_RATIO = 7.64e5
#: The displayed run draws its noise from ``SeedSequence([seed, DISPLAY_STREAM])``: a stream of
#: its own, apart from the Monte Carlo blocks' ``SeedSequence(seed)`` children, so the run a
#: viewer draws depends on the seed and σ only, not on the number of runs or the block size.
DISPLAY_STREAM = 7
#: The Monte Carlo cloud of converted points (``conversion_cloud``) draws from
#: ``SeedSequence([seed, CLOUD_STREAM])``.
CLOUD_STREAM = 11
#: Conversions shown point by point (they need no prediction, unlike ``ducm``).
SHOWN_CONVERSIONS: tuple[str, ...] = ("naive", "seed", "cmkf_d", "ucm")

ProgressFn = Callable[[int, int], None]


@dataclass(frozen=True)
class TrackingConfig:
    """One Monte Carlo tracking experiment with a single radar at the origin, 2D or 3D.

    The target decides the dimension: a ``ConstantVelocityTarget3D``
    (``core.scenarios.spatial.prosov_target_3d``) makes the radar measure elevation too, with
    noise ``sigma_elevation_deg`` (required then), and every method runs in 3D on the numpy
    engine (the compiled kernels are 2D: a 3D config must say ``engine="numpy"``).

    Every field is a ``core.params.PARAMETERS`` entry: its default comes from there and it is
    validated against it (once, here).

    Attributes:
        sigma_r_m: range noise σr, m.
        sigma_beta_deg: azimuth noise σβ, degrees.
        runs: Monte Carlo runs M (>= 2).
        seed: root seed of ``numpy.random.SeedSequence``.
        target: the true trajectory (period and number of scans live there; 2D or 3D).
        sigma_a_mps2: process-noise acceleration std of the filters (0: the paper's Q = 0).
        sigma_v0_mps: initial velocity std of every track.
        methods: which filters to run, from ``ALL_METHODS``.
        engine: ``"compiled"`` (``core.filters.compiled``: one compiled loop over tracks and
            scans, the fast path) or ``"numpy"`` (the vectorised reference engine the tests
            hold the compiled one to). Results agree to rounding (~1e-12 relative), far
            inside any Monte Carlo error, but not bit for bit.
        sigma_elevation_deg: elevation noise σε, degrees (3D targets only).
    """

    sigma_r_m: float = default("sigma_r_m")
    sigma_beta_deg: float = default("sigma_beta_deg")
    runs: int = default("runs")
    seed: int = default("seed")
    target: ConstantVelocityTarget2D | ConstantVelocityTarget3D = field(
        default_factory=prosov_target
    )
    sigma_a_mps2: float = default("sigma_a_mps2")
    sigma_v0_mps: float = default("sigma_v0_mps")
    methods: tuple[str, ...] = ALL_METHODS
    engine: str = "compiled"
    sigma_elevation_deg: float | None = None

    def __post_init__(self) -> None:
        for name in ("sigma_r_m", "sigma_beta_deg", "runs", "seed", "sigma_a_mps2", "sigma_v0_mps"):
            check(name, getattr(self, name))
        if not self.methods:
            raise ParameterError(
                f"methods must name at least one of {', '.join(ALL_METHODS)}", "methods"
            )
        for m in self.methods:
            check_choice("method", m, ALL_METHODS)
        check_distinct("methods", tuple(self.methods))
        check_choice("engine", self.engine, ENGINES)
        if self.dims == 3:
            if self.sigma_elevation_deg is None:
                raise ParameterError(
                    "sigma_elevation_deg must be given for a 3D target", "sigma_elevation_deg"
                )
            check("sigma_elevation_deg", self.sigma_elevation_deg)
            if self.engine != "numpy":
                raise ParameterError(
                    "engine must be numpy for a 3D target (the compiled kernels are 2D)", "engine"
                )
        elif self.sigma_elevation_deg is not None:
            raise ParameterError(
                "sigma_elevation_deg must be left out for a 2D target", "sigma_elevation_deg"
            )
        self._check_conditioning()

    def _check_conditioning(self) -> None:
        """``ParameterError`` unless σr / (r σβ) (and σr / (r σε)) stays within
        [``MIN_RANGE_CROSS_RATIO``, ``MAX_RANGE_CROSS_RATIO``] at every true range r of the run."""
        positions = self.target.truth()[:, list(position_index(self.dims))]
        ranges = np.sqrt(np.sum(positions * positions, axis=1))
        r_near, r_far = float(ranges.min()), float(ranges.max())
        angles = [("σβ", self.sigma_beta_rad)]
        if self.dims == 3:
            angles.append(("σε", self.sigma_elevation_rad))
        for symbol, sigma_rad in angles:
            # The smallest ratio is at the farthest range, the largest at the nearest.
            for r in (r_far, r_near):
                cross_m = r * sigma_rad
                ratio = self.sigma_r_m / cross_m if cross_m > 0 else math.inf
                if not MIN_RANGE_CROSS_RATIO <= ratio <= MAX_RANGE_CROSS_RATIO:
                    raise ParameterError(
                        f"sigma_r_m must be {MIN_RANGE_CROSS_RATIO:g} to "
                        f"{MAX_RANGE_CROSS_RATIO:g} times the cross-range σ r {symbol} along the "
                        f"run (got σr = {self.sigma_r_m:g} m against {cross_m:.3g} m at "
                        f"r = {r:.3g} m): the position covariance would be singular to rounding",
                        "sigma_r_m",
                    )

    @property
    def dims(self) -> int:
        """2 or 3: the dimension of the target, the radar's plots and every track."""
        return 3 if isinstance(self.target, ConstantVelocityTarget3D) else 2

    @property
    def sigma_beta_rad(self) -> float:
        return float(np.deg2rad(self.sigma_beta_deg))

    @property
    def sigma_elevation_rad(self) -> float:
        """σε in rad (0 for a 2D target)."""
        return float(np.deg2rad(self.sigma_elevation_deg or 0.0))


@dataclass(frozen=True)
class TrackingResult:
    """Per-scan statistics of every method for one configuration.

    Attributes:
        config: what was run.
        n: (N,) scan numbers 1 … N.
        metrics: method name → per-scan statistics.
        nees_pos_band95 / nees_state_band95: 95% χ² band of the run-averaged NEES of a
            consistent filter (where its average falls; not the Monte Carlo error).
        leave_one_out: method → the statistics with each of the ``BAND_GROUPS`` groups of runs
            left out, every field (G, N) (``MetricsAccumulator.leave_one_out``); empty when
            the sums came without groups (a sweep's stored chunks), and then every band is NaN.
    """

    config: TrackingConfig
    n: NDArray[np.int64]
    metrics: dict[str, TrackMetrics]
    nees_pos_band95: tuple[float, float]
    nees_state_band95: tuple[float, float]
    leave_one_out: dict[str, TrackMetrics] = field(default_factory=dict)

    def delta_x_percent(self) -> dict[str, NDArray[np.float64]]:
        """Prosov's Δx(n) of ``seed`` against ``naive`` under the three readings of σ̂x."""
        return _delta_x(self.metrics["seed"], self.metrics["naive"])

    def delta_x_ci95_percent(self) -> dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """The 95% Monte Carlo band of ``delta_x_percent``: reading → (lo, hi) per scan, %.

        Δx is a ratio of two methods' statistics over the *same* runs, so its band is the
        delete-a-group jackknife (``core.confidence``) with both methods' leave-outs taken
        over the same group of runs: the common random numbers that make seed − naive far
        more precise than either are kept. (A Student-t band over each group's own Δx would
        carry the O(G/M) bias of a ratio of small-sample estimates; the jackknife's
        leave-outs hold (G − 1)/G of the runs each.)
        """
        full = self.delta_x_percent()
        if "seed" not in self.leave_one_out or "naive" not in self.leave_one_out:
            return {k: _nan_band(v) for k, v in full.items()}
        loo = _delta_x(self.leave_one_out["seed"], self.leave_one_out["naive"])
        return {k: jackknife_band(full[k], loo[k]) for k in full}

    def band95(self, method: str, name: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The 95% Monte Carlo band (lo, hi) per scan of one method's ``TrackMetrics`` field
        ``name``: ``band95("ucm", "rmse_x_m")``, ``band95("seed", "bias_range_m")``,
        ``band95("ducm", "nees_pos")``; the delete-a-group jackknife (``core.confidence``),
        NaN where undefined."""
        value = getattr(self.metrics[method], name)
        if method not in self.leave_one_out:
            return _nan_band(value)
        return metric_band(name, value, getattr(self.leave_one_out[method], name))


def _delta_x(a: TrackMetrics, b: TrackMetrics) -> dict[str, NDArray[np.float64]]:
    """Δx of ``a`` against ``b`` under the three readings (any common shape)."""
    return {
        "filter": delta_percent(a.sigma_x_filter_m, b.sigma_x_filter_m),
        "rmse": delta_percent(a.rmse_x_m, b.rmse_x_m),
        "std": delta_percent(a.std_x_m, b.std_x_m),
    }


def _nan_band(value: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    nan = np.full(np.shape(value), np.nan)
    return nan, nan.copy()


class DeltaXClaim(NamedTuple):
    """A claim of the paper on Δx: |Δx(n)| ≤ ``bound_percent`` for scans n = 1 … ``scans``."""

    sigma_beta_deg: float
    bound_percent: float
    scans: int


#: The paper's claims (``docs/conversion.md``, finding 4): |Δx| within 2.1% at σβ = 1° and
#: "up to 18%" at 2°, over the scans its figures show (the first 20).
PROSOV_CLAIMS: tuple[DeltaXClaim, ...] = (DeltaXClaim(1.0, 2.1, 20), DeltaXClaim(2.0, 18.0, 20))


class ClaimCheck(NamedTuple):
    """A claim checked against one reading of Δx and its 95% band.

    Attributes:
        claim: what is checked.  reading: "filter", "rmse" or "std".
        verdict: ``core.confidence.claim_verdict`` over scans 1 … claim.scans.
        peak_scan: the scan of the window where |Δx| is largest; peak_percent its Δx and
            peak_lo / peak_hi its 95% band, %.
        runs: the Monte Carlo runs the band comes from.
    """

    claim: DeltaXClaim
    reading: str
    verdict: Verdict
    peak_scan: int
    peak_percent: float
    peak_lo: float
    peak_hi: float
    runs: int


def check_delta_x_claims(
    result: TrackingResult, claims: Sequence[DeltaXClaim] = PROSOV_CLAIMS
) -> list[ClaimCheck]:
    """Every claim made for ``result``'s σβ (none if the paper made none), for each reading.

    The verdict is from the 95% band of each scan of the window (``claim_verdict``): a claim
    is only said to hold, or not, when the Monte Carlo error of the curve cannot change it.
    """
    sigma_beta_deg = result.config.sigma_beta_deg
    if "seed" not in result.metrics or "naive" not in result.metrics:
        return []
    values, bands = result.delta_x_percent(), result.delta_x_ci95_percent()
    out = []
    for claim in claims:
        if not np.isclose(claim.sigma_beta_deg, sigma_beta_deg) or claim.scans > len(result.n):
            continue
        w = slice(0, claim.scans)
        for reading, v in values.items():
            lo, hi = bands[reading][0][w], bands[reading][1][w]
            i = int(np.nanargmax(np.abs(v[w])))
            out.append(
                ClaimCheck(
                    claim=claim,
                    reading=reading,
                    verdict=claim_verdict(lo, hi, claim.bound_percent),
                    peak_scan=int(result.n[i]),
                    peak_percent=float(v[i]),
                    peak_lo=float(lo[i]),
                    peak_hi=float(hi[i]),
                    runs=result.config.runs,
                )
            )
    return out


def block_sizes(runs: int, block: int = BLOCK_RUNS) -> list[int]:
    """Split ``runs`` into blocks of ``block`` runs (the last one shorter)."""
    full, rest = divmod(runs, block)
    return [block] * full + ([rest] if rest else [])


def filter_block(
    name: str,
    r_hat: NDArray[np.float64],
    beta_hat: NDArray[np.float64],
    config: TrackingConfig,
    on_scan: Callable[[int, CVBatch], None],
    elevation_hat: NDArray[np.float64] | None = None,
) -> CVBatch:
    """Run one method over a block of runs; ``on_scan(n, state)`` sees every filtered state.

    Args:
        r_hat, beta_hat: (m, N) measured ranges (m) and azimuths (rad).
        elevation_hat: (m, N) measured elevations (rad) of a 3D config.
    Returns:
        The state after the last scan.

    Tracks start at scan 1 from the first measurement: the converted point of the method
    (``ducm`` starts like ``ucm``: there is no prediction yet) or, for the EKF and UKF, the
    naive point with its linearized covariance; velocity 0 with std ``sigma_v0_mps``.
    """
    group = MethodGroup((name,))
    squeeze = group.converted  # a converted group has a leading method axis of length 1

    def one(n: int, state: CVBatch) -> None:
        on_scan(n, CVBatch(state.x[0], state.P[0]) if squeeze else state)

    state = filter_group(group, r_hat, beta_hat, config, one, elevation_hat)
    return CVBatch(state.x[0], state.P[0]) if squeeze else state


def filter_group(
    group: MethodGroup,
    r_hat: NDArray[np.float64],
    beta_hat: NDArray[np.float64],
    config: TrackingConfig,
    on_scan: Callable[[int, CVBatch], None],
    elevation_hat: NDArray[np.float64] | None = None,
) -> CVBatch:
    """``filter_block`` for a group of methods at once: the converted methods of ``group`` are
    one batch (k, m) (row i: method i), so their predictions and updates are one set of vector
    operations; each row is what ``filter_block`` gives for its method alone.

    With ``elevation_hat`` (m, N) the plots are 3D (r̂, β̂, ε̂) and every track is 3D."""
    T, qa = config.target.period_s, config.sigma_a_mps2
    steps = r_hat.shape[1]
    if (elevation_hat is None) != (config.dims == 2):
        raise ValueError(f"a {config.dims}D config needs {config.dims} measured coordinates")
    noise = PolarNoise(config.sigma_r_m, config.sigma_beta_rad, config.sigma_elevation_rad)
    # Scan-major copies, so each scan's measurements are contiguous vectors.
    scans = [np.ascontiguousarray(a.T) for a in (r_hat, beta_hat, elevation_hat) if a is not None]

    def plot(n: int) -> PolarPlot:
        return PolarPlot(*(a[n] for a in scans))

    state = group.start(plot(0), noise, sigma_v0_mps=config.sigma_v0_mps)

    def update(n: int, pred: CVBatch, out: CVBatch) -> CVBatch:
        return group.update(pred, plot(n), noise, out=out)

    return run_scans(state, steps, T, update, sigma_a_mps2=qa, on_scan=on_scan)


def block_seed(seed: int, index: int) -> np.random.SeedSequence:
    """The seed of block ``index``: the ``index``-th child of ``SeedSequence(seed)``.

    ``SeedSequence(seed).spawn(n)[b]`` is ``SeedSequence(seed, spawn_key=(b,))`` whatever n,
    so a block's noise depends on (seed, b) alone: a worker can draw block b without knowing
    how many blocks there are or seeing the others.
    """
    return np.random.SeedSequence(seed, spawn_key=(index,))


def block_measurements(
    config: TrackingConfig, index: int, size: int, truth: NDArray[np.float64]
) -> tuple[NDArray[np.float64], ...]:
    """Block ``index``'s measured ranges and azimuths (and elevations, 3D), each (size, N),
    from ``block_seed``."""
    rng = np.random.default_rng(block_seed(config.seed, index))
    return _measurements(config, truth, size, rng)


def _measurements(
    config: TrackingConfig, truth: NDArray[np.float64], runs: int, rng: np.random.Generator
) -> tuple[NDArray[np.float64], ...]:
    """(r̂, β̂) or, for a 3D config, (r̂, β̂, ε̂), each (runs, N), drawn from ``rng``."""
    if config.dims == 3:
        return spherical_measurements(
            truth,
            sigma_r_m=config.sigma_r_m,
            sigma_beta_rad=config.sigma_beta_rad,
            sigma_elevation_rad=config.sigma_elevation_rad,
            runs=runs,
            rng=rng,
        )
    return polar_measurements(
        truth,
        sigma_r_m=config.sigma_r_m,
        sigma_beta_rad=config.sigma_beta_rad,
        runs=runs,
        rng=rng,
    )


class DisplayedTrack(NamedTuple):
    """One method's filtered states of the displayed run: x (N, 4) as (x, ẋ, y, ẏ) in m and
    m/s (3D: (N, 6), (x, ẋ, y, ẏ, z, ż)), and P (N, 4, 4) (3D: (N, 6, 6)) their covariances."""

    x: NDArray[np.float64]
    P: NDArray[np.float64]


def _run_block(
    config: TrackingConfig,
    index: int,
    size: int,
    truth: NDArray[np.float64],
    shown: tuple[NDArray[np.float64], ...] | None = None,
) -> tuple[dict[str, MetricsAccumulator], dict[str, DisplayedTrack]]:
    """``run_block``, and with ``shown = (r̂, β̂[, ε̂])`` (1, N) also the states of that run.

    The shown run is filtered as one more row of the block, after its ``size`` runs, by the
    same ``filter_block`` call: every row of a batch is filtered on its own (element-wise
    arithmetic), so its states are the ones ``track_history`` gives for it alone and the
    block's statistics are ``run_block``'s — bit for bit both (``tests/test_prosov.py``),
    for one pass over the scans instead of two (at a few hundred runs a pass costs about the
    same for 1 run as for all of them).
    """
    check_int("index", index, low=0)
    check_int("size", size, low=1)
    steps = truth.shape[0]
    meas = block_measurements(config, index, size, truth)
    if shown is not None:
        meas = tuple(np.concatenate([a, b]) for a, b in zip(meas, shown, strict=True))
    r_hat, beta_hat = meas[:2]
    elevation_hat = meas[2] if config.dims == 3 else None
    out = {method: MetricsAccumulator(steps) for method in config.methods}
    tracks: dict[str, DisplayedTrack] = {}
    d = 2 * config.dims
    if shown is not None:
        tracks = {
            m: DisplayedTrack(np.empty((steps, d)), np.empty((steps, d, d))) for m in config.methods
        }
    compiled = [m for m in config.methods if config.engine == "compiled" and m in COMPILED_METHODS]
    if compiled:
        settings = FilterSettings(
            config.sigma_r_m,
            config.sigma_beta_rad,
            config.target.period_s,
            config.sigma_a_mps2,
            config.sigma_v0_mps,
        )
        # The kernel sums every run's metric terms per group as it goes (only the shown run's
        # states leave it), ``TERMS_SCANS`` scans a pass.
        want = TermsRequest(size, truth, truth_line_of_sight(truth))
        for method in compiled:
            for c in filter_scans(method, r_hat, beta_hat, settings, TERMS_SCANS, terms=want):
                out[method].add_group_sums(c.first, size, c.group_sums)
                if shown is not None:
                    span = slice(c.first, c.first + c.x.shape[0])
                    tracks[method].x[span] = c.x[:, 0]
                    tracks[method].P[span] = c.P[:, 0]
    # The rest on the numpy engine (all of them with engine="numpy"; a method the kernel does
    # not have otherwise). Methods share a batch while it stays within a block's size.
    rest = [m for m in config.methods if m not in compiled]
    n_rows = r_hat.shape[0]
    for names in method_groups(rest, max_group=max(1, BLOCK_RUNS // n_rows)) if rest else []:
        group = MethodGroup(names)

        def on_scan(n: int, st: CVBatch, group: MethodGroup = group) -> None:
            rows = (
                [(group.names[i], st.x[i], st.P[i]) for i in range(len(group.names))]
                if group.converted
                else [(group.names[0], st.x, st.P)]
            )
            for method, x, P in rows:
                out[method].add(n, CVBatch(x[:size], P[:size]), truth[n])
                if shown is not None:
                    tracks[method].x[n], tracks[method].P[n] = x[size], P[size]

        filter_group(group, r_hat, beta_hat, config, on_scan, elevation_hat)
    return out, tracks


def run_block(
    config: TrackingConfig,
    index: int,
    size: int,
    truth: NDArray[np.float64] | None = None,
) -> dict[str, MetricsAccumulator]:
    """Block ``index`` of the Monte Carlo: ``size`` runs, every configured method.

    The measurements are drawn from ``block_seed(config.seed, index)`` and shared by all
    methods (common random numbers). Returns one fresh accumulator per method holding this
    block's sums only, so the caller decides the order in which blocks are added up — the one
    thing that could change the last bit of a result.

    Args:
        truth: ``config.target.truth()`` if the caller already has it.
    """
    if truth is None:
        truth = config.target.truth()
    return _run_block(config, index, size, truth)[0]


def tracking_result(
    config: TrackingConfig, accumulators: dict[str, MetricsAccumulator]
) -> TrackingResult:
    """The per-scan statistics of accumulators holding all ``config.runs`` runs."""
    steps = config.target.steps
    dof_pos, dof_state = nees_dof(config.dims)
    return TrackingResult(
        config=config,
        n=np.arange(1, steps + 1),
        metrics={m: accumulators[m].result() for m in config.methods},
        nees_pos_band95=nees_band(dof_pos, config.runs),
        nees_state_band95=nees_band(dof_state, config.runs),
        leave_one_out={
            m: accumulators[m].leave_one_out() for m in config.methods if accumulators[m].has_groups
        },
    )


def _monte_carlo(
    config: TrackingConfig,
    truth: NDArray[np.float64],
    progress: ProgressFn | None,
    block: int,
    shown: tuple[NDArray[np.float64], ...] | None = None,
    workers: int | None = None,
) -> tuple[TrackingResult, dict[str, DisplayedTrack]]:
    """Blocks 0, 1, … added into zero accumulators in that order; ``shown`` rides in block 0.

    With the compiled engine the blocks are filtered by ``workers`` threads (default: every
    available core; its kernels release the GIL). Each block's sums depend on its own runs
    only and are merged in block order as they come back, so the result is the one-thread
    result bit for bit (``tests/test_compiled.py``). The numpy engine's small vector
    operations hold the GIL, so it stays on one thread.
    """
    steps = truth.shape[0]
    sizes = block_sizes(config.runs, block)
    check_int("workers", workers if workers is not None else 1, low=1)
    n_workers = min(len(sizes), workers or available_cores())
    acc = {m: MetricsAccumulator(steps) for m in config.methods}
    tracks: dict[str, DisplayedTrack] = {}

    def one(index: int) -> tuple[dict[str, MetricsAccumulator], dict[str, DisplayedTrack]]:
        return _run_block(config, index, sizes[index], truth, shown if index == 0 else None)

    pool = ThreadPoolExecutor(n_workers) if n_workers > 1 and config.engine == "compiled" else None
    try:
        # ``map`` yields in submission order: block b is merged after blocks 0 … b − 1.
        blocks = pool.map(one, range(len(sizes))) if pool else map(one, range(len(sizes)))
        done = 0
        for size, (block_acc, block_tracks) in zip(sizes, blocks, strict=True):
            tracks.update(block_tracks)
            for method, a in block_acc.items():
                acc[method].merge(a)
            done += size
            if progress is not None:
                progress(done, config.runs)
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    return tracking_result(config, acc), tracks


def run_tracking(
    config: TrackingConfig,
    progress: ProgressFn | None = None,
    block: int = BLOCK_RUNS,
    workers: int | None = None,
) -> TrackingResult:
    """Monte Carlo of every configured method; statistics accumulated block by block.

    Block b (``run_block``) is added into a zero accumulator in the order b = 0, 1, …; a
    parameter sweep (``core.experiments.sweep``) that computes the same blocks anywhere and adds
    them in the same order gets the same result bit for bit.

    Args:
        progress: called as ``progress(runs_done, runs_total)`` after each block.
        workers: threads filtering blocks (default: every available core); the result does
            not depend on it.
    """
    return _monte_carlo(config, config.target.truth(), progress, block, workers=workers)[0]


def displayed_measurements(
    config: TrackingConfig, truth: NDArray[np.float64] | None = None
) -> tuple[NDArray[np.float64], ...]:
    """The displayed run's measured r̂ and β̂ (3D: and ε̂), each (1, N) in m and rad
    (``DISPLAY_STREAM``).

    ``radarviz simulate --preset prosov`` writes this run as a measurement file.
    """
    if truth is None:
        truth = config.target.truth()
    rng = np.random.default_rng(np.random.SeedSequence([config.seed, DISPLAY_STREAM]))
    return _measurements(config, truth, 1, rng)


@dataclass(frozen=True)
class ProsovScene:
    """What a viewer shows of one configuration: the statistics and one displayed run.

    Attributes:
        result: the Monte Carlo statistics, equal bit for bit to ``run_tracking(config)``.
        truth: (N, 4) true states (x, ẋ, y, ẏ); 3D: (N, 6) (x, ẋ, y, ẏ, z, ż).
        times_s: (N,) scan times 0, T, 2T, … in s.
        r_hat_m, beta_hat_rad: (N,) the displayed run's measured range (m) and azimuth (rad).
        converted_xy_m: conversion method → (N, 2) (3D: (N, 3)) its converted points of the
            displayed run, for ``SHOWN_CONVERSIONS`` (``naive`` is the plain polar-to-Cartesian
            point).
        tracks: method → the displayed run's filtered states, for every configured method.
        elevation_hat_rad: (N,) the displayed run's measured elevation (rad); None in 2D.
    """

    result: TrackingResult
    truth: NDArray[np.float64]
    times_s: NDArray[np.float64]
    r_hat_m: NDArray[np.float64]
    beta_hat_rad: NDArray[np.float64]
    converted_xy_m: dict[str, NDArray[np.float64]]
    tracks: dict[str, DisplayedTrack]
    elevation_hat_rad: NDArray[np.float64] | None = None

    @property
    def config(self) -> TrackingConfig:
        return self.result.config


def prosov_scene(
    config: TrackingConfig, progress: ProgressFn | None = None, block: int = BLOCK_RUNS
) -> ProsovScene:
    """The Prosov scene of ``config``: Monte Carlo statistics and one displayed run.

    The displayed run's measurements come from ``displayed_measurements`` (its own seed
    stream, ``DISPLAY_STREAM``), so it is the same run for any number of Monte Carlo runs.
    Each method filters it with ``filter_block`` as one more row of the Monte Carlo's first
    block (see ``_run_block``): its states equal ``track_history(method, r̂, β̂, config)`` bit
    for bit, and ``result`` equals ``run_tracking(config, block=block)`` bit for bit.

    Args:
        progress: called as ``progress(runs_done, runs_total)`` after each block.
    """
    truth = config.target.truth()
    shown = displayed_measurements(config, truth)
    r_hat, beta_hat = shown[:2]
    result, tracks = _monte_carlo(config, truth, progress, block, shown)
    sigma_r_m, sigma_beta_rad = config.sigma_r_m, config.sigma_beta_rad
    converted = {}
    for method in SHOWN_CONVERSIONS:
        if config.dims == 3:
            c3 = convert_3d(
                method,
                r_hat[0],
                beta_hat[0],
                shown[2][0],
                sigma_r_m=sigma_r_m,
                sigma_beta_rad=sigma_beta_rad,
                sigma_elevation_rad=config.sigma_elevation_rad,
            )
            converted[method] = c3.z
            continue
        c = convert_parts(
            method, r_hat[0], beta_hat[0], sigma_r_m=sigma_r_m, sigma_beta_rad=sigma_beta_rad
        )
        converted[method] = np.stack([c.x, c.y], -1)
    return ProsovScene(
        elevation_hat_rad=shown[2][0] if config.dims == 3 else None,
        result=result,
        truth=truth,
        times_s=np.arange(truth.shape[0]) * config.target.period_s,
        r_hat_m=r_hat[0],
        beta_hat_rad=beta_hat[0],
        converted_xy_m=converted,
        tracks=tracks,
    )


CLOUD_BLOCK_SCANS = 16
"""Scans converted at once by ``conversion_cloud`` (its peak memory is one block's)."""


class ConversionCloud(NamedTuple):
    """A Monte Carlo cloud of converted points at every scan of the true trajectory.

    Attributes:
        points: method → (N, P, 2) converted points in m (P noisy measurements per scan).
        offset_mean_m: method → (N, 2) the cloud's mean offset from the true position in the
            target frame (cross-range, down-range), m (``core.geometry.range_cross_basis``):
            the conversion's bias, seen from the radar.
        offset_half_width95_m: method → (N, 2) half-width of that mean's 95% confidence
            interval per axis, 1.96 s / √P with s the sample std of the offsets (the P draws
            are independent, so the mean's standard error is s / √P; P is in the thousands, so
            the normal quantile).
    """

    points: dict[str, NDArray[np.float64]]
    offset_mean_m: dict[str, NDArray[np.float64]]
    offset_half_width95_m: dict[str, NDArray[np.float64]]


def conversion_cloud(
    config: TrackingConfig, points: int, keep: int | None = None
) -> ConversionCloud:
    """``points`` noisy measurements of every true position, converted by each of
    ``SHOWN_CONVERSIONS`` (seed stream ``CLOUD_STREAM``).

    ``keep``: hold only the first ``keep`` draws of each scan in ``points`` (the same draws
    as with every one kept); the means and half-widths are of all ``points`` all the same.
    A viewer that draws a few hundred of the thousands the means need holds a sixteenth
    of the memory; the conversion runs ``CLOUD_BLOCK_SCANS`` scans at a time for the same reason.

    The cloud shows each conversion's bias at a glance: E[cos β̂] = cos β · e^(−σβ²/2), so the
    ``naive`` cloud's mean sits r (1 − e^(−σβ²/2)) short of the truth along the line of sight;
    ``ucm``'s scale e^(σβ²/2) removes that bias, ``seed``'s 1 − σβ²/2 doubles it.
    """
    check_int("points", points, low=2)
    kept = points if keep is None else check_int("keep", keep, low=1, high=points)
    truth = config.target.truth()
    true_xy = truth[:, [0, 2]]
    basis = range_cross_basis(np.zeros(2), true_xy)  # (N, 2, 2)
    rng = np.random.default_rng(np.random.SeedSequence([config.seed, CLOUD_STREAM]))
    sigma_r_m, sigma_beta_rad = config.sigma_r_m, config.sigma_beta_rad
    # (P, N): one row per draw, one column per scan.
    r_c, b_c = polar_measurements(
        truth, sigma_r_m=sigma_r_m, sigma_beta_rad=sigma_beta_rad, runs=points, rng=rng
    )
    scans = truth.shape[0]
    cloud = {m: np.empty((scans, kept, 2)) for m in SHOWN_CONVERSIONS}
    mean = {m: np.empty((scans, 2)) for m in SHOWN_CONVERSIONS}
    half = {m: np.empty((scans, 2)) for m in SHOWN_CONVERSIONS}
    # A block of scans at a time: every statistic is per scan, so the blocks give the same
    # figures as one pass, and the peak memory is one block's conversion, not all scans'.
    for lo in range(0, scans, CLOUD_BLOCK_SCANS):
        block = slice(lo, min(lo + CLOUD_BLOCK_SCANS, scans))
        r_b, b_b = r_c[:, block].T, b_c[:, block].T  # (n, P)
        for method in SHOWN_CONVERSIONS:
            c = convert_parts(method, r_b, b_b, sigma_r_m=sigma_r_m, sigma_beta_rad=sigma_beta_rad)
            xy = np.stack([c.x, c.y], -1)  # (n, P, 2)
            # offsets[n, p] = B[n] (xy[n, p] − truth[n]), one batched matmul (einsum is slow).
            offsets = (xy - true_xy[block, None, :]) @ np.swapaxes(basis[block], -1, -2)
            cloud[method][block] = xy[:, :kept]
            mean[method][block] = offsets.mean(axis=1)
            half[method][block] = 1.959964 * offsets.std(axis=1, ddof=1) / np.sqrt(points)
    return ConversionCloud(cloud, mean, half)


def prosov_configs(
    sigma_beta_deg: Sequence[float] = (1.0, 2.0),
    runs: int = default("runs"),
    seed: int = default("seed"),
    period_s: float = default("period_s"),
    steps: int = default("steps"),
    *,
    sigma_r_m: float = default("sigma_r_m"),
    methods: Sequence[str] = ALL_METHODS,
    dims: int = 2,
    elevation_deg: float = default("target_elevation_deg"),
    sigma_elevation_deg: float | None = None,
) -> list[TrackingConfig]:
    """The paper's experiment, one configuration per σβ (the paper: 1° and 2°).

    ``dims=3``: the 3D reproduction, the same range and radial motion at elevation
    ``elevation_deg`` (``core.scenarios.spatial.prosov_target_3d``), elevation noise
    ``sigma_elevation_deg``, on the numpy engine. Each value is validated once, by the target
    (period, scans, elevation) and the configs (the rest).
    """
    check_int("dims", dims, low=2, high=3)
    three_d = dims == 3
    target = (
        prosov_target_3d(elevation_deg, period_s, steps)
        if three_d
        else prosov_target(period_s, steps)
    )
    # 3D runs on the numpy engine and needs σε; 2D takes the defaults.
    extra = {"engine": "numpy", "sigma_elevation_deg": sigma_elevation_deg} if three_d else {}
    return [
        TrackingConfig(
            sigma_r_m=sigma_r_m,
            sigma_beta_deg=float(sigma_deg),
            runs=runs,
            seed=seed,
            target=target,
            methods=tuple(methods),
            **extra,
        )
        for sigma_deg in sigma_beta_deg
    ]


def track_history(
    method: str,
    r_hat: NDArray[np.float64],
    beta_hat: NDArray[np.float64],
    config: TrackingConfig,
    elevation_hat: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Every filtered state of a few runs, for display: x (m, N, 4) and P (m, N, 4, 4)
    (3D, with ``elevation_hat`` (m, N): (m, N, 6) and (m, N, 6, 6)).

    The Monte Carlo statistics never keep states; this is for the handful of runs a viewer
    draws (memory grows as m · N).
    """
    m, steps = r_hat.shape
    d = 2 * config.dims
    xs = np.empty((m, steps, d))
    ps = np.empty((m, steps, d, d))

    def keep(n: int, state: CVBatch) -> None:
        xs[:, n] = state.x
        ps[:, n] = state.P

    filter_block(method, r_hat, beta_hat, config, keep, elevation_hat)
    return xs, ps
