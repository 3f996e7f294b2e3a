"""The IMM's mixing, mode probabilities and combination written once, as plain arithmetic
over one track's arrays or a batch's component-major views alike.

With μ the model probabilities and Π the transition matrix (``core.filters.imm``)::

    mixing        c̄ⱼ = Σᵢ πᵢⱼ μᵢ,   μᵢ|ⱼ = πᵢⱼ μᵢ / c̄ⱼ
                  x⁰ⱼ = Σᵢ μᵢ|ⱼ xᵢ,   P⁰ⱼ = Σᵢ μᵢ|ⱼ (Pᵢ + (xᵢ − x⁰ⱼ)(xᵢ − x⁰ⱼ)ᵀ)
    update        μⱼ ∝ Λⱼ c̄ⱼ   (Λⱼ model j's likelihood of the plot)
    combination   x = Σⱼ μⱼ xⱼ,   P = Σⱼ μⱼ (Pⱼ + (xⱼ − x)(xⱼ − x)ᵀ)

The models' estimates are indexed ``xm[i, a]``, ``Pm[i, a, b]`` and the probabilities
``mu[i]``: one track's (r, n), (r, n, n), (r,) arrays in numba-compiled code
(``core.filters.kernels_imm`` compiles these functions), or a batch's component-major views
(r, n, ...), (r, n, n, ...), (r, ...) in the numpy engine (``core.filters.imm``). Each model's
(x, p) is read once into tuples (``core.filters.tuples``) and the sums are carried in them:
in compiled code they stay in registers. One form per state size (n = 4, 6): against loops
over arrays of any n, a quarter of the time in 2D (two models: 114 against 453 ns a
mixing, 44 against 116 ns a combination), and in 3D 286 against about 630 ns a mixing, each
measured as a compiled call.
"""

from __future__ import annotations

import numpy as np

from radarviz.core.filters.position_2d import _add_outer
from radarviz.core.filters.tuples import load_2d, load_3d, store_2d, store_3d

#: The elementary functions, numpy's here (numba compiles them on numbers too); the kernels
#: re-bind ``where`` to a scalar select.
where = np.where
exp = np.exp
log = np.log
isfinite = np.isfinite
maximum = np.maximum
inf = np.inf


def _log_weight(prior, ll, j):
    # (whether model j can take weight, log Λⱼ + log c̄ⱼ there): a model of prior 0 or whose
    # likelihood is not finite (its S not positive definite) gets none
    ok = (prior[j] > 0.0) & isfinite(ll[j])
    return ok, ll[j] + log(where(ok, prior[j], 1.0))


def updated_probabilities(prior, ll, mu):
    """μⱼ ∝ Λⱼ c̄ⱼ into mu (r, …) (may be ``prior``), from the prior c̄ (r, …) and the
    models' log-likelihoods ll (r, …), as exp(log Λⱼ + log c̄ⱼ − max) normalised over the
    models (so that a far-off plot does not underflow every model to 0). The prior is inside
    the shift: a plot updates μ once per stage (position, then Doppler), and a first stage
    that left a model μ = 0 (underflow) while the second stage's likelihood favours it by
    more than e⁷⁴⁵ gave 0 · 1 + μ · 0 = 0 / 0 with the likelihoods alone shifted (a 3D track
    at 89.9999° elevation with Doppler: NaN states). A model of prior 0 or whose likelihood
    is not finite gets no weight; a track with no model that can take weight keeps its
    prior."""
    r = prior.shape[0]
    top = -inf
    for j in range(r):
        ok, lw = _log_weight(prior, ll, j)
        top = maximum(top, where(ok, lw, -inf))
    found = isfinite(top)
    shift = where(found, top, 0.0)
    total = 0.0
    for j in range(r):
        ok, lw = _log_weight(prior, ll, j)
        w = where(found, exp(where(ok, lw - shift, -inf)), prior[j])
        mu[j] = w
        total = total + w
    for j in range(r):
        mu[j] = mu[j] / total


def predicted_probabilities(mu, Pi, c):
    """The predicted model probabilities c̄ⱼ = Σᵢ πᵢⱼ μᵢ into c (r,); Π (r, r) numbers."""
    r = mu.shape[0]
    for j in range(r):
        acc = mu[0] * Pi[0, j]
        for i in range(1, r):
            acc += mu[i] * Pi[i, j]
        c[j] = acc


def _weights(mu, Pi, c, j, wj):
    # the mixing weights μᵢ|ⱼ = πᵢⱼ μᵢ / c̄ⱼ of model j into wj (r,)
    for i in range(mu.shape[0]):
        wj[i] = Pi[i, j] * mu[i] / c[j]


def _add_scaled(p, w, q):
    # p + w q on the ten upper entries
    return (
        p[0] + w * q[0], p[1] + w * q[1], p[2] + w * q[2], p[3] + w * q[3], p[4] + w * q[4],
        p[5] + w * q[5], p[6] + w * q[6], p[7] + w * q[7], p[8] + w * q[8], p[9] + w * q[9],
    )  # fmt: skip


def _mean_2d(xm, mu):
    # Σᵢ μᵢ xᵢ over the models of xm (r, 4)
    xa = (0.0, 0.0, 0.0, 0.0)
    for i in range(xm.shape[0]):
        m = mu[i]
        xa = (
            xa[0] + m * xm[i, 0],
            xa[1] + m * xm[i, 1],
            xa[2] + m * xm[i, 2],
            xa[3] + m * xm[i, 3],
        )
    return xa


def _spread_2d(xm, Pm, mu, xa):
    # Σᵢ μᵢ (Pᵢ + (xᵢ − x̄)(xᵢ − x̄)ᵀ), upper entries
    pa = (0.0,) * 10
    for i in range(xm.shape[0]):
        xi, pi = load_2d(xm[i], Pm[i])
        d = (xi[0] - xa[0], xi[1] - xa[1], xi[2] - xa[2], xi[3] - xa[3])
        pa = _add_outer(_add_scaled(pa, mu[i], pi), mu[i], d)
    return pa


def mix_2d(xm, Pm, mu, Pi, x0, P0, c, w):
    """The mixed initial conditions (module docstring), 2D (n = 4): from the models' xm
    (r, n), Pm (r, n, n) (read as its upper triangles) and μ (r,), with Π (r, r), into x0
    (r, n), P0 (r, n, n) (symmetric) and c̄ (r,); w (r, r) scratch (row 0 the weights μᵢ|ⱼ of
    one j, model j's mixture being ``combine_2d``'s with them)."""
    predicted_probabilities(mu, Pi, c)
    wj = w[0]  # μᵢ|ⱼ of one j at a time
    for j in range(xm.shape[0]):
        _weights(mu, Pi, c, j, wj)
        xa = _mean_2d(xm, wj)
        store_2d(xa, _spread_2d(xm, Pm, wj, xa), x0[j], P0[j])


def combine_2d(xm, Pm, mu, x, P):
    """The moment-matched Σⱼ μⱼ N(xⱼ, Pⱼ) (module docstring), 2D (n = 4): of xm (r, n),
    Pm (r, n, n) (upper triangles), μ (r,) into x (n,), P (n, n) (symmetric)."""
    xa = _mean_2d(xm, mu)
    store_2d(xa, _spread_2d(xm, Pm, mu, xa), x, P)


def _add_term_3d(p, w, q, e):
    # p + w (q + e eᵀ) on the 21 upper entries
    e0, e1, e2, e3, e4, e5 = e
    return (
        p[0] + w * (q[0] + e0 * e0), p[1] + w * (q[1] + e0 * e1), p[2] + w * (q[2] + e0 * e2),
        p[3] + w * (q[3] + e0 * e3), p[4] + w * (q[4] + e0 * e4), p[5] + w * (q[5] + e0 * e5),
        p[6] + w * (q[6] + e1 * e1), p[7] + w * (q[7] + e1 * e2), p[8] + w * (q[8] + e1 * e3),
        p[9] + w * (q[9] + e1 * e4), p[10] + w * (q[10] + e1 * e5), p[11] + w * (q[11] + e2 * e2),
        p[12] + w * (q[12] + e2 * e3), p[13] + w * (q[13] + e2 * e4),
        p[14] + w * (q[14] + e2 * e5), p[15] + w * (q[15] + e3 * e3),
        p[16] + w * (q[16] + e3 * e4), p[17] + w * (q[17] + e3 * e5),
        p[18] + w * (q[18] + e4 * e4), p[19] + w * (q[19] + e4 * e5),
        p[20] + w * (q[20] + e5 * e5),
    )  # fmt: skip


def _mean_3d(xm, mu):
    # Σᵢ μᵢ xᵢ over the models of xm (r, 6)
    xa = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    for i in range(xm.shape[0]):
        m = mu[i]
        xa = (
            xa[0] + m * xm[i, 0], xa[1] + m * xm[i, 1], xa[2] + m * xm[i, 2],
            xa[3] + m * xm[i, 3], xa[4] + m * xm[i, 4], xa[5] + m * xm[i, 5],
        )  # fmt: skip
    return xa


def _spread_3d(xm, Pm, mu, xa):
    # Σᵢ μᵢ (Pᵢ + (xᵢ − x̄)(xᵢ − x̄)ᵀ), upper entries
    pa = (0.0,) * 21
    for i in range(xm.shape[0]):
        xi, pi = load_3d(xm[i], Pm[i])
        d = (
            xi[0] - xa[0],
            xi[1] - xa[1],
            xi[2] - xa[2],
            xi[3] - xa[3],
            xi[4] - xa[4],
            xi[5] - xa[5],
        )
        pa = _add_term_3d(pa, mu[i], pi, d)
    return pa


def mix_3d(xm, Pm, mu, Pi, x0, P0, c, w):
    """``mix_2d`` for the 3D state (n = 6)."""
    predicted_probabilities(mu, Pi, c)
    wj = w[0]  # μᵢ|ⱼ of one j at a time
    for j in range(xm.shape[0]):
        _weights(mu, Pi, c, j, wj)
        xa = _mean_3d(xm, wj)
        store_3d(xa, _spread_3d(xm, Pm, wj, xa), x0[j], P0[j])


def combine_3d(xm, Pm, mu, x, P):
    """``combine_2d`` for the 3D state (n = 6)."""
    xa = _mean_3d(xm, mu)
    store_3d(xa, _spread_3d(xm, Pm, mu, xa), x, P)


#: The functions, in the order ``core.filters.rebind`` compiles them (each after those it
#: calls): the IMM's kernels compile them with ``tuples``'s and ``position_2d``'s helpers.
STEP_FUNCTIONS = (
    predicted_probabilities,
    _weights,
    _add_scaled,
    _mean_2d,
    _spread_2d,
    mix_2d,
    combine_2d,
    _add_term_3d,
    _mean_3d,
    _spread_3d,
    mix_3d,
    combine_3d,
)
