"""A track's state read into tuples of numbers and written back, 2D and 3D: the layout the
plain-arithmetic steps take (``core.filters.position_2d``'s and the IMM's,
``core.filters.imm_moments``).

x and P are indexable as ``x[i]``, ``P[i, j]``: one track's (n,), (n, n) arrays in
numba-compiled code (``core.filters.kernels_2d`` compiles these functions), or a batch's
component-major views (n, ...), (n, n, ...) in the numpy engine, each entry then a (...)
array. The tuple holds x's n components and P's upper entries row by row (10 in 2D, 21 in
3D, ``core.filters.state.UPPER_2D`` order); a store writes P symmetric.
"""

from __future__ import annotations


def load_2d(x, P):
    """(x, p) of x (4,), P (4, 4) (P's ten upper entries)."""
    return (x[0], x[1], x[2], x[3]), (
        P[0, 0], P[0, 1], P[0, 2], P[0, 3], P[1, 1], P[1, 2], P[1, 3], P[2, 2], P[2, 3], P[3, 3]
    )  # fmt: skip


def store_2d(xt, p, x, P):
    """Write (x, p) into x (4,) and the symmetric P (4, 4)."""
    for i in range(4):
        x[i] = xt[i]
    p00, p01, p02, p03, p11, p12, p13, p22, p23, p33 = p
    P[0, 0], P[0, 1], P[0, 2], P[0, 3] = p00, p01, p02, p03
    P[1, 0], P[1, 1], P[1, 2], P[1, 3] = p01, p11, p12, p13
    P[2, 0], P[2, 1], P[2, 2], P[2, 3] = p02, p12, p22, p23
    P[3, 0], P[3, 1], P[3, 2], P[3, 3] = p03, p13, p23, p33


def load_3d(x, P):
    """(x, p) of x (6,), P (6, 6) (P's 21 upper entries, row by row)."""
    return (x[0], x[1], x[2], x[3], x[4], x[5]), (
        P[0, 0], P[0, 1], P[0, 2], P[0, 3], P[0, 4], P[0, 5],
        P[1, 1], P[1, 2], P[1, 3], P[1, 4], P[1, 5],
        P[2, 2], P[2, 3], P[2, 4], P[2, 5],
        P[3, 3], P[3, 4], P[3, 5],
        P[4, 4], P[4, 5],
        P[5, 5],
    )  # fmt: skip


def store_3d(xt, p, x, P):
    """Write (x, p) into x (6,) and the symmetric P (6, 6): the upper entries, mirrored."""
    for a in range(6):
        x[a] = xt[a]
    k = 0
    for a in range(6):
        for b in range(a, 6):
            P[a, b] = p[k]
            P[b, a] = p[k]
            k += 1
