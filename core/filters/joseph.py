"""The Joseph-form Kalman update for a measurement of any H, as matrix products: the
converted Doppler update (``core.filters.converted_doppler``) and the joint EKF and Doppler
update (``core.filters.joint_doppler``), which have no compiled kernel.

    U = P Hᵀ,  S = H U + R,  K = U S⁻¹,  x⁺ = x + K ν
    P⁺ = Z Zᵀ + K R Kᵀ,   Z = (I − K H) L = L − K (H L),   L Lᵀ = P

Why on a factor. P − K S Kᵀ, and the Joseph form multiplied out, P − K Uᵀ + (K S − U) Kᵀ,
subtract from P terms of P's size to leave P⁺: when P is large against R (a long time step:
P ≈ 10¹² R and more) what is left is rounding, of either sign, and so is (I − K H) P (I − K H)ᵀ
evaluated as products wherever P⁺ is small against P (a velocity known from Doppler under a
prediction of 10⁸ s). On a factor the subtraction is in Z, where an error is only an error:
P⁺ is a sum of squares (Z Zᵀ) and of K R Kᵀ, positive semi-definite for any gain, and its
entries stay within rounding of P⁺'s own size. Every update of the engine takes its
covariance this way (``core.filters.position_2d``, ``position_3d``, ``doppler_2d``,
``doppler_3d``; the UKF's Joseph form is a sum over its points).

L is the semi-definite Cholesky factor of those modules (``semidefinite_cholesky_2d``,
``semidefinite_cholesky_3d``) with every pivot <= 0 taken as a null direction: P is positive
semi-definite in exact arithmetic (a prediction F P Fᵀ + Q, an IMM mixing, an earlier update,
each a sum of positive semi-definite terms), so a negative pivot is rounding whatever its
size against P_jj, which in a nearly singular P (a long prediction: eigenvalues 10¹⁴ apart)
exceeds any fixed fraction (10⁻⁸ of P_jj measured after 10⁶ s steps).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.position_2d import semidefinite_cholesky_2d
from radarviz.core.filters.position_3d import semidefinite_cholesky_3d
from radarviz.core.filters.state import CVBatch, cov_components, target_batch, tuples_2d


def cholesky_factor(state: CVBatch) -> NDArray[np.float64]:
    """The semi-definite lower Cholesky factor (..., n, n) of every P of ``state``, a pivot
    <= 0 a null direction (module docstring): the engine's own factor, 2D or 3D."""
    L = np.zeros(state.P.shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        if state.dims == 2:
            cols = semidefinite_cholesky_2d(tuples_2d(state)[1], 1.0, True)
            for k, col in enumerate(cols):
                for i in range(k, 4):
                    L[..., i, k] = col[i]
        else:
            semidefinite_cholesky_3d(cov_components(state.P), 1.0, cov_components(L), True)
    return L


def joseph_update(
    state: CVBatch,
    innovation: NDArray[np.float64],
    H: NDArray[np.float64],
    R: NDArray[np.float64],
    out: CVBatch | None = None,
) -> CVBatch:
    """The Kalman update of a batch by a measurement z = H x + v, v ~ N(0, R), given its
    innovation ν = z − H x⁻ (module docstring).

    Args:
        state: the predicted batch, x (..., n), P (..., n, n).
        innovation: ν (..., k).  H: (..., k, n) or (k, n).  R: (..., k, k).
        out: optional preallocated batch to write into (must not alias ``state``).
    """
    x, P = state.x, state.P
    U = P @ H.mT
    S = H @ U + R
    if S.shape[-1] == 1:  # a scalar measurement: S⁻¹ is a division
        K = U / S
    else:
        K = np.linalg.solve(S, U.mT).mT  # U S⁻¹ (S symmetric)
    L = cholesky_factor(state)
    Z = L - K @ (H @ L)  # (I − K H) L
    P_new = Z @ Z.mT + K @ R @ K.mT
    out = target_batch(state, out)
    out.x[...] = x + (K @ innovation[..., None])[..., 0]
    out.P[...] = 0.5 * (P_new + P_new.mT)
    return out
