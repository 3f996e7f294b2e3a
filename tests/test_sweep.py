"""Parameter sweeps: exact reduction, Dask vs serial, worker death, resume, CLI errors, output.

Every comparison here is bitwise (``np.array_equal``): a sweep adds each grid point's blocks
in block order, so nothing about scheduling may change a single bit.
"""

from __future__ import annotations

import json
import math
import os
import sys
from functools import partial
from pathlib import Path

import cloudpickle
import numpy as np
import pyarrow.parquet as pq
import pytest
from rerun.chunk import RrdReader

from radarviz.core.experiments.prosov import (
    TrackingConfig,
    block_seed,
    block_sizes,
    prosov_configs,
    run_tracking,
)
from radarviz.core.experiments.sweep import (
    ChunkSums,
    GridAxis,
    SweepBase,
    SweepSpec,
    compute_chunk,
    point_config,
    reduce_chunks,
    run_sweep_serial,
)
from radarviz.core.metrics import nees_band
from radarviz.core.params import ParameterError
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.sweep.output import COLUMNS, METRIC_COLUMNS, sweep_table, table_columns
from radarviz.viz_app.sweep.run import ChunkStore, chunk_dir, parse_axis, run_sweep

# Chunk functions defined here run on Dask workers, which cannot import this test module:
# ship its functions by value.
cloudpickle.register_pickle_by_value(sys.modules[__name__])

METHODS = ("naive", "seed", "ducm", "ekf")


def _spec(seed: int = 5, runs: int = 1300, block: int = 500) -> SweepSpec:
    """2 × 2 points of 3 chunks each (500, 500, 300 runs), 12 scans: fast, yet several
    chunks per point so order matters."""
    base = SweepBase(runs=runs, seed=seed, steps=12, methods=METHODS)
    axes = (GridAxis("sigma_beta_deg", (1.0, 2.5)), GridAxis("range_km", (60.0, 150.0)))
    return SweepSpec(base=base, axes=axes, block=block)


def _assert_results_equal(a, b) -> None:
    assert len(a) == len(b)
    for ra, rb in zip(a, b, strict=True):
        assert ra.config == rb.config
        assert ra.nees_pos_band95 == rb.nees_pos_band95
        for m in ra.metrics:
            for x, y, name in zip(ra.metrics[m], rb.metrics[m], ra.metrics[m]._fields, strict=True):
                assert np.array_equal(x, y, equal_nan=True), (m, name)


@pytest.fixture(scope="module")
def client():
    """One 2-worker LocalCluster (2 processes, 1 thread each) for the Dask tests."""
    from radarviz.viz_app.sweep.run import dask_client

    with dask_client("local", 2) as c:
        c.wait_for_workers(2, timeout=60)
        yield c


@pytest.fixture(scope="module")
def serial_results():
    return run_sweep_serial(_spec())


# ------------------------------------------------------------------ exact reduction


def test_block_seed_is_the_spawned_child() -> None:
    children = np.random.SeedSequence(9).spawn(5)
    for b, child in enumerate(children):
        assert np.array_equal(block_seed(9, b).generate_state(4), child.generate_state(4))


def test_grid_point_equals_run_tracking_bitwise() -> None:
    """A point reduced from its chunks, in any arrival order, is run_tracking exactly."""
    (cfg,) = prosov_configs([1.7], runs=1300, seed=11, steps=12, methods=METHODS)
    sizes = block_sizes(cfg.runs, 500)
    chunks = [compute_chunk(cfg, b, s) for b, s in enumerate(sizes)]
    expected = run_tracking(cfg, block=500)
    for order in ([0, 1, 2], [2, 0, 1], [1, 2, 0]):
        got = reduce_chunks(cfg, [chunks[i] for i in order], block=500)
        _assert_results_equal([got], [expected])
    with pytest.raises(ValueError, match="expected blocks"):
        reduce_chunks(cfg, chunks[:2], block=500)


def test_range_axis_at_150_km_is_the_prosov_target() -> None:
    base = SweepBase(runs=10, steps=60)
    (cfg,) = prosov_configs([1.0], runs=10)
    assert point_config(base, {"range_km": 150.0}) == cfg
    moved = point_config(base, {"range_km": 50.0}).target
    assert (moved.x0_m, moved.y0_m, moved.vx_mps, moved.vy_mps) == (50e3, 0.0, 200.0, 0.0)


def test_sweep_point_equals_reproduce_prosov_json(tmp_path: Path, capsys) -> None:
    """One grid point of a sweep at the default block size equals ``reproduce prosov
    --json`` with the same runs and seed, bit for bit (JSON floats round-trip exactly)."""
    runs = 16_384 + 300  # two blocks of the default size
    common = ["--runs", str(runs), "--seed", "3", "--steps", "8", "--methods", "naive", "ekf"]
    assert main(["reproduce", "prosov", "--sigma-beta-deg", "2", "--json", *common]) == 0
    doc = json.loads(capsys.readouterr().out)
    out = tmp_path / "one.parquet"
    assert (
        main(
            [
                "sweep",
                "--grid",
                "sigma_beta_deg=1,2",
                "--scheduler",
                "serial",
                "--out",
                str(out),
                "--json",
                *common,
            ]
        )
        == 0
    )
    capsys.readouterr()
    table = pq.read_table(out).to_pydict()
    rows = [
        i
        for i, (sigma_beta_deg, m) in enumerate(
            zip(table["sigma_beta_deg"], table["method"], strict=True)
        )
        if sigma_beta_deg == 2.0
    ]
    case = doc["cases"][0]
    for method in ("naive", "ekf"):
        idx = [i for i in rows if table["method"][i] == method]
        for key in ("rmse_x_m", "std_x_m", "bias_range_m", "nees_pos", "sigma_x_filter_m"):
            assert [table[key][i] for i in idx] == case["methods"][method][key], (method, key)


# ------------------------------------------------------------------ Dask


def test_two_worker_cluster_equals_serial(client, serial_results) -> None:
    run = run_sweep(_spec(), store=None, client=client)
    assert run.workers == 2 and run.computed == 12 and run.reused == 0
    _assert_results_equal(run.results, serial_results)
    a = sweep_table(_spec(), run.results)
    b = sweep_table(_spec(), serial_results)
    for col in COLUMNS:
        assert a.column(col).equals(b.column(col)), col


def _die_once(marker: str, victim: int, config: TrackingConfig, index: int, size: int) -> ChunkSums:
    """Chunk function that kills its worker process the first time it meets block
    ``victim`` (the marker file records that it did), then computes normally."""
    if index == victim and not os.path.exists(marker):
        Path(marker).touch()
        os._exit(1)
    return compute_chunk(config, index, size)


def test_worker_killed_mid_sweep_gives_the_identical_result(
    client, serial_results, tmp_path: Path
) -> None:
    marker = tmp_path / "killed"
    store = ChunkStore(tmp_path / "chunks")
    run = run_sweep(_spec(), store, client=client, task=partial(_die_once, str(marker), 1))
    assert marker.exists()  # a worker did die running a chunk
    assert run.computed == 12
    _assert_results_equal(run.results, serial_results)
    client.wait_for_workers(2, timeout=60)  # the nanny restarts it for the next test


def test_cli_on_a_tcp_scheduler_writes_table_figures_and_recording(
    serial_results, tmp_path: Path, capsys
) -> None:
    """``--scheduler tcp://…``: the user's own plain-TCP scheduler (the sweep's local cluster
    speaks TLS, so it cannot stand in for one)."""
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        protocol="tcp",
        dashboard_address=None,
        scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
    ) as cluster:
        assert cluster.scheduler_address.startswith("tcp://")
        _sweep_cli_on(cluster.scheduler_address, serial_results, tmp_path, capsys)


def _sweep_cli_on(scheduler: str, serial_results, tmp_path: Path, capsys) -> None:
    out = tmp_path / "s.parquet"
    rrd = tmp_path / "s.rrd"
    code = main(
        [
            "sweep",
            "--grid",
            "sigma_beta_deg=1,2.5",
            "range_km=60,150",
            "--runs",
            "1300",
            "--block",
            "500",
            "--seed",
            "5",
            "--steps",
            "12",
            "--methods",
            *METHODS,
            "--scheduler",
            scheduler,
            "--out",
            str(out),
            "--plot",
            str(tmp_path / "figs"),
            "--rrd",
            str(rrd),
            "--json",
        ]
    )
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["computed"] == 12 and doc["workers"] == 1
    table = pq.read_table(out)
    expected = sweep_table(_spec(), serial_results)
    for col in COLUMNS:
        assert table.column(col).equals(expected.column(col)), col
    assert sorted(p.name for p in (tmp_path / "figs").iterdir()) == [
        "sweep_bias_range_m.png",
        "sweep_nees_pos.png",
        "sweep_rmse_x_m.png",
    ]
    entities = {c.entity_path for c in RrdReader(str(rrd)).stream()}
    for m in METHODS:
        assert f"/sweep/heatmap/nees_pos/{m}" in entities
        assert f"/sweep/final/rmse_x_m/{m}" in entities


def test_bench_sweep_rows_match_the_serial_sweep_and_their_wall_times(capsys, monkeypatch) -> None:
    """Every timed run of ``bench-sweep`` gives the serial sweep's numbers, and its figures
    follow from its wall times.

    The bench's own ``identical_to_first`` compares each run with the first one, so it holds
    for the first by construction; here each run's results (captured from ``run_sweep``) are
    compared with ``run_sweep_serial`` of the same spec, computed in this process, and the
    flags must say what that comparison says. Speed is not asserted, only consistency:
    speed-up and efficiency recomputed from the printed compute times, and a compute time
    long enough to hold the chunks' own wall time spread over the workers."""
    import radarviz.viz_app.bench.sweep as bench_sweep
    import radarviz.viz_app.sweep.run as sweep_run

    calls: list[tuple[SweepSpec, int, object]] = []
    real_run_sweep = sweep_run.run_sweep

    def recording_run_sweep(spec, store, scheduler="serial", workers=1, **kwargs):
        run = real_run_sweep(spec, store, scheduler, workers, **kwargs)
        calls.append((spec, workers, run))
        return run

    for module in (sweep_run, bench_sweep):
        if hasattr(module, "run_sweep"):
            monkeypatch.setattr(module, "run_sweep", recording_run_sweep)
    code = main(
        [
            "bench-sweep",
            "--grid",
            "sigma_beta_deg=1,2",
            "--runs",
            "300",
            "--steps",
            "5",
            "--methods",
            "naive",
            "ekf",
            "--workers",
            "1",
            "2",
            "--json",
        ]
    )
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert [w for _, w, _ in calls] == [1, 2], "bench-sweep must time one sweep per worker count"

    spec = calls[0][0]
    assert all(c[0] == spec for c in calls)
    assert spec.base.runs == 300 and spec.base.steps == 5
    assert spec.base.methods == ("naive", "ekf") and spec.shape == (2,)
    reference = run_sweep_serial(spec)
    for _, _, run in calls:
        _assert_results_equal(run.results, reference)

    assert doc["points"] == 2 and doc["runs_per_point"] == 300 and doc["total_runs"] == 600
    assert doc["chunks"] == len(spec.tasks()) and doc["steps"] == 5
    assert doc["methods"] == ["naive", "ekf"]
    rows = doc["runs"]
    assert [r["workers"] for r in rows] == [run.workers for _, _, run in calls] == [1, 2]
    assert all(r["identical_to_first"] is True for r in rows)

    base = min(rows, key=lambda r: r["workers"])
    for r, (_, _, run) in zip(rows, calls, strict=True):
        t = r["compute_s"]
        assert t == round(run.compute_s, 3) and math.isfinite(t) and t > 0
        assert r["chunk_wall_s"] == round(run.chunk_wall_s, 3) > 0
        # The chunks ran inside the compute window, at most ``workers`` at a time (each
        # printed figure is rounded to 1 ms).
        assert r["workers"] * t + 0.0005 * (r["workers"] + 1) >= r["chunk_wall_s"], r
        speedup = base["compute_s"] / t
        efficiency = speedup * base["workers"] / r["workers"]
        assert math.isfinite(r["efficiency"]) and r["efficiency"] > 0
        assert r["speedup"] == pytest.approx(speedup, abs=0.0005 + 1e-12)
        assert r["efficiency"] == pytest.approx(efficiency, abs=0.0005 + 1e-12)


# ------------------------------------------------------------------ resume


def _sweep_cli(out: Path, *extra: str) -> list[str]:
    return [
        "sweep",
        "--grid",
        "sigma_beta_deg=1,2.5",
        "--runs",
        "1300",
        "--block",
        "500",
        "--steps",
        "12",
        "--methods",
        *METHODS,
        "--scheduler",
        "serial",
        "--out",
        str(out),
        "--json",
        *extra,
    ]


def test_rerun_computes_only_missing_chunks_and_ignores_stale_ones(tmp_path: Path, capsys) -> None:
    out = tmp_path / "s.parquet"
    assert main(_sweep_cli(out)) == 0
    first = json.loads(capsys.readouterr().out)
    assert (first["computed"], first["reused"]) == (6, 0)
    reference = pq.read_table(out)
    files = sorted(chunk_dir(out).glob("*.npz"))
    assert len(files) == 6
    files[0].unlink()
    files[3].unlink()
    files[4].write_bytes(b"not a chunk")  # damaged files are recomputed, not trusted
    files[5].write_bytes(files[5].read_bytes()[:200])  # a truncated zip
    assert main(_sweep_cli(out)) == 0
    second = json.loads(capsys.readouterr().out)
    assert (second["computed"], second["reused"]) == (4, 2)
    assert pq.read_table(out).equals(reference)
    # Another seed: none of the stored chunks applies.
    assert main(_sweep_cli(out, "--seed", "2")) == 0
    third = json.loads(capsys.readouterr().out)
    assert (third["computed"], third["reused"]) == (6, 0)
    assert not pq.read_table(out).equals(reference)
    assert len(list(chunk_dir(out).glob("*.npz"))) == 12


def test_interrupted_sweep_resumes_where_it_stopped(tmp_path: Path, serial_results) -> None:
    store = ChunkStore(tmp_path / "chunks")
    calls = []

    def crash_after_five(config: TrackingConfig, index: int, size: int) -> ChunkSums:
        if len(calls) == 5:
            raise KeyboardInterrupt
        calls.append(index)
        return compute_chunk(config, index, size)

    with pytest.raises(KeyboardInterrupt):
        run_sweep(_spec(), store, task=crash_after_five)
    assert len(list(store.directory.glob("*.npz"))) == 5
    assert not list(store.directory.glob("*.tmp*"))
    run = run_sweep(_spec(), store)
    assert (run.computed, run.reused) == (7, 5)
    _assert_results_equal(run.results, serial_results)


def test_more_runs_reuse_the_full_blocks_of_fewer(tmp_path: Path) -> None:
    store = ChunkStore(tmp_path / "chunks")
    run_sweep(_spec(runs=1000), store)  # blocks 500, 500 per point
    run = run_sweep(_spec(runs=1300), store)  # blocks 500, 500, 300
    assert (run.computed, run.reused) == (4, 8)


# ------------------------------------------------------------------ grid syntax and errors


def test_grid_ranges_include_stop_on_the_grid_in_decimal() -> None:
    assert parse_axis("sigma_beta_deg=0.5:3:0.5").values == (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
    assert parse_axis("range_km=50:300:40").values == (50, 90, 130, 170, 210, 250, 290)
    assert parse_axis("sigma_beta_deg=0.1:0.3:0.1").values == (0.1, 0.2, 0.3)
    assert parse_axis("period_s=5,10,2.5").values == (5.0, 10.0, 2.5)


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["--grid", "sigma_beta=1,2"], "--grid name"),
        (["--grid", "sigma_beta_deg=0.5:3:0"], "--grid sigma_beta_deg step"),
        (["--grid", "sigma_beta_deg=0:3:0.5"], "--grid sigma_beta_deg"),
        (["--grid", "sigma_beta_deg=1:30:1"], "--grid sigma_beta_deg"),
        (["--grid", "sigma_beta_deg=3:1:0.5"], "--grid sigma_beta_deg stop"),
        (["--grid", "range_km=abc"], "--grid range_km value"),
        (["--grid", "range_km=1:2"], "--grid range_km range"),
        (["--grid", "range_km=10,10"], "--grid range_km"),
        (["--grid", "range_km"], "--grid items"),
        (["--grid", "range_km=1,2", "range_km=3"], "--grid range_km"),
        (["--grid", "sigma_r_m=1:1e9:1"], "--grid sigma_r_m"),
        (["--grid", "sigma_beta_deg=1,2", "--sigma-beta-deg", "2"], "--sigma-beta-deg"),
        (["--scheduler", "localhost:8786"], "--scheduler"),
        (["--workers", "0"], "--workers"),
        (["--runs", "1"], "--runs"),
        (["--methods", "kalman"], "--methods"),
        (["--preset", "gorshkov"], "--preset"),
        (["--grid", "elevation_deg=0,30"], "--dims must be 3 for grid axis elevation_deg"),
        (["--grid", "sigma_elevation_deg=1,2"], "--dims"),
        (["--elevation-deg", "30"], "--elevation-deg needs --dims 3"),
        (["--sigma-elevation-deg", "2"], "--sigma-elevation-deg needs --dims 3"),
        (["--dims", "3", "--grid", "elevation_deg=0:90:30"], "--grid elevation_deg"),
        (["--dims", "3", "--elevation-deg", "-81"], "--elevation-deg"),
        (["--dims", "3", "--sigma-elevation-deg", "0"], "--sigma-elevation-deg"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(
    tmp_path: Path, capsys, args: list[str], names: str
) -> None:
    out = tmp_path / "s.parquet"
    code = main(["sweep", "--out", str(out), "--scheduler", "serial", "--runs", "10", *args])
    assert code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("radarviz: error: "), err
    assert names in err, err
    assert list(tmp_path.iterdir()) == []


def test_core_rejects_a_repeated_axis() -> None:
    with pytest.raises(ParameterError, match="more than once"):
        SweepSpec(axes=(GridAxis("range_km", (1.0,)), GridAxis("range_km", (2.0,))))


# ------------------------------------------------------------------ output table


def test_parquet_has_the_documented_columns(tmp_path: Path, capsys) -> None:
    out = tmp_path / "s.parquet"
    assert main(_sweep_cli(out)) == 0
    capsys.readouterr()
    table = pq.read_table(out)
    assert tuple(table.column_names) == COLUMNS
    assert set(METRIC_COLUMNS) <= set(COLUMNS)
    assert table.num_rows == 2 * len(METHODS) * 12
    meta = json.loads(table.schema.metadata[b"radarviz.sweep"])
    assert meta["axes"] == [{"name": "sigma_beta_deg", "unit": "deg", "values": [1.0, 2.5]}]
    assert meta["runs"] == 1300 and meta["block"] == 500
    d = table.to_pydict()
    assert set(d["method"]) == set(METHODS)
    assert d["scan"][:12] == list(range(1, 13))
    assert d["time_s"][:3] == [0.0, 10.0, 20.0]
    assert set(d["runs"]) == {1300} and set(d["range_km"]) == {150.0}
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries


def _always_die(config: TrackingConfig, index: int, size: int) -> ChunkSums:
    """Chunk function whose block 1 kills every worker that runs it."""
    if index == 1:
        os._exit(1)
    return compute_chunk(config, index, size)


def test_a_chunk_that_keeps_killing_workers_is_one_line_and_keeps_the_rest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    """Past ``allowed-failures`` Dask gives up on a chunk: the command says so in one line,
    exits 1, writes no table, and the chunks that did finish are kept for a re-run."""
    import dask

    import radarviz.viz_app.cli.sweep as sweep_mod

    real_run_sweep = sweep_mod.run_sweep

    def run_with_bad_task(*args, **kwargs):
        return real_run_sweep(*args, task=_always_die, **kwargs)

    monkeypatch.setattr(sweep_mod, "run_sweep", run_with_bad_task)
    out = tmp_path / "s.parquet"
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        status = main(
            [
                "sweep",
                "--preset",
                "prosov",
                "--grid",
                "sigma_beta_deg=1",
                "--runs",
                "1200",
                "--block",
                "500",
                "--workers",
                "1",
                "--steps",
                "5",
                "--out",
                str(out),
                "--json",
            ]
        )
    err = capsys.readouterr().err
    assert status == 1
    lines = [ln for ln in err.splitlines() if ln.startswith("radarviz: error:")]
    # Dask blames every chunk that was on the dying worker (queued ones too), so the chunk
    # named is block 1 or one queued behind it.
    assert len(lines) == 1 and "Dask gave up on chunk" in lines[0], err
    assert "of grid point 0: workers died" in lines[0], err
    assert not out.exists()
    kept = len(list(chunk_dir(out).glob("*.npz")))
    assert kept <= 2  # block 1 never finished
    # A re-run with a healthy chunk function resumes from what was kept.
    monkeypatch.setattr(sweep_mod, "run_sweep", real_run_sweep)
    assert (
        main(
            [
                "sweep",
                "--preset",
                "prosov",
                "--grid",
                "sigma_beta_deg=1",
                "--runs",
                "1200",
                "--block",
                "500",
                "--scheduler",
                "serial",
                "--steps",
                "5",
                "--out",
                str(out),
                "--json",
            ]
        )
        == 0
    )
    doc = json.loads(capsys.readouterr().out)
    assert (doc["reused"], doc["computed"]) == (kept, 3 - kept)
    assert out.exists()


# ------------------------------------------------------------------ 3D sweeps


def _spec_3d(runs: int = 700, block: int = 300) -> SweepSpec:
    """A 3D sweep over both elevation axes: 2 × 2 points of 3 chunks, 6 scans."""
    base = SweepBase(runs=runs, seed=4, steps=6, methods=("naive", "seed", "ukf"), dims=3)
    axes = (GridAxis("elevation_deg", (-20.0, 30.0)), GridAxis("sigma_elevation_deg", (0.5, 2.0)))
    return SweepSpec(base=base, axes=axes, block=block)


def test_3d_grid_point_is_the_3d_reproduction_bitwise() -> None:
    """A 3D point's config is ``prosov_configs(dims=3)``'s at the same E and σε (range 150 km),
    and its chunks, reduced in any order, are ``run_tracking`` of that config exactly."""
    spec = _spec_3d()
    for point, cfg in zip(spec.points(), spec.configs(), strict=True):
        (expected,) = prosov_configs(
            [1.0],
            runs=700,
            seed=4,
            steps=6,
            methods=("naive", "seed", "ukf"),
            dims=3,
            elevation_deg=point["elevation_deg"],
            sigma_elevation_deg=point["sigma_elevation_deg"],
        )
        assert cfg == expected
    cfg = spec.configs()[3]
    chunks = [compute_chunk(cfg, b, s) for b, s in enumerate(block_sizes(cfg.runs, 300))]
    got = reduce_chunks(cfg, chunks[::-1], block=300)
    _assert_results_equal([got], [run_tracking(cfg, block=300)])
    assert got.nees_pos_band95 == nees_band(3, 700)  # 3 degrees of freedom in 3D
    # The elevation noise reaches the statistics: the points differ in their σε.
    results = run_sweep_serial(spec)
    assert (
        results[2].metrics["naive"].bias_range_m[0] != results[3].metrics["naive"].bias_range_m[0]
    )


def test_3d_chunk_keys_see_elevation_and_sigma_elevation() -> None:
    from radarviz.core.experiments.sweep import chunk_key

    keys = {chunk_key(cfg, 0, 300) for cfg in _spec_3d().configs()}
    assert len(keys) == 4
    (flat,) = prosov_configs([1.0], runs=700, seed=4, steps=6, methods=("naive",))
    (lifted,) = prosov_configs(
        [1.0], runs=700, seed=4, steps=6, methods=("naive",), dims=3, sigma_elevation_deg=1.0
    )
    assert chunk_key(flat, 0, 300) != chunk_key(lifted, 0, 300)


def test_3d_sweep_on_the_cluster_equals_serial(client) -> None:
    run = run_sweep(_spec_3d(), store=None, client=client)
    assert run.computed == 12
    _assert_results_equal(run.results, run_sweep_serial(_spec_3d()))


def test_3d_sweep_point_equals_reproduce_prosov_dims_3_json(tmp_path: Path, capsys) -> None:
    """The CLI: a point of ``sweep --dims 3`` equals ``reproduce prosov --dims 3 --json`` with
    the same runs and seed bit for bit, and the table has the elevation columns."""
    common = ["--runs", "400", "--seed", "3", "--steps", "5", "--methods", "naive", "ukf"]
    el = ["--elevation-deg", "25", "--sigma-elevation-deg", "1.5"]
    assert (
        main(
            ["reproduce", "prosov", "--dims", "3", "--sigma-beta-deg", "1", *el, "--json", *common]
        )
        == 0
    )
    doc = json.loads(capsys.readouterr().out)
    out = tmp_path / "three.parquet"
    sweep = ["sweep", "--dims", "3", "--grid", "sigma_beta_deg=1,2", "--scheduler", "serial"]
    assert main([*sweep, *el, "--out", str(out), "--json", *common]) == 0
    capsys.readouterr()
    table = pq.read_table(out)
    assert tuple(table.column_names) == table_columns(3)
    meta = json.loads(table.schema.metadata[b"radarviz.sweep"])
    assert meta["dims"] == 3
    assert meta["fixed"]["elevation_deg"] == 25.0 and meta["fixed"]["sigma_elevation_deg"] == 1.5
    d = table.to_pydict()
    assert set(d["elevation_deg"]) == {25.0} and set(d["sigma_elevation_deg"]) == {1.5}
    assert set(d["nees_pos_lo95"]) == {nees_band(3, 400)[0]}
    (case,) = doc["cases"]
    for method in ("naive", "ukf"):
        idx = [
            i
            for i, (sigma_beta_deg, m) in enumerate(
                zip(d["sigma_beta_deg"], d["method"], strict=True)
            )
            if sigma_beta_deg == 1.0 and m == method
        ]
        for key in ("rmse_x_m", "bias_range_m", "nees_pos", "nees_state", "sigma_x_filter_m"):
            assert [d[key][i] for i in idx] == case["methods"][method][key], (method, key)
