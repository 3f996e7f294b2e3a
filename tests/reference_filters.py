"""Reference filters for the tests: the textbook matrix form, compiled, one track at a time.

Each is written from the equations, not from the engine: the polar EKF with the polar
Jacobian H (not the engine's change of variables), the Joseph form as (I − KH) P (I − KH)ᵀ +
K R Kᵀ, the UKF with LAPACK's Cholesky and all nine points. So they are an
independent route to the engine's numbers (``tests/test_compiled.py``). Plain Python and
numpy, one track at a time: slow, and meant for a few tracks.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

#: The reference of each kind, by the engine's method it mirrors.
REFERENCE_METHODS: tuple[str, ...] = ("ucm", "ekf", "ukf", "ekf+doppler")


def kernels() -> dict[str, Callable[..., None]]:
    """The references, by ``REFERENCE_METHODS`` name (plain Python and numpy, one track at a
    time: a few tracks are enough for a check)."""

    def jit(f):
        return f

    @jit
    def predict(x, P, T):
        x[0] += T * x[1]
        x[2] += T * x[3]
        for j in range(4):
            P[0, j] += T * P[1, j]
            P[2, j] += T * P[3, j]
        for i in range(4):
            P[i, 0] += T * P[i, 1]
            P[i, 2] += T * P[i, 3]

    @jit
    def update(x, P, H, nu, R, d):
        # Kalman update with H (d × 4), ν (d), R (d × d); Joseph form (I − KH) P (I − KH)ᵀ + KRKᵀ.
        S = H[:d] @ P @ H[:d].T + R[:d, :d]
        K = P @ H[:d].T @ np.linalg.inv(S)
        x += K @ nu[:d]
        A = np.eye(4) - K @ H[:d]
        P[:, :] = A @ P @ A.T + K @ R[:d, :d] @ K.T

    @jit
    def start(x, P, zx, zy, R, v0):
        x[:] = 0.0
        P[:, :] = 0.0
        x[0], x[2] = zx, zy
        P[0, 0], P[0, 2], P[2, 0], P[2, 2] = R[0, 0], R[0, 1], R[0, 1], R[1, 1]
        P[1, 1] = P[3, 3] = v0 * v0

    @jit
    def ucm(r_hat, b_hat, sr, sigma_beta_rad, T, v0, out):
        s = sigma_beta_rad * sigma_beta_rad
        es = math.exp(s)
        x, P, H, R, nu = (
            np.empty(4),
            np.empty((4, 4)),
            np.zeros((2, 4)),
            np.empty((2, 2)),
            np.empty(2),
        )
        H[0, 0] = H[1, 2] = 1.0
        for m in range(r_hat.shape[0]):
            for n in range(r_hat.shape[1]):
                r, b = r_hat[m, n], b_hat[m, n]
                c, sn = math.cos(b), math.sin(b)
                # Mo et al.: point e^(s/2) r̂ u(β̂); covariance e^s Cov(naive | r̂, β̂)
                a = 0.5 * es * (sr * sr * (1 + math.exp(-2 * s)) + r * r * (1 - math.exp(-s)) ** 2)
                bb = 0.5 * es * (sr * sr + r * r) * (1 - math.exp(-2 * s))
                cc = es * (sr * sr * math.exp(-2 * s) - r * r * math.exp(-s) * (1 - math.exp(-s)))
                R[0, 0], R[1, 1] = c * c * a + sn * sn * bb, sn * sn * a + c * c * bb
                R[0, 1] = R[1, 0] = sn * c * cc
                zx, zy = math.sqrt(es) * r * c, math.sqrt(es) * r * sn
                if n == 0:
                    start(x, P, zx, zy, R, v0)
                    continue
                predict(x, P, T)
                nu[0], nu[1] = zx - x[0], zy - x[2]
                update(x, P, H, nu, R, 2)
            out[m] = x

    @jit
    def ekf_step(x, P, r, b, sr, sigma_beta_rad, H, R, nu):
        px, py = x[0], x[2]
        rp = math.hypot(px, py)
        H[:, :] = 0.0
        H[0, 0], H[0, 2] = px / rp, py / rp
        H[1, 0], H[1, 2] = -py / (rp * rp), px / (rp * rp)
        R[:, :] = 0.0
        R[0, 0], R[1, 1] = sr * sr, sigma_beta_rad * sigma_beta_rad
        nu[0] = r - rp
        d = b - math.atan2(py, px)
        nu[1] = d - 2 * math.pi * math.floor((d + math.pi) / (2 * math.pi))
        update(x, P, H, nu, R, 2)

    @jit
    def naive_start(x, P, r, b, sr, sigma_beta_rad, v0, R):
        c, sn = math.cos(b), math.sin(b)
        rs = r * r * sigma_beta_rad * sigma_beta_rad
        R[0, 0], R[1, 1] = sr * sr * c * c + rs * sn * sn, sr * sr * sn * sn + rs * c * c
        R[0, 1] = R[1, 0] = (sr * sr - rs) * sn * c
        start(x, P, r * c, r * sn, R, v0)

    @jit
    def ekf(r_hat, b_hat, vr_hat, sr, sigma_beta_rad, svr, T, v0, doppler, out):
        x, P, H, R, nu = (
            np.empty(4),
            np.empty((4, 4)),
            np.zeros((2, 4)),
            np.zeros((2, 2)),
            np.empty(2),
        )
        for m in range(r_hat.shape[0]):
            for n in range(r_hat.shape[1]):
                r, b = r_hat[m, n], b_hat[m, n]
                if n == 0:
                    naive_start(x, P, r, b, sr, sigma_beta_rad, v0, R)
                    continue
                predict(x, P, T)
                ekf_step(x, P, r, b, sr, sigma_beta_rad, H, R, nu)
                if doppler:
                    # V̂r along the measured line of sight; angle error inflates its variance
                    c, sn = math.cos(b), math.sin(b)
                    H[:, :] = 0.0
                    H[0, 1], H[0, 3] = c, sn
                    gv = -sn * x[1] + c * x[3]
                    gpg = sn * sn * P[1, 1] + c * c * P[3, 3] - 2 * sn * c * P[1, 3]
                    R[0, 0] = svr * svr + sigma_beta_rad * sigma_beta_rad * (gv * gv + gpg)
                    nu[0] = vr_hat[m, n] - (c * x[1] + sn * x[3])
                    update(x, P, H, nu, R, 1)
            out[m] = x

    @jit
    def ukf(r_hat, b_hat, sr, sigma_beta_rad, T, v0, out):
        # Van der Merwe points with α = 1, β = 2, κ = 0: ±√4 · Cholesky columns, W = 1/8, Wc₀ = 2
        x, P, R = np.empty(4), np.empty((4, 4)), np.zeros((2, 2))
        chi, zeta = np.empty((9, 4)), np.empty((9, 2))
        wm = np.full(9, 0.125)
        wm[0] = 0.0
        wc = wm.copy()
        wc[0] = 2.0
        for m in range(r_hat.shape[0]):
            for n in range(r_hat.shape[1]):
                r, b = r_hat[m, n], b_hat[m, n]
                if n == 0:
                    naive_start(x, P, r, b, sr, sigma_beta_rad, v0, R)
                    continue
                predict(x, P, T)
                L = np.linalg.cholesky(4.0 * P)
                chi[0] = x
                for k in range(4):
                    chi[1 + k] = x + L[:, k]
                    chi[5 + k] = x - L[:, k]
                for p in range(9):
                    zeta[p, 0] = math.hypot(chi[p, 0], chi[p, 2])
                    zeta[p, 1] = math.atan2(chi[p, 2], chi[p, 0])
                b0 = zeta[0, 1]
                for p in range(9):  # bearings relative to the central point's
                    d = zeta[p, 1] - b0
                    zeta[p, 1] = b0 + d - 2 * math.pi * math.floor((d + math.pi) / (2 * math.pi))
                zm = wm @ zeta
                dz = zeta - zm
                dx = chi - x
                S = (dz.T * wc) @ dz
                S[0, 0] += sr * sr
                S[1, 1] += sigma_beta_rad * sigma_beta_rad
                K = ((dx.T * wc) @ dz) @ np.linalg.inv(S)
                nu = np.array([r - zm[0], b - zm[1]])
                nu[1] -= 2 * math.pi * math.floor((nu[1] + math.pi) / (2 * math.pi))
                x += K @ nu
                P[:, :] = P - K @ S @ K.T
            out[m] = x

    return {"ucm": ucm, "ekf": ekf, "ukf": ukf}


def reference_final_states(
    kind: str,
    r_hat: NDArray[np.float64],
    b_hat: NDArray[np.float64],
    *,
    sigma_r_m: float,
    sigma_beta_rad: float,
    period_s: float,
    sigma_v0_mps: float,
    radial_velocity_mps: NDArray[np.float64] | None = None,
    sigma_vr_mps: float = 1.0,
) -> NDArray[np.float64]:
    """(m, 4) final states of a ``REFERENCE_METHODS`` filter over (m, N) measurements (Q = 0,
    radar at the origin)."""
    k = kernels()
    out = np.empty((r_hat.shape[0], 4))
    r, b = np.ascontiguousarray(r_hat), np.ascontiguousarray(b_hat)
    sr, T, v0 = sigma_r_m, period_s, sigma_v0_mps
    if kind == "ucm":
        k["ucm"](r, b, sr, sigma_beta_rad, T, v0, out)
    elif kind == "ukf":
        k["ukf"](r, b, sr, sigma_beta_rad, T, v0, out)
    else:
        doppler = kind == "ekf+doppler"
        vr = np.ascontiguousarray(radial_velocity_mps) if doppler else np.zeros((1, 1))
        k["ekf"](r, b, vr, sr, sigma_beta_rad, sigma_vr_mps, T, v0, doppler, out)
    return out
