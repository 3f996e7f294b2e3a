"""Streaming metrics equal the direct computation; the NEES band has its stated coverage."""

from __future__ import annotations

import numpy as np

from radarviz.core.filters.state import as_batch
from radarviz.core.metrics import MetricsAccumulator, delta_percent, nees_band


def test_accumulator_equals_direct_statistics_over_blocks() -> None:
    rng = np.random.default_rng(2)
    m, steps = 3000, 3
    truth = np.array([[1e5, 10.0, 2e4, -5.0]] * steps)
    acc = MetricsAccumulator(steps)
    xs, Ps = [], []
    for n in range(steps):
        a = rng.normal(size=(m, 4, 4))
        P = a @ a.transpose(0, 2, 1) * 100.0 + np.eye(4) * 50.0
        x = truth[n] + rng.normal(size=(m, 4)) * [20.0, 1.0, 30.0, 2.0] + [5.0, 0, -3.0, 0]
        xs.append(x)
        Ps.append(P)
        for lo in range(0, m, 1024):  # blocks of unequal size, merged
            block = MetricsAccumulator(steps)
            block.add(n, as_batch(x[lo : lo + 1024], P[lo : lo + 1024]), truth[n])
            acc.merge(block)
    res = acc.result()
    for n in range(steps):
        e = xs[n] - truth[n]
        u = truth[n, [0, 2]] / np.hypot(truth[n, 0], truth[n, 2])
        epos = e[:, [0, 2]]
        Ppos = Ps[n][:, [0, 2]][:, :, [0, 2]]
        np.testing.assert_allclose(res.bias_x_m[n], e[:, 0].mean(), rtol=1e-12)
        np.testing.assert_allclose(res.rmse_x_m[n], np.sqrt((e[:, 0] ** 2).mean()), rtol=1e-12)
        np.testing.assert_allclose(res.std_x_m[n], e[:, 0].std(ddof=1), rtol=1e-9)
        np.testing.assert_allclose(res.bias_range_m[n], (epos @ u).mean(), rtol=1e-9)
        np.testing.assert_allclose(
            res.bias_cross_m[n], (epos @ np.array([-u[1], u[0]])).mean(), rtol=1e-9
        )
        np.testing.assert_allclose(
            res.sigma_x_filter_m[n], np.sqrt(Ps[n][:, 0, 0].mean()), rtol=1e-12
        )
        nees_pos = np.einsum("mi,mij,mj->m", epos, np.linalg.inv(Ppos), epos).mean()
        nees = np.einsum("mi,mij,mj->m", e, np.linalg.inv(Ps[n]), e).mean()
        np.testing.assert_allclose(res.nees_pos[n], nees_pos, rtol=1e-9)
        np.testing.assert_allclose(res.nees_state[n], nees, rtol=1e-9)


def test_nees_band_coverage_is_95_percent() -> None:
    """Averages of M χ²(2) draws fall inside the band with probability 0.95."""
    rng = np.random.default_rng(9)
    runs, trials = 50, 40_000
    lo, hi = nees_band(2, runs)
    avg = rng.chisquare(2, size=(trials, runs)).mean(axis=1)
    inside = np.mean((avg >= lo) & (avg <= hi))
    se = np.sqrt(0.95 * 0.05 / trials)
    assert abs(inside - 0.95) < 4.5 * se


def test_delta_percent() -> None:
    np.testing.assert_allclose(delta_percent(np.array([102.0]), np.array([100.0])), [2.0])


def test_staged_sums_equal_scan_by_scan_sums_bit_for_bit(monkeypatch) -> None:
    """Staging scans (``STAGE_ROWS``) forms the same sums, added in the same order, as adding
    every scan on its own — with blocks of changing size (an empty one too), scans out of
    order and repeated."""
    import radarviz.core.metrics as metrics

    rng = np.random.default_rng(4)
    steps = 7
    truth = np.array([[1e5 + 2e3 * n, 200.0, 3e3 * n, 10.0] for n in range(steps)])
    adds = []
    for n, m in [(0, 50), (1, 50), (3, 0), (3, 50), (2, 50), (2, 31), (4, 300), (5, 300), (4, 2)]:
        a = rng.normal(size=(m, 4, 4))
        P = a @ a.transpose(0, 2, 1) * 100.0 + np.eye(4) * 50.0
        x = truth[n] + rng.normal(size=(m, 4)) * [200.0, 5.0, 300.0, 5.0]
        adds.append((n, as_batch(x, P)))

    def accumulate() -> tuple[np.ndarray, np.ndarray]:
        acc = MetricsAccumulator(steps)
        for n, st in adds:
            acc.add(n, st, truth[n])
        return acc.to_arrays()

    staged = accumulate()
    monkeypatch.setattr(metrics, "STAGE_ROWS", 1)  # every scan summed as it arrives
    one_by_one = accumulate()
    np.testing.assert_array_equal(staged[0], one_by_one[0])
    np.testing.assert_array_equal(staged[1], one_by_one[1])
    assert staged[0].tolist() == [50, 50, 81, 50, 302, 300, 0]
