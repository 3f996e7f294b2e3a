"""``radarviz bench``: speed of the batched filter against filterpy, measured in one run.

Figures (ns per track-step = wall time / (runs × scans), one core):

* ``kf_ns_per_step``: the batched converted-measurement filter end to end (``ucm`` conversion
  of each measurement, predict, Joseph update), the code path of the Monte Carlo engine,
  at each run count in ``runs``.
* ``kf_filter_only_ns_per_step``: the same without the conversion (converted points given).
* ``filterpy_ns_per_step``: filterpy ``KalmanFilter.predict`` + ``update`` on a subsample of
  runs, with the converted points and covariances computed beforehand and not timed (so the
  ratio is, if anything, unfair to the batched filter).
* ``speedup_vs_filterpy`` = filterpy_ns_per_step / kf_ns_per_step.
* ``engine_runs`` / ``numpy_ns_per_step`` / ``compiled_ns_per_step``: per method, the
  Monte Carlo filter (start, then predict + update every scan, states handed on) by the
  numpy engine (``filter_block``) and by the compiled kernel (``core.filters.compiled``),
  on the same measurements, best of three; ``compiled_speedup`` their ratio.
* ``experiment_ns_per_step`` / ``experiment_over_filter``: the whole one-method Monte Carlo
  (measurements, compiled filter, statistics) per track-step, and its ratio to the filter.
* ``per_method``: the engine against the compiled reference and filterpy, per method,
  and the all-method Monte Carlo against the filter alone (``viz_app.bench.per_method``).
* ``one_thread_s`` / ``all_cores_s`` / ``parallel_efficiency``: the all-method Monte Carlo
  of ``parallel_runs`` runs on one thread and on every core (blocks over threads), with
  speed-up / cores; ``parallel_bit_identical`` checks the two results equal.
* ``gorshkov_s``: wall time of the whole Gorshkov experiment (six radars, 10⁵ trials each,
  range only and range + Doppler, k = 1 … 20), best of ``repeats``.
* ``imm``: the tracker's step (``core.tracking.stream.TrackGroup``: predict and the ``ucm``
  position update, innovation statistics included) on the Prosov plots, ns per track-step,
  for the default IMM and for the CV filter in the same run, on a batch of ``runs[0]`` tracks
  (the Monte Carlo path) and on one track (the streaming path); ``imm_over_cv`` their ratios;
  ``filterpy_imm_ns_per_step``: filterpy's ``IMMEstimator`` (two ``KalmanFilter`` models,
  the converted points given) on a subsample of runs.
* ``targets``: the tracker of many targets (``core.tracking.targets.TargetTracker``) on
  ``targets`` Prosov runs as targets (one plot per target per scan, times offset by 1 ms per
  target, all seven 2D methods, the cv model with σa = 1 m/s²), plots per second over the
  whole file (the plots made beforehand, not timed): ``batched_plots_per_s`` on the compiled
  engine (``TargetTracker.add_arrays``), ``numpy_plots_per_s`` on the numpy engine
  (``add_block``), ``compiled_over_numpy`` their ratio; ``models``: per motion model, the cv
  one above and the default IMM (``DEFAULT_IMM``), one after the other in the same run, plots
  per second of wall and of CPU time on each engine and ``compiled_over_numpy_cpu``, and
  ``imm_over_cv_compiled_cpu`` the IMM's rate over cv's on the compiled engine (per CPU-s);
  beside them the same plots tracked
  one target at a time (``StreamTracker``, on a subsample of ``loop_targets`` targets),
  ``batched_over_loop`` the ratio of plots per second. ``one_target_ns_per_step``: per
  method, one target's long stream of plots (``one_target_plots``) as the track file's
  blocks of arrays (``add_arrays``, 2 500 plots), ns per method-step, and
  ``one_target_speedup_vs_filterpy`` = filterpy's ``filterpy_ns_per_step`` (measured above
  in the same run, converted points given) / ours; ``one_target_plot_list_ns_per_step``: the
  same plots as lists of ``Plot`` (``StreamTracker.add_block``, 1 024 at a time);
  ``one_plot_per_call_ns_per_step``: one ``Plot`` per call (all methods).
  ``file``: ``radarviz track`` end to end in its own process (read, all seven methods,
  the tracks written) on the air-traffic file (``viz_app.bench.track_file``: 1000 targets,
  two radars, 2D and 3D with Doppler, cv model) of ``--track-plots`` plots and of a tenth
  of them: wall and CPU time, plots per second of each, peak resident memory (the same at
  both lengths when memory does not grow with the file); ``imm_csv``: the same file tracked
  with the IMM (the command's default model) into CSV, and ``imm_over_cv_cpu`` its plots per
  CPU-s over cv's.
* ``association``: unlabelled plots associated (``core.tracking.association``) against the
  same plots with their labels, ``viz_app.bench.association``.
* ``asterix``: reading an ASTERIX CAT048 file of the fusion plots against reading the same
  plots from CSV, plots per second and their same-run ratio, and ``track`` of an ASTERIX file
  of many targets end to end, the compiled block path against the row path and the decoder
  alone (``viz_app.bench.asterix``; alone: ``radarviz bench --only asterix``).
* ``live``: a rotating-radar feed replayed to 127.0.0.1 into ``radarviz live`` with its
  viewer: plots sent, tracked, dropped, malformed, the latency's median and 99th percentile,
  the live process's peak RSS (``viz_app.bench.live``; alone: ``radarviz bench --only live``).
* ``peak_rss_mb``: peak resident memory of the process.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from filterpy.kalman import KalmanFilter

from radarviz.core.conversion.planar import convert
from radarviz.core.cores import available_cores
from radarviz.core.experiments.prosov import (
    BLOCK_RUNS,
    TrackingConfig,
    block_sizes,
    filter_block,
    run_tracking,
)
from radarviz.core.filters.position import cv_update
from radarviz.core.filters.predict import transition_matrix
from radarviz.core.filters.run import run_scans
from radarviz.core.filters.state import cv_init
from radarviz.core.params import MIN_MONTE_CARLO_RUNS
from radarviz.core.scenarios.planar import polar_measurements, prosov_target
from radarviz.viz_app.bench.association import bench_association, format_association
from radarviz.viz_app.bench.per_method import bench_filterpy_per_method, bench_per_method
from radarviz.viz_app.runtime import machine, peak_rss_mb
from radarviz.viz_app.tune.params import SCENES
from radarviz.viz_app.tune.serve import measure_tune_latency

_H2 = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])


def _measurements(runs: int, steps: int, config: TrackingConfig, seed: int):
    rng = np.random.default_rng(seed)
    truth = config.target.truth()
    return polar_measurements(
        truth,
        sigma_r_m=config.sigma_r_m,
        sigma_beta_rad=config.sigma_beta_rad,
        runs=runs,
        rng=rng,
    )


def bench_batched(runs: int, config: TrackingConfig, repeats: int = 3) -> tuple[float, float]:
    """(end-to-end, filter-only) ns per track-step of the batched ucm filter; best of repeats."""
    steps = config.target.steps
    sigma_r_m, sigma_beta_rad, T = config.sigma_r_m, config.sigma_beta_rad, config.target.period_s
    sizes = block_sizes(runs)
    blocks = [_measurements(m, steps, config, seed=i) for i, m in enumerate(sizes)]
    end_to_end = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for r_hat, b_hat in blocks:
            filter_block("ucm", r_hat, b_hat, config, lambda n, st: None)
        end_to_end = min(end_to_end, time.perf_counter() - t0)
    # Filter only: convert every block's measurements first, then time predict + update.
    converted = []
    for r_hat, b_hat in blocks:
        c = convert("ucm", r_hat, b_hat, sigma_r_m=sigma_r_m, sigma_beta_rad=sigma_beta_rad)
        converted.append(
            (
                np.ascontiguousarray(c.z.transpose(1, 0, 2)),
                np.ascontiguousarray(c.R.transpose(1, 0, 2, 3)),
            )
        )
    filter_only = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for z, R in converted:
            run_scans(
                cv_init(z[0], R[0]),
                steps,
                T,
                lambda n, pred, out, z=z, R=R: cv_update(pred, z[n], R[n], out=out),
            )
        filter_only = min(filter_only, time.perf_counter() - t0)
    track_steps = runs * steps
    return end_to_end / track_steps * 1e9, filter_only / track_steps * 1e9


def bench_filterpy(runs: int, config: TrackingConfig) -> float:
    """ns per step of filterpy's KalmanFilter (predict + update) on ``runs`` runs."""
    steps = config.target.steps
    sigma_r_m, sigma_beta_rad, T = config.sigma_r_m, config.sigma_beta_rad, config.target.period_s
    r_hat, b_hat = _measurements(runs, steps, config, seed=12345)
    c = convert("ucm", r_hat, b_hat, sigma_r_m=sigma_r_m, sigma_beta_rad=sigma_beta_rad)
    F = transition_matrix(T)
    elapsed = 0.0
    for m in range(runs):
        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.F = F
        kf.H = _H2
        kf.Q = np.zeros((4, 4))
        init = cv_init(c.z[m, :1], c.R[m, :1])
        kf.x = init.x[0].copy()
        kf.P = init.P[0].copy()
        z, R = c.z[m], c.R[m]
        t0 = time.perf_counter()
        for n in range(1, steps):
            kf.predict()
            kf.update(z[n], R=R[n])
        elapsed += time.perf_counter() - t0
    return elapsed / (runs * (steps - 1)) * 1e9


def bench_engines(runs: int, config: TrackingConfig, repeats: int = 3) -> dict[str, Any]:
    """ns per track-step of every method by the numpy engine and by the compiled kernel."""
    from radarviz.core.filters.compiled import FilterSettings, filter_scans
    from radarviz.core.filters.methods import ALL_METHODS
    from radarviz.core.metrics import STAGE_ROWS

    steps = config.target.steps
    r_hat, b_hat = _measurements(runs, steps, config, seed=7)
    settings = FilterSettings(
        config.sigma_r_m,
        config.sigma_beta_rad,
        config.target.period_s,
        config.sigma_a_mps2,
        config.sigma_v0_mps,
    )
    chunk = max(1, STAGE_ROWS // runs)
    for _ in filter_scans("naive", r_hat[:2], b_hat[:2], settings, chunk):
        pass  # compile or load the kernel before timing
    numpy_ns, compiled_ns, experiment_ns = {}, {}, {}
    for method in ALL_METHODS:
        one = replace(config, runs=runs, methods=(method,))
        best_np = best_c = best_e = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            filter_block(method, r_hat, b_hat, config, lambda n, st: None)
            t1 = time.perf_counter()
            for _ in filter_scans(method, r_hat, b_hat, settings, chunk):
                pass
            t2 = time.perf_counter()
            run_tracking(one, workers=1)
            t3 = time.perf_counter()
            best_np, best_c, best_e = (
                min(best_np, t1 - t0),
                min(best_c, t2 - t1),
                min(best_e, t3 - t2),
            )
        numpy_ns[method] = best_np / (runs * steps) * 1e9
        compiled_ns[method] = best_c / (runs * steps) * 1e9
        experiment_ns[method] = best_e / (runs * steps) * 1e9
    return {
        "engine_runs": runs,
        "numpy_ns_per_step": numpy_ns,
        "compiled_ns_per_step": compiled_ns,
        "compiled_speedup": {m: numpy_ns[m] / compiled_ns[m] for m in numpy_ns},
        "experiment_ns_per_step": experiment_ns,
        "experiment_over_filter": {m: experiment_ns[m] / compiled_ns[m] for m in numpy_ns},
    }


def bench_parallel(runs: int, repeats: int = 2) -> dict[str, Any]:
    """The Prosov Monte Carlo (all methods, ``runs`` runs in four blocks per core or more) on
    one thread and on every core: seconds, speed-up and parallel efficiency (speed-up /
    cores); the two results are checked equal bit for bit."""
    cores = available_cores()
    block = max(256, min(BLOCK_RUNS, runs // (4 * cores)))
    config = TrackingConfig(runs=runs)
    best = {}
    results = {}
    for workers in (1, cores):
        t = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            results[workers] = run_tracking(config, block=block, workers=workers)
            t = min(t, time.perf_counter() - t0)
        best[workers] = t
    same = all(
        np.array_equal(a, getattr(results[cores].metrics[m], name), equal_nan=True)
        for m in config.methods
        for name, a in results[1].metrics[m]._asdict().items()
    )
    speedup = best[1] / best[cores]
    return {
        "parallel_runs": runs,
        "parallel_block": block,
        "cores": cores,
        "one_thread_s": best[1],
        "all_cores_s": best[cores],
        "parallel_speedup": speedup,
        "parallel_efficiency": speedup / cores,
        "parallel_bit_identical": same,
    }


def bench_gorshkov(trials: int = 100_000, repeats: int = 2) -> float:
    """Seconds for the whole Gorshkov Monte Carlo (all six presets), best of ``repeats``."""
    from radarviz.core.finite_memory.fit import run_gorshkov

    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        run_gorshkov(None, trials=trials, seed=1)
        best = min(best, time.perf_counter() - t0)
    return best


def _track_group_ns(
    motion: Any, r_hat: np.ndarray, b_hat: np.ndarray, config: TrackingConfig
) -> float:
    """ns per track-step of ``TrackGroup.add_arrays`` (ucm, 2D) over a batch of runs."""
    from radarviz.core.filters.methods import PolarNoise, PolarPlot
    from radarviz.core.tracking.stream import TrackGroup

    runs, steps = r_hat.shape
    noise = PolarNoise(config.sigma_r_m, config.sigma_beta_rad)
    g = TrackGroup(("ucm",), 2, motion)
    site = np.zeros(2)
    T = config.target.period_s
    t0 = time.perf_counter()
    for n in range(steps):
        plot = PolarPlot(r_hat[:, n], b_hat[:, n])
        g.add_arrays(n * T, plot, noise, site, g.group.start_parts(plot, noise), None)
    return (time.perf_counter() - t0) / (runs * steps) * 1e9


def bench_imm(runs: int, filterpy_runs: int, config: TrackingConfig) -> dict[str, Any]:
    """The ``imm`` figures (module docstring)."""
    from filterpy.kalman import IMMEstimator

    from radarviz.core.filters.models import DEFAULT_IMM, CVModel
    from radarviz.core.filters.predict import process_noise
    from radarviz.core.filters.turn import turn_transition_matrix

    steps = config.target.steps
    out: dict[str, Any] = {"runs": runs}
    for label, m in (("batch", runs), ("single", 1)):
        r_hat, b_hat = _measurements(m, steps, config, seed=7)
        cv = _track_group_ns(CVModel(1.0), r_hat, b_hat, config)
        imm = _track_group_ns(DEFAULT_IMM, r_hat, b_hat, config)
        out[label] = {"cv_ns_per_step": cv, "imm_ns_per_step": imm, "imm_over_cv": imm / cv}
    sigma_r_m, sigma_beta_rad, T = config.sigma_r_m, config.sigma_beta_rad, config.target.period_s
    r_hat, b_hat = _measurements(filterpy_runs, steps, config, seed=12345)
    c = convert("ucm", r_hat, b_hat, sigma_r_m=sigma_r_m, sigma_beta_rad=sigma_beta_rad)
    elapsed = 0.0
    for m in range(filterpy_runs):
        init = cv_init(c.z[m, :1], c.R[m, :1])
        filters = []
        for sigma_a_mps2, omega in zip(
            DEFAULT_IMM.sigma_a_mps2, DEFAULT_IMM.turn_rates_radps(), strict=True
        ):
            kf = KalmanFilter(dim_x=4, dim_z=2)
            F = transition_matrix(T) if omega == 0.0 else turn_transition_matrix(omega, T)
            kf.F, kf.H, kf.Q = F, _H2, process_noise(T, sigma_a_mps2)
            kf.x, kf.P = init.x[0].copy(), init.P[0].copy()
            filters.append(kf)
        bank = IMMEstimator(
            filters, DEFAULT_IMM.initial_probabilities(), DEFAULT_IMM.transition_matrix()
        )
        t0 = time.perf_counter()
        for n in range(1, steps):
            bank.predict()
            for f in bank.filters:
                f.R = c.R[m, n]
            bank.update(c.z[m, n])
        elapsed += time.perf_counter() - t0
    out["filterpy_runs"] = filterpy_runs
    out["filterpy_imm_ns_per_step"] = elapsed / (filterpy_runs * (steps - 1)) * 1e9
    return out


def _block_slice(block: Any, i: int, j: int) -> Any:
    """Plots i … j − 1 of a ``PlotBlock``."""
    cut = {
        k: None if v is None else v[i:j]
        for k, v in block._asdict().items()
        if k not in ("radars", "labels")
    }
    return block._replace(**cut)


def bench_targets(
    targets: int,
    config: TrackingConfig,
    filterpy_ns: float,
    loop_targets: int = 20,
    track_plots: int = 1_000_000,
) -> dict[str, Any]:
    """The ``targets`` figures (module docstring)."""
    import math

    from radarviz.core.filters.methods import ALL_METHODS
    from radarviz.core.tracking.stream import Plot, StreamOptions, StreamTracker, plot_block
    from radarviz.core.tracking.targets import TargetTracker
    from radarviz.viz_app.io.plots import READ_BLOCK

    steps = config.target.steps
    r_hat, b_hat = _measurements(targets, steps, config, seed=21)
    T, sigma_r_m, sigma_beta_rad = config.target.period_s, config.sigma_r_m, config.sigma_beta_rad
    by_target = [
        [
            Plot(
                n * T + 1e-3 * k,
                float(r_hat[k, n]),
                float(b_hat[k, n]),
                sigma_r_m,
                sigma_beta_rad,
                target=str(k),
            )
            for n in range(steps)
        ]
        for k in range(targets)
    ]
    plots = [by_target[k][n] for n in range(steps) for k in range(targets)]
    block = plot_block(plots)
    options = StreamOptions(model="cv", sigma_a_mps2=1.0)
    # cv then the IMM (``DEFAULT_IMM``), each on both engines, one after the other in this
    # run: wall and CPU time of each.
    models: dict[str, dict[str, float]] = {}
    for model, opts in (("cv", options), ("imm", StreamOptions(model="imm"))):
        figures: dict[str, float] = {}
        # Untimed: the compiled kernel loaded from numba's cache (or compiled).
        TargetTracker(ALL_METHODS, False, opts).add_arrays(_block_slice(block, 0, 16))
        for engine in ("compiled", "numpy"):
            tracker = TargetTracker(ALL_METHODS, False, replace(opts, engine=engine))
            t0, c0 = time.perf_counter(), time.process_time()
            for i in range(0, len(plots), 8192):
                if engine == "compiled":  # the array path, as the track file's blocks
                    tracker.add_arrays(_block_slice(block, i, i + 8192))
                else:  # the reference engine, a Plot per row
                    tracker.add_block(plots[i : i + 8192])
            figures[f"{engine}_plots_per_s"] = len(plots) / (time.perf_counter() - t0)
            figures[f"{engine}_plots_per_cpu_s"] = len(plots) / (time.process_time() - c0)
        figures["compiled_over_numpy_cpu"] = (
            figures["compiled_plots_per_cpu_s"] / figures["numpy_plots_per_cpu_s"]
        )
        models[model] = figures
    rate = {e: models["cv"][f"{e}_plots_per_s"] for e in ("compiled", "numpy")}
    loop_targets = min(loop_targets, targets)
    t0 = time.perf_counter()
    for own in by_target[:loop_targets]:
        StreamTracker(ALL_METHODS, False, options).add_block(own)
    loop = loop_targets * steps / (time.perf_counter() - t0)
    # One target, one method, a long stream of plots in the file's blocks: ns per step.
    runs = max(1, 20_000 // steps)
    r1, b1 = _measurements(runs, steps, config, seed=22)
    one = [
        Plot((k * steps + n) * T, float(r1[k, n]), float(b1[k, n]), sigma_r_m, sigma_beta_rad)
        for k in range(runs)
        for n in range(steps)
    ]
    one_block = plot_block(one)
    step = 5000  # plots per block of the track file's reader (~256 KB)
    single: dict[str, float] = {}
    listed: dict[str, float] = {}
    # First calls off the clock (lazy imports, loading cached kernels): they fell on the
    # first method's figure, 5× the others'.
    TargetTracker(ALL_METHODS, False, options).add_arrays(_block_slice(one_block, 0, 100))
    StreamTracker(ALL_METHODS, False, options).add_block(one[:100])
    for m in ALL_METHODS:
        arrays = TargetTracker((m,), False, options)
        t0 = time.perf_counter()
        for i in range(0, len(one), step):
            arrays.add_arrays(_block_slice(one_block, i, i + step))
        single[m] = (time.perf_counter() - t0) / len(one) * 1e9
        tracker = StreamTracker((m,), False, options)
        t0 = time.perf_counter()
        for i in range(0, len(one), READ_BLOCK):
            tracker.add_block(one[i : i + READ_BLOCK])
        listed[m] = (time.perf_counter() - t0) / len(one) * 1e9
    # The same, one plot per call (a caller that has one plot at a time).
    tracker = StreamTracker(ALL_METHODS, False, options)
    t0 = time.perf_counter()
    for p in one[:2000]:
        tracker.add(p)
    per_call = (time.perf_counter() - t0) / (2000 * len(ALL_METHODS)) * 1e9
    measured = (*rate.values(), loop, per_call, *single.values(), *listed.values())
    measured = (*measured, *(v for f in models.values() for v in f.values()))
    assert all(math.isfinite(v) for v in measured)
    return {
        "targets": targets,
        "scans": steps,
        "methods": len(ALL_METHODS),
        "batched_plots_per_s": rate["compiled"],
        "numpy_plots_per_s": rate["numpy"],
        "compiled_over_numpy": rate["compiled"] / rate["numpy"],
        "models": models,
        "imm_over_cv_compiled_cpu": models["imm"]["compiled_plots_per_cpu_s"]
        / models["cv"]["compiled_plots_per_cpu_s"],
        "loop_targets": loop_targets,
        "loop_plots_per_s": loop,
        "batched_over_loop": rate["compiled"] / loop,
        "one_target_plots": len(one),
        "one_target_ns_per_step": single,
        "one_target_speedup_vs_filterpy": {m: filterpy_ns / v for m, v in single.items()},
        "one_target_plot_list_ns_per_step": listed,
        "one_plot_per_call_ns_per_step": per_call,
        "file": bench_track_file(track_plots),
    }


def _timed_track(
    d: Path, meas: Path, kind: str, plots: int, model: tuple[str, ...]
) -> dict[str, float]:
    """One ``radarviz track`` run of ``meas`` (``plots`` plots, radars ``d/radars.toml``) into
    a track file of ``kind`` in ``d`` (deleted after): its ``file`` figures."""
    from radarviz.viz_app.bench.track_file import time_track

    tracks = d / f"tracks.{kind}"
    run = time_track(meas, d / "radars.toml", tracks, model)
    tracks.unlink()
    return {
        "wall_s": run.wall_s,
        "cpu_s": run.cpu_s,
        "plots_per_s": plots / run.wall_s,
        "plots_per_cpu_s": plots / run.cpu_s,
        "peak_rss_mb": run.peak_rss_mb,
    }


def bench_track_file(plots: int) -> dict[str, Any]:
    """``radarviz track`` end to end on the air-traffic file (``viz_app.bench.track_file``),
        1000 targets (fewer for a short file), 2D and 3D (Doppler), all seven methods, the cv
        model: at ``plots`` plots and at a tenth of them (the memory must not grow with the
        file), each writing the CSV track file and then the Parquet one (``--out X.parquet``) of
        the same input, one after the other (their ratio is a same-run figure), then the IMM into
    CSV (its ratio to cv's CSV run likewise). Each run is its
        own process, after untimed warm-up runs (numba's cache)."""
    import tempfile

    from radarviz.viz_app.bench.track_file import air_traffic_file

    out: dict[str, Any] = {}
    targets = min(1000, max(1, plots // 100))
    with tempfile.TemporaryDirectory(prefix="radarviz-bench-") as tmp:
        d = Path(tmp)
        for dims in (2, 3):
            runs = {}
            for warm_up, n in ((True, 200), (False, plots // 10), (False, plots)):
                meas = d / "plots.csv"
                written = air_traffic_file(meas, d / "radars.toml", targets, n, dims == 3)
                figures: dict[str, Any] = {"plots": written}
                for kind in TRACK_FILE_KINDS:
                    figures[kind] = _timed_track(d, meas, kind, written, CV_TRACK)
                figures["parquet_over_csv_cpu"] = (
                    figures["parquet"]["plots_per_cpu_s"] / figures["csv"]["plots_per_cpu_s"]
                )
                # The command's default model, the IMM, into the CSV track file.
                figures["imm_csv"] = _timed_track(d, meas, "csv", written, IMM_TRACK)
                figures["imm_over_cv_cpu"] = (
                    figures["imm_csv"]["plots_per_cpu_s"] / figures["csv"]["plots_per_cpu_s"]
                )
                if not warm_up:
                    runs[str(written)] = figures
            out[f"{dims}d"] = runs
    return out


#: The track files of the file figure, by ``--out`` suffix.
TRACK_FILE_KINDS = ("csv", "parquet")
#: The track options of the file figure: the cv model with σa = 1 m/s² (all methods).
CV_TRACK = ("--model", "cv", "--sigma-a", "1")
#: ... and the IMM beside it (``DEFAULT_IMM``, the command's default model).
IMM_TRACK = ("--model", "imm")


def run_bench(
    runs: Sequence[int] = (10_000, 100_000),
    filterpy_runs: int = 200,
    targets: int = 1000,
    asterix_plots: int = 20_000,
    asterix_targets: int = 200,
    track_plots: int = 1_000_000,
    live: tuple[float, float, int] = (2000.0, 20.0, 300),
) -> dict[str, Any]:
    """All figures of ``radarviz bench`` as a JSON-ready dict (``live``: the live section's
    rate, seconds and targets)."""
    from radarviz.viz_app.bench.asterix import bench_asterix
    from radarviz.viz_app.bench.live import bench_live

    host = machine()
    config = TrackingConfig(runs=MIN_MONTE_CARLO_RUNS, target=prosov_target())
    gorshkov_s = bench_gorshkov()
    fp = bench_filterpy(filterpy_runs, config)
    kf, kf_only = [], []
    for m in runs:
        e2e, only = bench_batched(m, config)
        kf.append(e2e)
        kf_only.append(only)
    engines = bench_engines(min(runs), config)
    per_method = bench_per_method(config, min(runs))
    fp_methods = bench_filterpy_per_method(config, filterpy_runs)
    per_method["filterpy_runs"] = filterpy_runs
    per_method["filterpy_ns_per_step"] = fp_methods
    per_method["filterpy_over_engine"] = {
        m: v / per_method["engine_filter_ns_per_step"][m] for m, v in fp_methods.items()
    }
    parallel = bench_parallel(max(runs))
    return {
        **engines,
        **parallel,
        "per_method": per_method,
        "runs": list(runs),
        "scans": config.target.steps,
        "block_runs": BLOCK_RUNS,
        "kf_ns_per_step": kf,
        "kf_filter_only_ns_per_step": kf_only,
        "filterpy_runs": filterpy_runs,
        "filterpy_ns_per_step": fp,
        "speedup_vs_filterpy": [fp / v for v in kf],
        "gorshkov_trials": 100_000,
        "gorshkov_s": gorshkov_s,
        "tune_median_ms": {scene: measure_tune_latency(scene) for scene in SCENES},
        "imm": bench_imm(runs[0], filterpy_runs, config),
        "targets": bench_targets(targets, config, fp, track_plots=track_plots),
        "association": bench_association(targets),
        "asterix": bench_asterix(asterix_plots, targets=asterix_targets),
        "live": bench_live(*live),
        "peak_rss_mb": peak_rss_mb(),
        # the load at the start and at the end: a shared machine's figures read with it
        "machine": {**host, "load_avg_1min_after": machine()["load_avg_1min"]},
    }


def format_bench(doc: dict[str, Any]) -> str:
    """Readable report of ``run_bench``."""
    host = doc["machine"]
    lines = [
        f"machine: {host['cpu']}, {host['cores']} cores, {host['memory_gib']} GiB, Python "
        f"{host['python']}; load average (1 min) {host['load_avg_1min']} at the start, "
        f"{host['load_avg_1min_after']} at the end",
        f"filterpy KalmanFilter: {doc['filterpy_ns_per_step']:.0f} ns per step "
        f"({doc['filterpy_runs']} runs × {doc['scans']} scans)",
    ]
    for m, e2e, only, sp in zip(
        doc["runs"],
        doc["kf_ns_per_step"],
        doc["kf_filter_only_ns_per_step"],
        doc["speedup_vs_filterpy"],
        strict=True,
    ):
        lines.append(
            f"batched ucm filter, {m:>7} runs: {e2e:6.1f} ns per track-step "
            f"(filter only {only:6.1f})   speedup vs filterpy {sp:6.0f}×"
        )
    lines.append(
        f"Monte Carlo filter per method, {doc['engine_runs']} runs × {doc['scans']} scans, "
        "ns per track-step: numpy engine → compiled kernel (speed-up)"
    )
    for method, v in doc["numpy_ns_per_step"].items():
        c, ratio = doc["compiled_ns_per_step"][method], doc["compiled_speedup"][method]
        e, over = doc["experiment_ns_per_step"][method], doc["experiment_over_filter"][method]
        lines.append(
            f"  {method:>7}: {v:6.1f} → {c:6.1f}  ({ratio:.1f}×);  this method's Monte Carlo "
            f"alone (its own measurements, filter, statistics) {e:6.1f} = {over:.2f}× the filter"
        )
    pm = doc["per_method"]
    lines.append(
        f"engine vs compiled textbook reference vs filterpy, {pm['per_method_runs']} runs × "
        f"{doc['scans']} scans (filterpy {pm['filterpy_runs']} runs), ns per track-step, "
        f"medians of {pm['per_method_repeats']} interleaved repeats ({pm['per_method_clock']}):"
    )
    lines.append(
        "   method   engine  reference  engine/ref   +metrics  metrics/ref   filterpy  "
        "filterpy/engine"
    )
    for method, e in pm["engine_filter_ns_per_step"].items():
        lines.append(
            f"  {method:>11} {e:7.1f} {pm['reference_ns_per_step'][method]:10.1f} "
            f"{pm['engine_over_reference'][method]:10.2f}× "
            f"{pm['engine_metrics_ns_per_step'][method]:9.1f} "
            f"{pm['metrics_over_reference'][method]:11.2f}× "
            f"{pm['filterpy_ns_per_step'][method]:10.0f} "
            f"{pm['filterpy_over_engine'][method]:14.0f}×"
        )
    lines.append(
        f"whole Monte Carlo (all methods: measurements, filters, statistics), one thread: "
        f"{pm['whole_run_ns_per_method_step']:.1f} ns per method-track-step = "
        f"{pm['whole_run_over_filter']:.2f}× the filters alone "
        f"({pm['filter_ns_per_method_step']:.1f}; by wall time "
        f"{pm['whole_run_over_filter_wall']:.2f}×)"
    )
    lines.append(
        f"Prosov Monte Carlo, {doc['parallel_runs']} runs, all methods (blocks of "
        f"{doc['parallel_block']}): {doc['one_thread_s']:.2f} s on one thread, "
        f"{doc['all_cores_s']:.2f} s on "
        f"{doc['cores']} cores: {doc['parallel_speedup']:.2f}× (efficiency "
        f"{doc['parallel_efficiency']:.0%}; "
        f"{'bit-identical' if doc['parallel_bit_identical'] else 'RESULTS DIFFER'})"
    )
    lines.append(
        f"Gorshkov experiment (6 radars × {doc['gorshkov_trials']} trials, both variants): "
        f"{doc['gorshkov_s']:.2f} s"
    )
    per_scene = ", ".join(f"{k} {v:.0f} ms" for k, v in doc["tune_median_ms"].items())
    lines.append(f"tune: change → recording flushed, median per scene: {per_scene}")
    imm = doc["imm"]
    for label, what in (("batch", f"{imm['runs']} runs"), ("single", "one track")):
        v = imm[label]
        lines.append(
            f"tracker step, ucm, {what}: IMM {v['imm_ns_per_step']:.0f} ns, CV "
            f"{v['cv_ns_per_step']:.0f} ns per track-step (IMM/CV {v['imm_over_cv']:.2f}×)"
        )
    lines.append(
        f"filterpy IMMEstimator (2 models): {imm['filterpy_imm_ns_per_step']:.0f} ns per step "
        f"({imm['filterpy_runs']} runs)"
    )
    tg = doc["targets"]
    lines.append(
        f"tracker of many targets, {tg['targets']} targets × {tg['scans']} scans, "
        f"{tg['methods']} methods: compiled {tg['batched_plots_per_s']:.0f} plots/s, numpy "
        f"engine {tg['numpy_plots_per_s']:.0f} plots/s ({tg['compiled_over_numpy']:.1f}×); "
        f"one target at a time ({tg['loop_targets']} targets): {tg['loop_plots_per_s']:.0f} "
        f"plots/s (batched/loop {tg['batched_over_loop']:.1f}×)"
    )
    for model, what in (("cv", "cv, σa = 1 m/s²"), ("imm", "IMM (default)")):
        f = tg["models"][model]
        lines.append(
            f"  {what}: compiled {f['compiled_plots_per_cpu_s']:.0f}, numpy engine "
            f"{f['numpy_plots_per_cpu_s']:.0f} plots per CPU-s "
            f"(compiled/numpy {f['compiled_over_numpy_cpu']:.1f}×)"
        )
    lines.append(
        f"  IMM/cv on the compiled engine, per CPU-s: {tg['imm_over_cv_compiled_cpu']:.2f}×"
    )
    per = ", ".join(
        f"{m} {v:.0f} ns ({tg['one_target_speedup_vs_filterpy'][m]:.0f}×)"
        for m, v in tg["one_target_ns_per_step"].items()
    )
    listed = ", ".join(f"{m} {v:.0f} ns" for m, v in tg["one_target_plot_list_ns_per_step"].items())
    lines.append(
        f"one target, {tg['one_target_plots']} plots, per method-step, blocks of arrays (vs "
        f"filterpy): {per}; lists of Plot: {listed}; one plot per call: "
        f"{tg['one_plot_per_call_ns_per_step']:.0f} ns"
    )
    for dims, runs in tg["file"].items():
        for r in runs.values():
            each = "; ".join(
                f"{kind} {r[kind]['plots_per_s']:.0f} plots/s wall ({r[kind]['wall_s']:.1f} s), "
                f"{r[kind]['plots_per_cpu_s']:.0f} plots per CPU-s, "
                f"peak RSS {r[kind]['peak_rss_mb']:.0f} MB"
                for kind in TRACK_FILE_KINDS
            )
            lines.append(
                f"radarviz track, {dims}, {r['plots']} plots, all methods, into {each} "
                f"(Parquet/CSV per CPU-s {r['parquet_over_csv_cpu']:.2f}×)"
            )
            k = r["imm_csv"]
            lines.append(
                f"  the IMM into csv: {k['plots_per_s']:.0f} plots/s wall ({k['wall_s']:.1f} s), "
                f"{k['plots_per_cpu_s']:.0f} plots per CPU-s, peak RSS {k['peak_rss_mb']:.0f} MB "
                f"(IMM/cv per CPU-s {r['imm_over_cv_cpu']:.2f}×)"
            )
    lines.append(format_association(doc["association"]))
    from radarviz.viz_app.bench.asterix import format_asterix

    lines.append(format_asterix(doc["asterix"]))
    if "live" in doc:  # a document of before the section
        from radarviz.viz_app.bench.live import format_live

        lines.append(format_live(doc["live"]))
    lines.append(f"peak RSS: {doc['peak_rss_mb']:.0f} MiB")
    return "\n".join(lines)
