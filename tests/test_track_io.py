"""``radarviz simulate`` and ``radarviz track``: files in, files out (``viz_app.io.plots``).

* Round trip: the Prosov run written by ``simulate`` and tracked from the file equals the
  in-memory tracks (``core.experiments.prosov.track_history`` on the same measurements) to 1e-9
  relative; the only differences are the azimuth's degrees → radians round trip (≈ 1 ulp).
* Bad files: exit 2, one line on standard error naming file, line and column, no output file
  (and no temporary file left beside it; an existing output is left untouched).
* The ``ekf`` rows equal filterpy's ``ExtendedKalmanFilter`` run directly on the same file (two
  radars, one away from the origin, irregular time steps including dt = 0, process noise).
"""

from __future__ import annotations

import csv
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import ExtendedKalmanFilter

from radarviz.core.experiments.prosov import (
    ALL_METHODS,
    TrackingConfig,
    displayed_measurements,
    track_history,
)
from radarviz.core.filters.methods import METHODS_3D
from radarviz.core.filters.predict import transition_matrix
from radarviz.core.tracking.stream import (
    StreamOptions,
    StreamTracker,
)
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io.plots import (
    READ_BLOCK,
    TRACK_COLUMNS,
    covariance_column,
    parse_radars,
    simulated_plots,
    state_from_row,
    track_lines,
)

RTOL = 1e-9

GOOD_RADARS = """\
[radars.a]
x_m = 0.0
y_m = 0.0
z_m = 0.0
sigma_r_m = 250.0
sigma_beta_deg = 1.0

[radars.b]
x_m = 60000.0
y_m = -20000.0
z_m = 15.0
sigma_r_m = 100.0
sigma_beta_deg = 0.5
"""

HEADER = "time_s,radar,range_m,azimuth_deg\n"
GOOD_ROWS = [
    "0,a,150000,0.5\n",
    "10,b,94000,10.0\n",
    "20,a,152000,0.4\n",
    "30,b,95000,10.2\n",
]


def read_tracks(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert rows and tuple(rows[0]) == TRACK_COLUMNS
    return rows


def state_of(row: dict[str, str]) -> tuple[np.ndarray, np.ndarray]:
    """The 2D (x, ẋ, y, ẏ) mean and covariance of one output row."""
    x = np.array([float(row[k]) for k in ("x_m", "vx_mps", "y_m", "vy_mps")])
    names = ("x", "vx", "y", "vy")
    P = np.empty((4, 4))
    for i, a in enumerate(names):
        for j, b in enumerate(names):
            key = (
                covariance_column(a, b)
                if covariance_column(a, b) in row
                else covariance_column(b, a)
            )
            P[i, j] = float(row[key])
    for k in (
        "z_m",
        "vz_mps",
        "p_xz_m2",
        "p_yz_m2",
        "p_zz_m2",
        "p_vzvz_m2ps2",
        "p_zvx_m2ps",
        "p_xvz_m2ps",
    ):
        assert float(row[k]) == 0.0
    return x, P


def close(a: np.ndarray, b: np.ndarray) -> None:
    np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * np.abs(b).max())


# --------------------------------------------------------------------------------------------
# Round trip
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("sigma_beta_deg", [1.0, 2.0])
def test_simulate_then_track_equals_in_memory(tmp_path: Path, sigma_beta_deg: float) -> None:
    meas, radars, out = tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "t.csv"
    assert (
        main(
            [
                "simulate",
                "--preset",
                "prosov",
                "--out",
                str(meas),
                "--radars-out",
                str(radars),
                "--seed",
                "3",
                "--sigma-beta-deg",
                str(sigma_beta_deg),
            ]
        )
        == 0
    )
    # The reproduction's Q = 0 filter (track's own default on a user's file is the IMM).
    track = ["track", "--input", str(meas), "--radars", str(radars), "--out", str(out)]
    assert main([*track, "--model", "cv"]) == 0
    rows = read_tracks(out)
    cfg = TrackingConfig(sigma_beta_deg=sigma_beta_deg, seed=3)
    r_hat, b_hat = displayed_measurements(cfg)
    times = np.arange(cfg.target.steps) * cfg.target.period_s
    n = len(times)
    assert len(rows) == n * len(ALL_METHODS)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.csv", "r.toml", "t.csv"]
    for k, method in enumerate(ALL_METHODS):
        xs, ps = track_history(method, r_hat, b_hat, cfg)
        mine = rows[k :: len(ALL_METHODS)]
        for i, row in enumerate(mine):
            assert row["method"] == method
            assert float(row["time_s"]) == times[i]
            x, P = state_of(row)
            close(x, xs[0, i])
            close(P, ps[0, i])


def test_method_subset_and_default_out(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "m.csv").write_text(HEADER + "".join(GOOD_ROWS))
    (tmp_path / "r.toml").write_text(GOOD_RADARS)
    monkeypatch.chdir(tmp_path)
    assert main(["track", "--input", "m.csv", "--radars", "r.toml", "--method", "ducm", "ukf"]) == 0
    rows = read_tracks(tmp_path / "tracks.csv")
    assert [r["method"] for r in rows] == ["ducm", "ukf"] * len(GOOD_ROWS)


# --------------------------------------------------------------------------------------------
# Bad files
# --------------------------------------------------------------------------------------------

BAD_CASES = {
    "missing column": (
        "time_s,radar,azimuth_deg\n0,a,1\n",
        GOOD_RADARS,
        "m.csv line 1, column range_m: missing",
    ),
    "unknown column": (
        "time_s,radar,range_m,azimuth_deg,snr\n0,a,1,1,3\n",
        GOOD_RADARS,
        "m.csv line 1, column snr: unknown column",
    ),
    "non-numeric": (
        HEADER + GOOD_ROWS[0] + "10,a,abc,1\n",
        GOOD_RADARS,
        "m.csv line 3, column range_m: must be a finite number in (0, 1e+08] (got 'abc')",
    ),
    "nan": (
        HEADER + GOOD_ROWS[0] + "10,a,150000,nan\n",
        GOOD_RADARS,
        "m.csv line 3, column azimuth_deg: must be a finite number",
    ),
    "unsorted": (
        HEADER + GOOD_ROWS[0] + GOOD_ROWS[2] + GOOD_ROWS[1],
        GOOD_RADARS,
        "m.csv line 4, column time_s: must not be before",
    ),
    "unknown radar": (
        HEADER + GOOD_ROWS[0] + "10,zz,150000,1\n",
        GOOD_RADARS,
        "m.csv line 3, column radar: unknown radar",
    ),
    "range zero": (HEADER + "0,a,0,1\n", GOOD_RADARS, "m.csv line 2, column range_m"),
    "range negative": (HEADER + "0,a,-5,1\n", GOOD_RADARS, "m.csv line 2, column range_m"),
    "azimuth": (HEADER + "0,a,1000,361\n", GOOD_RADARS, "m.csv line 2, column azimuth_deg"),
    "elevation": (
        "time_s,radar,range_m,azimuth_deg,elevation_deg\n0,a,1000,1,x\n",
        GOOD_RADARS,
        "m.csv line 2, column elevation_deg",
    ),
    "short row": (HEADER + "0,a,1000\n", GOOD_RADARS, "m.csv line 2: expected 4 fields"),
    "no plots": (HEADER, GOOD_RADARS, "m.csv: no plots"),
    "negative sigma": (
        HEADER + GOOD_ROWS[0],
        GOOD_RADARS.replace("100.0", "-1.0"),
        "r.toml, radar 'b', key sigma_r_m: must be a finite number in [2, 100000]",
    ),
    "missing radar key": (
        HEADER + GOOD_ROWS[0],
        GOOD_RADARS.replace("z_m = 15.0\n", ""),
        "r.toml, radar 'b', key z_m: missing",
    ),
    "bad toml": (HEADER + GOOD_ROWS[0], "[radars.a\n", "r.toml: not valid TOML"),
    # Many good rows, then a bad one: the tracks already written must be discarded.
    "late error": (
        HEADER
        + "".join(f"{t},a,{150000 + 2000 * t},0.1\n" for t in range(300))
        + "5000,a,150000,1e400\n",
        GOOD_RADARS,
        "m.csv line 302, column azimuth_deg",
    ),
}


@pytest.mark.parametrize("case", list(BAD_CASES))
@pytest.mark.parametrize("existing", [False, True])
def test_bad_file_exit_2_one_line_no_output(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    case: str,
    existing: bool,
) -> None:
    meas_text, radars_text, expected = BAD_CASES[case]
    (tmp_path / "m.csv").write_text(meas_text)
    (tmp_path / "r.toml").write_text(radars_text)
    if existing:
        (tmp_path / "t.csv").write_text("old\n")
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    status = main(["track", "--input", "m.csv", "--radars", "r.toml", "--out", "t.csv"])
    out, err = capsys.readouterr()
    assert status == 2
    assert out == ""
    assert err.count("\n") == 1 and err.startswith("radarviz: error: "), err
    assert expected in err, err
    expected_files = ["m.csv", "r.toml"] + (["t.csv"] if existing else [])
    assert sorted(p.name for p in tmp_path.iterdir()) == expected_files
    if existing:
        assert (tmp_path / "t.csv").read_text() == "old\n"


def test_unknown_method_and_preset(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "m.csv").write_text(HEADER + "".join(GOOD_ROWS))
    (tmp_path / "r.toml").write_text(GOOD_RADARS)
    out = tmp_path / "t.csv"
    assert (
        main(
            [
                "track",
                "--input",
                str(tmp_path / "m.csv"),
                "--radars",
                str(tmp_path / "r.toml"),
                "--method",
                "kf",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert (
        main(
            [
                "simulate",
                "--preset",
                "nope",
                "--out",
                str(tmp_path / "x.csv"),
                "--radars-out",
                str(tmp_path / "x.toml"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and "--method" in err[0] and "--preset" in err[1]
    assert not out.exists() and not (tmp_path / "x.csv").exists()


# --------------------------------------------------------------------------------------------
# EKF against filterpy, on the file
# --------------------------------------------------------------------------------------------


def write_two_radar_file(path: Path) -> None:
    """A target seen alternately by radars a (origin) and b (away), irregular times."""
    rng = np.random.default_rng(5)
    sites = {"a": (0.0, 0.0, 250.0, 1.0), "b": (60000.0, -20000.0, 100.0, 0.5)}
    times = np.concatenate([[0.0], np.cumsum(rng.uniform(0.5, 12.0, 59))])
    times[10] = times[9]  # two plots at the same time: dt = 0
    lines = [HEADER]
    for k, t in enumerate(times.tolist()):
        name = "ab"[k % 2]
        sx, sy, sr, sigma_beta_deg = sites[name]
        px, py = 140e3 + 150.0 * t, 10e3 - 80.0 * t
        r = math.hypot(px - sx, py - sy) + sr * rng.standard_normal()
        az = math.degrees(math.atan2(py - sy, px - sx)) + sigma_beta_deg * rng.standard_normal()
        lines.append(f"{t!r},{name},{r!r},{az!r}\n")
    path.write_text("".join(lines))


def test_ekf_matches_filterpy_on_the_file(tmp_path: Path) -> None:
    meas, radars, out = tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "t.csv"
    write_two_radar_file(meas)
    radars.write_text(GOOD_RADARS)
    sigma_a = 0.3
    assert (
        main(
            [
                "track",
                "--input",
                str(meas),
                "--radars",
                str(radars),
                "--out",
                str(out),
                "--method",
                "ekf",
                "--sigma-a",
                str(sigma_a),
            ]
        )
        == 0
    )
    rows = read_tracks(out)
    sites = {"a": (0.0, 0.0, 250.0, 1.0), "b": (60000.0, -20000.0, 100.0, 0.5)}
    with open(meas, newline="") as fh:
        plots = list(csv.DictReader(fh))
    assert len(rows) == len(plots)

    f = ExtendedKalmanFilter(dim_x=4, dim_z=2)
    last_t = None
    for row, plot in zip(rows, plots, strict=True):
        t = float(plot["time_s"])
        sx, sy, sr, sigma_beta_deg = sites[plot["radar"]]
        sigma_beta_rad = math.radians(sigma_beta_deg)
        r, b = float(plot["range_m"]), math.radians(float(plot["azimuth_deg"]))
        z = np.array([r, b])
        if last_t is None:
            # The first-plot start: naive point, linearized covariance, velocity 0 ± 1000 m/s.
            c, s = math.cos(b), math.sin(b)
            J = np.array([[c, -r * s], [s, r * c]])
            Rxy = J @ np.diag([sr**2, sigma_beta_rad**2]) @ J.T
            f.x = np.array([sx + r * c, 0.0, sy + r * s, 0.0])
            P = np.zeros((4, 4))
            P[np.ix_([0, 2], [0, 2])] = Rxy
            P[1, 1] = P[3, 3] = 1000.0**2
            f.P = P
        else:
            dt = t - last_t
            if dt > 0:
                f.F = transition_matrix(dt)
                f.Q = Q_discrete_white_noise(2, dt=dt, var=sigma_a**2, block_size=2)
                f.predict()

            def hx(x: np.ndarray, sx: float = sx, sy: float = sy) -> np.ndarray:
                return np.array(
                    [math.hypot(x[0] - sx, x[2] - sy), math.atan2(x[2] - sy, x[0] - sx)]
                )

            def jac(x: np.ndarray, sx: float = sx, sy: float = sy) -> np.ndarray:
                dx, dy = x[0] - sx, x[2] - sy
                r2 = dx * dx + dy * dy
                rr = math.sqrt(r2)
                return np.array([[dx / rr, 0.0, dy / rr, 0.0], [-dy / r2, 0.0, dx / r2, 0.0]])

            def residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
                y = np.asarray(a, dtype=float) - b
                y[1] = math.remainder(y[1], 2.0 * math.pi)
                return y

            f.update(z, jac, hx, R=np.diag([sr**2, sigma_beta_rad**2]), residual=residual)
        last_t = t
        x, P = state_of(row)
        close(x, f.x)
        close(P, f.P)


# --------------------------------------------------------------------------------------------
# 3D + Doppler files, finite-memory start, streaming, recording
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("init", ["first-plot", "finite-memory"])
def test_fusion_file_round_trip_equals_in_memory(tmp_path: Path, init: str) -> None:
    """``simulate --preset fusion`` (3 radars, 3D, Doppler, staggered scans) tracked from the
    file equals the same plots tracked in memory, plot by plot (``StreamTracker.add``: blocks
    of one plot, so this also checks the file's 1 024-plot blocks against single plots)."""
    meas, radars, out = tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "t.csv"
    assert (
        main(
            [
                "simulate",
                "--preset",
                "fusion",
                "--scans",
                "30",
                "--seed",
                "4",
                "--out",
                str(meas),
                "--radars-out",
                str(radars),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "track",
                "--input",
                str(meas),
                "--radars",
                str(radars),
                "--out",
                str(out),
                "--sigma-a",
                "1.5",
                "--init",
                init,
            ]
        )
        == 0
    )
    rows = read_tracks(out)
    plots, _ = simulated_plots("fusion", seed=4, steps=30)
    tracker = StreamTracker(METHODS_3D, True, StreamOptions(sigma_a_mps2=1.5, init=init))
    expected = [(p.time_s, r) for p in plots for r in tracker.add(p)]
    assert len(plots) == 90
    # finite-memory: R1's plots at 0, 10, 20 s make the window; the 6 plots up to the start
    # (R2's and R3's included) give no rows.
    assert len(rows) == len(expected) == (90 if init == "first-plot" else 84) * len(METHODS_3D)
    for row, (t, (method, x, P)) in zip(rows, expected, strict=True):
        assert row["method"] == method and float(row["time_s"]) == t
        got_x, got_P = state_from_row(row)
        close(got_x, x)
        close(got_P, P)
        assert np.all(np.linalg.eigvalsh(got_P) > 0)


class _CountingLines:
    """Measurement lines made on demand; records how many tracked rows existed per line."""

    def __init__(self, n: int, written: list[int]):
        self.n, self.written, self.lag = n, written, 0

    def __iter__(self):
        yield HEADER
        for k in range(self.n):
            # Rows written so far must trail the lines read by at most one read block.
            self.lag = max(self.lag, k - self.written[0])
            t = 10.0 * k
            yield f"{t!r},a,{150000 + 200 * t!r},{0.5 + 0.001 * k!r}\n"


def test_tracking_streams_with_a_bounded_buffer() -> None:
    """The reader is never more than ``READ_BLOCK`` plots ahead of the tracks written."""
    written = [0]
    n = 3 * READ_BLOCK + 17
    lines = _CountingLines(n, written)

    def on_rows(plot: object, rows: list) -> None:
        written[0] += 1

    radars = parse_radars(GOOD_RADARS, "r.toml")
    plots, three_d, methods, targets = track_lines(
        lines, "m.csv", radars, ("ucm",), StreamOptions(), on_rows
    )
    assert (plots, three_d, methods, targets) == (n, False, ("ucm",), ())
    assert written[0] == n
    assert READ_BLOCK - 1 <= lines.lag <= READ_BLOCK


def test_rrd_recording_of_a_tracked_file(tmp_path: Path, rrd_contents) -> None:
    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    out, rrd = tmp_path / "t.csv", tmp_path / "t.rrd"
    assert (
        main(
            [
                "simulate",
                "--preset",
                "fusion",
                "--scans",
                "12",
                "--out",
                str(meas),
                "--radars-out",
                str(radars),
            ]
        )
        == 0
    )
    rrd.write_text("old")  # replaced, like the track CSV
    assert (
        main(
            [
                "track",
                "--input",
                str(meas),
                "--radars",
                str(radars),
                "--out",
                str(out),
                "--rrd",
                str(rrd),
                "--method",
                "ekf",
                "ucm",
            ]
        )
        == 0
    )
    rows, cols = rrd_contents(rrd)
    tracks = read_tracks(out)
    for m in ("ekf", "ucm"):
        for part in ("position", "covariance", "velocity"):
            assert rows[f"/world/tracks/{m}/{part}"] == 36
        assert rows[f"/plots/sigma_pos_m/{m}"] == 36
        assert f"/world/tracks/{m}/path/000000" in rows
        got = cols[f"/world/tracks/{m}/position"]
        assert got["plot"] == list(range(1, 37))
        pos = np.array([v[0] for v in got["Points3D:positions"]])
        want = np.array(
            [[float(r[k]) for k in ("x_m", "y_m", "z_m")] for r in tracks if r["method"] == m]
        )
        np.testing.assert_allclose(pos, want, rtol=1e-6)  # the recording stores float32
    for r in ("R1", "R2", "R3"):
        assert rows[f"/world/measurements/{r}"] == 12
        assert f"/world/radars/{r}" in rows
    exe = Path(sys.executable).with_name("rerun")
    proc = subprocess.run([str(exe), "rrd", "verify", str(rrd)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


MIXED_RADARS = GOOD_RADARS.replace(
    "sigma_beta_deg = 1.0\n", "sigma_beta_deg = 1.0\nsigma_vr_mps = 2.0\n"
)


def test_empty_radial_velocity_cells_skip_the_doppler_update(tmp_path: Path) -> None:
    """Radar a has Doppler, b has none (empty cells): a's rows change with --doppler, b's
    first update does not see a Doppler row."""
    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    lines = [
        "time_s,radar,range_m,azimuth_deg,radial_velocity_mps\n",
        "0,a,150000,0.5,190\n",
        "10,b,94000,10.0,\n",
        "20,a,152000,0.4,201\n",
    ]
    meas.write_text("".join(lines))
    radars.write_text(MIXED_RADARS)
    results = {}
    for mode in ("use", "ignore"):
        out = tmp_path / f"{mode}.csv"
        assert (
            main(
                [
                    "track",
                    "--input",
                    str(meas),
                    "--radars",
                    str(radars),
                    "--out",
                    str(out),
                    "--method",
                    "naive",
                    "--doppler",
                    mode,
                ]
            )
            == 0
        )
        results[mode] = [state_from_row(r)[0] for r in read_tracks(out)]
    use, ignore = results["use"], results["ignore"]
    # Plot 1 (a, Doppler 190 m/s along 0.5°): the velocity moves from 0 to ≈ 190 m/s.
    assert np.allclose(ignore[0][[1, 3]], 0.0)
    assert abs(np.hypot(use[0][1], use[0][3]) - 190.0) < 1.0
    assert not np.allclose(use[2], ignore[2])


NEW_BAD_CASES = {
    "doppler without sigma": (
        "time_s,radar,range_m,azimuth_deg,radial_velocity_mps\n0,a,150000,0.5,10\n",
        GOOD_RADARS,
        "m.csv line 2, column radial_velocity_mps: radar 'a' has no sigma_vr_mps",
    ),
    "elevation without sigma": (
        "time_s,radar,range_m,azimuth_deg,elevation_deg\n0,a,150000,0.5,3\n",
        GOOD_RADARS,
        "m.csv line 2, column elevation_deg: radar 'a' has no sigma_elevation_deg",
    ),
    "empty elevation": (
        "time_s,radar,range_m,azimuth_deg,elevation_deg\n0,a,150000,0.5,\n",
        GOOD_RADARS.replace("[radars.b]", "sigma_elevation_deg = 1.0\n\n[radars.b]"),
        "m.csv line 2, column elevation_deg: must be a finite number",
    ),
    "bad doppler": (
        "time_s,radar,range_m,azimuth_deg,radial_velocity_mps\n0,a,150000,0.5,fast\n",
        MIXED_RADARS,
        "m.csv line 2, column radial_velocity_mps: must be a finite number in "
        "[−100000, 100000] or empty",
    ),
    "elevation sigma range": (
        HEADER + GOOD_ROWS[0],
        GOOD_RADARS.replace("[radars.b]", "sigma_elevation_deg = 45.0\n\n[radars.b]"),
        "r.toml, radar 'a', key sigma_elevation_deg: must be a finite number in [1e-06, 20]",
    ),
}


@pytest.mark.parametrize("case", list(NEW_BAD_CASES))
def test_bad_3d_doppler_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str
) -> None:
    meas_text, radars_text, expected = NEW_BAD_CASES[case]
    (tmp_path / "m.csv").write_text(meas_text)
    (tmp_path / "r.toml").write_text(radars_text)
    capsys.readouterr()
    status = main(
        [
            "track",
            "--input",
            str(tmp_path / "m.csv"),
            "--radars",
            str(tmp_path / "r.toml"),
            "--out",
            str(tmp_path / "t.csv"),
        ]
    )
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and expected in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.csv", "r.toml"]


@pytest.mark.parametrize(
    "args, name",
    [
        (["--init", "kalman"], "--init"),
        (["--init-k", "1"], "--init-k"),
        (["--doppler", "maybe"], "--doppler"),
        (["--sigma-v0", "0"], "--sigma-v0"),
    ],
)
def test_bad_track_options(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], name: str
) -> None:
    (tmp_path / "m.csv").write_text(HEADER + "".join(GOOD_ROWS))
    (tmp_path / "r.toml").write_text(GOOD_RADARS)
    capsys.readouterr()
    status = main(
        [
            "track",
            "--input",
            str(tmp_path / "m.csv"),
            "--radars",
            str(tmp_path / "r.toml"),
            "--out",
            str(tmp_path / "t.csv"),
            *args,
        ]
    )
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and name in err, err
    assert not (tmp_path / "t.csv").exists()


def test_finite_memory_start_skips_other_radars_until_it_starts(tmp_path: Path) -> None:
    """Radar a's first 3 plots make the start; b's plot in between gives no rows."""
    lines = [
        HEADER,
        "0,a,150000,0.5\n",
        "5,b,94000,10.0\n",
        "10,a,152000,0.5\n",
        "20,a,154000,0.5\n",
        "30,b,95000,10.2\n",
    ]
    (tmp_path / "m.csv").write_text("".join(lines))
    (tmp_path / "r.toml").write_text(GOOD_RADARS)
    out = tmp_path / "t.csv"
    assert (
        main(
            [
                "track",
                "--input",
                str(tmp_path / "m.csv"),
                "--radars",
                str(tmp_path / "r.toml"),
                "--out",
                str(out),
                "--init",
                "finite-memory",
                "--method",
                "naive",
            ]
        )
        == 0
    )
    rows = read_tracks(out)
    assert [float(r["time_s"]) for r in rows] == [20.0, 30.0]
    x, _ = state_from_row(rows[0])
    # Range-only fit of 150, 152, 154 km over T = 10 s: r̂ = 154 km, V̂r = 200 m/s at 0.5°.
    b = math.radians(0.5)
    np.testing.assert_allclose(
        x[[0, 2]], 154000.0 * np.array([math.cos(b), math.sin(b)]), rtol=1e-12
    )
    np.testing.assert_allclose(x[[1, 3]], 200.0 * np.array([math.cos(b), math.sin(b)]), rtol=1e-9)


def test_a_finite_memory_start_longer_than_the_file_is_an_error(tmp_path: Path, capsys) -> None:
    """``--init-k`` larger than the plots: one line naming the flag, exit 2, no tracks file
    (it used to write an empty one and exit 0)."""
    radars = tmp_path / "r.toml"
    radars.write_text(GOOD_RADARS)
    meas = tmp_path / "m.csv"
    lines = ["time_s,radar,range_m,azimuth_deg"]
    lines += [f"{10 * k},a,{100000.0 + 200 * k},10" for k in range(12)]
    meas.write_text("\n".join(lines) + "\n")
    out = tmp_path / "t.csv"
    argv = ["track", "--input", str(meas), "--radars", str(radars), "--out", str(out)]
    assert main([*argv, "--init", "finite-memory", "--init-k", "20"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--init-k" in err and "12 plot(s)" in err, err
    assert not out.exists()
    assert main([*argv, "--init", "finite-memory", "--init-k", "5"]) == 0
    assert out.exists()


def test_the_reader_bounds_lines_names_bad_bytes_and_waits_for_a_fifo(
    tmp_path: Path, capsys, monkeypatch
) -> None:
    """A line longer than ``MAX_LINE_BYTES`` is refused as it is read (memory stays bounded);
    bytes that are not UTF-8 are reported at their own line; a FIFO with no writer gives up
    after ``FIFO_WAIT_S`` with one line. Each exits 2 and writes nothing."""
    import os

    from radarviz.viz_app.io import plots

    radars = tmp_path / "r.toml"
    radars.write_text(GOOD_RADARS)
    out = tmp_path / "t.csv"
    good = ["time_s,radar,range_m,azimuth_deg"] + [f"{10 * k},a,1e5,10" for k in range(6)]
    cases = {
        "long.csv": (
            "\n".join(good[:3]) + "\n" + "9" * (plots.MAX_LINE_BYTES + 10) + "\n"
        ).encode(),
        "latin.csv": ("\n".join(good[:4]) + "\n").encode() + b"40,a,1e5,1\xe9\n",
    }
    expected = {"long.csv": "line 4: longer than", "latin.csv": "line 5: not UTF-8 text"}
    for name, data in cases.items():
        path = tmp_path / name
        path.write_bytes(data)
        argv = ["track", "--input", str(path), "--radars", str(radars), "--out", str(out)]
        assert main(argv) == 2, name
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and expected[name] in err, err
        assert not out.exists()
    fifo = tmp_path / "plots.fifo"
    os.mkfifo(fifo)
    monkeypatch.setattr(plots, "FIFO_WAIT_S", 0.3)
    assert main(["track", "--input", str(fifo), "--radars", str(radars), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "a FIFO with no writer after 0.3 s" in err and not out.exists(), err
