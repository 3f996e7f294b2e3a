"""Exact quantiles in two passes (``core.order_statistics``) and the velocity Monte Carlo's flat
memory that they allow."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from radarviz.core.order_statistics import TwoPassQuantiles
from radarviz.core.velocity import estimate


@pytest.mark.parametrize("block", [1, 97, 5000])
def test_two_pass_quantiles_equal_numpy_quantile_bit_for_bit(block: int) -> None:
    """Heavy-tailed columns (Cauchy, and one with ties), fed in blocks, split over sets: every
    set's quantiles equal ``numpy.quantile`` of that set's values exactly."""
    rng = np.random.default_rng(3)
    n, sets = 5000, 4
    v = np.stack(
        [rng.standard_cauchy(n), rng.integers(0, 7, n).astype(float), rng.normal(5.0, 1e-9, n)],
        -1,
    )
    s = 1 + rng.integers(0, sets - 1, n)
    probs = [0.0, 0.25, 0.5, 0.75, 0.9, 1.0]
    q = TwoPassQuantiles(probs, sets, 3)
    for i in range(0, n, block):
        q.count(v[i : i + block], s[i : i + block])
    for i in range(0, n, block):
        q.select(v[i : i + block], s[i : i + block])
    got = q.result()
    np.testing.assert_array_equal(got[0], np.quantile(v, probs, axis=0))
    for st in range(1, sets):
        np.testing.assert_array_equal(got[st], np.quantile(v[s == st], probs, axis=0))


_PEAK = """
import gc, sys, tracemalloc
from radarviz.core.velocity import estimate
estimate.BLOCK_TRIALS, estimate.KEEP_TRIALS = 2048, 4096
problem = estimate.baseline_problem()
estimate.monte_carlo_velocity(problem, 4 * 2048, 5)  # warm: imports and caches
gc.collect()
tracemalloc.start()
estimate.monte_carlo_velocity(problem, int(sys.argv[1]), 5)
print(tracemalloc.get_traced_memory()[1])
"""


def test_velocity_monte_carlo_memory_does_not_grow_with_trials() -> None:
    """With small blocks and a small keep budget, 16× the trials costs no more than a few
    blocks of memory more (a stored (trials, 3) array would add 24 B per trial). Each peak is
    taken in a fresh process, so no other test's threads or garbage count."""

    def peak(trials: int) -> int:
        out = subprocess.run(
            [sys.executable, "-c", _PEAK, str(trials)], capture_output=True, text=True, check=True
        )
        return int(out.stdout.strip())

    small, large = peak(8 * 2048), peak(128 * 2048)
    assert large - small < 0.1 * 24 * (128 - 8) * 2048, (small, large)


def test_velocity_monte_carlo_is_the_same_kept_or_drawn_again(monkeypatch) -> None:
    problem = estimate.baseline_problem()
    kept = estimate.monte_carlo_velocity(problem, 20_000, 9)
    monkeypatch.setattr(estimate, "KEEP_TRIALS", 1000)
    again = estimate.monte_carlo_velocity(problem, 20_000, 9)
    np.testing.assert_array_equal(kept.sigma_robust, again.sigma_robust)
    np.testing.assert_array_equal(kept.sigma_robust_ci95_lo, again.sigma_robust_ci95_lo)
    np.testing.assert_allclose(kept.covariance, again.covariance, rtol=1e-12)
