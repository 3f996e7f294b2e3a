"""The IMM (core.filters.imm) against filterpy's IMMEstimator on a linear case, with
constant-velocity and fixed-rate coordinated-turn models; the turn prediction
(core.filters.turn) on both engines; and the models' validation."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import IMMEstimator, KalmanFilter

from radarviz.core.filters.imm import IMMState, imm_combine, imm_mix, imm_predict, imm_step
from radarviz.core.filters.measurement import PositionMeasurement
from radarviz.core.filters.models import IMMModel
from radarviz.core.filters.position import position_matrix
from radarviz.core.filters.predict import process_noise, transition_matrix
from radarviz.core.filters.state import CVBatch
from radarviz.core.params import ParameterError

T = 2.0
MODEL = IMMModel((0.5, 12.0), ((0.93, 0.07), (0.15, 0.85)))
#: Constant velocity and turns at ±5°/s (the manoeuvre below turns at +5°/s).
TURN_MODEL = IMMModel(
    (0.5, 2.0, 2.0),
    ((0.9, 0.05, 0.05), (0.1, 0.85, 0.05), (0.1, 0.05, 0.85)),
    turn_rate_degps=(0.0, 5.0, -5.0),
)
R = np.array([[400.0, 60.0], [60.0, 900.0]])


def turn_matrix(omega: float, T: float, dims: int) -> np.ndarray:
    """The coordinated turn's F written out with cos and sin (Bar-Shalom, Li and
    Kirubarajan 2001, eq. 11.7.1-4), independent of ``core.filters.turn``'s half angles."""
    c, s = np.cos(omega * T), np.sin(omega * T)
    F = transition_matrix(T, dims)
    F[:4, :4] = [
        [1.0, s / omega, 0.0, -(1.0 - c) / omega],
        [0.0, c, 0.0, -s],
        [0.0, (1.0 - c) / omega, 1.0, s / omega],
        [0.0, s, 0.0, c],
    ]
    return F


def _filterpy_bank(model: IMMModel, x0: np.ndarray, P0: np.ndarray) -> IMMEstimator:
    filters = []
    for sigma_a, omega in zip(model.sigma_a_mps2, model.turn_rates_radps(), strict=True):
        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.F = transition_matrix(T, 2) if omega == 0.0 else turn_matrix(omega, T, 2)
        kf.Q = process_noise(T, sigma_a, 2)
        kf.H = np.array(position_matrix(2))
        kf.R = R.copy()
        kf.x = x0.copy()
        kf.P = P0.copy()
        filters.append(kf)
    return IMMEstimator(filters, model.initial_probabilities(), model.transition_matrix())


def _manoeuvring_positions(steps: int, rng: np.random.Generator) -> np.ndarray:
    """A target that flies straight, turns hard, then flies straight, measured with R."""
    p, v = np.array([1000.0, -2000.0]), np.array([200.0, 50.0])
    out = []
    for n in range(steps):
        if 10 <= n < 18:  # 5°/s turn
            c, s = np.cos(np.radians(10.0)), np.sin(np.radians(10.0))
            v = np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])
        p = p + T * v
        out.append(p + np.linalg.cholesky(R) @ rng.standard_normal(2))
    return np.array(out)


@pytest.mark.parametrize("model", [MODEL, TURN_MODEL], ids=["cv", "turns"])
def test_imm_matches_filterpy_imm_estimator_on_a_linear_case(model: IMMModel) -> None:
    """Mixing, model-conditioned predictions, mode probabilities and the combined estimate
    equal filterpy's at every step to 1e-9 (relative), three independent tracks in a batch."""
    r = model.models
    rng = np.random.default_rng(7)
    tracks = 3
    zs = np.stack([_manoeuvring_positions(30, rng) for _ in range(tracks)], axis=1)  # (N, 3, 2)
    x0 = np.zeros((tracks, 4))
    x0[:, 0::2] = zs[0]
    P0 = np.tile(np.diag([400.0, 1e4, 900.0, 1e4]), (tracks, 1, 1))
    banks = [_filterpy_bank(model, x0[t], P0[t]) for t in range(tracks)]
    start = CVBatch(np.repeat(x0[:, None], r, axis=1), np.repeat(P0[:, None], r, axis=1))
    imm = IMMState(start, np.tile(model.initial_probabilities(), (tracks, 1)))
    Rd = {(0, 0): R[0, 0], (0, 1): R[0, 1], (1, 1): R[1, 1]}
    for n in range(1, zs.shape[0]):
        mixed, _ = imm_mix(imm, model.transition_matrix())
        pred = imm_predict(mixed, T, model)
        stage = PositionMeasurement((zs[n, :, 0], zs[n, :, 1]), Rd)
        imm, combined, _ = imm_step(imm, T, model, [stage])
        for t, bank in enumerate(banks):
            bank.predict()
            for j, f in enumerate(bank.filters):
                np.testing.assert_allclose(pred.x[t, j], f.x, rtol=1e-9, atol=1e-9)
                np.testing.assert_allclose(pred.P[t, j], f.P, rtol=1e-9, atol=1e-9)
            bank.update(zs[n, t])
            np.testing.assert_allclose(imm.probabilities[t], bank.mu, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(combined.x[t], bank.x, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(combined.P[t], bank.P, rtol=1e-9, atol=1e-9)
    # The turn was seen: the manoeuvre model took over during it and handed back after.
    assert banks[0].mu[0] > 0.5


@pytest.mark.parametrize("dims", [2, 3])
def test_the_turn_prediction_is_f_p_ft_plus_q_on_both_engines(dims: int) -> None:
    """A turn model's prediction (``core.filters.turn``) of a batch with one time step per
    track is F x, F P Fᵀ + Q with F written out (``turn_matrix``), to 1e-12; the compiled
    form (``kernels_imm.turn_model_predict``) gives the same on one track at a time; and at
    ω → 0 the turn is the constant-velocity prediction."""
    from radarviz.core.filters import kernels_imm

    n = 2 * dims
    rng = np.random.default_rng(3)
    x = 100.0 * rng.standard_normal((4, 2, n))
    A = rng.standard_normal((4, 2, n, n))
    P = 1e3 * (A @ A.mT + np.eye(n))
    dt = np.array([4.5, 5.0, 0.0, 1.7])
    model = IMMModel((0.5, 3.0), ((0.9, 0.1), (0.1, 0.9)), turn_rate_degps=(0.0, -2.5))
    pred = imm_predict(CVBatch(x, P), dt, model)
    omega, q = np.radians(-2.5), 9.0
    for t in range(4):
        F, Q = turn_matrix(omega, dt[t], dims), process_noise(dt[t], 3.0, dims)
        scale = np.abs(P[t, 1]).max()
        np.testing.assert_allclose(pred.x[t, 1], F @ x[t, 1], rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(pred.P[t, 1], F @ P[t, 1] @ F.T + Q, atol=1e-12 * scale)
        xc, Pc = x[t, 1].copy(), P[t, 1].copy()
        kernels_imm.turn_model_predict(xc, Pc, n, dt[t], omega, q)
        np.testing.assert_allclose(xc, pred.x[t, 1], rtol=1e-13, atol=1e-9)
        np.testing.assert_allclose(Pc, pred.P[t, 1], atol=1e-12 * scale)
    slow = IMMModel((0.5, 3.0), ((0.9, 0.1), (0.1, 0.9)), turn_rate_degps=(0.0, 1e-12))
    cv = IMMModel((0.5, 3.0), ((0.9, 0.1), (0.1, 0.9)))
    a, b = imm_predict(CVBatch(x, P), dt, slow), imm_predict(CVBatch(x, P), dt, cv)
    np.testing.assert_allclose(a.x, b.x, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(a.P, b.P, atol=1e-12 * np.abs(P).max())


def test_combination_of_one_certain_model_is_that_model() -> None:
    rng = np.random.default_rng(1)
    x = rng.standard_normal((5, 2, 4))
    A = rng.standard_normal((5, 2, 4, 4))
    P = A @ A.mT + np.eye(4)
    mu = np.zeros((5, 2))
    mu[:, 1] = 1.0
    c = imm_combine(CVBatch(x, P), mu)
    np.testing.assert_allclose(c.x, x[:, 1])
    np.testing.assert_allclose(c.P, P[:, 1])


@pytest.mark.parametrize(
    ("sigma_a", "transition", "needle"),
    [
        ((-1.0, 10.0), ((0.9, 0.1), (0.1, 0.9)), "imm_sigma_a_mps2 must be a finite number"),
        ((1.0,), ((1.0,),), "imm_sigma_a_mps2 must give at least 2 models"),
        ((1.0, 10.0), ((0.9, 0.2), (0.1, 0.9)), "transition_prob row 1 must sum to 1"),
        (
            (1.0, 10.0),
            ((1.0, 0.0), (0.1, 0.9)),
            "transition_prob must be a finite number in (0, 1)",
        ),
        ((1.0, 10.0), ((0.9, 0.1),), "transition_prob must be a 2 × 2 matrix"),
        ((1.0, 10.0), ((0.9, 0.1), (0.1, 0.9)), "imm_turn_rate_degps must have one entry per"),
        ((1.0, 10.0), ((0.9, 0.1), (0.1, 0.9)), "imm_turn_rate_degps must be a finite number"),
    ],
)
def test_bad_imm_models_are_one_line_naming_the_parameter(sigma_a, transition, needle) -> None:
    turns = {"one entry": (0.0,), "finite number": (0.0, 25.0)}
    rates = next((v for k, v in turns.items() if k in needle), None)
    with pytest.raises(ParameterError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        IMMModel(sigma_a, transition, turn_rate_degps=rates)


def test_initial_probabilities_are_stationary() -> None:
    mu = MODEL.initial_probabilities()
    np.testing.assert_allclose(mu @ MODEL.transition_matrix(), mu, rtol=1e-12)


def test_a_model_without_a_finite_likelihood_gets_no_weight() -> None:
    from radarviz.core.filters.imm import mode_probabilities

    prior = np.array([[0.7, 0.3], [0.7, 0.3], [0.7, 0.3]])
    ll = np.array([[-5.0, np.nan], [np.nan, np.nan], [-1000.0, -1001.0]])
    mu = mode_probabilities(prior, ll)
    np.testing.assert_allclose(mu[0], [1.0, 0.0])
    np.testing.assert_allclose(mu[1], prior[1])  # nothing to weigh: the prior stays
    w = 0.7 * np.exp(1.0) / (0.7 * np.exp(1.0) + 0.3)  # no underflow at −1000
    np.testing.assert_allclose(mu[2], [w, 1.0 - w], rtol=1e-12)


def test_innovation_of_a_broken_track_is_nan_not_an_exception() -> None:
    from radarviz.core.filters.innovation import gaussian_stats

    S = np.array([[[4.0, 0.0], [0.0, 9.0]], [[1.0, 2.0], [2.0, 1.0]]])  # second: indefinite
    nu = np.array([[2.0, 3.0], [1.0, 1.0]])
    st = gaussian_stats(nu, S)
    assert st.nis[0] == pytest.approx(2.0) and st.log_det_s[0] == pytest.approx(np.log(36.0))
    assert np.isnan(st.nis[1]) and np.isnan(st.log_det_s[1])
