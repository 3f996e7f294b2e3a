"""The batched CV Kalman filter against filterpy, and the Joseph identity for any gain."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from radarviz.core.conversion.planar import convert
from radarviz.core.filters.position import cv_update
from radarviz.core.filters.predict import cv_predict, process_noise, transition_matrix
from radarviz.core.filters.state import cv_init, empty_batch, quad_form_inv

H2 = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])


def _random_spd(rng: np.random.Generator, m: int, n: int, scale: float) -> np.ndarray:
    a = rng.normal(size=(m, n, n))
    return scale * (a @ a.transpose(0, 2, 1) + n * np.eye(n))


@pytest.mark.parametrize("sigma_a", [0.0, 0.7])
@pytest.mark.parametrize("method", ["naive", "seed", "ucm"])
def test_batched_kf_equals_filterpy_step_by_step(method: str, sigma_a: float) -> None:
    rng = np.random.default_rng(7)
    runs, steps, T = 6, 40, 10.0
    sr, sigma_beta_rad = 250.0, np.deg2rad(2.0)
    r_true = 150e3 + 200.0 * T * np.arange(steps)
    beta_true = 0.4 + 0.002 * np.arange(steps)
    r_hat = r_true + sr * rng.standard_normal((runs, steps))
    b_hat = beta_true + sigma_beta_rad * rng.standard_normal((runs, steps))
    c = convert(method, r_hat, b_hat, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad)
    state = cv_init(c.z[:, 0], c.R[:, 0])
    ref = []
    for m in range(runs):
        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.F, kf.H, kf.Q = transition_matrix(T), H2, process_noise(T, sigma_a)
        kf.x, kf.P = state.x[m].copy(), state.P[m].copy()
        ref.append(kf)
    a, b = empty_batch(runs), empty_batch(runs)
    for n in range(1, steps):
        pred = cv_predict(state, T, sigma_a, out=a)
        state = cv_update(pred, c.z[:, n], c.R[:, n], out=b)
        for m, kf in enumerate(ref):
            kf.predict()
            kf.update(c.z[m, n], R=c.R[m, n])
            # filterpy's Joseph update and ours differ only by rounding: relative 1e-9 of the
            # largest entry leaves six orders of magnitude for error growth over 40 steps.
            np.testing.assert_allclose(state.x[m], kf.x, rtol=0, atol=1e-9 * np.abs(kf.x).max())
            np.testing.assert_allclose(state.P[m], kf.P, rtol=0, atol=1e-9 * np.abs(kf.P).max())


@pytest.mark.parametrize("sigma_a", [0.0, 0.7])
def test_batched_3d_kf_equals_filterpy(sigma_a: float) -> None:
    """The same engine in 3D (state (x, ẋ, y, ẏ, z, ż)) against filterpy's KalmanFilter."""
    rng = np.random.default_rng(8)
    runs, steps, T = 4, 30, 5.0
    truth = np.array([40e3, 30e3, 8e3]) + np.outer(np.arange(steps) * T, [-150.0, 90.0, 5.0])
    H = np.zeros((3, 6))
    H[[0, 1, 2], [0, 2, 4]] = 1.0
    R = _random_spd(rng, runs * steps, 3, 1e4).reshape(runs, steps, 3, 3)
    z = truth + np.einsum("msij,msj->msi", np.linalg.cholesky(R), rng.normal(size=(runs, steps, 3)))
    state = cv_init(z[:, 0], R[:, 0])
    ref = []
    for m in range(runs):
        kf = KalmanFilter(dim_x=6, dim_z=3)
        kf.F, kf.H, kf.Q = transition_matrix(T, 3), H, process_noise(T, sigma_a, 3)
        kf.x, kf.P = state.x[m].copy(), state.P[m].copy()
        ref.append(kf)
    for n in range(1, steps):
        state = cv_update(cv_predict(state, T, sigma_a), z[:, n], R[:, n])
        for m, kf in enumerate(ref):
            kf.predict()
            kf.update(z[m, n], R=R[m, n])
            np.testing.assert_allclose(state.x[m], kf.x, rtol=0, atol=1e-9 * np.abs(kf.x).max())
            np.testing.assert_allclose(state.P[m], kf.P, rtol=0, atol=1e-9 * np.abs(kf.P).max())


def test_any_leading_batch_shape_equals_the_flat_batch() -> None:
    """A (3, 5) batch of tracks gives bit for bit the 15 tracks of a flat batch."""
    rng = np.random.default_rng(4)
    z = rng.normal(size=(3, 5, 3)) * 1e3
    R = _random_spd(rng, 15, 3, 1e4).reshape(3, 5, 3, 3)
    grid = cv_update(cv_predict(cv_init(z, R), 2.0, 0.3), z * 1.01, R)
    flat = cv_update(
        cv_predict(cv_init(z.reshape(15, 3), R.reshape(15, 3, 3)), 2.0, 0.3),
        z.reshape(15, 3) * 1.01,
        R.reshape(15, 3, 3),
    )
    assert grid.x.shape == (3, 5, 6) and grid.P.shape == (3, 5, 6, 6)
    np.testing.assert_array_equal(grid.x.reshape(15, 6), flat.x)
    np.testing.assert_array_equal(grid.P.reshape(15, 6, 6), flat.P)


def test_update_keeps_covariance_symmetric_positive_definite() -> None:
    rng = np.random.default_rng(11)
    m, T = 200, 5.0
    state = cv_init(rng.normal(size=(m, 2)) * 1e3, _random_spd(rng, m, 2, 1e4))
    for _ in range(100):
        state = cv_predict(state, T, 0.1)
        state = cv_update(state, rng.normal(size=(m, 2)) * 1e3, _random_spd(rng, m, 2, 1e4))
        np.testing.assert_array_equal(state.P, state.P.transpose(0, 2, 1))
        assert np.all(np.linalg.eigvalsh(state.P) > 0)


def test_layout_is_run_leading_and_component_contiguous() -> None:
    b = empty_batch(10)
    assert b.x.shape == (10, 4) and b.P.shape == (10, 4, 4)
    assert b.P[:, 1, 2].flags["C_CONTIGUOUS"] and b.x[:, 3].flags["C_CONTIGUOUS"]


def test_out_must_not_alias_the_input() -> None:
    b = cv_init(np.zeros((3, 2)), np.tile(np.eye(2), (3, 1, 1)))
    with pytest.raises(ValueError, match="separate batch"):
        cv_predict(b, 1.0, out=b)
    with pytest.raises(ValueError, match="same number of runs"):
        cv_predict(b, 1.0, out=empty_batch(4))


def test_init_is_the_first_plot_start() -> None:
    R = np.array([[[4.0, 1.0], [1.0, 9.0]]])
    b = cv_init(np.array([[10.0, 20.0]]), R, sigma_v0_mps=1000.0)
    np.testing.assert_array_equal(b.x[0], [10.0, 0.0, 20.0, 0.0])
    expected = np.array([[4.0, 0, 1.0, 0], [0, 1e6, 0, 0], [1.0, 0, 9.0, 0], [0, 0, 0, 1e6]])
    np.testing.assert_array_equal(b.P[0], expected)


def test_quad_form_inv_equals_solve() -> None:
    rng = np.random.default_rng(5)
    for n in (2, 4):
        P = _random_spd(rng, 100, n, 3.0)
        e = rng.normal(size=(100, n))
        expected = np.einsum("mi,mi->m", e, np.linalg.solve(P, e[:, :, None])[:, :, 0])
        np.testing.assert_allclose(quad_form_inv(P, e), expected, rtol=1e-10)


def test_process_noise_matches_filterpy() -> None:
    from filterpy.common import Q_discrete_white_noise

    q = Q_discrete_white_noise(dim=2, dt=7.0, var=0.3**2)
    Q = process_noise(7.0, 0.3)
    np.testing.assert_allclose(Q[:2, :2], q)
    np.testing.assert_allclose(Q[2:, 2:], q)
    assert not Q[:2, 2:].any()
