"""``track --rrd``'s memory grew with the file: the encoded recording was held in memory until
it was written (10⁵ plots of 7 methods peaked at 2.2 GB against 250 MB without ``--rrd``). The
recording now goes to its file as it is logged, so the peak does not depend on the length."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from radarviz.viz_app.cli.main import main

#: Report the peak RSS of one ``track --rrd`` run (MiB), in a fresh process of its own.
PEAK = """
import resource, sys
from radarviz.viz_app.cli.main import main
code = main(sys.argv[1:])
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)
sys.exit(code)
"""
#: What the recording of one plot of two methods adds to the file (the fusion preset's, measured:
#: 10⁵ plots of 7 methods are a 571 MB recording, 5.7 kB a plot, 1.6 kB for two methods). Held in
#: memory, 3 · 10⁴ more plots would add their 48 MB at least; a recording that streams adds
#: only the bookkeeping of its chunks (0.1 kB a plot measured), well under this bound.
MAX_GROWTH_MIB_PER_PLOT = 0.5 / 1024


def _peak_mib(tmp_path: Path, scans: int) -> tuple[float, int]:
    meas, radars = tmp_path / f"m{scans}.csv", tmp_path / "r.toml"
    argv = ["simulate", "--preset", "fusion", "--scans", str(scans)]
    assert main([*argv, "--out", str(meas), "--radars-out", str(radars)]) == 0
    plots = sum(1 for _ in meas.open()) - 1
    track = ["track", "--input", str(meas), "--radars", str(radars), "--method", "ucm", "ekf"]
    track += ["--out", str(tmp_path / "t.csv"), "--rrd", str(tmp_path / "t.rrd")]
    run = subprocess.run(
        [sys.executable, "-c", PEAK, *track], capture_output=True, text=True, check=False
    )
    assert run.returncode == 0, run.stderr[-2000:]
    assert (tmp_path / "t.rrd").stat().st_size > plots * 1000  # the recording is all there
    return float(run.stdout.strip().splitlines()[-1]), plots


def test_track_rrd_memory_does_not_grow_with_the_file(tmp_path: Path, capsys) -> None:
    small, n_small = _peak_mib(tmp_path, 3_334)
    large, n_large = _peak_mib(tmp_path, 13_334)
    capsys.readouterr()
    growth = large - small
    assert growth < MAX_GROWTH_MIB_PER_PLOT * (n_large - n_small), (small, large)


def test_a_disk_without_room_for_the_next_chunk_is_one_line(
    tmp_path: Path, capsys, monkeypatch
) -> None:
    """The recording streams to its file, so a disk filling up shows mid-run: it is refused
    before the SDK's writer would stall on it, in one line naming the target, which keeps its
    previous file."""
    import shutil

    import radarviz.viz_app.rerun.recording as recording

    meas, radars, rrd = tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "t.rrd"
    argv = ["simulate", "--preset", "fusion", "--scans", "2000"]
    assert main([*argv, "--out", str(meas), "--radars-out", str(radars)]) == 0
    rrd.write_bytes(b"previous")
    full = shutil.disk_usage(tmp_path)._replace(free=1 << 20)
    monkeypatch.setattr(recording.shutil, "disk_usage", lambda path: full)
    capsys.readouterr()
    track = ["track", "--input", str(meas), "--radars", str(radars), "--method", "ucm"]
    assert main([*track, "--out", str(tmp_path / "t.csv"), "--rrd", str(rrd)]) == 1
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line == f"radarviz: error: cannot write {rrd}: No space left on device", line
    assert rrd.read_bytes() == b"previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.csv", "r.toml", "t.rrd"]
