"""Many targets per file (``core.tracking.targets``, the ``target`` column of ``track``).

* Per target, as alone: the tracks of a file of several interleaved targets (their own time
  offsets, three radars each, Doppler missing on some plots) equal, target by target,
  ``StreamTracker`` run on that target's plots alone, to 1e-9 (relative, with an absolute
  floor of 1e-9 in the entry's unit), for the cv and the IMM model, 2D (all seven methods) and
  3D (the four 3D methods), whatever the block boundaries. The batched tracker takes other
  routes through the same formulas (one time step per target, a site per target), so the
  reference is the one-target tracker, not itself.
* The same through files: ``radarviz track`` on the many-target file and on each target's
  own file (written without the column) give the same rows.
* The per-track prediction period equals the scalar one track by track.
* Bad input: one line naming file, line and column (plots out of time order within a target,
  an empty label, an unknown radar), or the flag (the finite-memory start and track are one
  target's), exit 2, nothing written. Out of order across targets is fine, and so is a target
  that changes radar.
"""

from __future__ import annotations

import csv
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_track_io import GOOD_RADARS  # the two radars a and b of the file-format tests

from radarviz.core.filters.methods import ALL_METHODS, METHODS_3D
from radarviz.core.filters.predict import cv_predict
from radarviz.core.filters.state import CVBatch
from radarviz.core.tracking.stream import (
    Plot,
    StreamOptions,
    StreamTracker,
)
from radarviz.core.tracking.targets import TargetTracker, track_name
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io.plots import (
    TRACK_COLUMNS,
    fusion_plots,
    prosov_plots,
    state_from_row,
    write_measurements,
)

TOL = 1e-9


def close(a: np.ndarray, b: np.ndarray) -> bool:
    """|a − b| ≤ 1e-9 (1 + |a|) entry by entry."""
    return bool(np.all(np.abs(np.asarray(a) - np.asarray(b)) <= TOL * (1.0 + np.abs(a))))


def scene(three_d: bool, targets: int = 4, scans: int = 15) -> dict[str, list[Plot]]:
    """Each target's plots: the prosov run (2D, one radar) or the fusion run (3D, three
    radars with Doppler, one cell in four left without), per target its own seed, time
    offset and label."""
    out = {}
    for k in range(targets):
        if three_d:
            plots, _ = fusion_plots(seed=k + 1, steps=scans)
        else:
            plots, _ = prosov_plots(seed=k + 1)
        out[f"T{k}"] = [
            replace(
                p,
                time_s=p.time_s + 0.37 * k,
                target=f"T{k}",
                radial_velocity_mps=None if (j + k) % 4 == 0 else p.radial_velocity_mps,
            )
            for j, p in enumerate(plots)
        ]
    return out


def interleaved(by_target: dict[str, list[Plot]]) -> list[Plot]:
    return sorted((p for ps in by_target.values() for p in ps), key=lambda p: p.time_s)


@pytest.mark.parametrize("three_d", [False, True], ids=["2d", "3d"])
@pytest.mark.parametrize("model", ["cv", "imm"])
@pytest.mark.parametrize("block", [3, 1024])
def test_each_target_equals_its_plots_tracked_alone(three_d: bool, model: str, block: int) -> None:
    methods = METHODS_3D if three_d else ALL_METHODS
    options = StreamOptions(model=model, sigma_a_mps2=1.0)
    by_target = scene(three_d)
    plots = interleaved(by_target)
    tracker = TargetTracker(methods, three_d, options)
    rows = []
    for i in range(0, len(plots), block):
        rows += tracker.add_block(plots[i : i + block])
    assert tracker.targets == tuple(sorted(by_target))
    for name, own in by_target.items():
        alone = StreamTracker(methods, three_d, options).add_block(own)
        mine = [r for p, r in zip(plots, rows, strict=True) if p.target == name]
        assert len(mine) == len(alone) == len(own)
        for a, b in zip(alone, mine, strict=True):
            assert [m for m, _, _ in a] == [m for m, _, _ in b] == list(methods)
            for (_, xa, Pa), (_, xb, Pb) in zip(a, b, strict=True):
                assert close(xa, xb) and close(Pa, Pb)


def test_targets_out_of_order_across_targets_and_changing_radar() -> None:
    """Plots of different targets in any order, a target whose radar changes: still each
    target's own tracks (the fusion run changes radar every plot)."""
    by_target = scene(True, targets=3)
    plots = interleaved(by_target)
    # Target T2's plots first, then the others: times go back across targets.
    order = [p for p in plots if p.target == "T2"] + [p for p in plots if p.target != "T2"]
    options = StreamOptions(model="cv", sigma_a_mps2=2.0)
    rows = TargetTracker(METHODS_3D, True, options).add_block(order)
    for name, own in by_target.items():
        assert len({p.radar for p in own}) == 3
        alone = StreamTracker(METHODS_3D, True, options).add_block(own)
        mine = [r for p, r in zip(order, rows, strict=True) if p.target == name]
        for a, b in zip(alone, mine, strict=True):
            for (_, xa, Pa), (_, xb, Pb) in zip(a, b, strict=True):
                assert close(xa, xb) and close(Pa, Pb)


def test_a_period_per_track_equals_the_scalar_period_track_by_track() -> None:
    rng = np.random.default_rng(5)
    for dims, batch in ((2, (3, 40)), (3, (40,))):
        n = 2 * dims
        x = rng.normal(size=(*batch, n)) * 1e3
        a = rng.normal(size=(*batch, n, n))
        P = a @ a.mT + np.eye(n)
        T = rng.uniform(0.0, 12.0, size=batch[-1])
        T[3] = 0.0
        got = cv_predict(CVBatch(x, P), T, 3.0)
        for k in range(batch[-1]):
            one = cv_predict(CVBatch(x[..., k, :], P[..., k, :, :]), float(T[k]), 3.0)
            assert close(one.x, got.x[..., k, :]) and close(one.P, got.P[..., k, :, :])
        assert close(x[..., 3, :], got.x[..., 3, :]) and close(P[..., 3, :, :], got.P[..., 3, :, :])


def _read(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _track(meas: Path, radars: Path, out: Path, *extra: str) -> int:
    return main(["track", "--input", str(meas), "--radars", str(radars), "--out", str(out), *extra])


def test_the_track_file_of_many_targets_equals_each_target_alone(tmp_path: Path) -> None:
    by_target = scene(True, targets=3, scans=10)
    _, radars = fusion_plots(seed=1, steps=2)
    meas, rad = tmp_path / "m.csv", tmp_path / "r.toml"
    write_measurements(str(meas), str(rad), interleaved(by_target), radars)
    summary = tmp_path / "s.json"
    assert _track(meas, rad, tmp_path / "t.csv", "--summary", str(summary)) == 0
    rows = _read(tmp_path / "t.csv")
    with open(tmp_path / "t.csv", newline="") as fh:
        header = next(csv.reader(fh))
    assert tuple(header) == (TRACK_COLUMNS[0], "target", *TRACK_COLUMNS[1:])
    doc = json.loads(summary.read_text())
    assert doc["targets"] == 3
    assert set(doc["tracks"]) == {track_name(t, m) for t in by_target for m in METHODS_3D}
    for name, own in by_target.items():
        alone_meas = tmp_path / f"{name}.csv"
        write_measurements(str(alone_meas), str(rad), [replace(p, target="") for p in own], radars)
        assert _track(alone_meas, rad, tmp_path / f"{name}-t.csv") == 0
        alone = _read(tmp_path / f"{name}-t.csv")
        assert "target" not in alone[0]
        mine = [r for r in rows if r["target"] == name]
        assert len(mine) == len(alone) == len(own) * len(METHODS_3D)
        for a, b in zip(alone, mine, strict=True):
            assert a["time_s"] == b["time_s"] and a["method"] == b["method"]
            xa, Pa = state_from_row(a)
            xb, Pb = state_from_row(b)
            assert close(xa, xb) and close(Pa, Pb)


def test_the_recording_has_one_entity_per_target_and_method(tmp_path: Path, rrd_contents) -> None:
    by_target = scene(False, targets=2)
    meas, rad = tmp_path / "m.csv", tmp_path / "r.toml"
    _, radars = prosov_plots()
    plots = interleaved(by_target)
    plots = [replace(p, target="track 7/a" if p.target == "T1" else p.target) for p in plots]
    write_measurements(str(meas), str(rad), plots, radars)
    rrd = tmp_path / "t.rrd"
    assert _track(meas, rad, tmp_path / "t.csv", "--rrd", str(rrd), "--method", "ekf", "ucm") == 0
    rows, _ = rrd_contents(rrd)
    for target in ("T0", "track\\ 7\\/a"):
        for m in ("ekf", "ucm"):
            assert rows[f"/world/tracks/{target}/{m}/position"] == 60
            assert rows[f"/plots/speed_mps/{target}/{m}"] == 60
    assert not any(k.startswith("/world/tracks/ekf") for k in rows)


HEADER = "time_s,radar,range_m,azimuth_deg,target\n"
GOOD = ["0,a,150000,0.5,A\n", "5,b,94000,10.0,B\n", "10,b,95000,10.2,A\n", "8,a,152000,0.4,B\n"]

BAD = {
    "time back within a target": (
        HEADER + "".join(GOOD) + "9,a,152000,0.4,A\n",
        [],
        "m.csv line 6, column time_s: must not be before the previous time of target 'A' 10.0",
    ),
    "empty label": (
        HEADER + "".join(GOOD[:2]) + "12,a,152000,0.4, \n",
        [],
        "m.csv line 4, column target: must not be empty",
    ),
    "unknown radar": (
        HEADER + "".join(GOOD[:2]) + "12,c,152000,0.4,A\n",
        [],
        "m.csv line 4, column radar: unknown radar",
    ),
    "finite-memory start": (HEADER + "".join(GOOD), ["--init", "finite-memory"], "--init must"),
    "finite-memory track": (
        HEADER + "".join(GOOD),
        ["--finite-memory", "3"],
        "--finite-memory must be 0",
    ),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_target_files_exit_2_one_line_no_output(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str
) -> None:
    text, extra, expected = BAD[case]
    (tmp_path / "m.csv").write_text(text)
    (tmp_path / "r.toml").write_text(GOOD_RADARS)
    capsys.readouterr()
    status = _track(tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "t.csv", *extra)
    out, err = capsys.readouterr()
    assert status == 2 and out == ""
    assert err.count("\n") == 1 and expected in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.csv", "r.toml"]


def test_good_target_file_out_of_order_across_targets(tmp_path: Path) -> None:
    (tmp_path / "m.csv").write_text(HEADER + "".join(GOOD))
    (tmp_path / "r.toml").write_text(GOOD_RADARS)
    assert _track(tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "t.csv") == 0
    rows = _read(tmp_path / "t.csv")
    assert [r["target"] for r in rows[:: len(ALL_METHODS)]] == ["A", "B", "A", "B"]
    assert [float(r["time_s"]) for r in rows[:: len(ALL_METHODS)]] == [0.0, 5.0, 10.0, 8.0]
