"""Parameter sweeps of the Prosov experiment, cut into chunks that can run anywhere.

A sweep is the Prosov Monte Carlo (``core.experiments.prosov``) repeated over a grid of parameters:
σβ, σr, the target's initial range, the scan period. Each grid point is one ``TrackingConfig``;
its runs are cut into exactly the blocks ``run_tracking`` uses (``block_sizes``), and block b
draws its noise from ``block_seed(seed, b)``. A *chunk* is one (grid point, block) pair.

Why the result does not depend on the number of workers: a chunk's sums are a pure function
of (config, block index, block size), and the sums of a grid point are added into a zero
accumulator in block order 0, 1, 2, … — never in the order chunks happen to finish. That is
the very sequence of floating-point additions ``run_tracking`` performs, so a grid point of a
sweep equals ``run_tracking`` on its config (and ``radarviz reproduce prosov``) bit for bit.

This module is pure: no Dask, no files. ``viz_app.sweep.run`` schedules the chunks and stores
them.
"""

from __future__ import annotations

import hashlib
import itertools
import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.experiments.prosov import (
    ALL_METHODS,
    BLOCK_RUNS,
    TrackingConfig,
    TrackingResult,
    block_sizes,
    run_block,
    tracking_result,
)
from radarviz.core.metrics import SUM_NAMES, MetricsAccumulator
from radarviz.core.params import PARAMETERS, ParameterError, check, check_int, check_real, default
from radarviz.core.scenarios.planar import ConstantVelocityTarget2D

#: Bump when a chunk's meaning changes (sums, filters, noise draw), so stored chunks of an
#: older version are never mistaken for current ones.
CHUNK_VERSION = 1
#: Largest number of grid points of one sweep (a guard against a mistyped step).
MAX_POINTS = 100_000


class AxisSpec(NamedTuple):
    """What a grid axis means and the values it accepts: the interval (low, high]."""

    unit: str
    meaning: str
    low: float
    high: float


def _axis(name: str, scale: float = 1.0, unit: str | None = None) -> AxisSpec:
    """The grid axis of table parameter ``name``, its values in units of ``scale`` × its unit."""
    p = PARAMETERS[name]
    assert p.low is not None and p.high is not None
    return AxisSpec(unit or p.unit, f"{p.meaning} {p.symbol}", p.low / scale, p.high / scale)


#: The parameters a grid may vary, with the bounds of the parameter table. ``range_km`` is
#: ``target_range_m`` in km: the target starts at (range_km · 1000, 0) m and keeps the preset's
#: motion, 200 m/s radially outward.
GRID_AXES: dict[str, AxisSpec] = {
    "sigma_beta_deg": _axis("sigma_beta_deg"),
    "sigma_r_m": _axis("sigma_r_m"),
    "range_km": _axis("target_range_m", 1000.0, "km"),
    "period_s": _axis("period_s"),
}


@dataclass(frozen=True)
class GridAxis:
    """One axis of the grid: a parameter name from ``GRID_AXES`` and its distinct values."""

    name: str
    values: tuple[float, ...]

    def __post_init__(self) -> None:
        if self.name not in GRID_AXES:
            raise ParameterError(
                f"grid axis must be one of {', '.join(GRID_AXES)} (got {self.name!r})"
            )
        spec = GRID_AXES[self.name]
        if not self.values:
            raise ParameterError(f"grid axis {self.name} needs at least one value")
        for v in self.values:
            check_real(self.name, v, low=spec.low, high=spec.high)
        if len(set(self.values)) != len(self.values):
            raise ParameterError(f"grid axis {self.name} repeats a value ({self.values})")


@dataclass(frozen=True)
class SweepBase:
    """The fixed parameters of a sweep; a grid axis overrides the field of the same name.

    The defaults are the Prosov experiment (``docs/conversion.md``): σr = 250 m,
    σβ = 1°, target at 150 km moving outward at 200 m/s, T = 10 s, 60 scans.
    """

    sigma_r_m: float = default("sigma_r_m")
    sigma_beta_deg: float = default("sigma_beta_deg")
    range_km: float = default("target_range_m") / 1000.0
    period_s: float = default("period_s")
    steps: int = default("steps")
    speed_mps: float = default("target_speed_mps")
    runs: int = default("runs")
    seed: int = default("seed")
    methods: tuple[str, ...] = ALL_METHODS

    def __post_init__(self) -> None:
        for name, spec in GRID_AXES.items():
            check_real(name, getattr(self, name), low=spec.low, high=spec.high)
        for name in ("steps", "runs", "seed"):
            check(name, getattr(self, name))
        check("target_speed_mps", self.speed_mps)


#: The presets a sweep can start from.
SWEEP_PRESETS: dict[str, SweepBase] = {"prosov": SweepBase()}


class ChunkTask(NamedTuple):
    """One unit of work: block ``index`` (``size`` runs) of grid point ``point``."""

    point: int
    index: int
    size: int
    config: TrackingConfig


class ChunkSums(NamedTuple):
    """The Monte Carlo sums of one chunk, as plain arrays (cheap to pickle and to store).

    Attributes:
        index: block index b within the grid point.
        methods: method names, the row order of ``runs`` and ``sums``.
        runs: (methods, N) int64 runs counted per scan.
        sums: (methods, len(SUM_NAMES), N) float64 running sums (``core.metrics``).
    """

    index: int
    methods: tuple[str, ...]
    runs: NDArray[np.int64]
    sums: NDArray[np.float64]


@dataclass(frozen=True)
class SweepSpec:
    """A whole sweep: fixed parameters, grid axes, block size.

    Grid points are the Cartesian product of the axes in the order given, the first axis
    slowest (C order), so the results reshape to ``shape``.
    """

    base: SweepBase = field(default_factory=SweepBase)
    axes: tuple[GridAxis, ...] = ()
    block: int = BLOCK_RUNS

    def __post_init__(self) -> None:
        names = [a.name for a in self.axes]
        for name in names:
            if names.count(name) > 1:
                raise ParameterError(f"grid axis {name} is given more than once")
        check_int("block", self.block, low=1)
        count = int(np.prod(self.shape, dtype=np.int64))
        if count > MAX_POINTS:
            raise ParameterError(
                f"grid must have at most {MAX_POINTS} points (got {count}: {self.shape})"
            )

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(a.values) for a in self.axes)

    def points(self) -> list[dict[str, float]]:
        """Every grid point as {parameter: value} over all of ``GRID_AXES`` (fixed ones too)."""
        fixed = {name: float(getattr(self.base, name)) for name in GRID_AXES}
        names = [a.name for a in self.axes]
        return [
            {**fixed, **dict(zip(names, combo, strict=True))}
            for combo in itertools.product(*(a.values for a in self.axes))
        ]

    def config(self, point: dict[str, float]) -> TrackingConfig:
        """The ``TrackingConfig`` of a grid point (see ``point_config``)."""
        return point_config(self.base, point)

    def configs(self) -> list[TrackingConfig]:
        return [self.config(p) for p in self.points()]

    def tasks(self) -> list[ChunkTask]:
        """Every chunk of the sweep, point by point, block by block."""
        out = []
        for p, cfg in enumerate(self.configs()):
            for b, size in enumerate(block_sizes(cfg.runs, self.block)):
                out.append(ChunkTask(p, b, size, cfg))
        return out


def point_config(base: SweepBase, point: dict[str, float]) -> TrackingConfig:
    """The tracking experiment at one grid point.

    The target starts at (range_km · 1000, 0) m and moves along +x at ``base.speed_mps``: at
    range_km = 150 this is ``core.scenarios.planar.prosov_target`` exactly (150 · 1000.0 == 150e3).
    """
    values = {name: float(point.get(name, getattr(base, name))) for name in GRID_AXES}
    target = ConstantVelocityTarget2D(
        values["range_km"] * 1000.0, 0.0, base.speed_mps, 0.0, values["period_s"], base.steps
    )
    return TrackingConfig(
        sigma_r_m=values["sigma_r_m"],
        sigma_beta_deg=values["sigma_beta_deg"],
        runs=base.runs,
        seed=base.seed,
        target=target,
        methods=tuple(base.methods),
    )


def chunk_key(config: TrackingConfig, index: int, size: int) -> str:
    """A name for one chunk's result that changes whenever the result could change.

    SHA-256 of a canonical description: every field of the config except ``runs`` (a block's
    sums depend on the total only through its size, so a longer sweep reuses the blocks of a
    shorter one), floats in exact hexadecimal, the block index and size, ``CHUNK_VERSION``.
    """
    t = config.target
    desc = {
        "version": CHUNK_VERSION,
        "sigma_r_m": float(config.sigma_r_m).hex(),
        "sigma_beta_deg": float(config.sigma_beta_deg).hex(),
        "seed": int(config.seed),
        "target": [float(v).hex() for v in (t.x0_m, t.y0_m, t.vx_mps, t.vy_mps, t.period_s)]
        + [int(t.steps)],
        "sigma_a_mps2": float(config.sigma_a_mps2).hex(),
        "sigma_v0_mps": float(config.sigma_v0_mps).hex(),
        "methods": list(config.methods),
        "index": int(index),
        "size": int(size),
    }
    text = json.dumps(desc, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def compute_chunk(config: TrackingConfig, index: int, size: int) -> ChunkSums:
    """Block ``index`` of ``config`` (``size`` runs) as arrays: a pure function of its inputs,
    so a chunk lost with a worker can be recomputed anywhere with the same result."""
    acc = run_block(config, index, size)
    parts = [acc[m].to_arrays() for m in config.methods]
    return ChunkSums(
        index=index,
        methods=tuple(config.methods),
        runs=np.stack([r for r, _ in parts]),
        sums=np.stack([s for _, s in parts]),
    )


def check_chunk(config: TrackingConfig, chunk: ChunkSums, index: int, size: int) -> None:
    """Raise ValueError unless ``chunk`` has the shape and run count of block ``index``."""
    steps = config.target.steps
    m = len(config.methods)
    if chunk.index != index or tuple(chunk.methods) != tuple(config.methods):
        raise ValueError(f"chunk {chunk.index} {chunk.methods} is not block {index} of {config}")
    if chunk.runs.shape != (m, steps) or chunk.sums.shape != (m, len(SUM_NAMES), steps):
        raise ValueError(f"chunk {index} has shapes {chunk.runs.shape}, {chunk.sums.shape}")
    if not np.all(chunk.runs == size):
        raise ValueError(f"chunk {index} counts {chunk.runs.max()} runs, expected {size}")


def reduce_chunks(
    config: TrackingConfig, chunks: Iterable[ChunkSums], block: int = BLOCK_RUNS
) -> TrackingResult:
    """The result of one grid point from its chunks, added in block order 0, 1, 2, ….

    ``chunks`` may come in any order (e.g. as they finished); they are sorted by index and
    each block must be present exactly once. Equals ``run_tracking(config, block=block)``
    bit for bit.
    """
    by_index: dict[int, ChunkSums] = {}
    for c in chunks:
        if c.index in by_index:
            raise ValueError(f"block {c.index} given twice")
        by_index[c.index] = c
    sizes = block_sizes(config.runs, block)
    if sorted(by_index) != list(range(len(sizes))):
        raise ValueError(f"expected blocks 0 … {len(sizes) - 1}, got {sorted(by_index)}")
    steps = config.target.steps
    acc = {m: MetricsAccumulator(steps) for m in config.methods}
    for b, size in enumerate(sizes):
        chunk = by_index[b]
        check_chunk(config, chunk, b, size)
        for i, m in enumerate(config.methods):
            acc[m].merge(MetricsAccumulator.from_arrays(chunk.runs[i], chunk.sums[i]))
    return tracking_result(config, acc)


def run_sweep_serial(spec: SweepSpec) -> list[TrackingResult]:
    """The whole sweep in this process, point by point: the reference the schedulers match."""
    results = []
    for cfg in spec.configs():
        sizes = block_sizes(cfg.runs, spec.block)
        chunks = [compute_chunk(cfg, b, size) for b, size in enumerate(sizes)]
        results.append(reduce_chunks(cfg, chunks, spec.block))
    return results
