"""Kalman update with a Cartesian position measurement (the converted-measurement update).

The measurement picks the position out of the state, H = H_pos (d × n: ones at the position
indexes (0, 2[, 4])), with noise covariance R (d × d)::

    S = H P⁻ Hᵀ + R,   K = P⁻ Hᵀ S⁻¹,   x⁺ = x⁻ + K (z − H x⁻)
    P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ                     (Joseph form)

This is the update of every converted-measurement method (Prosov's naive and corrected
conversions, Lerro & Bar-Shalom's, Mo et al.'s, Bordonaro et al.'s) and, after the exact
change of variables in ``core.filters.polar_ekf``, of the polar EKF too: one implementation.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.filters.position_2d import position_update_2d
from radarviz.core.filters.state import (
    CVBatch,
    Vec,
    cov_components,
    dense_joseph_update,
    factored_joseph,
    mean_components,
    position_index,
    semidefinite_cholesky,
    step_2d,
    sym,
    symmetric_inverse,
    target_batch,
    use_dense,
)


def joseph_update_position(
    state: CVBatch,
    innovation: Sequence[Vec],
    K: NDArray[np.float64],
    R: dict[tuple[int, int], Vec],
    out: CVBatch | None = None,
) -> CVBatch:
    """Joseph-form update for a position measurement (H = H_pos), any gain K.

        x⁺ = x + K ν
        P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ

    An identity for *any* gain K, so an error δK in the gain changes P only at second order
    (the reason to prefer Joseph over P − K H P). Evaluated on a Cholesky factor of P
    (``core.filters.state.factored_joseph``): a sum of squares, positive semi-definite however
    large P is against R (a long time step), which no form subtracting from P is.

    Args:
        state: the predicted batch, x (..., n), P (..., n, n).
        innovation: the d components of ν, each (...).
        K: the (n, d, ...) component-major gain.
        R: the upper-triangle entries (i, j), i <= j, of the measurement noise, each (...).
        out: optional preallocated batch to write into (must not alias ``state``).
    """
    # The mean with explicit output buffers (``out=``, in-place operators): each line is one
    # pass over the batch with no temporary to allocate and copy.
    x, P = state.x, state.P
    n, d = x.shape[-1], len(innovation)
    pos = position_index(state.dims)
    out = target_batch(state, out)
    xc = mean_components(x)
    oxc = mean_components(out.x)
    tmp = np.empty(state.batch_shape)
    Kl = [[K[i, k] for k in range(d)] for i in range(n)]
    for i in range(n):
        o = oxc[i]
        np.multiply(Kl[i][0], innovation[0], out=o)
        o += xc[i]
        for k in range(1, d):
            np.multiply(Kl[i][k], innovation[k], out=tmp)
            o += tmp
    L = semidefinite_cholesky(P, null_negative=True)
    HL = [[L[p, k] if p >= k else 0.0 for k in range(n)] for p in pos]
    factored_joseph(L, Kl, HL, R, out.P)
    return out


def position_gain(state: CVBatch, S: dict[tuple[int, int], Vec]) -> NDArray[np.float64]:
    """K = P Hᵀ S⁻¹ (n, d, ...) component-major, S⁻¹ written out (``symmetric_inverse``)."""
    Pc = cov_components(state.P)
    n, dims = state.P.shape[-1], state.dims
    pos = position_index(dims)
    inv = symmetric_inverse(S, dims)
    invf = {(i, j): sym(inv, i, j) for i in range(dims) for j in range(dims)}
    K = np.empty((n, dims, *state.batch_shape))
    tmp = np.empty(state.batch_shape)
    for i in range(n):
        for j in range(dims):
            o = K[i, j]
            np.multiply(Pc[i, pos[0]], invf[0, j], out=o)
            for k in range(1, dims):
                np.multiply(Pc[i, pos[k]], invf[k, j], out=tmp)
                o += tmp
    return K


@functools.lru_cache(maxsize=2)
def position_matrix(dims: int) -> NDArray[np.float64]:
    """H_pos (d, 2d): picks the position out of the state (read-only, made once per d)."""
    H = np.zeros((dims, 2 * dims))
    H[np.arange(dims), position_index(dims)] = 1.0
    H.flags.writeable = False
    return H


def innovation_update(
    state: CVBatch,
    innovation: Sequence[Vec],
    R: dict[tuple[int, int], Vec],
    out: CVBatch | None = None,
) -> CVBatch:
    """The position update given its innovation ν (d components) and noise R (upper entries).

        S = H P Hᵀ + R,   K = P Hᵀ S⁻¹   (S⁻¹ written out),   then the Joseph form
        (``joseph_update_position``).

    In 2D the arithmetic is ``core.filters.position_2d.position_update_2d`` on the batch's
    components, the compiled kernels' own function; in 3D small batches take the dense path
    (``core.filters.state.dense_joseph_update``).
    """
    if state.dims == 2:
        args = (innovation[0], innovation[1], R[0, 0], R[0, 1], R[1, 1])
        return step_2d(position_update_2d, state, args, out)
    P = state.P
    pos = position_index(state.dims)
    d = len(pos)
    if use_dense(state):
        shape = state.batch_shape
        Rm = np.empty((*shape, d, d))
        for (i, j), v in R.items():
            Rm[..., i, j] = Rm[..., j, i] = v
        H = position_matrix(state.dims)
        nu = np.stack(np.broadcast_arrays(*innovation), -1).reshape(*shape, d)
        return dense_joseph_update(state, nu, H, Rm, out)
    Pc = cov_components(P)
    S = {(i, j): Pc[pos[i], pos[j]] + R[i, j] for i in range(d) for j in range(i, d)}
    K = position_gain(state, S)
    return joseph_update_position(state, innovation, K, R, out)


def cv_update_parts(
    state: CVBatch,
    z: Sequence[Vec],
    R: dict[tuple[int, int], Vec],
    out: CVBatch | None = None,
) -> CVBatch:
    """Kalman update with a position measurement given as components (the fast path).

    Args:
        state: predicted batch (..., n).
        z: the d components of the measured position, each (...).
        R: upper-triangle entries (i, j), i <= j, of its covariance, each (...).
    """
    pos = position_index(state.dims)
    nu = [z[i] - state.x[..., pos[i]] for i in range(len(pos))]
    return innovation_update(state, nu, R, out)


def upper_entries(R: NDArray[np.float64]) -> dict[tuple[int, int], Vec]:
    """The upper-triangle entries of (..., d, d) matrices as a dict of (...) arrays."""
    d = R.shape[-1]
    return {(i, j): R[..., i, j] for i in range(d) for j in range(i, d)}


def cv_update(state: CVBatch, z: ArrayLike, R: ArrayLike, out: CVBatch | None = None) -> CVBatch:
    """Kalman update with Cartesian positions z (..., d) and covariances R (..., d, d)."""
    z = np.asarray(z, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    return cv_update_parts(state, [z[..., i] for i in range(z.shape[-1])], upper_entries(R), out)
