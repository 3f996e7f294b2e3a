"""The compiled Monte Carlo kernel against the numpy engine it mirrors.

The two evaluate the same equations in a different order, so they agree to rounding: states
to 1e-9 of their own standard deviation and covariances to 1e-9 of their largest entry
(measured: ~1e-12 and ~1e-13), for every method, with and without process noise, for a
radar at the origin and off it. A wrong sign or coefficient anywhere in a kernel moves the
states by whole standard deviations within a few scans.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from radarviz.core.experiments.doppler_start import DopplerTrackingConfig, run_doppler_tracking
from radarviz.core.experiments.prosov import TrackingConfig, block_measurements, run_tracking
from radarviz.core.filters.compiled import (
    COMPILED_METHODS,
    FilterSettings,
    filter_history,
)
from radarviz.core.filters.doppler import doppler_update
from radarviz.core.filters.methods import ALL_METHODS, METHODS, PolarNoise, PolarPlot
from radarviz.core.filters.predict import cv_predict
from radarviz.core.filters.state import as_batch
from radarviz.core.metrics import scan_terms, truth_line_of_sight

TOL = 1e-9


def numpy_history(method, r_hat, beta_hat, s: FilterSettings, site=None):
    """Every scan's states by the numpy engine: ``Method.start``, ``cv_predict``, update."""
    m = METHODS[method]
    noise = PolarNoise(s.sigma_r_m, s.sigma_beta_rad)
    st = m.start(
        PolarPlot(r_hat[:, 0], beta_hat[:, 0]), noise, sigma_v0_mps=s.sigma_v0_mps, site=site
    )
    xs, Ps = [st.x.copy()], [st.P.copy()]
    for n in range(1, r_hat.shape[1]):
        pred = cv_predict(st, s.period_s, s.sigma_a_mps2)
        st = m.update(pred, PolarPlot(r_hat[:, n], beta_hat[:, n]), noise, site=site)
        xs.append(st.x.copy())
        Ps.append(st.P.copy())
    return np.array(xs), np.array(Ps)


def assert_close(x, P, x_ref, P_ref) -> None:
    sigma = np.sqrt(np.diagonal(P_ref, axis1=-2, axis2=-1))
    assert np.all(np.isfinite(x_ref))
    assert np.max(np.abs(x - x_ref) / sigma) < TOL
    scale = np.abs(P_ref).max(axis=(-1, -2), keepdims=True)
    assert np.max(np.abs(P - P_ref) / scale) < TOL


def test_every_registered_2d_method_is_compiled() -> None:
    assert set(COMPILED_METHODS) == {n for n, m in METHODS.items() if 2 in m.dims}
    assert set(COMPILED_METHODS) == set(ALL_METHODS)


@pytest.mark.parametrize("method", COMPILED_METHODS)
@pytest.mark.parametrize(("sigma_beta_deg", "sigma_a_mps2"), [(1.0, 0.0), (2.0, 0.7)])
def test_kernel_matches_numpy_engine(method: str, sigma_beta_deg: float, sigma_a_mps2: float):
    cfg = TrackingConfig(sigma_beta_deg=sigma_beta_deg, sigma_a_mps2=sigma_a_mps2, seed=5)
    r_hat, beta_hat = block_measurements(cfg, 0, 64, cfg.target.truth())
    s = FilterSettings(
        cfg.sigma_r_m, cfg.sigma_beta_rad, cfg.target.period_s, sigma_a_mps2, cfg.sigma_v0_mps
    )
    x, P = filter_history(method, r_hat, beta_hat, s)
    assert_close(x, P, *numpy_history(method, r_hat, beta_hat, s))


@pytest.mark.parametrize("method", COMPILED_METHODS)
def test_kernel_matches_numpy_engine_off_the_origin(method: str) -> None:
    """A radar at (−40 km, 25 km) seeing a target that crosses its line of sight, with the
    bearing passing ±π (the wrapped residuals and the UKF's bearing mean)."""
    rng = np.random.default_rng(2)
    site = np.array([-40e3, 25e3])
    steps, runs = 30, 32
    t = np.arange(steps) * 5.0
    target = np.stack([-90e3 + 0.0 * t, 25e3 + 240.0 * (t - 70.0)], -1)  # due north, west
    d = target - site
    r = np.hypot(d[:, 0], d[:, 1])
    b = np.arctan2(d[:, 1], d[:, 0])
    sr, sigma_beta_rad = 80.0, np.deg2rad(1.5)
    r_hat = r + sr * rng.standard_normal((runs, steps))
    beta_hat = np.angle(np.exp(1j * (b + sigma_beta_rad * rng.standard_normal((runs, steps)))))
    s = FilterSettings(sr, sigma_beta_rad, 5.0, 2.0, 300.0, site_m=(float(site[0]), float(site[1])))
    x, P = filter_history(method, r_hat, beta_hat, s)
    assert np.any(b > 3.0) and np.any(b < -3.0)  # the bearing does cross ±π
    assert_close(x, P, *numpy_history(method, r_hat, beta_hat, s, site=site))


def test_ukf_kernel_takes_a_null_direction_and_refuses_an_indefinite_covariance() -> None:
    """As the numpy engine (``position_2d.semidefinite_cholesky_2d``): σv0 = 0 with Q = 0 leaves the
    velocity variance exactly 0, a null direction the sigma points do not move along (finite
    states, equal to numpy's); a start covariance indefinite beyond rounding makes that track
    NaN and leaves the others alone."""
    cfg = TrackingConfig(sigma_beta_deg=1.0)
    r_hat, beta_hat = block_measurements(cfg, 0, 20, cfg.target.truth())
    s = FilterSettings(cfg.sigma_r_m, cfg.sigma_beta_rad, 10.0, 0.0, 0.0)
    x, P = filter_history("ukf", r_hat[:, :4], beta_hat[:, :4], s)
    x_ref, P_ref = numpy_history("ukf", r_hat[:, :4], beta_hat[:, :4], s)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(x_ref))
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=TOL * cfg.sigma_r_m)
    np.testing.assert_allclose(P, P_ref, rtol=0, atol=TOL * np.abs(P_ref).max())
    # An indefinite start (a negative velocity variance) for track 3 only.
    start = as_batch(np.broadcast_to(x[1, :, :], (20, 4)), P[1].copy())
    start.P[3, 1, 1] = -1e6  # far below what one scan of process noise adds back
    s2 = FilterSettings(cfg.sigma_r_m, cfg.sigma_beta_rad, 10.0, 0.5, 100.0)
    xk, _ = filter_history("ukf", r_hat, beta_hat, s2, start=(1, start))
    assert np.isnan(xk[:, 3]).all()
    assert np.isfinite(np.delete(xk, 3, axis=1)).all()


def test_experiment_engines_agree_on_every_statistic() -> None:
    """``run_tracking`` by the compiled and by the numpy engine: every per-scan statistic of
    every method to 1e-9 of its scale (the same runs: common random numbers)."""
    cfg = TrackingConfig(runs=300, sigma_beta_deg=2.0, seed=9)
    a = run_tracking(cfg)
    b = run_tracking(replace(cfg, engine="numpy"))
    for method in cfg.methods:
        for name, va in a.metrics[method]._asdict().items():
            vb = getattr(b.metrics[method], name)
            scale = np.nanmax(np.abs(vb))
            np.testing.assert_allclose(va, vb, rtol=0, atol=TOL * scale, err_msg=name)
        lo_a, hi_a = a.band95(method, "rmse_x_m")
        lo_b, hi_b = b.band95(method, "rmse_x_m")
        np.testing.assert_allclose(hi_a - lo_a, hi_b - lo_b, rtol=1e-7)


@pytest.mark.parametrize("method", ["ekf", "ucm", "ukf"])
def test_kernel_doppler_update_matches_numpy_engine(method: str) -> None:
    """The Doppler update after the position update, from a given start state (the
    Doppler-aided experiment's finite-memory start at scan k)."""
    rng = np.random.default_rng(4)
    steps, runs, T = 25, 40, 2.0
    t = np.arange(steps) * T
    pos = np.stack([60e3 - 150.0 * t, 20e3 + 90.0 * t], -1)
    r, b = np.hypot(pos[:, 0], pos[:, 1]), np.arctan2(pos[:, 1], pos[:, 0])
    vr_true = (pos[:, 0] * -150.0 + pos[:, 1] * 90.0) / r
    sr, sigma_beta_rad, svr = 40.0, np.deg2rad(0.8), 0.5
    r_hat = r + sr * rng.standard_normal((runs, steps))
    b_hat = b + sigma_beta_rad * rng.standard_normal((runs, steps))
    vr_hat = vr_true + svr * rng.standard_normal((runs, steps))
    s = FilterSettings(sr, sigma_beta_rad, T, 1.0, 200.0, sigma_vr_mps=svr)
    k = 3
    x0 = np.zeros((runs, 4))
    x0[:, 0], x0[:, 2] = r_hat[:, k] * np.cos(b_hat[:, k]), r_hat[:, k] * np.sin(b_hat[:, k])
    P0 = np.broadcast_to(np.diag([sr**2 * 4, 200.0**2, sr**2 * 4, 200.0**2]), (runs, 4, 4))
    start = as_batch(x0, P0)
    x, P = filter_history(method, r_hat, b_hat, s, radial_velocity_mps=vr_hat, start=(k, start))
    m = METHODS[method]
    noise = PolarNoise(sr, sigma_beta_rad)
    st, xs, Ps = start, [], []
    for n in range(k + 1, steps):
        pred = cv_predict(st, T, s.sigma_a_mps2)
        st = m.update(pred, PolarPlot(r_hat[:, n], b_hat[:, n]), noise)
        st = doppler_update(
            st, vr_hat[:, n], b_hat[:, n], sigma_vr_mps=svr, sigma_beta_rad=sigma_beta_rad
        )
        xs.append(st.x.copy())
        Ps.append(st.P.copy())
    assert x.shape == (steps - k - 1, runs, 4)
    assert_close(x, P, np.array(xs), np.array(Ps))


def test_doppler_experiment_engines_agree() -> None:
    cfg = DopplerTrackingConfig(radar="RLS3", runs=200, seed=3)
    a = run_doppler_tracking(cfg)
    b = run_doppler_tracking(replace(cfg, engine="numpy"))
    for variant in a.metrics:
        for name, va in a.metrics[variant]._asdict().items():
            vb = getattr(b.metrics[variant], name)
            np.testing.assert_allclose(va, vb, rtol=0, atol=TOL * np.nanmax(np.abs(vb)))
        np.testing.assert_allclose(a.rmse_vr_mps[variant], b.rmse_vr_mps[variant], rtol=TOL)
        np.testing.assert_allclose(
            a.sigma_vr_filter_mps[variant], b.sigma_vr_filter_mps[variant], rtol=TOL
        )


def test_kernel_metric_terms_match_scan_terms() -> None:
    """The kernel's per-track terms (NEES by the Schur complement) against the numpy
    ``scan_terms`` (NEES by the Cholesky factor), and NaN for a P that is not positive
    definite in both."""
    from radarviz.core.filters.kernels_2d import track_terms

    cfg = TrackingConfig(sigma_beta_deg=2.0, seed=8)
    truth = cfg.target.truth()
    r_hat, beta_hat = block_measurements(cfg, 0, 20, truth)
    s = FilterSettings(cfg.sigma_r_m, cfg.sigma_beta_rad, cfg.target.period_s, 0.0, 1000.0)
    x, P = filter_history("ukf", r_hat, beta_hat, s)
    c, sn = truth_line_of_sight(truth)

    def kernel_terms(P):
        out = np.empty((10, *x.shape[:2]))
        for k in range(x.shape[0]):
            for m in range(x.shape[1]):
                track_terms(x[k, m], P[k, m], truth[k], c[k, 0], sn[k, 0], out, k, m, 0, 0, 0)
        return out

    a, b = kernel_terms(P), scan_terms(x, P, truth)
    scale = np.abs(b).max(axis=(1, 2), keepdims=True)
    assert np.max(np.abs(a - b) / scale) < TOL
    P_bad = P.copy()
    P_bad[5, 3, 1, 1] *= -1.0  # a negative velocity variance: not positive definite
    assert np.isnan(kernel_terms(P_bad)[9, 5, 3])
    assert np.isnan(scan_terms(x, P_bad, truth)[9, 5, 3])


def test_kernel_group_sums_deal_runs_as_the_accumulator_does() -> None:
    """Two blocks (64 runs, then 45 more at offset 64) summed per group in the kernel give the
    sums and the per-group sums of the numpy terms of the same states."""
    from radarviz.core.filters.compiled import TermsRequest, filter_scans
    from radarviz.core.metrics import MetricsAccumulator

    cfg = TrackingConfig(sigma_beta_deg=1.0, seed=3)
    truth = cfg.target.truth()
    los = truth_line_of_sight(truth)
    s = FilterSettings(cfg.sigma_r_m, cfg.sigma_beta_rad, cfg.target.period_s, 0.3, 1000.0)
    steps = truth.shape[0]
    kernel, numpy = MetricsAccumulator(steps), MetricsAccumulator(steps)
    offset = 0
    for index, size in ((0, 64), (1, 45)):
        r_hat, beta_hat = block_measurements(cfg, index, size, truth)
        want = TermsRequest(size, truth, los, offset)
        for c in filter_scans("ucm", r_hat, beta_hat, s, 7, terms=want):
            kernel.add_group_sums(c.first, size, c.group_sums, offset)
        x, P = filter_history("ucm", r_hat, beta_hat, s)
        numpy.add_scans(0, x, P, truth, los)
        offset += size
    np.testing.assert_array_equal(kernel.runs, numpy.runs)
    np.testing.assert_array_equal(kernel.group_runs, numpy.group_runs)
    for a, b in (
        (kernel.result(), numpy.result()),
        (kernel.leave_one_out(), numpy.leave_one_out()),
    ):
        for name, va in a._asdict().items():
            vb = getattr(b, name)
            np.testing.assert_allclose(va, vb, rtol=TOL, atol=TOL * np.nanmax(np.abs(vb)))
    with pytest.raises(ValueError, match="offset 0 is not the runs counted"):
        kernel.add_group_sums(0, 1, np.zeros((32, 1, 10)))


def test_threads_over_blocks_give_the_one_thread_result_bit_for_bit() -> None:
    cfg = TrackingConfig(runs=700, sigma_beta_deg=2.0, seed=12)
    one = run_tracking(cfg, block=128, workers=1)
    many = run_tracking(cfg, block=128, workers=3)
    for method in cfg.methods:
        for name, v in one.metrics[method]._asdict().items():
            np.testing.assert_array_equal(v, getattr(many.metrics[method], name), err_msg=name)
        for name, v in one.leave_one_out[method]._asdict().items():
            np.testing.assert_array_equal(v, getattr(many.leave_one_out[method], name))


def test_a_method_without_a_kernel_runs_on_the_numpy_engine(monkeypatch) -> None:
    """A registered method the kernel lacks is filtered by the numpy engine inside a compiled
    run (bit for bit its numpy-engine statistics), the others by the kernel."""
    import radarviz.core.experiments.prosov as prosov

    monkeypatch.setattr(prosov, "COMPILED_METHODS", ("naive",))
    cfg = TrackingConfig(runs=100, methods=("naive", "ukf"), seed=2)
    mixed = run_tracking(cfg)
    reference = run_tracking(replace(cfg, engine="numpy"))
    np.testing.assert_array_equal(mixed.metrics["ukf"].rmse_x_m, reference.metrics["ukf"].rmse_x_m)
    assert not np.array_equal(mixed.metrics["naive"].rmse_x_m, reference.metrics["naive"].rmse_x_m)
    np.testing.assert_allclose(
        mixed.metrics["naive"].rmse_x_m, reference.metrics["naive"].rmse_x_m, rtol=TOL
    )
