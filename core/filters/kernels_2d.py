"""The compiled (numba) kernel behind ``core.filters.compiled``: scalar code, one track at a
time, mirroring the numpy engine's equations line by line (see that module's table).

Imported only by ``core.filters.compiled._kernel`` on first use, so importing numba (and
loading the cached machine code) is paid only by commands that filter a Monte Carlo.
"""

from __future__ import annotations

import math
from math import atan2, ceil, cos, cosh, exp, expm1, hypot, sin, sinh, sqrt

import numba
import numpy as np

# A Cholesky pivot within this fraction of its diagonal is a direction of zero variance (a
# zero column); below it the track is NaN (numba reads it as a compile-time constant).
from radarviz.core.filters.polar_ukf import SEMIDEFINITE_RTOL

# error_model="numpy": a division by zero or a negative pivot gives inf / NaN for that track,
# as the numpy engine does, instead of raising. cache=True: compiled once per machine.
# nogil=True: blocks of runs filter in parallel threads (``core.experiments.prosov``).
_jit = numba.njit(cache=True, error_model="numpy", nogil=True)


_TWO_PI = 2.0 * math.pi


@_jit
def wrap(a: float) -> float:
    # core.geometry.wrap_angle: a − 2π ceil(a/(2π) − ½), to (−π, π]
    return a - _TWO_PI * ceil(a * (1.0 / _TWO_PI) - 0.5)


@_jit
def coefficients(code: int, s: float, sr2: float):
    """The scalars of a conversion that depend on s = σβ² and σr² only, formed once per block
    (they are most of a conversion's transcendental functions)."""
    co = np.zeros(8)
    if code == 1 or code == 2:
        # seed κ = 1 − s/2 (eq. 10 as printed); cmkf_d κ = 1 − (e^(−s) − e^(−s/2))
        co[0] = 1.0 - s / 2.0 if code == 1 else 1.0 - (exp(-s) - exp(-s / 2.0))
        # eq. 11: e^(−2s), cosh 2s − cosh s and sinh 2s − sinh s as products, 2 cosh 2s −
        # cosh s, 2 sinh 2s − sinh s, e^(−4s), e^s − 1 (core.conversion.planar._averaged_parts)
        sh_half = sinh(0.5 * s)
        co[1] = exp(-2.0 * s)
        co[2], co[3] = 2.0 * sinh(1.5 * s) * sh_half, 2.0 * cosh(1.5 * s) * sh_half
        co[4], co[5] = 2.0 * cosh(2.0 * s) - cosh(s), 2.0 * sinh(2.0 * s) - sinh(s)
        co[6], co[7] = exp(-4.0 * s), expm1(s)
    elif code == 3 or code == 4:
        # ucm / ducm: κ = e^(s/2); _true_cov_parts × e^s: A = a1 r² + a0, B = b1 (r² + σr²),
        # C = c1 r² + c0
        k = exp(s)
        e1, e2 = exp(-s), exp(-2.0 * s)
        om1, om2 = -expm1(-s), -expm1(-2.0 * s)
        co[0] = sqrt(k)
        co[1], co[2] = (0.5 * k) * om1 * om1, (0.5 * k) * sr2 * (1.0 + e2)
        co[3] = (0.5 * k) * om2
        co[4], co[5] = -k * e1 * om1, k * sr2 * e2
    return co


@_jit
def true_cov(r: float, c: float, sn: float, sr2: float, co):
    # core.conversion.planar._true_cov_parts: the exact true-conditioned covariance × e^s
    r2 = r * r
    a = r2 * co[1] + co[2]
    b = (r2 + sr2) * co[3]
    cc = r2 * co[4] + co[5]
    return c * c * a + sn * sn * b, cc * (sn * c), sn * sn * a + c * c * b


@_jit
def averaged_cov(r: float, c: float, sn: float, sr2: float, co):
    # core.conversion.planar._averaged_parts: Prosov eq. 11a–c at the measurement
    c2, s2 = c * c, sn * sn
    e2, a_c, a_s, b_c, b_s = co[1], co[2], co[3], co[4], co[5]
    r2 = r * r
    c11 = r2 * (e2 * (c2 * a_c + s2 * a_s)) + sr2 * e2 * (c2 * b_c + s2 * b_s)
    c22 = r2 * (e2 * (s2 * a_c + c2 * a_s)) + sr2 * e2 * (s2 * b_c + c2 * b_s)
    c12 = sn * c * co[6] * (sr2 - (r2 + sr2) * co[7])
    return c11, c12, c22


@_jit
def convert(code: int, r: float, b: float, sr2: float, s: float, px: float, py: float, co):
    # The five conversions of core.conversion.planar: point and covariance (radar-centred);
    # ``co``: ``coefficients(code, s, sr2)``.
    c, sn = cos(b), sin(b)
    if code == 0:  # naive: eq. 8, linearised covariance eq. 9
        rs = r * r * s
        return (
            r * c,
            r * sn,
            sr2 * c * c + rs * sn * sn,
            (sr2 - rs) * sn * c,
            (sr2 * sn * sn + rs * c * c),
        )
    kr = co[0] * r
    if code == 1 or code == 2:  # seed / cmkf_d, covariance eq. 11
        c11, c12, c22 = averaged_cov(r, c, sn, sr2, co)
    elif code == 3:  # ucm: exact covariance at the measurement
        c11, c12, c22 = true_cov(r, c, sn, sr2, co)
    else:  # ducm: the same covariance at the predicted position
        rp = hypot(px, py)
        c11, c12, c22 = true_cov(rp, px / rp, py / rp, sr2, co)
    return kr * c, kr * sn, c11, c12, c22


@_jit
def start(x, P, zx: float, zy: float, r00: float, r01: float, r11: float, v0: float):
    # cv_init: position z with covariance R, velocity 0 with variance σv0²
    for i in range(4):
        x[i] = 0.0
        for j in range(4):
            P[i, j] = 0.0
    x[0], x[2] = zx, zy
    P[0, 0], P[0, 2], P[2, 0], P[2, 2] = r00, r01, r01, r11
    P[1, 1] = P[3, 3] = v0 * v0


@_jit
def predict(x, P, T: float, q: float):
    # cv_predict: x⁻ = F x, P⁻ = F P Fᵀ + Q (per axis [[1, T], [0, 1]]; Q = σa² g gᵀ)
    x[0] += T * x[1]
    x[2] += T * x[3]
    for j in range(4):  # rows of F P
        P[0, j] += T * P[1, j]
        P[2, j] += T * P[3, j]
    for i in range(4):  # columns of (F P) Fᵀ
        P[i, 0] += T * P[i, 1]
        P[i, 2] += T * P[i, 3]
    if q != 0.0:
        T2 = T * T
        for p in (0, 2):
            P[p, p] += q * T2 * T2 / 4.0
            P[p, p + 1] += q * T2 * T / 2.0
            P[p + 1, p] += q * T2 * T / 2.0
            P[p + 1, p + 1] += q * T2


@_jit
def position_update(x, P, nx: float, ny: float, r00: float, r01: float, r11: float, K, V):
    # core.filters.position: S = H P Hᵀ + R, K = P Hᵀ S⁻¹, x⁺ = x + K ν,
    # P⁺ = P − K Uᵀ + (K S − U) Kᵀ with U = P Hᵀ (Joseph form multiplied out).
    s00, s01, s11 = P[0, 0] + r00, P[0, 2] + r01, P[2, 2] + r11
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    for i in range(4):
        u0, u1 = P[i, 0], P[i, 2]
        K[i, 0] = u0 * i00 + u1 * i01
        K[i, 1] = u0 * i01 + u1 * i11
    for i in range(4):
        V[i, 0] = K[i, 0] * s00 + K[i, 1] * s01 - P[i, 0]
        V[i, 1] = K[i, 0] * s01 + K[i, 1] * s11 - P[i, 2]
    for i in range(4):
        x[i] += K[i, 0] * nx + K[i, 1] * ny
    # U's columns are P's position columns: read them before P is overwritten.
    for i in range(4):
        for j in range(i, 4):
            V[j, 2] = P[j, 0]
            V[j, 3] = P[j, 2]
    for i in range(4):
        for j in range(i, 4):
            u0, u1 = V[j, 2], V[j, 3]
            P[i, j] = (
                P[i, j] - (K[i, 0] * u0 + K[i, 1] * u1) + (V[i, 0] * K[j, 0] + V[i, 1] * K[j, 1])
            )
    for i in range(4):
        for j in range(i):
            P[i, j] = P[j, i]


@_jit
def ukf_update(x, P, r, b, vr, vb, sx, sy, prm, L, Z, K, E):
    # core.filters.polar_ukf: sigma points of (x⁻, P⁻) through the polar map, unscented S and
    # Pxz, K = Pxz S⁻¹, x⁺ = x + K ν, and P⁺ in Joseph form, Σ_p Wc_p e_p e_pᵀ + K R Kᵀ with
    # e_p = (χ_p − x⁻) − K d_p (a sum of semi-definite terms: it cannot turn indefinite).
    c, wm0, wc0, w = prm[0], prm[1], prm[2], prm[3]
    for j in range(4):  # lower Cholesky factor of c·P, semi-definite (semidefinite_cholesky)
        d = c * P[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        tol = SEMIDEFINITE_RTOL * c * P[j, j]
        null = abs(d) <= tol
        if null:
            d = 0.0
        elif d < -tol:
            d = math.nan  # indefinite beyond rounding: this track becomes NaN
        d = sqrt(d)
        L[j, j] = d
        for i in range(j + 1, 4):
            e = c * P[i, j]
            for k in range(j):
                e -= L[i, k] * L[j, k]
            L[i, j] = 0.0 if null else e / d
        for i in range(j):
            L[i, j] = 0.0
    px, py = x[0] - sx, x[2] - sy
    r0, b0 = hypot(px, py), atan2(py, px)
    # Z[p] = (range, bearing) of point p: 0 central, 1 + 2k = +column k, 2 + 2k = −column k
    Z[0, 0], Z[0, 1] = r0, b0
    for k in range(4):
        for sgn in range(2):
            f = 1.0 if sgn == 0 else -1.0
            qx, qy = px + f * L[0, k], py + f * L[2, k]
            Z[1 + 2 * k + sgn, 0] = hypot(qx, qy)
            Z[1 + 2 * k + sgn, 1] = atan2(qy, qx)
    zr = wm0 * r0
    acc = 0.0
    for p in range(1, 9):
        zr += w * Z[p, 0]
        acc += wrap(Z[p, 1] - b0)
    zb = wrap(b0 + w * acc)
    s00, s01, s11 = vr, 0.0, vb
    for p in range(9):
        wp = wc0 if p == 0 else w
        dr, db = Z[p, 0] - zr, wrap(Z[p, 1] - zb)
        Z[p, 0], Z[p, 1] = dr, db
        s00 += wp * dr * dr
        s01 += wp * dr * db
        s11 += wp * db * db
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    nr, nb = r - zr, wrap(b - zb)
    for i in range(4):  # Pxz = W Σ_k L[:, k] (d_k+ − d_k−)ᵀ, then K = Pxz S⁻¹
        a0, a1 = 0.0, 0.0
        for k in range(4):
            a0 += L[i, k] * (Z[1 + 2 * k, 0] - Z[2 + 2 * k, 0])
            a1 += L[i, k] * (Z[1 + 2 * k, 1] - Z[2 + 2 * k, 1])
        a0 *= w
        a1 *= w
        K[i, 0] = a0 * i00 + a1 * i01
        K[i, 1] = a0 * i01 + a1 * i11
    for i in range(4):
        x[i] += K[i, 0] * nr + K[i, 1] * nb
    for i in range(4):  # the central point (e = −K d₀) and K R Kᵀ
        E[i] = K[i, 0] * Z[0, 0] + K[i, 1] * Z[0, 1]
    for i in range(4):
        for j in range(i, 4):
            P[i, j] = wc0 * E[i] * E[j] + vr * K[i, 0] * K[j, 0] + vb * K[i, 1] * K[j, 1]
    for k in range(4):  # the points ± column k: e = ±L[:, k] − K d
        for sgn in range(2):
            p, f = 1 + 2 * k + sgn, 1.0 if sgn == 0 else -1.0
            for i in range(4):
                E[i] = f * L[i, k] - (K[i, 0] * Z[p, 0] + K[i, 1] * Z[p, 1])
            for i in range(4):
                for j in range(i, 4):
                    P[i, j] += w * E[i] * E[j]
    for i in range(4):
        for j in range(i):
            P[i, j] = P[j, i]


@_jit
def doppler_update(x, P, vr_hat: float, b: float, var_vr: float, vb: float, K):
    # core.filters.doppler: V̂r = û·v + e along the measured line of sight û = (cos β̂, sin β̂),
    # var e = σVr² + σβ² ((g·v)² + gᵀ P_vv g), g = (−sin β̂, cos β̂); scalar Joseph form.
    u0, u1 = cos(b), sin(b)
    g0, g1 = -u1, u0
    gv = g0 * x[1] + g1 * x[3]
    gpg = g0 * g0 * P[1, 1] + g1 * g1 * P[3, 3] + 2.0 * g1 * g0 * P[3, 1]
    r_e = var_vr + vb * (gv * gv + gpg)
    for i in range(4):  # U = P hᵀ in column 2 of K, the gain in column 3
        K[i, 2] = P[i, 1] * u0 + P[i, 3] * u1
    S = u0 * K[1, 2] + u1 * K[3, 2] + r_e
    nu = vr_hat - (u0 * x[1] + u1 * x[3])
    for i in range(4):
        K[i, 3] = K[i, 2] * (1.0 / S)
        x[i] += K[i, 3] * nu
    for i in range(4):
        for j in range(i, 4):
            a = P[i, j] - K[i, 3] * K[j, 2] + (K[i, 3] * S - K[i, 2]) * K[j, 3]
            if i != j:
                a = 0.5 * (a + P[j, i] - K[j, 3] * K[i, 2] + (K[j, 3] * S - K[j, 2]) * K[i, 3])
            P[i, j] = a
    for i in range(4):
        for j in range(i):
            P[i, j] = P[j, i]


@_jit
def filter_scans_2d(
    code, start_code, r_scans, b_scans, vr_scans, doppler, first, last, sr, sb, svr, T, sa,
    v0, sx, sy, c, wm0, wc0, w, x_state, P_state, xs, Ps, n_terms, truth, cos_los, sin_los,
    terms,
):  # fmt: skip
    """Scans ``first … last − 1`` of every run; scan 0 starts a track from its plot (code
    ``start_code``), later scans continue from ``x_state``/``P_state`` (updated in place).

    Runs m < ``n_terms`` give their metric terms (``track_terms``) at each scan into
    terms[:, n − first, m] (truth, cos_los, sin_los indexed by scan); the others their states
    into xs[n − first, m − n_terms], Ps[…]."""
    sr2, s, vr, vb, q = sr * sr, sb * sb, sr * sr, sb * sb, sa * sa
    prm = np.array([c, wm0, wc0, w])
    co, co_start = coefficients(code, s, sr2), coefficients(start_code, s, sr2)
    K = np.empty((4, 4))
    L = np.empty((4, 4))
    Z = np.empty((9, 2))
    x, P = np.empty(4), np.empty((4, 4))  # one track's state, in and out of the batch arrays
    y, e, E = np.empty(4), np.empty(4), np.empty(4)
    runs = r_scans.shape[1]
    # Scan-major: at each scan the runs' states, measurements and outputs are walked in
    # memory order (run-major walks stride through every scan's rows: 3× slower).
    for n in range(first, last):
        for m in range(runs):
            r, b = r_scans[n, m], b_scans[n, m]
            if n == 0:
                zx, zy, r00, r01, r11 = convert(start_code, r, b, sr2, s, 0.0, 0.0, co_start)
                start(x, P, zx + sx, zy + sy, r00, r01, r11, v0)
            else:
                for a in range(4):
                    x[a] = x_state[m, a]
                    for b_ in range(4):
                        P[a, b_] = P_state[m, a, b_]
                predict(x, P, T, q)
                if code == 5:  # ekf: ν' = J ν and R' = J R Jᵀ at the prediction
                    px, py = x[0] - sx, x[2] - sy
                    rp = hypot(px, py)
                    cb, sb_ = px / rp, py / rp
                    nr, nb = r - rp, wrap(b - atan2(py, px))
                    position_update(
                        x,
                        P,
                        cb * nr - py * nb,
                        sb_ * nr + px * nb,
                        cb * cb * vr + py * py * vb,
                        cb * sb_ * vr - px * py * vb,
                        sb_ * sb_ * vr + px * px * vb,
                        K,
                        L,
                    )
                elif code == 6:
                    ukf_update(x, P, r, b, vr, vb, sx, sy, prm, L, Z, K, E)
                else:
                    px, py = x[0] - sx, x[2] - sy
                    zx, zy, r00, r01, r11 = convert(code, r, b, sr2, s, px, py, co)
                    position_update(x, P, zx + sx - x[0], zy + sy - x[2], r00, r01, r11, K, L)
                if doppler:
                    doppler_update(x, P, vr_scans[n, m], b, svr * svr, vb, K)
            for a in range(4):
                x_state[m, a] = x[a]
                for b_ in range(4):
                    P_state[m, a, b_] = P[a, b_]
            i = n - first
            if m < n_terms:
                track_terms(x, P, truth[n], cos_los[n, 0], sin_los[n, 0], terms, i, m, L, y, e)
            else:
                j = m - n_terms
                for a in range(4):
                    xs[i, j, a] = x[a]
                    for b_ in range(4):
                        Ps[i, j, a, b_] = P[a, b_]


@_jit
def track_terms(x, P, t, c, s, out, k, m, L, y, e):
    """The terms of one track at one scan into out[:, k, m] (``metric_terms_2d``): x (4,),
    P (4, 4), t the (4,) truth, (c, s) the true line of sight."""
    ex, ey = x[0] - t[0], x[2] - t[2]
    pxx, pyy, pxy = P[0, 0], P[2, 2], P[0, 2]
    out[0, k, m], out[1, k, m] = ex, ex * ex
    out[2, k, m], out[3, k, m] = ey, ey * ey
    out[4, k, m], out[5, k, m] = c * ex + s * ey, c * ey - s * ex
    out[6, k, m], out[7, k, m] = pxx, pyy
    out[8, k, m] = (pyy * ex * ex - 2.0 * pxy * ex * ey + pxx * ey * ey) / (pxx * pyy - pxy * pxy)
    for i in range(4):
        e[i] = x[i] - t[i]
    total = 0.0
    for i in range(4):  # eᵀ P⁻¹ e by the Cholesky factor (core.filters.state.quad_form_inv)
        for j in range(i + 1):
            acc = P[i, j]
            for q in range(j):
                acc -= L[i, q] * L[j, q]
            if i == j:
                L[i, i] = sqrt(acc) if acc >= 0.0 else np.nan
            else:
                L[i, j] = acc / L[j, j]
        yi = e[i]
        for q in range(i):
            yi -= L[i, q] * y[q]
        yi /= L[i, i]
        y[i] = yi
        total += yi * yi
    out[9, k, m] = total


@_jit
def metric_terms_2d(x, P, truth, cos_los, sin_los, out):
    """``core.metrics.scan_terms`` compiled: the per-run terms of the running sums, out
    (len(SUM_NAMES), K, m), of x (K, m, 4), P (K, m, 4, 4) against truth (K, 4), with the true
    line of sight cos_los, sin_los (K, 1). NEES by the Cholesky factor of P, as
    ``core.filters.state.quad_form_inv`` (NaN where P is not positive definite)."""
    L = np.empty((4, 4))
    y = np.empty(4)
    e = np.empty(4)
    for k in range(x.shape[0]):
        for m in range(x.shape[1]):
            track_terms(
                x[k, m], P[k, m], truth[k], cos_los[k, 0], sin_los[k, 0], out, k, m, L, y, e
            )
