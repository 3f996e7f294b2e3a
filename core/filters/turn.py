"""The coordinated-turn prediction at a known turn rate ω, as plain arithmetic for any number
type: Python floats in numba-compiled code (``core.filters.kernels_imm`` compiles
``turn_predict``) and numpy arrays of a batch (``core.filters.imm.imm_predict``). One home for
the IMM's turn models on both engines (``core.filters.models.IMMModel.turn_rate_degps``).

A target flying a coordinated turn keeps its speed and turns its horizontal velocity at the
rate ω (rad/s, positive counter-clockwise from x towards y). Over T seconds, with θ = ωT,
the horizontal state (x, ẋ, y, ẏ) moves exactly by (Bar-Shalom, Li and Kirubarajan 2001,
sec. 11.7.1)::

    x⁺ = x + S ẋ − C ẏ          S = sin θ / ω
    ẋ⁺ =     c ẋ − s ẏ          C = (1 − cos θ) / ω = 2 sin²(θ/2) / ω
    y⁺ = y + C ẋ + S ẏ          c = cos θ = 1 − 2 sin²(θ/2)
    ẏ⁺ =     s ẋ + c ẏ          s = sin θ

and the vertical axis (z, ż) of a 3D state is constant velocity. At a fixed ω this F is
linear in the state, so the prediction is x⁻ = F x, P⁻ = F P Fᵀ + Q with no Jacobian, Q the
white-noise acceleration of ``core.filters.predict`` (σa² g gᵀ per axis, g = (T²/2, T),
added by ``add_process_noise``), which here absorbs the difference between the model's ω
and the target's. As ω → 0, S → T, C → 0 and F → the constant-velocity one; ω = 0
itself is the constant-velocity model (``core.filters.predict``), never passed here.

The half-angle forms keep C and c free of the cancellation of 1 − cos θ at small θ. The
caller evaluates sin θ and sin(θ/2) in its own namespace (``math`` for scalars, numpy for a
batch of time steps), so the functions below use + − × ÷ only.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: A number or an array of numbers (the functions below are written for either).
Num = Any


def turn_factors(omega: float, sin_theta: Num, sin_half: Num) -> tuple[Num, Num, Num, Num]:
    """(S, C, c, s) of the turn at ω (rad/s, ≠ 0) over T, from sin θ and sin(θ/2), θ = ωT."""
    h2 = 2.0 * sin_half * sin_half
    return sin_theta / omega, h2 / omega, 1.0 - h2, sin_theta


def turn_predict(x: Any, P: Any, n: int, T: Num, k: tuple[Num, Num, Num, Num]) -> None:
    """x⁻ = F x, F P Fᵀ in place, F the turn (factors k over T) on (x, ẋ, y, ẏ) and
    constant velocity on (z, ż) when n = 6; the caller adds Q
    (``core.filters.predict.add_process_noise``, the constant-velocity model's own).

    ``x[i]`` and ``P[i, j]`` must be the state's components: a track's arrays x (n,),
    P (n, n) in compiled code, or a batch's with the state axes first, x (n, ...),
    P (n, n, ...) (``numpy.moveaxis`` views), whose components are arrays broadcasting
    against ``T`` and ``k``. F P is formed column by column, then (F P) Fᵀ row by row.
    """
    S, C, c, s = k

    def turn(a, va, b, vb):  # F on (x, ẋ, y, ẏ) (module docstring)
        return a + S * va - C * vb, c * va - s * vb, b + C * va + S * vb, s * va + c * vb

    x[0], x[1], x[2], x[3] = turn(x[0], x[1], x[2], x[3])
    if n == 6:
        x[4] = x[4] + T * x[5]
    for j in range(n):
        P[0, j], P[1, j], P[2, j], P[3, j] = turn(P[0, j], P[1, j], P[2, j], P[3, j])
        if n == 6:
            P[4, j] = P[4, j] + T * P[5, j]
    for i in range(n):
        P[i, 0], P[i, 1], P[i, 2], P[i, 3] = turn(P[i, 0], P[i, 1], P[i, 2], P[i, 3])
        if n == 6:
            P[i, 4] = P[i, 4] + T * P[i, 5]


def turn_transition_matrix(omega: float, T: float, dims: int = 2) -> NDArray[np.float64]:
    """F (n, n), n = 2·dims, of the turn at ω ≠ 0 (rad/s) over T: ``turn_predict``'s image of
    each unit state, column by column (for a reference filter built from matrices)."""
    n = 2 * dims
    theta = omega * T
    k = turn_factors(omega, math.sin(theta), math.sin(0.5 * theta))
    F = np.eye(n)
    for j in range(n):
        turn_predict(F[:, j], np.zeros((n, n)), n, T, k)
    return F
