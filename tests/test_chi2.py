"""``core.chi2`` against scipy's χ² distribution (an independent implementation)."""

from __future__ import annotations

import math

import pytest
from scipy import special, stats

from radarviz.core.chi2 import chi2_quantile, gamma_tails

DOFS = [*range(1, 41), 60, 100, 250, 1000, 4000, 10_000]
PROBABILITIES = [1e-9, 1e-6, 5e-4, 0.025, 0.1, 0.5, 0.9, 0.975, 0.999, 0.9995, 1 - 1e-6]


@pytest.mark.parametrize("dof", DOFS)
def test_the_quantile_is_scipys(dof: int) -> None:
    for p in PROBABILITIES:
        ours, theirs = chi2_quantile(p, dof), float(stats.chi2.ppf(p, dof))
        assert math.isclose(ours, theirs, rel_tol=1e-12), (p, dof, ours, theirs)


def test_the_incomplete_gamma_tails_are_scipys() -> None:
    for a in (0.5, 1.0, 1.5, 3.0, 10.5, 200.0):
        for x in (1e-8, 0.01, 0.5, a, a + 1.0, 3.0 * a, 10.0 * a + 5.0):
            p, q = gamma_tails(a, x)
            assert math.isclose(p, special.gammainc(a, x), rel_tol=1e-12, abs_tol=1e-300)
            assert math.isclose(q, special.gammaincc(a, x), rel_tol=1e-11, abs_tol=1e-300)


@pytest.mark.parametrize("p, dof", [(0.0, 3), (1.0, 3), (0.5, 0), (float("nan"), 2)])
def test_out_of_range_is_refused(p: float, dof: float) -> None:
    with pytest.raises(ValueError, match="chi2_quantile needs 0 < p < 1 and dof > 0"):
        chi2_quantile(p, dof)
