"""The joint EKF + line-of-sight Doppler update (core.filters.joint_doppler): the covariance of
the angle errors with the Doppler error by Monte Carlo, and the update against filterpy's
KalmanFilter on the polar measurement (r̂, β̂[, ε̂], V̂r) linearised at the prediction."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from radarviz.core.filters.doppler import doppler_tilt_covariance
from radarviz.core.filters.joint_doppler import joint_doppler_update
from radarviz.core.filters.state import CVBatch
from radarviz.core.geometry import direction_cosines, polar_coordinates

Z = 4.0  # standard errors allowed


@pytest.mark.parametrize("dims", [2, 3])
def test_angle_error_and_doppler_error_covariance_by_monte_carlo(dims: int) -> None:
    """Cov(δβ, e) and Cov(δε, e) of e = V̂r − u(β̂, ε̂)·v, against the first-order
    −(g·v)σ² (at the true velocity), within 4 standard errors plus the known second-order
    gap: the exact value is −(g·v) σ² e^(−σ²/2) (E[x sin x] for x ~ N(0, σ²))."""
    rng = np.random.default_rng(7)
    m = 400_000
    p = np.array([80e3, 60e3, 20e3])[:dims]
    v = np.array([-200.0, 100.0, 30.0])[:dims]
    sigma_beta_rad, se, sv = np.deg2rad(1.0), np.deg2rad(0.7 if dims == 3 else 0.0), 1.0
    r, beta, *el = polar_coordinates(list(p))
    eps = el[0] if dims == 3 else 0.0
    db = sigma_beta_rad * rng.standard_normal(m)
    de = se * rng.standard_normal(m)
    u_hat = direction_cosines(beta + db, eps + de)[:, :dims]
    vr = float(np.dot(p, v) / r)
    e = vr + sv * rng.standard_normal(m) - u_hat @ v
    x = np.zeros(2 * dims)
    x[1::2] = v
    state = CVBatch(x[None], np.eye(2 * dims)[None])
    # Evaluated at the true angles (the first-order term is at the measured one, which
    # differs from it by one δ: averaged over the draws that is a higher-order effect).
    c_b, c_e = doppler_tilt_covariance(
        state, beta, eps, sigma_vr_mps=sv, sigma_beta_rad=sigma_beta_rad, sigma_elevation_rad=se
    )
    for delta, sigma, c in ((db, sigma_beta_rad, c_b[0]), (de, se, c_e[0])):
        if sigma == 0.0:
            assert c == 0.0
            continue
        prod = delta * (e - e.mean())
        got, se_got = prod.mean(), prod.std(ddof=1) / np.sqrt(m)
        exact = c * np.exp(-(sigma**2) / 2)
        assert abs(got - c) <= Z * se_got + abs(exact - c), (got, c, se_got)
        assert abs(c) > 10 * se_got  # the covariance is resolved, not zero


def _polar_reference(x, P, z, sr, sigma_beta_rad, se, sv, dims):
    """filterpy's KalmanFilter on (r̂, β̂[, ε̂], V̂r) with H the polar Jacobian at x and the
    line-of-sight row, R with the angle–Doppler covariance, z mapped to the linearised form."""
    n = 2 * dims
    pos, vel = list(range(0, n, 2)), list(range(1, n, 2))
    d = x[pos]
    r = np.linalg.norm(d)
    beta = np.arctan2(d[1], d[0])
    rows = [d / r, np.array([-d[1], d[0], 0.0][:dims]) / (d[0] ** 2 + d[1] ** 2)]
    h = [r, beta]
    if dims == 3:
        rho = np.hypot(d[0], d[1])
        rows.append(np.array([-d[2] * d[0], -d[2] * d[1], rho**2]) / (r * r * rho))
        h.append(np.arcsin(d[2] / r))
    b_hat, e_hat = z[1], (z[2] if dims == 3 else 0.0)
    u = np.array(direction_cosines(b_hat, e_hat))[:dims]
    g_b = np.array([-np.cos(e_hat) * np.sin(b_hat), np.cos(e_hat) * np.cos(b_hat), 0.0])[:dims]
    g_e = np.array([-np.sin(e_hat) * np.cos(b_hat), -np.sin(e_hat) * np.sin(b_hat), np.cos(e_hat)])[
        :dims
    ]
    v = x[vel]
    Pvv = P[np.ix_(vel, vel)]
    k = dims + 1
    H = np.zeros((k, n))
    for i, row in enumerate(rows):
        H[i, pos] = row
    H[dims, vel] = u
    R = np.zeros((k, k))
    R[0, 0], R[1, 1] = sr**2, sigma_beta_rad**2
    var_e = sv**2 + sigma_beta_rad**2 * ((g_b @ v) ** 2 + g_b @ Pvv @ g_b)
    R[1, dims] = R[dims, 1] = -(g_b @ v) * sigma_beta_rad**2
    if dims == 3:
        R[2, 2] = se**2
        var_e += se**2 * ((g_e @ v) ** 2 + g_e @ Pvv @ g_e)
        R[2, dims] = R[dims, 2] = -(g_e @ v) * se**2
    R[dims, dims] = var_e
    nu = np.empty(k)
    nu[:dims] = np.asarray(z[:dims]) - np.array(h)
    nu[dims] = z[dims] - u @ v
    f = KalmanFilter(dim_x=n, dim_z=k)
    f.x, f.P = x.copy(), P.copy()
    f.update(nu + H @ x, R=R, H=H)  # z − H x = ν: the linearised measurement
    return f.x, f.P


@pytest.mark.parametrize("dims", [2, 3])
def test_joint_update_equals_filterpy_on_the_polar_measurement(dims: int) -> None:
    """The joint update works in metres (ν' = J ν, R' = J R Jᵀ, the cross term through J);
    filterpy's update here works on the polar residuals with the polar Jacobian: the same
    Kalman update, to 1e-9 of the states' σ."""
    rng = np.random.default_rng(3)
    n = 2 * dims
    for _ in range(5):
        x = np.zeros(n)
        x[0::2] = np.array([80e3, 60e3, 15e3])[:dims] + rng.normal(0, 500, dims)
        x[1::2] = np.array([-200.0, 100.0, 20.0])[:dims] + rng.normal(0, 20, dims)
        a = rng.standard_normal((n, n))
        P = a @ a.T + np.diag(np.tile([4e5, 400.0], dims))
        sr, sigma_beta_rad, se, sv = 50.0, np.deg2rad(1.0), np.deg2rad(0.5), 1.0
        truth = x + rng.multivariate_normal(np.zeros(n), P)
        r, beta, *el = polar_coordinates(list(truth[0::2]))
        z = [r + sr * rng.standard_normal(), beta + sigma_beta_rad * rng.standard_normal()]
        if dims == 3:
            z.append(el[0] + se * rng.standard_normal())
        u = np.array(direction_cosines(beta, el[0] if dims == 3 else 0.0))[:dims]
        z.append(u @ truth[1::2] + sv * rng.standard_normal())
        got = joint_doppler_update(
            CVBatch(x[None], P[None]),
            [np.array([c]) for c in z[:dims]],
            np.array([z[dims]]),
            sigma_r_m=sr,
            sigma_beta_rad=sigma_beta_rad,
            sigma_elevation_rad=se if dims == 3 else 0.0,
            sigma_vr_mps=sv,
        )
        x_ref, P_ref = _polar_reference(
            x, P, z, sr, sigma_beta_rad, se if dims == 3 else 0.0, sv, dims
        )
        sd = np.sqrt(np.diag(P_ref))
        np.testing.assert_allclose((got.x[0] - x_ref) / sd, 0.0, atol=1e-9)
        np.testing.assert_allclose((got.P[0] - P_ref) / np.outer(sd, sd), 0.0, atol=1e-9)
