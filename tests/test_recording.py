"""Recordings read back: documented entity paths, one row per scan, values equal to core's."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from radarviz.core.experiments.prosov import ALL_METHODS, TrackingConfig, prosov_scene, run_tracking
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.rerun.recording import ellipsoid_axes, recording_file
from radarviz.viz_app.rerun.scenes import log_prosov


@pytest.fixture(scope="module")
def prosov_rrd(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "prosov.rrd"
    with recording_file(path) as rec:
        log_prosov(rec, sigma_beta_deg=2.0, runs=200, seed=3, cloud_points=500)
    return path


def test_documented_entity_paths_exist_with_one_row_per_scan(
    prosov_rrd: Path, rrd_contents
) -> None:
    rows, _ = rrd_contents(prosov_rrd)
    scans = 60
    per_scan = ["/world/truth/position", "/world/measurements/radar", "/world/converted/seed"]
    for m in ("naive", "seed", "cmkf_d", "ucm", "ducm", "ekf", "ukf"):
        per_scan += [f"/world/tracks/{m}/{part}" for part in ("position", "covariance", "velocity")]
        per_scan += [
            f"/plots/{metric}/{m}"
            for metric in ("bias_range", "rmse_x", "sigma_x_filter", "nees_pos")
        ]
    per_scan += [
        "/plots/delta_x/filter",
        "/plots/delta_x/rmse",
        "/plots/delta_x/std",
        "/plots/nees_pos/band95_lo",
    ]
    for path in per_scan:
        assert rows.get(path) == scans, (path, rows.get(path))
    for static in (
        "/world/radars/radar",
        "/world/truth/path",
        "/world/tracks/ducm/path",
        "/world/monte_carlo/ucm/cloud",
        "/world/monte_carlo/ucm/mean",
        "/log",
    ):
        assert static in rows, static


def test_logged_series_equal_core_outputs(prosov_rrd: Path, rrd_contents) -> None:
    _, cols = rrd_contents(prosov_rrd)
    res = run_tracking(TrackingConfig(sigma_beta_deg=2.0, runs=200, seed=3))
    for m, metric in (("naive", "rmse_x"), ("ducm", "nees_pos"), ("ukf", "bias_range")):
        got = cols[f"/plots/{metric}/{m}"]
        assert got["scan"] == list(range(1, 61))
        np.testing.assert_array_equal(np.array(got["time"]) / 1e9, np.arange(60) * 10.0)
        np.testing.assert_array_equal(
            [v[0] for v in got["Scalars:scalars"]], getattr(res.metrics[m], metric)
        )


def test_rrd_verify_passes(prosov_rrd: Path) -> None:
    exe = Path(sys.executable).with_name("rerun")
    proc = subprocess.run(
        [str(exe), "rrd", "verify", str(prosov_rrd)], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr


def test_ellipsoid_axes_reconstruct_the_covariance() -> None:
    rng = np.random.default_rng(1)
    a = rng.normal(size=(50, 3, 3))
    cov = a @ a.transpose(0, 2, 1) + np.eye(3) * 0.1
    half, q = ellipsoid_axes(cov)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )
    rebuilt = R @ (half[:, :, None] ** 2 * np.eye(3)) @ R.transpose(0, 2, 1)
    np.testing.assert_allclose(rebuilt, cov, rtol=1e-9, atol=1e-12)


def test_record_refuses_to_overwrite_and_leaves_no_temporary(
    tmp_path: Path, capsys, rrd_contents
) -> None:
    out = tmp_path / "g.rrd"
    out.write_bytes(b"keep me")
    assert main(["record", "--preset", "prosov", "--out", str(out)]) == 2
    assert "refusing to overwrite (pass --overwrite)" in capsys.readouterr().err
    assert out.read_bytes() == b"keep me"
    assert main(["record", "--preset", "gorshkov", "--out", str(out), "--overwrite"]) == 0
    rows, _ = rrd_contents(out)
    assert rows["/plots/finite_memory/gain_r/RLS6"] == 20
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.rrd"]


def test_demo_writes_a_recording_headless(tmp_path: Path, capsys, rrd_contents) -> None:
    """The demo holds the three presets' documented entities, one row per scan, and its
    Prosov part is core's scene (σβ = 2°, 500 runs, seed 1): the statistics and the displayed
    run's tracks."""
    out = tmp_path / "sub" / "demo.rrd"
    assert main(["demo", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"wrote {out}" in printed and "radarviz view" in printed
    assert out.stat().st_size < 20e6
    rows, cols = rrd_contents(out)
    per_scan = ["/world/truth/position", "/world/measurements/radar", "/plots/nees_pos/band95_hi"]
    per_scan += [
        f"/world/tracks/{m}/{part}" for m in ALL_METHODS for part in ("position", "velocity")
    ]
    per_scan += [f"/plots/rmse_x/{m}" for m in ALL_METHODS]
    per_scan += [
        "/world/fusion/position",
        "/world/fusion/truth/position",
        "/plots/fused_velocity/m",
    ]
    for path in per_scan:
        assert rows.get(path) == 60, (path, rows.get(path))
    assert rows.get("/plots/finite_memory/gain_r/RLS6") == 20  # k = 1 … 20 scans in the window
    scene = prosov_scene(TrackingConfig(sigma_beta_deg=2.0, runs=500, seed=1))
    np.testing.assert_array_equal(
        [v[0] for v in cols["/plots/rmse_x/naive"]["Scalars:scalars"]],
        scene.result.metrics["naive"].rmse_x,
    )
    for m in ("seed", "ukf"):
        logged = np.array([p[0] for p in cols[f"/world/tracks/{m}/position"]["Points3D:positions"]])
        np.testing.assert_array_equal(
            logged[:, :2], scene.tracks[m].x[:, [0, 2]].astype(np.float32)
        )


def test_velocity_preset_logs_the_fused_velocity_and_flags_bad_geometry(
    tmp_path: Path, rrd_contents
) -> None:
    from radarviz.core.scenarios.multi_radar import fusion_scenario, generate_measurements
    from radarviz.core.velocity.estimate import M_WARN

    out = tmp_path / "v.rrd"
    assert main(["record", "--preset", "velocity", "--out", str(out), "--seed", "2"]) == 0
    rows, cols = rrd_contents(out)
    for r in ("R1", "R2", "R3"):
        assert f"/world/radars/{r}" in rows and rows[f"/world/fusion/measurements/{r}"] == 60
    assert rows["/world/fusion/position"] == 60 and rows["/world/fusion/truth/position"] == 60
    m = np.array([v[0] for v in cols["/plots/fused_velocity/m"]["Scalars:scalars"]])
    shown = set(cols["/world/fused_velocity/vector"]["scan"])
    flagged = {
        n for n, mv in zip(cols["/plots/fused_velocity/m"]["scan"], m, strict=True) if mv > M_WARN
    }
    # Every scan gets either an arrow with its ellipsoid or a warning, never both.
    assert shown.isdisjoint(flagged) and len(shown) + len(flagged) == 60
    assert rows["/world/fused_velocity/covariance"] == len(shown)
    warnings = [t[0] for t in cols["/log"]["TextLog:text"] if "velocity at scan" in t[0]]
    assert len(warnings) == len(flagged) > 0
    # The logged error series is the estimate minus the truth of the same scenario.
    truth = generate_measurements(fusion_scenario(), 590.0, seed=None)["R1"].true_velocity
    err_vz = cols["/plots/fused_velocity/error_vz"]
    arrows = cols["/world/fused_velocity/vector"]
    assert err_vz["scan"] == arrows["scan"]
    vz = np.array([v[0][2] for v in arrows["Arrows3D:vectors"]]) / 10.0  # one period of motion
    expected = vz - truth[np.array(arrows["scan"]) - 1, 2]
    np.testing.assert_allclose(
        [v[0] for v in err_vz["Scalars:scalars"]], expected, rtol=1e-5, atol=1e-4
    )
