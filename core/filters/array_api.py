"""The 2D Monte Carlo filters written against the Python array API standard: the GPU path.

The numpy engine writes into preallocated buffers (``out=``) and the compiled kernel is
scalar CPU code; neither runs on a GPU. This module evaluates the same equations with only
array-API operations on whole batches, every state component a (m,) array (the numpy
engine's component-major layout), each operation returning a new array. So it runs on any
namespace that implements the standard: numpy, CuPy (NVIDIA GPUs), PyTorch or JAX through
``array_api_compat``, and ``array_api_strict`` (which the tests use to prove nothing outside
the standard is called).

Every method: the five conversions (``core.conversion.planar``), the polar EKF
(``core.filters.polar_ekf``) and UKF (``core.filters.polar_ukf``), each optionally followed by
the Doppler update (``core.filters.doppler``). ``tests/test_array_api.py`` holds it to the
numpy engine to 1e-9 under ``array_api_strict``. ``radarviz bench --device gpu`` times it on
CuPy when a GPU is present.

The scalar coefficients that depend only on σr, σβ (e^(−s), eq. 11's hyperbolic terms, …)
are Python floats, formed once per call; per scan a method costs a few dozen array
operations, so a GPU pays off from about 10⁵ runs.
"""

from __future__ import annotations

import math
from typing import Any

from radarviz.core.conversion.elementwise import DUCM, conversion_coefficients, converted_point
from radarviz.core.filters.codes import EKF, METHOD_CODES, START_CODES, UKF
from radarviz.core.filters.compiled import FilterSettings
from radarviz.core.filters.polar_ukf import SEMIDEFINITE_RTOL
from radarviz.core.filters.predict import predict_2d, white_acceleration
from radarviz.core.filters.state import UPPER_2D

Array = Any  # an array of the caller's namespace
_TWO_PI = 2.0 * math.pi


def _wrap(xp: Any, a: Array) -> Array:
    """``core.geometry.wrap_angle``: a − 2π ceil(a/(2π) − ½), to (−π, π]."""
    return a - _TWO_PI * xp.ceil(a * (1.0 / _TWO_PI) - 0.5)


def _convert(xp: Any, code: int, r, b, sr2: float, s: float, co, px=None, py=None):
    """The five 2D conversions: (x, y, R00, R01, R11), radar-centred
    (``core.conversion.elementwise.converted_point``; (px, py) the prediction, for ducm)."""
    rp = cp = sp = None
    if code == DUCM:
        rp = xp.hypot(px, py)
        cp, sp = px / rp, py / rp
    return converted_point(code, r, xp.cos(b), xp.sin(b), sr2, s, co, rp, cp, sp)


def _predict(x: list, P: dict, T: float, q: float) -> tuple[list, dict]:
    """x⁻ = F x, P⁻ = F P Fᵀ + Q (``core.filters.predict.predict_2d``); P as its upper
    entries."""
    xn, pn = predict_2d(tuple(x), tuple(P[k] for k in UPPER_2D), T, white_acceleration(T, q))
    return list(xn), dict(zip(UPPER_2D, pn, strict=True))


def _sym(P: dict, i: int, j: int):
    return P[(i, j) if i <= j else (j, i)]


def _cholesky(xp: Any, P: dict, c: float, null_negative: bool = False) -> dict:
    """The lower Cholesky factor of c·P, semi-definite (``core.filters.state.
    semidefinite_cholesky``, with its ``null_negative``): entries (i, k), i >= k."""
    L = {}
    for j in range(4):
        d = c * P[j, j]
        for k in range(j):
            d = d - L[j, k] * L[j, k]
        tol = SEMIDEFINITE_RTOL * c * P[j, j]
        null = d <= 0.0  # a pivot above 0 is a variance, however small
        if not null_negative:
            null = null & (d >= -tol)
        d = xp.where(null, 0.0, xp.where(d < -tol, xp.nan, d))
        L[j, j] = xp.sqrt(d)
        for i in range(j + 1, 4):
            e = c * _sym(P, i, j)
            for k in range(j):
                e = e - L[i, k] * L[j, k]
            L[i, j] = xp.where(null, 0.0, e / xp.where(null, 1.0, L[j, j]))
    return L


def _joseph(xp: Any, x: list, P: dict, h: list, nu: list, R: dict) -> tuple[list, dict]:
    """x⁺ = x + K ν and the Joseph form on P's Cholesky factor L, P⁺ = Z Zᵀ + K R Kᵀ with
    Z = L − K (H L) (``core.filters.state.factored_joseph``), for a measurement H = rows ``h``
    of weighted state indexes, noise R (upper entries): the position update of
    ``core.filters.position`` (d = 2) and Doppler's scalar one (d = 1) alike."""
    d = len(h)
    U = [[sum(_sym(P, i, k) * w for k, w in h[a]) for a in range(d)] for i in range(4)]
    S = {}
    for a in range(d):
        for b in range(a, d):
            S[a, b] = sum(U[k][b] * w for k, w in h[a]) + R[a, b]
    if d == 1:
        inv = {(0, 0): 1.0 / S[0, 0]}
    else:
        det = S[0, 0] * S[1, 1] - S[0, 1] * S[0, 1]
        inv = {(0, 0): S[1, 1] / det, (0, 1): -S[0, 1] / det, (1, 1): S[0, 0] / det}
    K = [[sum(U[i][c] * _sym(inv, c, a) for c in range(d)) for a in range(d)] for i in range(4)]
    x_new = [x[i] + sum(K[i][a] * nu[a] for a in range(d)) for i in range(4)]
    L = _cholesky(xp, P, 1.0, True)
    HL = [[sum(L[i, k] * w for i, w in h[a] if i >= k) for k in range(4)] for a in range(d)]
    Z = [
        [(L[i, k] if i >= k else 0.0) - sum(K[i][a] * HL[a][k] for a in range(d)) for k in range(4)]
        for i in range(4)
    ]
    P_new = {}
    for i in range(4):
        for j in range(i, 4):
            krk = sum(K[i][a] * _sym(R, a, b) * K[j][b] for a in range(d) for b in range(d))
            P_new[i, j] = krk + sum(Z[i][k] * Z[j][k] for k in range(4))
    return x_new, P_new


_POSITION = [[(0, 1.0)], [(2, 1.0)]]  # H_pos: x and y picked out of (x, ẋ, y, ẏ)


def _ukf(xp, x, P, r, b, vr, vb, sx, sy, prm):
    """``core.filters.polar_ukf.ukf_update`` on components."""
    c, wm0, wc0, w = prm
    L = _cholesky(xp, P, c)
    px, py = x[0] - sx, x[2] - sy
    r0, b0 = xp.hypot(px, py), xp.atan2(py, px)
    pts = []  # (range, bearing) of +column k, −column k; columns touching x or y only
    for k in range(4):
        for f in (1.0, -1.0):
            qx = px + f * L[0, k] if k == 0 else px
            qy = py + f * L[2, k] if k <= 2 else py
            pts.append((xp.hypot(qx, qy), xp.atan2(qy, qx)))
    zr = wm0 * r0
    acc = 0.0
    for pr, pb in pts:
        zr = zr + w * pr
        acc = acc + _wrap(xp, pb - b0)
    zb = _wrap(xp, b0 + w * acc)
    d0 = (r0 - zr, _wrap(xp, b0 - zb))
    ds = [(pr - zr, _wrap(xp, pb - zb)) for pr, pb in pts]
    S = {(a, bb): wc0 * d0[a] * d0[bb] for a in range(2) for bb in range(a, 2)}
    for dd in ds:
        for a in range(2):
            for bb in range(a, 2):
                S[a, bb] = S[a, bb] + w * dd[a] * dd[bb]
    S[0, 0] = S[0, 0] + vr
    S[1, 1] = S[1, 1] + vb
    det = S[0, 0] * S[1, 1] - S[0, 1] * S[0, 1]
    i00, i01, i11 = S[1, 1] / det, -S[0, 1] / det, S[0, 0] / det
    K = []
    for i in range(4):
        a0 = 0.0
        a1 = 0.0
        for k in range(min(i, 3) + 1):
            lk = L[i, k]
            a0 = a0 + lk * (ds[2 * k][0] - ds[2 * k + 1][0])
            a1 = a1 + lk * (ds[2 * k][1] - ds[2 * k + 1][1])
        a0, a1 = a0 * w, a1 * w
        K.append((a0 * i00 + a1 * i01, a0 * i01 + a1 * i11))
    nr, nb = r - zr, _wrap(xp, b - zb)
    x_new = [x[i] + K[i][0] * nr + K[i][1] * nb for i in range(4)]
    # P⁺ in Joseph form: Σ_p Wc_p e_p e_pᵀ + K R Kᵀ, e_p = (χ_p − x⁻) − K d_p.
    e0 = [K[i][0] * d0[0] + K[i][1] * d0[1] for i in range(4)]
    P_new = {
        (i, j): wc0 * e0[i] * e0[j] + vr * K[i][0] * K[j][0] + vb * K[i][1] * K[j][1]
        for i in range(4)
        for j in range(i, 4)
    }
    for k in range(4):
        for sgn, f in ((0, 1.0), (1, -1.0)):
            dd = ds[2 * k + sgn]
            e = [
                (f * L[i, k] if i >= k else 0.0) - (K[i][0] * dd[0] + K[i][1] * dd[1])
                for i in range(4)
            ]
            for i in range(4):
                for j in range(i, 4):
                    P_new[i, j] = P_new[i, j] + w * e[i] * e[j]
    return x_new, P_new


def filter_history_xp(
    method: str,
    r_hat: Array,
    beta_hat: Array,
    settings: FilterSettings,
    *,
    radial_velocity_mps: Array | None = None,
    xp: Any = None,
) -> tuple[Array, Array]:
    """Every scan's states of m runs: x (N, m, 4) and P (N, m, 4, 4) in ``xp``'s arrays.

    Args:
        method: one of ``core.filters.compiled.COMPILED_METHODS``.
        r_hat, beta_hat: (m, N) measured ranges (m) and azimuths (rad), arrays of ``xp``.
        settings: the shared scalars (``core.filters.compiled.FilterSettings``).
        radial_velocity_mps: (m, N) measured V̂r: the Doppler update after each plot's.
        xp: the array namespace (default: ``array_api_compat.array_namespace(r_hat)``).
    """
    if xp is None:
        from array_api_compat import array_namespace

        xp = array_namespace(r_hat)
    s_ = settings
    code, start_code = METHOD_CODES[method], START_CODES[method]
    sr2, s = s_.sigma_r_m**2, s_.sigma_beta_rad**2
    co = conversion_coefficients(code, s, sr2)
    co_start = conversion_coefficients(start_code, s, sr2)
    sx, sy = s_.site_m
    T, q = s_.period_s, s_.sigma_a_mps2**2
    prm = s_.ukf.weights(4)
    steps = r_hat.shape[1]
    zx, zy, r00, r01, r11 = _convert(xp, start_code, r_hat[:, 0], beta_hat[:, 0], sr2, s, co_start)
    zero = xp.zeros_like(zx)
    x = [zx + sx, zero, zy + sy, zero]
    P = {(i, j): zero for i in range(4) for j in range(i, 4)}
    P[0, 0], P[0, 2], P[2, 2] = r00, r01, r11
    P[1, 1] = P[3, 3] = zero + s_.sigma_v0_mps**2
    xs, Ps = [x], [P]
    for n in range(1, steps):
        r, b = r_hat[:, n], beta_hat[:, n]
        x, P = _predict(x, P, T, q)
        if code == EKF:  # ekf: ν' = J ν, R' = J R Jᵀ at the prediction, then the position update
            px, py = x[0] - sx, x[2] - sy
            rp = xp.hypot(px, py)
            cos_b, sin_b = px / rp, py / rp
            nr, nb = r - rp, _wrap(xp, b - xp.atan2(py, px))
            nu = [cos_b * nr - py * nb, sin_b * nr + px * nb]
            vb = s
            R = {
                (0, 0): cos_b * cos_b * sr2 + py * py * vb,
                (0, 1): cos_b * sin_b * sr2 - px * py * vb,
                (1, 1): sin_b * sin_b * sr2 + px * px * vb,
            }
            x, P = _joseph(xp, x, P, _POSITION, nu, R)
        elif code == UKF:
            x, P = _ukf(xp, x, P, r, b, sr2, s, sx, sy, prm)
        else:
            zx, zy, r00, r01, r11 = _convert(xp, code, r, b, sr2, s, co, x[0] - sx, x[2] - sy)
            nu = [zx + sx - x[0], zy + sy - x[2]]
            x, P = _joseph(xp, x, P, _POSITION, nu, {(0, 0): r00, (0, 1): r01, (1, 1): r11})
        if radial_velocity_mps is not None:
            u0, u1 = xp.cos(b), xp.sin(b)
            gv = -u1 * x[1] + u0 * x[3]
            gpg = u1 * u1 * P[1, 1] + u0 * u0 * P[3, 3] - 2.0 * u0 * u1 * P[1, 3]
            r_e = s_.sigma_vr_mps**2 + s * (gv * gv + gpg)
            nu = [radial_velocity_mps[:, n] - (u0 * x[1] + u1 * x[3])]
            x, P = _joseph(xp, x, P, [[(1, u0), (3, u1)]], nu, {(0, 0): r_e})
        xs.append(x)
        Ps.append(P)
    x_out = xp.stack([xp.stack(v, axis=-1) for v in xs])
    rows = [
        xp.stack([xp.stack([_sym(Pn, i, j) for j in range(4)], axis=-1) for i in range(4)], axis=-2)
        for Pn in Ps
    ]
    return x_out, xp.stack(rows)
