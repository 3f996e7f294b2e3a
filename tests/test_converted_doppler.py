"""The range × range-rate pseudo-measurement (core.filters.converted_doppler): its moments
given the truth by Monte Carlo, the quadratic state function's moments by Monte Carlo, and the
update against a filterpy Kalman filter built from the same linear-in-state form."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from radarviz.core.filters.converted_doppler import (
    converted_doppler_moments,
    converted_doppler_update,
)
from radarviz.core.filters.state import CVBatch, as_batch

Z = 4.0  # standard errors allowed: a false alarm about once in 16 000 checks


def _mean_and_var_tolerance(sample: np.ndarray) -> tuple[float, float, float, float]:
    """Sample mean and variance and their standard errors (the variance's from the fourth
    central moment: var(s²) ≈ (m4 − s⁴) / M)."""
    m = sample.size
    mean, var = sample.mean(), sample.var(ddof=1)
    m4 = np.mean((sample - mean) ** 4)
    return mean, var, np.sqrt(var / m), np.sqrt((m4 - var * var) / m)


@pytest.mark.parametrize(
    ("r", "vr", "sr", "sv"), [(1e5, -200.0, 50.0, 1.0), (2e4, 80.0, 250.0, 35.0)]
)
def test_moments_given_the_truth_by_monte_carlo(r: float, vr: float, sr: float, sv: float) -> None:
    rng = np.random.default_rng(11)
    m = 400_000
    r_hat = r + sr * rng.standard_normal(m)
    v_hat = vr + sv * rng.standard_normal(m)
    eta, r_eta = converted_doppler_moments(r_hat, v_hat, sigma_r_m=sr, sigma_vr_mps=sv)
    mean, var, se_mean, se_var = _mean_and_var_tolerance(eta)
    true_var = r * r * sv * sv + vr * vr * sr * sr + sr * sr * sv * sv
    assert abs(mean - r * vr) < Z * se_mean  # no bias
    assert abs(var - true_var) < Z * se_var
    # R_η, formed from the measurement, is unbiased for that variance.
    assert abs(r_eta.mean() - true_var) < Z * r_eta.std(ddof=1) / np.sqrt(m)


@pytest.mark.parametrize("dims", [2, 3])
def test_quadratic_moments_of_a_gaussian_state(dims: int) -> None:
    """E[d·v] = d̂·v̂ + tr P_pv and var[d·v] = H P Hᵀ + tr(P_pv²) + tr(P_pp P_vv): the
    innovation's mean and variance, less R_η, as the update forms them."""
    rng = np.random.default_rng(5)
    n = 2 * dims
    x0 = rng.standard_normal(n) * np.array([1e3, 50.0] * dims)
    a = rng.standard_normal((n, n)) * np.array([300.0, 20.0] * dims)
    P = a @ a.T
    draws = rng.multivariate_normal(x0, P, size=400_000)
    h = np.sum(draws[:, 0::2] * draws[:, 1::2], axis=-1)
    mean, var, se_mean, se_var = _mean_and_var_tolerance(h)
    d, v = x0[0::2], x0[1::2]
    p_pv = P[0::2, 1::2]
    H = np.zeros(n)
    H[0::2], H[1::2] = v, d
    want_mean = d @ v + np.trace(p_pv)
    want_var = H @ P @ H + np.trace(p_pv @ p_pv) + np.trace(P[0::2, 0::2] @ P[1::2, 1::2])
    assert abs(mean - want_mean) < Z * se_mean
    assert abs(var - want_var) < Z * se_var
    # With R_η → 0 the update's S is exactly that variance: recover it from the gain.
    state = as_batch(x0[None], P[None])
    tiny = 1e-12
    upd = converted_doppler_update(
        state, d @ v / np.linalg.norm(d), np.linalg.norm(d), sigma_r_m=tiny, sigma_vr_mps=tiny
    )
    # P⁺ = P − U Uᵀ / S with U = P Hᵀ: the drop along H gives S.
    U = P @ H
    drop = H @ (P - upd.P[0]) @ H
    assert (H @ U) ** 2 / drop == pytest.approx(want_var, rel=1e-6)


@pytest.mark.parametrize("dims", [2, 3])
def test_update_equals_a_filterpy_kalman_filter(dims: int) -> None:
    """On the linear-in-state form the update is a linear Kalman update: filterpy's, with
    z = η̂ − (d̂·v̂ + tr P_pv) + H x̂ and R = R_η + the second-order terms, gives the same
    state for every row of a batch (with a site off the origin)."""
    rng = np.random.default_rng(8)
    n, rows = 2 * dims, 5
    site = rng.standard_normal(dims) * 1e3
    x = rng.standard_normal((rows, n)) * np.array([5e4, 150.0] * dims)
    a = rng.standard_normal((rows, n, n)) * np.array([200.0, 10.0] * dims)
    P = a @ a.mT + np.eye(n)
    d = x[:, 0::2] - site
    r_hat = np.linalg.norm(d, axis=-1) + 40.0 * rng.standard_normal(rows)
    v_hat = np.sum(d * x[:, 1::2], -1) / np.linalg.norm(d, axis=-1) + rng.standard_normal(rows)
    sr, sv = 50.0, 1.0
    got = converted_doppler_update(
        as_batch(x, P), r_hat, v_hat, sigma_r_m=sr, sigma_vr_mps=sv, site=site
    )
    eta, r_eta = converted_doppler_moments(r_hat, v_hat, sigma_r_m=sr, sigma_vr_mps=sv)
    for i in range(rows):
        kf = KalmanFilter(dim_x=n, dim_z=1)
        kf.x, kf.P = x[i].copy(), P[i].copy()
        H = np.zeros((1, n))
        H[0, 0::2], H[0, 1::2] = x[i, 1::2], d[i]
        p_pv, p_pp, p_vv = P[i, 0::2, 1::2], P[i, 0::2, 0::2], P[i, 1::2, 1::2]
        mean = d[i] @ x[i, 1::2] + np.trace(p_pv)
        R = r_eta[i] + np.trace(p_pv @ p_pv) + np.trace(p_pp @ p_vv)
        kf.update(np.array([eta[i] - mean + H[0] @ x[i]]), R=np.array([[R]]), H=H)
        np.testing.assert_allclose(got.x[i], kf.x, rtol=1e-10, atol=1e-8)
        np.testing.assert_allclose(got.P[i], kf.P, rtol=1e-8, atol=1e-6)


def test_batched_rows_equal_single_rows() -> None:
    rng = np.random.default_rng(2)
    x = rng.standard_normal((4, 3, 6)) * 1e3
    a = rng.standard_normal((4, 3, 6, 6)) * 10.0
    P = a @ a.mT + np.eye(6)
    r = rng.uniform(1e4, 2e4, (4, 3))
    v = rng.uniform(-100.0, 100.0, (4, 3))
    full = converted_doppler_update(CVBatch(x, P), r, v, sigma_r_m=30.0, sigma_vr_mps=2.0)
    one = converted_doppler_update(
        CVBatch(x[2:3, 1], P[2:3, 1]), r[2:3, 1], v[2:3, 1], sigma_r_m=30.0, sigma_vr_mps=2.0
    )
    np.testing.assert_allclose(full.x[2, 1], one.x[0], rtol=1e-12)
    np.testing.assert_allclose(full.P[2, 1], one.P[0], rtol=1e-12, atol=1e-9)


def test_doppler_experiment_runs_the_converted_variant_from_the_same_start() -> None:
    from radarviz.core.experiments.doppler_start import (
        DopplerTrackingConfig,
        compare_doppler_updates,
        doppler_consistency,
        run_doppler_tracking,
    )
    from radarviz.core.params import ParameterError

    with pytest.raises(ParameterError, match="variant must be one of"):
        DopplerTrackingConfig(variants=("range_only", "bogus"))
    cfg = DopplerTrackingConfig(
        radar="RLS2",
        runs=60,
        steps=12,
        engine="numpy",
        variants=("range_doppler", "range_converted_doppler"),
    )
    res = run_doppler_tracking(cfg)
    a, b = (res.metrics[v] for v in cfg.variants)
    k = cfg.start_scans - 1  # the start scan: the same finite-memory start for both
    assert a.rmse_x[k] == b.rmse_x[k] and a.nees_pos[k] == b.nees_pos[k]
    assert not np.array_equal(a.nees_pos[k + 1 :], b.nees_pos[k + 1 :])
    (summary,) = [doppler_consistency(r) for r in compare_doppler_updates(("RLS2",), runs=60)]
    assert [c.variant for c in summary] == ["range_doppler", "range_converted_doppler"]
    for c in summary:
        assert c.nees_last_ci95[0] <= c.nees_last <= c.nees_last_ci95[1]
        assert c.verdict in ("consistent", "over-confident", "under-confident")


def test_cli_reproduce_doppler(capsys) -> None:
    import json

    from radarviz.viz_app.cli.main import main

    assert main(["reproduce", "doppler", "--radars", "RLS1", "--runs", "20", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["cases"][0]["radar"] == "RLS1"
    assert {c["variant"] for c in doc["cases"][0]["consistency"]} == {
        "range_doppler",
        "range_converted_doppler",
    }
    assert main(["reproduce", "doppler", "--radars", "RLS9", "--runs", "20"]) == 2
    assert "--radars must be among" in capsys.readouterr().err
