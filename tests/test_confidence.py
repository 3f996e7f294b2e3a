"""Monte Carlo bands (``core.confidence``): the group bookkeeping, the verdicts, and coverage.

The coverage test repeats a small Prosov experiment R times with different seeds and counts
how often each 95% band covers a high-precision reference (the statistic of all R · M runs
pooled). The count is binomial(R, 0.95) if the bands are right, so the tolerance is three of
its standard deviations, √(0.95 · 0.05 / R); a band of the wrong width fails it (a band half as
wide covers about 68%, twice as wide about 100%: both outside the tolerance at R = 160).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from radarviz.core.confidence import (
    BAND_GROUPS,
    chi2_ppf,
    claim_verdict,
    group_counts,
    group_sums,
    jackknife_band,
    sigma_band,
    student_t_quantile,
)
from radarviz.core.experiments.prosov import TrackingConfig, run_tracking
from radarviz.core.metrics import delta_percent, nees_band
from radarviz.core.scenarios.planar import prosov_target


def test_group_sums_deal_run_j_to_group_j_mod_g() -> None:
    rng = np.random.default_rng(3)
    terms = rng.standard_normal((2, 3, 101))
    for offset in (0, 5, 64, 95):
        got = group_sums(terms, offset)
        groups = (offset + np.arange(101)) % BAND_GROUPS
        want = np.stack([terms[..., groups == g].sum(axis=-1) for g in range(BAND_GROUPS)])
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(group_counts(offset, 101), np.bincount(groups))


def test_blocks_deal_runs_as_one_block() -> None:
    """Feeding runs in blocks of any size puts every run in the same group as one block."""
    rng = np.random.default_rng(4)
    terms = rng.standard_normal(200)
    whole = group_sums(terms, 0)
    parts = group_sums(terms[:37], 0) + group_sums(terms[37:150], 37) + group_sums(terms[150:], 150)
    np.testing.assert_allclose(parts, whole, rtol=1e-12, atol=1e-12)


def test_verdicts() -> None:
    assert claim_verdict([-1.0, -1.5], [1.0, 1.9], 2.0) == "holds"
    assert claim_verdict([-1.0, -2.6], [1.0, -2.2], 2.0) == "does not hold"
    assert claim_verdict([-1.0, -2.3], [1.0, -1.9], 2.0) == "not resolved"
    assert claim_verdict([np.nan], [np.nan], 2.0) == "not resolved"
    with pytest.raises(ValueError):
        claim_verdict([], [], 1.0)


def test_jackknife_of_a_mean_is_the_t_interval() -> None:
    """For a mean, the delete-a-group jackknife variance is the batch-means variance exactly."""
    rng = np.random.default_rng(5)
    group_means = rng.standard_normal(BAND_GROUPS) + 3.0
    g = BAND_GROUPS
    full = group_means.mean()
    loo = (full * g - group_means) / (g - 1)
    lo, hi = jackknife_band(full, loo)
    from scipy import stats

    half = stats.t.ppf(0.975, g - 1) * group_means.std(ddof=1) / math.sqrt(g)
    assert hi - full == pytest.approx(half, rel=1e-12)
    assert full - lo == pytest.approx(half, rel=1e-12)


def _covered(lo: np.ndarray, hi: np.ndarray, ref: float) -> float:
    return float(np.mean((lo <= ref) & (ref <= hi)))


def _check_coverage(fraction: float, replicates: int, what: str) -> None:
    tol = 3.0 * math.sqrt(0.95 * 0.05 / replicates)
    assert abs(fraction - 0.95) <= tol, f"{what}: coverage {fraction:.3f}, 0.95 ± {tol:.3f}"


def test_prosov_bands_cover_at_95_percent() -> None:
    """Δx(10) in its three readings and one method's RMSE and range bias, σβ = 2°."""
    replicates, runs = 160, 256
    target = prosov_target(10.0, 10)
    est: dict[str, list[float]] = {}
    lo: dict[str, list[float]] = {}
    hi: dict[str, list[float]] = {}
    sums: dict[str, list[np.ndarray]] = {"seed": [], "naive": []}
    for r in range(replicates):
        cfg = TrackingConfig(
            sigma_beta_deg=2.0, runs=runs, seed=500 + r, target=target, methods=("naive", "seed")
        )
        res = run_tracking(cfg)
        bands = {f"dx_{k}": v for k, v in res.delta_x_ci95_percent().items()}
        values = {f"dx_{k}": v for k, v in res.delta_x_percent().items()}
        for name in ("rmse_x_m", "bias_range_m"):
            bands[name] = res.band95("seed", name)
            values[name] = getattr(res.metrics["seed"], name)
        for k, v in values.items():
            est.setdefault(k, []).append(v[-1])
            lo.setdefault(k, []).append(bands[k][0][-1])
            hi.setdefault(k, []).append(bands[k][1][-1])
        for method in sums:
            m = res.metrics[method]
            # Σe, Σe², ΣPxx, Σe_range of the replicate, from its statistics.
            s_e = runs * m.bias_x_m[-1]
            s_e2 = (runs - 1) * m.std_x_m[-1] ** 2 + runs * m.bias_x_m[-1] ** 2
            sums[method].append(
                np.array([s_e, s_e2, runs * m.sigma_x_filter_m[-1] ** 2, runs * m.bias_range_m[-1]])
            )
    total = replicates * runs
    pooled = {}
    for method, rows in sums.items():
        s_e, s_e2, s_p, s_r = np.sum(rows, axis=0)
        std = math.sqrt((s_e2 - s_e * s_e / total) / (total - 1))
        pooled[method] = (math.sqrt(s_p / total), math.sqrt(s_e2 / total), std, s_r / total)
    a, b = pooled["seed"], pooled["naive"]
    ref = {
        "dx_filter": float(delta_percent(np.array(a[0]), np.array(b[0]))),
        "dx_rmse": float(delta_percent(np.array(a[1]), np.array(b[1]))),
        "dx_std": float(delta_percent(np.array(a[2]), np.array(b[2]))),
        "rmse_x_m": a[1],
        "bias_range_m": a[3],
    }
    for k, value in ref.items():
        _check_coverage(_covered(np.array(lo[k]), np.array(hi[k]), value), replicates, k)
        # The band's half-width estimates 1.96-ish standard errors of one replicate: its mean
        # over the replicates is within 15% of t · (the replicates' own spread); the spread's
        # relative error at R = 160 is 1/√(2R) = 5.6%.
        t = 2.04
        spread = float(np.std(est[k], ddof=1))
        half = float(np.mean((np.array(hi[k]) - np.array(lo[k])) / 2.0))
        assert half == pytest.approx(t * spread, rel=0.15), k


def test_sigma_band_covers_at_95_percent() -> None:
    rng = np.random.default_rng(6)
    replicates, n = 2000, 50
    s = rng.standard_normal((replicates, n)).std(axis=1, ddof=1) * 3.0
    lo, hi = sigma_band(s, n)
    _check_coverage(_covered(lo, hi, 3.0), replicates, "sigma_band")


def test_the_quantiles_are_scipy_stats_bit_for_bit_without_importing_it() -> None:
    # The bands' t and χ² quantiles call scipy.stats' own special functions (scipy.stats
    # itself weighs ~50 MB): equal to the last bit, NaN where scipy.stats gives NaN (dof 0).
    from scipy import stats

    dof = np.array([0, 1, 2, 3, 7, 19, 99, 1000, 60_000])
    for level in (0.9, 0.95, 0.99):
        tail = (1.0 - level) / 2.0
        np.testing.assert_array_equal(
            student_t_quantile(dof, level), stats.t.ppf(0.5 + level / 2.0, dof)
        )
        for d in dof:
            np.testing.assert_array_equal(
                chi2_ppf([tail, 1.0 - tail], d), stats.chi2.ppf([tail, 1.0 - tail], d)
            )
    lo, hi = stats.chi2.ppf([0.025, 0.975], 500 * 2) / 500
    assert nees_band(2, 500) == (lo, hi)
