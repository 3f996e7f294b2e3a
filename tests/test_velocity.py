"""3D velocity from N radial velocities: first-order covariance, second-order bias, geometry.

Statistical checks use z = 4.5 against the Monte Carlo standard error: a false alarm
probability of about 7e-6 per comparison (two-sided), so the whole file (≈ 40 comparisons,
fixed seeds) fails spuriously far less than once in a thousand seed choices; with fixed seeds
the outcome is deterministic anyway.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from radarviz.core.conversion.spatial import convert_ucm_3d
from radarviz.core.params import ParameterError
from radarviz.core.velocity.estimate import (
    M_WARN,
    GeometryError,
    baseline_problem,
    diagnose_geometry,
    direction_cosines,
    estimate_velocity,
    fuse_positions,
    line_of_sight,
    monte_carlo_velocity,
    perturbed_velocity,
    solve_velocity,
    summarize_errors,
    sweep_target,
    velocity_problem,
    velocity_statistics,
)
from radarviz.viz_app.cli.main import main

Z = 4.5
DEG = np.pi / 180.0
SITES3 = np.array([[0.0, 0.0, 0.0], [80e3, 0.0, 0.0], [40e3, 70e3, 0.0]])
SITES4 = np.vstack([SITES3, [[40e3, -40e3, 0.0]]])
TARGET = np.array([40e3, 30e3, 10e3])
VEL = np.array([216.5, 125.0, 0.0])
S_VR = np.array([1.0, 3.0, 5.0])
S_EL = np.array([0.2, 0.5, 1.0]) * DEG
S_AZ = np.array([0.1, 0.3, 0.5]) * DEG
ANGLES = {"sigma_beta_rad": S_AZ, "sigma_elevation_rad": S_EL}
SIGMAS = {"sigma_vr_mps": S_VR, **ANGLES}
#: One σ for every radar: σVr 1 m/s, both angles 0.01 rad.
SIG1 = {"sigma_vr_mps": 1.0, "sigma_beta_rad": 0.01, "sigma_elevation_rad": 0.01}


def _problem4(scale: float = 1.0, s4: tuple[float, float, float] = (2.0, 0.4, 0.2)):
    return velocity_problem(
        SITES4,
        TARGET,
        VEL,
        sigma_vr_mps=[*S_VR, s4[0]],
        sigma_beta_rad=np.r_[S_AZ, s4[2] * DEG] * scale,
        sigma_elevation_rad=np.r_[S_EL, s4[1] * DEG] * scale,
    )


def _antithetic_bias(problem, pairs: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean error and its standard error from antithetic pairs (δ, −δ).

    The pair average cancels every odd-order term of δV exactly, so its spread is O(σ²) and
    the second-order bias stands out after far fewer trials than with plain sampling.
    """
    rng = np.random.default_rng(seed)
    n = problem.sites.shape[0]
    z = rng.standard_normal((3, pairs, n))
    d = {
        "d_vr_mps": z[0] * problem.sigma_vr_mps,
        "d_elevation_rad": z[1] * problem.sigma_elevation_rad,
        "d_azimuth_rad": z[2] * problem.sigma_beta_rad,
    }
    e1 = perturbed_velocity(problem, **d) - problem.velocity
    e2 = perturbed_velocity(problem, **{k: -x for k, x in d.items()}) - problem.velocity
    a = 0.5 * (e1 + e2)
    return a.mean(axis=0), a.std(axis=0, ddof=1) / np.sqrt(pairs)


# --------------------------------------------------------------------------------------------
# First-order covariance
# --------------------------------------------------------------------------------------------


def test_equivalent_variance_matches_direct_linearisation() -> None:
    """σeq² from g_ε, g_β (docs/velocity.md) equals the finite-difference Jacobian of c · V."""
    st = velocity_statistics(baseline_problem())
    los = st.geometry.los
    h = 1e-6
    c0 = direction_cosines(los.azimuth, los.elevation) @ VEL
    g_e = (direction_cosines(los.azimuth, los.elevation + h) @ VEL - c0) / h
    g_b = (direction_cosines(los.azimuth + h, los.elevation) @ VEL - c0) / h
    var = S_VR**2 + (g_e * S_EL) ** 2 + (g_b * S_AZ) ** 2
    np.testing.assert_allclose(st.sigma_eq**2, var, rtol=1e-5)
    np.testing.assert_allclose(st.radial_velocity, c0, rtol=1e-12)


@pytest.mark.parametrize("weighted", [False, True])
def test_first_order_covariance_matches_monte_carlo(weighted: bool) -> None:
    pb = baseline_problem() if not weighted else _problem4()
    st = velocity_statistics(pb)
    n = 200_000
    mc = monte_carlo_velocity(pb, n, 11)
    var_lin, var_mc = st.sigma**2, mc.sigma**2
    se = var_lin * np.sqrt(2.0 / (n - 1))  # Gaussian sample-variance standard error
    assert np.all(np.abs(var_mc - var_lin) < Z * se), (var_mc, var_lin, se)
    # Correlations: se of a sample correlation ≈ (1 − ρ²) / √n.
    se_rho = (1.0 - st.correlation**2) / np.sqrt(n) + 1e-12
    assert np.all(np.abs(mc.correlation - st.correlation) < Z * se_rho)


def test_vz_is_the_needle_from_ground_radars() -> None:
    st = velocity_statistics(baseline_problem())
    assert np.argmax(st.sigma) == 2 and st.sigma[2] > 3.0 * st.sigma[0]
    w, vecs = np.linalg.eigh(st.covariance)
    major = vecs[:, -1]
    assert abs(major[2]) > 0.9  # the longest axis of the ellipsoid is nearly vertical
    assert w[-1] > 5.0 * w[-2]


# --------------------------------------------------------------------------------------------
# Second-order bias
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("weighted", [False, True])
def test_second_order_bias_matches_monte_carlo(weighted: bool) -> None:
    """Angles ×2 (m ≈ 0.1): bias many SE from zero, both terms needed, agreement within SE.

    The tolerance adds 3 % of |bias| for the neglected O(σ⁴) terms (relative size ≈ m²).
    """
    scale = 2.0
    pb = (
        baseline_problem()._replace(sigma_elevation_rad=S_EL * scale, sigma_beta_rad=S_AZ * scale)
        if not weighted
        else _problem4(scale)
    )
    st = velocity_statistics(pb)
    mean, se = _antithetic_bias(pb, 400_000, 5)
    bias = st.bias_second_order
    assert abs(mean[2]) > 20.0 * se[2]  # the bias is real
    assert np.all(np.abs(mean - bias) < Z * se + 0.03 * np.abs(bias)), (mean, bias, se)
    # The paper's term alone is wrong by many standard errors.
    assert np.max(np.abs(mean - st.bias_curvature) / se) > 20.0


def test_second_order_bias_plain_monte_carlo_baseline_is_consistent() -> None:
    """Without antithetics the baseline bias is within SE of the second-order value."""
    pb = baseline_problem()
    mc = monte_carlo_velocity(pb, 200_000, 3)
    st = velocity_statistics(pb)
    assert np.all(np.abs(mc.mean - st.bias_second_order) < Z * mc.mean_se)


# --------------------------------------------------------------------------------------------
# WLS
# --------------------------------------------------------------------------------------------


def test_wls_with_three_radars_equals_direct_solve() -> None:
    direct = velocity_statistics(baseline_problem())
    wls = velocity_statistics(baseline_problem()._replace(weighted=True))
    np.testing.assert_allclose(wls.gain, direct.gain, atol=1e-12)
    np.testing.assert_allclose(wls.covariance, direct.covariance, rtol=1e-10)
    np.testing.assert_allclose(
        wls.bias_second_order, direct.bias_second_order, rtol=1e-8, atol=1e-14
    )
    rng = np.random.default_rng(0)
    C = direction_cosines(rng.uniform(-3, 3, (50, 3)), rng.uniform(0.05, 1.2, (50, 3)))
    vr = rng.normal(0, 100, (50, 3))
    np.testing.assert_allclose(
        solve_velocity(C, vr, rng.uniform(0.1, 2, (50, 3))),
        solve_velocity(C, vr),
        rtol=1e-9,
        atol=1e-9,
    )


def test_wls_fourth_radar_improves_and_vanishes_when_useless() -> None:
    direct = velocity_statistics(baseline_problem())
    four = velocity_statistics(_problem4())
    diff = direct.covariance - four.covariance
    assert np.all(np.linalg.eigvalsh(diff) > -1e-9)  # N = 4 is never worse
    assert np.all(four.sigma < direct.sigma)
    useless = velocity_statistics(_problem4(s4=(1e7, 0.4, 0.2)))
    np.testing.assert_allclose(useless.covariance, direct.covariance, rtol=1e-6)
    np.testing.assert_allclose(useless.bias_second_order, direct.bias_second_order, rtol=1e-4)


def test_direct_solve_needs_exactly_three() -> None:
    with pytest.raises(ParameterError, match="exactly 3 radars"):
        velocity_problem(SITES4, TARGET, VEL, **SIG1, weighted=False)


# --------------------------------------------------------------------------------------------
# Unobservable and ill-conditioned geometry
# --------------------------------------------------------------------------------------------


def _one_line(exc: pytest.ExceptionInfo) -> str:
    msg = str(exc.value)
    assert "\n" not in msg and msg
    return msg


def test_fewer_than_three_radars_raise() -> None:
    with pytest.raises(GeometryError, match="at least 3 radars") as exc:
        velocity_problem(SITES3[:2], TARGET, VEL, **SIG1)
    _one_line(exc)
    with pytest.raises(GeometryError, match="at least 3 radars"):
        estimate_velocity(SITES3[:2], [1, 2], [0, 1], [0.1, 0.1], **SIG1)


def test_coplanar_lines_of_sight_flag_and_raise() -> None:
    """Ground radars and a target on the ground: all lines of sight horizontal, Vz unseen."""
    geo = diagnose_geometry(SITES3, [40e3, 30e3, 0.0], **ANGLES)
    assert not geo.observable and "coplanar" in geo.reason
    assert geo.m == np.inf and geo.warning is None
    with pytest.raises(GeometryError, match="coplanar") as exc:
        velocity_statistics(velocity_problem(SITES3, [40e3, 30e3, 0.0], VEL, **SIGMAS))
    _one_line(exc)


def test_collinear_sites_with_target_on_their_line_raise() -> None:
    sites = np.array([[0.0, 0, 0], [10e3, 0, 0], [20e3, 0, 0]])
    geo = diagnose_geometry(sites, [50e3, 0.0, 0.0], **ANGLES)
    assert not geo.observable
    los = line_of_sight(sites, [50e3, 0.0, 0.0])
    with pytest.raises(GeometryError, match="not observable"):
        estimate_velocity(sites, [100.0, 100.0, 100.0], los.azimuth, los.elevation, **SIG1)


def test_duplicate_sites_and_target_at_site_raise() -> None:
    dup = np.array([[0.0, 0, 0], [80e3, 0, 0], [80e3, 0, 0]])
    with pytest.raises(GeometryError, match="radars 1 and 2 share a site") as exc:
        velocity_statistics(velocity_problem(dup, TARGET, VEL, **SIGMAS))
    _one_line(exc)
    # Four radars, two co-located: still three distinct lines of sight, so observable.
    dup4 = np.vstack([SITES3, SITES3[:1]])
    assert diagnose_geometry(dup4, TARGET, sigma_beta_rad=0.01, sigma_elevation_rad=0.01).observable
    with pytest.raises(GeometryError, match="target is at the site of radar 1"):
        velocity_statistics(velocity_problem(SITES3, SITES3[1], VEL, **SIGMAS))


def test_far_target_warns_instead_of_a_confident_ellipsoid() -> None:
    pb = baseline_problem(sweep_target(300.0, 5.0))
    st = velocity_statistics(pb)
    assert st.geometry.m > M_WARN and "unreliable" in st.geometry.warning
    assert velocity_statistics(baseline_problem()).geometry.warning is None
    mc = monte_carlo_velocity(pb, 20_000, 1)
    assert np.max(mc.sigma / st.sigma) > 2.0  # and indeed the linear statistics fail there


def test_bad_parameters_raise_parameter_error() -> None:
    with pytest.raises(ParameterError, match="sigma_vr_mps must be > 0"):
        velocity_problem(SITES3, TARGET, VEL, **{**SIGMAS, "sigma_vr_mps": [1.0, 0.0, 1.0]})
    with pytest.raises(ParameterError, match="target must be finite"):
        velocity_problem(SITES3, [np.nan, 0, 0], VEL, **SIGMAS)
    with pytest.raises(ParameterError, match=r"sites must have shape \(N, 3\)"):
        velocity_problem(np.zeros((3, 2)), TARGET, VEL, **SIGMAS)


# --------------------------------------------------------------------------------------------
# Per-scan estimate and fused position
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("sites", [SITES3, SITES4])
def test_estimate_velocity_noise_free_is_exact(sites: np.ndarray) -> None:
    los = line_of_sight(sites, TARGET)
    vr = direction_cosines(los.azimuth, los.elevation) @ VEL
    n = sites.shape[0]
    sig = {"sigma_vr_mps": np.ones(n), "sigma_beta_rad": 0.003, "sigma_elevation_rad": 0.005}
    est = estimate_velocity(sites, vr, los.azimuth, los.elevation, **sig)
    np.testing.assert_allclose(est.velocity, VEL, atol=1e-9)
    assert est.warning is None and est.m < M_WARN
    pb = velocity_problem(sites, TARGET, VEL, **sig)
    np.testing.assert_allclose(est.covariance, velocity_statistics(pb).covariance, rtol=1e-9)


def test_fused_position_covariance_matches_monte_carlo() -> None:
    n = 100_000
    sr, sigma_beta_rad, se = np.array([50.0, 100.0, 150.0]), S_AZ, S_EL
    los = line_of_sight(SITES3, TARGET)
    rng = np.random.default_rng(21)
    z = rng.standard_normal((3, n, 3))
    fused = fuse_positions(
        SITES3,
        los.range + z[0] * sr,
        los.azimuth + z[1] * sigma_beta_rad,
        los.elevation + z[2] * se,
        sigma_r_m=sr,
        sigma_beta_rad=sigma_beta_rad,
        sigma_elevation_rad=se,
    )
    sig = {"sigma_r_m": sr, "sigma_beta_rad": sigma_beta_rad, "sigma_elevation_rad": se}
    truth = fuse_positions(SITES3, los.range, los.azimuth, los.elevation, **sig)
    # Noise-free points are the target up to the debiasing scale e^(s/2) (≈ r σ²/2, metres).
    np.testing.assert_allclose(truth.points, np.broadcast_to(TARGET, (3, 3)), atol=10.0)
    err = fused.position - TARGET
    stats = summarize_errors(err)
    var_pred = np.diag(truth.covariance)
    assert np.all(
        np.abs(stats.covariance.diagonal() - var_pred) < Z * var_pred * np.sqrt(2.0 / (n - 1))
    )
    assert np.all(np.abs(stats.mean) < Z * stats.mean_se)
    # Without the refinement, weights taken at each radar's own measurement bias the point.
    raw = fuse_positions(
        SITES3,
        los.range + z[0] * sr,
        los.azimuth + z[1] * sigma_beta_rad,
        los.elevation + z[2] * se,
        **sig,
        refine=False,
    )
    assert np.max(np.abs((raw.position - TARGET).mean(axis=0)) / stats.mean_se) > 10.0
    # Fusion is at least as good as every single radar: R_k − P is positive semi-definite.
    single = convert_ucm_3d(
        los.range,
        los.azimuth,
        los.elevation,
        sigma_r_m=sr,
        sigma_beta_rad=sigma_beta_rad,
        sigma_elevation_rad=se,
    ).R
    for R_k in single:
        assert np.all(np.linalg.eigvalsh(R_k - truth.covariance) > -1e-6)


def test_monte_carlo_is_bit_reproducible() -> None:
    a = monte_carlo_velocity(baseline_problem(), 5_000, 9)
    b = monte_carlo_velocity(baseline_problem(), 5_000, 9)
    assert np.array_equal(a.covariance, b.covariance) and np.array_equal(a.mean, b.mean)


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------


def test_cli_reproduce_velocity_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["reproduce", "velocity", "--trials", "3000", "--seed", "2", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["experiment"] == "velocity" and doc["trials"] == 3000 and doc["seed"] == 2
    b = doc["baseline"]
    for key in ("sigma_first_order_mps", "sigma_mc_mps", "bias_mc_mps", "bias_second_order_mps"):
        assert len(b[key]) == 3 and all(isinstance(v, float) for v in b[key])
    for key in ("corr_first_order", "corr_mc"):
        assert np.shape(b[key]) == (3, 3)
    assert b["condition_number"] > 1 and 0 < b["m"] < M_WARN
    lo, hi = np.array(b["sigma_mc_ci95_mps"]["lo"]), np.array(b["sigma_mc_ci95_mps"]["hi"])
    assert np.all((lo < b["sigma_mc_mps"]) & (np.array(b["sigma_mc_mps"]) < hi))
    corr_lo, corr_hi = np.array(b["corr_mc_ci95"]["lo"]), np.array(b["corr_mc_ci95"]["hi"])
    assert corr_lo.shape == (3, 3) and np.all(corr_lo <= np.array(b["corr_mc"]) + 1e-12)
    assert np.all(np.array(b["corr_mc"]) <= corr_hi + 1e-12)
    assert doc["band"]["level"] == 0.95
    assert doc["sweep"]
    for p in doc["sweep"]:
        assert {"distance_km", "altitude_km", "m", "ratio_mc_to_linear"} <= set(p)
        assert len(p["ratio_mc_to_linear"]) == 3
        for key in ("ratio_mc_to_linear", "ratio_robust_to_linear"):
            band = p[key + "_ci95"]
            for x, lo_i, hi_i in zip(p[key], band["lo"], band["hi"], strict=True):
                assert lo_i <= x <= hi_i
    again = main(["reproduce", "velocity", "--trials", "3000", "--seed", "2", "--json"])
    assert again == 0 and json.loads(capsys.readouterr().out) == doc


def test_cli_reproduce_velocity_table_and_plot(tmp_path, capsys) -> None:
    png = tmp_path / "v.png"
    assert main(["reproduce", "velocity", "--trials", "2000", "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "σ first order" in out and "Sweep" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["v.png"]


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--trials", "1"], "--trials must be an integer in [3, 100000000] (got 1)"),
        (["--seed", "-1"], "--seed must be an integer >= 0 (got -1)"),
        (["--trials", "x"], "not an integer"),
        (["--plot", " "], "--plot must name a file"),
    ],
)
def test_cli_reproduce_velocity_bad_input(args, needle, capsys) -> None:
    try:
        code = main(["reproduce", "velocity", *args])
    except SystemExit as exc:  # argparse type errors exit from inside parse_args
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2
    assert needle in err and err.count("\n") == 1 and "Traceback" not in err


def test_monte_carlo_bands_cover_at_95_percent() -> None:
    """``summarize_errors``' bands (jackknife σ and correlation, batch-means robust σ) over R
    replicates of Gaussian errors with a known covariance: each coverage count is
    binomial(R, 0.95) if the bands are right, so it is within 3.5 of its standard deviations
    (5e-4 false alarms per quantity, 7 quantities); half or twice the width fails."""
    rng = np.random.default_rng(11)
    cov = np.array([[4.0, -1.2, 0.6], [-1.2, 9.0, -3.0], [0.6, -3.0, 25.0]])
    sigma = np.sqrt(np.diag(cov))
    corr = cov / np.outer(sigma, sigma)
    chol = np.linalg.cholesky(cov)
    replicates, n = 400, 640
    hits = np.zeros(7)
    for _ in range(replicates):
        mc = summarize_errors(rng.standard_normal((n, 3)) @ chol.T)
        hits[:3] += (mc.sigma_ci95_lo <= sigma) & (sigma <= mc.sigma_ci95_hi)
        hits[3:6] += (mc.sigma_robust_ci95_lo <= sigma) & (sigma <= mc.sigma_robust_ci95_hi)
        hits[6] += mc.correlation_ci95_lo[1, 2] <= corr[1, 2] <= mc.correlation_ci95_hi[1, 2]
    tol = 3.5 * np.sqrt(0.95 * 0.05 / replicates)
    assert np.all(np.abs(hits / replicates - 0.95) <= tol), hits / replicates
