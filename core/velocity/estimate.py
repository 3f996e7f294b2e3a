"""Full 3D velocity vector (and fused position) from the radial velocities of N ≥ 3 radars.

The model, its derivation and the findings are in ``docs/velocity.md``. Radar k at site s_k
(ECS Cartesian, m) sees the target at p with azimuth β_k (from x towards y), elevation ε_k (from
the horizontal plane) and range r_k, and measures the radial velocity Vr_k = c_k · V with the
unit line of sight

    c_k = [cos ε_k cos β_k,  cos ε_k sin β_k,  sin ε_k]          (row k of C, N × 3)

    C V = Vr   →   V̂ = C⁻¹ V̂r (N = 3),   V̂ = (Cᵀ W C)⁻¹ Cᵀ W V̂r (N > 3, W = diag(1/σeq²))

Errors δVr_k ~ N(0, σVr_k²), δε_k ~ N(0, σε_k²), δβ_k ~ N(0, σβ_k²), independent. With
Ĉ = C + δC and A = C⁻¹ or (Cᵀ W C)⁻¹ Cᵀ W (3 × N), to first order

    δV ≈ A (δVr − δC V),       (δC V)_k = g_ε,k δε_k + g_β,k δβ_k
    g_ε = u · V = −sin ε (cos β Vx + sin β Vy) + cos ε Vz,   u = ∂c/∂ε
    g_β = w · V = cos ε (−sin β Vx + cos β Vy),               w = ∂c/∂β
    σeq_k² = σVr_k² + g_ε,k² σε_k² + g_β,k² σβ_k²,   cov(δV) = A diag(σeq²) Aᵀ

which for the WLS weights equals (Cᵀ diag(σeq⁻²) C)⁻¹.

Second-order mean error. V̂ solves Ĉᵀ W (Ĉ V̂ − V̂r) = 0; with the residual at the truth
e = Ĉ V − V̂r = δC V − δVr, V̂ − V = −Â e, Â = (Ĉᵀ W Ĉ)⁻¹ Ĉᵀ W. Expanding Â to first order
(M = Cᵀ W C, δÂ = M⁻¹ δCᵀ W (I − C A) − A δC A):

    δV ≈ A (δVr − δC V) + A δC A (δC V − δVr) − M⁻¹ δCᵀ W (I − C A)(δC V − δVr)

(for N = 3, C A = I and the last term vanishes: the direct solve's expansion of
(C + δC)⁻¹ = A − A δC A + A δC A δC A + …). δC itself has a second-order (curvature) part,
E[δc_k] = −½[σε_k² c_k + σβ_k² cos ε_k (cos β_k, sin β_k, 0)]. With S_k = E[δc_k δc_kᵀ] =
σε_k² u_k u_kᵀ + σβ_k² w_k w_kᵀ and a_k column k of A, taking expectations (δVr independent of
δC and zero-mean; only k = j survives in the double sums):

    E[δV] ≈ A h + A d − M⁻¹ f
    h_k = −E[δc_k] · V = ½[σε_k² Vr_k + σβ_k² cos ε_k (cos β_k Vx + sin β_k Vy)]   (the paper's)
    d_k = a_kᵀ S_k V = σε_k² g_ε,k (a_k · u_k) + σβ_k² g_β,k (a_k · w_k)           (δC A δC V)
    f   = Σ_k P_kk S_k V,  P = W (I − C A)                                          (WLS only)

The three terms are of the same order σ²; the paper keeps only A h. W is taken as known
(evaluated at the truth): weights computed from the measurements add O(σ²) terms not modelled.

Geometry. The condition number of C and

    m = max_k sqrt(σε_k² + cos² ε_k σβ_k²) / σ_min(C)

(‖δc_k‖ ≈ sqrt(δε² + cos² ε δβ²), so m is the relative size of δC against the smallest
singular value of C: the ratio of the dropped second-order terms to the first-order ones).
Above :data:`M_WARN` the linear statistics stop holding (Monte Carlo σ departs from the
first-order σ by more than a few per cent, ``radarviz reproduce velocity`` sweep) and results
carry a ``warning``. Note that for the direct solve the exact variance of V̂ = Ĉ⁻¹ V̂r is
infinite (det Ĉ has a positive density at 0); the first-order covariance describes the bulk of
the distribution, and the sample σ only approaches it while such draws are vanishingly rare
(small m). Geometries where C is singular (fewer than 3 radars or distinct sites,
coplanar lines of sight, the target at a site) raise :class:`GeometryError`.

Position. Each radar's (r, β, ε) is converted by :func:`core.conversion.spatial.convert_ucm_3d`,
shifted by its site, and the points are fused by information-weighted least squares
P = (Σ R_k⁻¹)⁻¹, p̂ = P Σ R_k⁻¹ (s_k + z_k), with R_k re-evaluated at the first-pass fused
point (:func:`fuse_positions`).

All array functions broadcast over a leading batch shape ``(...)`` (Monte Carlo trials first).
Angles are radians; the frame is flat (no earth curvature).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.confidence import BAND_GROUPS, jackknife_band, student_t_quantile
from radarviz.core.conversion.spatial import convert_ucm_3d, ucm_cov_3d
from radarviz.core.geometry import (
    LineOfSight,
    direction_cosines,
    line_of_sight,
    unit_vector_partials,
)
from radarviz.core.order_statistics import TwoPassQuantiles
from radarviz.core.params import ParameterError, check, check_int

#: m above which the first-order statistics are flagged as unreliable. In the sweep of
#: ``radarviz reproduce velocity`` the Monte Carlo σ exceeds the first-order σ by ≈ m² (1 % at
#: m = 0.1, 5 % at m ≈ 0.23) and from m ≈ 0.3 on heavy tails (near-singular Ĉ) take over.
M_WARN = 0.2
#: Condition number of C above which the velocity is declared unobservable (C singular).
COND_MAX = 1e8
#: Two sites closer than this (m) are the same site; a target closer than this to a site has no
#: line of sight.
SITE_TOL_M = 1e-6
#: Fewest trials of a sweep point (and so of the experiment, whose sweep takes min(trials,
#: ``SWEEP_TRIALS``)): the robust σ's band is by batch means over the groups holding at least
#: two trials, and needs two such groups; trial t is in group t mod ``BAND_GROUPS``, so
#: ``BAND_GROUPS + 2`` trials give the first two groups two each (fewer left the band NaN).
MIN_SWEEP_TRIALS = BAND_GROUPS + 2
#: Monte Carlo trials per block (bounds the working set).
BLOCK_TRIALS = 1 << 17
#: Names of the velocity components, in the order of every vector and matrix here.
AXES: tuple[str, ...] = ("Vx", "Vy", "Vz")


class GeometryError(ParameterError):
    """The radar geometry does not determine the velocity (C singular); one line, for a user."""


# --------------------------------------------------------------------------------------------
# Checks
# --------------------------------------------------------------------------------------------


def _f(a: ArrayLike) -> NDArray[np.float64]:
    return np.asarray(a, dtype=np.float64)


def _finite(name: str, value: ArrayLike, shape: tuple[int, ...]) -> NDArray[np.float64]:
    try:
        a = np.broadcast_to(_f(value), shape).copy()
    except (ValueError, TypeError):
        raise ParameterError(
            f"{name} must be an array of shape {shape} (got shape {np.shape(value)})", name
        ) from None
    if not np.all(np.isfinite(a)):
        raise ParameterError(f"{name} must be finite (got {np.asarray(value).tolist()})", name)
    return a


def _positive(name: str, value: ArrayLike, n: int) -> NDArray[np.float64]:
    a = _finite(name, value, (n,))
    if np.any(a <= 0.0):
        raise ParameterError(f"{name} must be > 0 for every radar (got {a.tolist()})", name)
    return a


def _sites(sites: ArrayLike, name: str = "sites") -> NDArray[np.float64]:
    s = _f(sites)
    if s.ndim != 2 or s.shape[1] != 3:
        raise ParameterError(f"{name} must have shape (N, 3) (got {s.shape})", name)
    if s.shape[0] < 3:
        raise GeometryError(
            f"a 3D velocity needs at least 3 radars (got {s.shape[0]}): velocity not observable"
        )
    if not np.all(np.isfinite(s)):
        raise ParameterError(f"{name} must be finite", name)
    return s


# --------------------------------------------------------------------------------------------
# Lines of sight
# --------------------------------------------------------------------------------------------


def equivalent_variance(
    azimuth: ArrayLike,
    elevation: ArrayLike,
    velocity: ArrayLike,
    *,
    sigma_vr_mps: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> NDArray[np.float64]:
    """σeq_k² = σVr_k² + g_ε,k² σε_k² + g_β,k² σβ_k², shape (..., N); ``velocity`` (..., 3).

    Azimuth and elevation (rad) are those of the lines of sight; the σ's are keyword-only so
    the two angle accuracies cannot be swapped silently.
    """
    w, u = unit_vector_partials(azimuth, elevation)
    v = _f(velocity)[..., None, :]
    g_e, g_b = np.sum(u * v, axis=-1), np.sum(w * v, axis=-1)
    return (
        _f(sigma_vr_mps) ** 2
        + (g_e * _f(sigma_elevation_rad)) ** 2
        + (g_b * _f(sigma_beta_rad)) ** 2
    )


# --------------------------------------------------------------------------------------------
# Solves
# --------------------------------------------------------------------------------------------


def velocity_gain(C: ArrayLike, weights: ArrayLike | None = None) -> NDArray[np.float64]:
    """A (..., 3, N): C⁻¹ when N = 3 and ``weights`` is None, else (Cᵀ W C)⁻¹ Cᵀ W.

    ``weights`` (..., N) is the diagonal of W (1/σeq²); None means W = I.
    """
    C = _f(C)
    n = C.shape[-2]
    if n == 3 and weights is None:
        return np.linalg.inv(C)
    wts = np.ones(C.shape[:-1]) if weights is None else _f(weights)
    CtW = np.swapaxes(C, -1, -2) * wts[..., None, :]
    return np.linalg.solve(CtW @ C, CtW)


def _solve3(C: NDArray, b: NDArray) -> NDArray[np.float64]:
    """C⁻¹ b for (..., 3, 3) C by cross products: C⁻¹ = [c₂×c₃, c₃×c₁, c₁×c₂] / det C.

    Several times faster than a batched LAPACK solve for millions of 3 × 3 systems.
    """
    c1, c2, c3 = C[..., 0, :], C[..., 1, :], C[..., 2, :]
    x23, x31, x12 = np.cross(c2, c3), np.cross(c3, c1), np.cross(c1, c2)
    det = np.sum(c1 * x23, axis=-1)
    num = b[..., 0, None] * x23 + b[..., 1, None] * x31 + b[..., 2, None] * x12
    return num / det[..., None]


def solve_velocity(
    C: ArrayLike, radial_velocity: ArrayLike, weights: ArrayLike | None = None
) -> NDArray[np.float64]:
    """V̂ (..., 3) from C (..., N, 3) and Vr (..., N).

    N = 3 without weights: the direct solve C⁻¹ Vr. Otherwise weighted least squares
    (Cᵀ W C)⁻¹ Cᵀ W Vr, computed by QR of the whitened W^½ C (no squared condition number).
    """
    C, vr = _f(C), _f(radial_velocity)
    if C.shape[-2] == 3 and weights is None:
        return _solve3(C, vr)
    sw = np.ones(C.shape[:-1]) if weights is None else np.sqrt(_f(weights))
    q, r = np.linalg.qr(C * sw[..., None])
    rhs = np.einsum("...ni,...n->...i", q, vr * sw)
    return np.linalg.solve(r, rhs[..., None])[..., 0]


# --------------------------------------------------------------------------------------------
# Geometry diagnostics
# --------------------------------------------------------------------------------------------


class Geometry(NamedTuple):
    """Lines of sight and how well they determine V.

    Attributes:
        C: (N, 3) direction cosines.
        los: range, azimuth, elevation per radar, each (N,).
        singular_values: (3,) of C, descending.
        condition_number: σ_max(C) / σ_min(C) (inf when singular).
        m: max_k sqrt(σε_k² + cos² ε_k σβ_k²) / σ_min(C).
        observable: C has full column rank (condition number ≤ :data:`COND_MAX`, ≥ 3
            distinct sites, target at none of them).
        reason: why not observable, else None.
        warning: set when observable but m > :data:`M_WARN` (linear statistics unreliable).
    """

    C: NDArray[np.float64]
    los: LineOfSight
    singular_values: NDArray[np.float64]
    condition_number: float
    m: float
    observable: bool
    reason: str | None
    warning: str | None


def diagnose_geometry(
    sites: ArrayLike,
    target: ArrayLike,
    *,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> Geometry:
    """Diagnose one geometry; flags (never raises) on singular C. Sites (N, 3), target (3,).

    Raises:
        GeometryError: fewer than 3 radars. ParameterError: malformed or non-finite input.
    """
    s = _sites(sites)
    n = s.shape[0]
    p = _finite("target", target, (3,))
    sigma_beta_rad = _positive("sigma_beta_rad", sigma_beta_rad, n)
    se = _positive("sigma_elevation_rad", sigma_elevation_rad, n)
    los = line_of_sight(s, p)
    reason = None
    at_site = np.flatnonzero(los.range < SITE_TOL_M)
    if at_site.size:
        reason = f"target is at the site of radar {at_site[0]}: its line of sight is undefined"
    else:
        distinct = _distinct_sites(s)
        if len(distinct) < 3:
            i, j = _first_duplicate(s)
            reason = (
                f"radars {i} and {j} share a site: only {len(distinct)} distinct lines of "
                "sight, velocity not observable"
            )
    C = direction_cosines(los.azimuth, los.elevation)
    sv = np.linalg.svd(C, compute_uv=False) if reason is None else np.zeros(3)
    cond = float(sv[0] / sv[2]) if sv[2] > 0 else float("inf")
    if reason is None and not cond <= COND_MAX:
        reason = (
            f"lines of sight are coplanar (condition number of C = {cond:.3g} > "
            f"{COND_MAX:g}): velocity not observable"
        )
    spread = np.sqrt(se * se + (np.cos(los.elevation) * sigma_beta_rad) ** 2)
    m = float(np.max(spread) / sv[2]) if reason is None else float("inf")
    warning = None
    if reason is None and m > M_WARN:
        warning = (
            f"m = {m:.3g} > {M_WARN:g}: first-order velocity statistics unreliable "
            "(low elevation, far target or nearly coplanar lines of sight)"
        )
    return Geometry(C, los, sv, cond, m, reason is None, reason, warning)


def _distinct_sites(s: NDArray) -> list[int]:
    keep: list[int] = []
    for k in range(s.shape[0]):
        if all(np.linalg.norm(s[k] - s[j]) >= SITE_TOL_M for j in keep):
            keep.append(k)
    return keep


def _first_duplicate(s: NDArray) -> tuple[int, int]:
    for i in range(s.shape[0]):
        for j in range(i + 1, s.shape[0]):
            if np.linalg.norm(s[i] - s[j]) < SITE_TOL_M:
                return i, j
    return 0, 0  # pragma: no cover - only called when a duplicate exists


def require_observable(geometry: Geometry) -> Geometry:
    """Return ``geometry`` if the velocity is observable, else raise :class:`GeometryError`."""
    if not geometry.observable:
        raise GeometryError(geometry.reason or "velocity not observable")
    return geometry


# --------------------------------------------------------------------------------------------
# Analytic statistics
# --------------------------------------------------------------------------------------------


class VelocityProblem(NamedTuple):
    """A checked scenario: N sites, truth and per-radar accuracies (radians, m/s).

    ``weighted`` is False for the direct solve (N = 3 only) and True for WLS.
    """

    sites: NDArray[np.float64]
    target: NDArray[np.float64]
    velocity: NDArray[np.float64]
    sigma_vr_mps: NDArray[np.float64]
    sigma_beta_rad: NDArray[np.float64]
    sigma_elevation_rad: NDArray[np.float64]
    weighted: bool


def velocity_problem(
    sites: ArrayLike,
    target: ArrayLike,
    velocity: ArrayLike,
    *,
    sigma_vr_mps: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
    weighted: bool | None = None,
) -> VelocityProblem:
    """Check and pack a scenario. ``weighted`` defaults to N > 3 (direct solve for N = 3)."""
    s = _sites(sites)
    n = s.shape[0]
    if weighted is None:
        weighted = n > 3
    if not weighted and n != 3:
        raise ParameterError(f"the direct solve needs exactly 3 radars (got {n}); use weighted")
    return VelocityProblem(
        sites=s,
        target=_finite("target", target, (3,)),
        velocity=_finite("velocity", velocity, (3,)),
        sigma_vr_mps=_positive("sigma_vr_mps", sigma_vr_mps, n),
        sigma_beta_rad=_positive("sigma_beta_rad", sigma_beta_rad, n),
        sigma_elevation_rad=_positive("sigma_elevation_rad", sigma_elevation_rad, n),
        weighted=bool(weighted),
    )


class VelocityStats(NamedTuple):
    """First- and second-order statistics of V̂ for one scenario.

    Attributes:
        geometry: :class:`Geometry` (condition number, m, warning).
        radial_velocity: (N,) true Vr = C V.
        sigma_eq: (N,) equivalent radial-velocity σ per radar.
        weights: (N,) diagonal of W (1/σeq²) used by WLS, ones for the direct solve.
        gain: A (3, N).
        covariance: (3, 3) first-order A diag(σeq²) Aᵀ.
        sigma: (3,) its standard deviations.
        correlation: (3, 3).
        bias_curvature: (3,) A h, the paper's term (E[δc_k]).
        bias_cross: (3,) A d − M⁻¹ f, the δC A δC V term (and the WLS weight term).
        bias_second_order: (3,) their sum.
    """

    geometry: Geometry
    radial_velocity: NDArray[np.float64]
    sigma_eq: NDArray[np.float64]
    weights: NDArray[np.float64]
    gain: NDArray[np.float64]
    covariance: NDArray[np.float64]
    sigma: NDArray[np.float64]
    correlation: NDArray[np.float64]
    bias_curvature: NDArray[np.float64]
    bias_cross: NDArray[np.float64]
    bias_second_order: NDArray[np.float64]


def velocity_statistics(problem: VelocityProblem) -> VelocityStats:
    """First-order covariance and second-order mean error of V̂ (module docstring).

    Raises:
        GeometryError: C is singular (see :func:`diagnose_geometry`).
    """
    pr = problem
    sigma_beta_rad, se = pr.sigma_beta_rad, pr.sigma_elevation_rad
    geo = require_observable(
        diagnose_geometry(
            pr.sites, pr.target, sigma_beta_rad=sigma_beta_rad, sigma_elevation_rad=se
        )
    )
    C, az, el = geo.C, geo.los.azimuth, geo.los.elevation
    V = pr.velocity
    var_eq = equivalent_variance(
        az,
        el,
        V,
        sigma_vr_mps=pr.sigma_vr_mps,
        sigma_beta_rad=sigma_beta_rad,
        sigma_elevation_rad=se,
    )
    weights = 1.0 / var_eq if pr.weighted else np.ones_like(var_eq)
    A = velocity_gain(C, weights if pr.weighted else None)
    cov = (A * var_eq) @ A.T
    cov = 0.5 * (cov + cov.T)
    sigma = np.sqrt(np.diag(cov))
    corr = cov / np.outer(sigma, sigma)

    vr = C @ V
    se2, sb2 = se**2, sigma_beta_rad**2
    ce = np.cos(el)
    h = 0.5 * (se2 * vr + sb2 * ce * (np.cos(az) * V[0] + np.sin(az) * V[1]))
    w, u = unit_vector_partials(az, el)
    g_e, g_b = u @ V, w @ V
    a_cols = A.T  # (N, 3): a_k
    d = se2 * g_e * np.sum(a_cols * u, axis=1) + sb2 * g_b * np.sum(a_cols * w, axis=1)
    bias_cross = A @ d
    if pr.weighted:
        M = (C.T * weights) @ C
        P_diag = weights * (1.0 - np.einsum("ki,ik->k", C, A))  # diag of W (I − C A)
        f = (P_diag * se2 * g_e) @ u + (P_diag * sb2 * g_b) @ w
        bias_cross = bias_cross - np.linalg.solve(M, f)
    bias_curv = A @ h
    return VelocityStats(
        geo,
        vr,
        np.sqrt(var_eq),
        weights,
        A,
        cov,
        sigma,
        corr,
        bias_curv,
        bias_cross,
        bias_curv + bias_cross,
    )


# --------------------------------------------------------------------------------------------
# Monte Carlo
# --------------------------------------------------------------------------------------------


def perturbed_velocity(
    problem: VelocityProblem,
    *,
    d_vr_mps: ArrayLike,
    d_azimuth_rad: ArrayLike,
    d_elevation_rad: ArrayLike,
    weights: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """V̂ (..., 3) from measurements perturbed by the given errors, each (..., N).

    Ĉ is built from ε_k + δε_k, β_k + δβ_k and V̂r = C V + δVr; the solve is direct or WLS as
    ``problem.weighted`` says, with ``weights`` (N,) (default: 1/σeq² at the truth).
    """
    los = line_of_sight(problem.sites, problem.target)
    C = direction_cosines(los.azimuth, los.elevation)
    vr = C @ problem.velocity + _f(d_vr_mps)
    C_hat = direction_cosines(los.azimuth + _f(d_azimuth_rad), los.elevation + _f(d_elevation_rad))
    if not problem.weighted:
        return solve_velocity(C_hat, vr)
    if weights is None:
        weights = 1.0 / equivalent_variance(
            los.azimuth,
            los.elevation,
            problem.velocity,
            sigma_vr_mps=problem.sigma_vr_mps,
            sigma_beta_rad=problem.sigma_beta_rad,
            sigma_elevation_rad=problem.sigma_elevation_rad,
        )
    return solve_velocity(C_hat, vr, np.broadcast_to(_f(weights), vr.shape))


class VelocityMC(NamedTuple):
    """Monte Carlo statistics of the error V̂ − V.

    Attributes:
        trials: number of trials.
        mean: (3,) bias; mean_se: (3,) its standard error.
        covariance: (3, 3) sample covariance; sigma: (3,); correlation: (3, 3).
        sigma_robust: (3,) interquartile range / 1.349 (a σ that ignores the heavy tails).
        sigma_ci95_lo / sigma_ci95_hi (3,), correlation_ci95_lo / correlation_ci95_hi (3, 3):
            95% Monte Carlo bands, the delete-a-group jackknife over ``BAND_GROUPS`` groups
            of trials (trial t in group t mod G) of these smooth functions of the first and
            second moments (``core.confidence``). Not the χ² band: the errors are not
            Gaussian (Ĉ⁻¹ is nonlinear in the angle errors), and where they have no finite
            variance (m beyond ~0.75) no band of σ means anything; read the robust σ there.
        sigma_robust_ci95_lo / sigma_robust_ci95_hi: (3,) the 95% band of ``sigma_robust`` by
            batch means: the robust σ of each group, and the full estimate ± t_{G−1} · their
            standard deviation / √G (a quantile is not smooth enough for the jackknife).
    """

    trials: int
    mean: NDArray[np.float64]
    mean_se: NDArray[np.float64]
    covariance: NDArray[np.float64]
    sigma: NDArray[np.float64]
    correlation: NDArray[np.float64]
    sigma_robust: NDArray[np.float64]
    sigma_ci95_lo: NDArray[np.float64]
    sigma_ci95_hi: NDArray[np.float64]
    correlation_ci95_lo: NDArray[np.float64]
    correlation_ci95_hi: NDArray[np.float64]
    sigma_robust_ci95_lo: NDArray[np.float64]
    sigma_robust_ci95_hi: NDArray[np.float64]


def velocity_error_blocks(
    problem: VelocityProblem, trials: int, rng: np.random.Generator
) -> Iterator[NDArray[np.float64]]:
    """Errors V̂ − V, block by block ((≤ BLOCK_TRIALS, 3) each), with Gaussian δVr, δε, δβ
    drawn per radar per trial: per block, in order, δVr, δε, δβ as (b, N) standard normals
    scaled by σ. The same ``rng`` state gives the same blocks (the two passes of
    ``monte_carlo_velocity`` draw them twice)."""
    trials = check_int("trials", trials, low=1)
    n = problem.sites.shape[0]
    for start in range(0, trials, BLOCK_TRIALS):
        b = min(BLOCK_TRIALS, trials - start)
        z = rng.standard_normal((3, b, n))
        est = perturbed_velocity(
            problem,
            d_vr_mps=z[0] * problem.sigma_vr_mps,
            d_elevation_rad=z[1] * problem.sigma_elevation_rad,
            d_azimuth_rad=z[2] * problem.sigma_beta_rad,
        )
        yield est - problem.velocity


def velocity_errors(
    problem: VelocityProblem, trials: int, rng: np.random.Generator
) -> NDArray[np.float64]:
    """All (trials, 3) errors of ``velocity_error_blocks`` in one array (small trial counts)."""
    return np.concatenate(list(velocity_error_blocks(problem, trials, rng)))


#: Trials whose errors the Monte Carlo keeps between its two passes (24 MB); beyond, the
#: second pass draws them again (the same draws: the result does not depend on it).
KEEP_TRIALS = 1 << 20
#: The interquartile range of a normal distribution in units of its σ (2 · Φ⁻¹(0.75)).
IQR_PER_SIGMA = 1.3489795003921634


class ErrorSums:
    """Streaming first and second moments of (trials, 3) errors per group of trials (trial t
    in group t mod G), about a shift (the first block's mean) so the sums do not cancel."""

    def __init__(self) -> None:
        self.shift: NDArray[np.float64] | None = None
        self.n = np.zeros(BAND_GROUPS, dtype=np.int64)
        self.s1 = np.zeros((BAND_GROUPS, 3))
        self.s2 = np.zeros((BAND_GROUPS, 3, 3))
        self.trials = 0

    def groups(self, b: int) -> NDArray[np.int64]:
        """The groups of the next ``b`` trials."""
        return (self.trials + np.arange(b)) % BAND_GROUPS

    def add(self, e: NDArray[np.float64]) -> None:
        if self.shift is None:
            self.shift = e.mean(axis=0)
        d = e - self.shift
        g = self.groups(len(e))
        self.n += np.bincount(g, minlength=BAND_GROUPS)
        for k in range(3):
            self.s1[:, k] += np.bincount(g, weights=d[:, k], minlength=BAND_GROUPS)
            for j in range(k, 3):
                w = np.bincount(g, weights=d[:, k] * d[:, j], minlength=BAND_GROUPS)
                self.s2[:, k, j] += w
                if j != k:
                    self.s2[:, j, k] += w
        self.trials += len(e)


def monte_carlo_velocity(
    problem: VelocityProblem, trials: int, seed: int | np.random.SeedSequence
) -> VelocityMC:
    """Seeded Monte Carlo of V̂ (bit-reproducible for the same seed), in memory flat in the
    number of trials: moments are summed block by block and the quartiles of the robust σ
    come exactly from two passes over the same draws (``core.order_statistics``)."""
    ss = (
        seed
        if isinstance(seed, np.random.SeedSequence)
        else np.random.SeedSequence(check_int("seed", seed, low=0))
    )
    return _summarize(lambda: velocity_error_blocks(problem, trials, np.random.default_rng(ss)))


def summarize_errors(errors: ArrayLike) -> VelocityMC:
    """Mean, covariance, σ, correlation and robust σ of (trials, 3) errors, with their 95%
    Monte Carlo bands (``VelocityMC``); the errors as one block of ``monte_carlo_velocity``."""
    e = _f(errors)
    return _summarize(lambda: iter([e]))


def _summarize(blocks: Callable[[], Iterator[NDArray[np.float64]]]) -> VelocityMC:
    """``VelocityMC`` of the error blocks ``blocks()`` yields (called twice: the same blocks)."""
    sums = ErrorSums()
    quart = TwoPassQuantiles([0.25, 0.75], 1 + BAND_GROUPS, 3)
    kept: list[NDArray[np.float64]] | None = []  # the first pass's blocks, while they fit
    for e in blocks():
        quart.count(e, 1 + sums.groups(len(e)))
        sums.add(e)
        if kept is not None:
            kept.append(e)
            if sums.trials > KEEP_TRIALS:
                kept = None  # past the budget: the second pass draws the blocks again
    seen = 0
    for e in blocks() if kept is None else kept:
        quart.select(e, 1 + (seen + np.arange(len(e))) % BAND_GROUPS)
        seen += len(e)
    q = quart.result()  # (1 + G, 2, 3): the whole sample, then each group
    n = sums.trials
    t1, t2 = sums.s1.sum(axis=0), sums.s2.sum(axis=0)
    mean = sums.shift + t1 / n
    cov = (t2 - np.outer(t1, t1) / n) / (n - 1)
    sigma = np.sqrt(np.diag(cov))
    corr = cov / np.outer(sigma, sigma)
    robust = (q[0, 1] - q[0, 0]) / IQR_PER_SIGMA
    # Leave-one-group-out covariances from the per-group sums (shift-invariant).
    counts = sums.n
    n_out = (n - counts).astype(np.float64)[:, None, None]
    r1 = t1 - sums.s1
    with np.errstate(invalid="ignore", divide="ignore"):
        cov_out = (t2 - sums.s2 - r1[:, :, None] * r1[:, None, :] / n_out) / (n_out - 1.0)
        sig_out = np.sqrt(np.maximum(np.diagonal(cov_out, axis1=1, axis2=2), 0.0))
        corr_out = cov_out / (sig_out[:, :, None] * sig_out[:, None, :])
    empty = counts == 0
    sig_out[empty], corr_out[empty] = np.nan, np.nan
    sig_lo, sig_hi = jackknife_band(sigma, sig_out)
    sig_lo = np.maximum(sig_lo, 0.0)  # a σ is not negative, whatever its band says
    corr_lo, corr_hi = jackknife_band(corr, corr_out)
    # Batch means for the robust σ: each group's own IQR σ (groups of at least 2 trials).
    per_group = [(q[1 + g, 1] - q[1 + g, 0]) / IQR_PER_SIGMA for g in range(BAND_GROUPS)]
    per_group = [v for v, c in zip(per_group, counts, strict=True) if c >= 2]
    half = np.full(3, np.nan)
    if len(per_group) >= 2:
        spread = np.std(per_group, axis=0, ddof=1) / np.sqrt(len(per_group))
        half = student_t_quantile(len(per_group) - 1) * spread
    return VelocityMC(
        n,
        mean,
        sigma / np.sqrt(n),
        cov,
        sigma,
        corr,
        robust,
        sig_lo,
        sig_hi,
        corr_lo,
        corr_hi,
        robust - half,
        robust + half,
    )


# --------------------------------------------------------------------------------------------
# Per-scan estimate from measurements
# --------------------------------------------------------------------------------------------


class VelocityEstimate(NamedTuple):
    """V̂ from one scan of N radars, its first-order covariance and the geometry flags.

    Attributes:
        velocity: (3,) estimate; covariance: (3, 3) first-order, evaluated at the estimate.
        condition_number, m: geometry diagnostics at the measured angles.
        warning: set when m > :data:`M_WARN` (do not trust the ellipsoid).
    """

    velocity: NDArray[np.float64]
    covariance: NDArray[np.float64]
    condition_number: float
    m: float
    warning: str | None


def estimate_velocity(
    sites_m: ArrayLike,
    radial_velocity_mps: ArrayLike,
    azimuth_rad: ArrayLike,
    elevation_rad: ArrayLike,
    *,
    sigma_vr_mps: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
) -> VelocityEstimate:
    """Estimate V from measured (Vr_k, β_k, ε_k), k = 1 … N ≥ 3, each (N,).

    N = 3: direct solve. N > 3: a first unweighted pass gives V̂₀, then WLS with
    W = diag(1/σeq²(V̂₀)). The covariance is A diag(σeq²) Aᵀ at the estimate.

    Raises:
        GeometryError: fewer than 3 radars, duplicate sites leaving < 3 lines of sight, or
            coplanar lines of sight.
    """
    s = _sites(sites_m, "sites_m")
    n = s.shape[0]
    vr = _finite("radial_velocity_mps", radial_velocity_mps, (n,))
    az = _finite("azimuth_rad", azimuth_rad, (n,))
    el = _finite("elevation_rad", elevation_rad, (n,))
    sigmas = {
        "sigma_vr_mps": _positive("sigma_vr_mps", sigma_vr_mps, n),
        "sigma_beta_rad": (sigma_beta_rad := _positive("sigma_beta_rad", sigma_beta_rad, n)),
        "sigma_elevation_rad": (se := _positive("sigma_elevation_rad", sigma_elevation_rad, n)),
    }
    C = direction_cosines(az, el)
    if len(_distinct_sites(s)) < 3:
        i, j = _first_duplicate(s)
        raise GeometryError(
            f"radars {i} and {j} share a site: fewer than 3 distinct lines of "
            "sight, velocity not observable"
        )
    svals = np.linalg.svd(C, compute_uv=False)
    cond = float(svals[0] / svals[2]) if svals[2] > 0 else float("inf")
    if not cond <= COND_MAX:
        raise GeometryError(
            f"lines of sight are coplanar (condition number of C = {cond:.3g} "
            f"> {COND_MAX:g}): velocity not observable"
        )
    if n == 3:
        v = solve_velocity(C, vr)
        var_eq = equivalent_variance(az, el, v, **sigmas)
        A = velocity_gain(C)
    else:
        v0 = solve_velocity(C, vr, np.ones(n))
        w = 1.0 / equivalent_variance(az, el, v0, **sigmas)
        v = solve_velocity(C, vr, w)
        var_eq = equivalent_variance(az, el, v, **sigmas)
        A = velocity_gain(C, 1.0 / var_eq)
    cov = (A * var_eq) @ A.T
    m = float(np.max(np.sqrt(se * se + (np.cos(el) * sigma_beta_rad) ** 2)) / svals[2])
    warning = None
    if m > M_WARN:
        warning = f"m = {m:.3g} > {M_WARN:g}: first-order velocity covariance unreliable"
    return VelocityEstimate(v, 0.5 * (cov + cov.T), cond, m, warning)


# --------------------------------------------------------------------------------------------
# Fused position
# --------------------------------------------------------------------------------------------


class FusedPosition(NamedTuple):
    """Information-weighted fusion of the radars' converted points.

    Attributes:
        position: (..., 3) fused point; covariance: (..., 3, 3) (Σ R_k⁻¹)⁻¹.
        points: (..., N, 3) each radar's converted point shifted by its site.
    """

    position: NDArray[np.float64]
    covariance: NDArray[np.float64]
    points: NDArray[np.float64]


def fuse_positions(
    sites: ArrayLike,
    range_: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
    refine: bool = True,
) -> FusedPosition:
    """Fuse the radars' (r, β, ε) (..., N) into one point; per-radar σ's (N,).

    Each measurement is converted by :func:`core.conversion.spatial.convert_ucm_3d` (unbiased point,
    covariance R_k at the measurement) and shifted by its site s_k; then
    P = (Σ R_k⁻¹)⁻¹, p̂ = P Σ R_k⁻¹ (s_k + z_k). One radar is enough (N ≥ 1).

    ``refine`` (default): the weights R_k evaluated at each radar's own measurement are
    correlated with its error, which biases p̂ by O(σ²) (about 15 standard errors in the 10⁵-
    trial test, 6.5 m in z at the baseline). A second pass re-evaluates every R_k at the line of
    sight of the first-pass fused point (as ``ducm`` does with the prediction), which removes
    that bias; the returned covariance is the second pass's P.

    Raises:
        GeometryError: a radar's R_k is singular (zero range, or the target at its zenith where
            azimuth is undefined).
    """
    s = _f(sites)
    if s.ndim != 2 or s.shape[1] != 3 or s.shape[0] < 1:
        raise ParameterError(f"sites must have shape (N, 3) with N >= 1 (got {s.shape})")
    n = s.shape[0]
    sigma_r_m = _positive("sigma_r_m", sigma_r_m, n)
    sigma_beta_rad = _positive("sigma_beta_rad", sigma_beta_rad, n)
    se = _positive("sigma_elevation_rad", sigma_elevation_rad, n)
    r, az, el = _f(range_), _f(azimuth), _f(elevation)
    if np.any(r <= 0.0) or np.any(np.abs(np.cos(el)) < 1e-9):
        raise GeometryError(
            "a radar sees the target at zero range or at its zenith: "
            "its position covariance is singular"
        )
    sig = {"sigma_r_m": sigma_r_m, "sigma_beta_rad": sigma_beta_rad, "sigma_elevation_rad": se}
    conv = convert_ucm_3d(r, az, el, **sig)
    pts = conv.z + s
    pos, P = _fuse(conv.R, pts)
    if refine:
        los = line_of_sight(s, pos)
        if np.any(los.range <= 0.0) or np.any(np.abs(np.cos(los.elevation)) < 1e-9):
            raise GeometryError(
                "the fused point is at a site or its zenith: position covariance singular"
            )
        R = ucm_cov_3d(los.range, los.azimuth, los.elevation, **sig)
        pos, P = _fuse(R, pts)
    return FusedPosition(pos, P, pts)


def _fuse(R: NDArray, pts: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    info = np.linalg.inv(R)
    P = np.linalg.inv(info.sum(axis=-3))
    P = 0.5 * (P + np.swapaxes(P, -1, -2))
    rhs = np.einsum("...kij,...kj->...i", info, pts)
    return np.einsum("...ij,...j->...i", P, rhs), P


# --------------------------------------------------------------------------------------------
# The experiment (preset ``velocity``)
# --------------------------------------------------------------------------------------------

#: Baseline geometry (the paper gives no numbers; ``docs/velocity.md``): three ground radars,
#: target, velocity, accuracies.
BASELINE_SITES_M: tuple[tuple[float, float, float], ...] = (
    (0.0, 0.0, 0.0),
    (80e3, 0.0, 0.0),
    (40e3, 70e3, 0.0),
)
BASELINE_TARGET_M: tuple[float, float, float] = (40e3, 30e3, 10e3)
BASELINE_VELOCITY_MPS: tuple[float, float, float] = (216.5, 125.0, 0.0)
BASELINE_SIGMA_VR_MPS: tuple[float, ...] = (1.0, 3.0, 5.0)
BASELINE_SIGMA_EL_DEG: tuple[float, ...] = (0.2, 0.5, 1.0)
BASELINE_SIGMA_AZ_DEG: tuple[float, ...] = (0.1, 0.3, 0.5)
#: Sweep: the target at horizontal distance D from the sites' centroid towards −y (away from the
#: triangle, passing over no site) and altitude h; velocity and accuracies as the baseline.
SWEEP_DISTANCES_KM: tuple[float, ...] = (10.0, 25.0, 50.0, 100.0, 150.0, 200.0, 300.0, 400.0)
SWEEP_ALTITUDES_KM: tuple[float, ...] = (1.0, 5.0, 10.0, 20.0)
SWEEP_DIRECTION: tuple[float, float, float] = (0.0, -1.0, 0.0)
#: Trials per sweep point at most (the sweep looks for departures of several per cent).
SWEEP_TRIALS = 20_000


def baseline_problem(target_m: ArrayLike = BASELINE_TARGET_M) -> VelocityProblem:
    """The baseline scenario (direct solve, N = 3), optionally with another target."""
    return velocity_problem(
        BASELINE_SITES_M,
        target_m,
        BASELINE_VELOCITY_MPS,
        sigma_vr_mps=BASELINE_SIGMA_VR_MPS,
        sigma_beta_rad=np.deg2rad(BASELINE_SIGMA_AZ_DEG),
        sigma_elevation_rad=np.deg2rad(BASELINE_SIGMA_EL_DEG),
    )


def sweep_target(distance_km: float, altitude_km: float) -> NDArray[np.float64]:
    """Target position (m) of a sweep point: centroid + D · direction + h · ẑ."""
    centroid = np.mean(np.asarray(BASELINE_SITES_M), axis=0)
    centroid[2] = 0.0
    return centroid + 1e3 * (
        distance_km * np.asarray(SWEEP_DIRECTION) + altitude_km * np.array([0.0, 0.0, 1.0])
    )


class SweepPoint(NamedTuple):
    """One sweep geometry: its analytic statistics and Monte Carlo."""

    distance_km: float
    altitude_km: float
    stats: VelocityStats
    mc: VelocityMC


class VelocityExperiment(NamedTuple):
    """``radarviz reproduce velocity``: baseline (analytic vs MC) and the geometry sweep.

    ``seed`` is the root of ``SeedSequence``; the baseline draws from child 0, sweep point j
    (altitude-major order) from child j + 1.
    """

    trials: int
    seed: int
    sweep_trials: int
    baseline: VelocityStats
    baseline_mc: VelocityMC
    sweep: tuple[SweepPoint, ...]


def run_velocity_experiment(
    trials: int = 200_000,
    seed: int = 1,
    *,
    sweep_trials: int | None = None,
    distances_km: tuple[float, ...] = SWEEP_DISTANCES_KM,
    altitudes_km: tuple[float, ...] = SWEEP_ALTITUDES_KM,
) -> VelocityExperiment:
    """Run the baseline and the sweep (``sweep_trials`` defaults to min(trials, SWEEP_TRIALS))."""
    trials = check_int("trials", int(check("trials", trials)), low=MIN_SWEEP_TRIALS)
    seed = int(check("seed", seed))
    st = (
        min(trials, SWEEP_TRIALS)
        if sweep_trials is None
        else check_int("sweep_trials", sweep_trials, low=MIN_SWEEP_TRIALS)
    )
    grid = [(float(h), float(d)) for h in altitudes_km for d in distances_km]
    children = np.random.SeedSequence(seed).spawn(1 + len(grid))
    base = baseline_problem()
    base_stats = velocity_statistics(base)
    base_mc = monte_carlo_velocity(base, trials, children[0])
    points = []
    for (h, d), child in zip(grid, children[1:], strict=True):
        pb = baseline_problem(sweep_target(d, h))
        stats = velocity_statistics(pb)
        points.append(SweepPoint(d, h, stats, monte_carlo_velocity(pb, st, child)))
    return VelocityExperiment(trials, seed, st, base_stats, base_mc, tuple(points))
