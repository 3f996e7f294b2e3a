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
from typing import NamedTuple

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
        if use_dense(state):  # the dense path needs no component-major storage
            return CVBatch(np.empty(state.x.shape), np.empty(state.P.shape))
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


def step_2d(
    step: Callable[..., tuple[tuple, tuple]],
    state: CVBatch,
    args: Sequence[ArrayLike],
    out: CVBatch | None = None,
) -> CVBatch:
    """A 2D step written once as plain arithmetic (``core.filters.position_2d`` and its
    siblings: ``step(x, p, *args) -> (x⁺, p⁺)`` on the ``tuples_2d`` layout) applied to a
    numpy batch, in blocks of ``BLOCK_TRACKS`` along the batch's last axis.

    Each of ``args`` is a number or an array broadcasting against the batch shape; one that
    varies along the last axis is cut with the block, one that broadcasts is passed whole.
    A singular step (a zero S, an indefinite P) gives NaN for its tracks, as compiled code
    does, without a warning."""
    out = target_batch(state, out)
    shape = state.batch_shape
    last = shape[-1] if shape else 1
    block = max(1, BLOCK_TRACKS // max(1, math.prod(shape[:-1])))
    for start in range(0, last, block):
        cut = (Ellipsis, slice(start, start + block)) if shape else ()
        part = [a[cut] if cut and np.ndim(a) and np.shape(a)[-1] == last else a for a in args]
        with np.errstate(invalid="ignore", divide="ignore"):
            xn, pn = step(*tuples_2d(state, cut), *part)
        store_tuples_2d(xn, pn, out, cut)
    mirror_upper(out.P)
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


def semidefinite_cholesky(
    P: NDArray[np.float64], columns: int | None = None, null_negative: bool = False
) -> dict[tuple[int, int], Vec]:
    """Entries (i, k), i >= k, k < ``columns``, of the lower Cholesky factor L of every
    positive semi-definite P (..., n, n), L Lᵀ = P, as (...) vectors.

    The column-by-column (Cholesky–Banachiewicz) recursion::

        d_j = P_jj − Σ_{k<j} L_jk²,   L_jj = √d_j,   L_ij = (P_ij − Σ_{k<j} L_ik L_jk) / L_jj

    A pivot with −``SEMIDEFINITE_RTOL`` · P_jj ≤ d_j ≤ 0 is a direction of zero variance (to
    rounding): its column is zero, which is the exact factor of a semi-definite P (there the
    P_ij − Σ L_ik L_jk vanish with d_j). A pivot below −``SEMIDEFINITE_RTOL`` · P_jj (P
    indefinite beyond rounding) gives NaN for that track only. Where P is positive definite
    this is the usual Cholesky factor, LAPACK's to rounding. ``columns`` None: all n.

    ``null_negative``: every pivot <= 0 is a null direction (NaN only from a NaN in P). For
    the Kalman updates' factor (``factored_joseph``), whose P is positive semi-definite in
    exact arithmetic (a prediction F P Fᵀ + Q, an IMM mixing, an earlier update, each a sum
    of positive semi-definite terms): a negative pivot there is rounding whatever its size
    against P_jj, which in a nearly singular P (a long prediction: eigenvalues 10¹⁴ apart)
    exceeds any fixed fraction (10⁻⁸ of P_jj measured after 10⁶ s steps).
    """
    n = P.shape[-1]
    columns = n if columns is None else columns
    Pc = cov_components(P)
    L: dict[tuple[int, int], Vec] = {}
    with np.errstate(invalid="ignore", divide="ignore"):
        for j in range(columns):
            d = Pc[j, j].copy()
            for k in range(j):
                d -= L[j, k] * L[j, k]
            tol = SEMIDEFINITE_RTOL * Pc[j, j]
            null = (d <= 0.0) if null_negative else (d <= 0.0) & (d >= -tol)
            d[null] = 0.0
            d[d < -tol] = np.nan  # indefinite beyond rounding: this track becomes NaN
            np.sqrt(d, out=d)
            L[j, j] = d
            for i in range(j + 1, n):
                e = Pc[i, j].copy()
                for k in range(j):
                    e -= L[i, k] * L[j, k]
                e /= d
                e[null] = 0.0
                L[i, j] = e
    return L


def symmetric_inverse(
    S: dict[tuple[int, int], Vec], m: int, scale: float = 1.0
) -> dict[tuple[int, int], Vec]:
    """Entries (i, j), i <= j, of ``scale`` · S⁻¹ for a batch of symmetric m × m matrices.

    ``S`` holds the upper-triangle entries as (...) arrays, m = 1, 2 or 3. Written out
    (adjugate over the determinant) so the cost is a dozen vector operations, whatever the
    batch size; ``scale`` is folded into the reciprocal of the determinant.
    """
    if m == 1:
        return {(0, 0): scale / S[0, 0]}
    if m == 2:
        s00, s01, s11 = S[0, 0], S[0, 1], S[1, 1]
        inv_det = scale / (s00 * s11 - s01 * s01)
        return {(0, 0): s11 * inv_det, (0, 1): -s01 * inv_det, (1, 1): s00 * inv_det}
    if m == 3:
        s00, s01, s02 = S[0, 0], S[0, 1], S[0, 2]
        s11, s12, s22 = S[1, 1], S[1, 2], S[2, 2]
        c00 = s11 * s22 - s12 * s12
        c01 = s02 * s12 - s01 * s22
        c02 = s01 * s12 - s02 * s11
        inv_det = scale / (s00 * c00 + s01 * c01 + s02 * c02)
        return {
            (0, 0): c00 * inv_det,
            (0, 1): c01 * inv_det,
            (0, 2): c02 * inv_det,
            (1, 1): (s00 * s22 - s02 * s02) * inv_det,
            (1, 2): (s01 * s02 - s00 * s12) * inv_det,
            (2, 2): (s00 * s11 - s01 * s01) * inv_det,
        }
    raise ValueError(f"symmetric_inverse supports 1 to 3 dimensions (got {m})")


def sym(M: dict[tuple[int, int], Vec], i: int, j: int) -> Vec:
    """Entry (i, j) of a symmetric matrix stored by its upper triangle."""
    return M[(i, j)] if i <= j else M[(j, i)]


def factored_joseph(
    L: dict[tuple[int, int], Vec],
    K: list[list[Vec]],
    HL: list[list[Vec | float]],
    R: dict[tuple[int, int], Vec],
    out_P: NDArray[np.float64],
) -> None:
    """The Joseph-form covariance P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ of a batch, on a factor
    L of P (P = L Lᵀ, ``semidefinite_cholesky``), into ``out_P`` (..., n, n)::

        Z = L − K (H L),   P⁺ = Z Zᵀ + K R Kᵀ

    Why on a factor. P − K S Kᵀ, and the Joseph form multiplied out, P − K Uᵀ + (K S − U) Kᵀ,
    subtract from P terms of P's size to leave P⁺: when P is large against R (a long time
    step: P ≈ 10¹² R and more) what is left is rounding, of either sign, and so is M P Mᵀ
    evaluated as products wherever P⁺ is small against P (a velocity known from Doppler under
    a prediction of 10⁸ s). Here the subtraction is in Z, where an error is only an error:
    P⁺ is a sum of squares (Z Zᵀ) and of K R Kᵀ, positive semi-definite for any gain, and its
    entries stay within rounding of P⁺'s own size.

    Args:
        L: the entries (i, k), i >= k, of P's lower factor, each (...)
            (``semidefinite_cholesky`` with ``null_negative``).
        K: the gain, K[i][a] (...) for state i and measurement component a.
        HL: H L, HL[a][k] (...) (or 0.0) for measurement component a and column k.
        R: the upper entries (a, b), a <= b, of the measurement noise, each (...).
        out_P: the (..., n, n) output, written whole (symmetric).
    """
    n, d = len(K), len(HL)
    Pc = cov_components(out_P)
    # K R Kᵀ first, then one column z = Z[:, k] at a time added as z zᵀ: the working memory
    # is L, K R and one column, not Z whole.
    KR = [[sum(K[i][a] * sym(R, a, b) for a in range(d)) for b in range(d)] for i in range(n)]
    for i in range(n):
        for j in range(i, n):
            acc = KR[i][0] * K[j][0]
            for b in range(1, d):
                acc += KR[i][b] * K[j][b]
            Pc[i, j] = acc
    del KR
    for k in range(n):
        z = []
        for i in range(n):
            v = K[i][0] * HL[0][k]
            for a in range(1, d):
                v = v + K[i][a] * HL[a][k]
            z.append(L[i, k] - v if i >= k else -v)
        for i in range(n):
            for j in range(i, n):
                Pc[i, j] += z[i] * z[j]
    for i in range(n):
        for j in range(i + 1, n):
            Pc[j, i] = Pc[i, j]


#: Batches of at most this many tracks take the dense path (``dense_joseph_update``): below it
#: numpy's per-call overhead, not arithmetic, is the cost, and a few matrix products beat a few
#: hundred vector operations (measured crossover: between 16 and 64 tracks).
DENSE_MAX_RUNS = 16


def use_dense(state: CVBatch) -> bool:
    """Whether ``state`` is small enough for the dense path."""
    return state.runs <= DENSE_MAX_RUNS


def dense_joseph_update(
    state: CVBatch,
    innovation: NDArray[np.float64],
    H: NDArray[np.float64],
    R: NDArray[np.float64],
    out: CVBatch | None = None,
) -> CVBatch:
    """The Joseph-form Kalman update as matrix products, for small batches.

        U = P Hᵀ,  S = H U + R,  K = U S⁻¹,  x⁺ = x + K ν,
        P⁺ = M P Mᵀ + K R Kᵀ,   M = I − K H                        (symmetrised)

    The same equations as the component-wise updates (``core.filters.position``,
    ``core.filters.doppler``), evaluated with a handful of batched matrix products instead of
    one vector operation per entry; the tests check the two against each other.

    P⁺ is the Joseph form on a factor of P (``factored_joseph``): M P Mᵀ = (M L)(M L)ᵀ with
    L the (semi-definite) Cholesky factor of P, so P⁺ is a sum of squares, positive
    semi-definite however large P is against R.

    Args:
        innovation: ν (..., k).  H: (..., k, n) or (k, n).  R: (..., k, k).
    """
    x, P = state.x, state.P
    U = P @ H.mT
    S = H @ U + R
    if S.shape[-1] == 1:  # a scalar measurement (Doppler): S⁻¹ is a division
        K = U / S
    else:
        K = np.linalg.solve(S, U.mT).mT  # U S⁻¹ (S symmetric)
    L = np.zeros(P.shape)
    for (i, k), v in semidefinite_cholesky(P, null_negative=True).items():
        L[..., i, k] = v
    Z = L - K @ (H @ L)  # (I − K H) L
    P_new = Z @ Z.mT + K @ R @ K.mT
    out = target_batch(state, out)
    out.x[...] = x + (K @ innovation[..., None])[..., 0]
    out.P[...] = 0.5 * (P_new + P_new.mT)
    return out
