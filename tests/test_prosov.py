"""The Prosov reproduction: the filter bias pattern (docs/conversion.md) and the Δx claim."""

from __future__ import annotations

import numpy as np
import pytest

from radarviz.core.experiments.prosov import TrackingConfig, prosov_configs, run_tracking
from radarviz.core.params import ParameterError
from radarviz.core.scenarios.planar import prosov_target

#: z for the Monte Carlo tolerances below: with a few dozen asserts, a false alarm rate
#: of 7e-6 per assert keeps the file's false alarm rate under 1e-3.
Z = 4.5


@pytest.fixture(scope="module")
def two_degree():
    (cfg,) = prosov_configs(
        [2.0], runs=20_000, seed=3, methods=("naive", "seed", "cmkf_d", "ucm", "ducm")
    )
    return run_tracking(cfg)


def test_filter_bias_pattern(two_degree) -> None:
    """Net range bias ≈ r(κ − 1 + s/2): naive +rs/2, seed ≈ 0, cmkf_d and ucm +rs, ducm small.

    The pattern r(κ − 1 + s/2) is a first-order approximation, so the bands are relative to r·s (not
    Monte Carlo bands); the Monte Carlo error is added on top. Averaged over scans 30–60, where
    the filter has converged.
    """
    res = two_degree
    s = np.deg2rad(2.0) ** 2
    truth = prosov_target().truth()
    win = slice(29, 60)
    rs = np.mean(truth[win, 0] * s)
    for name, (lo, hi) in {
        "naive": (0.35, 0.6),
        "seed": (-0.12, 0.12),
        "cmkf_d": (0.8, 1.1),
        "ucm": (0.8, 1.1),
        "ducm": (-0.12, 0.12),
    }.items():
        m = res.metrics[name]
        bias = np.mean(m.bias_range[win])
        se = np.max(m.std_x[win]) / np.sqrt(res.config.runs)
        assert lo * rs - Z * se <= bias <= hi * rs + Z * se, (name, bias, rs)


def test_ducm_is_consistent_and_ucm_is_not(two_degree) -> None:
    _, hi = two_degree.nees_pos_band95
    ducm = two_degree.metrics["ducm"].nees_pos[-1]
    ucm = two_degree.metrics["ucm"].nees_pos[-1]
    # ducm slightly above nominal: the band is for a perfectly consistent filter.
    assert ducm < 1.25 * hi
    assert ucm > 4 * hi


def _delta_x_batches(sigma_beta_deg: float, batches: int = 8, runs: int = 2500) -> np.ndarray:
    """Δx_rmse(n) from independent batches (different seeds): (batches, N)."""
    out = []
    for b in range(batches):
        (cfg,) = prosov_configs(
            [sigma_beta_deg], runs=runs, seed=100 + b, methods=("naive", "seed")
        )
        out.append(run_tracking(cfg).delta_x_percent()["rmse"])
    return np.array(out)


@pytest.mark.parametrize(("sigma_beta_deg", "paper_bound"), [(1.0, 2.1), (2.0, 18.0)])
def test_paper_claim_holds_under_the_rmse_reading(sigma_beta_deg: float, paper_bound: float):
    """|Δx| ≤ 2.1% at 1° and up to 18% at 2°, growing with n, over the paper's 20 scans.

    The tolerance is Z standard errors of the batch mean of Δx (batch-means standard error).
    """
    d = _delta_x_batches(sigma_beta_deg)
    mean = d.mean(axis=0)
    se = d.std(axis=0, ddof=1) / np.sqrt(d.shape[0])
    window = slice(0, 20)
    peak = np.argmax(np.abs(mean[window]))
    # The paper's figures (2.1%, 18%) are rounded readings of its plots: allow 10% of them
    # on top of the Monte Carlo tolerance.
    assert abs(abs(mean[peak]) - paper_bound) <= Z * se[peak] + 0.1 * paper_bound
    # Growing with n: the magnitude at the end of the window is the window's largest.
    assert peak == 19
    # Beyond the paper's window the magnitude keeps growing (the figure stopped at 20 scans).
    assert abs(mean[59]) > 2 * abs(mean[19])


def test_p_based_reading_does_not_reproduce_the_claim() -> None:
    (cfg,) = prosov_configs([2.0], runs=500, steps=20, methods=("naive", "seed"))
    d = run_tracking(cfg).delta_x_percent()
    assert d["filter"][0] > 20.0  # already above 18% at the first scan
    assert np.all(np.abs(d["std"]) < 2.0)


def test_same_seed_is_bit_identical_and_seed_matters() -> None:
    (cfg,) = prosov_configs([1.0], runs=300, steps=8, methods=("naive", "ekf"))
    a, b = run_tracking(cfg), run_tracking(cfg)
    for name in a.metrics:
        for x, y in zip(a.metrics[name], b.metrics[name], strict=True):
            np.testing.assert_array_equal(x, y)
    (other,) = prosov_configs([1.0], runs=300, steps=8, seed=2, methods=("naive",))
    assert not np.array_equal(
        run_tracking(other).metrics["naive"].rmse_x, a.metrics["naive"].rmse_x
    )


def test_all_methods_run_and_report_finite_statistics() -> None:
    (cfg,) = prosov_configs([1.0], runs=64, steps=6)
    res = run_tracking(cfg)
    assert set(res.metrics) == {"naive", "seed", "cmkf_d", "ucm", "ducm", "ekf", "ukf"}
    for m in res.metrics.values():
        for series in m:
            assert series.shape == (6,) and np.all(np.isfinite(series))


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"sigma_r_m": 0.0}, "sigma_r_m must be a finite number in (0, 1e+06]"),
        ({"sigma_beta_deg": float("nan")}, "sigma_beta_deg must be a finite number in (0, 20]"),
        ({"runs": 1}, "runs must be an integer >= 2"),
        ({"methods": ("naive", "kalman")}, "method must be one of naive, seed"),
    ],
)
def test_bad_config_is_one_clear_line(kwargs: dict, needle: str) -> None:
    with pytest.raises(ParameterError) as err:
        TrackingConfig(**kwargs)
    assert needle in str(err.value) and "\n" not in str(err.value)
