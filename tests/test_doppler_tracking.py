"""Doppler-aided tracking: the finite-memory start and the Doppler updates."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

from radarviz.core.experiments.doppler_start import (
    DopplerTrackingConfig,
    doppler_los_update,
    doppler_target,
    ekf_doppler_update,
    finite_memory_start,
    polar_doppler_measurements,
    radial_velocity,
    run_doppler_tracking,
)
from radarviz.core.filters.cv import as_batch, cv_predict, transition_matrix
from radarviz.core.filters.polar import wrap_angle
from radarviz.core.finite_memory.fit import finite_memory_fit, preset
from radarviz.core.params import ParameterError

Z = 4.5  # Monte Carlo tolerance in standard errors (a dozen asserts: false alarm < 1e-4)


def _hx(x: np.ndarray) -> np.ndarray:
    r = np.hypot(x[0], x[2])
    return np.array([r, np.arctan2(x[2], x[0]), (x[0] * x[1] + x[2] * x[3]) / r])


def _jac(x: np.ndarray) -> np.ndarray:
    px, vx, py, vy = x
    r = np.hypot(px, py)
    vr = (px * vx + py * vy) / r
    return np.array(
        [
            [px / r, 0, py / r, 0],
            [-py / r**2, 0, px / r**2, 0],
            [(vx - vr * px / r) / r, px / r, (vy - vr * py / r) / r, py / r],
        ]
    )


def _residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = a - b
    d[1] = wrap_angle(d[1])
    return d


def test_joint_doppler_ekf_equals_filterpy_step_by_step() -> None:
    rng = np.random.default_rng(4)
    target = doppler_target(10.0, 25)
    truth = target.truth()
    sr, sb, svr, runs = 250.0, np.deg2rad(1.0), 15.0, 4
    meas = polar_doppler_measurements(truth, sr, sb, svr, runs, rng)
    x0 = truth[0] + rng.normal(size=(runs, 4)) * [300, 20, 300, 20]
    P0 = np.tile(np.diag([300.0**2, 50.0**2, 300.0**2, 50.0**2]), (runs, 1, 1))
    state = as_batch(x0, P0)
    R = np.diag([sr**2, sb**2, svr**2])
    ref = []
    for m in range(runs):
        ekf = ExtendedKalmanFilter(dim_x=4, dim_z=3)
        ekf.x, ekf.P, ekf.F, ekf.Q = x0[m].copy(), P0[m].copy(), transition_matrix(10.0), 0
        ref.append(ekf)
    for n in range(1, 25):
        state = cv_predict(state, 10.0)
        state = ekf_doppler_update(state, meas.r[:, n], meas.beta[:, n], meas.vr[:, n], sr, sb, svr)
        for m, ekf in enumerate(ref):
            ekf.predict()
            z = np.array([meas.r[m, n], meas.beta[m, n], meas.vr[m, n]])
            ekf.update(z, _jac, _hx, R=R, residual=_residual)
            np.testing.assert_allclose(state.x[m], ekf.x, rtol=0, atol=1e-9 * np.abs(ekf.x).max())
            np.testing.assert_allclose(state.P[m], ekf.P, rtol=0, atol=1e-9 * np.abs(ekf.P).max())


def test_los_doppler_update_is_the_kalman_update_of_its_linear_model() -> None:
    rng = np.random.default_rng(8)
    m = 20
    a = rng.normal(size=(m, 4, 4))
    P = a @ a.transpose(0, 2, 1) * 100 + np.eye(4) * 10
    x = rng.normal(size=(m, 4)) * [1e4, 100, 1e4, 100]
    vr, beta = rng.normal(size=m) * 50, rng.uniform(-3, 3, size=m)
    svr, sb = 2.0, 0.01
    out = doppler_los_update(as_batch(x, P), vr, beta, svr, sb)
    for i in range(m):
        c, s = np.cos(beta[i]), np.sin(beta[i])
        h = np.array([0.0, c, 0.0, s])
        w = np.array([0.0, -s, 0.0, c])
        var = svr**2 + ((w @ x[i]) ** 2 + w @ P[i] @ w) * sb**2
        S = h @ P[i] @ h + var
        K = P[i] @ h / S
        np.testing.assert_allclose(out.x[i], x[i] + K * (vr[i] - h @ x[i]), rtol=1e-12)
        np.testing.assert_allclose(
            out.P[i], P[i] - np.outer(K, K) * S, rtol=1e-9, atol=1e-9 * np.abs(P[i]).max()
        )


@pytest.mark.parametrize("doppler", [False, True])
def test_finite_memory_start_covariance_matches_monte_carlo(doppler: bool) -> None:
    """Along the line of sight, the start's position and velocity errors have the fit's R."""
    radar = preset("RLS3")
    k, runs = 3, 200_000
    sr, svr, T = radar.sigma_r_m, radar.sigma_vr_mps, radar.period_s
    sb = np.deg2rad(0.5)
    # A radially moving target (no tangential motion): the fit is then exact in the mean.
    from radarviz.core.scenarios.planar import ConstantVelocityTarget2D

    truth = ConstantVelocityTarget2D(60e3, 80e3, 150.0, 200.0, T, k).truth()
    meas = polar_doppler_measurements(truth, sr, sb, svr, runs, np.random.default_rng(3))
    fit = finite_memory_fit(k, sr, svr, T, with_doppler=doppler)
    st = finite_memory_start(
        fit, meas.r, meas.vr if doppler else None, meas.beta[:, -1], sb, 1000.0
    )
    # Range and radial velocity of the start state are the fit's r̂ and V̂r (the measured line
    # of sight carries them), so their errors have mean 0 and covariance R exactly.
    b = meas.beta[:, -1]
    e_pos = np.hypot(st.x[:, 0], st.x[:, 2]) - np.hypot(truth[-1, 0], truth[-1, 2])
    e_vel = np.cos(b) * st.x[:, 1] + np.sin(b) * st.x[:, 3] - radial_velocity(truth[-1])
    for e, var in ((e_pos, fit.R[0, 0]), (e_vel, fit.R[1, 1])):
        sd = np.sqrt(var)
        assert abs(e.mean()) < Z * sd / np.sqrt(runs)
        assert abs(e.std(ddof=1) - sd) < Z * sd / np.sqrt(2 * (runs - 1))
    assert abs(np.mean(e_pos * e_vel) - fit.R[0, 1]) < Z * np.std(e_pos * e_vel) / np.sqrt(runs)
    # ...and the reported P carries the same variances along the measured line of sight.
    g = np.stack([np.cos(b), np.zeros(runs), np.sin(b), np.zeros(runs)], axis=-1)
    np.testing.assert_allclose(np.einsum("mi,mij,mj->m", g, st.P, g), fit.R[0, 0], rtol=1e-9)


def test_doppler_start_and_track_beat_range_only_for_rls3() -> None:
    res = run_doppler_tracking(DopplerTrackingConfig(radar="RLS3", runs=3000, steps=30))
    ro, rd = res.rmse_vr["range_only"], res.rmse_vr["range_doppler"]
    assert np.all(np.isnan(ro[:2])) and np.isfinite(ro[2])
    # At the start the radial-velocity error is the fit's: σVr-like with Doppler, far larger
    # without (the paper's gains); the filter's own σ agrees with the empirical RMSE.
    assert rd[2] < 0.5 * ro[2]
    for v in ("range_only", "range_doppler"):
        rel_se = 1.0 / np.sqrt(2 * res.config.runs)
        s = res.sigma_vr_filter[v][2]
        assert abs(res.rmse_vr[v][2] - s) < Z * rel_se * s + 0.02 * s
    # Consistent over the track for this radar (NEES near 2, loose: EKF, not exact).
    for v in ("range_only", "range_doppler"):
        assert np.all(res.metrics[v].nees_pos[2:] < 2.6)


def test_bad_config() -> None:
    with pytest.raises(ParameterError, match="RLS1"):
        DopplerTrackingConfig(radar="RLS9")
    with pytest.raises(ParameterError, match="start_scans must be an integer in"):
        DopplerTrackingConfig(start_scans=1)
