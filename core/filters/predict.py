"""Constant-velocity prediction of a batch of tracks, 2D or 3D.

Per axis (p, ṗ) the motion over T seconds is ``[[1, T], [0, 1]]``; the process noise is the
discrete white-noise acceleration with std σa on each axis (filterpy's
``Q_discrete_white_noise(2, T, σa²)``)::

    F = blockdiag([[1, T], [0, 1]] per axis)
    Q = σa² blockdiag(g gᵀ per axis),   g = (T²/2, T)      (σa = 0: the papers' Q = 0)
    x⁻ = F x,   P⁻ = F P Fᵀ + Q

The step is written once per dimension as plain arithmetic, for any number type: Python
floats in numba-compiled code and arrays of a batch (numpy, or any array-API namespace).
``predict_2d`` takes and returns the 2D state as tuples (x and the ten upper entries of P),
which compiled code keeps in registers (``core.filters.kernels_2d`` compiles it; the array-API
path calls it on arrays); ``predict_components`` updates the components x[i], P[i, j] of any
n in place (the 3D kernels compile it; the numpy engine calls it on a batch's component-major
views), and ``add_process_noise`` adds Q to them, after this prediction or the
coordinated turn's (``core.filters.turn``). ``white_acceleration`` is the one home of Q's
entries. A function here calls no other (compiled code compiles each one and composes
them), so each takes what it needs as arguments.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.state import (
    CVBatch,
    cov_components,
    mean_components,
    mirror_upper,
    store_tuples_2d,
    target_batch,
    tuples_2d,
)

#: A number or an array of numbers (the step functions are written for either).
Num = Any


def white_acceleration(T: Num, q: float) -> tuple[Num, Num, Num]:
    """One axis's Q = σa² g gᵀ, g = (T²/2, T), as (Q_pp, Q_pv, Q_vv); q = σa² (m²/s⁴)."""
    T2 = T * T
    return q * T2 * T2 / 4.0, q * T2 * T / 2.0, q * T2


def predict_2d(x: tuple, p: tuple, T: Num, Q: tuple[Num, Num, Num]) -> tuple[tuple, tuple]:
    """x⁻ = F x, P⁻ = F P Fᵀ + Q of the 2D state (x, ẋ, y, ẏ), as new tuples.

    Args:
        x: the four components of the state.
        p: the ten upper entries of P in ``core.filters.state.UPPER_2D`` order,
            (p00, p01, p02, p03, p11, p12, p13, p22, p23, p33).
        T: the step (s), one number or an array broadcasting against the components.
        Q: each axis's process noise, ``white_acceleration(T, σa²)``.
    """
    x0, x1, x2, x3 = x
    p00, p01, p02, p03, p11, p12, p13, p22, p23, p33 = p
    qa, qb, qc = Q
    return (x0 + T * x1, x1, x2 + T * x3, x3), (
        (p00 + T * p01) + T * (p01 + T * p11) + qa,
        p01 + T * p11 + qb,
        (p02 + T * p12) + T * (p03 + T * p13),
        p03 + T * p13,
        p11 + qc,
        p12 + T * p13,
        p13,
        (p22 + T * p23) + T * (p23 + T * p33) + qa,
        p23 + T * p33 + qb,
        p33 + qc,
    )


def predict_components(x: Any, P: Any, n: int, T: Num) -> None:
    """x⁻ = F x, F P Fᵀ in place, for an n-component state (n = 4 or 6); Q is added by
    ``add_process_noise`` (a separate step, shared with the coordinated-turn models).

    ``x[i]`` and ``P[i, j]`` must be the state's components (both triangles of P): a
    track's arrays x (n,), P (n, n) in compiled code, or a batch's component-major views
    x (n, ...), P (n, n, ...), whose components broadcast against ``T``. F P is formed
    row by row (a position row gains T times its velocity row), then (F P) Fᵀ column by
    column.
    """
    for a in range(n // 2):
        p = 2 * a
        x[p] = x[p] + T * x[p + 1]
        for j in range(n):
            P[p, j] = P[p, j] + T * P[p + 1, j]
    for i in range(n):
        for a in range(n // 2):
            p = 2 * a
            P[i, p] = P[i, p] + T * P[i, p + 1]


def add_process_noise(P: Any, n: int, Q: tuple[Num, Num, Num]) -> None:
    """P += Q in place on every axis block of the n-component state, Q the per-axis entries
    ``white_acceleration(T, σa²)`` (components as in ``predict_components``)."""
    qa, qb, qc = Q
    for a in range(n // 2):
        p = 2 * a
        P[p, p] = P[p, p] + qa
        P[p, p + 1] = P[p, p + 1] + qb
        P[p + 1, p] = P[p + 1, p] + qb
        P[p + 1, p + 1] = P[p + 1, p + 1] + qc


def transition_matrix(period_s: float, dims: int = 2) -> NDArray[np.float64]:
    """F (n, n), n = 2·dims, for the interleaved state (x, ẋ, y, ẏ[, z, ż])."""
    out = np.eye(2 * dims)
    for a in range(dims):
        out[2 * a, 2 * a + 1] = period_s
    return out


def process_noise(period_s: float, sigma_a_mps2: float, dims: int = 2) -> NDArray[np.float64]:
    """Q (n, n): σa² g gᵀ on each axis block, g = (T²/2, T)."""
    g = np.array([period_s**2 / 2.0, period_s])
    q = sigma_a_mps2**2 * np.outer(g, g)
    out = np.zeros((2 * dims, 2 * dims))
    for a in range(dims):
        out[2 * a : 2 * a + 2, 2 * a : 2 * a + 2] = q
    return out


def cv_predict(
    state: CVBatch,
    period_s: float | NDArray[np.float64],
    sigma_a_mps2: float = 0.0,
    out: CVBatch | None = None,
) -> CVBatch:
    """x⁻ = F x, P⁻ = F P Fᵀ + Q for every track of the batch.  Returns ``out`` or a new batch.

    ``period_s`` is one period T for the whole batch, or an array of periods, one per track,
    broadcasting against the batch shape from its end (many targets, each with its own time
    since its last plot: T (K,) for a batch (M, K) of M methods × K targets); T = 0 leaves a
    track as it is. The arithmetic is ``predict_2d`` (2D) or ``predict_components`` and
    ``add_process_noise`` (3D) on the batch's components, the compiled kernels' own steps.
    """
    per_track = np.ndim(period_s) > 0
    T = np.asarray(period_s, dtype=np.float64) if per_track else float(period_s)
    Q = white_acceleration(T, float(sigma_a_mps2) ** 2)
    out = target_batch(state, out)
    if state.dims == 2:
        store_tuples_2d(*predict_2d(*tuples_2d(state), T, Q), out)
        mirror_upper(out.P)
        return out
    ox, oP = mean_components(out.x), cov_components(out.P)
    out.x[...] = state.x
    out.P[...] = state.P
    n = state.x.shape[-1]
    predict_components(ox, oP, n, T)
    add_process_noise(oP, n, Q)
    return out
