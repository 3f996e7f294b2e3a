"""``radarviz bench``'s per-method figures: the Monte Carlo engine against the compiled
reference filter in textbook matrix form (``viz_app.bench.reference``) and filterpy, measured
in the same run.

Per method (the seven 2D methods and ``ekf+doppler``, the EKF followed by the Doppler update
of each plot's V̂r), ns per track-step (wall time / (runs × scans), one thread), the same
measurements for every one:

* ``engine_filter_ns_per_step``: ``core.filters.compiled.filter_scans`` with no output but
  the final states (``states=False``): the same work as the reference.
* ``engine_metrics_ns_per_step``: the same filter forming the Monte Carlo's metric sums as it
  goes (``TermsRequest``, ``TERMS_SCANS`` scans a pass), as ``reproduce prosov`` runs it.
* ``reference_ns_per_step``: the compiled reference (final states).
* ``engine_over_reference`` / ``metrics_over_reference``: the median over the repeats of the
  same-repeat ratio (timings interleaved, so a load on the machine hits both).
* ``filterpy_ns_per_step``: filterpy's ``KalmanFilter`` (converted methods: the method's
  converted point and covariance given, computed outside the timed calls),
  ``ExtendedKalmanFilter``, ``UnscentedKalmanFilter`` (Van der Merwe points, the engine's
  α, β, κ), and for ``ekf+doppler`` a one-dimensional ``KalmanFilter.update`` after the
  EKF's, on a subsample of runs; only ``predict`` and ``update`` are timed.
* ``whole_run_ns_per_method_step``: the all-method Monte Carlo (``run_tracking``, measurements
  and statistics included, one thread) per method-track-step, timed right after the seven
  filters alone (``filter_ns_per_method_step``); ``whole_run_over_filter`` their ratio.

Each figure is the median over ``repeats``. Everything here runs on the calling thread, so
the clock is that thread's CPU time (``time.thread_time``): on a machine shared with other
jobs the time the system gives them is not counted, which wall time would add to whichever
of two back-to-back timings it fell in. ``whole_run_over_filter_wall`` is the same ratio by
wall time, for comparison.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

import numpy as np

from radarviz.core.conversion.planar import convert
from radarviz.core.experiments.prosov import (
    TERMS_SCANS,
    TrackingConfig,
    block_measurements,
    run_tracking,
)
from radarviz.core.filters.compiled import FilterSettings, TermsRequest, filter_scans
from radarviz.core.filters.predict import process_noise, transition_matrix
from radarviz.core.geometry import wrap_angle
from radarviz.core.metrics import truth_line_of_sight
from radarviz.viz_app.bench.reference import REFERENCE_METHODS, run_reference

#: σVr of the Doppler measurements the ``ekf+doppler`` figures filter, m/s.
BENCH_SIGMA_VR_MPS = 1.0
#: The clock of the one-thread figures (module docstring).
CLOCK = time.thread_time


def bench_measurements(
    config: TrackingConfig, runs: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Block 0's (r̂, β̂) of ``config`` with ``runs`` runs, and V̂r: the true radial velocity
    plus N(0, σVr²) noise (its own stream), each (runs, N)."""
    truth = config.target.truth()
    r_hat, b_hat = block_measurements(config, 0, runs, truth)
    pos, vel = truth[:, [0, 2]], truth[:, [1, 3]]
    vr_true = np.sum(pos * vel, axis=1) / np.hypot(pos[:, 0], pos[:, 1])
    rng = np.random.default_rng(np.random.SeedSequence([config.seed, 3]))
    vr_hat = vr_true + BENCH_SIGMA_VR_MPS * rng.standard_normal(r_hat.shape)
    return r_hat, b_hat, vr_hat


def _settings(config: TrackingConfig) -> FilterSettings:
    return FilterSettings(
        config.sigma_r_m,
        config.sigma_beta_rad,
        config.target.period_s,
        config.sigma_a_mps2,
        config.sigma_v0_mps,
        sigma_vr_mps=BENCH_SIGMA_VR_MPS,
    )


def _engine(
    method: str, r, b, vr, settings: FilterSettings, chunk: int | None = None, **kw: Any
) -> None:
    doppler = method.endswith("+doppler")
    for _ in filter_scans(
        method.removesuffix("+doppler"),
        r,
        b,
        settings,
        r.shape[1] if chunk is None else chunk,
        radial_velocity_mps=vr if doppler else None,
        **kw,
    ):
        pass


def _reference(method: str, r, b, vr, s: FilterSettings, out) -> None:
    run_reference(
        method,
        r,
        b,
        sigma_r_m=s.sigma_r_m,
        sigma_beta_rad=s.sigma_beta_rad,
        period_s=s.period_s,
        sigma_a_mps2=s.sigma_a_mps2,
        sigma_v0_mps=s.sigma_v0_mps,
        radial_velocity_mps=vr,
        sigma_vr_mps=s.sigma_vr_mps,
        ukf_weights=s.ukf.weights(4),
        out=out,
    )


def bench_per_method(config: TrackingConfig, runs: int, repeats: int = 5) -> dict[str, Any]:
    """The engine, the reference and the whole Monte Carlo, interleaved (module docstring)."""
    r, b, vr = bench_measurements(config, runs)
    steps = r.shape[1]
    s = _settings(config)
    truth = config.target.truth()
    want = TermsRequest(runs, truth, truth_line_of_sight(truth))
    small = TermsRequest(2, truth, want.los)
    out = (np.empty((runs, 4)), np.empty((runs, 4, 4)))
    whole = replace(config, runs=runs)
    for method in REFERENCE_METHODS:  # compile or load every kernel before timing
        _engine(method, r[:2], b[:2], vr[:2], s, states=False)
        _engine(method, r[:2], b[:2], vr[:2], s, terms=small)
        _reference(method, r[:2], b[:2], vr[:2], s, (out[0][:2], out[1][:2]))
    times: dict[str, list[list[float]]] = {m: [] for m in REFERENCE_METHODS}
    whole_s: list[float] = []
    filters_s: list[float] = []
    wall: list[float] = []
    for _ in range(repeats):
        for method in REFERENCE_METHODS:
            t0 = CLOCK()
            _engine(method, r, b, vr, s, states=False)
            t1 = CLOCK()
            _engine(method, r, b, vr, s, terms=want, chunk=TERMS_SCANS)
            t2 = CLOCK()
            _reference(method, r, b, vr, s, out)
            t3 = CLOCK()
            times[method].append([t1 - t0, t2 - t1, t3 - t2])
        # The seven filters alone, then the whole Monte Carlo, back to back.
        w0, t0 = time.perf_counter(), CLOCK()
        for method in config.methods:
            _engine(method, r, b, vr, s, states=False)
        w1, t1 = time.perf_counter(), CLOCK()
        run_tracking(whole, workers=1)
        filters_s.append(t1 - t0)
        whole_s.append(CLOCK() - t1)
        wall.append((time.perf_counter() - w1) / (w1 - w0))
    per = runs * steps * 1e-9
    doc: dict[str, Any] = {
        "per_method_runs": runs,
        "per_method_repeats": repeats,
        "per_method_clock": "thread CPU time",
        "engine_filter_ns_per_step": {},
        "engine_metrics_ns_per_step": {},
        "reference_ns_per_step": {},
        "engine_over_reference": {},
        "metrics_over_reference": {},
    }
    for method, rows in times.items():
        a = np.array(rows)
        med = np.median(a, axis=0) / per
        doc["engine_filter_ns_per_step"][method] = float(med[0])
        doc["engine_metrics_ns_per_step"][method] = float(med[1])
        doc["reference_ns_per_step"][method] = float(med[2])
        doc["engine_over_reference"][method] = float(np.median(a[:, 0] / a[:, 2]))
        doc["metrics_over_reference"][method] = float(np.median(a[:, 1] / a[:, 2]))
    methods = config.methods
    filter_sum = np.array(filters_s)
    doc["whole_run_ns_per_method_step"] = float(np.median(whole_s) / (per * len(methods)))
    doc["filter_ns_per_method_step"] = float(np.median(filter_sum) / (per * len(methods)))
    doc["whole_run_over_filter"] = float(np.median(np.array(whole_s) / filter_sum))
    doc["whole_run_over_filter_wall"] = float(np.median(wall))
    return doc


def _polar_residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = np.subtract(a, b)
    d[1] = wrap_angle(d[1])
    return d


def bench_filterpy_per_method(config: TrackingConfig, runs: int) -> dict[str, float]:
    """ns per track-step of filterpy's filter for each ``REFERENCE_METHODS`` name (module
    docstring) on ``runs`` runs; conversions and Jacobian set-up outside the timed calls."""
    from filterpy.kalman import (
        ExtendedKalmanFilter,
        KalmanFilter,
        MerweScaledSigmaPoints,
        UnscentedKalmanFilter,
    )

    r_all, b_all, vr_all = bench_measurements(config, runs)
    s = _settings(config)
    T, sigma_r_m, sigma_beta_rad = s.period_s, s.sigma_r_m, s.sigma_beta_rad
    steps = r_all.shape[1]
    F, Q = transition_matrix(T), process_noise(T, s.sigma_a_mps2)
    H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    R_polar = np.diag([sigma_r_m * sigma_r_m, sigma_beta_rad * sigma_beta_rad])
    ukf = s.ukf

    def start(method: str, r: float, b: float) -> tuple[np.ndarray, np.ndarray]:
        kind = {"ducm": "ucm", "ekf": "naive", "ukf": "naive", "ekf+doppler": "naive"}
        c = convert(
            kind.get(method, method), r, b, sigma_r_m=sigma_r_m, sigma_beta_rad=sigma_beta_rad
        )
        x = np.array([c.z[0], 0.0, c.z[1], 0.0])
        P = np.zeros((4, 4))
        P[np.ix_([0, 2], [0, 2])] = c.R
        P[1, 1] = P[3, 3] = s.sigma_v0_mps**2
        return x, P

    def hx(x: np.ndarray) -> np.ndarray:
        return np.array([math.hypot(x[0], x[2]), math.atan2(x[2], x[0])])

    def jacobian(x: np.ndarray) -> np.ndarray:
        r2 = x[0] * x[0] + x[2] * x[2]
        rp = math.sqrt(r2)
        return np.array([[x[0] / rp, 0.0, x[2] / rp, 0.0], [-x[2] / r2, 0.0, x[0] / r2, 0.0]])

    def z_mean(sigmas: np.ndarray, wm: np.ndarray) -> np.ndarray:
        b0 = sigmas[0, 1]
        return np.array([wm @ sigmas[:, 0], b0 + wm @ wrap_angle(sigmas[:, 1] - b0)])

    out: dict[str, float] = {}
    for method in REFERENCE_METHODS:
        elapsed = 0.0
        for m in range(runs):
            r, b, vr = r_all[m], b_all[m], vr_all[m]
            x0, P0 = start(method, float(r[0]), float(b[0]))
            if method == "ukf":
                points = MerweScaledSigmaPoints(4, ukf.alpha, ukf.beta, ukf.kappa)
                f: Any = UnscentedKalmanFilter(
                    4,
                    2,
                    T,
                    hx,
                    lambda x, dt: F @ x,
                    points,
                    z_mean_fn=z_mean,
                    residual_z=_polar_residual,
                )
                f.R = R_polar
            elif method.startswith("ekf"):
                f = ExtendedKalmanFilter(4, 2)
                f.F = F
                f.R = R_polar
                dop = KalmanFilter(4, 1)
            else:
                f = KalmanFilter(4, 2)
                f.F, f.H = F, H
                if method != "ducm":
                    c = convert(method, r, b, sigma_r_m=sigma_r_m, sigma_beta_rad=sigma_beta_rad)
            f.Q = Q
            f.x, f.P = x0, P0
            for n in range(1, steps):
                t0 = time.perf_counter()
                f.predict()
                t1 = time.perf_counter()
                if method == "ducm":
                    pred = (f.x[0], f.x[2])
                    cn = convert("ducm", r[n], b[n], sigma_r_m=sigma_r_m,
                                 sigma_beta_rad=sigma_beta_rad,
                                 predicted_xy=np.array(pred))  # fmt: skip
                    z_n, R_n = cn.z, cn.R
                elif method in ("naive", "seed", "cmkf_d", "ucm"):
                    z_n, R_n = c.z[n], c.R[n]
                t2 = time.perf_counter()
                if method == "ukf":
                    f.update(np.array([r[n], b[n]]))
                elif method.startswith("ekf"):
                    f.update(np.array([r[n], b[n]]), jacobian, hx, residual=_polar_residual)
                    if method == "ekf+doppler":
                        cb, sbn = math.cos(b[n]), math.sin(b[n])
                        gv = -sbn * f.x[1] + cb * f.x[3]
                        g = np.array([-sbn, cb])
                        pv = f.P[np.ix_([1, 3], [1, 3])]
                        dop.x, dop.P = f.x, f.P
                        dop.H = np.array([[0.0, cb, 0.0, sbn]])
                        dop.update(
                            vr[n],
                            R=s.sigma_vr_mps**2
                            + sigma_beta_rad * sigma_beta_rad * (gv * gv + g @ pv @ g),
                        )
                        f.x, f.P = dop.x, dop.P
                else:
                    f.update(z_n, R=R_n)
                t3 = time.perf_counter()
                elapsed += (t1 - t0) + (t3 - t2)
            if not np.all(np.isfinite(f.x)):
                raise RuntimeError(f"filterpy {method} diverged on the bench's measurements")
        out[method] = elapsed / (runs * (steps - 1)) * 1e9
    return out
