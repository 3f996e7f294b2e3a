"""``radarviz score``: each metric against a case worked by hand, a perfect and a swapped track
file, simulate → track → score through the command line, the experiment's own GOSPA, the
JSON document, and bad inputs (one line, exit status 2)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from radarviz.core.chi2 import chi2_quantile
from radarviz.core.experiments.association import AssociationConfig, scan_plots, track_run
from radarviz.core.tracking.scoring import ScoreOptions, TrackRows, Truth, score_tracks
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io.score_files import TrackFile, read_truth

TRUTH_HEADER = ["time_s", "target", "x_m", "y_m"]
TRACK_HEADER = ["time_s", "target", "method", "x_m", "y_m", "z_m", "p_xx_m2", "p_xy_m2", "p_yy_m2"]


def _write(path: Path, header: list[str], rows: list[list[object]]) -> Path:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


# --------------------------------------------------------------------------------------------
# A case worked by hand
# --------------------------------------------------------------------------------------------
#
# Truth: A still at (0, 0) and B still at (100, 0), at t = 0, 1, 2, 3. Tracks (rows at those
# times only, every position variance 4 m²), c = 10 m, p = 2 (c^p/2 = 50), Δt_max = 0.5 s:
#
#   t  T1          T2          T3        T4          pairs (distance)        L    M   F
#   0  (3, 0)      (100, 4)    -         -           A-T1 3, B-T2 4          25   0   0
#   1  (0, 6)      -           -         -           A-T1 6 (B missed)       36  50   0
#   2  (100, 0)    -           (0, 3)    -           B-T1 0, A-T3 3           9   0   0
#   3  (100, 0)    -           (0, 3)    (50, 50)    B-T1 0, A-T3 3 (T4)      9   0  50
#
# purity: T1 2 of 4 (A twice, B twice), T2 1 of 1, T3 2 of 2, T4 0 of 1: 5/8 overall.
# fragmentation: A T1 T1 T3 T3 (2 segments), B T2 - T1 T1 (2): 1 + 1 = 2.
# swaps: B goes from T2 to T1, reported since t = 0: 1; A goes to T3, new at t = 2: none.
# CLEAR MOT: at t = 2 neither last match is valid, so both re-match: 2 swaps; T4 is false.
# RMSE: √((9 + 16 + 36 + 0 + 9 + 0 + 9)/7); NEES: Σ d²/4 over 7 pairs.

HAND_TRACKS = [
    (0, "T1", 3, 0),
    (0, "T2", 100, 4),
    (1, "T1", 0, 6),
    (2, "T1", 100, 0),
    (2, "T3", 0, 3),
    (3, "T1", 100, 0),
    (3, "T3", 0, 3),
    (3, "T4", 50, 50),
]
HAND_OPTIONS = ScoreOptions(gospa_cutoff_m=10.0, gospa_order=2.0, score_max_gap_s=0.5)


def _hand_truth() -> Truth:
    times = np.repeat(np.arange(4.0), 2)
    targets = np.array(["A", "B"] * 4)
    pos = np.array([[0.0, 0.0], [100.0, 0.0]] * 4)
    return Truth(times, targets, pos)


def _hand_rows() -> TrackRows:
    t = np.array([r[0] for r in HAND_TRACKS], dtype=float)
    pos = np.array([[r[2], r[3], 0.0] for r in HAND_TRACKS], dtype=float)
    cov = np.tile(np.diag([4.0, 4.0, 0.0]), (len(t), 1, 1))
    return TrackRows(t, np.array([r[1] for r in HAND_TRACKS]), pos, None, cov, None)


def test_hand_case_every_metric() -> None:
    s = score_tracks(_hand_truth(), _hand_rows(), HAND_OPTIONS)
    np.testing.assert_allclose(
        s.gospa_per_time[:, 1:], [[25, 0, 0], [36, 50, 0], [9, 0, 0], [9, 0, 50]]
    )
    np.testing.assert_allclose(s.gospa_per_time[:, 0], np.sqrt([25, 86, 9, 59]))
    assert s.gospa.value == pytest.approx(np.sqrt([25, 86, 9, 59]).mean())
    assert (s.localisation.value, s.missed.value, s.false.value) == pytest.approx(
        (79 / 4, 50 / 4, 50 / 4)
    )
    assert s.purity.value == pytest.approx(5 / 8)
    assert {k: v.purity for k, v in s.track_purity.items()} == {
        "T1": 0.5,
        "T2": 1.0,
        "T3": 1.0,
        "T4": 0.0,
    }
    assert s.track_purity["T4"].target is None
    assert (s.fragmentation, s.target_segments) == (2, {"A": 2, "B": 2})
    assert (s.swaps, s.target_swaps) == (1, {"A": 0, "B": 1})
    assert (s.clear_mot_swaps, s.clear_mot_false_tracks) == (2, 1)
    assert (s.pairs, s.tracks, s.dims) == (7, 4, 2)
    assert s.position_rmse.value == pytest.approx(math.sqrt(79 / 7))
    assert s.velocity_rmse is None
    assert s.nees is not None
    assert s.nees.mean == pytest.approx(79 / 4 / 7)
    assert (s.nees.pairs, s.nees.dof, s.nees.excluded) == (7, 2, 0)
    assert s.nees.lo == pytest.approx(chi2_quantile(0.025, 14) / 7)
    assert s.nees.hi == pytest.approx(chi2_quantile(0.975, 14) / 7)
    assert s.nees.verdict == "within"
    # Four truth times: two blocks of two; the bands hold their figure.
    for band in (s.gospa, s.position_rmse):
        assert band.lo is not None and band.hi is not None
        assert 0.0 <= band.lo <= band.value <= band.hi


def test_hand_case_gap_and_tentative_rows() -> None:
    """A longer gap predicts T2 over t = 1 (B no longer missed); a tentative row is left out
    unless every track is asked for."""
    s = score_tracks(_hand_truth(), _hand_rows(), ScoreOptions(10.0, 2.0, 1.0))
    assert s.gospa_per_time[1, 2] == 0.0 and s.gospa_per_time[1, 1] == 36 + 16
    rows = _hand_rows()._replace(confirmed=np.array([r[1] != "T4" for r in HAND_TRACKS]))
    s = score_tracks(_hand_truth(), rows, HAND_OPTIONS)
    assert s.gospa_per_time[3, 3] == 0.0 and "T4" not in s.track_purity
    s = score_tracks(_hand_truth(), rows, ScoreOptions(10.0, 2.0, 0.5, confirmed_only=False))
    assert s.gospa_per_time[3, 3] == 50.0


def test_hand_case_through_the_command_line(tmp_path: Path, capsys) -> None:
    truth = _write(
        tmp_path / "truth.csv",
        TRUTH_HEADER,
        [[t, n, x, 0] for t in range(4) for n, x in (("A", 0), ("B", 100))],
    )
    tracks = _write(
        tmp_path / "tracks.csv",
        TRACK_HEADER,
        [[t, j, "mine", x, y, 0, 4, 0, 4] for t, j, x, y in HAND_TRACKS],
    )
    args = ["score", str(tracks), "--truth", str(truth), "--gospa-cutoff-m", "10"]
    assert main([*args, "--max-gap-s", "0.5", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    m = doc["methods"]["mine"]
    assert m["purity"]["value"] == pytest.approx(5 / 8)
    assert (m["swaps"]["total"], m["swaps"]["clear_mot"], m["fragmentation"]["total"]) == (1, 2, 2)
    assert m["gospa"]["missed_m_p"]["value"] == pytest.approx(12.5)
    assert m["position_rmse_m"]["value"] == pytest.approx(math.sqrt(79 / 7))
    assert m["velocity_rmse_mps"] == {
        "value": None,
        "band": None,
        "reason": "the truth or the tracks have no velocity",
    }
    assert m["nees_position"]["mean"] == pytest.approx(79 / 28)


# --------------------------------------------------------------------------------------------
# Perfect and swapped track files of two parallel targets
# --------------------------------------------------------------------------------------------

TIMES = np.arange(20) * 2.0


def _parallel_truth(tmp_path: Path) -> Path:
    """Two targets 1 km apart flying +x at 100 m/s, with velocities."""
    rows = [
        [t, name, 100.0 * t, y, 100.0, 0.0]
        for t in TIMES
        for name, y in (("a", 0.0), ("b", 1000.0))
    ]
    return _write(tmp_path / "truth.csv", [*TRUTH_HEADER, "vx_mps", "vy_mps"], rows)


def _parallel_tracks(path: Path, label: dict[tuple[str, int], str]) -> Path:
    """Tracks exactly on the truth; ``label[(target, k)]`` names the track at time k."""
    header = [*TRACK_HEADER, "vx_mps", "vy_mps"]
    rows = [
        [t, label[(name, k)], "perfect", 100.0 * t, y, 0, 25, 0, 25, 100.0, 0.0]
        for k, t in enumerate(TIMES)
        for name, y in (("a", 0.0), ("b", 1000.0))
        if (name, k) in label
    ]
    return _write(path, header, rows)


def _score_json(capsys, tracks: Path, truth: Path, *extra: str) -> dict:
    assert main(["score", str(tracks), "--truth", str(truth), "--json", *extra]) == 0
    return json.loads(capsys.readouterr().out)["methods"]["perfect"]


def test_perfect_track_file_scores_zero(tmp_path: Path, capsys) -> None:
    truth = _parallel_truth(tmp_path)
    label = {(n, k): "T" + n for n in "ab" for k in range(len(TIMES))}
    m = _score_json(capsys, _parallel_tracks(tmp_path / "t.csv", label), truth)
    assert m["gospa"]["mean_m"] == {"value": 0.0, "band": [0.0, 0.0]}
    assert m["purity"]["value"] == 1.0
    assert (m["swaps"]["total"], m["fragmentation"]["total"], m["pairs"]) == (0, 0, 40)
    assert m["position_rmse_m"]["value"] == 0.0 and m["velocity_rmse_mps"]["value"] == 0.0
    assert m["nees_position"]["mean"] == 0.0 and m["nees_position"]["verdict"] == "below"


def test_a_track_taking_over_another_target_is_one_swap(tmp_path: Path, capsys) -> None:
    """From time 10 on, b's track ends and a's track follows b; a gets a new track."""
    truth = _parallel_truth(tmp_path)
    label = {}
    for k in range(len(TIMES)):
        label[("a", k)] = "Ta" if k < 10 else "Tc"
        label[("b", k)] = "Tb" if k < 10 else "Ta"
    m = _score_json(capsys, _parallel_tracks(tmp_path / "t.csv", label), truth, "--max-gap-s", "0")
    assert m["swaps"]["total"] == 1 and m["swaps"]["per_target"] == {"a": 0, "b": 1}
    assert m["fragmentation"] == {"total": 2, "segments": {"a": 2, "b": 2}}
    assert m["purity"]["tracks"]["Ta"] == {"purity": 0.5, "times": 20, "target": "a"}
    assert m["gospa"]["mean_m"]["value"] == 0.0


def test_two_tracks_exchanging_their_targets_are_two_swaps(tmp_path: Path, capsys) -> None:
    truth = _parallel_truth(tmp_path)
    label = {}
    for k in range(len(TIMES)):
        label[("a", k)] = "Ta" if k < 10 else "Tb"
        label[("b", k)] = "Tb" if k < 10 else "Ta"
    tracks = _parallel_tracks(tmp_path / "t.csv", label)
    m = _score_json(capsys, tracks, truth)
    # The optimal assignment follows the positions: two swaps. Within the default cut-off
    # (2 km > 1 km apart) the CLEAR MOT matching keeps each target's old track, a valid match.
    assert (m["swaps"]["total"], m["swaps"]["clear_mot"]) == (2, 0)
    m = _score_json(capsys, tracks, truth, "--gospa-cutoff-m", "500")
    assert (m["swaps"]["total"], m["swaps"]["clear_mot"]) == (2, 2)
    assert m["purity"]["value"] == 0.5


def test_parquet_inputs_by_magic(tmp_path: Path, capsys) -> None:
    """Parquet truth and tracks are read by content, whatever their names."""
    truth_csv = _parallel_truth(tmp_path)
    label = {(n, k): "T" + n for n in "ab" for k in range(len(TIMES))}
    tracks_csv = _parallel_tracks(tmp_path / "t.csv", label)
    want = _score_json(capsys, tracks_csv, truth_csv)
    for src, dst in ((truth_csv, "truth.dat"), (tracks_csv, "tracks.bin")):
        with src.open(newline="") as fh:
            rows = list(csv.DictReader(fh))
        cols = {
            k: [r[k] if k in ("target", "method") else float(r[k]) for r in rows] for k in rows[0]
        }
        pq.write_table(pa.table(cols), tmp_path / dst)
    got = _score_json(capsys, tmp_path / "tracks.bin", tmp_path / "truth.dat")
    assert got == want


# --------------------------------------------------------------------------------------------
# simulate → track → score, and the association experiment's own GOSPA
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def crossing(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``simulate --preset crossing`` with its truth, tracked by ``track --associate gnn``
    with the experiment's filter (cv, σa = 1 m/s², σv0 = 300 m/s)."""
    d = tmp_path_factory.mktemp("crossing")
    files = {k: d / n for k, n in (("meas", "m.csv"), ("radars", "r.toml"), ("truth", "t.csv"))}
    files["tracks"] = d / "tracks.parquet"
    sim = ["simulate", "--preset", "crossing", "--out", str(files["meas"])]
    sim += ["--radars-out", str(files["radars"]), "--truth-out", str(files["truth"])]
    assert main(sim) == 0
    track = ["track", "--input", str(files["meas"]), "--radars", str(files["radars"])]
    track += ["--associate", "gnn", "--model", "cv", "--sigma-a", "1", "--sigma-v0", "300"]
    assert main([*track, "--method", "ucm", "ekf", "--out", str(files["tracks"])]) == 0
    return files


def test_simulate_track_score_end_to_end(crossing: dict[str, Path], tmp_path: Path, capsys):
    capsys.readouterr()
    out = tmp_path / "score.json"
    args = ["score", str(crossing["tracks"]), "--truth", str(crossing["truth"])]
    assert main([*args, "--json", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    doc = json.loads(text)
    assert json.loads(out.read_text()) == doc
    assert set(doc) == {
        "tracks_file",
        "truth_file",
        "track_file_columns",
        "parameters",
        "truth",
        "methods",
    }
    assert doc["track_file_columns"] == {
        "rows": pq.ParquetFile(crossing["tracks"]).metadata.num_rows,
        "status": True,
        "velocity": True,
        "covariance": True,
    }
    assert set(doc["parameters"]) == {
        "gospa_cutoff_m",
        "gospa_order",
        "gospa_alpha",
        "score_max_gap_s",
        "confirmed_only",
        "band_level",
    }
    assert doc["truth"] == {"rows": 80, "times": 40, "targets": 2}
    assert list(doc["methods"]) == ["ucm", "ekf"]
    for m in doc["methods"].values():
        assert set(m) == {
            "dims",
            "tracks",
            "pairs",
            "gospa",
            "purity",
            "fragmentation",
            "swaps",
            "false_tracks_clear_mot",
            "position_rmse_m",
            "velocity_rmse_mps",
            "nees_position",
        }
        assert set(m["gospa"]) == {"mean_m", "localisation_m_p", "missed_m_p", "false_m_p"}
        lo, hi = m["gospa"]["mean_m"]["band"]
        assert lo <= m["gospa"]["mean_m"]["value"] <= hi
        assert m["purity"]["value"] > 0.9
        assert set(m["nees_position"]) >= {"mean", "band", "pairs", "dof", "verdict"}
        # σr = 50 m, σβ = 0.3° at 40-65 km: the position error is some 100-300 m.
        assert 50.0 < m["position_rmse_m"]["value"] < 400.0
    for bad in ("NaN", "Infinity"):
        assert bad not in text
    # The table: one block per method, no NaN, --out also named.
    assert main([*args, "--method", "ucm", "--out", str(out)]) == 0
    table = capsys.readouterr().out
    assert "ucm (2D)" in table and "ekf" not in table and "nan" not in table.lower()
    assert f"scores written to {out}" in table


def test_score_agrees_with_the_association_experiment(crossing: dict[str, Path]) -> None:
    """``simulate --preset crossing`` writes run 0 of the experiment; its GOSPA per scan
    (confirmed tracks, a missed track predicted) is the score's with Δt_max = 10 s, two
    scans, how long the association keeps a track it no longer sees (deleted at the third
    miss). The plots' angles went through degrees in the file: the difference is rounding."""
    cfg = AssociationConfig(methods=("ucm",))
    scans = scan_plots(
        cfg.scene, np.random.default_rng(np.random.SeedSequence(cfg.seed).spawn(1)[0])
    )
    want, counter = track_run(cfg, "ucm", scans)
    rows = TrackFile(str(crossing["tracks"])).rows["ucm"]
    s = score_tracks(read_truth(str(crossing["truth"])), rows, ScoreOptions())
    np.testing.assert_allclose(s.gospa_per_time, want, rtol=1e-9, atol=1e-6)
    assert (s.clear_mot_swaps, s.clear_mot_false_tracks) == (counter.swaps, counter.false_tracks)


# --------------------------------------------------------------------------------------------
# The document's undefined figures, and bad inputs
# --------------------------------------------------------------------------------------------


def test_undefined_figures_are_null_with_a_reason(tmp_path: Path, capsys) -> None:
    """Three truth times (no band), no velocity, no covariance: null and a reason, never NaN."""
    truth = _write(tmp_path / "truth.csv", TRUTH_HEADER, [[t, "a", 0, 0] for t in range(3)])
    tracks = _write(
        tmp_path / "tracks.csv",
        ["time_s", "method", "x_m", "y_m"],
        [[0, "m", 1, 0], [1, "m", 2, 0]],
    )
    assert main(["score", str(tracks), "--truth", str(truth), "--json"]) == 0
    text = capsys.readouterr().out
    m = json.loads(text)["methods"]["m"]
    assert m["gospa"]["mean_m"]["band"] is None
    assert "a band needs 4" in m["gospa"]["mean_m"]["reason"]
    assert m["nees_position"] == {
        "mean": None,
        "band": None,
        "reason": "the track file has no position covariance",
    }
    assert m["velocity_rmse_mps"]["value"] is None
    assert "NaN" not in text
    # Without velocity columns a track is held still over a gap: 2 m off at t = 2.
    assert m["pairs"] == 3
    assert main(["score", str(tracks), "--truth", str(truth)]) == 0
    table = capsys.readouterr().out
    assert "n/a (the track file has no position covariance)" in table


@pytest.mark.parametrize(
    ("truth_rows", "track_rows", "extra", "needle"),
    [
        (
            [["time_s", "target", "x_m"], [0, "a", 0]],
            None,
            [],
            "truth.csv line 1, column y_m: missing",
        ),
        (
            [TRUTH_HEADER, [0, "a", 0, 0], [1, "a", 0, "abc"]],
            None,
            [],
            "truth.csv row 2, column y_m: must be a finite number (got 'abc')",
        ),
        (
            [TRUTH_HEADER, [0, "a", 0, 0], [0, "a", 1, 1]],
            None,
            [],
            "truth.csv row 2, column target: a second row of target 'a' at time 0",
        ),
        ([[*TRUTH_HEADER, "speed"], [0, "a", 0, 0, 1]], None, [], "column speed: unknown column"),
        (
            [TRUTH_HEADER, [0, "", 0, 0]],
            None,
            [],
            "truth.csv row 1, column target: must not be empty",
        ),
        ([TRUTH_HEADER], None, [], "truth.csv: no rows after the header"),
        (
            None,
            [["time_s", "method", "x_m", "y_m", "status"], [0, "m", 0, 0, "lost"]],
            [],
            "tracks.csv row 1, column status: must be one of tentative, confirmed (got 'lost')",
        ),
        (
            None,
            [["time_s", "method", "x_m", "y_m"], [0, "m", 0, "inf"]],
            [],
            "tracks.csv row 1, column y_m: must be a finite number (got 'inf')",
        ),
        (
            None,
            [
                ["time_s", "method", "x_m", "y_m", "p_xx_m2", "p_xy_m2", "p_yy_m2"],
                [0, "m", 0, 0, -1, 0, 1],
            ],
            [],
            "tracks.csv row 1, column p_xx_m2: must be a finite number >= 0 (got '-1')",
        ),
        (
            None,
            [["time_s", "x_m", "y_m"], [0, 0, 0]],
            [],
            "tracks.csv line 1, column method: missing",
        ),
        (
            None,
            None,
            ["--gospa-cutoff-m", "0"],
            "--gospa-cutoff-m must be a finite number in (0, 1e+08]",
        ),
        (None, None, ["--gospa-order", "0.5"], "--gospa-order must be a finite number in [1, 16]"),
        (None, None, ["--max-gap-s", "-1"], "--max-gap-s must be a finite number in [0, 1e+06]"),
        (None, None, ["--method", "ucm"], "--method must be one of m (got 'ucm')"),
        (None, None, ["--out", "/no/such/dir/s.json"], "--out: no such directory '/no/such/dir'"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(
    tmp_path: Path, capsys, truth_rows, track_rows, extra: list[str], needle: str
) -> None:
    truth_rows = truth_rows or [TRUTH_HEADER, [0, "a", 0, 0]]
    track_rows = track_rows or [["time_s", "method", "x_m", "y_m"], [0, "m", 0, 0]]
    truth = _write(tmp_path / "truth.csv", truth_rows[0], truth_rows[1:])
    tracks = _write(tmp_path / "tracks.csv", track_rows[0], track_rows[1:])
    assert main(["score", str(tracks), "--truth", str(truth), *extra]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert needle in captured.err, captured.err
    assert captured.err.count("\n") == 1 and "Traceback" not in captured.err


def test_missing_file_is_one_line(tmp_path: Path, capsys) -> None:
    truth = _write(tmp_path / "truth.csv", TRUTH_HEADER, [[0, "a", 0, 0]])
    assert main(["score", str(tmp_path / "none.csv"), "--truth", str(truth)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "none.csv" in err


def test_help_shows_the_parameters_and_their_ranges(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["score", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for flag in ("--gospa-cutoff-m", "--gospa-order", "--max-gap-s", "--all-tracks", "--out"):
        assert flag in text
    assert "Δt_max, longest time a track's last row is predicted over to a truth time (s)" in text


def test_3d_truth_and_tracks_compare_in_3d_else_in_the_plane() -> None:
    """A z error counts when both are 3D (NEES of 3 dof); a 2D track file is scored in the
    x–y plane against a 3D truth."""
    times = np.arange(4.0)
    truth = Truth(times, np.array(["a"] * 4), np.tile([0.0, 0.0, 1000.0], (4, 1)))
    cov = np.tile(np.eye(3), (4, 1, 1))
    rows = TrackRows(times, np.array(["t"] * 4), np.tile([0.0, 0.0, 1003.0], (4, 1)), None, cov)
    s = score_tracks(truth, rows, ScoreOptions())
    assert s.dims == 3 and s.position_rmse.value == pytest.approx(3.0)
    assert s.nees is not None and (s.nees.dof, s.nees.mean) == (3, pytest.approx(9.0))
    flat = rows._replace(position_m=np.tile([0.0, 4.0, 0.0], (4, 1)), position_cov_m2=None)
    s = score_tracks(truth, flat, ScoreOptions())
    assert s.dims == 2 and s.position_rmse.value == pytest.approx(4.0)
