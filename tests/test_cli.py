"""The command line: JSON interface, figures, one-line errors with exit status 2."""

from __future__ import annotations

import contextlib
import json
import math
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from radarviz.viz_app.cli.main import main

METHOD_KEYS = {
    "sigma_x_filter_m",
    "rmse_x_m",
    "std_x_m",
    "bias_range_m",
    "bias_cross_m",
    "nees_pos",
    "nees_state",
}


def test_reproduce_prosov_json_document(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(
        [
            "reproduce",
            "prosov",
            "--runs",
            "50",
            "--steps",
            "5",
            "--seed",
            "4",
            "--sigma-beta-deg",
            "1",
            "2",
            "--json",
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    doc = json.loads(out)
    assert doc["experiment"] == "prosov" and doc["runs"] == 50 and doc["seed"] == 4
    assert doc["period_s"] == 10.0
    assert doc["band"] == {"level": 0.95, "method": "delete-a-group jackknife", "groups": 32}
    assert [c["sigma_beta_deg"] for c in doc["cases"]] == [1.0, 2.0]
    for case in doc["cases"]:
        assert case["sigma_r_m"] == 250.0 and case["n"] == [1, 2, 3, 4, 5]
        assert set(case["methods"]) == {"naive", "seed", "cmkf_d", "ucm", "ducm", "ekf", "ukf"}
        for m in case["methods"].values():
            assert set(m) == METHOD_KEYS | {"ci95"}
            series = {k: v for k, v in m.items() if k != "ci95"}
            assert all(len(v) == 5 and all(math.isfinite(x) for x in v) for v in series.values())
            assert set(m["ci95"]) == METHOD_KEYS
            for key, band in m["ci95"].items():
                assert all(
                    lo <= x <= hi for lo, x, hi in zip(band["lo"], m[key], band["hi"], strict=True)
                )
        assert set(case["delta_x_percent"]) == {"filter", "rmse", "std"}
        assert set(case["delta_x_ci95_percent"]) == {"filter", "rmse", "std"}
        assert case["claims"] == []  # the paper's claims are over 20 scans; this run has 5
        lo, hi = case["nees_pos_band95"]
        assert 0 < lo < 2 < hi


def test_reproduce_prosov_table_and_plot(tmp_path: Path, capsys) -> None:
    png = tmp_path / "prosov.png"
    code = main(["reproduce", "prosov", "--runs", "40", "--steps", "25", "--plot", str(png)])
    assert code == 0
    out = capsys.readouterr().out
    assert "Δx(n) of seed vs naive" in out and "rmse reading" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["prosov.png"]  # no temporary left behind


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--sigma-beta-deg", "0"], "--sigma-beta-deg must be a finite number in [5e-05, 20]"),
        (["--sigma-beta-deg", "-1"], "--sigma-beta-deg must be a finite number in [5e-05, 20]"),
        (["--sigma-beta-deg", "nan"], "--sigma-beta-deg must be a finite number in [5e-05, 20]"),
        (["--sigma-r-m", "0"], "--sigma-r-m must be a finite number in [2, 100000]"),
        (["--sigma-r-m", "inf"], "--sigma-r-m must be a finite number"),
        (["--period", "0"], "--period must be a finite number in [0.001, 3600]"),
        (["--period", "nan"], "--period must be a finite number in [0.001, 3600]"),
        (["--runs", "1"], "--runs must be an integer in [3, 100000000]"),
        (["--steps", "1"], "--steps must be an integer in [2, 100000]"),
        (["--methods", "naive", "magic"], "--methods must be among naive, seed, cmkf_d"),
        (["--runs", "ten"], "not an integer: 'ten'"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(args: list[str], needle: str, capsys) -> None:
    # argparse type errors exit from the parser; range errors return 2 from main().
    with pytest.raises(SystemExit) if args[-1] == "ten" else contextlib.nullcontext():
        code = main(["reproduce", "prosov", *args])
        assert code == 2
    err = capsys.readouterr().err
    assert needle in err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_console_script_exit_status_and_no_traceback() -> None:
    exe = Path(sys.executable).with_name("radarviz")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "radarviz.viz_app.cli.main"]
    proc = subprocess.run(
        [*cmd, "reproduce", "prosov", "--sigma-beta-deg", "nan"],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONWARNINGS": "ignore"},
    )
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.strip().splitlines() == [
        "radarviz: error: --sigma-beta-deg must be a finite number in [5e-05, 20] (got nan)"
    ]


def test_unwritable_plot_path_is_an_error(tmp_path: Path, capsys) -> None:
    code = main(
        [
            "reproduce",
            "prosov",
            "--runs",
            "10",
            "--steps",
            "3",
            "--plot",
            str(tmp_path / "missing-dir" / "x.png"),
        ]
    )
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("radarviz: error:") and err.count("\n") == 1


def _high_water_rss_mib() -> float:
    """This process's peak resident memory so far, from the kernel (VmHWM, in KiB)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
    pytest.skip("no VmHWM in /proc/self/status")


def physical_mib_of_machine() -> float:
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**20


def test_bench_figures_are_consistent(capsys) -> None:
    """The benchmark's figures agree with each other and with what was asked.

    Speed itself is never asserted (it is measured by running the benchmark, not by a timed
    unit test); what can be wrong without the machine being slow is checked instead: the run
    counts, the ratio filterpy / ours, the units of the peak memory, and the table printing
    the same numbers as the JSON to its precision."""
    from radarviz.core.experiments.prosov import BLOCK_RUNS
    from radarviz.core.scenarios.planar import prosov_target
    from radarviz.viz_app.bench.engine import format_bench

    rss_before = _high_water_rss_mib()
    code = main(
        [
            *("bench", "--json", "--runs", "500", "1000", "--filterpy-runs", "3"),
            *("--targets", "30", "--asterix-plots", "300", "--track-plots", "2000"),
        ]
    )
    assert code == 0
    ru_after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    doc = json.loads(capsys.readouterr().out)

    assert doc["runs"] == [500, 1000] and doc["filterpy_runs"] == 3
    assert doc["scans"] == prosov_target().steps and doc["block_runs"] == BLOCK_RUNS
    kf, kf_only, fp = (
        doc["kf_ns_per_step"],
        doc["kf_filter_only_ns_per_step"],
        doc["filterpy_ns_per_step"],
    )
    assert len(kf) == len(kf_only) == len(doc["speedup_vs_filterpy"]) == 2
    for name in ("kf_ns_per_step", "kf_filter_only_ns_per_step", "speedup_vs_filterpy"):
        assert all(math.isfinite(v) and v > 0 for v in doc[name]), (name, doc[name])
    for name in ("filterpy_ns_per_step", "gorshkov_s"):
        assert math.isfinite(doc[name]) and doc[name] > 0, (name, doc[name])
    from radarviz.core.filters.methods import ALL_METHODS

    for name in ("numpy_ns_per_step", "compiled_ns_per_step", "experiment_ns_per_step"):
        assert set(doc[name]) == set(ALL_METHODS), name
        assert all(math.isfinite(v) and v > 0 for v in doc[name].values()), (name, doc[name])
    for m in ALL_METHODS:
        assert doc["compiled_speedup"][m] == pytest.approx(
            doc["numpy_ns_per_step"][m] / doc["compiled_ns_per_step"][m], rel=1e-12
        )
    from radarviz.viz_app.bench.reference import REFERENCE_METHODS

    pm = doc["per_method"]
    assert pm["per_method_runs"] == 500 and pm["filterpy_runs"] == 3
    for name in (
        "engine_filter_ns_per_step",
        "engine_metrics_ns_per_step",
        "reference_ns_per_step",
        "filterpy_ns_per_step",
    ):
        assert list(pm[name]) == list(REFERENCE_METHODS), name
        assert all(math.isfinite(v) and v > 0 for v in pm[name].values()), (name, pm[name])
    for m in REFERENCE_METHODS:
        assert pm["filterpy_over_engine"][m] == pytest.approx(
            pm["filterpy_ns_per_step"][m] / pm["engine_filter_ns_per_step"][m], rel=1e-12
        )
        for ratio in ("engine_over_reference", "metrics_over_reference"):
            # medians of same-repeat ratios, not ratios of medians: only their sign is exact
            assert math.isfinite(pm[ratio][m]) and pm[ratio][m] > 0, (ratio, m)
    for k in ("whole_run_ns_per_method_step", "filter_ns_per_method_step", "whole_run_over_filter"):
        assert math.isfinite(pm[k]) and pm[k] > 0, k
    assert doc["engine_runs"] == 500 and doc["parallel_runs"] == 1000
    assert doc["parallel_bit_identical"] is True
    assert doc["parallel_efficiency"] == pytest.approx(
        doc["one_thread_s"] / doc["all_cores_s"] / doc["cores"], rel=1e-12
    )
    assert set(doc["tune_median_ms"]) == {"prosov", "gorshkov", "velocity"}
    for scene, ms in doc["tune_median_ms"].items():
        assert math.isfinite(ms) and ms > 0, (scene, ms)
    imm = doc["imm"]
    assert imm["runs"] == 500 and imm["filterpy_runs"] == 3
    for label in ("batch", "single"):
        v = imm[label]
        assert all(math.isfinite(v[k]) and v[k] > 0 for k in v), (label, v)
        assert v["imm_over_cv"] == pytest.approx(v["imm_ns_per_step"] / v["cv_ns_per_step"])
    assert math.isfinite(imm["filterpy_imm_ns_per_step"]) and imm["filterpy_imm_ns_per_step"] > 0
    tg = doc["targets"]
    assert tg["targets"] == 30 and tg["loop_targets"] == 20 and tg["methods"] == 7
    assert tg["scans"] == prosov_target().steps
    for k in ("batched_plots_per_s", "loop_plots_per_s"):
        assert math.isfinite(tg[k]) and tg[k] > 0, (k, tg)
    assert tg["batched_over_loop"] == pytest.approx(
        tg["batched_plots_per_s"] / tg["loop_plots_per_s"], rel=1e-12
    )
    assert doc["asterix"]["plots"] == 300  # the section's own figures: tests/test_asterix.py
    assert tg["compiled_over_numpy"] == pytest.approx(
        tg["batched_plots_per_s"] / tg["numpy_plots_per_s"], rel=1e-12
    )
    assert set(tg["models"]) == {"cv", "imm"}
    for f in tg["models"].values():
        for k in ("compiled", "numpy"):
            assert math.isfinite(f[f"{k}_plots_per_cpu_s"]) and f[f"{k}_plots_per_cpu_s"] > 0
        assert f["compiled_over_numpy_cpu"] == pytest.approx(
            f["compiled_plots_per_cpu_s"] / f["numpy_plots_per_cpu_s"], rel=1e-12
        )
    cv_rates = tg["models"]["cv"]
    assert (cv_rates["compiled_plots_per_s"], cv_rates["numpy_plots_per_s"]) == (
        tg["batched_plots_per_s"],
        tg["numpy_plots_per_s"],
    )
    assert tg["imm_over_cv_compiled_cpu"] == pytest.approx(
        tg["models"]["imm"]["compiled_plots_per_cpu_s"] / cv_rates["compiled_plots_per_cpu_s"],
        rel=1e-12,
    )
    assert set(tg["one_target_ns_per_step"]) == set(ALL_METHODS)
    assert set(tg["one_target_plot_list_ns_per_step"]) == set(ALL_METHODS)
    for m, v in tg["one_target_ns_per_step"].items():
        assert tg["one_target_speedup_vs_filterpy"][m] == pytest.approx(fp / v, rel=1e-12)
    assert set(tg["file"]) == {"2d", "3d"}
    for runs in tg["file"].values():
        # Two runs (a tenth of --track-plots, then all): the plots written, 2 radars × 20
        # targets × whole scans, at least as many as asked.
        assert [r["plots"] for r in runs.values()] == [200, 2000]
        for r in runs.values():
            # The same input tracked into a CSV and a Parquet track file.
            for kind in ("csv", "parquet"):
                k = r[kind]
                assert k["plots_per_s"] == pytest.approx(r["plots"] / k["wall_s"], rel=1e-12)
                assert k["plots_per_cpu_s"] == pytest.approx(r["plots"] / k["cpu_s"], rel=1e-12)
                assert 0 < k["peak_rss_mb"] < physical_mib_of_machine()
            assert r["parquet_over_csv_cpu"] == pytest.approx(
                r["parquet"]["plots_per_cpu_s"] / r["csv"]["plots_per_cpu_s"], rel=1e-12
            )
            k = r["imm_csv"]  # the IMM (the command's default) into the CSV track file
            assert k["plots_per_cpu_s"] == pytest.approx(r["plots"] / k["cpu_s"], rel=1e-12)
            assert r["imm_over_cv_cpu"] == pytest.approx(
                k["plots_per_cpu_s"] / r["csv"]["plots_per_cpu_s"], rel=1e-12
            )
    # JSON keeps full precision: the ratio is exact to rounding.
    for ours, ratio in zip(kf, doc["speedup_vs_filterpy"], strict=True):
        assert ratio == pytest.approx(fp / ours, rel=1e-12)
    # Peak RSS is this process's (the CLI ran in it), in MiB: at least the kernel's high-water
    # mark before the run, at most the one after, and below the machine's memory.
    physical_mib = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**20
    assert rss_before <= doc["peak_rss_mb"] <= ru_after < physical_mib

    # The table prints fp to 1 ns, ours to 0.1 ns and the speed-up to 1: its speed-up must be
    # its own fp / ours within what that rounding allows.
    table = format_bench(doc).splitlines()
    # the machine first: the throughput figures mean nothing without it
    host = doc["machine"]
    assert host["cores"] >= 1 and host["cpu"] and host["load_avg_1min_after"] >= 0
    assert table[0].startswith(f"machine: {host['cpu']}, {host['cores']} cores")
    fp_printed = float(table[1].split("filterpy KalmanFilter:")[1].split("ns")[0])
    assert fp_printed == round(fp)
    rows = [line for line in table if line.startswith("batched ucm filter")]
    assert len(rows) == 2
    for line, runs in zip(rows, doc["runs"], strict=True):
        head, tail = line.split(" runs:")
        assert int(head.split(",")[1]) == runs
        ours = float(tail.split("ns")[0])
        speedup = float(tail.split("speedup vs filterpy")[1].rstrip("×"))
        ratio = fp_printed / ours
        assert abs(speedup - ratio) <= 0.5 + ratio * (0.5 / fp_printed + 0.05 / ours), line
    assert f"peak RSS: {doc['peak_rss_mb']:.0f} MiB" in table
    for m in REFERENCE_METHODS:  # one table row per method, its engine figure to 0.1 ns
        row = [line for line in table if line.split()[:1] == [m]]
        assert len(row) == 1 and float(row[0].split()[1]) == round(
            pm["engine_filter_ns_per_step"][m], 1
        ), m


def test_reproduce_gorshkov_json_document(capsys) -> None:
    code = main(
        [
            "reproduce",
            "gorshkov",
            "--trials",
            "2000",
            "--seed",
            "5",
            "--radars",
            "RLS1",
            "RLS6",
            "--tracking-runs",
            "50",
            "--json",
        ]
    )
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["experiment"] == "gorshkov" and doc["trials"] == 2000 and doc["seed"] == 5
    assert [r["name"] for r in doc["radars"]] == ["RLS1", "RLS6"]
    rls1 = doc["radars"][0]
    assert rls1["sigma_r_m"] == 250 and rls1["sigma_vr_mps"] == 35 and rls1["period_s"] == 10
    assert abs(rls1["c0"] - 250**2 / (10**2 * 35**2)) < 1e-12
    assert rls1["k"] == list(range(1, 21))
    for group in ("sigma", "sigma_analytic"):
        assert set(rls1[group]) == {"range_only", "range_doppler"}
        for v in rls1[group].values():
            assert set(v) == {"r_m", "vr_mps", "a_mps2"} and all(len(x) == 20 for x in v.values())
    # Undefined values are null: range-only acceleration below k = 3, velocity at k = 1,
    # Doppler acceleration at k = 1.
    ro, rd = rls1["sigma"]["range_only"], rls1["sigma"]["range_doppler"]
    assert ro["a_mps2"][:2] == [None, None] and ro["a_mps2"][2] is not None
    assert ro["vr_mps"][0] is None and rd["vr_mps"][0] is not None
    assert rd["a_mps2"][0] is None and rd["a_mps2"][1] is not None
    assert set(rls1["gain_percent"]) == {"r_m", "vr_mps", "a_mps2"}
    tr = doc["tracking"]
    assert tr["radar"] == "RLS3" and tr["runs"] == 50 and tr["start_scans"] == 3
    assert set(tr["variants"]) == {"range_only", "range_doppler"}
    assert tr["variants"]["range_doppler"]["rmse_vr_mps"][:2] == [None, None]
    # Every Monte Carlo series has its band, null exactly where the series is null, and the
    # band brackets the value.
    assert doc["band"]["level"] == 0.95 and doc["band"]["groups"] == 32
    pairs = [
        (rls1["sigma"][v][c], rls1["sigma_ci95"][v][c])
        for v in ("range_only", "range_doppler")
        for c in ("r_m", "vr_mps", "a_mps2")
    ]
    pairs += [(rls1["gain_percent"][c], rls1["gain_ci95_percent"][c]) for c in ("vr_mps", "a_mps2")]
    for name in ("range_only", "range_doppler"):
        entry = tr["variants"][name]
        pairs += [(entry[k], entry["ci95"][k]) for k in ("rmse_vr_mps", "rmse_x_m", "nees_pos")]
    for values, band in pairs:
        for x, lo, hi in zip(values, band["lo"], band["hi"], strict=True):
            assert (x is None) == (lo is None) == (hi is None)
            assert x is None or lo < x < hi
    peak = rls1["range_gain_peak"]
    assert (
        peak["k"] in peak["k_within_band"] and peak["gain_ci95_percent"][0] < peak["gain_percent"]
    )


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--radars", "RLS7"], "--radars must be among RLS1, RLS2, RLS3, RLS4, RLS5, RLS6"),
        (["--trials", "1"], "--trials must be an integer in [3,"),
        (["--tracking-runs", "1"], "--tracking-runs must be 0 (skip) or an integer >= 2"),
        (["--tracking-radar", "X"], "--tracking-radar must be one of RLS1"),
        (["--sigma-beta-deg", "nan"], "--sigma-beta-deg must be a finite number in [5e-05, 20]"),
        (["--k-max", "0"], "--k-max must be an integer in [1, 20]"),
        (["--custom", "250", "0", "10"], "--custom C0 must be a finite number in (0, 1e+08]"),
        (["--custom", "-1", "1", "10"], "--custom SIGMA_R_M must be a finite number in (0,"),
        (["--custom", "250", "1", "0"], "--custom PERIOD_S must be a finite number in (0, 3600]"),
    ],
)
def test_gorshkov_bad_input(args: list[str], needle: str, capsys) -> None:
    assert main(["reproduce", "gorshkov", *args]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1


def test_gorshkov_custom_radar_follows_c0(capsys) -> None:
    code = main(
        [
            "reproduce",
            "gorshkov",
            "--trials",
            "500",
            "--radars",
            "RLS2",
            "--custom",
            "250",
            "1",
            "10",
            "--k-max",
            "5",
            "--tracking-runs",
            "0",
            "--json",
        ]
    )
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    rls2, custom = doc["radars"]
    assert custom["name"] == "custom" and abs(custom["sigma_vr_mps"] - 25.0) < 1e-9
    assert custom["k"] == [1, 2, 3, 4, 5] and "tracking" not in doc
    # Same σr, σVr, T as RLS2: identical analytic σ.
    assert custom["sigma_analytic"] == {
        v: {k: x[:5] for k, x in d.items()} for v, d in rls2["sigma_analytic"].items()
    }


def test_reproduce_gorshkov_plot(tmp_path: Path, capsys) -> None:
    png = tmp_path / "g.png"
    assert (
        main(
            ["reproduce", "gorshkov", "--trials", "500", "--tracking-runs", "0", "--plot", str(png)]
        )
        == 0
    )
    assert "range gain peaks at" in capsys.readouterr().out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["g.png"]


def test_compile_runs_only_command_lines_the_parser_accepts() -> None:
    """Each warm-up of ``radarviz compile`` is a command line of this parser (a renamed flag
    would otherwise leave its kernels to the first run), and they reach both commands the
    set-up promises to prepare."""
    from radarviz.viz_app.cli.compile_kernels import JOBS
    from radarviz.viz_app.cli.main import build_parser

    parser = build_parser()
    seen = set()
    for job in JOBS:
        for command in job.commands:
            args = parser.parse_args([a.replace("{d}", "/nowhere") for a in command])
            seen.add((args.command, getattr(args, "associate", None), getattr(args, "rrd", None)))
    commands = {c for c, _, _ in seen}
    assert {"demo", "track", "simulate"} <= commands
    assert any(a == "gnn" for _, a, _ in seen) and any(r for _, _, r in seen)


def test_compile_bad_jobs_is_one_line(capsys) -> None:
    assert main(["compile", "--jobs", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--jobs" in err and "Traceback" not in err


def test_top_level_help_imports_no_command_module() -> None:
    """``radarviz --help`` lists every command from ``viz_app.cli.commands`` without importing
    a command's module (their imports reach the engine); ``radarviz track --help`` imports
    ``track``'s (and its presets) alone."""
    script = """
import sys, contextlib, io
from radarviz.viz_app.cli.commands import COMMANDS
from radarviz.viz_app.cli.main import main
with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.suppress(SystemExit):
    main(sys.argv[1:])
cli = {m.rsplit(".", 1)[1] for m in sys.modules if m.startswith("radarviz.viz_app.cli.")}
print(sorted(cli - {"main", "commands", "args", "params"}))
if len(sys.argv) == 2:
    assert all(name in out.getvalue() for name in COMMANDS), out.getvalue()
"""

    def imported(*argv: str) -> str:
        done = subprocess.run(
            [sys.executable, "-c", script, *argv], capture_output=True, text=True, check=True
        )
        return done.stdout.strip()

    assert imported("--help") == "[]"
    assert imported("track", "--help") == "['presets', 'track']"  # track's presets


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="Linux's VmHWM")
def test_peak_rss_is_the_process_own_not_its_parents() -> None:
    """``peak_rss_mb`` of a process started by a large one is its own peak: ``ru_maxrss``
    keeps the parent's across fork and exec (a child of this 400 MB test reported 407)."""
    import numpy as np

    held = np.ones(400 * 2**20 // 8)  # 400 MiB, touched
    code = "from radarviz.viz_app.runtime import peak_rss_mb; print(peak_rss_mb())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    child = float(out.stdout)
    assert 0.0 < child < 200.0, child
    assert held.sum() > 0
