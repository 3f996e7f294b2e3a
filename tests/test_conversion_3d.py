"""The second-order tool (``core.conversion.second_order``), every conversion in 3D
(``core.conversion.spatial``, ``core.conversion.modified``) and ``radarviz track`` with each
method on 3D plots (the math: docs/conversion.md, sections 2, 4 and 6).

* **Second order.** The analytic Jacobian and Hessians of the spherical and polar maps agree
  with central differences within the differences' own error bound; the tool reproduces the
  2D ``seed`` point (1e-12) and, with the other sign, the opposite correction; for a quadratic
  h, where the second-order mean and covariance are exact, they match a Monte Carlo.
* **Given the truth** (many measurements of one target): the mean converted error of each 3D
  method equals its closed form (test-side formulas from the one-angle moments, not radarviz
  calls): naive and ``seed`` biased (the negative control: both biases detected; ``seed``'s
  twice naive's to first order), ``cmkf_d`` at O(s²), ``ucm``/``ducm``/``mucm`` unbiased;
  the covariance of the error equals D C D, and ``ducm``'s R at a prediction on the truth.
* **Given the measurement** (the truth drawn from its flat-prior posterior): the averaged
  covariance is the posterior average of the true-conditioned one, ``mucm``'s R is the
  posterior mean-square error of ucm's point (ucm's own R is rejected), and the ``seed`` point
  is the posterior mean to second order.
* **Zero elevation**, σε = 0: each 3D form is its 2D form with z = 0 (1e-12).
* **Registry**: each method starts and updates a (2, 3) batch of 3D plots as a flat batch.
* **Tracks**: ``radarviz simulate --preset fusion`` on its straight-line leg, then ``radarviz
  track`` with every method: finite tracks whose position RMSE is below the raw converted
  measurements' over independent files, by more than Z standard errors of the mean ratio.

Monte Carlo tolerances are Z standard errors of each estimate, with Z the Bonferroni bound for
at most ``MAX_STAT_CHECKS`` comparisons at family level 1e-3 (Z ≈ 4.5): a correct
implementation fails any of them, for fresh seeds, with probability < 1e-3. Seeds are fixed.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

from radarviz.core.conversion import modified as mu
from radarviz.core.conversion import planar as cv
from radarviz.core.conversion import second_order as so
from radarviz.core.conversion import spatial as cv3
from radarviz.core.filters.methods import ALL_METHODS, METHODS, METHODS_3D, PolarNoise, PolarPlot
from radarviz.core.filters.predict import cv_predict
from radarviz.core.velocity.estimate import BASELINE_TARGET_M, BASELINE_VELOCITY_MPS
from radarviz.viz_app.cli.main import main

DEG = math.pi / 180.0
EPS = float(np.finfo(float).eps)

# ---------------------------------------------------------------------------------------------
# Monte Carlo machinery
# ---------------------------------------------------------------------------------------------

FAMILY_ALPHA = 1e-3
MAX_STAT_CHECKS = 150
Z = float(norm.isf(FAMILY_ALPHA / (2 * MAX_STAT_CHECKS)))
_STATS = {"checks": 0}
N_MC = 1_000_000


@pytest.fixture(scope="module", autouse=True)
def _stat_check_budget() -> Iterator[None]:
    """The Bonferroni argument holds only if the file makes at most MAX_STAT_CHECKS checks."""
    yield
    print(f"test_conversion_3d: {_STATS['checks']} Monte Carlo checks, Z = {Z:.2f}")
    assert _STATS["checks"] <= MAX_STAT_CHECKS, f"{_STATS['checks']} checks > {MAX_STAT_CHECKS}"


def check_mc(estimate, expected, se, what: str) -> None:
    """|estimate − expected| ≤ Z·se elementwise; each element counts as one check."""
    estimate, expected, se = np.broadcast_arrays(
        np.asarray(estimate, float), np.asarray(expected, float), np.asarray(se, float)
    )
    _STATS["checks"] += estimate.size
    assert np.all(se > 0), f"{what}: zero standard error"
    err = np.abs(estimate - expected) / se
    assert np.all(err <= Z), f"{what}: MC {estimate} vs {expected}, |error|/se = {err} > {Z:.2f}"


def mean_se(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample mean over axis 0 and its standard error."""
    return samples.mean(axis=0), samples.std(axis=0, ddof=1) / math.sqrt(samples.shape[0])


def upper(a: np.ndarray) -> np.ndarray:
    return a[..., *np.triu_indices(a.shape[-1])]


def moment_se(e: np.ndarray, centred: bool) -> tuple[np.ndarray, np.ndarray]:
    """Upper entries of the second moment E[e eᵀ] (or the covariance, ``centred``) of samples
    e (N, d), with their standard errors std(e_i e_j)/√N (centring changes it by O(1/N))."""
    if centred:
        e = e - e.mean(axis=0)
    i, j = np.triu_indices(e.shape[1])
    return mean_se(e[:, i] * e[:, j])


def rel_entrywise(a: np.ndarray, ref: np.ndarray) -> float:
    """max |a − ref|_ij / sqrt(ref_ii ref_jj) (entries of a covariance at their own scale)."""
    d = np.sqrt(np.abs(np.diagonal(ref, axis1=-2, axis2=-1)))
    return float(np.max(np.abs(a - ref) / (d[..., :, None] * d[..., None, :])))


# ---------------------------------------------------------------------------------------------
# Test-side formulas (from the one-angle moments E[cos θ̂] = e^(−s/2) cos θ, not radarviz calls)
# ---------------------------------------------------------------------------------------------


def point_3d(r, az, el) -> np.ndarray:
    """x = r cos ε cos β, y = r cos ε sin β, z = r sin ε; (...) → (..., 3)."""
    return np.stack(
        np.broadcast_arrays(
            r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)
        ),
        axis=-1,
    )


def axis_variances(sa: float, se: float) -> np.ndarray:
    """The angle variance in each direction cosine: sβ + sε on x and y, sε on z."""
    return np.array([sa**2 + se**2, sa**2 + se**2, se**2])


def shrink(sa: float, se: float) -> np.ndarray:
    """L: E[naive point | truth] = L ∘ truth, L = e^(−s/2) per axis."""
    return np.exp(-axis_variances(sa, se) / 2)


def scales(method: str, sa: float, se: float) -> np.ndarray:
    """Each method's point is κ ∘ naive point (seed: to the second-order term's first order,
    which for this map is exact; see test_seed_3d_is_the_second_order_tool)."""
    s = axis_variances(sa, se)
    L = np.exp(-s / 2)
    return {
        "naive": np.ones(3),
        "seed": 1 - s / 2,
        "cmkf_d": 1 - (L * L - L),
        "ucm": 1 / L,
        "ducm": 1 / L,
        "mucm": 1 / L,
    }[method]


def draws_3d(rng, n: int, r, az, el, sr, sa, se) -> tuple[np.ndarray, ...]:
    return (
        r + sr * rng.standard_normal(n),
        az + sa * rng.standard_normal(n),
        el + se * rng.standard_normal(n),
    )


def convert(method: str, r, az, el, sr, sa, se, predicted=None):
    """Every 3D conversion by name (mucm lives beside the registered five)."""
    sig = {"sigma_r_m": sr, "sigma_beta_rad": sa, "sigma_elevation_rad": se}
    if method == "mucm":
        return mu.convert_mucm_3d(r, az, el, **sig)
    return cv3.convert_3d(method, r, az, el, **sig, predicted_xyz=predicted)


EVERY_CONVERSION_3D = (*cv3.CONVERSIONS_3D, "mucm")

# r, azimuth, elevation, σr, σβ, σε: the fusion geometry, then large angle errors, where the
# O(s²) terms are many standard errors large, so the checks have power.
CONFIGS_3D = (
    (60e3, 0.6, 0.2, 100.0, 0.3 * DEG, 0.5 * DEG),
    (10e3, 2.5, -1.2, 30.0, 0.2, 0.25),
    (50e3, -2.0, 0.9, 100.0, 0.3, 0.15),
)


# ---------------------------------------------------------------------------------------------
# 1. The second-order tool
# ---------------------------------------------------------------------------------------------

DERIV_POINTS = np.array([[150e3, 0.0, 0.0], [60e3, 0.6, 0.2], [10e3, 2.5, -1.2], [2e3, -3.0, 1.5]])
#: Central-difference steps in (r, β, ε): m, rad, rad.
STEP = np.array([10.0, 1e-4, 1e-4])


def _fd_bound(r: np.ndarray, order: int) -> np.ndarray:
    """Error bound of ``numerical_jacobian`` (order 1: (..., 3, 3)) or ``numerical_hessians``
    (order 2: (..., 3, 3, 3)) for h = r u: rounding eps·|h| / (step product), |h| = r, plus
    truncation step² × the next derivatives, which vanish with two r's, are ≤ 1 with one r and
    ≤ r with angles only (u is linear in r and trigonometric in the angles)."""
    d, angle = STEP, np.arange(3) > 0
    rr = r[..., None, None]
    if order == 1:
        bound = EPS * rr / d + np.where(angle, d * d, 0.0) * rr  # (..., 1, 3) over k
        return np.broadcast_to(bound, (*r.shape, 3, 3))
    dj2 = np.where(angle, d * d, 0.0)[:, None]
    dk2 = np.where(angle, d * d, 0.0)[None, :]
    n_r = (~angle)[:, None].astype(int) + (~angle)[None, :].astype(int)
    size = np.where(n_r == 0, rr[..., None], 1.0)  # (..., 1, 3, 3)
    bound = EPS * rr[..., None] / (d[:, None] * d[None, :]) + (dj2 + dk2) * size
    return np.broadcast_to(bound, (*r.shape, 3, 3, 3))


def test_spherical_derivatives_match_finite_differences() -> None:
    """Analytic J and H of (r, β, ε) → r u against central differences, batched over points,
    within 4× the differences' error bound (``_fd_bound``; 4 covers the constants it leaves
    out). Power: a wrong sign of any non-zero entry (an error of 2|H|) would exceed it."""
    J = so.spherical_jacobian(DERIV_POINTS)
    H = so.spherical_hessians(DERIV_POINTS)
    assert J.shape == (4, 3, 3) and H.shape == (4, 3, 3, 3)
    Jn = so.numerical_jacobian(so.spherical_map, DERIV_POINTS, STEP)
    Hn = so.numerical_hessians(so.spherical_map, DERIV_POINTS, STEP)
    r = DERIV_POINTS[:, 0]
    j_tol, h_tol = 4 * _fd_bound(r, 1), 4 * _fd_bound(r, 2)
    assert np.all(np.abs(J - Jn) <= j_tol)
    assert np.all(np.abs(H - Hn) <= h_tol)
    nonzero = np.abs(H) > 1e-12 * r[:, None, None, None]
    assert np.all(2 * np.abs(H)[nonzero] > h_tol[nonzero])
    np.testing.assert_array_equal(H, np.swapaxes(H, -1, -2))  # symmetric in (j, k)
    # The polar map is the (x, y) × (r, β) block at zero elevation.
    polar = DERIV_POINTS[:, :2]
    Hp = so.polar_hessians(polar)
    assert np.all(
        np.abs(Hp - so.numerical_hessians(so.polar_map, polar, STEP[:2])) <= (h_tol[:, :2, :2, :2])
    )
    np.testing.assert_array_equal(
        Hp, so.spherical_hessians(np.concatenate([polar, np.zeros((4, 1))], axis=-1))[:, :2, :2, :2]
    )


SEED_GRID = [
    (150e3, 0.0, 250.0, 1 * DEG),
    (150e3, 0.7, 250.0, 2 * DEG),
    (10e3, 2.5, 30.0, 0.3),
    (1e7, 3.0, 0.1, 1e-4),
    (2e3, -3.0, 5.0, 5 * DEG),
]


def test_second_order_tool_reproduces_the_2d_seed() -> None:
    """Prosov eq. 7 applied to the polar map with the printed sign is ``seed``'s point (eq. 10)
    to 1e-12; the debiased sign is the opposite correction r̂ (1 + s/2)(cos β̂, sin β̂)."""
    r, beta, sr, sigma_beta_rad = (np.array(v) for v in zip(*SEED_GRID, strict=True))
    theta = np.stack([r, beta], axis=-1)  # a batch of five
    cov = np.zeros((len(r), 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = sr**2, sigma_beta_rad**2
    args = (so.polar_map(theta), so.polar_jacobian(theta), so.polar_hessians(theta), cov)
    printed = so.second_order_convert(*args, sign="printed")
    seed = cv.convert("seed", r, beta, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad)
    assert np.max(np.abs(printed.point - seed.z) / r[:, None]) < 1e-12
    debiased = so.second_order_convert(*args, sign="debiased").point
    naive = r[:, None] * np.stack([np.cos(beta), np.sin(beta)], axis=-1)
    np.testing.assert_allclose(
        debiased, naive * (1 + sigma_beta_rad**2 / 2)[:, None], rtol=1e-12, atol=1e-9
    )
    with pytest.raises(ValueError, match="sign must be one of debiased, printed"):
        so.second_order_correction(args[2], cov, sign="plus")  # type: ignore[arg-type]


def test_seed_3d_is_the_second_order_tool() -> None:
    """The 3D seed point is the tool on the spherical map: κ = (1 − (sβ+sε)/2, …, 1 − sε/2)."""
    for r, az, el, sr, sa, se in CONFIGS_3D:
        c = convert("seed", r, az, el, sr, sa, se)
        want = scales("seed", sa, se) * point_3d(r, az, el)
        assert np.max(np.abs(c.z - want)) < 1e-12 * r
        # and the general second-order tool's term on the naive point gives that point too
        sig = {"sigma_r_m": sr, "sigma_beta_rad": sa, "sigma_elevation_rad": se}
        term = cv3.seed_correction_3d(r, az, el, **sig)
        assert np.max(np.abs(c.z - (point_3d(r, az, el) + term))) < 1e-12 * r


def _quadratic(theta: np.ndarray) -> np.ndarray:
    """A quadratic map (..., 3) → (..., 2): its second-order expansion is exact."""
    a, b, c = theta[..., 0], theta[..., 1], theta[..., 2]
    return np.stack([a * b + 3.0 * c * c, b * b - 2.0 * a * c + a], axis=-1)


def test_second_order_moments_are_exact_for_a_quadratic() -> None:
    """With h quadratic and Gaussian noise, E[h(θ̂)] = h(θ) + ½ tr(H_i Σ) and Cov h(θ̂) =
    J Σ Jᵀ + ½ tr(H_i Σ H_j Σ) exactly: Monte Carlo with correlated Σ. Power: the first-order
    covariance J Σ Jᵀ alone is rejected."""
    theta = np.array([0.5, -1.0, 0.3])
    A = np.array([[0.4, 0.0, 0.0], [0.3, 0.5, 0.0], [-0.2, 0.1, 0.3]])
    cov = A @ A.T
    rng = np.random.default_rng(41)
    draws = theta + rng.standard_normal((N_MC, 3)) @ A.T
    h = _quadratic(draws)
    J = so.numerical_jacobian(_quadratic, theta, np.full(3, 1e-3))  # exact for a quadratic
    H = so.numerical_hessians(_quadratic, theta, np.full(3, 1e-3))
    H_exact = np.array(
        [
            [[0, 1, 0], [1, 0, 0], [0, 0, 6]],
            [[0, 0, -2], [0, 2, 0], [-2, 0, 0]],
        ],
        dtype=float,
    )
    np.testing.assert_allclose(H, H_exact, atol=1e-7)
    moments = so.second_order_convert(_quadratic(theta), J, H_exact, cov, sign="debiased")
    mean_term = so.second_order_term(H_exact, cov)
    m, m_se = mean_se(h)
    check_mc(m, _quadratic(theta) + mean_term, m_se, "quadratic mean")
    # The debiased point removes exactly that term.
    np.testing.assert_allclose(moments.point, _quadratic(theta) - mean_term, rtol=1e-15)
    c, c_se = moment_se(h, centred=True)
    check_mc(c, upper(moments.cov), c_se, "quadratic covariance")
    first = J @ cov @ J.T
    assert np.any(np.abs(c - upper(first)) > Z * c_se)


# ---------------------------------------------------------------------------------------------
# 2. Given the truth: bias and covariance of every 3D conversion
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("cfg", CONFIGS_3D, ids=str)
def test_3d_conversions_given_truth(cfg: tuple[float, ...]) -> None:
    r, az, el, sr, sa, se = cfg
    rng = np.random.default_rng([18, CONFIGS_3D.index(cfg)])
    rh, ah, eh = draws_3d(rng, N_MC, r, az, el, sr, sa, se)
    truth = point_3d(r, az, el)
    L = shrink(sa, se)
    large = sa >= 0.1  # the configurations where O(s²) effects are many standard errors
    naive_bias = (L - 1) * truth
    points = {}
    for method in ("naive", "seed", "cmkf_d", "ucm"):  # ducm and mucm have ucm's point
        points[method] = z = convert(method, rh, ah, eh, sr, sa, se).z
        assert z.shape == (N_MC, 3) and np.all(np.isfinite(z))
        m, m_se = mean_se(z - truth)
        expected = (scales(method, sa, se) * L - 1) * truth
        check_mc(m, expected, m_se, f"{method} mean error {cfg}")
        if method in ("naive", "seed"):  # negative control: the bias is detected
            assert np.any(np.abs(m) > Z * m_se), f"{method} bias not detected {cfg}"
        if method == "seed":  # Prosov's sign: twice the naive bias, to first order in s
            s = axis_variances(sa, se)
            np.testing.assert_allclose(expected, 2 * naive_bias, rtol=2 * s.max(), atol=1e-9)
        if method == "cmkf_d" and large:  # debiased to O(s²), and that residue is detected
            assert np.any(np.abs(m) > Z * m_se)
            assert np.all(np.abs(expected) <= 0.25 * np.abs(naive_bias) + 1e-9)
    for method in ("ducm", "mucm"):
        head = slice(0, 1000)
        c = convert(method, rh[head], ah[head], eh[head], sr, sa, se, predicted=truth)
        np.testing.assert_array_equal(c.z, points["ucm"][head])
    # Covariance of the error given the truth: D C D with D = diag(κ) and C the naive point's
    # exact covariance (itself checked by Monte Carlo in tests/test_conversion.py).
    C = cv3.naive_cov_given_truth_3d(
        r, az, el, sigma_r_m=sr, sigma_beta_rad=sa, sigma_elevation_rad=se
    )
    for method in ("cmkf_d", "ucm"):
        d = scales(method, sa, se)
        c, c_se = moment_se(points[method], centred=True)
        check_mc(c, upper(d[:, None] * C * d[None, :]), c_se, f"{method} cov {cfg}")
    # ducm's R about a prediction on the truth is that covariance, whatever the measurement.
    ducm = convert("ducm", rh[:100], ah[:100], eh[:100], sr, sa, se, predicted=truth)
    d = scales("ducm", sa, se)
    assert rel_entrywise(ducm.R, d[:, None] * C * d[None, :]) < 1e-13


# ---------------------------------------------------------------------------------------------
# 3. Given the measurement: the averaged covariance, mucm and the seed point as posterior mean
# ---------------------------------------------------------------------------------------------


def _posterior_truths(rng, cfg) -> tuple[np.ndarray, ...]:
    """(r, β, ε) drawn from the flat-prior posterior given the measurement: N(θ̂, Σ)."""
    r, az, el, sr, sa, se = cfg
    return draws_3d(rng, N_MC, r, az, el, sr, sa, se)


@pytest.mark.parametrize("cfg", CONFIGS_3D, ids=str)
def test_averaged_cov_3d_is_the_posterior_average(cfg: tuple[float, ...]) -> None:
    """averaged_cov_3d(θ̂) = E[C(θ) | θ̂]: draw θ from the posterior, then a measurement θ̂' of
    it; the error of its naive point about E[naive | θ] = L ∘ p(θ) has second moment
    E[C(θ)]. Power at large σ: C(θ̂) (the true-conditioned form at the measurement) is
    rejected."""
    r, az, el, sr, sa, se = cfg
    rng = np.random.default_rng([19, CONFIGS_3D.index(cfg)])
    tr, ta, te = _posterior_truths(rng, cfg)
    mr, ma, me = draws_3d(rng, N_MC, 0.0, 0.0, 0.0, sr, sa, se)
    err = point_3d(tr + mr, ta + ma, te + me) - shrink(sa, se) * point_3d(tr, ta, te)
    m2, m2_se = moment_se(err, centred=False)
    sig = {"sigma_r_m": sr, "sigma_beta_rad": sa, "sigma_elevation_rad": se}
    avg = cv3.averaged_cov_3d(r, az, el, **sig)
    check_mc(m2, upper(avg), m2_se, f"averaged cov 3D {cfg}")
    # seed and cmkf_d report it.
    for method in ("seed", "cmkf_d"):
        np.testing.assert_array_equal(convert(method, r, az, el, sr, sa, se).R, avg)
    if sa >= 0.1:
        at_measurement = cv3.naive_cov_given_truth_3d(r, az, el, **sig)
        assert np.any(np.abs(m2 - upper(at_measurement)) > Z * m2_se)


@pytest.mark.parametrize("cfg", CONFIGS_3D, ids=str)
def test_mucm_3d_is_the_posterior_mean_square_error(cfg: tuple[float, ...]) -> None:
    """mucm's R(θ̂) = E[(z_u − p)(z_u − p)ᵀ | θ̂], the truth p from the posterior; ucm's R at the
    measurement is rejected at large σ. The seed point is the posterior mean E[p | θ̂] =
    L ∘ r̂ û to second order: nearer it than the naive point by a factor O(s)."""
    r, az, el, sr, sa, se = cfg
    rng = np.random.default_rng([20, CONFIGS_3D.index(cfg)])
    p = point_3d(*_posterior_truths(rng, cfg))
    mucm = convert("mucm", r, az, el, sr, sa, se)
    ucm = convert("ucm", r, az, el, sr, sa, se)
    np.testing.assert_array_equal(mucm.z, ucm.z)
    m2, m2_se = moment_se(mucm.z - p, centred=False)
    check_mc(m2, upper(mucm.R), m2_se, f"mucm R {cfg}")
    if sa >= 0.1:
        assert np.any(np.abs(m2 - upper(ucm.R)) > Z * m2_se)
    m, m_se = mean_se(p)
    post_mean = shrink(sa, se) * point_3d(r, az, el)
    check_mc(m, post_mean, m_se, f"posterior mean {cfg}")
    s = axis_variances(sa, se).max()
    seed = convert("seed", r, az, el, sr, sa, se).z
    naive = point_3d(r, az, el)
    assert np.max(np.abs(seed - post_mean)) <= s * np.max(np.abs(naive - post_mean))


def test_mucm_2d_is_duan_han_li() -> None:
    """The 2D mucm covariance equals Duan, Han and Li's printed form (1e-11: their form
    subtracts O(r̂²) terms, losing ~eps/s), and its Monte Carlo posterior check."""
    for r, beta, sr, sigma_beta_rad in [(150e3, 0.7, 250.0, 2 * DEG), (10e3, 2.5, 30.0, 0.3)]:
        s = sigma_beta_rad * sigma_beta_rad
        c = mu.convert_mucm(r, beta, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad)
        k = (math.exp(s) - 2) * r * r
        h = 0.5 * (r * r + sr * sr)
        e2 = math.exp(-2 * s)
        duan = np.array(
            [
                [
                    k * math.cos(beta) ** 2 + h * (1 + e2 * math.cos(2 * beta)),
                    k * math.sin(beta) * math.cos(beta) + h * e2 * math.sin(2 * beta),
                ],
                [0.0, k * math.sin(beta) ** 2 + h * (1 - e2 * math.cos(2 * beta))],
            ]
        )
        duan[1, 0] = duan[0, 1]
        assert rel_entrywise(c.R, duan) < 1e-11
        rng = np.random.default_rng(21)
        tr, tb = (
            r + sr * rng.standard_normal(N_MC),
            beta + sigma_beta_rad * rng.standard_normal(N_MC),
        )
        err = c.z - np.stack([tr * np.cos(tb), tr * np.sin(tb)], axis=-1)
        m2, m2_se = moment_se(err, centred=False)
        check_mc(m2, upper(c.R), m2_se, f"mucm 2D R {r, beta, sr, sigma_beta_rad}")


# ---------------------------------------------------------------------------------------------
# 4. Zero elevation: every 3D form is its 2D form
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", EVERY_CONVERSION_3D)
def test_3d_reduces_to_2d_at_zero_elevation(method: str) -> None:
    """ε̂ = 0 and σε = 0: the x–y part equals the 2D conversion to 1e-12, z and its rows are 0
    (a batch of five, including r/σr = 1e8, where only cancellation-free formulas pass)."""
    r, beta, sr, sigma_beta_rad = (np.array(v) for v in zip(*SEED_GRID, strict=True))
    pred = 1.01 * r[:, None] * np.stack([np.cos(beta + 0.01), np.sin(beta + 0.01)], axis=-1)
    sig2 = {"sigma_r_m": sr, "sigma_beta_rad": sigma_beta_rad}
    if method == "mucm":
        two = mu.convert_mucm(r, beta, **sig2)
    else:
        two = cv.convert(method, r, beta, **sig2, predicted_xy=pred)
    pred3 = np.concatenate([pred, np.zeros((len(r), 1))], axis=-1)
    three = convert(method, r, beta, np.zeros_like(r), sr, sigma_beta_rad, 0.0, predicted=pred3)
    assert np.max(np.abs(three.z[:, :2] - two.z) / r[:, None]) < 1e-12
    assert rel_entrywise(three.R[:, :2, :2], two.R) < 1e-12
    assert np.all(three.z[:, 2] == 0) and np.all(three.R[:, 2, :] == 0)


def test_3d_conversions_broadcast_over_a_batch() -> None:
    """A (2, 3) batch gives the six single conversions (each method's arrays of any shape)."""
    rng = np.random.default_rng(22)
    r = 50e3 + 100 * rng.standard_normal((2, 3))
    az, el = 0.4 + 0.01 * rng.standard_normal((2, 3)), 0.2 + 0.01 * rng.standard_normal((2, 3))
    pred = point_3d(r + 50, az, el)
    for method in EVERY_CONVERSION_3D:
        grid = convert(method, r, az, el, 80.0, 0.01, 0.02, predicted=pred)
        for idx in np.ndindex(2, 3):
            one = convert(method, r[idx], az[idx], el[idx], 80.0, 0.01, 0.02, predicted=pred[idx])
            np.testing.assert_allclose(grid.z[idx], one.z, rtol=1e-15)
            np.testing.assert_allclose(grid.R[idx], one.R, rtol=1e-14, atol=1e-9)
    with pytest.raises(ValueError, match="method ducm needs predicted_xyz"):
        cv3.convert_3d("ducm", r, az, el, sigma_r_m=1, sigma_beta_rad=1, sigma_elevation_rad=1)
    with pytest.raises(ValueError, match="method must be one of naive, seed, cmkf_d, ucm, ducm"):
        cv3.convert_3d("magic", r, az, el, sigma_r_m=1, sigma_beta_rad=1, sigma_elevation_rad=1)


# ---------------------------------------------------------------------------------------------
# 5. Every method tracks 3D plots
# ---------------------------------------------------------------------------------------------


def test_every_method_exists_in_3d() -> None:
    assert METHODS_3D == ALL_METHODS and all(3 in m.dims for m in METHODS.values())


@pytest.mark.parametrize("name", ALL_METHODS)
def test_every_method_starts_and_updates_a_3d_batch_of_any_shape(name: str) -> None:
    """Each method on a (2, 3) batch of 3D plots, one radar away from the origin, gives its six
    tracks of a flat batch bit for bit (``ducm`` converts about each row's own prediction)."""
    rng = np.random.default_rng(23)
    r = 80e3 + rng.normal(0, 100.0, (2, 3))
    b, e = 0.4 + rng.normal(0, 0.01, (2, 3)), 0.1 + rng.normal(0, 0.01, (2, 3))
    noise, site = PolarNoise(100.0, 0.01, 0.02), np.array([1e3, -2e3, 50.0])
    kind = METHODS[name]
    grid = kind.start(PolarPlot(r, b, e), noise, sigma_v0_mps=300.0, site=site)
    flat = kind.start(
        PolarPlot(r.ravel(), b.ravel(), e.ravel()), noise, sigma_v0_mps=300.0, site=site
    )
    nxt = (r + 900.0, b + 0.001, e)
    grid = kind.update(cv_predict(grid, 5.0), PolarPlot(*nxt), noise, site=site)
    flat = kind.update(
        cv_predict(flat, 5.0), PolarPlot(*(v.ravel() for v in nxt)), noise, site=site
    )
    assert grid.x.shape == (2, 3, 6) and np.all(np.isfinite(grid.P))
    np.testing.assert_array_equal(grid.x.reshape(6, 6), flat.x)
    np.testing.assert_array_equal(grid.P.reshape(6, 6, 6), flat.P)


#: Independent simulated files; 20 scans per radar (T = 10 s) keep the target on its straight
#: leg (the turn starts at 200 s).
TRACK_FILES = 12
TRACK_SCANS = "20"


def _read_rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.parametrize("doppler", ["ignore", "use"])
def test_track_runs_every_method_on_3d_plots(tmp_path: Path, doppler: str) -> None:
    """``simulate --preset fusion`` then ``track`` with every method (position updates only,
    or with Doppler): finite tracks, positive variances, and a position RMSE below the raw
    converted measurements' (each plot's naive point plus its site) on every file and in the
    mean over independent files, by more than Z standard errors of the mean ratio."""
    truth0, vel = np.array(BASELINE_TARGET_M), np.array(BASELINE_VELOCITY_MPS)
    ratios: dict[str, list[float]] = {m: [] for m in ALL_METHODS}
    for seed in range(TRACK_FILES):
        meas, radars, out = (tmp_path / f"{n}{seed}" for n in ("m.csv", "r.toml", "t.csv"))
        sim = ["simulate", "--preset", "fusion", "--seed", str(seed), "--scans", TRACK_SCANS]
        assert main([*sim, "--out", str(meas), "--radars-out", str(radars)]) == 0
        track = ["track", "--input", str(meas), "--radars", str(radars), "--out", str(out)]
        assert main([*track, "--doppler", doppler]) == 0
        plots = _read_rows(meas)
        assert plots and all(p["elevation_deg"] for p in plots)  # a 3D file
        sites = _radar_sites(radars)
        t = np.array([float(p["time_s"]) for p in plots])
        assert t.max() < 200.0  # the straight leg
        truth = truth0 + t[:, None] * vel
        raw = np.stack(
            [
                sites[p["radar"]]
                + point_3d(
                    float(p["range_m"]),
                    math.radians(float(p["azimuth_deg"])),
                    math.radians(float(p["elevation_deg"])),
                )
                for p in plots
            ]
        )
        raw_rmse = math.sqrt(np.mean(np.sum((raw - truth) ** 2, axis=1)))
        rows = _read_rows(out)
        assert len(rows) == len(plots) * len(ALL_METHODS)
        for method in ALL_METHODS:
            mine = [row for row in rows if row["method"] == method]
            assert [float(row["time_s"]) for row in mine] == t.tolist()
            values = {
                k: np.array([float(row[k]) for row in mine]) for k in mine[0] if k != "method"
            }
            assert all(np.all(np.isfinite(v)) for v in values.values()), method
            assert all(np.all(values[k] > 0) for k in ("p_xx_m2", "p_yy_m2", "p_zz_m2")), method
            pos = np.stack([values["x_m"], values["y_m"], values["z_m"]], axis=-1)
            rmse = math.sqrt(np.mean(np.sum((pos - truth) ** 2, axis=1)))
            assert rmse < raw_rmse, (method, seed, rmse, raw_rmse)
            ratios[method].append(rmse / raw_rmse)
    for method, values in ratios.items():
        m, se = mean_se(np.array(values))
        assert m + Z * se < 1.0, (method, m, se)


def _radar_sites(path: Path) -> dict[str, np.ndarray]:
    import tomllib

    doc = tomllib.loads(path.read_text())
    return {n: np.array([r["x_m"], r["y_m"], r["z_m"]]) for n, r in doc["radars"].items()}
