"""The Prosov experiment: converted-measurement Kalman filters by Monte Carlo.

One radar at the origin, a target starting at 150 km on the x axis moving radially outward at
200 m/s, σr = 250 m, σβ = 1° or 2°, T = 10 s, 60 scans (``docs/conversion.md``). Every
method filters the *same* noisy measurements (common random numbers), so differences between
methods are not Monte Carlo noise of the measurements.

Runs are processed in blocks of ``BLOCK_RUNS``; block b draws its noise from the b-th child of
``numpy.random.SeedSequence(seed)``, so a result is reproducible bit for bit for the same seed
and the first runs of a long experiment are the runs of a short one.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.methods import ALL_METHODS, PolarNoise, PolarPlot, method_named
from radarviz.core.filters.run import run_scans
from radarviz.core.filters.state import CVBatch
from radarviz.core.metrics import MetricsAccumulator, TrackMetrics, delta_percent, nees_band
from radarviz.core.params import (
    MAX_SIGMA_ANGLE_DEG,
    ParameterError,
    check,
    check_choice,
    check_int,
    default,
)
from radarviz.core.scenarios.planar import (
    ConstantVelocityTarget2D,
    polar_measurements,
    prosov_target,
)

#: Runs per block: large enough that vector operations dominate Python overhead, small enough
#: that a block's working set stays in cache.
BLOCK_RUNS = 16384
#: Upper limit of σβ accepted anywhere (``core.params.PARAMETERS["sigma_beta_deg"].high``).
MAX_SIGMA_BETA_DEG = MAX_SIGMA_ANGLE_DEG

ProgressFn = Callable[[int, int], None]


@dataclass(frozen=True)
class TrackingConfig:
    """One Monte Carlo tracking experiment with a single 2D radar at the origin.

    Every field is a ``core.params.PARAMETERS`` entry: its default comes from there and it is
    validated against it (once, here).

    Attributes:
        sigma_r_m: range noise σr, m.
        sigma_beta_deg: azimuth noise σβ, degrees.
        runs: Monte Carlo runs M (>= 2).
        seed: root seed of ``numpy.random.SeedSequence``.
        target: the true trajectory (period and number of scans live there).
        sigma_a_mps2: process-noise acceleration std of the filters (0: the paper's Q = 0).
        sigma_v0_mps: initial velocity std of every track.
        methods: which filters to run, from ``ALL_METHODS``.
    """

    sigma_r_m: float = default("sigma_r_m")
    sigma_beta_deg: float = default("sigma_beta_deg")
    runs: int = default("runs")
    seed: int = default("seed")
    target: ConstantVelocityTarget2D = field(default_factory=prosov_target)
    sigma_a_mps2: float = default("sigma_a_mps2")
    sigma_v0_mps: float = default("sigma_v0_mps")
    methods: tuple[str, ...] = ALL_METHODS

    def __post_init__(self) -> None:
        for name in ("sigma_r_m", "sigma_beta_deg", "runs", "seed", "sigma_a_mps2", "sigma_v0_mps"):
            check(name, getattr(self, name))
        if not self.methods:
            raise ParameterError(
                f"methods must name at least one of {', '.join(ALL_METHODS)}", "methods"
            )
        for m in self.methods:
            check_choice("method", m, ALL_METHODS)

    @property
    def sigma_beta_rad(self) -> float:
        return float(np.deg2rad(self.sigma_beta_deg))


@dataclass(frozen=True)
class TrackingResult:
    """Per-scan statistics of every method for one configuration.

    Attributes:
        config: what was run.
        n: (N,) scan numbers 1 … N.
        metrics: method name → per-scan statistics.
        nees_pos_band95 / nees_state_band95: 95% χ² band of the run-averaged NEES.
    """

    config: TrackingConfig
    n: NDArray[np.int64]
    metrics: dict[str, TrackMetrics]
    nees_pos_band95: tuple[float, float]
    nees_state_band95: tuple[float, float]

    def delta_x_percent(self) -> dict[str, NDArray[np.float64]]:
        """Prosov's Δx(n) of ``seed`` against ``naive`` under the three readings of σ̂x."""
        a, b = self.metrics["seed"], self.metrics["naive"]
        return {
            "filter": delta_percent(a.sigma_x_filter, b.sigma_x_filter),
            "rmse": delta_percent(a.rmse_x, b.rmse_x),
            "std": delta_percent(a.std_x, b.std_x),
        }


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
) -> CVBatch:
    """Run one method over a block of runs; ``on_scan(n, state)`` sees every filtered state.

    Args:
        r_hat, beta_hat: (m, N) measured ranges (m) and azimuths (rad).
    Returns:
        The state after the last scan.

    Tracks start at scan 1 from the first measurement: the converted point of the method
    (``ducm`` starts like ``ucm``: there is no prediction yet) or, for the EKF and UKF, the
    naive point with its linearized covariance; velocity 0 with std ``sigma_v0_mps``.
    """
    T, qa = config.target.period_s, config.sigma_a_mps2
    steps = r_hat.shape[1]
    kind = method_named(name)
    noise = PolarNoise(config.sigma_r_m, config.sigma_beta_rad)
    state = kind.start(
        PolarPlot(r_hat[:, 0], beta_hat[:, 0]), noise, sigma_v0_mps=config.sigma_v0_mps
    )
    # Scan-major copies, so each scan's measurements are contiguous vectors.
    r_scans, b_scans = np.ascontiguousarray(r_hat.T), np.ascontiguousarray(beta_hat.T)

    def update(n: int, pred: CVBatch, out: CVBatch) -> CVBatch:
        return kind.update(pred, PolarPlot(r_scans[n], b_scans[n]), noise, out=out)

    state = run_scans(state, steps, T, update, sigma_a_mps2=qa, on_scan=on_scan)
    return state


def block_seed(seed: int, index: int) -> np.random.SeedSequence:
    """The seed of block ``index``: the ``index``-th child of ``SeedSequence(seed)``.

    ``SeedSequence(seed).spawn(n)[b]`` is ``SeedSequence(seed, spawn_key=(b,))`` whatever n,
    so a block's noise depends on (seed, b) alone: a worker can draw block b without knowing
    how many blocks there are or seeing the others.
    """
    return np.random.SeedSequence(seed, spawn_key=(index,))


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
    check_int("index", index, low=0)
    check_int("size", size, low=1)
    if truth is None:
        truth = config.target.truth()
    steps = truth.shape[0]
    rng = np.random.default_rng(block_seed(config.seed, index))
    r_hat, beta_hat = polar_measurements(
        truth,
        sigma_r_m=config.sigma_r_m,
        sigma_azimuth_rad=config.sigma_beta_rad,
        runs=size,
        rng=rng,
    )
    out: dict[str, MetricsAccumulator] = {}
    for method in config.methods:
        block_acc = MetricsAccumulator(steps)
        filter_block(
            method,
            r_hat,
            beta_hat,
            config,
            lambda n, st, a=block_acc: a.add(n, st, truth[n]),
        )
        out[method] = block_acc
    return out


def tracking_result(
    config: TrackingConfig, accumulators: dict[str, MetricsAccumulator]
) -> TrackingResult:
    """The per-scan statistics of accumulators holding all ``config.runs`` runs."""
    steps = config.target.steps
    return TrackingResult(
        config=config,
        n=np.arange(1, steps + 1),
        metrics={m: accumulators[m].result() for m in config.methods},
        nees_pos_band95=nees_band(2, config.runs),
        nees_state_band95=nees_band(4, config.runs),
    )


def run_tracking(
    config: TrackingConfig,
    progress: ProgressFn | None = None,
    block: int = BLOCK_RUNS,
) -> TrackingResult:
    """Monte Carlo of every configured method; statistics accumulated block by block.

    Block b (``run_block``) is added into a zero accumulator in the order b = 0, 1, …; a
    parameter sweep (``core.experiments.sweep``) that computes the same blocks anywhere and adds
    them in the same order gets the same result bit for bit.

    Args:
        progress: called as ``progress(runs_done, runs_total)`` after each block.
    """
    truth = config.target.truth()
    steps = truth.shape[0]
    acc = {m: MetricsAccumulator(steps) for m in config.methods}
    done = 0
    for index, size in enumerate(block_sizes(config.runs, block)):
        for method, block_acc in run_block(config, index, size, truth).items():
            acc[method].merge(block_acc)
        done += size
        if progress is not None:
            progress(done, config.runs)
    return tracking_result(config, acc)


def prosov_configs(
    sigma_beta_deg: Sequence[float] = (1.0, 2.0),
    runs: int = default("runs"),
    seed: int = default("seed"),
    period_s: float = default("period_s"),
    steps: int = default("steps"),
    *,
    sigma_r_m: float = default("sigma_r_m"),
    methods: Sequence[str] = ALL_METHODS,
) -> list[TrackingConfig]:
    """The paper's experiment, one configuration per σβ (the paper: 1° and 2°).

    Each value is validated once, by the target (period, scans) and the configs (the rest).
    """
    target = prosov_target(period_s, steps)
    return [
        TrackingConfig(
            sigma_r_m=sigma_r_m,
            sigma_beta_deg=float(sb),
            runs=runs,
            seed=seed,
            target=target,
            methods=tuple(methods),
        )
        for sb in sigma_beta_deg
    ]


def track_history(
    method: str,
    r_hat: NDArray[np.float64],
    beta_hat: NDArray[np.float64],
    config: TrackingConfig,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Every filtered state of a few runs, for display: x (m, N, 4) and P (m, N, 4, 4).

    The Monte Carlo statistics never keep states; this is for the handful of runs a viewer
    draws (memory grows as m · N).
    """
    m, steps = r_hat.shape
    xs = np.empty((m, steps, 4))
    ps = np.empty((m, steps, 4, 4))

    def keep(n: int, state: CVBatch) -> None:
        xs[:, n] = state.x
        ps[:, n] = state.P

    filter_block(method, r_hat, beta_hat, config, keep)
    return xs, ps
