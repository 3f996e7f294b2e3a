"""Finite-memory (sliding-window) least-squares filter of range and radial velocity.

Gorshkov and Zavizhenets (2016); the model, the closed forms and the findings are in
``docs/finite_memory.md``. Once per scan (period T) a radar measures range ``r_i`` (variance
Dr = σr²) and Doppler radial velocity ``Vr_i`` (variance DVr = σVr²), i = 1 … k with i = 1 the
oldest. The state at the newest sample, θ = (r, Vr, a), is the least-squares fit of a
quadratic trajectory to the last k scans. With the lag j = k − i:

    r(t_i)  = r − Vr·T·j + a·T²·j²/2        row [1, −T j, T² j²/2],  weight 1/Dr
    Vr(t_i) = Vr − a·T·j                     row [0, 1, −T j],         weight 1/DVr

    R = (Hᵀ Q H)⁻¹,   W = R Hᵀ Q  (3 × 2k),   θ̂ = W z,   z = (r_1 … r_k, Vr_1 … Vr_k)

Q = diag(1/Dr ×k, 1/DVr ×k). Row 1 of W gives range, row 2 radial velocity, row 3 acceleration;
the first k columns weigh ranges, the last k radial velocities. Range only drops the Vr rows
(W is 3 × k). Besides k, the only parameter that matters is ``C0 = Dr / (T² DVr)``: R and W
depend on σr, σVr and T only through C0 and the unit scalings Dr, T.

Two routes to R and W:

* numerical (:func:`ls_covariance_numeric`, :func:`ls_weights_numeric`): QR of the whitened
  design matrix, the ground truth;
* closed forms (:func:`ls_covariance_closed`, :func:`ls_weights_closed`): the paper's eqs. 7–12
  (R) and 15–20 (W), for range + Doppler and k ≥ 2. Range only has no printed closed form: it
  is the C0 → 0 limit of the same expressions (Doppler infinitely noisy), which is the classical
  quadratic least-squares fit and needs k ≥ 3.

Reduced order. A fit of p parameters needs at least p equations. Range + Doppler has 2k
equations, so k = 1 fits (r, Vr) (p = 2) and k ≥ 2 the full (r, Vr, a). Range only has k:
k = 1 fits r, k = 2 fits (r, Vr), k ≥ 3 the full state. :class:`FiniteMemoryFit` reports the
number of parameters fitted as ``order`` and pads R and W with NaN for the rest. A reduced fit
of a quadratic truth is biased (the two-point range-only velocity (r₂ − r₁)/T is off by −a T/2).

The paper's Monte Carlo experiment (:func:`run_gorshkov`) reproduces σ of the filtering errors
of r, Vr, a for six radars (:data:`PRESETS`) and k = 1 … 20, range only against range + Vr,
and the gain ``K(k) = (σ_range-only − σ_range+Vr) / σ_range-only · 100 %``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.confidence import (
    BAND_GROUPS,
    group_counts,
    group_sums,
    jackknife_band,
    sigma_band,
)
from radarviz.core.params import (
    ParameterError,
    check,
    check_choice,
    check_int,
    check_real,
    default,
)

#: Largest window accepted; far beyond any radar use, small enough for dense (3, 2k) weights.
MAX_K = 10_000
#: Range of C0 accepted (the paper's radars span 0.51 … 100); outside it C0² in the closed
#: forms and the whitened design's condition number stop being harmless.
C0_MIN, C0_MAX = 1e-12, 1e12
#: Ways to compute R and W.
METHODS: tuple[str, ...] = ("closed", "numeric")
#: Monte Carlo trials per block of :func:`run_gorshkov` (bounds the working set).
BLOCK_TRIALS = 65_536
#: Trials of a block whose errors :func:`run_gorshkov` forms at once (bounds the errors' array).
ERROR_SLICE_TRIALS = 8_192


# --------------------------------------------------------------------------------------------
# Radar presets (the paper's table)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RadarPreset:
    """One radar of the paper's table.

    Attributes:
        name: "RLS1" … "RLS6".
        band: wave band as printed (MW metre, DMW decimetre, CMW centimetre).
        sigma_r_m: range noise σr, m.
        sigma_vr_mps: radial-velocity noise σVr, m/s.
        period_s: scan period T, s.
    """

    name: str
    band: str
    sigma_r_m: float
    sigma_vr_mps: float
    period_s: float

    @property
    def c0(self) -> float:
        """C0 = σr² / (T² σVr²), the ratio of range to velocity information."""
        return c0_ratio(
            sigma_r_m=self.sigma_r_m, sigma_vr_mps=self.sigma_vr_mps, period_s=self.period_s
        )


PRESETS: dict[str, RadarPreset] = {
    p.name: p
    for p in (
        RadarPreset("RLS1", "MW", 250.0, 35.0, 10.0),  # C0 = 0.5102
        RadarPreset("RLS2", "MW", 250.0, 25.0, 10.0),  # C0 = 1
        RadarPreset("RLS3", "DMW", 250.0, 15.0, 10.0),  # C0 = 2.778
        # C0 = 250² / (5² · 15²) = 11.11; the paper prints 11.01, a typo.
        RadarPreset("RLS4", "DMW", 250.0, 15.0, 5.0),
        RadarPreset("RLS5", "CMW", 50.0, 1.0, 10.0),  # C0 = 25
        RadarPreset("RLS6", "CMW", 50.0, 1.0, 5.0),  # C0 = 100
    )
}


def preset(name: str) -> RadarPreset:
    """The preset called ``name`` (RLS1 … RLS6); ParameterError naming the allowed names."""
    return PRESETS[check_choice("preset", name, PRESETS)]


def c0_ratio(*, sigma_r_m: float, sigma_vr_mps: float, period_s: float) -> float:
    """C0 = σr² / (T² σVr²): σr in m, σVr in m/s, T in s (dimensionless)."""
    ratio = sigma_r_m / (period_s * sigma_vr_mps)
    return ratio * ratio  # not ** 2: a float power raises OverflowError instead of giving inf


# --------------------------------------------------------------------------------------------
# Parameter checks
# --------------------------------------------------------------------------------------------


class _Params(NamedTuple):
    k: int
    sigma_r_m: float
    sigma_vr_mps: float  # NaN for range only
    period_s: float
    with_doppler: bool
    c0: float  # NaN for range only


def max_order(k: int, with_doppler: bool) -> int:
    """Number of parameters a window of k scans can fit: min(3, 2k) or min(3, k)."""
    return min(3, 2 * k if with_doppler else k)


def _check(
    k: object,
    sigma_r_m: object,
    sigma_vr_mps: object,
    period_s: object,
    with_doppler: object,
    k_min: int = 1,
) -> _Params:
    kk = check_int("k", k, low=k_min, high=MAX_K)
    if not isinstance(with_doppler, bool | np.bool_):
        raise ParameterError(f"with_doppler must be True or False (got {with_doppler!r})")
    sigma_r_m = check_real("sigma_r_m", sigma_r_m, low=0.0)
    T = check_real("period_s", period_s, low=0.0)
    sr2, t4 = sigma_r_m * sigma_r_m, T * T * T * T
    if not (math.isfinite(sr2) and sr2 > 0.0 and math.isfinite(t4) and t4 > 0.0):
        raise ParameterError(
            "sigma_r_m and period_s must keep σr² and T⁴ finite and > 0"
            f" (got {sigma_r_m:g}, {T:g})",
            "sigma_r_m",
        )
    if not with_doppler:
        return _Params(kk, sigma_r_m, math.nan, T, False, math.nan)
    sigma_vr_mps = check_real("sigma_vr_mps", sigma_vr_mps, low=0.0)
    c0 = c0_ratio(sigma_r_m=sigma_r_m, sigma_vr_mps=sigma_vr_mps, period_s=T)
    if not C0_MIN <= c0 <= C0_MAX:
        raise ParameterError(f"C0 = σr²/(T² σVr²) must be in [{C0_MIN:g}, {C0_MAX:g}] (got {c0:g})")
    return _Params(kk, sigma_r_m, sigma_vr_mps, T, True, c0)


# --------------------------------------------------------------------------------------------
# Numerical least squares (the ground truth)
# --------------------------------------------------------------------------------------------


def design_matrix(k: int, period: float, with_doppler: bool, order: int = 3) -> NDArray[np.float64]:
    """H of the first ``order`` parameters of (r, Vr, a).  Shape (2k, order) or (k, order).

    Row i (i = 1 oldest … k newest, lag j = k − i) is ``[1, −T j, T² j²/2]`` for the range
    and, with Doppler, row k + i is ``[0, 1, −T j]`` for the radial velocity.
    """
    p = _check(k, 1.0, 1.0, period, with_doppler)
    order = check_int("order", order, low=1, high=3)
    j = np.arange(p.k - 1, -1, -1, dtype=np.float64)
    T = p.period_s
    rows = np.stack([np.ones_like(j), -T * j, 0.5 * (T * j) ** 2], axis=-1)
    if with_doppler:
        vrows = np.stack([np.zeros_like(j), np.ones_like(j), -T * j], axis=-1)
        rows = np.concatenate([rows, vrows], axis=0)
    return rows[:, :order]


def _numeric(p: _Params, order: int | None) -> tuple[int, NDArray, NDArray]:
    """(order, R padded (3, 3), W padded (3, m)) by QR of the whitened, column-scaled H.

    The columns are scaled by S = diag(1, 1/T, 1/T²), i.e. φ = (r, Vr T, a T²), so that
    A = Q^½ H S has the T-free rows [1, −j, j²/2]/σr and [0, 1, −j]/(T σVr). With A = Qₐ Rₐ
    (reduced QR), R_φ = Rₐ⁻¹ Rₐ⁻ᵀ and W_φ = Rₐ⁻¹ Qₐᵀ Q^½; then R = S R_φ S, W = S W_φ.
    No normal-equation matrix HᵀQH is ever formed. (``scipy.linalg`` is imported here: it
    is most of the package's import time and only this numerical reference needs it.)
    """
    from scipy.linalg import solve_triangular

    top = max_order(p.k, p.with_doppler)
    n = top if order is None else check_int("order", order, low=1, high=top)
    j = np.arange(p.k - 1, -1, -1, dtype=np.float64)
    cols = np.stack([np.ones_like(j), -j, 0.5 * j * j], axis=-1)[:, :n] / p.sigma_r_m
    sqrt_q = np.full(p.k, 1.0 / p.sigma_r_m)
    if p.with_doppler:
        s_v = 1.0 / (p.period_s * p.sigma_vr_mps)
        vcols = np.stack([np.zeros_like(j), np.ones_like(j), -j], axis=-1)[:, :n] * s_v
        cols = np.concatenate([cols, vcols], axis=0)
        sqrt_q = np.concatenate([sqrt_q, np.full(p.k, 1.0 / p.sigma_vr_mps)])
    q_a, r_a = np.linalg.qr(cols, mode="reduced")
    r_inv = solve_triangular(r_a, np.eye(n), lower=False)
    w_phi = solve_triangular(r_a, q_a.T, lower=False) * sqrt_q
    scale = (1.0, 1.0 / p.period_s, 1.0 / p.period_s**2)[:n]
    s = np.asarray(scale)
    R = np.full((3, 3), np.nan)
    W = np.full((3, cols.shape[0]), np.nan)
    R[:n, :n] = (r_inv @ r_inv.T) * s[:, None] * s[None, :]
    W[:n] = w_phi * s[:, None]
    return n, R, W


def ls_covariance_numeric(
    k: int,
    *,
    sigma_r_m: float,
    sigma_vr_mps: float | None,
    period_s: float,
    with_doppler: bool = True,
    order: int | None = None,
) -> NDArray[np.float64]:
    """R = (Hᵀ Q H)⁻¹ by least squares.  Shape (3, 3), NaN rows/columns for unfitted parameters.

    Args:
        order: number of parameters fitted (1 = r, 2 = r, Vr, 3 = r, Vr, a); ``None`` fits as
            many as the window allows (:func:`max_order`).
    """
    return _numeric(_check(k, sigma_r_m, sigma_vr_mps, period_s, with_doppler), order)[1]


def ls_weights_numeric(
    k: int,
    *,
    sigma_r_m: float,
    sigma_vr_mps: float | None,
    period_s: float,
    with_doppler: bool = True,
    order: int | None = None,
) -> NDArray[np.float64]:
    """W = R Hᵀ Q by least squares.  Shape (3, 2k) or (3, k), NaN rows for unfitted parameters."""
    return _numeric(_check(k, sigma_r_m, sigma_vr_mps, period_s, with_doppler), order)[2]


# --------------------------------------------------------------------------------------------
# Closed forms (eqs. 7–12 and 15–20)
# --------------------------------------------------------------------------------------------


def _closed_cov(k: int, dr: float, c0: float, T: float) -> NDArray[np.float64]:
    """Eqs. 7–12. Valid for range + Doppler (C0 > 0) with k ≥ 2, and for C0 = 0 with k ≥ 3."""
    kf = float(k)
    e12 = 12.0 * c0 + (kf * kf - 1.0)
    e60 = 60.0 * c0 + (kf * kf - 4.0)
    D = kf * (kf + 1.0) * e12 * e60
    k1 = kf * (kf + 1.0) * e60
    R = np.empty((3, 3))
    R[0, 0] = (
        3.0
        * dr
        * (
            (kf * kf - 1.0) * (kf - 2.0) * (3.0 * kf * kf - 3.0 * kf + 2.0)
            + 8.0 * c0 * (13.0 * kf**3 - 17.0 * kf * kf + 8.0 * kf - 7.0)
            + 240.0 * c0 * c0 * (kf + 1.0)
        )
        / D
    )
    R[1, 1] = (
        12.0 * dr * (2.0 * kf - 1.0) * ((kf + 1.0) * (8.0 * kf - 11.0) + 120.0 * c0) / (T * T * D)
    )
    R[2, 2] = 720.0 * dr / (T**4 * kf * (kf * kf - 1.0) * e60)
    R[0, 1] = R[1, 0] = (
        18.0 * dr * (2.0 * kf - 1.0) * (kf - 1.0) * ((kf + 1.0) * (kf - 2.0) + 20.0 * c0) / (T * D)
    )
    R[0, 2] = R[2, 0] = 60.0 * dr * (kf - 2.0) / (T * T * k1)
    R[1, 2] = R[2, 1] = 360.0 * dr / (T**3 * k1)
    return R


def _closed_weights(k: int, c0: float, T: float, with_doppler: bool) -> NDArray[np.float64]:
    """Eqs. 15–20 (they do not depend on Dr). C0 = 0 gives the range-only weights (k ≥ 3)."""
    kf = float(k)
    i = np.arange(1, k + 1, dtype=np.float64)
    e12 = 12.0 * c0 + (kf * kf - 1.0)
    e60 = 60.0 * c0 + (kf * kf - 4.0)
    Dp = kf * e12 * e60
    D = (kf + 1.0) * Dp
    D3 = kf * (kf * kf - 1.0) * e60
    w1r = (
        3.0
        * (kf - 1.0)
        * (kf - 2.0)
        * ((kf + 2.0) * (kf + 1.0) - 2.0 * i * (4.0 * kf + 3.0 - 5.0 * i))
        / Dp
        - 24.0
        * c0
        * (
            (kf + 1.0) * (2.0 * kf * kf + 7.0)
            - 15.0 * i * (i * kf + kf + 1.0 - 2.0 * i)
            - 30.0 * c0 * (kf + 1.0)
        )
        / D
    )
    w2r = 6.0 * (
        (4.0 * kf - 3.0) * (kf + 2.0) * (kf + 1.0)
        - 2.0 * i * kf * (14.0 * kf - 15.0 * i)
        - 2.0 * i * (15.0 * i - 11.0)
    ) / (T * Dp) + 360.0 * c0 * (kf - 4.0 * i * kf - 2.0 * i * (2.0 - 3.0 * i) + 1.0) / (T * D)
    w3r = 60.0 * (kf * kf - 6.0 * i * kf + 3.0 * kf + 6.0 * i * i - 6.0 * i + 2.0) / (T * T * D3)
    if not with_doppler:
        return np.stack([w1r, w2r, w3r])
    w1v = (
        c0
        * T
        * (
            6.0 * (kf * kf - 1.0) * (kf - 2.0) * (10.0 * i - 4.0 * kf - 3.0)
            + 360.0 * c0 * (kf + 1.0 - 4.0 * i + 2.0 * i * kf)
        )
        / D
    )
    w2v = (
        -12.0
        * c0
        * (
            (kf + 1.0) * (14.0 * kf * kf - 11.0)
            - 30.0 * i * (kf * kf - 1.0)
            + 120.0 * c0 * (kf + 1.0 - 3.0 * i)
        )
        / D
    )
    w3v = -360.0 * c0 * (kf - 2.0 * i + 1.0) / (T * D3)
    return np.stack(
        [np.concatenate([w1r, w1v]), np.concatenate([w2r, w2v]), np.concatenate([w3r, w3v])]
    )


def ls_covariance_closed(
    k: int,
    *,
    sigma_r_m: float,
    sigma_vr_mps: float | None,
    period_s: float,
    with_doppler: bool = True,
) -> NDArray[np.float64]:
    """R of the full (r, Vr, a) fit from the closed forms.  Shape (3, 3).

    With C0 = σr²/(T² σVr²), D = k(k+1)(12C0 + k² − 1)(60C0 + k² − 4):

        R11 = 3Dr[(k²−1)(k−2)(3k²−3k+2) + 8C0(13k³−17k²+8k−7) + 240C0²(k+1)] / D   (7)
        R22 = 12Dr(2k−1)[(k+1)(8k−11) + 120C0] / (T² D)                              (8)
        R33 = 720Dr / [T⁴ k(k²−1)(60C0 + k² − 4)]                                   (9)
        R12 = 18Dr(2k−1)(k−1)[(k+1)(k−2) + 20C0] / (T D)                             (10)
        R13 = 60Dr(k−2) / [T² k(k+1)(60C0 + k² − 4)]                                 (11)
        R23 = 360Dr / [T³ k(k+1)(60C0 + k² − 4)]                                     (12)

    Range + Doppler needs k ≥ 2 (at k = 1, k(k² − 1) = 0: two equations cannot fix three
    parameters). Range only (``with_doppler=False``, ``sigma_vr_mps`` ignored) is derived, not
    printed: it is the C0 → 0 limit of the same formulas, e.g. R11 = 3Dr(3k²−3k+2)/(k(k+1)(k+2)),
    and needs k ≥ 3. For smaller k use :func:`finite_memory_fit` (reduced order).
    """
    p = _check(k, sigma_r_m, sigma_vr_mps, period_s, with_doppler, k_min=2 if with_doppler else 3)
    return _closed_cov(p.k, p.sigma_r_m**2, p.c0 if with_doppler else 0.0, p.period_s)


def ls_weights_closed(
    k: int,
    *,
    sigma_r_m: float,
    sigma_vr_mps: float | None,
    period_s: float,
    with_doppler: bool = True,
) -> NDArray[np.float64]:
    """W of the full (r, Vr, a) fit from the closed forms.  Shape (3, 2k) or (3, k).

    Column i = 1 … k (oldest first) weighs r_i, column k + i weighs Vr_i. With
    D′ = k(12C0 + k² − 1)(60C0 + k² − 4), D = (k+1)D′, D3 = k(k² − 1)(60C0 + k² − 4):

        W1r = 3(k−1)(k−2)[(k+2)(k+1) − 2i(4k+3−5i)]/D′
              − 24C0[(k+1)(2k²+7) − 15i(ik+k+1−2i) − 30C0(k+1)]/D                   (15)
        W1V = C0 T[6(k²−1)(k−2)(10i−4k−3) + 360C0(k+1−4i+2ik)]/D                    (16)
        W2r = 6[(4k−3)(k+2)(k+1) − 2ik(14k−15i) − 2i(15i−11)]/(T D′)
              + 360C0[k − 4ik − 2i(2−3i) + 1]/(T D)                                  (17)
        W2V = −12C0[(k+1)(14k²−11) − 30i(k²−1) + 120C0(k+1−3i)]/D                   (18)
        W3r = 60(k² − 6ik + 3k + 6i² − 6i + 2)/(T² D3)                               (19)
        W3V = −360C0(k − 2i + 1)/(T D3)                                              (20)

    Validity as for :func:`ls_covariance_closed` (range only: C0 = 0, k ≥ 3).
    """
    p = _check(k, sigma_r_m, sigma_vr_mps, period_s, with_doppler, k_min=2 if with_doppler else 3)
    return _closed_weights(p.k, p.c0 if with_doppler else 0.0, p.period_s, with_doppler)


def _reduced_closed(p: _Params) -> tuple[int, NDArray, NDArray]:
    """Closed forms of the reduced fits (k = 1 both variants, k = 2 range only), padded."""
    dr, T = p.sigma_r_m**2, p.period_s
    R = np.full((3, 3), np.nan)
    if p.with_doppler:  # k = 1: r̂ = r₁, V̂r = Vr₁
        R[:2, :2] = np.diag([dr, p.sigma_vr_mps**2])
        W = np.full((3, 2), np.nan)
        W[:2] = np.eye(2)
        return 2, R, W
    if p.k == 1:  # r̂ = r₁
        R[0, 0] = dr
        return 1, R, np.array([[1.0], [np.nan], [np.nan]])
    # k = 2 range only: the line through two points, r̂ = r₂, V̂r = (r₂ − r₁)/T
    R[:2, :2] = dr * np.array([[1.0, 1.0 / T], [1.0 / T, 2.0 / T**2]])
    W = np.array([[0.0, 1.0], [-1.0 / T, 1.0 / T], [np.nan, np.nan]])
    return 2, R, W


# --------------------------------------------------------------------------------------------
# The fit and the filter
# --------------------------------------------------------------------------------------------


class FiniteMemoryFit(NamedTuple):
    """Covariance and weights of the k-scan least-squares fit, with its order.

    Attributes:
        k: window length (scans).
        with_doppler: True for range + radial velocity, False for range only.
        order: number of parameters fitted: 1 (r), 2 (r, Vr) or 3 (r, Vr, a); the polynomial
            degree is ``order − 1``.
        R: (3, 3) error covariance of (r, Vr, a) at the newest scan; NaN rows/columns for
            parameters not fitted.
        W: (3, 2k) with Doppler (ranges then radial velocities, oldest first) or (3, k) range
            only; NaN rows for parameters not fitted.
        method: "closed" or "numeric".
    """

    k: int
    with_doppler: bool
    order: int
    R: NDArray[np.float64]
    W: NDArray[np.float64]
    method: str

    @property
    def sigma(self) -> NDArray[np.float64]:
        """(3,) σ = sqrt(diag R) of r, Vr, a (NaN where not fitted)."""
        return np.sqrt(np.diagonal(self.R))


def finite_memory_fit(
    k: int,
    *,
    sigma_r_m: float,
    sigma_vr_mps: float | None,
    period_s: float,
    with_doppler: bool = True,
    method: str = "closed",
) -> FiniteMemoryFit:
    """R and W of the largest fit the window allows (see :func:`max_order`).

    ``method="closed"`` uses eqs. 7–12 / 15–20 (and their C0 = 0 limit for range only) for the
    full order and the elementary formulas for the reduced ones; ``"numeric"`` solves the least
    squares (:func:`ls_covariance_numeric`). ``sigma_vr_mps`` is ignored (may be None) range
    only. σr in m, σVr in m/s, T in s; pass them by keyword (they are still accepted by position
    for the callers in ``core.tracking.stream`` and ``core.experiments.doppler_start``).
    """
    p = _check(k, sigma_r_m, sigma_vr_mps, period_s, with_doppler)
    check_choice("method", method, METHODS)
    if method == "numeric":
        n, R, W = _numeric(p, None)
    elif p.k < (2 if p.with_doppler else 3):
        n, R, W = _reduced_closed(p)
    else:
        c0 = p.c0 if p.with_doppler else 0.0
        n, R, W = (
            3,
            _closed_cov(p.k, p.sigma_r_m**2, c0, p.period_s),
            _closed_weights(p.k, c0, p.period_s, p.with_doppler),
        )
    return FiniteMemoryFit(p.k, bool(p.with_doppler), n, R, W, method)


def finite_memory_weights(
    k: int,
    *,
    sigma_r_m: float,
    sigma_vr_mps: float | None,
    period_s: float,
    with_doppler: bool = True,
    method: str = "closed",
) -> NDArray[np.float64]:
    """Just W of :func:`finite_memory_fit`.  Shape (3, 2k) or (3, k)."""
    return finite_memory_fit(
        k,
        sigma_r_m=sigma_r_m,
        sigma_vr_mps=sigma_vr_mps,
        period_s=period_s,
        with_doppler=with_doppler,
        method=method,
    ).W


def finite_memory_estimate(
    ranges: ArrayLike,
    radial_velocities: ArrayLike | None,
    fit: FiniteMemoryFit,
) -> NDArray[np.float64]:
    """θ̂ = W z for a batch of windows.  Shape (..., 3); NaN for parameters not fitted.

    Args:
        ranges: (..., k) ranges, oldest first.
        radial_velocities: (..., k) Doppler radial velocities, oldest first; required with a
            range + Doppler fit, must be None with a range-only one.
        fit: from :func:`finite_memory_fit`.
    """
    r = np.asarray(ranges, dtype=np.float64)
    if r.ndim < 1 or r.shape[-1] != fit.k:
        raise ParameterError(f"ranges must have last axis k = {fit.k} (got shape {r.shape})")
    n = fit.order
    est = r @ fit.W[:n, : fit.k].T
    if fit.with_doppler:
        if radial_velocities is None:
            raise ParameterError("radial_velocities must be given for a range + Doppler fit")
        v = np.asarray(radial_velocities, dtype=np.float64)
        if v.shape[-1:] != (fit.k,):
            raise ParameterError(
                f"radial_velocities must have last axis k = {fit.k} (got shape {v.shape})"
            )
        est = est + v @ fit.W[:n, fit.k :].T
    elif radial_velocities is not None:
        raise ParameterError("radial_velocities must be None for a range-only fit")
    out = np.full((*est.shape[:-1], 3), np.nan)
    out[..., :n] = est
    return out


class SlidingEstimates(NamedTuple):
    """The finite-memory filter run over a sequence of N scans.

    Attributes:
        estimates: (..., N, 3) θ̂ = (r, Vr, a) at every scan, NaN where not fitted.
        R: (N, 3, 3) error covariance at every scan (NaN where not fitted).
        order: (N,) number of parameters fitted at every scan.
        window: (N,) samples used, min(n, k) at scan n = 1 … N.
    """

    estimates: NDArray[np.float64]
    R: NDArray[np.float64]
    order: NDArray[np.int64]
    window: NDArray[np.int64]


def sliding_window_estimates(
    ranges: ArrayLike,
    radial_velocities: ArrayLike | None,
    k: int,
    *,
    sigma_r_m: float,
    sigma_vr_mps: float | None,
    period_s: float,
    method: str = "closed",
) -> SlidingEstimates:
    """Estimates at every scan n = 1 … N from the last min(n, k) samples.

    The window grows 1, 2, … up to k and then slides; the order grows with it (reduced order
    at the first scans). ``radial_velocities=None`` gives the range-only filter.

    Args:
        ranges: (..., N) ranges, oldest first; radial_velocities: (..., N) or None.
        k: window length.
    """
    with_doppler = radial_velocities is not None
    r = np.asarray(ranges, dtype=np.float64)
    v = None if radial_velocities is None else np.asarray(radial_velocities, dtype=np.float64)
    if r.ndim < 1 or r.shape[-1] < 1:
        raise ParameterError(f"ranges must have a last axis of N >= 1 scans (got {r.shape})")
    if v is not None and v.shape != r.shape:
        raise ParameterError(
            f"radial_velocities must have the shape of ranges {r.shape} (got {v.shape})"
        )
    kk = check_int("k", k, low=1, high=MAX_K)
    n_scans = r.shape[-1]
    window = np.minimum(np.arange(1, n_scans + 1), kk)
    est = np.full((*r.shape, 3), np.nan)
    R = np.full((n_scans, 3, 3), np.nan)
    order = np.zeros(n_scans, dtype=np.int64)
    for w in range(1, min(kk, n_scans) + 1):
        fit = finite_memory_fit(
            w,
            sigma_r_m=sigma_r_m,
            sigma_vr_mps=sigma_vr_mps,
            period_s=period_s,
            with_doppler=with_doppler,
            method=method,
        )
        if w < kk:  # the single scan n = w
            idx = [w - 1]
            rw = r[..., None, :w]
            vw = None if v is None else v[..., None, :w]
        else:  # every scan n >= k: sliding windows
            idx = list(range(kk - 1, n_scans))
            rw = np.lib.stride_tricks.sliding_window_view(r, kk, axis=-1)
            vw = None if v is None else np.lib.stride_tricks.sliding_window_view(v, kk, axis=-1)
        est[..., idx, :] = finite_memory_estimate(rw, vw, fit)
        R[idx] = fit.R
        order[idx] = fit.order
    return SlidingEstimates(est, R, order, window)


# --------------------------------------------------------------------------------------------
# The paper's Monte Carlo experiment
# --------------------------------------------------------------------------------------------


#: The three fitted parameters along the last axis of every ``FilterStats`` array, each as
#: (name, unit suffix): range r in m, radial velocity Vr in m/s, acceleration a in m/s². Tables
#: and documents name a parameter's values with them (``sigma_mc_r_m``, ``"vr_mps"``).
STATES: tuple[tuple[str, str], ...] = (("r", "m"), ("vr", "mps"), ("a", "mps2"))
#: ``STATES`` as names with their units: ``("r_m", "vr_mps", "a_mps2")``.
STATE_NAMES: tuple[str, ...] = tuple(f"{name}_{unit}" for name, unit in STATES)


class FilterStats(NamedTuple):
    """Error statistics of one filter variant of one radar, per k.  Every (K, 3) array holds
    (r, Vr, a) along the last axis; NaN where the parameter is not fitted.

    Attributes:
        order: (K,) number of parameters fitted.
        sigma_mc: (K, 3) Monte Carlo σ of the error (sample std about its mean, ddof = 1).
        bias_mc: (K, 3) Monte Carlo mean error.
        sigma_mc_ci95_lo / sigma_mc_ci95_hi: (K, 3) the 95% χ² band of ``sigma_mc``
            (``core.confidence.sigma_band``): the estimates are linear in Gaussian noise, so
            (trials − 1) s²/σ² is exactly χ²(trials − 1).
        sigma_analytic: (K, 3) sqrt(R_ii).
        bias_analytic: (K, 3) W z_true − θ_true: 0 (to rounding) for the full order, the model
            bias of a reduced fit otherwise (e.g. −a T/2 for the two-point range-only velocity).
    """

    order: NDArray[np.int64]
    sigma_mc: NDArray[np.float64]
    bias_mc: NDArray[np.float64]
    sigma_analytic: NDArray[np.float64]
    bias_analytic: NDArray[np.float64]
    sigma_mc_ci95_lo: NDArray[np.float64]
    sigma_mc_ci95_hi: NDArray[np.float64]


class GorshkovRadar(NamedTuple):
    """One radar of the experiment.

    Attributes:
        preset: the radar.
        range_only: statistics of the range-only filter.
        range_doppler: statistics of the range + radial-velocity filter.
        gain_mc: (K, 3) K(k) = (σ_range-only − σ_range+Vr)/σ_range-only · 100 % from the Monte
            Carlo σ, for r, Vr, a (NaN where either side is undefined).
        gain_analytic: (K, 3) the same from sqrt(R_ii).
        gain_mc_ci95_lo / gain_mc_ci95_hi: (K, 3) the 95% band of ``gain_mc``: both variants
            filter the same range noise, so their σ are correlated and the band is the
            delete-a-group jackknife over ``BAND_GROUPS`` groups of trials
            (``core.confidence``), which keeps that pairing (two independent χ² bands would
            be several times too wide where Doppler adds little).
    """

    preset: RadarPreset
    range_only: FilterStats
    range_doppler: FilterStats
    gain_mc: NDArray[np.float64]
    gain_analytic: NDArray[np.float64]
    gain_mc_ci95_lo: NDArray[np.float64]
    gain_mc_ci95_hi: NDArray[np.float64]


class GorshkovResult(NamedTuple):
    """The whole experiment.

    Attributes:
        ks: (K,) window lengths; the estimate for k is made at scan k from scans 1 … k.
        trials: Monte Carlo trials per radar.
        seed: root of ``numpy.random.SeedSequence``; radar j of ``radars`` draws from child j.
        r0, vr0, a0: true range (m), radial velocity (m/s), acceleration (m/s²) at scan 1; the
            truth of a radar is ``quadratic_truth(r0, vr0, a0, preset.period_s, n_points)``.
        n_points: scans simulated.
        radars: one entry per preset, in the order given.
    """

    ks: NDArray[np.int64]
    trials: int
    seed: int
    r0: float
    vr0: float
    a0: float
    n_points: int
    radars: tuple[GorshkovRadar, ...]


def gain_percent(sigma_range_only: ArrayLike, sigma_range_doppler: ArrayLike) -> NDArray:
    """K = (σ_range-only − σ_range+Vr) / σ_range-only · 100 %, NaN where undefined."""
    a = np.asarray(sigma_range_only, dtype=np.float64)
    b = np.asarray(sigma_range_doppler, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (a - b) / a * 100.0


def quadratic_truth(
    r0: float, vr0: float, a0: float, period: float, n_points: int
) -> NDArray[np.float64]:
    """True (r, Vr, a) of uniformly accelerated radial motion at t = 0, T, …  Shape (n, 3)."""
    t = np.arange(n_points, dtype=np.float64) * period
    return np.stack([r0 + vr0 * t + 0.5 * a0 * t * t, vr0 + a0 * t, np.full_like(t, a0)], axis=-1)


class _Moments:
    """Per-row mean and sum of squared deviations, merged block by block (Chan et al. 1979)."""

    def __init__(self, rows: int) -> None:
        self.n = 0
        self.mean = np.zeros(rows)
        self.m2 = np.zeros(rows)

    def add(self, e: NDArray[np.float64]) -> None:
        """Add a block ``e`` of shape (rows, trials); ``e`` is overwritten."""
        nb = e.shape[1]
        mb = e.mean(axis=1)
        e -= mb[:, None]
        m2b = np.einsum("ij,ij->i", e, e)
        n = self.n + nb
        delta = mb - self.mean
        self.mean = self.mean + delta * (nb / n)
        self.m2 = self.m2 + m2b + delta * delta * (self.n * nb / n)
        self.n = n

    def std(self) -> NDArray[np.float64]:
        return np.sqrt(self.m2 / (self.n - 1))


class _GroupMoments:
    """Per-group Σe and Σe² of each row (trial t in group t mod G, ``core.confidence``), for
    the leave-one-group-out σ of the jackknife."""

    def __init__(self, rows: int) -> None:
        self.n = np.zeros(BAND_GROUPS, dtype=np.int64)
        self.s1 = np.zeros((BAND_GROUPS, rows))
        self.s2 = np.zeros((BAND_GROUPS, rows))

    def add(self, e: NDArray[np.float64]) -> None:
        """Add a block ``e`` of shape (rows, trials), the trials after those already added."""
        offset = int(self.n.sum())
        self.n += group_counts(offset, e.shape[1])
        self.s1 += group_sums(e, offset)
        self.s2 += group_sums(e, offset, square=True)

    def leave_one_out_std(self) -> NDArray[np.float64]:
        """(G, rows) the sample std (ddof = 1) of all trials but group g's; NaN for an empty
        group."""
        n = (self.n.sum() - self.n)[:, None].astype(np.float64)
        s1 = self.s1.sum(axis=0) - self.s1
        s2 = self.s2.sum(axis=0) - self.s2
        with np.errstate(invalid="ignore", divide="ignore"):
            out = np.sqrt(np.maximum(s2 - s1 * s1 / n, 0.0) / (n - 1.0))
        out[self.n == 0] = np.nan
        return out


def _stacked_weights(fits: Sequence[FiniteMemoryFit], n_points: int) -> NDArray[np.float64]:
    """All windows' weights in one (3K, 2 n_points) matrix acting on (r_1 … r_n, Vr_1 … Vr_n).

    Rows 3m … 3m + 2 are (r, Vr, a) of window m over scans 1 … k_m; unfitted rows and the
    Vr columns of a range-only fit are zero.
    """
    out = np.zeros((3 * len(fits), 2 * n_points))
    for m, fit in enumerate(fits):
        k, n = fit.k, fit.order
        out[3 * m : 3 * m + n, :k] = fit.W[:n, :k]
        if fit.with_doppler:
            out[3 * m : 3 * m + n, n_points : n_points + k] = fit.W[:n, k:]
    return out


def _resolve_presets(presets: Iterable[RadarPreset | str] | None) -> list[RadarPreset]:
    if presets is None:
        return list(PRESETS.values())
    out = [p if isinstance(p, RadarPreset) else preset(p) for p in presets]
    if not out:
        raise ParameterError(f"presets must name at least one of {', '.join(PRESETS)}")
    return out


def run_gorshkov(
    presets: Iterable[RadarPreset | str] | None = None,
    trials: int = default("trials"),
    seed: int = default("seed"),
    ks: Sequence[int] = range(1, 21),
    r0: float = 100_000.0,
    vr0: float = -300.0,
    a0: float = 5.0,
    n_points: int = 20,
    method: str = "closed",
    block: int = BLOCK_TRIALS,
) -> GorshkovResult:
    """The paper's Monte Carlo: σ of the r, Vr, a errors per radar and k, both variants.

    A target in uniformly accelerated radial motion (r0, Vr0, a0 at scan 1) is measured at
    ``n_points`` scans with range noise σr and Doppler noise σVr of each radar. For each k the
    estimate at scan k is formed from scans 1 … k (the window grows as in
    :func:`sliding_window_estimates`) with the weights W of every k stacked in one matrix, so a
    block of trials costs one ``(3K, 2n) @ (2n, trials)`` product per variant. Estimates are
    made from the *noisy* measurements and the true state is subtracted (nothing assumes the
    fit unbiased). Both variants filter the same range noise (common random numbers).

    Trials run in blocks of ``block``; radar j draws, block after block, from one generator
    seeded with child j of ``SeedSequence(seed)``, so results are bit-reproducible for the same
    seed, presets order and block size.

    Args:
        presets: RadarPreset objects or names; None for all six.
        trials: Monte Carlo trials per radar (>= 2).
        ks: window lengths, each in [1, n_points].
        method: "closed" or "numeric" weights.
    """
    radars = _resolve_presets(presets)
    trials = int(check("trials", trials))
    seed = int(check("seed", seed))
    n_points = check_int("n_points", n_points, low=1, high=MAX_K)
    block = check_int("block", block, low=1)
    ks_list = [check_int("k", k, low=1, high=n_points) for k in ks]
    if not ks_list:
        raise ParameterError("ks must hold at least one window length")
    r0 = check_real("r0", r0, low=0.0)
    vr0 = check_real("vr0", vr0)
    a0 = check_real("a0", a0)
    check_choice("method", method, METHODS)
    sizes = [block] * (trials // block) + ([trials % block] if trials % block else [])
    children = np.random.SeedSequence(seed).spawn(len(radars))
    out = []
    for rad, child in zip(radars, children, strict=True):
        T = rad.period_s
        truth = quadratic_truth(r0, vr0, a0, T, n_points)
        fits = {
            dop: [
                finite_memory_fit(
                    k,
                    sigma_r_m=rad.sigma_r_m,
                    sigma_vr_mps=rad.sigma_vr_mps,
                    period_s=T,
                    with_doppler=dop,
                    method=method,
                )
                for k in ks_list
            ]
            for dop in (False, True)
        }
        weights = {dop: _stacked_weights(fits[dop], n_points) for dop in (False, True)}
        # True state at scan k of every window, aligned with the rows of ``weights``.
        target = np.concatenate([truth[k - 1] for k in ks_list])[:, None]
        moments = {dop: _Moments(3 * len(ks_list)) for dop in (False, True)}
        groups = {dop: _GroupMoments(3 * len(ks_list)) for dop in (False, True)}
        clean = np.concatenate([truth[:, 0], truth[:, 1]])[:, None]
        scale = np.repeat([rad.sigma_r_m, rad.sigma_vr_mps], n_points)[:, None]
        rng = np.random.default_rng(child)
        for size in sizes:
            # (2 n_points, size): ranges of scans 1 … n, then radial velocities.
            z = rng.standard_normal((2 * n_points, size))
            z *= scale
            z += clean
            # The errors a slice of trials at a time: (3K, size) at once would be the peak of
            # the whole run; the moments merge slice by slice to the same figures.
            for lo in range(0, size, ERROR_SLICE_TRIALS):
                z_slice = z[:, lo : lo + ERROR_SLICE_TRIALS]
                for dop in (False, True):
                    err = weights[dop] @ z_slice
                    err -= target
                    groups[dop].add(err)
                    moments[dop].add(err)
        stats = {}
        loo_sigma = {}  # (G, K, 3) leave-one-group-out σ, NaN where not fitted
        for dop in (False, True):
            nk = len(ks_list)
            sig_mc = np.full((nk, 3), np.nan)
            bias_mc = np.full((nk, 3), np.nan)
            sig_an = np.full((nk, 3), np.nan)
            bias_an = np.full((nk, 3), np.nan)
            order = np.zeros(nk, dtype=np.int64)
            for idx, (k, fit) in enumerate(zip(ks_list, fits[dop], strict=True)):
                n = fit.order
                order[idx] = n
                sig_mc[idx, :n] = moments[dop].std()[3 * idx : 3 * idx + n]
                bias_mc[idx, :n] = moments[dop].mean[3 * idx : 3 * idx + n]
                sig_an[idx] = fit.sigma
                est_true = finite_memory_estimate(truth[:k, 0], truth[:k, 1] if dop else None, fit)
                bias_an[idx] = est_true - truth[k - 1]
            fitted = np.isfinite(sig_mc)
            loo = groups[dop].leave_one_out_std().reshape(BAND_GROUPS, nk, 3)
            loo_sigma[dop] = np.where(fitted, loo, np.nan)
            lo, hi = sigma_band(sig_mc, trials)
            stats[dop] = FilterStats(order, sig_mc, bias_mc, sig_an, bias_an, lo, hi)
        gain = gain_percent(stats[False].sigma_mc, stats[True].sigma_mc)
        gain_lo, gain_hi = jackknife_band(gain, gain_percent(loo_sigma[False], loo_sigma[True]))
        out.append(
            GorshkovRadar(
                preset=rad,
                range_only=stats[False],
                range_doppler=stats[True],
                gain_mc=gain,
                gain_analytic=gain_percent(stats[False].sigma_analytic, stats[True].sigma_analytic),
                gain_mc_ci95_lo=gain_lo,
                gain_mc_ci95_hi=gain_hi,
            )
        )
    return GorshkovResult(
        ks=np.asarray(ks_list, dtype=np.int64),
        trials=trials,
        seed=seed,
        r0=r0,
        vr0=vr0,
        a0=a0,
        n_points=n_points,
        radars=tuple(out),
    )
