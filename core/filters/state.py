"""The state of a batch of constant-velocity tracks, in 2D or 3D, and how it is stored.

State vector, one (position, velocity) pair per axis, interleaved::

    2D:  x = (x, ẋ, y, ẏ)            n = 4
    3D:  x = (x, ẋ, y, ẏ, z, ż)      n = 6      (the 2D state is its first four components)

Batch. Every array has any leading batch shape ``(...)`` (Monte Carlo runs, targets,
methods, or a single track as a batch of one) and the state last: ``x`` is (..., n) and ``P``
is (..., n, n). The arrays are views of component-major storage ((n, ...) and (n, n, ...)),
so each component ``P[..., i, j]`` is one contiguous block of memory and every update is
written as a few hundred vector operations over the whole batch instead of one small matrix
product per track: that is what makes 10⁵ runs cheap (see ``radarviz bench``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

Vec = NDArray[np.float64]
BatchShape = int | tuple[int, ...]


class CVBatch(NamedTuple):
    """A batch of constant-velocity track states.

    Attributes:
        x: (..., n) means, n = 4 (2D) or 6 (3D); components (x, ẋ, y, ẏ[, z, ż]) in m, m/s.
        P: (..., n, n) covariances.
    """

    x: NDArray[np.float64]
    P: NDArray[np.float64]

    @property
    def dims(self) -> int:
        """Number of position axes: 2 or 3."""
        return self.x.shape[-1] // 2

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return self.x.shape[:-1]

    @property
    def runs(self) -> int:
        """Number of tracks in the batch (the product of the batch shape)."""
        return math.prod(self.x.shape[:-1])


def position_index(dims: int) -> tuple[int, ...]:
    """Indexes of the position components: (0, 2) in 2D, (0, 2, 4) in 3D."""
    return tuple(range(0, 2 * dims, 2))


def velocity_index(dims: int) -> tuple[int, ...]:
    """Indexes of the velocity components: (1, 3) in 2D, (1, 3, 5) in 3D."""
    return tuple(range(1, 2 * dims, 2))


def _shape(batch: BatchShape) -> tuple[int, ...]:
    return (batch,) if isinstance(batch, int | np.integer) else tuple(batch)


def empty_batch(batch: BatchShape, dims: int = 2) -> CVBatch:
    """An uninitialised batch with component-major storage (see the module docstring)."""
    if dims not in (2, 3):
        raise ValueError(f"dims must be 2 or 3 (got {dims})")
    shape, n = _shape(batch), 2 * dims
    k = len(shape)
    xs = np.empty((n, *shape))
    ps = np.empty((n, n, *shape))
    return CVBatch(xs.transpose(*range(1, k + 1), 0), ps.transpose(*range(2, k + 2), 0, 1))


def as_batch(x: ArrayLike, P: ArrayLike) -> CVBatch:
    """Copy state-last arrays x (..., n) and P (..., n, n) into the fast layout."""
    x = np.asarray(x, dtype=np.float64)
    P = np.asarray(P, dtype=np.float64)
    out = empty_batch(x.shape[:-1], x.shape[-1] // 2)
    out.x[...] = x
    out.P[...] = P
    return out


def cv_init(z: ArrayLike, R: ArrayLike, sigma_v0_mps: float = 1000.0) -> CVBatch:
    """Start tracks from one converted point each (the papers' initialisation).

    Position = z (..., d) with covariance R (..., d, d); velocity = 0 with variance σv0² on
    each axis, uncorrelated with the position. d = 2 or 3 sets the state's dimension.
    """
    z = np.asarray(z, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    dims = z.shape[-1]
    out = empty_batch(z.shape[:-1], dims)
    pos = position_index(dims)
    out.x[...] = 0.0
    out.P[...] = 0.0
    for i, pi in enumerate(pos):
        out.x[..., pi] = z[..., i]
        out.P[..., pi + 1, pi + 1] = sigma_v0_mps**2
        for j, pj in enumerate(pos):
            out.P[..., pi, pj] = R[..., i, j]
    return out


def target_batch(state: CVBatch, out: CVBatch | None) -> CVBatch:
    """The batch to write into: ``out`` (preallocated, must not alias ``state``) or a new one.

    Passing ``out`` matters for speed: a fresh 10⁴-run batch is megabytes of untouched pages,
    and faulting them in costs more than the arithmetic. Loops ping-pong between two batches.
    """
    if out is None:
        return empty_batch(state.batch_shape, state.dims)
    if out.x.shape != state.x.shape or np.shares_memory(out.P, state.P):
        raise ValueError("out must be a separate batch with the same number of runs")
    return out


def mean_components(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """The (n, ...) component-major view of x (..., n): ``xc[i]`` is ``x[..., i]``."""
    nd = x.ndim
    return x.transpose(nd - 1, *range(nd - 1))


def cov_components(P: NDArray[np.float64]) -> NDArray[np.float64]:
    """The (n, n, ...) component-major view of P (..., n, n): ``Pc[i, j]`` is ``P[..., i, j]``.

    For a batch made by ``empty_batch`` this is its storage, so ``Pc[i, j]`` is a contiguous
    block, and indexing it with two integers costs less than ``P[..., i, j]``: the
    component-wise updates index a few hundred times per call.
    """
    nd = P.ndim
    return P.transpose(nd - 2, nd - 1, *range(nd - 2))


#: The (i, j) of the ten upper entries of a 2D P: the order of the plain-arithmetic steps'
#: tuples (``core.filters.predict.predict_2d``, ``core.filters.position_2d``).
UPPER_2D: tuple[tuple[int, int], ...] = tuple((i, j) for i in range(4) for j in range(i, 4))


def tuples_2d(state: CVBatch, cut: tuple = ()) -> tuple[tuple, tuple]:
    """A 2D batch (or its part ``cut`` of every component) as the steps' tuples: the four
    components of x and P's upper entries in ``UPPER_2D`` order, each a view."""
    xc, Pc = mean_components(state.x), cov_components(state.P)
    return tuple(xc[i][cut] for i in range(4)), tuple(Pc[i, j][cut] for i, j in UPPER_2D)


def store_tuples_2d(x: tuple, p: tuple, out: CVBatch, cut: tuple = ()) -> None:
    """Write the steps' tuples (``tuples_2d``'s layout) into ``out`` (or its part ``cut``);
    P's upper triangle only: the caller mirrors it (``mirror_upper``) once written whole."""
    ox, oP = mean_components(out.x), cov_components(out.P)
    for i in range(4):
        ox[i][cut] = x[i]
    for (i, j), v in zip(UPPER_2D, p, strict=True):
        oP[i, j][cut] = v


#: Tracks per block of a 2D step on a batch (``step_2d``): a step's tuple arithmetic holds
#: about sixty temporaries of a block at once, so blocks bound the working memory (and stay
#: in cache).
BLOCK_TRACKS = 8192


def _blocks(shape: tuple[int, ...]) -> list[tuple]:
    """The cuts (``(..., slice)``) of a batch of ``shape`` into blocks of about
    ``BLOCK_TRACKS`` tracks along its last axis; ``[()]`` for a single track."""
    if not shape:
        return [()]
    last = shape[-1]
    block = max(1, BLOCK_TRACKS // max(1, math.prod(shape[:-1])))
    return [(Ellipsis, slice(start, start + block)) for start in range(0, last, block)]


def _cut(args: Sequence[Any], cut: tuple, last: int) -> list[Any]:
    """``args`` for one block: an array whose last axis is the batch's is cut with it; a
    number, a tuple, or an array that broadcasts along that axis is passed whole."""
    return [
        a[cut] if cut and isinstance(a, np.ndarray) and a.ndim and a.shape[-1] == last else a
        for a in args
    ]


def step_2d(
    step: Callable[..., tuple[tuple, tuple]],
    state: CVBatch,
    args: Sequence[Any],
    out: CVBatch | None = None,
) -> CVBatch:
    """A 2D step written once as plain arithmetic (``core.filters.position_2d`` and its
    siblings: ``step(x, p, *args) -> (x⁺, p⁺)`` on the ``tuples_2d`` layout) applied to a
    numpy batch, in blocks of ``BLOCK_TRACKS`` along the batch's last axis.

    Each of ``args`` is a number, a tuple of numbers, or an array broadcasting against the
    batch shape; an array whose last axis is the batch's is cut with the block. A singular
    step (a zero S, an indefinite P) gives NaN for its tracks, as compiled code does,
    without a warning."""
    out = target_batch(state, out)
    shape = state.batch_shape
    for cut in _blocks(shape):
        part = _cut(args, cut, shape[-1] if shape else 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            xn, pn = step(*tuples_2d(state, cut), *part)
        store_tuples_2d(xn, pn, out, cut)
    mirror_upper(out.P)
    return out


def step_3d(
    step: Callable[..., None],
    state: CVBatch,
    args: Sequence[Any],
    scratch: Sequence[tuple[int, ...]],
    out: CVBatch | None = None,
) -> CVBatch:
    """A 3D step written once as plain arithmetic (``core.filters.position_3d`` and its
    siblings: ``step(x, P, *args, *scratch)`` updating x (6,) and P (6, 6) in place, indexed
    ``x[i]``, ``P[i, j]``) applied to a numpy batch: on its component-major views (6, ...)
    and (6, 6, ...), so every entry is a vector over the block, in blocks of
    ``BLOCK_TRACKS`` along the batch's last axis.

    ``args`` as for ``step_2d`` (an argument indexed per component, ν or R, is one array
    with the components first and the batch shape after); ``scratch``: the shapes of the
    step's scratch arrays, each allocated with the block's shape appended."""
    out = target_batch(state, out)
    out.x[...] = state.x
    out.P[...] = state.P
    xc, Pc = mean_components(out.x), cov_components(out.P)
    shape = state.batch_shape
    for cut in _blocks(shape):
        part = _cut(args, cut, shape[-1] if shape else 1)
        block = xc[(0, *cut)].shape if cut else ()
        bufs = [np.empty((*s, *block)) for s in scratch]
        with np.errstate(invalid="ignore", divide="ignore"):
            step(xc[(slice(None), *cut)], Pc[(slice(None), slice(None), *cut)], *part, *bufs)
    return out


def components(values: Sequence[ArrayLike], shape: tuple[int, ...]) -> NDArray[np.float64]:
    """Numbers or arrays broadcasting against a batch ``shape`` as one (k, *shape) array
    (an argument of a 3D step indexed per component: ν, û's angles)."""
    out = np.empty((len(values), *shape))
    for i, v in enumerate(values):
        out[i] = v
    return out


def mirror_upper(P: NDArray[np.float64]) -> None:
    """Copy the upper triangle of (..., n, n) into the lower one, in place."""
    n = P.shape[-1]
    Pc = cov_components(P)
    for i in range(n):
        for j in range(i + 1, n):
            Pc[j, i] = Pc[i, j]


def quad_form_inv(P: NDArray[np.float64], e: NDArray[np.float64]) -> NDArray[np.float64]:
    """eᵀ P⁻¹ e for a batch: P (..., n, n) symmetric positive definite, e (..., n) → (...).

    Cholesky factorisation written out over the batch (n is 2 to 6 here), so it costs a few
    dozen vector operations rather than one LAPACK call per track.
    """
    n = e.shape[-1]
    Lc: dict[tuple[int, int], Vec] = {}
    y: list[Vec] = []
    total = np.zeros(e.shape[:-1])
    for i in range(n):
        for j in range(i + 1):
            acc = P[..., i, j].copy()
            for k in range(j):
                acc -= Lc[i, k] * Lc[j, k]
            if i == j:
                Lc[i, i] = np.sqrt(acc)
            else:
                Lc[i, j] = acc / Lc[j, j]
        yi = e[..., i].copy()
        for k in range(i):
            yi -= Lc[i, k] * y[k]
        yi /= Lc[i, i]
        y.append(yi)
        total += yi * yi
    return total


#: A negative Cholesky pivot (the variance of a component given the earlier ones) at most this
#: fraction of its diagonal entry is taken as zero: that direction is known to rounding.
#: P⁺ = P⁻ − K S Kᵀ is a subtraction that loses log₁₀(P⁻ᵢᵢ / P⁺ᵢᵢ) of the 16 digits (a start
#: with σv0 = 1000 m/s and a scan later: 4 to 6 of them), so a null direction comes back as
#: ± 10⁻¹⁶ to 10⁻¹¹ of its diagonal; 10⁻⁹ is above that. A positive pivot is a variance however
#: small, and is kept: after two plots with σβ = 10⁻⁶° at 150 km and σv0 = 1000 m/s, T = 10 s,
#: the cross-range velocity given the position has (rσβ / T)² = 7·10⁻⁸ m²/s², 7·10⁻¹⁴ of its
#: marginal σv0², and zeroing it left P⁺ singular (NEES NaN). Keeping a positive pivot that is
#: rounding of a true zero is harmless: the column below it is rounding over its square root,
#: at most √(10⁻¹¹) of the marginal σ.
SEMIDEFINITE_RTOL = 1e-9


def sym(M: dict[tuple[int, int], Vec], i: int, j: int) -> Vec:
    """Entry (i, j) of a symmetric matrix stored by its upper triangle."""
    return M[(i, j)] if i <= j else M[(j, i)]
