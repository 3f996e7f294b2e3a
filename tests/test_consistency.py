"""The NIS consistency monitor (core.tracking.consistency): its band, a matched filter in band
≈ 95% of the time within Monte Carlo error, the streaming monitor equal to the batched test."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from radarviz.core.filters.measurement import PositionMeasurement
from radarviz.core.filters.state import CVBatch
from radarviz.core.filters.step import cv_step
from radarviz.core.tracking.consistency import (
    ConsistencyMonitor,
    nis_band,
    out_of_band,
    windowed_nis,
)

T, SIGMA_A, STEPS, RUNS, WINDOW = 2.0, 3.0, 120, 400, 10
R = np.array([[900.0, 200.0], [200.0, 400.0]])


def _matched_run(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A CV target with white-noise acceleration σa, tracked by the matched Kalman filter
    (started at the truth with the truth's spread): the NIS (N − 1, M) and dof (N − 1,)."""
    n = 4
    x = np.zeros((RUNS, n))
    x[:, 1], x[:, 3] = 150.0, -40.0
    P0 = np.diag([100.0, 25.0, 100.0, 25.0])
    est = CVBatch(
        x + rng.standard_normal((RUNS, n)) * np.sqrt(np.diag(P0)), np.tile(P0, (RUNS, 1, 1))
    )
    L = np.linalg.cholesky(R)
    g = np.array([T * T / 2.0, T])
    nis, dof = [], []
    Rd = {(0, 0): R[0, 0], (0, 1): R[0, 1], (1, 1): R[1, 1]}
    for _ in range(STEPS - 1):
        a = SIGMA_A * rng.standard_normal((RUNS, 2))  # constant over the period (the DWNA model)
        x[:, 0] += T * x[:, 1] + g[0] * a[:, 0]
        x[:, 1] += g[1] * a[:, 0]
        x[:, 2] += T * x[:, 3] + g[0] * a[:, 1]
        x[:, 3] += g[1] * a[:, 1]
        z = x[:, [0, 2]] + rng.standard_normal((RUNS, 2)) @ L.T
        est, s = cv_step(est, T, SIGMA_A, [PositionMeasurement((z[:, 0], z[:, 1]), Rd)])
        nis.append(s.nis)
        dof.append(s.dof)
    return np.array(nis), np.array(dof)


def test_band_is_the_chi2_interval_of_the_window_mean() -> None:
    lo, hi = nis_band(20)
    assert math.isclose(lo, stats.chi2.ppf(0.025, 20) / 20, rel_tol=1e-12)
    assert math.isclose(hi, stats.chi2.ppf(0.975, 20) / 20, rel_tol=1e-12)


def test_matched_filter_is_in_band_95_percent_of_the_time_within_mc_error() -> None:
    """A consistent filter's windowed NIS is χ²(D)/D at every window, so the expected
    out-of-band fraction is 5%; the runs are independent, so the SE of the mean fraction is
    the run-to-run std / √M (windows of one run are correlated, runs are not)."""
    nis, dof = _matched_run(np.random.default_rng(11))
    assert np.all(dof == 2)
    # The single-update NIS is χ²(2): mean 2 within 4.5 SE.
    m = nis.mean()
    se = nis.mean(axis=0).std(ddof=1) / math.sqrt(RUNS)
    assert abs(m - 2.0) < 4.5 * se, (m, se)
    q, D = windowed_nis(nis, dof, WINDOW)
    below, above = out_of_band(q, D)
    per_run = (below | above).mean(axis=0)
    frac, se = per_run.mean(), per_run.std(ddof=1) / math.sqrt(RUNS)
    assert abs(frac - 0.05) < 4.5 * se, (frac, se)
    # Both tails take their 2.5% (within the same error).
    for side in (below, above):
        f = side.mean(axis=0)
        assert abs(f.mean() - 0.025) < 4.5 * f.std(ddof=1) / math.sqrt(RUNS)


def test_streaming_monitor_equals_the_batched_windows() -> None:
    nis, dof = _matched_run(np.random.default_rng(5))
    q, D = windowed_nis(nis, dof, WINDOW)
    below, above = out_of_band(q, D)
    for run in range(3):
        mon = ConsistencyMonitor(WINDOW)
        for n in range(nis.shape[0]):
            mon.add("t", float(n), float(nis[n, run]), int(dof[n]))
        r = mon.result("t")
        assert r.windows == q.shape[0]
        assert r.above == int(above[:, run].sum())
        assert r.below == int(below[:, run].sum())
        assert math.isclose(r.mean_nis_per_dof, nis[:, run].sum() / dof.sum(), rel_tol=1e-12)


def test_a_sustained_exit_is_one_event_and_a_brief_one_none() -> None:
    events = []
    mon = ConsistencyMonitor(4, on_event=events.append)
    values = [2.0] * 10 + [40.0] + [2.0] * 10 + [40.0] * 12 + [2.0] * 20
    for t, v in enumerate(values):
        mon.add("t", float(t), v, 2)
    assert [e.kind for e in events] == ["leaves", "returns"]
    assert events[0].q > events[0].hi
    r = mon.result("t")
    assert r.above > 0 and r.first_exit_s == events[0].time_s
    mon.add("u", 0.0, math.nan, 2)  # a broken update counts as far above the band
    assert mon.result("u").updates == 1


def test_a_monitor_keeping_its_newest_events_counts_every_one() -> None:
    """``events_kept`` (``radarviz live``'s monitor, whose feed never ends): the newest
    events are kept, as a monitor keeping every one has them, and ``events_seen`` counts
    them all; memory does not grow with the events."""
    values = ([2.0] * 10 + [40.0] * 12) * 20 + [2.0] * 10
    every, newest = ConsistencyMonitor(4), ConsistencyMonitor(4, events_kept=3)
    for mon in (every, newest):
        for t, v in enumerate(values):
            mon.add("t", float(t), v, 2)
    assert every.events_seen == len(every.events) == 40
    assert newest.events_seen == 40 and list(newest.events) == list(every.events)[-3:]
