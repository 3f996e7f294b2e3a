"""Batched constant-velocity Kalman filter for position measurements (M filters at once).

State ``(x, ẋ, y, ẏ)``, transition and measurement (Prosov, sec. 3)::

    F = blockdiag([[1, T], [0, 1]], [[1, T], [0, 1]])       H2 = [[1, 0, 0, 0], [0, 0, 1, 0]]
    Q = σa² blockdiag(g gᵀ, g gᵀ),  g = (T²/2, T)   (discrete white-noise acceleration; σa = 0
                                                      gives the paper's Q = 0)

Predict:  x⁻ = F x,  P⁻ = F P Fᵀ + Q.
Update (Joseph form, which stays symmetric positive definite for any gain):

    S = H2 P⁻ H2ᵀ + R,  K = P⁻ H2ᵀ S⁻¹,  x = x⁻ + K (z − H2 x⁻)
    P = (I − K H2) P⁻ (I − K H2)ᵀ + K R Kᵀ

Layout. The run index leads every public array: ``x`` is (M, 4) and ``P`` is (M, 4, 4). The
arrays are transposed views of component-major storage ((4, M) and (4, 4, M)), so that each
component ``P[:, i, j]`` is one contiguous vector and the update is written as a few hundred
vector operations over all runs instead of M small matrix products: this is what makes 10⁵
runs cheap (see ``radarviz bench``). Only position measurements (H = H2) are supported;
that is the structure exploited (the polar EKF maps its update onto one).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

Vec = NDArray[np.float64]

#: Upper-triangle index pairs of a symmetric 4 × 4 matrix, the entries the update computes.
_UPPER4: tuple[tuple[int, int], ...] = tuple((i, j) for i in range(4) for j in range(i, 4))


class CVBatch(NamedTuple):
    """M constant-velocity filter states.

    Attributes:
        x: (M, 4) means, columns (x, ẋ, y, ẏ) in m and m/s.
        P: (M, 4, 4) covariances.
    """

    x: NDArray[np.float64]
    P: NDArray[np.float64]

    @property
    def runs(self) -> int:
        return self.x.shape[0]


def empty_batch(runs: int) -> CVBatch:
    """Allocate an uninitialised batch with component-major storage (see module docstring)."""
    xs = np.empty((4, runs))
    ps = np.empty((4, 4, runs))
    return CVBatch(xs.T, ps.transpose(2, 0, 1))


def as_batch(x: ArrayLike, P: ArrayLike) -> CVBatch:
    """Copy run-leading arrays x (M, 4) and P (M, 4, 4) into the fast layout."""
    x = np.asarray(x, dtype=np.float64)
    P = np.asarray(P, dtype=np.float64)
    out = empty_batch(x.shape[0])
    out.x[...] = x
    out.P[...] = P
    return out


def transition_matrix(period: float) -> NDArray[np.float64]:
    """F (4, 4) for state (x, ẋ, y, ẏ)."""
    f = np.array([[1.0, period], [0.0, 1.0]])
    out = np.zeros((4, 4))
    out[:2, :2] = f
    out[2:, 2:] = f
    return out


def process_noise(period: float, sigma_a: float) -> NDArray[np.float64]:
    """Q (4, 4), discrete white-noise acceleration with std σa (m/s²) on each axis.

    Equals filterpy's ``Q_discrete_white_noise(2, T, σa²)`` on each axis block.
    """
    g = np.array([period**2 / 2.0, period])
    q = sigma_a**2 * np.outer(g, g)
    out = np.zeros((4, 4))
    out[:2, :2] = q
    out[2:, 2:] = q
    return out


def cv_init(z: ArrayLike, R: ArrayLike, sigma_v: float = 1000.0) -> CVBatch:
    """Start M tracks from one converted point each (the spec's initialisation).

    Position = z (M, 2), velocity = 0; position covariance = R (M, 2, 2), velocity variance
    σv² on each axis (default (1000 m/s)²), no position–velocity correlation.
    """
    z = np.asarray(z, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    out = empty_batch(z.shape[0])
    out.x[...] = 0.0
    out.x[:, 0] = z[:, 0]
    out.x[:, 2] = z[:, 1]
    out.P[...] = 0.0
    out.P[:, 0, 0] = R[:, 0, 0]
    out.P[:, 2, 2] = R[:, 1, 1]
    out.P[:, 0, 2] = out.P[:, 2, 0] = R[:, 0, 1]
    out.P[:, 1, 1] = out.P[:, 3, 3] = sigma_v**2
    return out


def _target(state: CVBatch, out: CVBatch | None) -> CVBatch:
    """The batch to write into: ``out`` (preallocated, must not alias ``state``) or a new one.

    Passing ``out`` matters for speed: a fresh 10⁴-run batch is megabytes of untouched pages,
    and faulting them in costs more than the arithmetic. Loops ping-pong between two batches.
    """
    if out is None:
        return empty_batch(state.runs)
    if out.x.shape != state.x.shape or np.shares_memory(out.P, state.P):
        raise ValueError("out must be a separate batch with the same number of runs")
    return out


def cv_predict(
    state: CVBatch, period: float, sigma_a: float = 0.0, out: CVBatch | None = None
) -> CVBatch:
    """x⁻ = F x, P⁻ = F P Fᵀ + Q for every run.  Returns ``out`` or a new batch."""
    T = float(period)
    x, P = state.x, state.P
    out = _target(state, out)
    ox, oP = out.x, out.P
    T2 = T * T
    tmp = np.empty(state.runs)
    # Same explicit-buffer style as the update (see joseph_update_position).
    for p, v in ((0, 1), (2, 3)):
        # Within-axis block: [p, v] -> [p + T v, v].
        np.multiply(x[:, v], T, out=ox[:, p])
        ox[:, p] += x[:, p]
        ox[:, v] = x[:, v]
        ppv, pvv = P[:, p, v], P[:, v, v]
        d = oP[:, p, p]
        np.multiply(ppv, 2.0 * T, out=d)
        d += P[:, p, p]
        np.multiply(pvv, T2, out=tmp)
        d += tmp
        d = oP[:, p, v]
        np.multiply(pvv, T, out=d)
        d += ppv
        oP[:, v, v] = pvv
    # Cross-axis block.
    p13 = P[:, 1, 3]
    d = oP[:, 0, 2]
    np.add(P[:, 1, 2], P[:, 0, 3], out=d)
    d *= T
    d += P[:, 0, 2]
    np.multiply(p13, T2, out=tmp)
    d += tmp
    np.multiply(p13, T, out=oP[:, 0, 3])
    oP[:, 0, 3] += P[:, 0, 3]
    np.multiply(p13, T, out=oP[:, 1, 2])
    oP[:, 1, 2] += P[:, 1, 2]
    oP[:, 1, 3] = p13
    if sigma_a:
        q = sigma_a**2
        for p, v in ((0, 1), (2, 3)):
            oP[:, p, p] += q * T2 * T2 / 4.0
            oP[:, p, v] += q * T2 * T / 2.0
            oP[:, v, v] += q * T2
    _mirror(oP)
    return out


def _mirror(P: NDArray[np.float64]) -> None:
    """Copy the upper triangle of (M, 4, 4) into the lower one."""
    for i, j in _UPPER4:
        if i != j:
            P[:, j, i] = P[:, i, j]


def joseph_update_position(
    state: CVBatch,
    innovation: tuple[Vec, Vec],
    K: NDArray[np.float64],
    S: tuple[Vec, Vec, Vec],
    out: CVBatch | None = None,
) -> CVBatch:
    """Joseph-form update for a position measurement (H = H2), any gain K.

        x⁺ = x + K ν
        P⁺ = (I − K H2) P (I − K H2)ᵀ + K R Kᵀ,            S = H2 P H2ᵀ + R
           = P − K Uᵀ + (K S − U) Kᵀ,                       U = P H2ᵀ  (columns 0 and 2 of P)

    The second line is the Joseph form multiplied out: an identity for *any* gain K, so an
    error δK in the gain changes P only at second order (the reason to prefer Joseph over
    P − K H P); the term K S − U vanishes for the optimal gain up to rounding. It costs about
    half the vector operations of forming (I − K H2) P first. ``K`` is the (4, 2, M)
    component-major gain, ``innovation`` the two (M,) components of ν, ``S`` the (M,) entries
    (s00, s01, s11). A polar EKF uses this too, after mapping its innovation and R to position
    (see ``core.filters.polar.ekf_update``).
    """
    # Written with explicit output buffers (``out=``, in-place operators): each line is one
    # pass over M floats with no temporary to allocate and copy, which matters more than the
    # arithmetic at these sizes (1.5× faster than the same formulas as plain expressions).
    x, P = state.x, state.P
    out = _target(state, out)
    nu0, nu1 = innovation
    tmp = np.empty(state.runs)
    K0 = [K[i, 0] for i in range(4)]
    K1 = [K[i, 1] for i in range(4)]
    for i in range(4):
        d = out.x[:, i]
        np.multiply(K0[i], nu0, out=d)
        d += x[:, i]
        np.multiply(K1[i], nu1, out=tmp)
        d += tmp
    s00, s01, s11 = S
    U0 = [P[:, i, 0] for i in range(4)]
    U1 = [P[:, i, 2] for i in range(4)]
    # V = K S − U, row by row.
    V0, V1 = [], []
    for i in range(4):
        v0 = K0[i] * s00
        np.multiply(K1[i], s01, out=tmp)
        v0 += tmp
        v0 -= U0[i]
        v1 = K0[i] * s01
        np.multiply(K1[i], s11, out=tmp)
        v1 += tmp
        v1 -= U1[i]
        V0.append(v0)
        V1.append(v1)
    oP = out.P
    for i, j in _UPPER4:
        # P⁺[i, j] = P[i, j] − K[i]·U[j] + V[i]·K[j]
        d = oP[:, i, j]
        np.multiply(K0[i], U0[j], out=d)
        np.subtract(P[:, i, j], d, out=d)
        np.multiply(K1[i], U1[j], out=tmp)
        d -= tmp
        np.multiply(V0[i], K0[j], out=tmp)
        d += tmp
        np.multiply(V1[i], K1[j], out=tmp)
        d += tmp
    _mirror(oP)
    return out


def cv_update(state: CVBatch, z: ArrayLike, R: ArrayLike, out: CVBatch | None = None) -> CVBatch:
    """Kalman update of every run with a Cartesian position z (M, 2), covariance R (M, 2, 2)."""
    z = np.asarray(z, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    return cv_update_parts(state, z[:, 0], z[:, 1], R[:, 0, 0], R[:, 0, 1], R[:, 1, 1], out)


def cv_update_parts(
    state: CVBatch,
    zx: Vec,
    zy: Vec,
    r00: Vec,
    r01: Vec,
    r11: Vec,
    out: CVBatch | None = None,
) -> CVBatch:
    """``cv_update`` with z and R given as their (M,) components (the Monte Carlo fast path).

    S = H2 P H2ᵀ + R,   K = P H2ᵀ S⁻¹   (2 × 2 inverse written out),   then Joseph.
    """
    P = state.P
    s00 = P[:, 0, 0] + r00
    s01 = P[:, 0, 2] + r01
    s11 = P[:, 2, 2] + r11
    inv_det = 1.0 / (s00 * s11 - s01 * s01)
    i00, i01, i11 = s11 * inv_det, -s01 * inv_det, s00 * inv_det
    K = np.empty((4, 2, state.runs))
    tmp = np.empty(state.runs)
    for i in range(4):
        u0, u1 = P[:, i, 0], P[:, i, 2]
        np.multiply(u0, i00, out=K[i, 0])
        np.multiply(u1, i01, out=tmp)
        K[i, 0] += tmp
        np.multiply(u0, i01, out=K[i, 1])
        np.multiply(u1, i11, out=tmp)
        K[i, 1] += tmp
    nu = (zx - state.x[:, 0], zy - state.x[:, 2])
    return joseph_update_position(state, nu, K, (s00, s01, s11), out)


def quad_form_inv(P: NDArray[np.float64], e: NDArray[np.float64]) -> NDArray[np.float64]:
    """eᵀ P⁻¹ e for a batch: P (M, n, n) symmetric positive definite, e (M, n) → (M,).

    Cholesky factorisation written out over the batch (n is 2 or 4 here), so it costs a few
    dozen vector operations rather than M LAPACK calls.
    """
    n = e.shape[-1]
    Lc: dict[tuple[int, int], Vec] = {}
    y: list[Vec] = []
    total = np.zeros(e.shape[0])
    for i in range(n):
        for j in range(i + 1):
            acc = P[:, i, j].copy()
            for k in range(j):
                acc -= Lc[i, k] * Lc[j, k]
            if i == j:
                Lc[i, i] = np.sqrt(acc)
            else:
                Lc[i, j] = acc / Lc[j, j]
        yi = e[:, i].copy()
        for k in range(i):
            yi -= Lc[i, k] * y[k]
        yi /= Lc[i, i]
        y.append(yi)
        total += yi * yi
    return total
