"""The finite-memory filter of range and radial velocity (Gorshkov and Zavizhenets 2016)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from radarviz.core.finite_memory.fit import (
    PRESETS,
    FiniteMemoryFit,
    GorshkovResult,
    design_matrix,
    finite_memory_estimate,
    finite_memory_fit,
    finite_memory_weights,
    gain_percent,
    ls_covariance_closed,
    ls_covariance_numeric,
    ls_weights_closed,
    ls_weights_numeric,
    preset,
    quadratic_truth,
    run_gorshkov,
    sliding_window_estimates,
)
from radarviz.core.params import ParameterError

C0S = (0.51, 1.0, 2.78, 11.11, 25.0, 100.0)
PERIODS = (5.0, 10.0)


def _sigmas(c0: float, period: float) -> tuple[float, float]:
    """(σr, σVr) with σVr = 3 m/s that give the requested C0 at this period."""
    sigma_vr = 3.0
    return math.sqrt(c0) * period * sigma_vr, sigma_vr


def _cov_rel_err(a: np.ndarray, b: np.ndarray) -> float:
    """max |a − b| / sqrt(b_ii b_jj): relative to the scale of each entry (R13 → 0 at k = 2)."""
    d = np.sqrt(np.diag(b))
    return float(np.max(np.abs(a - b) / np.outer(d, d)))


def _weights_rel_err(a: np.ndarray, b: np.ndarray) -> float:
    """max |a − b| relative to the largest |entry| of each row of b."""
    return float(np.max(np.abs(a - b) / np.max(np.abs(b), axis=1, keepdims=True)))


# --------------------------------------------------------------------------------------------
# Presets
# --------------------------------------------------------------------------------------------


def test_preset_c0_values() -> None:
    c0 = [PRESETS[f"RLS{n}"].c0 for n in range(1, 7)]
    assert c0 == pytest.approx([25 / 49, 1.0, 25 / 9, 100 / 9, 25.0, 100.0], rel=1e-14)
    # As printed in the paper, except RLS4 whose 11.01 is a typo for 11.11.
    assert [round(c, 2) for c in c0] == [0.51, 1.0, 2.78, 11.11, 25.0, 100.0]
    assert preset("RLS4").period_s == 5.0 and preset("RLS5").band == "CMW"


# --------------------------------------------------------------------------------------------
# Closed forms against numerical least squares
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("period", PERIODS)
@pytest.mark.parametrize("c0", C0S)
def test_closed_forms_equal_numerical_least_squares(c0: float, period: float) -> None:
    sr, sv = _sigmas(c0, period)
    for k in range(2, 31):
        for dop in (True, False):
            if not dop and k < 3:
                continue
            Rc = ls_covariance_closed(
                k, sigma_r_m=sr, sigma_vr_mps=sv, period_s=period, with_doppler=dop
            )
            Rn = ls_covariance_numeric(
                k, sigma_r_m=sr, sigma_vr_mps=sv, period_s=period, with_doppler=dop
            )
            Wc = ls_weights_closed(
                k, sigma_r_m=sr, sigma_vr_mps=sv, period_s=period, with_doppler=dop
            )
            Wn = ls_weights_numeric(
                k, sigma_r_m=sr, sigma_vr_mps=sv, period_s=period, with_doppler=dop
            )
            assert Rc.shape == (3, 3) and Wc.shape == (3, 2 * k if dop else k)
            assert _cov_rel_err(Rc, Rn) < 1e-10, (k, dop)
            assert _weights_rel_err(Wc, Wn) < 1e-10, (k, dop)


def _exact_least_squares(
    k: int, sigma_r: float, sigma_vr: float, period: float, dop: bool
) -> tuple[np.ndarray, np.ndarray]:
    """R and W in exact rational arithmetic (normal equations, Gauss-Jordan), then rounded."""
    T = Fraction(period)
    rows = [[Fraction(1), -T * (k - i), (T * (k - i)) ** 2 / 2] for i in range(1, k + 1)]
    q = [1 / Fraction(sigma_r) ** 2] * k
    if dop:
        rows += [[Fraction(0), Fraction(1), -T * (k - i)] for i in range(1, k + 1)]
        q += [1 / Fraction(sigma_vr) ** 2] * k
    a = [
        [sum(r[m] * w * r[n] for r, w in zip(rows, q, strict=True)) for n in range(3)]
        + [Fraction(int(m == n)) for n in range(3)]
        for m in range(3)
    ]
    for c in range(3):
        a[c] = [x / a[c][c] for x in a[c]]
        for r in range(3):
            if r != c:
                a[r] = [x - a[r][c] * y for x, y in zip(a[r], a[c], strict=True)]
    R = [row[3:] for row in a]
    W = [
        [sum(R[m][n] * r[n] for n in range(3)) * w for r, w in zip(rows, q, strict=True)]
        for m in range(3)
    ]
    return np.array(R, dtype=float), np.array(W, dtype=float)


@pytest.mark.parametrize("c0", [1e-12, 0.51, 100.0, 1e12])
def test_both_routes_against_exact_rational_least_squares(c0: float) -> None:
    """Also guards the closed forms against cancellation: 60C0 + k² − 4 evaluated as
    (60C0 + k²) − 4 loses all but ~1e-4 of C0 = 1e-12 at k = 2 (error 8e-8)."""
    T, sv = 5.0, 2.0
    sr = math.sqrt(c0) * T * sv
    for k in (2, 3, 5):
        for dop in (True, False):
            if not dop and k < 3:
                continue
            Re, We = _exact_least_squares(k, sr, sv, T, dop)
            closed = (
                ls_covariance_closed(
                    k, sigma_r_m=sr, sigma_vr_mps=sv, period_s=T, with_doppler=dop
                ),
                ls_weights_closed(k, sigma_r_m=sr, sigma_vr_mps=sv, period_s=T, with_doppler=dop),
            )
            assert _cov_rel_err(closed[0], Re) < 1e-13, (k, dop)
            assert _weights_rel_err(closed[1], We) < 1e-13, (k, dop)
            # The numerical route is as good as the problem's conditioning (~1/sqrt(C0)).
            tol = 1e-9 if c0 < 1e-6 else 1e-12
            assert (
                _cov_rel_err(
                    ls_covariance_numeric(
                        k, sigma_r_m=sr, sigma_vr_mps=sv, period_s=T, with_doppler=dop
                    ),
                    Re,
                )
                < tol
            )
            assert (
                _weights_rel_err(
                    ls_weights_numeric(
                        k, sigma_r_m=sr, sigma_vr_mps=sv, period_s=T, with_doppler=dop
                    ),
                    We,
                )
                < tol
            )


@pytest.mark.parametrize("dop", [True, False])
@pytest.mark.parametrize("k", [1, 2, 3, 7, 20])
def test_numerical_least_squares_is_least_squares(k: int, dop: bool) -> None:
    """W H = I (exactly unbiased for a polynomial of the fitted order), R = W Q⁻¹ Wᵀ, and R
    equals the normal-equation inverse (HᵀQH)⁻¹ computed independently."""
    sr, sv, T = 250.0, 15.0, 10.0
    fit = finite_memory_fit(
        k, sigma_r_m=sr, sigma_vr_mps=sv, period_s=T, with_doppler=dop, method="numeric"
    )
    n = fit.order
    H = design_matrix(k, T, dop, order=n)
    W, R = fit.W[:n], fit.R[:n, :n]
    var = np.concatenate([np.full(k, sr**2), np.full(k, sv**2)]) if dop else np.full(k, sr**2)
    assert np.allclose(W @ H, np.eye(n), rtol=0, atol=1e-10)
    assert _cov_rel_err(W @ np.diag(var) @ W.T, R) < 1e-12
    assert _cov_rel_err(np.linalg.inv(H.T @ np.diag(1.0 / var) @ H), R) < 1e-9
    assert np.all(np.isnan(fit.R[n:])) and np.all(np.isnan(fit.R[:, n:]))
    assert np.all(np.isnan(fit.W[n:]))


def test_design_matrix_rows() -> None:
    H = design_matrix(3, 10.0, True)
    expected_r = [[1, -20, 200], [1, -10, 50], [1, 0, 0]]
    expected_v = [[0, 1, -20], [0, 1, -10], [0, 1, 0]]
    assert np.array_equal(H, np.array(expected_r + expected_v, dtype=float))
    assert np.array_equal(design_matrix(3, 10.0, False, order=2), H[:3, :2])


# --------------------------------------------------------------------------------------------
# Reduced order
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["closed", "numeric"])
@pytest.mark.parametrize(
    ("k", "dop", "order"),
    [(1, True, 2), (2, True, 3), (3, True, 3), (1, False, 1), (2, False, 2), (3, False, 3)],
)
def test_reduced_order(k: int, dop: bool, order: int, method: str) -> None:
    sr, sv, T = 250.0, 15.0, 10.0
    fit = finite_memory_fit(
        k, sigma_r_m=sr, sigma_vr_mps=sv, period_s=T, with_doppler=dop, method=method
    )
    assert isinstance(fit, FiniteMemoryFit)
    assert (fit.k, fit.with_doppler, fit.order, fit.method) == (k, dop, order, method)
    assert fit.R.shape == (3, 3) and fit.W.shape == (3, 2 * k if dop else k)
    fitted = np.arange(3) < order
    assert np.array_equal(np.isnan(fit.sigma), ~fitted)
    assert np.all(np.isfinite(fit.R[np.ix_(fitted, fitted)]))
    assert np.all(np.isnan(fit.W[~fitted])) and np.all(np.isfinite(fit.W[fitted]))
    other = finite_memory_fit(
        k,
        sigma_r_m=sr,
        sigma_vr_mps=sv,
        period_s=T,
        with_doppler=dop,
        method="numeric" if method == "closed" else "closed",
    )
    # Rounding is relative to the matrix's scale: an exact zero of one form is ~1e-16·|R| in
    # the other.
    assert np.allclose(
        fit.R, other.R, rtol=1e-12, atol=1e-13 * np.nanmax(np.abs(fit.R)), equal_nan=True
    )
    assert np.allclose(
        fit.W, other.W, rtol=1e-12, atol=1e-13 * np.nanmax(np.abs(fit.W)), equal_nan=True
    )


def test_reduced_order_closed_values() -> None:
    sr, sv, T = 250.0, 15.0, 10.0
    one = finite_memory_fit(1, sigma_r_m=sr, sigma_vr_mps=sv, period_s=T, with_doppler=True)
    assert one.R[0, 0] == sr**2 and one.R[1, 1] == sv**2 and one.R[0, 1] == 0.0
    assert np.array_equal(one.W[:2], np.eye(2))
    two = finite_memory_fit(
        2, sigma_r_m=sr, sigma_vr_mps=None, period_s=T, with_doppler=False
    )  # r̂ = r₂, V̂r = (r₂ − r₁)/T
    assert np.array_equal(two.W[:2], [[0.0, 1.0], [-0.1, 0.1]])
    assert two.R[1, 1] == pytest.approx(2 * sr**2 / T**2, rel=1e-15)


def test_closed_form_needs_enough_samples() -> None:
    with pytest.raises(ParameterError, match=r"^k must be an integer in \[2, "):
        ls_covariance_closed(1, sigma_r_m=250.0, sigma_vr_mps=15.0, period_s=10.0)
    with pytest.raises(ParameterError, match=r"^k must be an integer in \[3, "):
        ls_weights_closed(2, sigma_r_m=250.0, sigma_vr_mps=None, period_s=10.0, with_doppler=False)
    with pytest.raises(ParameterError, match=r"^order must be an integer in \[1, 2\]"):
        ls_covariance_numeric(
            1, sigma_r_m=250.0, sigma_vr_mps=15.0, period_s=10.0, with_doppler=True, order=3
        )


# --------------------------------------------------------------------------------------------
# The filter
# --------------------------------------------------------------------------------------------


def test_estimate_recovers_a_quadratic_exactly_and_broadcasts() -> None:
    truth = quadratic_truth(100e3, -300.0, 5.0, 10.0, 8)
    rng = np.random.default_rng(0)
    fit = finite_memory_fit(8, sigma_r_m=250.0, sigma_vr_mps=15.0, period_s=10.0, with_doppler=True)
    est = finite_memory_estimate(truth[:, 0], truth[:, 1], fit)
    assert np.allclose(est, truth[-1], rtol=1e-12, atol=1e-9)
    r = truth[:, 0] + rng.normal(0, 250.0, (4, 5, 8))
    v = truth[:, 1] + rng.normal(0, 15.0, (4, 5, 8))
    batch = finite_memory_estimate(r, v, fit)
    assert batch.shape == (4, 5, 3)
    assert np.allclose(batch[2, 3], fit.W @ np.concatenate([r[2, 3], v[2, 3]]), rtol=1e-13)
    fit2 = finite_memory_fit(
        2, sigma_r_m=250.0, sigma_vr_mps=None, period_s=10.0, with_doppler=False
    )
    ro = finite_memory_estimate(r[..., -2:], None, fit2)
    assert ro.shape == (4, 5, 3) and np.all(np.isnan(ro[..., 2]))
    assert np.all(np.isfinite(ro[..., :2]))
    with pytest.raises(ParameterError, match=r"^radial_velocities must be given"):
        finite_memory_estimate(r, None, fit)
    with pytest.raises(ParameterError, match=r"^ranges must have last axis k = 8"):
        finite_memory_estimate(r[..., :7], v[..., :7], fit)


@pytest.mark.parametrize("dop", [True, False])
def test_sliding_window_estimates_match_window_by_window(dop: bool) -> None:
    n, k, T = 12, 5, 10.0
    truth = quadratic_truth(100e3, -300.0, 5.0, T, n)
    rng = np.random.default_rng(3)
    r = truth[:, 0] + rng.normal(0, 250.0, (6, n))
    v = truth[:, 1] + rng.normal(0, 15.0, (6, n)) if dop else None
    out = sliding_window_estimates(r, v, k, sigma_r_m=250.0, sigma_vr_mps=15.0, period_s=T)
    assert out.estimates.shape == (6, n, 3) and out.R.shape == (n, 3, 3)
    assert list(out.window) == [1, 2, 3, 4] + [5] * 8
    assert list(out.order[:3]) == ([2, 3, 3] if dop else [1, 2, 3])
    for scan in range(n):
        w = min(scan + 1, k)
        fit = finite_memory_fit(w, sigma_r_m=250.0, sigma_vr_mps=15.0, period_s=T, with_doppler=dop)
        lo = scan + 1 - w
        ref = finite_memory_estimate(
            r[:, lo : scan + 1], None if v is None else v[:, lo : scan + 1], fit
        )
        assert np.allclose(out.estimates[:, scan], ref, rtol=1e-13, equal_nan=True)
        assert np.array_equal(out.R[scan], fit.R, equal_nan=True)


def test_weights_accessor() -> None:
    W = finite_memory_weights(4, sigma_r_m=250.0, sigma_vr_mps=15.0, period_s=10.0)
    assert np.array_equal(
        W, ls_weights_closed(4, sigma_r_m=250.0, sigma_vr_mps=15.0, period_s=10.0)
    )


# --------------------------------------------------------------------------------------------
# The paper's claims (from the closed forms)
# --------------------------------------------------------------------------------------------


def _analytic_sigma(name: str, dop: bool, ks: range = range(1, 21)) -> np.ndarray:
    p = PRESETS[name]
    return np.array(
        [
            finite_memory_fit(
                k,
                sigma_r_m=p.sigma_r_m,
                sigma_vr_mps=p.sigma_vr_mps,
                period_s=p.period_s,
                with_doppler=dop,
            ).sigma
            for k in ks
        ]
    )


def _range_gain(name: str) -> np.ndarray:
    return gain_percent(_analytic_sigma(name, False), _analytic_sigma(name, True))[:, 0]


def _lstsq_range_sigma(name: str, dop: bool, ks: range = range(1, 21)) -> np.ndarray:
    """σ of the range estimate at scan k, by plain least squares written out here.

    Scan i of k (i = 1 … k) sits at t_i = −T(k − i) before the estimate; the state is
    (r, Vr, a) at scan k, fitted to the highest order the window allows (range only: order
    min(k, 3); with Doppler: min(k + 1, 3)). Whitening each row by its σ gives A, and the
    estimate's covariance is (AᵀA)⁻¹ = A⁺ A⁺ᵀ with A⁺ from ``np.linalg.lstsq``: no code of
    ``core.finite_memory`` is used."""
    p = PRESETS[name]
    T = p.period_s
    out = []
    for k in ks:
        n = min(k + 1, 3) if dop else min(k, 3)
        t = -T * (k - np.arange(1, k + 1))
        rows = [np.stack([np.ones(k), t, t * t / 2], axis=1)[:, :n] / p.sigma_r_m]
        if dop:
            rows.append(np.stack([np.zeros(k), np.ones(k), t], axis=1)[:, :n] / p.sigma_vr_mps)
        A = np.concatenate(rows)
        pinv = np.linalg.lstsq(A, np.eye(A.shape[0]), rcond=None)[0]
        out.append(math.sqrt((pinv @ pinv.T)[0, 0]))
    return np.array(out)


# The paper: a range gain of "about 20 %" at k = 3 (RLS1) up to "about 55 %" at k = 9 (RLS6).
PAPER_RANGE_GAIN_PEAKS = [("RLS1", 3, 20), ("RLS6", 9, 55)]


@pytest.mark.parametrize(("name", "k_paper", "percent_paper"), PAPER_RANGE_GAIN_PEAKS)
def test_range_gain_peak(name: str, k_paper: int, percent_paper: int) -> None:
    """The closed forms give the gain K(k) = (σr,range-only − σr,range+Vr)/σr,range-only of
    an independent least-squares computation to rounding, and its peak is the paper's: at
    the same k, and the same value to the paper's precision (20.00 % at k = 3; 55.41 % at
    k = 9, a flat peak: k = 10 gives 55.39 %)."""
    sigma_ro, sigma_rd = _lstsq_range_sigma(name, False), _lstsq_range_sigma(name, True)
    assert _analytic_sigma(name, False)[:, 0] == pytest.approx(sigma_ro, rel=1e-9)
    assert _analytic_sigma(name, True)[:, 0] == pytest.approx(sigma_rd, rel=1e-9)
    gain, reference = _range_gain(name), 100.0 * (1.0 - sigma_rd / sigma_ro)
    k_star = int(np.nanargmax(gain)) + 1
    assert k_star == int(np.nanargmax(reference)) + 1 == k_paper
    assert gain[k_star - 1] == pytest.approx(reference[k_star - 1], rel=1e-9)
    assert round(gain[k_star - 1]) == percent_paper
    assert gain[0] == 0.0  # one sample: r̂ = r₁ with or without Doppler


def test_doppler_gives_velocity_at_k1_with_error_sigma_vr() -> None:
    for p in PRESETS.values():
        fit = finite_memory_fit(
            1,
            sigma_r_m=p.sigma_r_m,
            sigma_vr_mps=p.sigma_vr_mps,
            period_s=p.period_s,
            with_doppler=True,
        )
        assert fit.order == 2 and fit.sigma[1] == p.sigma_vr_mps and fit.sigma[0] == p.sigma_r_m
        ro = finite_memory_fit(
            1, sigma_r_m=p.sigma_r_m, sigma_vr_mps=None, period_s=p.period_s, with_doppler=False
        )
        assert ro.order == 1 and np.isnan(ro.sigma[1])


def test_range_only_velocity_beats_doppler_only_at_k8_rls3() -> None:
    """The paper: the range-only σVr drops below σVr only at k = 7–8 (RLS3). Closed forms:
    17.03 m/s at k = 7, 14.04 m/s at k = 8, against σVr = 15 m/s."""
    sigma_vr = PRESETS["RLS3"].sigma_vr_mps
    s = _analytic_sigma("RLS3", False)[:, 1]
    first = int(np.flatnonzero(s < sigma_vr)[0]) + 1
    assert first in (7, 8)
    assert s[6] == pytest.approx(17.03, abs=0.01) and s[7] == pytest.approx(14.04, abs=0.01)


def test_acceleration_one_scan_earlier_with_doppler() -> None:
    for name in PRESETS:
        a_dop = _analytic_sigma(name, True)[:, 2]
        a_ro = _analytic_sigma(name, False)[:, 2]
        assert int(np.flatnonzero(np.isfinite(a_dop))[0]) + 1 == 2
        assert int(np.flatnonzero(np.isfinite(a_ro))[0]) + 1 == 3


# --------------------------------------------------------------------------------------------
# Monte Carlo against the analytic σ
# --------------------------------------------------------------------------------------------

MC_TRIALS = 50_000
# Every σ and mean comparison uses z = 4.5: P(|Z| > 4.5) = 6.8e-6 each. Six radars × two
# variants × ≤ 60 (k, parameter) cells × (σ, mean) ≈ 1400 comparisons, so by the union bound
# a correct implementation fails for fewer than 1 % of seeds (the seed is fixed, so the test
# itself is deterministic). At N = 50 000 the σ tolerance is 4.5/sqrt(2N) ≈ 1.4 % of σ.
Z = 4.5


@pytest.fixture(scope="module")
def gorshkov() -> GorshkovResult:
    return run_gorshkov(trials=MC_TRIALS, seed=20160601)


def test_monte_carlo_sigma_matches_analytic(gorshkov: GorshkovResult) -> None:
    n = gorshkov.trials
    for rad in gorshkov.radars:
        for stats in (rad.range_only, rad.range_doppler):
            sig = stats.sigma_analytic
            tol = Z * sig / np.sqrt(2.0 * (n - 1))  # SE of a Gaussian sample std
            assert np.array_equal(np.isnan(stats.sigma_mc), np.isnan(sig))
            ok = np.isnan(sig) | (np.abs(stats.sigma_mc - sig) <= tol)
            assert ok.all(), (rad.preset.name, np.argwhere(~ok))
            # Power: the band is narrow enough to reject a σ wrong by 3 %.
            fitted = np.isfinite(sig)
            assert np.all(np.abs(stats.sigma_mc - 1.03 * sig)[fitted] > tol[fitted])


def test_monte_carlo_mean_error_matches_analytic_bias(gorshkov: GorshkovResult) -> None:
    """Unbiased for every full-order fit; the reduced two-point range-only velocity is off by
    −a T/2 (the estimates are made from the noisy measurements, truth subtracted)."""
    n = gorshkov.trials
    for rad in gorshkov.radars:
        T = rad.preset.period_s
        for stats in (rad.range_only, rad.range_doppler):
            full = stats.order == 3
            assert np.all(np.abs(stats.bias_analytic[full]) < 1e-8)
            tol = Z * stats.sigma_analytic / np.sqrt(n)
            ok = np.isnan(tol) | (np.abs(stats.bias_mc - stats.bias_analytic) <= tol)
            assert ok.all(), (rad.preset.name, np.argwhere(~ok))
        assert rad.range_only.bias_analytic[1, 1] == pytest.approx(-gorshkov.a0 * T / 2)


def test_monte_carlo_layout_and_gains(gorshkov: GorshkovResult) -> None:
    assert [r.preset.name for r in gorshkov.radars] == list(PRESETS)
    assert list(gorshkov.ks) == list(range(1, 21))
    for rad in gorshkov.radars:
        assert list(rad.range_doppler.order[:3]) == [2, 3, 3]
        assert list(rad.range_only.order[:3]) == [1, 2, 3]
        assert rad.gain_mc.shape == rad.gain_analytic.shape == (20, 3)
        undefined = np.isnan(rad.gain_analytic)
        assert np.array_equal(np.isnan(rad.gain_mc), undefined)
        # Vr gain undefined at k = 1 and a gain at k ≤ 2 (range only has none); else defined.
        assert np.array_equal(np.argwhere(undefined), [[0, 1], [0, 2], [1, 2]])
    rls1 = gorshkov.radars[0]
    assert int(np.argmax(rls1.gain_mc[:, 0])) + 1 == 3


@pytest.mark.parametrize(("name", "k"), [(name, k) for name, k, _ in PAPER_RANGE_GAIN_PEAKS])
def test_monte_carlo_range_gain_peak_matches_analytic(
    gorshkov: GorshkovResult, name: str, k: int
) -> None:
    """The Monte Carlo gain at the peak agrees with the analytic one within Z standard errors.

    G = 100 (1 − ρ̂) with ρ̂ = σ̂_rd / σ̂_ro, the ratio of the two sample σ of the range error.
    Both errors are linear in the same noise (common random numbers), e_ro = w_ro·z and
    e_rd = w_rd·z, with correlation c = w_ro Σ w_rd / (σ_ro σ_rd). For Gaussian errors and n
    trials Var(log σ̂) = 1/(2n) and Cov(log σ̂_ro, log σ̂_rd) = c²/(2n), so by the delta
    method Var(log ρ̂) = (1 − c²)/n and SE(G) = 100 ρ (1 − c²)^½ / √n. (Here c = ρ: the
    range + Doppler fit is the best linear unbiased estimate from a superset of the data, so
    its error is uncorrelated with the difference e_ro − e_rd and Cov(e_ro, e_rd) = σ_rd².)"""
    rad = gorshkov.radars[list(PRESETS).index(name)]
    p = rad.preset
    fit_ro = finite_memory_fit(
        k,
        sigma_r_m=p.sigma_r_m,
        sigma_vr_mps=p.sigma_vr_mps,
        period_s=p.period_s,
        with_doppler=False,
    )
    fit_rd = finite_memory_fit(
        k,
        sigma_r_m=p.sigma_r_m,
        sigma_vr_mps=p.sigma_vr_mps,
        period_s=p.period_s,
        with_doppler=True,
    )
    cov = p.sigma_r_m**2 * float(fit_ro.W[0, :k] @ fit_rd.W[0, :k])
    c = cov / (fit_ro.sigma[0] * fit_rd.sigma[0])
    ratio = fit_rd.sigma[0] / fit_ro.sigma[0]
    assert c == pytest.approx(ratio, rel=1e-9)
    se = 100.0 * ratio * math.sqrt((1.0 - c * c) / gorshkov.trials)
    analytic, mc = rad.gain_analytic[k - 1, 0], rad.gain_mc[k - 1, 0]
    assert analytic == pytest.approx(100.0 * (1.0 - ratio), rel=1e-12)
    assert abs(mc - analytic) <= Z * se, (name, k, mc, analytic, se)


def test_monte_carlo_is_reproducible() -> None:
    a = run_gorshkov(["RLS2", "RLS5"], trials=3000, seed=7, block=1000)
    b = run_gorshkov(["RLS2", "RLS5"], trials=3000, seed=7, block=1000)
    c = run_gorshkov(["RLS2", "RLS5"], trials=3000, seed=8, block=1000)
    for ra, rb, rc in zip(a.radars, b.radars, c.radars, strict=True):
        assert np.array_equal(ra.range_doppler.sigma_mc, rb.range_doppler.sigma_mc, equal_nan=True)
        assert not np.array_equal(
            ra.range_doppler.sigma_mc, rc.range_doppler.sigma_mc, equal_nan=True
        )


# --------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"k": 0}, "k"),
        ({"k": -3}, "k"),
        ({"k": 2.5}, "k"),
        ({"sigma_r_m": 0.0}, "sigma_r_m"),
        ({"sigma_r_m": -250.0}, "sigma_r_m"),
        ({"sigma_r_m": math.nan}, "sigma_r_m"),
        ({"sigma_vr_mps": 0.0}, "sigma_vr_mps"),
        ({"sigma_vr_mps": math.inf}, "sigma_vr_mps"),
        ({"sigma_vr_mps": None}, "sigma_vr_mps"),
        ({"period_s": 0.0}, "period_s"),
        ({"period_s": math.nan}, "period_s"),
        ({"sigma_r_m": 1e-200}, "sigma_r_m"),
        ({"sigma_vr_mps": 1e-200}, "C0"),
        ({"method": "exact"}, "method"),
        ({"with_doppler": "yes"}, "with_doppler"),
    ],
)
def test_bad_fit_input(kwargs: dict, name: str) -> None:
    args = {
        "k": 4,
        "sigma_r_m": 250.0,
        "sigma_vr_mps": 15.0,
        "period_s": 10.0,
        "with_doppler": True,
        "method": "closed",
    } | kwargs
    with pytest.raises(ParameterError) as info:
        finite_memory_fit(**args)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(name + " "), msg


def test_bad_preset_and_experiment_input() -> None:
    with pytest.raises(
        ParameterError,
        match=r"^preset must be one of RLS1, RLS2, RLS3, RLS4, RLS5,"
        r" RLS6 \(got 'RLS7'\)$",
    ):
        preset("RLS7")
    for kwargs, name in [
        ({"presets": ["RLS9"]}, "preset"),
        ({"trials": 1}, "trials"),
        ({"ks": [0]}, "k"),
        ({"ks": [21]}, "k"),
        ({"seed": -1}, "seed"),
        ({"a0": math.nan}, "a0"),
        ({"presets": []}, "presets"),
    ]:
        with pytest.raises(ParameterError, match=rf"^{name} "):
            run_gorshkov(**({"trials": 10} | kwargs))
    with pytest.raises(ParameterError, match=r"^radial_velocities must be None"):
        finite_memory_estimate(
            np.zeros(3),
            np.zeros(3),
            finite_memory_fit(
                3, sigma_r_m=1.0, sigma_vr_mps=None, period_s=1.0, with_doppler=False
            ),
        )


def test_monte_carlo_bands_cover_the_analytic_values_at_95_percent() -> None:
    """The σ (χ²) and gain (jackknife) bands of ``run_gorshkov`` against their exact values
    sqrt(R_ii) and the analytic gain, over R independent seeds: each cell's coverage count is
    binomial(R, 0.95) if the bands are right, so it must be within 3.5 of its standard
    deviations √(0.95 · 0.05 / R) of 0.95: a false alarm rate of 5e-4 per cell, under 1% for
    the ≤ 17 cells; a band of half or twice the width (68% or ~100%) fails."""
    replicates = 150
    covered_sigma, covered_gain = [], []
    for seed in range(replicates):
        res = run_gorshkov(["RLS3"], trials=640, seed=seed, ks=(2, 4, 8), n_points=8)
        rad = res.radars[0]
        st = rad.range_doppler
        covered_sigma.append(
            (st.sigma_mc_ci95_lo <= st.sigma_analytic) & (st.sigma_analytic <= st.sigma_mc_ci95_hi)
        )
        g = rad.gain_analytic
        covered_gain.append((rad.gain_mc_ci95_lo <= g) & (g <= rad.gain_mc_ci95_hi))
    tol = 3.5 * np.sqrt(0.95 * 0.05 / replicates)
    sigma_cov = np.mean(covered_sigma, axis=0)
    gain_cov = np.mean(covered_gain, axis=0)
    fitted = np.isfinite(rad.gain_analytic) & (rad.gain_analytic > 0)
    assert np.all(np.abs(sigma_cov[np.isfinite(st.sigma_analytic)] - 0.95) <= tol), sigma_cov
    assert np.all(np.abs(gain_cov[fitted] - 0.95) <= tol), gain_cov
