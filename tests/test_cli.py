"""The command line: JSON interface, figures, one-line errors with exit status 2."""

from __future__ import annotations

import contextlib
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from radarviz.viz_app.cli.main import main

METHOD_KEYS = {
    "sigma_x_filter",
    "rmse_x",
    "std_x",
    "bias_range",
    "bias_cross",
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
    assert [c["sigma_beta_deg"] for c in doc["cases"]] == [1.0, 2.0]
    for case in doc["cases"]:
        assert case["sigma_r_m"] == 250.0 and case["n"] == [1, 2, 3, 4, 5]
        assert set(case["methods"]) == {"naive", "seed", "cmkf_d", "ucm", "ducm", "ekf", "ukf"}
        for m in case["methods"].values():
            assert set(m) == METHOD_KEYS
            assert all(len(v) == 5 and all(math.isfinite(x) for x in v) for v in m.values())
        assert set(case["delta_x_percent"]) == {"filter", "rmse", "std"}
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
        (["--sigma-beta-deg", "0"], "--sigma-beta-deg must be a finite number in (0, 20]"),
        (["--sigma-beta-deg", "-1"], "--sigma-beta-deg must be a finite number in (0, 20]"),
        (["--sigma-beta-deg", "nan"], "--sigma-beta-deg must be a finite number in (0, 20]"),
        (["--sigma-r-m", "0"], "--sigma-r-m must be a finite number in (0, 1e+06]"),
        (["--sigma-r-m", "inf"], "--sigma-r-m must be a finite number"),
        (["--period", "0"], "--period must be a finite number in (0, 3600]"),
        (["--period", "nan"], "--period must be a finite number in (0, 3600]"),
        (["--runs", "1"], "--runs must be an integer >= 2"),
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
        "radarviz: error: --sigma-beta-deg must be a finite number in (0, 20] (got nan)"
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


def test_bench_json_keys(capsys) -> None:
    """Smoke test of the benchmark's interface (figures are reported, never asserted)."""
    code = main(["bench", "--json", "--runs", "500", "1000", "--filterpy-runs", "3"])
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    for key in (
        "kf_ns_per_step",
        "filterpy_ns_per_step",
        "speedup_vs_filterpy",
        "runs",
        "peak_rss_mb",
    ):
        assert key in doc
    assert doc["runs"] == [500, 1000] and len(doc["kf_ns_per_step"]) == 2
    assert doc["filterpy_ns_per_step"] > 0 and all(v > 0 for v in doc["speedup_vs_filterpy"])


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
            assert set(v) == {"r", "vr", "a"} and all(len(x) == 20 for x in v.values())
    # Undefined values are null: range-only acceleration below k = 3, velocity at k = 1,
    # Doppler acceleration at k = 1.
    ro, rd = rls1["sigma"]["range_only"], rls1["sigma"]["range_doppler"]
    assert ro["a"][:2] == [None, None] and ro["a"][2] is not None
    assert ro["vr"][0] is None and rd["vr"][0] is not None
    assert rd["a"][0] is None and rd["a"][1] is not None
    assert set(rls1["gain_percent"]) == {"r", "vr", "a"}
    tr = doc["tracking"]
    assert tr["radar"] == "RLS3" and tr["runs"] == 50 and tr["start_scans"] == 3
    assert set(tr["variants"]) == {"range_only", "range_doppler"}
    assert tr["variants"]["range_doppler"]["rmse_vr"][:2] == [None, None]


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--radars", "RLS7"], "--radars must be among RLS1, RLS2, RLS3, RLS4, RLS5, RLS6"),
        (["--trials", "1"], "--trials must be an integer in [2,"),
        (["--tracking-runs", "1"], "--tracking-runs must be 0 (skip) or an integer >= 2"),
        (["--tracking-radar", "X"], "--tracking-radar must be one of RLS1"),
        (["--sigma-beta-deg", "nan"], "--sigma-beta-deg must be a finite number in (0, 20]"),
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
