"""Monte Carlo confidence bands, and verdicts on a claim drawn from a Monte Carlo curve.

A Monte Carlo curve is an estimate: with M runs it carries an error of order 1/√M, and a
claim read off the curve ("|Δx| ≤ 2.1%") is only decided when the curve's error band lies
wholly on one side of the claim's bound. This module computes the bands and the verdicts;
the experiments supply the run-to-run data.

Two methods, each where it is right:

**Delete-a-group jackknife** (``jackknife_band``), for any smooth function of per-run sums:
RMSE = √(Σe²/M), the ratio Δx = (σ̂_a − σ̂_b)/σ̂_b of two methods, a sample std, a mean NEES.
The runs are dealt into G groups (run j into group j mod G, ``group_counts``); θ̂ is the
statistic of all runs and θ̂₍g₎ the statistic with group g left out. Then

    Var(θ̂) ≈ (G − 1)/G · Σ_g (θ̂₍g₎ − θ̄)²,   θ̄ = mean_g θ̂₍g₎,

and θ̂ ± t_{G−1, 0.975} · √Var is a 95% band (Efron and Tibshirani 1993, ch. 11; Shao and Tu
1995, sec. 2.3.2 for grouped runs). It needs no derivative of θ, and it keeps common random
numbers: when two methods filter the same runs, group g holds the same runs for both, so the
positive correlation that makes a difference of methods precise is kept inside every
leave-out (a band from each method's own error would be far too wide). G − 1 degrees of
freedom in Student's t account for the band's own uncertainty.

**χ² interval for a σ** (``sigma_band``), for the sample standard deviation s of n
independent *Gaussian* errors: (n − 1) s²/σ² ~ χ²(n − 1), so

    σ ∈ [s √((n − 1)/χ²_{n−1, 0.975}),  s √((n − 1)/χ²_{n−1, 0.025})].

It is exact for the finite-memory fit (its estimates are linear in Gaussian noise) and wrong
for heavy-tailed errors, where the jackknife is the one to use.

Verdicts (``claim_verdict``): a claim |θ(n)| ≤ B over a window of n is

- ``"holds"`` when every band of the window lies inside [−B, B];
- ``"does not hold"`` when some band lies wholly outside [−B, B];
- ``"not resolved"`` otherwise: more runs shrink the bands by 1/√M, and a claim whose true
  curve touches its bound is not resolved at any M.

The bands are pointwise (95% at each n, not jointly over the window); the curves of one
experiment share their runs, so neighbouring scans' errors are strongly correlated and the
verdict over a window of ~20 scans is close to the pointwise one.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Groups G of the delete-a-group jackknife. 32 groups give t_{31, 0.975} = 2.04 (against 1.96
#: for an infinite number): the band's own uncertainty costs 4% of its width. A power of two
#: divides the 16 384-run blocks of the Prosov experiment, so every block deals its runs to the
#: groups the same way.
BAND_GROUPS = 32
#: The band's two-sided probability.
BAND_LEVEL = 0.95

Verdict = Literal["holds", "does not hold", "not resolved"]
VERDICTS: tuple[Verdict, ...] = ("holds", "does not hold", "not resolved")


def student_t_quantile(dof: int | NDArray[np.int64], level: float = BAND_LEVEL) -> NDArray:
    """The two-sided ``level`` quantile t_{dof, (1 + level)/2} of Student's t (NaN where
    dof ≤ 0).

    ``scipy.stats.t.ppf``'s own function, ``scipy.special.stdtrit``, called directly:
    ``scipy.stats`` adds about 50 MB to a process and scipy.special alone 14 MB; imported
    here, not at module level, as only the bands need it.
    """
    from scipy.special import stdtrit

    d = np.asarray(dof, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.asarray(np.where(d > 0, stdtrit(d, 0.5 + level / 2.0), np.nan), np.float64)


def chi2_ppf(p: ArrayLike, dof: ArrayLike) -> NDArray[np.float64]:
    """The p-quantiles of χ² with ``dof`` degrees of freedom, broadcast (NaN where dof ≤ 0):
    ``scipy.stats.chi2.ppf``'s own arithmetic, 2 · gammaincinv(dof / 2, p), without importing
    ``scipy.stats`` (``student_t_quantile``)."""
    from scipy.special import gammaincinv

    d = np.asarray(dof, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        q = 2 * gammaincinv(d / 2, np.asarray(p, dtype=np.float64))
    return np.asarray(np.where(d > 0, q, np.nan), dtype=np.float64)


def group_counts(offset: int, runs: int, groups: int = BAND_GROUPS) -> NDArray[np.int64]:
    """How many of runs offset … offset + runs − 1 fall in each group (run j in group j mod G)."""
    q, rest = divmod(runs, groups)
    counts = np.full(groups, q, dtype=np.int64)
    counts[(offset + np.arange(rest)) % groups] += 1
    return counts


def group_sums(
    terms: NDArray[np.float64], offset: int, groups: int = BAND_GROUPS, *, square: bool = False
) -> NDArray[np.float64]:
    """Per-group sums of per-run ``terms`` (..., m) (of their squares with ``square``):
    (groups, ...); run i is run offset + i.

    Run offset + i goes to group (offset + i) mod G, so a long experiment fed block by block
    deals its runs exactly as one block of all of them would. The sums over each group's
    runs are one matrix product (ones · terms) or one ``einsum`` of the squares, a fraction of
    the cost of a strided reduction.
    """
    m = terms.shape[-1]
    q = m // groups
    out = np.zeros((groups, *terms.shape[:-1]))
    if q:
        full = terms[..., : q * groups].reshape(*terms.shape[:-1], q, groups)
        if square:
            part = np.einsum("...qg,...qg->...g", full, full)
        else:
            part = np.matmul(np.ones(q), full)
        out += np.moveaxis(part, -1, 0)  # row r: runs with local index ≡ r (mod G)
    if m > q * groups:  # the last m mod G runs, one to each of the first groups
        rest = np.moveaxis(terms[..., q * groups :], -1, 0)
        out[: m - q * groups] += rest * rest if square else rest
    # Local residue r belongs to group (offset + r) mod G.
    return np.roll(out, offset % groups, axis=0)


def jackknife_band(
    estimate: ArrayLike,
    leave_out: ArrayLike,
    level: float = BAND_LEVEL,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The delete-a-group jackknife band (lo, hi) of ``estimate`` (module docstring).

    Args:
        estimate: θ̂ from all runs, any shape S.
        leave_out: (G, *S) θ̂₍g₎ with group g left out; NaN for a group that holds no run at
            that element (it is not counted in G).
        level: two-sided probability of the band.

    Returns:
        lo, hi of shape S; NaN where fewer than two groups are available or θ̂ is NaN.
    """
    theta = np.asarray(estimate, dtype=np.float64)
    loo = np.asarray(leave_out, dtype=np.float64)
    ok = np.isfinite(loo)
    g = ok.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(ok, loo, 0.0).sum(axis=0) / g
        ss = np.where(ok, (loo - mean) ** 2, 0.0).sum(axis=0)
        half = student_t_quantile(np.maximum(g - 1, 1), level) * np.sqrt((g - 1) / g * ss)
    half = np.where(g >= 2, half, np.nan)
    return theta - half, theta + half


def sigma_band(
    sigma: ArrayLike, samples: int, level: float = BAND_LEVEL
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The χ² band (lo, hi) of a σ estimated as the sample std (ddof = 1) of ``samples``
    independent Gaussian errors (module docstring)."""
    s = np.asarray(sigma, dtype=np.float64)
    dof = samples - 1
    tail = (1.0 - level) / 2.0
    chi_hi, chi_lo = chi2_ppf([1.0 - tail, tail], dof)
    return s * np.sqrt(dof / chi_hi), s * np.sqrt(dof / chi_lo)


def claim_verdict(lo: ArrayLike, hi: ArrayLike, bound: float) -> Verdict:
    """The verdict on the claim |θ| ≤ ``bound`` at every point of a window, from the band
    (lo, hi) of θ at those points (module docstring). A point without a band (NaN) can
    neither confirm nor refute the claim."""
    lo_a = np.asarray(lo, dtype=np.float64)
    hi_a = np.asarray(hi, dtype=np.float64)
    if lo_a.size == 0:
        raise ValueError("a claim needs at least one point")
    if np.any((lo_a > bound) | (hi_a < -bound)):
        return "does not hold"
    if np.all((lo_a >= -bound) & (hi_a <= bound)):  # False at NaN
        return "holds"
    return "not resolved"
