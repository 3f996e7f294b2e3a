"""Parameter sweeps of the Prosov experiment, cut into chunks that can run anywhere.

A sweep is the Prosov Monte Carlo (``core.experiments.prosov``) repeated over a grid of parameters:
σβ, σr, the target's initial range, the scan period and, in 3D (``SweepBase.dims = 3``), the
target's elevation and the elevation noise σε. Each grid point is one ``TrackingConfig``;
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
from radarviz.core.filters.terms import SUM_NAMES
from radarviz.core.metrics import MetricsAccumulator
from radarviz.core.params import PARAMETERS, ParameterError, check, check_int, check_real, default
from radarviz.core.scenarios.planar import ConstantVelocityTarget2D
from radarviz.core.scenarios.spatial import ConstantVelocityTarget3D, prosov_target_3d

#: Bump when a chunk's meaning changes (sums, filters, noise draw), so stored chunks of an
#: older version are never mistaken for current ones.
CHUNK_VERSION = 1
#: Largest number of grid points of one sweep (a guard against a mistyped step).
MAX_POINTS = 100_000
#: Largest number of chunks of one sweep (grid points × blocks per point). Each chunk is a
#: task held by the scheduler (a few kB with its future) and a file in the chunks directory:
#: a million is already gigabytes of bookkeeping, and ``--runs 10**15`` at one point would
#: have built a list of 6 · 10¹⁰ tasks before the first one ran (MemoryError).
MAX_CHUNKS = 1_000_000


class AxisSpec(NamedTuple):
    """What a grid axis means and the values it accepts: the parameter table's interval
    (``low_open``: low excluded, ``high_open``: high excluded; most axes are (low, high]).
    ``dims``: the sweep dimensions the axis exists in."""

    unit: str
    meaning: str
    low: float
    high: float
    low_open: bool = True
    high_open: bool = False
    dims: tuple[int, ...] = (2, 3)

    def check(self, name: str, value: object) -> float:
        """``value`` as a float, or ``ParameterError`` naming ``name`` and the interval."""
        return check_real(
            name,
            value,
            low=self.low,
            high=self.high,
            low_open=self.low_open,
            high_open=self.high_open,
        )


def _axis(
    name: str, scale: float = 1.0, unit: str | None = None, dims: tuple[int, ...] = (2, 3)
) -> AxisSpec:
    """The grid axis of table parameter ``name``, its values in units of ``scale`` × its unit."""
    p = PARAMETERS[name]
    assert p.low is not None and p.high is not None
    return AxisSpec(
        unit or p.unit,
        f"{p.meaning} {p.symbol}",
        p.low / scale,
        p.high / scale,
        p.low_open,
        p.high_open,
        dims,
    )


#: The parameters a grid may vary, with the bounds of the parameter table. ``range_km`` is
#: ``target_range_m`` in km: the target starts at (range_km · 1000, 0) m and keeps the preset's
#: motion, 200 m/s radially outward. ``elevation_deg`` (``target_elevation_deg``: the 3D target
#: starts at range_km · 1000 · u(0, E) and moves outward along u(0, E)) and
#: ``sigma_elevation_deg`` exist in 3D sweeps only.
GRID_AXES: dict[str, AxisSpec] = {
    "sigma_beta_deg": _axis("sigma_beta_deg"),
    "sigma_r_m": _axis("sigma_r_m"),
    "range_km": _axis("target_range_m", 1000.0, "km"),
    "period_s": _axis("period_s"),
    "elevation_deg": _axis("target_elevation_deg", dims=(3,)),
    "sigma_elevation_deg": _axis("sigma_elevation_deg", dims=(3,)),
}
#: The grid axes of a ``dims``-D sweep (the Parquet columns of its parameters, in order).
AXES_OF_DIMS: dict[int, tuple[str, ...]] = {
    d: tuple(n for n, a in GRID_AXES.items() if d in a.dims) for d in (2, 3)
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
            spec.check(self.name, v)
        if len(set(self.values)) != len(self.values):
            raise ParameterError(f"grid axis {self.name} repeats a value ({self.values})")


@dataclass(frozen=True)
class SweepBase:
    """The fixed parameters of a sweep; a grid axis overrides the field of the same name.

    The defaults are the Prosov experiment (``docs/conversion.md``): σr = 250 m,
    σβ = 1°, target at 150 km moving outward at 200 m/s, T = 10 s, 60 scans. ``dims = 3``
    is the 3D reproduction (``core.experiments.prosov.prosov_configs(dims=3)``): the target at
    elevation ``elevation_deg``, the radar measuring elevation with noise
    ``sigma_elevation_deg``, every method in 3D on the numpy engine; in 2D those two fields
    are unused (and may not be gridded).
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
    dims: int = 2
    elevation_deg: float = default("target_elevation_deg")
    sigma_elevation_deg: float = 1.0

    def __post_init__(self) -> None:
        check_int("dims", self.dims, low=2, high=3)
        for name, spec in GRID_AXES.items():
            spec.check(name, getattr(self, name))
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
            if name not in AXES_OF_DIMS[self.base.dims]:
                raise ParameterError(
                    f"dims must be 3 for grid axis {name} (got {self.base.dims})", "dims"
                )
        check_int("block", self.block, low=1)
        count = int(np.prod(self.shape, dtype=np.int64))
        if count > MAX_POINTS:
            raise ParameterError(
                f"grid must have at most {MAX_POINTS} points (got {count}: {self.shape})"
            )
        chunks = count * -(-self.base.runs // self.block)
        if chunks > MAX_CHUNKS:
            raise ParameterError(
                f"runs must make at most {MAX_CHUNKS} chunks of block {self.block} runs over "
                f"the grid's {count} point(s) (got {self.base.runs} runs: {chunks} chunks)",
                "runs",
            )

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(a.values) for a in self.axes)

    @property
    def axis_names(self) -> tuple[str, ...]:
        """The parameters of this sweep's dimension (``AXES_OF_DIMS``), gridded or fixed."""
        return AXES_OF_DIMS[self.base.dims]

    def points(self) -> list[dict[str, float]]:
        """Every grid point as {parameter: value} over ``axis_names`` (fixed ones too)."""
        fixed = {name: float(getattr(self.base, name)) for name in self.axis_names}
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

    2D: the target starts at (range_km · 1000, 0) m and moves along +x at ``base.speed_mps``;
    at range_km = 150 this is ``core.scenarios.planar.prosov_target`` exactly
    (150 · 1000.0 == 150e3). 3D: ``core.scenarios.spatial.prosov_target_3d`` at the point's
    elevation and range, σε the point's, on the numpy engine, which at range_km = 150 is
    ``prosov_configs(dims=3)``'s config exactly.
    """
    values = {name: float(point.get(name, getattr(base, name))) for name in AXES_OF_DIMS[base.dims]}
    common = {
        "sigma_r_m": values["sigma_r_m"],
        "sigma_beta_deg": values["sigma_beta_deg"],
        "runs": base.runs,
        "seed": base.seed,
        "methods": tuple(base.methods),
    }
    if base.dims == 3:
        target_3d = prosov_target_3d(
            values["elevation_deg"],
            values["period_s"],
            base.steps,
            target_range_m=values["range_km"] * 1000.0,
            target_speed_mps=base.speed_mps,
        )
        return TrackingConfig(
            target=target_3d,
            engine="numpy",
            sigma_elevation_deg=values["sigma_elevation_deg"],
            **common,
        )
    target = ConstantVelocityTarget2D(
        values["range_km"] * 1000.0, 0.0, base.speed_mps, 0.0, values["period_s"], base.steps
    )
    return TrackingConfig(target=target, **common)


def chunk_key(config: TrackingConfig, index: int, size: int) -> str:
    """A name for one chunk's result that changes whenever the result could change.

    SHA-256 of a canonical description: every field of the config except ``runs`` (a block's
    sums depend on the total only through its size, so a longer sweep reuses the blocks of a
    shorter one), floats in exact hexadecimal, the block index and size, ``CHUNK_VERSION``.
    A 3D config adds its height, vertical speed, σε and engine (a 2D key is unchanged, so the
    stored 2D chunks stay valid).
    """
    t = config.target
    desc: dict[str, object] = {
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
    if isinstance(t, ConstantVelocityTarget3D):
        desc["target_3d"] = [float(v).hex() for v in (t.z0_m, t.vz_mps)]
        desc["sigma_elevation_deg"] = float(config.sigma_elevation_deg or 0.0).hex()  # given in 3D
        desc["engine"] = config.engine
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
