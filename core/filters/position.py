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
from radarviz.core.filters.position_3d import position_update_3d
from radarviz.core.filters.state import (
    CVBatch,
    Vec,
    components,
    position_index,
    step_2d,
    step_3d,
)


@functools.lru_cache(maxsize=2)
def position_matrix(dims: int) -> NDArray[np.float64]:
    """H_pos (d, 2d): picks the position out of the state (read-only, made once per d)."""
    H = np.zeros((dims, 2 * dims))
    H[np.arange(dims), position_index(dims)] = 1.0
    H.flags.writeable = False
    return H


#: The scratch arrays of ``position_update_3d``: S, Si (3, 3), K (6, 3), U (6, 3), L (6, 6).
SCRATCH_3D = ((3, 3), (3, 3), (6, 3), (6, 3), (6, 6))


def innovation_update(
    state: CVBatch,
    innovation: Sequence[Vec],
    R: dict[tuple[int, int], Vec],
    out: CVBatch | None = None,
) -> CVBatch:
    """The position update given its innovation ν (d components) and noise R (upper entries).

        S = H P Hᵀ + R,   K = P Hᵀ S⁻¹,   then the Joseph form on a factor of P

    The arithmetic is the one every engine runs: ``core.filters.position_2d``'s
    ``position_update_2d`` on the batch's components in 2D, ``core.filters.position_3d``'s
    ``position_update_3d`` on its component-major views in 3D.
    """
    if state.dims == 2:
        args = (innovation[0], innovation[1], R[0, 0], R[0, 1], R[1, 1])
        return step_2d(position_update_2d, state, args, out)
    shape = state.batch_shape
    Rm = np.empty((3, 3, *shape))
    for (i, j), v in R.items():
        Rm[i, j] = Rm[j, i] = v
    return step_3d(position_update_3d, state, (components(innovation, shape), Rm), SCRATCH_3D, out)


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
