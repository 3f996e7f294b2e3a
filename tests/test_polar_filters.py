"""The batched polar EKF / UKF (``core.filters.polar_ekf``, ``polar_ukf``) against filterpy.

Scenario (the ``prosov`` preset's geometry, rotated): a target 150 km from the radar at azimuth
β0, moving radially outward at 200 m/s, T = 10 s, 30 scans, σr = 250 m, σβ = 1° or 2°,
optional process noise σa = 0.5 m/s². Tracks start from the first measurement
(the ``ekf``/``ukf`` methods' start); every later scan is predict (``cv_predict``) + update.

Tolerance. The batched filters and filterpy evaluate the same equations in a different order,
so they differ by rounding only: float64 ε ≈ 1.1e-16 per operation, amplified by the
cancellation in P⁺ = P⁻ − (…) (up to ~10³ in the first scans, when the velocity variance
collapses from (1000 m/s)²) and carried through 29 scans of a stable filter: ≲ 1e-16 · 10³ · 30
≈ 3e-12 relative to the largest entry. Measured: ≤ 6e-14. We assert rtol = 1e-9 with
atol = 1e-9 · max|entry| (so small off-diagonal entries are compared on the scale of the
matrix); any error in the equations shows at ≥ 1e-6.
"""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter

import radarviz.core.filters.ekf_2d as ekf_2d
import radarviz.core.filters.polar_ekf as ekf_module
import radarviz.core.filters.polar_ukf as ukf_module
import radarviz.core.filters.ukf_2d as ukf_2d
from radarviz.core.conversion.planar import convert
from radarviz.core.filters.methods import METHODS, PolarNoise, PolarPlot
from radarviz.core.filters.polar_ukf import UKFParams
from radarviz.core.filters.position_3d import semidefinite_cholesky_3d
from radarviz.core.filters.predict import cv_predict, transition_matrix
from radarviz.core.filters.state import CVBatch, cv_init, empty_batch, quad_form_inv
from radarviz.core.geometry import wrap_angle

DEFAULT_UKF = UKFParams()


def init_from_polar(r, b, sigma_r, sigma_beta, sigma_v=1000.0) -> CVBatch:
    """The polar methods' start: the naive point of the first measurement."""
    return METHODS["ekf"].start(
        PolarPlot(r, b), PolarNoise(sigma_r, sigma_beta), sigma_v0_mps=sigma_v
    )


def ekf_update(pred, r, b, sigma_r, sigma_beta, out=None) -> CVBatch:
    return ekf_module.ekf_update(
        pred, (r, b), sigma_r_m=sigma_r, sigma_beta_rad=sigma_beta, out=out
    )


def ukf_update(pred, r, b, sigma_r, sigma_beta, params=DEFAULT_UKF, out=None) -> CVBatch:
    return ukf_module.ukf_update(
        pred, (r, b), sigma_r_m=sigma_r, sigma_beta_rad=sigma_beta, params=params, out=out
    )


T = 10.0
STEPS = 30
SIGMA_R = 250.0
R0 = 150e3
SPEED = 200.0
RTOL = 1e-9
NEAR_PI = math.pi - 0.004  # σβ = 1°–2° is 0.017–0.035 rad: measurements straddle ±π

# --------------------------------------------------------------------------------------------
# Scenario
# --------------------------------------------------------------------------------------------


def true_ranges() -> np.ndarray:
    return R0 + SPEED * T * np.arange(STEPS)


def measurements(
    beta0: float, sigma_beta: float, runs: int, seed: int | list[int]
) -> tuple[np.ndarray, np.ndarray]:
    """(r̂, β̂), each (runs, STEPS); β̂ reported in (−π, π] as a radar's atan2 would."""
    rng = np.random.default_rng(seed)
    r_hat = true_ranges() + SIGMA_R * rng.standard_normal((runs, STEPS))
    b = beta0 + sigma_beta * rng.standard_normal((runs, STEPS))
    return r_hat, np.arctan2(np.sin(b), np.cos(b))


# --------------------------------------------------------------------------------------------
# filterpy reference: its own functions, written independently of core.filters
# --------------------------------------------------------------------------------------------


def _wrap(a: float) -> float:
    return math.remainder(a, 2.0 * math.pi)


def hx(x: np.ndarray) -> np.ndarray:
    return np.array([math.hypot(x[0], x[2]), math.atan2(x[2], x[0])])


def h_jacobian(x: np.ndarray) -> np.ndarray:
    r2 = x[0] ** 2 + x[2] ** 2
    r = math.sqrt(r2)
    return np.array([[x[0] / r, 0.0, x[2] / r, 0.0], [-x[2] / r2, 0.0, x[0] / r2, 0.0]])


def residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    y = np.asarray(a, dtype=float) - b
    y[1] = _wrap(y[1])
    return y


def z_mean(sigmas: np.ndarray, Wm: np.ndarray) -> np.ndarray:
    """Weighted mean of (r, β) sigma points, bearings relative to the first point's."""
    ref = sigmas[0, 1]
    rel = sum(w * _wrap(b - ref) for w, b in zip(Wm, sigmas[:, 1], strict=True))
    return np.array([Wm @ sigmas[:, 0], _wrap(ref + rel)])


def make_reference(kind: str, x0, P0, sigma_beta: float, sigma_a: float, params: UKFParams):
    F = transition_matrix(T)
    if kind == "ekf":
        f = ExtendedKalmanFilter(dim_x=4, dim_z=2)
        f.F = F
    else:
        points = MerweScaledSigmaPoints(4, params.alpha, params.beta, params.kappa)
        f = UnscentedKalmanFilter(
            dim_x=4,
            dim_z=2,
            dt=T,
            hx=hx,
            fx=lambda x, dt: F @ x,
            points=points,
            z_mean_fn=z_mean,
            residual_z=residual,
        )
    f.x = np.array(x0, dtype=float)
    f.P = np.array(P0, dtype=float)
    f.Q = Q_discrete_white_noise(2, dt=T, var=sigma_a**2, block_size=2)
    f.R = np.diag([SIGMA_R**2, sigma_beta**2])
    return f


def reference_step(f, kind: str, z: np.ndarray) -> None:
    f.predict()
    if kind == "ekf":
        f.update(z, h_jacobian, hx, R=f.R, residual=residual)
    else:
        f.update(z)


def run_batched(kind, r_hat, b_hat, sigma_beta, sigma_a, params=DEFAULT_UKF) -> list[CVBatch]:
    state = init_from_polar(r_hat[:, 0], b_hat[:, 0], SIGMA_R, sigma_beta)
    states = [state]
    for n in range(1, STEPS):
        pred = cv_predict(state, T, sigma_a)
        if kind == "ekf":
            state = ekf_update(pred, r_hat[:, n], b_hat[:, n], SIGMA_R, sigma_beta)
        else:
            state = ukf_update(pred, r_hat[:, n], b_hat[:, n], SIGMA_R, sigma_beta, params)
        states.append(state)
    return states


def compare_with_filterpy(
    kind: str,
    beta0: float,
    sigma_beta_deg: float,
    sigma_a: float,
    params: UKFParams = DEFAULT_UKF,
    runs: int = 5,
    seed: int = 0,
) -> tuple[float, float, bool]:
    """Max relative differences (x, P) over runs and scans; whether any sigma-point set
    straddled ±π (UKF only)."""
    sigma_beta = math.radians(sigma_beta_deg)
    r_hat, b_hat = measurements(beta0, sigma_beta, runs, seed)
    states = run_batched(kind, r_hat, b_hat, sigma_beta, sigma_a, params)
    worst_x = worst_p = 0.0
    straddled = False
    for j in range(runs):
        f = make_reference(kind, states[0].x[j], states[0].P[j], sigma_beta, sigma_a, params)
        for n in range(1, STEPS):
            reference_step(f, kind, np.array([r_hat[j, n], b_hat[j, n]]))
            if kind == "ukf":
                straddled |= bool(np.ptp(f.sigmas_h[:, 1]) > math.pi)
            x, P = states[n].x[j], states[n].P[j]
            np.testing.assert_allclose(x, f.x, rtol=RTOL, atol=RTOL * np.abs(f.x).max())
            np.testing.assert_allclose(P, f.P, rtol=RTOL, atol=RTOL * np.abs(f.P).max())
            worst_x = max(worst_x, np.abs(x - f.x).max() / np.abs(f.x).max())
            worst_p = max(worst_p, np.abs(P - f.P).max() / np.abs(f.P).max())
    return worst_x, worst_p, straddled


# --------------------------------------------------------------------------------------------
# Agreement with filterpy
# --------------------------------------------------------------------------------------------

CASES = [
    (beta0, sigma_beta_deg, sa)
    for beta0 in (0.3, NEAR_PI)
    for sigma_beta_deg in (1.0, 2.0)
    for sa in (0.0, 0.5)
]


@pytest.mark.parametrize(("beta0", "sigma_beta_deg", "sigma_a"), CASES)
def test_ekf_matches_filterpy(beta0: float, sigma_beta_deg: float, sigma_a: float) -> None:
    wx, wp = compare_with_filterpy("ekf", beta0, sigma_beta_deg, sigma_a)[:2]
    assert wx < RTOL and wp < RTOL


@pytest.mark.parametrize(("beta0", "sigma_beta_deg", "sigma_a"), CASES)
def test_ukf_matches_filterpy(beta0: float, sigma_beta_deg: float, sigma_a: float) -> None:
    wx, wp, straddled = compare_with_filterpy("ukf", beta0, sigma_beta_deg, sigma_a)
    assert wx < RTOL and wp < RTOL
    if beta0 == NEAR_PI:
        assert straddled, "the near-π case should put sigma points on both sides of ±π"


@pytest.mark.parametrize(
    "params", [UKFParams(alpha=0.8, beta=2.0, kappa=1.0), UKFParams(alpha=1.0, beta=0.0, kappa=1.0)]
)
def test_ukf_matches_filterpy_other_sigma_points(params: UKFParams) -> None:
    wx, wp, _ = compare_with_filterpy("ukf", NEAR_PI, 2.0, 0.5, params=params, seed=3)
    assert wx < RTOL and wp < RTOL


def test_near_pi_measurements_straddle() -> None:
    """The near-π scenario really exercises the wrapping: β̂ takes both signs."""
    _, b_hat = measurements(NEAR_PI, math.radians(1.0), 5, 0)
    assert (b_hat > 0).any() and (b_hat < 0).any()


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_comparison_catches_missing_wrap(kind: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Negative control: without angle wrapping the near-π comparison must fail. The 2D
    updates wrap by their module's ``wrap`` (``core.filters.ekf_2d``, ``ukf_2d``)."""
    no_wrap = lambda a: np.asarray(a, dtype=np.float64)  # noqa: E731
    for module in (ekf_2d, ukf_2d):
        monkeypatch.setattr(module, "wrap", no_wrap)
    with pytest.raises(AssertionError):
        compare_with_filterpy(kind, NEAR_PI, 1.0, 0.0)


# --------------------------------------------------------------------------------------------
# Statistics over many runs
# --------------------------------------------------------------------------------------------

#: Mean errors at scan 30 for β0 = 0.3 rad, Q = 0, from 10⁶ runs (seeds [12345, 0 … 9], blocks
#: of 10⁵): line-of-sight error (m), cross-range error (m), position NEES; standard errors
#: ≤ 0.1 m, ≤ 2.6 m and ≤ 0.003. Not zero: the estimate's bearing scatter puts it inside the
#: circle through the target (−E[e_c²]/2r ≈ −3.5 m at 1°, −16 m at 2°) and |p̂| itself runs
#: ≈ 5–6 m short; compare +r s/2 = +32 m / +127 m for the naive converted filter. The UKF's
#: nonzero cross-range mean comes from its frame-dependent (Cholesky) sigma points.
REFERENCE = {
    ("ekf", 1.0): (-8.38, -0.68, 2.0402),
    ("ekf", 2.0): (-22.39, -0.38, 2.4379),
    ("ukf", 1.0): (-2.71, 7.37, 2.0103),
    ("ukf", 2.0): (-21.38, 6.99, 2.1824),
}
REFERENCE_SE = {1.0: (0.09, 1.21, 0.0020), 2.0: (0.10, 2.57, 0.0027)}


@pytest.mark.parametrize(("kind", "sigma_beta_deg"), list(REFERENCE))
def test_bias_and_nees_at_last_scan(kind: str, sigma_beta_deg: float) -> None:
    """20 000 runs: the mean position error along and across the line of sight, and the mean
    position NEES, are within 4 standard errors of the 10⁶-run reference; the EKF's cross-range
    mean is also within 4 SE of 0 (the EKF is rotation-equivariant, so it is unbiased across the
    line of sight by symmetry)."""
    beta0, runs = 0.3, 20_000
    sigma_beta = math.radians(sigma_beta_deg)
    r_hat, b_hat = measurements(beta0, sigma_beta, runs, seed=[7, int(sigma_beta_deg)])
    state = init_from_polar(r_hat[:, 0], b_hat[:, 0], SIGMA_R, sigma_beta)
    pred, post = empty_batch(runs), empty_batch(runs)
    update = ekf_update if kind == "ekf" else ukf_update
    for n in range(1, STEPS):
        cv_predict(state, T, 0.0, out=pred)
        state = update(pred, r_hat[:, n], b_hat[:, n], SIGMA_R, sigma_beta, out=post)
    u = np.array([math.cos(beta0), math.sin(beta0)])
    e = state.x[:, [0, 2]] - true_ranges()[-1] * u
    along = e @ u
    across = e @ np.array([-u[1], u[0]])
    nees = quad_form_inv(np.ascontiguousarray(state.P[:, [0, 2]][:, :, [0, 2]]), e)
    ref = REFERENCE[kind, sigma_beta_deg]
    ref_se = REFERENCE_SE[sigma_beta_deg]
    for value, mean_ref, se_ref in zip((along, across, nees), ref, ref_se, strict=True):
        se = math.hypot(value.std() / math.sqrt(runs), se_ref)
        assert abs(value.mean() - mean_ref) < 4.0 * se, (value.mean(), mean_ref, se)
    if kind == "ekf":
        assert abs(across.mean()) < 4.0 * across.std() / math.sqrt(runs)
    assert 1.8 < nees.mean() < 2.6  # roughly consistent (2 dof)


# --------------------------------------------------------------------------------------------
# Initialisation, angles, shapes, aliasing, memory
# --------------------------------------------------------------------------------------------


def test_init_from_polar() -> None:
    r = np.array([150e3, 80e3, 1e3])
    b = np.array([0.3, -3.1, math.pi])
    sr, sigma_beta_rad = 250.0, math.radians(2.0)
    state = init_from_polar(r, b, sr, sigma_beta_rad, sigma_v=300.0)
    conv = convert("naive", r, b, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad)
    ref = cv_init(conv.z, conv.R, 300.0)
    np.testing.assert_array_equal(state.x, ref.x)
    np.testing.assert_array_equal(state.P, ref.P)
    np.testing.assert_allclose(state.x[:, 0], r * np.cos(b))
    np.testing.assert_allclose(state.x[:, 2], r * np.sin(b))
    assert np.all(state.x[:, [1, 3]] == 0.0)
    assert np.all(state.P[:, 1, 1] == 300.0**2) and np.all(state.P[:, 3, 3] == 300.0**2)


def test_wrap_angle() -> None:
    assert wrap_angle(math.pi) == math.pi
    assert wrap_angle(-math.pi) == math.pi
    assert wrap_angle(1e-300) == 1e-300 and wrap_angle(-1e-300) == -1e-300
    np.testing.assert_allclose(wrap_angle(1.5 * math.pi), -0.5 * math.pi, rtol=1e-15)
    a = np.random.default_rng(0).uniform(-50.0, 50.0, 10_000)
    w = wrap_angle(a)
    assert np.all(w > -math.pi) and np.all(w <= math.pi)
    ref = np.array([math.remainder(v, 2.0 * math.pi) for v in a])
    np.testing.assert_allclose(w, ref, rtol=0, atol=1e-13)
    inside = np.random.default_rng(1).uniform(-3.14, 3.14, 1000)
    np.testing.assert_array_equal(wrap_angle(inside), inside)


def _predicted(runs: int = 6) -> tuple[CVBatch, np.ndarray, np.ndarray]:
    r_hat, b_hat = measurements(0.3, math.radians(1.0), runs, 11)
    state = init_from_polar(r_hat[:, 0], b_hat[:, 0], SIGMA_R, math.radians(1.0))
    return cv_predict(state, T, 0.5), r_hat[:, 1], b_hat[:, 1]


UPDATES = [
    pytest.param(ekf_update, id="ekf"),
    pytest.param(ukf_update, id="ukf"),
]


@pytest.mark.parametrize("update", UPDATES)
def test_out_is_used_and_state_untouched(update) -> None:
    pred, r, b = _predicted()
    x0, P0 = pred.x.copy(), pred.P.copy()
    fresh = update(pred, r, b, SIGMA_R, 0.02)
    out = empty_batch(pred.runs)
    got = update(pred, r, b, SIGMA_R, 0.02, out=out)
    assert got is out
    np.testing.assert_array_equal(got.x, fresh.x)
    np.testing.assert_array_equal(got.P, fresh.P)
    np.testing.assert_array_equal(pred.x, x0)  # pure: the input batch is not modified
    np.testing.assert_array_equal(pred.P, P0)
    np.testing.assert_array_equal(got.P, got.P.transpose(0, 2, 1))  # exactly symmetric
    assert np.all(np.linalg.eigvalsh(got.P) > 0)


@pytest.mark.parametrize("update", UPDATES)
def test_shape_and_alias_errors(update) -> None:
    pred, r, b = _predicted()
    with pytest.raises(ValueError, match="shape"):
        update(pred, r[:-1], b, SIGMA_R, 0.02)
    with pytest.raises(ValueError, match="shape"):
        update(pred, r, b[:, None], SIGMA_R, 0.02)
    with pytest.raises(ValueError, match="out"):
        update(pred, r, b, SIGMA_R, 0.02, out=pred)
    with pytest.raises(ValueError, match="out"):
        update(pred, r, b, SIGMA_R, 0.02, out=empty_batch(pred.runs + 1))


@pytest.mark.parametrize("update", UPDATES)
def test_working_memory_is_linear_and_small(update) -> None:
    """10⁵ runs in one call, with at most ~48 floats per run of temporaries (no (M, 9, 4, 4)
    or per-run matrices; the UKF's budget from the brief is O(M · 9 · 4))."""
    runs = 100_000
    pred, r, b = _predicted(runs)
    out = empty_batch(runs)
    tracemalloc.start()
    try:
        update(pred, r, b, SIGMA_R, 0.02, out=out)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 48 * 8 * runs
    assert np.isfinite(out.P).all()


def _factor_3d(P: np.ndarray) -> np.ndarray:
    """``semidefinite_cholesky_3d`` of a batch P (m, 6, 6) on its component-major views."""
    L = np.zeros_like(P)
    with np.errstate(invalid="ignore", divide="ignore"):
        semidefinite_cholesky_3d(P.transpose(1, 2, 0), 1.0, L.transpose(1, 2, 0))
    return L


def test_semidefinite_cholesky_accepts_a_null_direction() -> None:
    """L Lᵀ = P for a batch of P (6, 6) of rank 4 (built as A Aᵀ, A 6 × 4: two exact null
    directions, which LAPACK's Cholesky refuses), LAPACK's factor where P is positive definite,
    and NaN for an indefinite P only (its neighbours untouched): the engine's one 3D factor
    (``core.filters.position_3d``), on a batch as the numpy engine runs it."""
    rng = np.random.default_rng(3)
    A = rng.standard_normal((5, 6, 4)) * np.array([1e3, 1.0, 1e3, 1.0, 1e2, 1.0])[:, None]
    P = A @ A.mT
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.cholesky(P)
    L = _factor_3d(P)
    np.testing.assert_allclose(L @ L.mT, P, rtol=0, atol=1e-12 * np.abs(P).max())
    assert np.all(np.triu(L, 1) == 0)
    B = rng.standard_normal((5, 6, 6))
    Q = B @ B.mT + np.eye(6)
    np.testing.assert_allclose(_factor_3d(Q), np.linalg.cholesky(Q), rtol=1e-12, atol=1e-12)
    Q[2, 0, 0] = -1.0  # indefinite
    L = _factor_3d(Q)
    assert np.isnan(L[2]).any()
    np.testing.assert_allclose(np.delete(L, 2, 0), np.linalg.cholesky(np.delete(Q, 2, 0)))
