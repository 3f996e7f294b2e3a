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
    assert a.rmse_x_m[k] == b.rmse_x_m[k] and a.nees_pos[k] == b.nees_pos[k]
    assert not np.array_equal(a.nees_pos[k + 1 :], b.nees_pos[k + 1 :])
    (summary,) = [doppler_consistency(r) for r in compare_doppler_updates(("RLS2",), runs=60)]
    assert [c.variant for c in summary] == [
        "range_doppler",
        "range_converted_doppler",
        "range_joint_doppler",
    ]
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
        "range_joint_doppler",
    }
    assert main(["reproduce", "doppler", "--radars", "RLS9", "--runs", "20"]) == 2
    assert "--radars must be among" in capsys.readouterr().err


# ------------------------------------------------------------------ the stream tracker


def _mc_converted_tracks(radar: str, runs: int, steps: int, seed: int = 3):
    """The Monte Carlo engine's converted-Doppler filter (``range_converted_doppler`` of
    ``core.experiments.doppler_start``: finite-memory start over k = 3 scans, then the polar
    EKF and the r̂ V̂r update) on its own measurements: (config, measurements, {scan: (x, P)})."""
    from radarviz.core.experiments.doppler_start import (
        DopplerTrackingConfig,
        _filter_numpy,
        polar_doppler_measurements,
    )
    from radarviz.core.filters.compiled import FilterSettings
    from radarviz.core.finite_memory.fit import finite_memory_fit
    from radarviz.core.finite_memory.start import finite_memory_start

    cfg = DopplerTrackingConfig(radar=radar, runs=runs, steps=steps, seed=seed, engine="numpy")
    rp = cfg.radar_preset()
    sigma_beta_rad = float(np.deg2rad(cfg.sigma_beta_deg))
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    meas = polar_doppler_measurements(
        cfg.scenario().truth(),
        sigma_r_m=rp.sigma_r_m,
        sigma_beta_rad=sigma_beta_rad,
        sigma_vr_mps=rp.sigma_vr_mps,
        runs=runs,
        rng=rng,
    )
    k = cfg.start_scans
    fit = finite_memory_fit(
        k,
        sigma_r_m=rp.sigma_r_m,
        sigma_vr_mps=rp.sigma_vr_mps,
        period_s=rp.period_s,
        with_doppler=True,
    )
    start = finite_memory_start(
        fit,
        meas.r[:, :k],
        meas.vr[:, :k],
        meas.beta[:, k - 1],
        sigma_beta_rad=sigma_beta_rad,
        sigma_v0_mps=cfg.sigma_v0_mps,
    )
    settings = FilterSettings(
        rp.sigma_r_m,
        sigma_beta_rad,
        rp.period_s,
        cfg.sigma_a_mps2,
        cfg.sigma_v0_mps,
        sigma_vr_mps=rp.sigma_vr_mps,
    )
    states = {k - 1: (start.x, start.P)}
    for n, x, P in _filter_numpy(meas.r, meas.beta, meas.vr, settings, (k - 1, start), "converted"):
        states[n] = (x[0], P[0])
    return cfg, meas, states


def _plots_of_run(cfg, meas, j: int, target: str = ""):
    from radarviz.core.tracking.stream import Plot

    rp = cfg.radar_preset()
    return [
        Plot(
            time_s=n * rp.period_s,
            range_m=float(meas.r[j, n]),
            azimuth_rad=float(meas.beta[j, n]),
            sigma_r_m=rp.sigma_r_m,
            sigma_beta_rad=float(np.deg2rad(cfg.sigma_beta_deg)),
            radar="a",
            radial_velocity_mps=float(meas.vr[j, n]),
            sigma_vr_mps=rp.sigma_vr_mps,
            target=target,
        )
        for n in range(meas.r.shape[1])
    ]


@pytest.mark.parametrize("radar", ["RLS3", "RLS5"])
def test_stream_tracker_converted_doppler_equals_the_monte_carlo_engine(radar: str) -> None:
    """``StreamOptions(doppler_update="converted")`` with the finite-memory start is the Monte
    Carlo's ``range_converted_doppler`` filter on the same plots: every state to 1e-9 of its
    own σ, every covariance entry to 1e-9 of its diagonal scale."""
    from radarviz.core.tracking.stream import StreamOptions, StreamTracker

    cfg, meas, states = _mc_converted_tracks(radar, runs=4, steps=15)
    options = StreamOptions(
        sigma_a_mps2=cfg.sigma_a_mps2,
        sigma_v0_mps=cfg.sigma_v0_mps,
        doppler_update="converted",
        init="finite-memory",
        init_k=cfg.start_scans,
    )
    los = StreamOptions(
        sigma_a_mps2=cfg.sigma_a_mps2,
        sigma_v0_mps=cfg.sigma_v0_mps,
        init="finite-memory",
        init_k=cfg.start_scans,
    )
    for j in range(4):
        plots = _plots_of_run(cfg, meas, j)
        rows = StreamTracker(("ekf",), False, options).add_block(plots)
        other = StreamTracker(("ekf",), False, los).add_block(plots)
        for n, (x_mc, P_mc) in states.items():
            ((_, x, P),) = rows[n]
            sd = np.sqrt(np.diag(P_mc[j]))
            np.testing.assert_allclose((x[:4] - x_mc[j]) / sd, 0.0, atol=1e-9)
            np.testing.assert_allclose((P[:4, :4] - P_mc[j]) / np.outer(sd, sd), 0.0, atol=1e-9)
        # The default (line of sight) is another filter: the option changes the result.
        assert not np.allclose(other[-1][0][1], rows[-1][0][1], rtol=1e-6)


def test_converted_doppler_in_the_many_target_tracker_and_the_imm() -> None:
    """Every method with ``doppler_update="converted"``: ``TargetTracker`` (two labelled targets,
    one batch) equals ``StreamTracker`` run per target, and an IMM of two identical models
    equals the CV filter (both to 1e-9); the monitor gets the converted update's NIS."""
    from radarviz.core.filters.methods import ALL_METHODS
    from radarviz.core.tracking.consistency import ConsistencyMonitor
    from radarviz.core.tracking.stream import StreamOptions, StreamTracker
    from radarviz.core.tracking.targets import TargetTracker

    cfg, meas, _ = _mc_converted_tracks("RLS3", runs=3, steps=10)
    options = StreamOptions(sigma_a_mps2=0.5, doppler_update="converted")
    per_target = [
        StreamTracker(ALL_METHODS, False, options).add_block(_plots_of_run(cfg, meas, j))
        for j in range(2)
    ]
    mixed = [
        p
        for pair in zip(*(_plots_of_run(cfg, meas, j, f"t{j}") for j in range(2)), strict=True)
        for p in pair
    ]
    both = TargetTracker(ALL_METHODS, False, options).add_block(mixed)
    for i, rows in enumerate(both):
        expected = per_target[i % 2][i // 2]
        for (m, x, P), (m2, x2, P2) in zip(rows, expected, strict=True):
            assert m == m2
            sd = np.sqrt(np.diag(P2)[:4])
            np.testing.assert_allclose((x[:4] - x2[:4]) / sd, 0.0, atol=1e-9, err_msg=m)
            scale = np.outer(sd, sd)
            np.testing.assert_allclose(P[:4, :4] / scale, P2[:4, :4] / scale, atol=1e-9)
    monitor = ConsistencyMonitor(5)
    imm = StreamOptions(
        model="imm",
        imm_sigma_a_mps2=(0.5, 0.5),
        transition_prob=((0.995, 0.005), (0.05, 0.95)),
        imm_turn_rate_degps=None,  # two constant-velocity models alike: the cv filter
        doppler_update="converted",
        monitor=monitor,
    )
    rows_imm = StreamTracker(ALL_METHODS, False, imm).add_block(_plots_of_run(cfg, meas, 0))
    for got, expected in zip(rows_imm, per_target[0], strict=True):
        for (m, x, P), (_, x2, P2) in zip(got, expected, strict=True):
            sd = np.sqrt(np.diag(P2)[:4])
            np.testing.assert_allclose((x[:4] - x2[:4]) / sd, 0.0, atol=1e-9, err_msg=m)
            np.testing.assert_allclose(
                P[:4, :4] / np.outer(sd, sd), P2[:4, :4] / np.outer(sd, sd), atol=1e-9
            )
    assert set(monitor.tracks) == set(ALL_METHODS)
    for m in ALL_METHODS:  # an NIS per update after the start, with the converted stage's
        result = monitor.result(m)
        assert result.updates == 9 and np.isfinite(result.mean_nis_per_dof)


def test_track_doppler_converted_end_to_end_on_a_simulated_doppler_file(tmp_path, capsys) -> None:
    """``simulate --preset fusion`` (three 3D radars with Doppler, off the origin) then
    ``track --doppler converted``: exit 0, finite rows for every method, different from the
    line-of-sight update's, and the summary names the update."""
    import csv
    import json

    from radarviz.viz_app.cli.main import main

    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    sim = ["simulate", "--preset", "fusion", "--out", str(meas), "--radars-out", str(radars)]
    assert main([*sim, "--scans", "12", "--seed", "2"]) == 0
    tracks = {}
    for mode in ("use", "converted"):
        out, summary = tmp_path / f"{mode}.csv", tmp_path / f"{mode}.json"
        args = ["track", "--input", str(meas), "--radars", str(radars), "--out", str(out)]
        args += ["--doppler", mode, "--summary", str(summary), "--model", "cv", "--sigma-a", "1"]
        assert main(args) == 0
        with out.open() as fh:
            tracks[mode] = list(csv.DictReader(fh))
        assert json.loads(summary.read_text())["doppler_update"] == (
            "converted" if mode == "converted" else "line_of_sight"
        )
    capsys.readouterr()
    a, b = tracks["use"], tracks["converted"]
    assert len(a) == len(b) > 0
    assert {r["method"] for r in b} >= {"naive", "ucm", "ducm", "ekf", "ukf"}
    cols = [c for c in b[0] if c.startswith(("x_", "vx", "vy", "vz", "y_", "z_"))] or [
        c for c in b[0] if c not in ("method", "target", "radar", "time_s", "plot")
    ]
    vals = np.array([[float(r[c]) for c in cols if r[c] != ""] for r in b])
    assert np.all(np.isfinite(vals))
    assert any(ra != rb for ra, rb in zip(a, b, strict=True))
