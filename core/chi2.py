"""The χ² distribution's quantile, in plain Python floats (no scipy).

The consistency monitor's bands and the association's gate need χ²_D quantiles; taking them
from ``scipy.special`` costs a ``radarviz track`` run 0.25 s of start-up and 24 MB, for a
handful of numbers. Here, with a = D/2 and the regularised incomplete gamma functions

    P(a, x) = γ(a, x)/Γ(a),   Q(a, x) = 1 − P(a, x),

the quantile is χ²_{D, p} = 2 x with P(a, x) = p. P is summed as its series
x^a e^(−x)/Γ(a + 1) · Σ_n x^n / ((a + 1)…(a + n)) for x < a + 1, and Q as its continued
fraction (modified Lentz) otherwise (Press et al., *Numerical Recipes*, 3rd ed., sec. 6.2);
the equation is solved in the smaller tail (P for p ≤ ½, Q = 1 − p above) by Newton's method
from the Wilson–Hilferty start, dP/dx = x^(a−1) e^(−x)/Γ(a), kept inside a bracket that
bisection narrows when a step would leave it. ``tests/test_chi2.py`` holds it to
``scipy.stats.chi2.ppf`` at 10⁻¹² relative over D = 1 … 10⁴.
"""

from __future__ import annotations

import math
from statistics import NormalDist

_EPS = 1e-16
_TINY = 1e-300


def _log_prefactor(a: float, x: float) -> float:
    """log(x^a e^(−x) / Γ(a))."""
    return a * math.log(x) - x - math.lgamma(a)


def _p_series(a: float, x: float) -> float:
    term = total = 1.0 / a
    n = 1
    while n < 100_000:
        term *= x / (a + n)
        total += term
        if abs(term) < abs(total) * _EPS:
            break
        n += 1
    return total * math.exp(_log_prefactor(a, x))


def _q_fraction(a: float, x: float) -> float:
    b = x + 1.0 - a
    c = 1.0 / _TINY
    d = 1.0 / b
    h = d
    for i in range(1, 100_000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = d if abs(d) > _TINY else _TINY
        c = b + an / c
        c = c if abs(c) > _TINY else _TINY
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < _EPS:
            break
    return math.exp(_log_prefactor(a, x)) * h


def gamma_tails(a: float, x: float) -> tuple[float, float]:
    """(P(a, x), Q(a, x)) for a > 0, x ≥ 0 (module docstring); the one not computed
    directly is 1 minus the other."""
    if x <= 0.0:
        return 0.0, 1.0
    if x < a + 1.0:
        p = _p_series(a, x)
        return p, 1.0 - p
    q = _q_fraction(a, x)
    return 1.0 - q, q


def chi2_quantile(p: float, dof: float) -> float:
    """The p-quantile of χ² with ``dof`` degrees of freedom (0 < p < 1, dof > 0)."""
    if not (0.0 < p < 1.0) or not dof > 0.0:
        raise ValueError(f"chi2_quantile needs 0 < p < 1 and dof > 0 (got p={p!r}, dof={dof!r})")
    a = dof / 2.0
    upper = p > 0.5
    target = 1.0 - p if upper else p
    # Wilson–Hilferty: χ²/D ≈ (1 − 2/(9D) + z √(2/(9D)))³, in the gamma variable x = χ²/2.
    z = NormalDist().inv_cdf(p)
    v = 2.0 / (9.0 * dof)
    base = 1.0 - v + z * math.sqrt(v)
    if base > 0.1:
        x = a * base**3
    else:  # far in the lower tail of few degrees of freedom: P ≈ x^a / Γ(a + 1)
        x = math.exp((math.log(p) + math.lgamma(a + 1.0)) / a)
    lo, hi = 0.0, math.inf
    for _ in range(200):
        pp, qq = gamma_tails(a, x)
        f = (qq if upper else pp) - target
        if f == 0.0:
            break
        # The tail decreases (Q) or increases (P) with x: keep the bracket of the root.
        if (f > 0.0) != upper:
            hi = x
        else:
            lo = x
        slope = math.exp(_log_prefactor(a, x)) / x  # dP/dx
        step = f / slope if slope > 0.0 else math.inf
        nxt = x + step if upper else x - step
        if nxt == x:
            break
        if not (lo < nxt < hi) or not math.isfinite(nxt):
            if not math.isfinite(hi):
                nxt = 2.0 * x
            elif lo > 0.0 and hi > 4.0 * lo:  # a bracket over orders of magnitude
                nxt = math.sqrt(lo * hi)
            else:
                nxt = 0.5 * (lo + hi)
        if abs(nxt - x) <= 4.0 * _EPS * x:
            x = nxt
            break
        x = nxt
    return 2.0 * x
