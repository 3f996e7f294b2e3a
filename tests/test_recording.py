"""Recordings read back: documented entity paths, one row per scan, values equal to core's."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from radarviz.core.experiments.prosov import (
    ALL_METHODS,
    SHOWN_CONVERSIONS,
    TrackingConfig,
    prosov_scene,
    run_tracking,
)
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.palette import rgb
from radarviz.viz_app.rerun.prosov_scene import CLOUD_SHOWN, log_prosov
from radarviz.viz_app.rerun.recording import ellipsoid_axes, recording_file


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
    per_scan = ["/prosov/map/scan"]
    per_scan += ["/prosov/bias/scan"]
    for c in (*ALL_METHODS, "polar"):
        per_scan.append(f"/prosov/target/{c}/scan")
    for m in ALL_METHODS:
        per_scan += [
            f"/plots/prosov/{name}/{m}" for name in ("bias_range_m", "rmse_x_m", "nees_pos")
        ]
    per_scan += [f"/plots/prosov/delta_x_percent/{r}" for r in ("filter", "rmse", "std")]
    per_scan += ["/plots/prosov/nees_pos/band95_lo", "/plots/prosov/nees_pos/band95_hi"]
    for path in per_scan:
        assert rows.get(path) == scans, (path, rows.get(path))
    for static in (
        "/prosov/map",
        "/prosov/map/radar",
        "/prosov/map/paths",
        "/prosov/bias",
        "/prosov/target",
        "/prosov/legend",
        "/log",
    ):
        assert static in rows, static


def test_logged_series_equal_core_outputs(prosov_rrd: Path, rrd_contents) -> None:
    _, cols = rrd_contents(prosov_rrd)
    res = run_tracking(TrackingConfig(sigma_beta_deg=2.0, runs=200, seed=3))
    for m, name, metric in (
        ("naive", "rmse_x_m", "rmse_x_m"),
        ("ducm", "nees_pos", "nees_pos"),
        ("ukf", "bias_range_m", "bias_range_m"),
    ):
        got = cols[f"/plots/prosov/{name}/{m}"]
        assert got["scan"] == list(range(1, 61))
        np.testing.assert_array_equal(np.array(got["time"]) / 1e9, np.arange(60) * 10.0)
        np.testing.assert_array_equal(
            [v[0] for v in got["Scalars:scalars"]], getattr(res.metrics[m], metric)
        )


def test_target_frame_is_the_estimate_seen_from_the_radar(prosov_rrd: Path, rrd_contents) -> None:
    """The logged target-frame estimate is (cross-range, down-range) of x̂ − x, computed here
    from the truth's azimuth β: (−sin β Δx + cos β Δy, cos β Δx + sin β Δy); every point of
    the logged outline lies on the 1σ ellipse of the rotated position covariance."""
    _, cols = rrd_contents(prosov_rrd)
    scene = prosov_scene(TrackingConfig(sigma_beta_deg=2.0, runs=200, seed=3))
    truth = scene.truth[:, [0, 2]]
    beta = np.arctan2(truth[:, 1], truth[:, 0])
    c, s = np.cos(beta), np.sin(beta)
    for m in ("naive", "ukf"):
        track = scene.tracks[m]
        d = track.x[:, [0, 2]] - truth
        expected = np.stack([-s * d[:, 0] + c * d[:, 1], c * d[:, 0] + s * d[:, 1]], -1)
        # Each scan's last point is the estimate (drawn over the cloud and the measurement).
        points = cols[f"/prosov/target/{m}/scan"]["Points2D:positions"]
        got = np.array([p[-1] for p in points])
        np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-2)
        rot = np.stack([np.stack([-s, c], -1), np.stack([c, s], -1)], -2)
        pos = track.P[:, [0, 2]][:, :, [0, 2]]
        cov = rot @ pos @ rot.transpose(0, 2, 1)
        strips = cols[f"/prosov/target/{m}/scan"]["LineStrips2D:strips"]
        # A conversion's scan also holds its × (two strokes) and its cloud and converted point.
        own = m in SHOWN_CONVERSIONS
        assert {len(row) for row in strips} == {3 if own else 1}, m
        # The truth, the scale (and a note), the cloud and the converted point, the estimate.
        assert {len(row) for row in points} == {CLOUD_SHOWN + 5 if own else 3}, m
        for n in (0, 30, 59):
            pts = np.array(strips[n][0]) - expected[n]
            q = np.einsum("si,ij,sj->s", pts, np.linalg.inv(cov[n]), pts)
            np.testing.assert_allclose(q, 1.0, rtol=1e-3)
        assert not np.allclose(got, 0.0)  # the comparison above can fail


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
    # The six radars' gains against k: one static curve each.
    assert rows["/charts/gorshkov/gain_r_percent"] == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.rrd"]


def test_demo_writes_a_recording_headless(tmp_path: Path, capsys, rrd_contents) -> None:
    """The demo holds the three scenes' documented entities, and its Prosov part is core's
    scene (σβ = 2°, 500 runs, seed 1): the statistics and the displayed run's tracks."""
    out = tmp_path / "sub" / "demo.rrd"
    assert main(["demo", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"wrote {out}" in printed and "radarviz view" in printed
    assert out.stat().st_size < 40e6
    rows, cols = rrd_contents(out)
    per_scan = {"/prosov/map/scan": 60, "/plots/prosov/nees_pos/band95_hi": 60}
    per_scan |= {f"/prosov/target/{m}/scan": 60 for m in ALL_METHODS}
    per_scan |= {"/velocity/map/fused/position": 50, "/velocity/error/covariance": 50}
    per_scan |= {"/plots/doppler_start/rmse_vr_mps/range_doppler": 58}
    for path, n in per_scan.items():
        assert rows.get(path) == n, (path, rows.get(path))
    # Gorshkov's curves are functions of the window length: static charts, no timeline of
    # their own (every tab shows whichever timeline is active).
    assert rows["/charts/gorshkov/gain_r_percent"] == 0
    assert not any("window_k" in c for entity in cols.values() for c in entity)
    scene = prosov_scene(TrackingConfig(sigma_beta_deg=2.0, runs=500, seed=1))
    np.testing.assert_array_equal(
        [v[0] for v in cols["/plots/prosov/rmse_x_m/naive"]["Scalars:scalars"]],
        scene.result.metrics["naive"].rmse_x_m,
    )
    pts = cols["/prosov/map/scan"]["Points2D:positions"]
    np.testing.assert_array_equal(
        np.array([p[-1] for p in pts]), scene.truth[:, [0, 2]].astype(np.float32)
    )
    for m in ("seed", "ukf"):
        # The plot first, then the estimates in the methods' order, the truth last.
        logged = np.array([p[1 + list(scene.tracks).index(m)] for p in pts])
        np.testing.assert_array_equal(logged, scene.tracks[m].x[:, [0, 2]].astype(np.float32))


def test_velocity_preset_logs_the_fused_velocity_and_flags_bad_geometry(
    tmp_path: Path, rrd_contents
) -> None:
    from radarviz.core.scenarios.multi_radar import fusion_scenario, generate_measurements
    from radarviz.core.velocity.estimate import M_WARN

    out = tmp_path / "v.rrd"
    assert main(["record", "--preset", "velocity", "--out", str(out), "--seed", "2"]) == 0
    rows, cols = rrd_contents(out)
    scans = 50
    for r in ("R1", "R2", "R3"):
        assert f"/velocity/map/radars/{r}" in rows
    # Every radar's line of sight and radial velocity, per scan, in one entity each.
    for entity in ("/velocity/map/lines_of_sight", "/velocity/vector/radial"):
        assert rows[entity] == scans
        assert {
            len(v)
            for v in cols[entity][
                "Arrows3D:vectors" if "radial" in entity else "LineStrips3D:strips"
            ]
        } == {3}
    assert rows["/velocity/map/fused/position"] == scans
    m_col = cols["/plots/velocity/geometry_metric/m"]
    m = np.array([v[0] for v in m_col["Scalars:scalars"]])
    flagged = {n for n, mv in zip(m_col["scan"], m, strict=True) if mv > M_WARN}
    warnings = [t[0] for t in cols["/log"]["TextLog:text"] if "velocity at scan" in t[0]]
    assert len(warnings) == len(flagged) > 0
    # Flagged scans are drawn grey and left out of the error plot.
    arrows = cols["/velocity/vector/fused"]
    grey = {
        n
        for n, c in zip(arrows["scan"], arrows["Arrows3D:colors"], strict=True)
        if c[0] == rgb_int("band")
    }
    assert grey == flagged
    err_vz = cols["/plots/velocity/error_mps/vz"]
    assert set(err_vz["scan"]) == set(arrows["scan"]) - flagged
    # The logged error is the estimate minus the truth of the same scenario.
    truth = generate_measurements(fusion_scenario(), 490.0, seed=None)["R1"].true_velocity
    vz = {n: v[0][2] for n, v in zip(arrows["scan"], arrows["Arrows3D:vectors"], strict=True)}
    expected = [vz[n] - truth[n - 1, 2] for n in err_vz["scan"]]
    np.testing.assert_allclose(
        [v[0] for v in err_vz["Scalars:scalars"]], expected, rtol=1e-5, atol=1e-3
    )


def rgb_int(name: str) -> int:
    """A palette colour as Rerun stores it: 0xRRGGBBAA."""
    r, g, b = rgb(name)
    return (r << 24) | (g << 16) | (b << 8) | 0xFF


def test_view_refuses_a_truncated_or_foreign_file(tmp_path: Path, capsys) -> None:
    """``view`` reads the whole file first: a truncated recording (cut anywhere, a message
    boundary included: such a prefix reads chunk by chunk like a whole file, and the viewer
    then waits for the rest for ever) or a file that is not one is a one-line error (exit 2)
    naming it, and no viewer starts."""
    good = tmp_path / "v.rrd"
    assert main(["record", "--preset", "velocity", "--out", str(good)]) == 0
    data = good.read_bytes()
    foreign = tmp_path / "notes.rrd"
    foreign.write_text("not a recording\n")
    cuts = [len(data) * k // 8 for k in range(1, 8)] + [len(data) - 1]
    paths = [foreign]
    for i, cut in enumerate(cuts):
        paths.append(tmp_path / f"t{i}.rrd")
        paths[-1].write_bytes(data[:cut])
    # A stream still open: every message whole, the footer not yet written.
    import rerun as rr

    stream = rr.RecordingStream("radarviz-open-stream")
    stream.save(str(tmp_path / "open.rrd"))
    stream.log("x", rr.Points3D([[0.0, 0.0, 0.0]]))
    stream.flush()
    paths.append(tmp_path / "unfinished.rrd")
    paths[-1].write_bytes((tmp_path / "open.rrd").read_bytes())
    stream.disconnect()
    exe = Path(sys.executable).with_name("radarviz")
    for path in paths:
        # A subprocess with a timeout: a file accepted by mistake would serve for ever.
        done = subprocess.run(
            [str(exe), "view", str(path)], capture_output=True, text=True, timeout=120
        )
        assert done.returncode == 2, (path, done.stderr)
        assert done.stderr.count("\n") == 1 and f"{path} is not a" in done.stderr, done.stderr


def test_prosov3d_scene_logs_every_method_in_the_3d_target_frame(tmp_path, rrd_contents) -> None:
    """``record --preset prosov3d``: per scan every method's estimate and 1σ ellipsoid in the
    (down-range, cross-range, up) frame and the statistics; the ellipsoids are the tracks'
    covariances rotated into that frame (checked through the basis itself)."""
    from radarviz.core.geometry import range_cross_up_basis
    from radarviz.viz_app.rerun.prosov_scene import log_prosov3d

    path = tmp_path / "p3d.rrd"
    with recording_file(path) as rec:
        axis = log_prosov3d(rec, runs=40, seed=2)
    assert np.isfinite(axis) and axis > 0
    # The axes' tips and their names stay inside what the small views frame (about ±axis
    # around the origin): at most AXIS_REACH of it, and a round length not far below.
    from rerun.chunk import RrdReader

    from radarviz.viz_app.rerun.prosov_scene import AXIS_NAMES, AXIS_REACH, axis_length_km

    (tips,) = [
        c.to_record_batch()
        for c in RrdReader(str(path)).stream()
        if c.is_static and c.entity_path == "/prosov3d/target/axes/tips"
    ]
    tip = np.array(tips.column("Points3D:positions").to_pylist()[0])
    length = axis_length_km(axis)
    np.testing.assert_allclose(np.linalg.norm(tip, axis=1), length)
    assert AXIS_REACH * axis / 1.5 <= length <= AXIS_REACH * axis
    assert tips.column("Points3D:labels").to_pylist()[0] == list(AXIS_NAMES)
    rows, _ = rrd_contents(path)
    for m in ALL_METHODS:
        for part in ("estimate", "covariance"):
            assert rows.get(f"/prosov3d/target/{m}/{part}") == 60, (m, part)
        assert rows.get(f"/plots/prosov3d/nees_pos/{m}") == 60
    # The frame: orthonormal, right-handed, down-range along the line of sight, up above it.
    B = range_cross_up_basis(np.zeros(3), [[1e5, 2e4, 3e4]])[0]
    np.testing.assert_allclose(B @ B.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(B) == pytest.approx(1.0)
    np.testing.assert_allclose(B[0], np.array([1e5, 2e4, 3e4]) / np.linalg.norm([1e5, 2e4, 3e4]))
    assert B[1, 2] == 0.0 and B[2, 2] > 0.0
