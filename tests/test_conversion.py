"""Statistical and property tests of ``core.conversion.planar`` (the math: docs/conversion.md).

Monte Carlo checks.  Every comparison of a Monte Carlo estimate with a closed form goes through
``check_mc``, whose tolerance is ``Z`` times the estimate's own standard error (never a
hand-picked number):

* sample mean of N draws:        se = std / sqrt(N)
* sample variance:               se = sqrt((m4 − var²) / N)   (m4: sample 4th central moment)
* sample covariance of (x, y):   se = std((x − x̄)(y − ȳ)) / sqrt(N)

(the last two are the same formula: the variance is the mean of the squared deviations).  With
N ≥ 4·10^5 the estimators are Gaussian to well within the accuracy needed here (CLT), and
centring on the sample mean changes the se only by O(1/N).

``Z`` is a Bonferroni bound: at most ``MAX_STAT_CHECKS`` scalar comparisons are made (a module
fixture enforces it), each two-sided at level FAMILY_ALPHA / MAX_STAT_CHECKS, so the chance that
correct code fails *any* of them, for a fresh choice of seeds, is < FAMILY_ALPHA = 1e-3.  That
gives Z ≈ 4.56.  The seeds are fixed, so the suite is deterministic.  The configurations
include σβ = 0.3 rad, where the higher-order terms (e.g. the e^s of the ucm covariance) are
many standard errors large, so the checks also have power; a few tests assert that explicitly.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from decimal import Decimal, getcontext

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from numpy.polynomial.hermite_e import hermegauss
from scipy.stats import norm

from radarviz.core.conversion import planar as cv
from radarviz.core.conversion import spatial as cv3

DEG = math.pi / 180.0

# ---------------------------------------------------------------------------------------------
# Monte Carlo machinery
# ---------------------------------------------------------------------------------------------

FAMILY_ALPHA = 1e-3
MAX_STAT_CHECKS = 200
# Bonferroni: per-check two-sided level FAMILY_ALPHA / MAX_STAT_CHECKS -> Z ≈ 4.56.  The
# family-wise false-alarm probability over all asserts of this file then stays < 1e-3.
Z = float(norm.isf(FAMILY_ALPHA / (2 * MAX_STAT_CHECKS)))
_STATS = {"checks": 0}


@pytest.fixture(scope="module", autouse=True)
def _stat_check_budget() -> Iterator[None]:
    """Keep the Bonferroni argument honest: fail if the file makes more checks than budgeted."""
    yield
    assert _STATS["checks"] <= MAX_STAT_CHECKS, (
        f"{_STATS['checks']} Monte Carlo checks > MAX_STAT_CHECKS={MAX_STAT_CHECKS}; raise the "
        "budget (Z follows automatically)"
    )


def check_mc(estimate: np.ndarray, expected: np.ndarray, se: np.ndarray, what: str) -> None:
    """Assert |estimate − expected| ≤ Z·se element-wise; each element counts as one check."""
    estimate, expected, se = np.broadcast_arrays(
        np.asarray(estimate, float), np.asarray(expected, float), np.asarray(se, float)
    )
    _STATS["checks"] += estimate.size
    assert np.all(se > 0), f"{what}: zero standard error"
    err = np.abs(estimate - expected) / se
    assert np.all(err <= Z), (
        f"{what}: MC {estimate} vs exact {expected}, se {se}, |error|/se = {err} > Z = {Z:.2f}"
    )


def mean_se(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample mean over axis 0 and its standard error std/sqrt(N)."""
    n = samples.shape[0]
    return samples.mean(axis=0), samples.std(axis=0, ddof=1) / math.sqrt(n)


def cov_se(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample covariance (d, d) of points (N, d) and the standard error of each entry.

    The entry (i, j) is the mean of the products of deviations u = (p_i − p̄_i)(p_j − p̄_j), so
    its se is std(u)/sqrt(N); for i = j that is sqrt((m4 − var²)/N).
    """
    _, d = points.shape
    dev = points - points.mean(axis=0)
    cov, se = np.empty((d, d)), np.empty((d, d))
    for i in range(d):
        for j in range(i, d):
            m, e = mean_se(dev[:, i] * dev[:, j])
            cov[i, j] = cov[j, i] = m
            se[i, j] = se[j, i] = e
    return cov, se


def check_mean(samples: np.ndarray, expected, what: str) -> None:
    """check_mc of the sample mean over axis 0 against its expectation."""
    mean, se = mean_se(samples)
    check_mc(mean, expected, se, what)


def upper(a: np.ndarray) -> np.ndarray:
    """Upper triangle (with diagonal) of a (d, d) matrix: the distinct entries."""
    return a[np.triu_indices(a.shape[-1])]


def rel_entrywise(a: np.ndarray, ref: np.ndarray) -> float:
    """max |a − ref|_ij / sqrt(ref_ii ref_jj): error relative to each entry's natural scale.

    (Plain relative error is meaningless for off-diagonal entries that are ~0, e.g. at β = 0.)
    """
    d = np.sqrt(np.abs(np.diagonal(ref, axis1=-2, axis2=-1)))
    return float(np.max(np.abs(a - ref) / (d[..., :, None] * d[..., None, :])))


def _polar_draws(
    rng: np.random.Generator, n: int, r: float, beta: float, sr: float, sigma_beta_rad: float
) -> tuple[np.ndarray, np.ndarray]:
    return r + sr * rng.standard_normal(n), beta + sigma_beta_rad * rng.standard_normal(n)


def _polar_point_3d(r, az, el) -> np.ndarray:
    """The polar map x = r cos ε cos β, y = r cos ε sin β, z = r sin ε (test-side copy)."""
    return np.stack(
        [r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)], axis=-1
    )


def _naive_mean_3d(r, az, el, sigma_beta_rad, se) -> np.ndarray:
    """E[naive 3D point | truth] from the one-angle moments E[cos θ̂] = e^(−s/2) cos θ etc."""
    ea, ee = math.exp(-(sigma_beta_rad**2) / 2), math.exp(-(se**2) / 2)
    return r * np.array(
        [
            ee * math.cos(el) * ea * math.cos(az),
            ee * math.cos(el) * ea * math.sin(az),
            ee * math.sin(el),
        ]
    )


def _ucm_3d_scales(sigma_beta_rad: float, se: float) -> np.ndarray:
    """D = (e^((sβ+sε)/2), e^((sβ+sε)/2), e^(sε/2)): one e^(s/2) per angle in each coordinate."""
    kxy = math.exp((sigma_beta_rad**2 + se**2) / 2)
    return np.array([kxy, kxy, math.exp(se**2 / 2)])


# ---------------------------------------------------------------------------------------------
# 1. The exact moments (docs/conversion.md, section 3)
# ---------------------------------------------------------------------------------------------

MOMENT_BETAS = (0.0, 0.7, 2.5)
MOMENT_SIGMAS = (1 * DEG, 2 * DEG, 5 * DEG, 0.3)


@pytest.mark.parametrize("sigma_beta_rad", MOMENT_SIGMAS, ids=lambda v: f"sigma_beta_rad={v:.4f}")
@pytest.mark.parametrize("beta", MOMENT_BETAS)
def test_exact_moments_match_monte_carlo(beta: float, sigma_beta_rad: float) -> None:
    rng = np.random.default_rng([1, MOMENT_BETAS.index(beta), MOMENT_SIGMAS.index(sigma_beta_rad)])
    n, r, sr = 400_000, 150e3, 250.0
    rh, bh = _polar_draws(rng, n, r, beta, sr, sigma_beta_rad)
    s = sigma_beta_rad * sigma_beta_rad
    cb, snb = np.cos(bh), np.sin(bh)
    cases = {
        "E[cos b]": (cb, math.exp(-s / 2) * math.cos(beta)),
        "E[sin b]": (snb, math.exp(-s / 2) * math.sin(beta)),
        "E[cos^2 b]": (cb * cb, 0.5 * (1 + math.exp(-2 * s) * math.cos(2 * beta))),
        "E[sin^2 b]": (snb * snb, 0.5 * (1 - math.exp(-2 * s) * math.cos(2 * beta))),
        "E[sin b cos b]": (snb * cb, 0.5 * math.exp(-2 * s) * math.sin(2 * beta)),
        "E[r^2]": (rh * rh, r * r + sr * sr),
    }
    for name, (samples, exact) in cases.items():
        check_mean(samples, exact, f"{name} beta={beta} sigma_beta_rad={sigma_beta_rad}")


# ---------------------------------------------------------------------------------------------
# 2. Mean and covariance of the naive point given the truth (2D and 3D)
# ---------------------------------------------------------------------------------------------

CONFIGS_2D = (
    (150e3, 0.0, 250.0, 1 * DEG),
    (150e3, 0.7, 250.0, 5 * DEG),
    (10e3, 2.5, 30.0, 0.3),
    (2e3, -1.2, 100.0, 0.1),
)
CONFIGS_3D = (  # r, azimuth, elevation, σr, σ_azimuth, σ_elevation
    (150e3, 0.7, 0.3, 250.0, 1 * DEG, 2 * DEG),
    (10e3, 2.5, -1.2, 30.0, 0.2, 0.25),
    (50e3, -2.0, 1.4, 100.0, 0.05, 0.3),
)
N_MC = 1_000_000


@pytest.mark.parametrize("cfg", CONFIGS_2D, ids=str)
def test_naive_moments_given_truth_2d(cfg: tuple[float, ...]) -> None:
    r, beta, sr, sigma_beta_rad = cfg
    rng = np.random.default_rng([2, CONFIGS_2D.index(cfg)])
    rh, bh = _polar_draws(rng, N_MC, r, beta, sr, sigma_beta_rad)
    pts = np.stack([rh * np.cos(bh), rh * np.sin(bh)], axis=-1)
    m, m_se = mean_se(pts)
    check_mc(
        m,
        cv.naive_mean_given_truth(r, beta, sigma_beta_rad=sigma_beta_rad),
        m_se,
        f"naive mean {cfg}",
    )
    c, c_se = cov_se(pts)
    exact = cv.naive_cov_given_truth(r, beta, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad)
    check_mc(upper(c), upper(exact), upper(c_se), f"naive cov {cfg}")


@pytest.mark.parametrize("cfg", CONFIGS_3D, ids=str)
def test_naive_cov_given_truth_3d(cfg: tuple[float, ...]) -> None:
    r, az, el, sr, sa, se = cfg
    rng = np.random.default_rng([3, CONFIGS_3D.index(cfg)])
    rh, ah = _polar_draws(rng, N_MC, r, az, sr, sa)
    eh = el + se * rng.standard_normal(N_MC)
    pts = _polar_point_3d(rh, ah, eh)
    m, m_se = mean_se(pts)
    check_mc(m, _naive_mean_3d(r, az, el, sa, se), m_se, f"naive 3D mean {cfg}")
    c, c_se = cov_se(pts)
    exact = cv3.naive_cov_given_truth_3d(
        r, az, el, sigma_r_m=sr, sigma_beta_rad=sa, sigma_elevation_rad=se
    )
    assert exact.shape == (3, 3)
    check_mc(upper(c), upper(exact), upper(c_se), f"naive 3D cov {cfg}")


# ---------------------------------------------------------------------------------------------
# 3. Bias of each 2D conversion given the truth
# ---------------------------------------------------------------------------------------------

BIAS_CONFIGS = (
    (150e3, 0.0, 250.0, 1 * DEG),  # the paper's geometry
    (150e3, 0.0, 250.0, 2 * DEG),
    (150e3, 0.7, 250.0, 5 * DEG),
    (150e3, 2.5, 250.0, 0.3),
)


def test_quoted_naive_bias() -> None:
    """docs/conversion.md: 'pulled towards the radar by about r·s/2 (23 m at 150 km and σβ = 1°,
    91 m at 2°)'."""
    for sigma_beta_rad, quoted in ((1 * DEG, 23), (2 * DEG, 91)):
        s = sigma_beta_rad * sigma_beta_rad
        pull = 150e3 * (1 - math.exp(-s / 2))  # exact, from E[cos β̂] = e^(−s/2) cos β
        assert round(pull) == quoted
        assert abs(pull - 150e3 * s / 2) <= 150e3 * s * s / 8  # ≈ r s/2 to second order


@pytest.mark.parametrize("cfg", BIAS_CONFIGS, ids=str)
def test_conversion_bias_given_truth(cfg: tuple[float, ...]) -> None:
    r, beta, sr, sigma_beta_rad = cfg
    s = sigma_beta_rad * sigma_beta_rad
    rng = np.random.default_rng([4, BIAS_CONFIGS.index(cfg)])
    rh, bh = _polar_draws(rng, N_MC, r, beta, sr, sigma_beta_rad)
    truth = r * np.array([math.cos(beta), math.sin(beta)])
    radial = truth / r
    naive_mean = cv.naive_mean_given_truth(r, beta, sigma_beta_rad=sigma_beta_rad)

    rad_bias: dict[str, np.ndarray] = {}  # per-draw radial error, per method
    exact_rad: dict[str, float] = {}
    for method in cv.METHODS_2D:
        z = cv.convert(
            method, rh, bh, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad, predicted_xy=truth
        ).z
        assert z.shape == (N_MC, 2)
        expected = (
            cv.scale_factor(method, sigma_beta_rad=sigma_beta_rad) * naive_mean
        )  # closed form κ·E[naive]
        check_mean(z, expected, f"{method} mean {cfg}")
        rad_bias[method] = (z - truth) @ radial
        exact_rad[method] = float((expected - truth) @ radial)

    # naive: pulled in by r(1 − e^(−s/2)) ≈ r s/2; far outside the MC noise (power check).
    assert abs(exact_rad["naive"] + r * s / 2) <= r * s * s / 8
    b_naive, se_naive = mean_se(rad_bias["naive"])
    assert b_naive + Z * se_naive < 0

    # seed: κ = 1 − s/2 pushes the wrong way, doubling the bias: ratio 2(1 − s/8 + …).
    assert abs(exact_rad["seed"] / exact_rad["naive"] - 2) <= s / 4
    diff = rad_bias["seed"] - 2 * rad_bias["naive"]  # same draws: se from the combination
    check_mean(diff, exact_rad["seed"] - 2 * exact_rad["naive"], f"seed − 2·naive bias {cfg}")

    # cmkf_d: unbiased to second order, the remainder is −r s²/2 + O(s³).
    assert abs(exact_rad["cmkf_d"]) <= r * s * s / 2
    assert abs(exact_rad["cmkf_d"]) < abs(exact_rad["naive"]) * s

    # ucm / ducm: exactly unbiased, so their MC check above was a check against the truth.
    for method in ("ucm", "ducm"):
        np.testing.assert_allclose(
            cv.scale_factor(method, sigma_beta_rad=sigma_beta_rad) * naive_mean,
            truth,
            rtol=1e-14,
            atol=1e-9 * r,
        )


# ---------------------------------------------------------------------------------------------
# 4. ucm / ducm covariance (2D) and the 3D unbiased conversion
# ---------------------------------------------------------------------------------------------

UCM_CONFIGS = (
    (150e3, 0.0, 250.0, 2 * DEG),
    (150e3, 0.7, 250.0, 5 * DEG),
    (10e3, 2.5, 30.0, 0.3),
)


@pytest.mark.parametrize("cfg", UCM_CONFIGS, ids=str)
def test_ucm_covariance_given_truth(cfg: tuple[float, ...]) -> None:
    r, beta, sr, sigma_beta_rad = cfg
    s = sigma_beta_rad * sigma_beta_rad
    rng = np.random.default_rng([5, UCM_CONFIGS.index(cfg)])
    rh, bh = _polar_draws(rng, N_MC, r, beta, sr, sigma_beta_rad)
    truth = r * np.array([math.cos(beta), math.sin(beta)])
    exact = math.exp(s) * cv.naive_cov_given_truth(
        r, beta, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad
    )

    c, c_se = cov_se(cv.convert("ucm", rh, bh, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad).z)
    check_mc(upper(c), upper(exact), upper(c_se), f"ucm cov {cfg}")
    if sigma_beta_rad >= 0.3:  # power: without the e^s factor the covariance is rejected
        wrong = cv.naive_cov_given_truth(r, beta, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad)
        assert np.any(np.abs(upper(c) - upper(wrong)) > Z * upper(c_se))

    # ducm evaluated at the true position: exactly the true-conditioned covariance, for every
    # measurement (it does not depend on r̂, β̂).
    ducm = cv.convert(
        "ducm",
        rh[:1000],
        bh[:1000],
        sigma_r_m=sr,
        sigma_beta_rad=sigma_beta_rad,
        predicted_xy=truth,
    )
    assert rel_entrywise(np.broadcast_to(ducm.R, (1000, 2, 2)), exact) < 1e-13
    # ... and ucm evaluated at the truth gives the same matrix.
    assert (
        rel_entrywise(
            cv.convert("ucm", r, beta, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad).R, exact
        )
        < 1e-13
    )


@pytest.mark.parametrize("cfg", CONFIGS_3D, ids=str)
def test_ucm_3d_unbiased_with_exact_covariance(cfg: tuple[float, ...]) -> None:
    r, az, el, sr, sa, se = cfg
    rng = np.random.default_rng([6, CONFIGS_3D.index(cfg)])
    rh, ah = _polar_draws(rng, N_MC, r, az, sr, sa)
    eh = el + se * rng.standard_normal(N_MC)
    z = cv3.convert_ucm_3d(rh, ah, eh, sigma_r_m=sr, sigma_beta_rad=sa, sigma_elevation_rad=se).z
    truth = _polar_point_3d(r, az, el)
    check_mean(z, truth, f"ucm 3D mean {cfg}")

    # convert_ucm_3d evaluates its covariance at the *measured* angles, so the formula is
    # tested at the truth: D · naive_cov_given_truth_3d · D with D the per-axis scales.
    d = _ucm_3d_scales(sa, se)
    exact = (
        d[:, None]
        * cv3.naive_cov_given_truth_3d(
            r, az, el, sigma_r_m=sr, sigma_beta_rad=sa, sigma_elevation_rad=se
        )
        * d[None, :]
    )
    c, c_se = cov_se(z)
    check_mc(upper(c), upper(exact), upper(c_se), f"ucm 3D cov {cfg}")
    at_truth = cv3.convert_ucm_3d(
        r, az, el, sigma_r_m=sr, sigma_beta_rad=sa, sigma_elevation_rad=se
    )
    assert rel_entrywise(at_truth.R, exact) < 1e-13
    np.testing.assert_allclose(at_truth.z, d * truth, rtol=1e-14)


# ---------------------------------------------------------------------------------------------
# 5. Eq. 11 is the posterior average of the true-conditioned covariance (quadrature)
# ---------------------------------------------------------------------------------------------

QUAD_CONFIGS = (  # r̂, β̂, σr, σβ
    (150e3, 0.0, 250.0, 1 * DEG),
    (150e3, 0.7, 250.0, 2 * DEG),
    (10e3, 2.5, 30.0, 0.3),
    (1e6, -1.2, 1e4, 0.1),
    (2e3, -3.0, 5.0, 5 * DEG),
    (1e7, 3.0, 0.1, 1e-4),  # r/σr = 1e8: needs the cancellation-free formulas
)


@pytest.mark.parametrize("cfg", QUAD_CONFIGS, ids=str)
def test_averaged_cov_is_posterior_average(cfg: tuple[float, ...]) -> None:
    r_hat, b_hat, sr, sigma_beta_rad = cfg
    x, w = hermegauss(40)  # probabilists' Hermite: weight e^(−x²/2)
    w = w / math.sqrt(2 * math.pi)  # -> expectation over a standard normal
    r = r_hat + sr * x[:, None]
    b = b_hat + sigma_beta_rad * x[None, :]
    avg = np.einsum(
        "i,j,ijkl->kl",
        w,
        w,
        cv.naive_cov_given_truth(r, b, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad),
    )
    assert (
        rel_entrywise(
            cv.averaged_cov(r_hat, b_hat, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad), avg
        )
        < 1e-10
    )
    # seed and cmkf_d both report exactly this matrix.
    for method in ("seed", "cmkf_d"):
        np.testing.assert_array_equal(
            cv.convert(method, r_hat, b_hat, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad).R,
            cv.averaged_cov(r_hat, b_hat, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad),
        )


# ---------------------------------------------------------------------------------------------
# 6. First-order covariances against numerical Jacobians
# ---------------------------------------------------------------------------------------------


def _num_jacobian(f, x: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Central differences: column k = (f(x + h_k e_k) − f(x − h_k e_k)) / (2 h_k)."""
    cols = []
    for k in range(x.size):
        e = np.zeros_like(x)
        e[k] = h[k]
        cols.append((f(x + e) - f(x - e)) / (2 * h[k]))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize(
    "cfg", [(150e3, 0.0, 250.0, 1 * DEG), (10e3, 2.5, 30.0, 0.3), (50.0, -1.9, 0.5, 1e-3)]
)
def test_linearized_cov_is_j_diag_jt(cfg: tuple[float, ...]) -> None:
    r, beta, sr, sigma_beta_rad = cfg
    jac = _num_jacobian(
        lambda p: np.array([p[0] * np.cos(p[1]), p[0] * np.sin(p[1])]),
        np.array([r, beta]),
        np.array([1e-3 * r, 1e-5]),
    )
    ref = jac @ np.diag([sr**2, sigma_beta_rad**2]) @ jac.T
    assert (
        rel_entrywise(cv.linearized_cov(r, beta, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad), ref)
        < 1e-6
    )
    naive = cv.convert("naive", r, beta, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad)
    np.testing.assert_array_equal(
        naive.R, cv.linearized_cov(r, beta, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad)
    )
    np.testing.assert_allclose(naive.z, [r * math.cos(beta), r * math.sin(beta)], rtol=1e-15)


@pytest.mark.parametrize("cfg", [*CONFIGS_3D, (80.0, 0.0, 0.0, 0.5, 1e-3, 2e-3)], ids=str)
def test_naive_3d_cov_is_j_diag_jt(cfg: tuple[float, ...]) -> None:
    r, az, el, sr, sa, se = cfg
    jac = _num_jacobian(
        lambda p: _polar_point_3d(p[0], p[1], p[2]),
        np.array([r, az, el]),
        np.array([1e-3 * r, 1e-5, 1e-5]),
    )
    ref = jac @ np.diag([sr**2, sa**2, se**2]) @ jac.T
    out = cv3.convert_naive_3d(r, az, el, sigma_r_m=sr, sigma_beta_rad=sa, sigma_elevation_rad=se)
    assert rel_entrywise(out.R, ref) < 1e-6
    np.testing.assert_allclose(out.z, _polar_point_3d(r, az, el), rtol=1e-15, atol=1e-12 * r)


# ---------------------------------------------------------------------------------------------
# Extreme dynamic range: the exact covariances against 50-digit arithmetic
# ---------------------------------------------------------------------------------------------

EXTREME = (  # r, σr, σβ: r²s spans 1e4..1e13 m² against σr² = 1e-2 m²
    (1e7, 0.1, 1e-5),
    (1e7, 0.1, 1e-4),
    (1e6, 1.0, 3e-4),
    (150e3, 250.0, 1 * DEG),
    (1e7, 0.1, 0.3),
)


@pytest.mark.parametrize("cfg", EXTREME, ids=str)
def test_exact_covariances_high_precision(cfg: tuple[float, ...]) -> None:
    """At β = 0 (and ε = 0) the exact-moment formulas need only exp: evaluate them in Decimal.

    Written as E[p pᵀ] − E[p] E[p]ᵀ, the radial variance cancels O(r²) terms down to
    ~σr² + r² s²/2; float64 loses eps·r²/σr² of it (once 56 %, and negative in 3D, here).
    """
    getcontext().prec = 50
    r, sr, sigma_beta_rad = cfg
    R, SR, S = Decimal(r), Decimal(sr), Decimal(sigma_beta_rad) ** 2
    m2 = R * R + SR * SR

    def ex(v: Decimal) -> Decimal:
        return v.exp()

    def ch(v: Decimal) -> Decimal:
        return (ex(v) + ex(-v)) / 2

    def sh(v: Decimal) -> Decimal:
        return (ex(v) - ex(-v)) / 2

    ecc, ess = (1 + ex(-2 * S)) / 2, (1 - ex(-2 * S)) / 2  # E[cos² θ̂], E[sin² θ̂] at θ = 0
    naive = [m2 * ecc - R * R * ex(-S), m2 * ess]
    e2 = ex(-2 * S)
    avg = [
        R * R * e2 * (ch(2 * S) - ch(S)) + SR * SR * e2 * (2 * ch(2 * S) - ch(S)),
        R * R * e2 * (sh(2 * S) - sh(S)) + SR * SR * e2 * (2 * sh(2 * S) - sh(S)),
    ]
    # 3D, az = el = 0, the same σ on both angles: diag(xx, yy, zz), off-diagonals zero.
    naive3 = [m2 * ecc * ecc - R * R * ex(-S) * ex(-S), m2 * ecc * ess, m2 * ess]

    for got, ref in (
        (cv.naive_cov_given_truth(r, 0.0, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad), naive),
        (cv.averaged_cov(r, 0.0, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad), avg),
        (
            cv3.naive_cov_given_truth_3d(
                r,
                0.0,
                0.0,
                sigma_r_m=sr,
                sigma_beta_rad=sigma_beta_rad,
                sigma_elevation_rad=sigma_beta_rad,
            ),
            naive3,
        ),
    ):
        ref_f = np.array([float(v) for v in ref])
        np.testing.assert_allclose(np.diagonal(got), ref_f, rtol=1e-12)
        assert np.all(got[~np.eye(len(ref), dtype=bool)] == 0.0)


# ---------------------------------------------------------------------------------------------
# 7. Properties for all valid inputs (hypothesis)
# ---------------------------------------------------------------------------------------------

EPS = np.finfo(float).eps
# Relative tolerance for "positive definite": the true matrices are PD but can be conditioned
# as badly as r²s/σr² ≈ 1e15 (naive, r = 1e7 m, σr = 0.1 m, σβ = 0.3 rad), so (a) unscaled,
# their eigenvalues span 1e-2 .. 1e13 m² and neither Cholesky nor an absolute eigenvalue test
# is meaningful — hence the diagonal (Jacobi) scaling to the correlation matrix, which is
# scale-free and whose eigenvalues lie in (0, d]; (b) even then the smallest correlation
# eigenvalue is ~1/cond ~ 1e-15, below what entries rounded to a few ulp can resolve.  A
# perturbation of each correlation entry by k·eps moves the eigenvalues by ≤ d·k·eps; 64·eps
# allows k ≈ 20 for d = 3.  Anything more negative is a genuine failure (the pre-fix ucm
# formulas gave correlation eigenvalues of −1e-3 and negative variances here).
PD_TOL = 64 * EPS

radius = st.floats(1.0, 1e7)
angle = st.floats(-math.pi, math.pi)
sigma_r = st.floats(0.1, 1e4)
sigma_angle = st.floats(1e-5, 0.3)
elevation = st.floats(-1.4, 1.4)


def assert_symmetric_pd(cov: np.ndarray, what: str) -> None:
    assert np.all(np.isfinite(cov)), what
    diag = np.diagonal(cov, axis1=-2, axis2=-1)
    assert np.all(diag > 0), f"{what}: non-positive variance {diag}"
    scale = np.sqrt(diag)
    corr = cov / (scale[..., :, None] * scale[..., None, :])
    asym = np.abs(corr - np.swapaxes(corr, -1, -2))
    assert np.all(asym <= 4 * EPS), f"{what}: not symmetric ({asym.max():.3g})"
    lam = np.linalg.eigvalsh(0.5 * (corr + np.swapaxes(corr, -1, -2)))
    assert np.all(lam[..., 0] > -PD_TOL), f"{what}: correlation eigenvalues {lam}"
    np.linalg.cholesky(corr + PD_TOL * np.eye(cov.shape[-1]))  # raises if not PD


@settings(max_examples=300, deadline=None)
@given(r=radius, beta=angle, sr=sigma_r, sigma_beta_rad=sigma_angle, rp=radius, bp=angle)
@example(
    r=1e7, beta=0.0, sr=0.1, sigma_beta_rad=1e-5, rp=1e7, bp=0.0
)  # negative variance before the fix
@example(r=1e7, beta=math.pi / 4, sr=0.1, sigma_beta_rad=0.3, rp=1.0, bp=-math.pi)  # cond ≈ 1e15
def test_2d_covariances_symmetric_pd(r, beta, sr, sigma_beta_rad, rp, bp) -> None:
    predicted = np.array([rp * math.cos(bp), rp * math.sin(bp)])
    for method in cv.METHODS_2D:
        out = cv.convert(
            method, r, beta, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad, predicted_xy=predicted
        )
        assert out.z.shape == (2,) and out.R.shape == (2, 2)
        assert np.all(np.isfinite(out.z))
        assert_symmetric_pd(out.R, method)
    assert_symmetric_pd(
        cv.naive_cov_given_truth(r, beta, sigma_r_m=sr, sigma_beta_rad=sigma_beta_rad),
        "naive_cov_given_truth",
    )


@settings(max_examples=300, deadline=None)
@given(r=radius, az=angle, el=elevation, sr=sigma_r, sa=sigma_angle, se=sigma_angle)
@example(r=1e7, az=0.0, el=0.0, sr=0.1, sa=1e-5, se=1e-5)  # negative variance before the fix
def test_3d_covariances_symmetric_pd(r, az, el, sr, sa, se) -> None:
    for name, fn in (("naive_3d", cv3.convert_naive_3d), ("ucm_3d", cv3.convert_ucm_3d)):
        out = fn(r, az, el, sigma_r_m=sr, sigma_beta_rad=sa, sigma_elevation_rad=se)
        assert out.z.shape == (3,) and out.R.shape == (3, 3)
        assert_symmetric_pd(out.R, name)
    assert_symmetric_pd(
        cv3.naive_cov_given_truth_3d(
            r, az, el, sigma_r_m=sr, sigma_beta_rad=sa, sigma_elevation_rad=se
        ),
        "naive_cov_given_truth_3d",
    )


def _valid_batch(rng: np.random.Generator, shape: tuple[int, ...]) -> dict[str, np.ndarray]:
    def log_uniform(lo: float, hi: float) -> np.ndarray:
        return np.exp(rng.uniform(math.log(lo), math.log(hi), shape))

    return {
        "r": log_uniform(1.0, 1e7),
        "beta": rng.uniform(-math.pi, math.pi, shape),
        "el": rng.uniform(-1.4, 1.4, shape),
        "sr": log_uniform(0.1, 1e4),
        "sigma_beta_rad": log_uniform(1e-5, 0.3),
        "se": log_uniform(1e-5, 0.3),
        "pred": log_uniform(1.0, 1e7)[..., None]
        * np.stack([np.cos(b := rng.uniform(-math.pi, math.pi, shape)), np.sin(b)], axis=-1),
    }


def _assert_batch_matches(batched: cv.Converted, single, shape, d: int, what: str) -> None:
    assert batched.z.shape == (*shape, d), what
    assert batched.R.shape == (*shape, d, d), what
    for idx in np.ndindex(*shape):
        one = single(idx)
        # Same formulas element-wise; allow a few ulp for SIMD vs scalar transcendental paths.
        np.testing.assert_allclose(
            batched.z[idx], one.z, rtol=1e-13, atol=1e-13 * np.abs(one.z).max(), err_msg=what
        )
        assert rel_entrywise(batched.R[idx], one.R) < 1e-13, what


@settings(max_examples=30, deadline=None)
@given(
    shape=hnp.array_shapes(min_dims=1, max_dims=3, max_side=4),
    seed=st.integers(0, 2**32 - 1),
    scalar_sigmas=st.booleans(),
)
def test_broadcasting_equals_elementwise(shape, seed, scalar_sigmas) -> None:
    v = _valid_batch(np.random.default_rng(seed), shape)
    if scalar_sigmas:  # the common case: one (σr, σβ, σε) for the whole batch
        for k in ("sr", "sigma_beta_rad", "se"):
            v[k] = np.asarray(v[k].flat[0])

    def at(k: str, idx: tuple[int, ...]):
        return v[k] if v[k].ndim == 0 else v[k][idx]

    for method in cv.METHODS_2D:
        batched = cv.convert(
            method,
            v["r"],
            v["beta"],
            sigma_r_m=v["sr"],
            sigma_beta_rad=v["sigma_beta_rad"],
            predicted_xy=v["pred"],
        )
        _assert_batch_matches(
            batched,
            lambda i, m=method: cv.convert(
                m,
                v["r"][i],
                v["beta"][i],
                sigma_r_m=at("sr", i),
                sigma_beta_rad=at("sigma_beta_rad", i),
                predicted_xy=v["pred"][i],
            ),
            shape,
            2,
            method,
        )

    def sig(i: tuple[int, ...] | None = None) -> dict:
        names = ("sigma_r_m", "sigma_beta_rad", "sigma_elevation_rad")
        if i is None:
            return {n: v[k] for n, k in zip(names, ("sr", "sigma_beta_rad", "se"), strict=True)}
        return {n: at(k, i) for n, k in zip(names, ("sr", "sigma_beta_rad", "se"), strict=True)}

    for name, fn in (("naive_3d", cv3.convert_naive_3d), ("ucm_3d", cv3.convert_ucm_3d)):
        args = (v["r"], v["beta"], v["el"])
        _assert_batch_matches(
            fn(*args, **sig()),
            lambda i, f=fn: f(v["r"][i], v["beta"][i], v["el"][i], **sig(i)),
            shape,
            3,
            name,
        )
        # A scalar elevation broadcasts against batched range and azimuth.
        mixed = fn(v["r"], v["beta"], 0.25, **sig())
        _assert_batch_matches(
            mixed,
            lambda i, f=fn: f(v["r"][i], v["beta"][i], 0.25, **sig(i)),
            shape,
            3,
            f"{name} scalar elevation",
        )
    # The helper functions carry the batch shape too.
    assert cv.naive_mean_given_truth(
        v["r"], v["beta"], sigma_beta_rad=v["sigma_beta_rad"]
    ).shape == (
        *shape,
        2,
    )
    for fn2 in (cv.naive_cov_given_truth, cv.linearized_cov, cv.averaged_cov):
        assert fn2(
            v["r"], v["beta"], sigma_r_m=v["sr"], sigma_beta_rad=v["sigma_beta_rad"]
        ).shape == (
            *shape,
            2,
            2,
        )
    assert cv3.naive_cov_given_truth_3d(
        v["r"],
        v["beta"],
        v["el"],
        sigma_r_m=v["sr"],
        sigma_beta_rad=v["sigma_beta_rad"],
        sigma_elevation_rad=v["se"],
    ).shape == (*shape, 3, 3)


# ---------------------------------------------------------------------------------------------
# 8. Errors
# ---------------------------------------------------------------------------------------------


def test_unknown_method_names_the_allowed_ones() -> None:
    for call in (
        lambda: cv.convert("bogus", 1e3, 0.1, sigma_r_m=10.0, sigma_beta_rad=0.01),
        lambda: cv.scale_factor("bogus", sigma_beta_rad=0.01),
    ):
        with pytest.raises(ValueError) as info:
            call()
        msg = str(info.value)
        assert "bogus" in msg
        for method in cv.METHODS_2D:
            assert method in msg


def test_ducm_needs_predicted_position() -> None:
    with pytest.raises(ValueError, match="predicted_xy"):
        cv.convert("ducm", 1e3, 0.1, sigma_r_m=10.0, sigma_beta_rad=0.01)


def test_point_and_covariance_share_the_batch_shape() -> None:
    """Scalar measurement, batched σ (or one prediction, batched measurements): z and R agree."""
    c = cv.convert("naive", 1e5, 0.3, sigma_r_m=250.0, sigma_beta_rad=np.array([0.01, 0.02, 0.03]))
    assert c.z.shape == (3, 2) and c.R.shape == (3, 2, 2)
    d = cv.convert(
        "ducm",
        np.array([1e5, 2e5]),
        0.1,
        sigma_r_m=250.0,
        sigma_beta_rad=0.01,
        predicted_xy=np.array([1e5, 1e4]),
    )
    assert d.z.shape == (2, 2) and d.R.shape == (2, 2, 2)
