"""Nothing is lost at an output: full disks, killed runs, races, outputs that are inputs,
special files and permissions (``viz_app.io.atomic``, ``viz_app.rerun.recording``).

Every case checks that the data that were there are still there, byte for byte, and that
the error is one line: exit status 2 naming the option for an output refused before any
work, exit status 1 naming the target for a write that failed.
"""

from __future__ import annotations

import errno
import math
import os
import shutil
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from radarviz.core.finite import ResultError, check_finite_document, check_finite_result
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io.atomic import (
    Stage,
    WriteError,
    atomic_write,
    check_outputs,
    commit_together,
    remove_stale_temps,
)
from radarviz.viz_app.rerun.recording import recording_file, verify_recording

RADARVIZ = [sys.executable, "-m", "radarviz.viz_app.cli.main"]


def one_error_line(err: str, *needles: str) -> str:
    """The single ``radarviz: error:`` line of ``err`` (asserting there is nothing else)."""
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("radarviz: error:"), err
    for needle in needles:
        assert needle in lines[0], err
    assert ".tmp" not in lines[0] and ".part" not in lines[0], err  # never a temporary name
    return lines[0]


def temporaries(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if p.name.endswith((".tmp", ".part")))


@pytest.fixture
def inputs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[Path, Path]:
    """A simulated measurement CSV and its radars TOML."""
    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    assert (
        main(["simulate", "--preset", "prosov", "--out", str(meas), "--radars-out", str(radars)])
        == 0
    )
    capsys.readouterr()
    return meas, radars


def track(meas: Path, radars: Path, *extra: str) -> list[str]:
    return ["track", "--input", str(meas), "--radars", str(radars), *extra]


# --------------------------------------------------------------------------------------------
# Full disk
# --------------------------------------------------------------------------------------------


@pytest.fixture
def small_disk(tmp_path: Path):
    """A 2 MB tmpfs (skipped where this process may not mount one)."""
    if os.geteuid() != 0:
        pytest.skip("mounting a 2 MB tmpfs needs root")
    if shutil.which("mount") is None or shutil.which("umount") is None:
        pytest.skip("no mount/umount on this machine")
    mnt = tmp_path / "small"
    mnt.mkdir()
    proc = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)],
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {proc.stderr.strip() or proc.returncode}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def fill(directory: Path, leave: int) -> None:
    """Fill the file system of ``directory`` until about ``leave`` bytes are free."""
    st = os.statvfs(directory)
    free = st.f_bavail * st.f_frsize
    with open(directory / "filler", "wb") as fh:
        fh.write(b"\0" * max(free - leave, 0))


def test_full_disk_keeps_the_recording_it_would_replace(
    small_disk: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = small_disk / "x.rrd"
    assert main(["record", "--preset", "prosov", "--out", str(out)]) == 0
    good = out.read_bytes()
    capsys.readouterr()
    fill(small_disk, 530_000)
    assert main(["record", "--preset", "prosov", "--out", str(out), "--overwrite"]) == 1
    one_error_line(capsys.readouterr().err, f"cannot write {out}", "No space left on device")
    assert out.read_bytes() == good
    verify_recording(out)
    assert temporaries(small_disk) == []


def test_full_disk_keeps_the_track_file_it_would_replace(
    small_disk: Path, inputs: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    out = small_disk / "t.csv"
    out.write_text("earlier tracks\n")
    fill(small_disk, 20_000)
    assert main(track(*inputs, "--out", str(out))) == 1
    one_error_line(capsys.readouterr().err, f"cannot write {out}", "No space left on device")
    assert out.read_text() == "earlier tracks\n"
    assert temporaries(small_disk) == []


def test_a_write_error_names_the_target_and_keeps_it(tmp_path: Path) -> None:
    """The mapping the full-disk cases rely on, where no tmpfs can be mounted: an OSError of
    the write (no file name, as ENOSPC has) becomes a WriteError naming the target."""
    out = tmp_path / "o.csv"
    out.write_text("keep")
    with pytest.raises(WriteError) as info, atomic_write(out, "w") as fh:
        fh.write("partial")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert str(info.value) == f"cannot write {out}: No space left on device"
    assert out.read_text() == "keep" and temporaries(tmp_path) == []


@pytest.mark.parametrize(
    "damage", ["cut short by one byte", "a byte flipped in a compressed chunk"]
)
def test_a_recording_that_does_not_read_back_is_not_renamed(tmp_path: Path, damage: str) -> None:
    """Verification before the rename: a recording cut short by one byte (no footer) or with
    one byte of a compressed chunk flipped (its codec fails, the footer intact) is refused."""
    import numpy as np
    import rerun as rr

    good = tmp_path / "good.rrd"
    with recording_file(good) as rec:
        rec.log("log", rr.TextLog("hello"))
        # A compressible chunk (lz4) filling the middle of the file. (Chunks carry no
        # checksum: a flipped byte of an uncompressed payload would go unseen.)
        rec.log("points", rr.Points3D(np.repeat(np.arange(20.0), 300).reshape(-1, 3)))
    data = bytearray(good.read_bytes())
    verify_recording(good)
    if damage.startswith("cut"):
        data = data[:-1]
    else:
        data[len(data) // 2] ^= 0xFF
    out = tmp_path / "x.rrd"
    out.write_bytes(b"previous")
    with pytest.raises(WriteError, match="does not read back whole"):
        with atomic_write(out, verify=verify_recording) as fh:
            fh.write(bytes(data))
    assert out.read_bytes() == b"previous" and temporaries(tmp_path) == []


# --------------------------------------------------------------------------------------------
# Killed runs and concurrent runs
# --------------------------------------------------------------------------------------------


def test_kill_9_mid_write_leaves_the_target_and_the_next_run_cleans_up(tmp_path: Path) -> None:
    out = tmp_path / "demo.rrd"
    assert (
        subprocess.run([*RADARVIZ, "record", "--preset", "prosov", "--out", str(out)]).returncode
        == 0
    )
    good = out.read_bytes()
    proc = subprocess.Popen(
        [*RADARVIZ, "demo", "--out", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    deadline = time.monotonic() + 30
    while not temporaries(tmp_path) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.01)
    assert temporaries(tmp_path), "the writer never staged its file"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert out.read_bytes() == good
    stale = temporaries(tmp_path)
    assert stale and all(f".{proc.pid}-" in name for name in stale)
    # The next run (another process) removes what the killed one left.
    other = tmp_path / "t.csv"
    sim = [*RADARVIZ, "simulate", "--preset", "prosov", "--out", str(other)]
    assert subprocess.run([*sim, "--radars-out", str(tmp_path / "r.toml")]).returncode == 0
    assert temporaries(tmp_path) == []
    assert out.read_bytes() == good


def test_two_runs_creating_one_file_exactly_one_wins(tmp_path: Path) -> None:
    out = tmp_path / "x.rrd"
    cmd = [*RADARVIZ, "record", "--preset", "gorshkov", "--out", str(out)]
    procs = [
        subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for _ in range(2)
    ]
    results = [(p.wait(), *p.communicate()) for p in procs]
    winners = [r for r in results if r[0] == 0]
    losers = [r for r in results if r[0] != 0]
    assert len(winners) == 1 and len(losers) == 1, results
    assert winners[0][1].startswith(f"wrote {out}")
    code, stdout, stderr = losers[0]
    assert "wrote" not in stdout and code in (1, 2)  # lost at the rename, or at the check
    one_error_line(stderr, str(out))
    verify_recording(out)
    assert temporaries(tmp_path) == []


def test_a_file_created_while_writing_is_not_replaced(tmp_path: Path) -> None:
    """The race itself, deterministically: the target appears between the check and the
    rename; without overwrite the rename (a hard link) fails and the newcomer is kept."""
    out = tmp_path / "x.csv"
    stage = Stage(out, overwrite=False)
    with stage.open("w") as fh:
        fh.write("mine")
    out.write_text("theirs")
    with pytest.raises(WriteError, match="created meanwhile by another run"):
        stage.commit()
    assert out.read_text() == "theirs" and temporaries(tmp_path) == []


# --------------------------------------------------------------------------------------------
# Outputs that are inputs or each other
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "flags, option",
    [
        (["--out", "{meas}"], "--out is the same file as --input"),
        (["--out", "{radars}"], "--out is the same file as --radars"),
        (["--out", "{tmp}/t.csv", "--rrd", "{meas}"], "--rrd is the same file as --input"),
        (["--out", "{tmp}/o.csv", "--rrd", "{tmp}/o.csv"], "--rrd is the same file as --out"),
        (["--out", "{tmp}/./sub/../m.csv"], "--out is the same file as --input"),
        (["--out", "{tmp}/hard.csv"], "--out is the same file as --input"),
    ],
)
def test_track_refuses_an_output_that_is_an_input(
    tmp_path: Path,
    inputs: tuple[Path, Path],
    capsys: pytest.CaptureFixture[str],
    flags: list[str],
    option: str,
) -> None:
    meas, radars = inputs
    (tmp_path / "sub").mkdir()
    os.link(meas, tmp_path / "hard.csv")
    before = {p: p.read_bytes() for p in (meas, radars)}
    names = sorted(p.name for p in tmp_path.iterdir())
    args = [f.format(meas=meas, radars=radars, tmp=tmp_path) for f in flags]
    assert main(track(meas, radars, *args)) == 2
    one_error_line(capsys.readouterr().err, option)
    assert {p: p.read_bytes() for p in before} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == names


def test_simulate_refuses_one_file_for_both_outputs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    x = tmp_path / "X"
    assert main(["simulate", "--preset", "prosov", "--out", str(x), "--radars-out", str(x)]) == 2
    one_error_line(capsys.readouterr().err, "--radars-out is the same file as --out")
    assert not x.exists()


def test_sweep_refuses_one_file_for_table_and_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    o = tmp_path / "o.parquet"
    args = ["sweep", "--grid", "sigma_beta_deg=1", "--runs", "10", "--scheduler", "serial"]
    assert main([*args, "--out", str(o), "--rrd", str(o)]) == 2
    one_error_line(capsys.readouterr().err, "--rrd is the same file as --out")
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------------
# Special files and existing non-recordings
# --------------------------------------------------------------------------------------------


def _fifo(path: Path) -> str:
    os.mkfifo(path)
    return "a FIFO"


def _symlink(path: Path) -> str:
    (path.parent / "real.csv").write_text("real")
    path.symlink_to(path.parent / "real.csv")
    return "a symbolic link"


def _directory(path: Path) -> str:
    path.mkdir()
    return "a directory"


def _device(path: Path) -> str:
    """A node like /dev/null (character device 1, 3), made in the test's own directory."""
    if os.geteuid() != 0:
        pytest.skip("making a device node needs root")
    try:
        os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    except OSError as exc:
        pytest.skip(f"cannot make a device node here: {exc.strerror}")
    return "a character device"


@pytest.mark.parametrize("make", [_fifo, _symlink, _directory, _device])
@pytest.mark.parametrize("command", ["track", "record", "demo"])
def test_special_files_are_never_replaced(
    tmp_path: Path,
    inputs: tuple[Path, Path],
    capsys: pytest.CaptureFixture[str],
    make,
    command: str,
) -> None:
    out = tmp_path / "special"
    kind = make(out)
    before = os.lstat(out)
    args = {
        "track": track(*inputs, "--out", str(out)),
        "record": ["record", "--preset", "prosov", "--out", str(out), "--overwrite"],
        "demo": ["demo", "--out", str(out), "--overwrite"],
    }[command]
    assert main(args) == 2
    one_error_line(capsys.readouterr().err, "--out must name a regular file", kind)
    after = os.lstat(out)
    assert (after.st_mode, after.st_ino) == (before.st_mode, before.st_ino)
    assert temporaries(tmp_path) == []


def test_the_writer_itself_refuses_a_special_file(tmp_path: Path) -> None:
    """Below the command line too (e.g. the tuning panel's saves): a FIFO is kept."""
    fifo = tmp_path / "f"
    os.mkfifo(fifo)
    with pytest.raises(WriteError, match="it is a FIFO"), atomic_write(fifo) as fh:
        fh.write(b"x")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and temporaries(tmp_path) == []


def test_demo_keeps_a_file_that_is_not_a_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes")
    assert main(["demo", "--out", str(notes)]) == 2
    one_error_line(capsys.readouterr().err, "--out", "is not a recording", "--overwrite")
    assert notes.read_text() == "my notes"


def test_check_outputs_names_the_option() -> None:
    with pytest.raises(Exception, match=r"^--plot must name a file"):
        check_outputs([("--plot", " ")])


# --------------------------------------------------------------------------------------------
# Permissions and stale temporaries
# --------------------------------------------------------------------------------------------


def test_replaced_files_keep_their_mode(
    tmp_path: Path, inputs: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    csv_out, rrd_out = tmp_path / "t.csv", tmp_path / "t.rrd"
    for path in (csv_out, rrd_out):
        path.write_text("old")
        path.chmod(0o600)
    assert main(track(*inputs, "--out", str(csv_out), "--rrd", str(rrd_out))) == 0
    for path in (csv_out, rrd_out):
        assert stat.S_IMODE(path.stat().st_mode) == 0o600, path
        assert path.read_bytes() != b"old"
    verify_recording(rrd_out)
    new = tmp_path / "new.csv"
    with atomic_write(new, "w") as fh:
        fh.write("x")
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(new.stat().st_mode) == 0o666 & ~umask


def test_stale_temporaries_of_dead_runs_are_removed_and_live_ones_kept(tmp_path: Path) -> None:
    out = tmp_path / "o.csv"
    past = time.time() - 3600
    dead = tmp_path / ".o.csv.999999999-0badc0de.tmp"  # above any pid_max: no such process
    legacy = tmp_path / ".o.csv.8_ielezd.tmp"  # an earlier version's name, an hour old
    live = tmp_path / f".o.csv.{os.getppid()}-0badc0de.tmp"  # a live process, recent
    unrelated = tmp_path / ".notes.abcdefgh.tmp"  # not a name of ours for this target
    for path in (dead, legacy, live, unrelated):
        path.write_text("partial")
    for path in (dead, legacy, unrelated):
        os.utime(path, (past, past))
    removed = remove_stale_temps(out)
    assert sorted(removed) == sorted([dead, legacy])
    assert live.exists() and unrelated.exists()


# --------------------------------------------------------------------------------------------
# Several outputs commit as a unit (``commit_together``)
# --------------------------------------------------------------------------------------------


def fail_second_rename(monkeypatch: pytest.MonkeyPatch, targets: list[Path]) -> list[str]:
    """Make the second ``os.replace`` onto one of ``targets`` fail with EIO (other renames,
    e.g. the sweep's chunk store and the restoring of a backup, go through). Returns the
    targets renamed onto, in order."""
    real = os.replace
    names = {os.path.realpath(t) for t in targets}
    calls: list[str] = []

    def replace(src, dst, *args, **kwargs):
        if os.path.realpath(dst) in names and not os.path.basename(src).startswith(
            "." + os.path.basename(dst) + "."
        ):
            return real(src, dst, *args, **kwargs)  # not a staged file: let it through
        if os.path.realpath(dst) in names:
            calls.append(str(dst))
            if len(calls) == 2:
                raise OSError(errno.EIO, os.strerror(errno.EIO))
        return real(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", replace)
    return calls


def snapshot(*paths: Path) -> dict[Path, bytes | None]:
    return {p: p.read_bytes() if p.exists() else None for p in paths}


@pytest.mark.parametrize("existing", [True, False])
def test_simulate_second_rename_failing_leaves_both_outputs(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    existing: bool,
) -> None:
    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    if existing:
        meas.write_text("old measurements\n")
        radars.write_text("# old radars\n")
    before = snapshot(meas, radars)
    calls = fail_second_rename(monkeypatch, [meas, radars])
    argv = ["simulate", "--preset", "prosov", "--out", str(meas), "--radars-out", str(radars)]
    assert main(argv) == 1
    assert len(calls) >= 2  # the first rename happened (then its backup went back)
    line = one_error_line(capsys.readouterr().err, f"cannot write {calls[1]}")
    assert os.strerror(errno.EIO) in line
    assert f"{calls[0]} left as before" in line
    assert snapshot(meas, radars) == before
    assert temporaries(tmp_path) == []  # neither the staged files nor the backup remain


def test_track_second_rename_failing_keeps_tracks_and_recording(
    tmp_path: Path,
    inputs: tuple[Path, Path],
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    meas, radars = inputs
    out, rrd = tmp_path / "t.csv", tmp_path / "t.rrd"
    assert main(track(meas, radars, "--out", str(out), "--rrd", str(rrd))) == 0
    capsys.readouterr()
    before = snapshot(out, rrd)
    calls = fail_second_rename(monkeypatch, [out, rrd])
    argv = track(meas, radars, "--out", str(out), "--rrd", str(rrd), "--method", "naive")
    assert main(argv) == 1
    assert len(calls) >= 2
    one_error_line(capsys.readouterr().err, f"cannot write {calls[1]}", "left as before")
    assert snapshot(out, rrd) == before
    verify_recording(rrd)
    assert temporaries(tmp_path) == []


def test_sweep_second_rename_failing_keeps_table_and_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    out, rrd = tmp_path / "s.parquet", tmp_path / "s.rrd"
    out.write_bytes(b"an older table")
    rrd.write_bytes(b"an older recording")
    before = snapshot(out, rrd)
    calls = fail_second_rename(monkeypatch, [out, rrd])
    args = ["sweep", "--grid", "sigma_beta_deg=1", "--runs", "10", "--scheduler", "serial"]
    assert main([*args, "--json", "--out", str(out), "--rrd", str(rrd)]) == 1
    assert len(calls) >= 2
    one_error_line(capsys.readouterr().err, f"cannot write {calls[1]}", "left as before")
    assert snapshot(out, rrd) == before
    assert temporaries(tmp_path) == []


def test_an_error_inside_the_unit_commits_nothing(tmp_path: Path) -> None:
    """A stage verified early in the block is not renamed when a later write fails."""
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old a")
    with pytest.raises(RuntimeError, match="second output"), commit_together():
        with atomic_write(a, "w") as fh:
            fh.write("new a")
        assert a.read_text() == "old a"  # verified, not yet renamed
        with atomic_write(b, "w") as fh:
            fh.write("partial b")
            raise RuntimeError("second output failed")
    assert a.read_text() == "old a" and not b.exists()
    assert temporaries(tmp_path) == []
    with commit_together():  # and a clean block renames both
        with atomic_write(a, "w") as fh:
            fh.write("new a")
        with atomic_write(b, "w") as fh:
            fh.write("new b")
    assert (a.read_text(), b.read_text()) == ("new a", "new b")
    assert temporaries(tmp_path) == []


# --------------------------------------------------------------------------------------------
# Results that are not finite (``core.finite``): one line, exit 1, nothing printed or written
# --------------------------------------------------------------------------------------------


def test_check_finite_result_names_the_value_and_spares_undefined_ones() -> None:
    n = np.arange(1, 6)
    values = np.array([np.nan, np.nan, 1.0, 2.0, 3.0])
    check_finite_result("w", "x", values, defined=n >= 3, index=n)  # undefined before scan 3
    with pytest.raises(ResultError, match=r"^w: x at scan 2 is NaN \(not a finite result\)$"):
        check_finite_result("w", "x", values, defined=n >= 2, index=n)
    with pytest.raises(ResultError, match=r"^w: nees at scan 4 is -0\.5 \(a negative value"):
        check_finite_result("w", "nees", [1.0, 2.0, 3.0, -0.5], nonnegative=True)
    check_finite_result("w", "bias", [1.0, -2.0])  # a bias may be negative
    with pytest.raises(ResultError, match=r"at k 7\[2\] is \+inf"):
        check_finite_result(
            "w", "g", np.array([[0.0, 0.0, 0.0], [0.0, 0.0, np.inf]]), index_name="k", index=[3, 7]
        )
    with pytest.raises(ResultError, match=r"^w: baseline\.sigma_mc_mps\[1\] is NaN"):
        check_finite_document("w", {"baseline": {"sigma_mc_mps": [1.0, math.nan], "warning": None}})


def test_a_bench_document_may_carry_a_negative_memory_slope() -> None:
    """A soak whose resident set shrinks after its warm-up has a negative slope: the bench's
    check takes it (``SIGNED_FIGURES``), and still refuses a negative time or a NaN slope."""
    from radarviz.viz_app.bench.live import SIGNED_FIGURES

    doc = {"live": {"latency_ms": 30.0, "memory": {"slope_mib_per_h": -6.1, "flat": True}}}
    check_finite_document("bench", doc, nonnegative=True, signed=SIGNED_FIGURES)
    with pytest.raises(ResultError, match=r"live\.memory\.slope_mib_per_h is -6\.1"):
        check_finite_document("bench", doc, nonnegative=True)
    doc["live"]["latency_ms"] = -1.0
    with pytest.raises(ResultError, match=r"live\.latency_ms is -1"):
        check_finite_document("bench", doc, nonnegative=True, signed=SIGNED_FIGURES)
    doc["live"]["latency_ms"], doc["live"]["memory"]["slope_mib_per_h"] = 30.0, math.nan
    with pytest.raises(ResultError, match=r"slope_mib_per_h is NaN"):
        check_finite_document("bench", doc, nonnegative=True, signed=SIGNED_FIGURES)


def _spoil(result, method: str, key: str, scan: int, value: float):
    """Put ``value`` into ``result.metrics[method].key`` at ``scan`` (1-based), in place."""
    getattr(result.metrics[method], key)[scan - 1] = value
    return result


@pytest.mark.parametrize(
    "value, expected",
    [
        (math.nan, "reproduce prosov: nees_pos of ukf at scan 12 is NaN (not a finite result)"),
        (-0.5, "reproduce prosov: nees_pos of ukf at scan 12 is -0.5 (a negative value"),
    ],
)
@pytest.mark.parametrize("as_json", [False, True])
def test_reproduce_prosov_refuses_a_nan_or_negative_nees(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    value: float,
    expected: str,
    as_json: bool,
) -> None:
    import radarviz.experiments as api  # the CLI runs the experiments through the API

    real = api.run_tracking
    monkeypatch.setattr(
        api,
        "run_tracking",
        lambda cfg, progress=None: _spoil(real(cfg), "ukf", "nees_pos", 12, value),
    )
    png = tmp_path / "f.png"
    argv = ["reproduce", "prosov", "--runs", "20", "--steps", "20", "--methods", "naive", "ukf"]
    argv += ["--sigma-beta-deg", "1", "--plot", str(png)] + (["--json"] if as_json else [])
    assert main(argv) == 1
    out, err = capsys.readouterr()
    assert out == ""
    one_error_line(err, expected)
    assert list(tmp_path.iterdir()) == []


def test_reproduce_gorshkov_undefined_is_null_and_a_nan_is_an_error(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Range-only acceleration at k < 3 and the track start's scans before its k are null by
    construction; a NaN where a value must exist (k = 5, scan 10) is an error."""
    import json

    import radarviz.experiments as api  # the CLI runs the experiments through the API

    argv = ["reproduce", "gorshkov", "--trials", "200", "--radars", "RLS1", "--k-max", "6"]
    argv += ["--tracking-runs", "20", "--json"]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["radars"][0]["sigma"]["range_only"]["a_mps2"][:2] == [None, None]
    assert all(v is not None for v in doc["radars"][0]["sigma"]["range_only"]["a_mps2"][2:])
    start = doc["tracking"]["start_scans"]
    rmse = doc["tracking"]["variants"]["range_doppler"]["rmse_x_m"]
    assert rmse[: start - 1] == [None] * (start - 1) and None not in rmse[start - 1 :]

    real_fit = api._run_gorshkov

    def spoiled_fit(*args, **kwargs):
        result = real_fit(*args, **kwargs)
        result.radars[0].range_only.sigma_mc[4, 0] = math.nan
        return result

    monkeypatch.setattr(api, "_run_gorshkov", spoiled_fit)
    assert main(argv) == 1
    out, err = capsys.readouterr()
    assert out == ""
    one_error_line(err, "reproduce gorshkov: sigma_mc of range_only (RLS1) at k 5[0] is NaN")

    monkeypatch.setattr(api, "_run_gorshkov", real_fit)
    real_track = api.run_doppler_tracking
    monkeypatch.setattr(
        api,
        "run_doppler_tracking",
        lambda cfg: _spoil(real_track(cfg), "range_only", "rmse_x_m", 10, math.nan),
    )
    assert main(argv) == 1
    one_error_line(capsys.readouterr().err, "rmse_x_m of range_only at scan 10 is NaN")


def test_reproduce_velocity_refuses_a_nan(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import radarviz.experiments as api  # the CLI runs the experiments through the API

    real = api.run_velocity_experiment

    def spoiled(*args, **kwargs):
        result = real(*args, **kwargs)
        result.baseline_mc.sigma[1] = math.nan
        return result

    monkeypatch.setattr(api, "run_velocity_experiment", spoiled)
    assert main(["reproduce", "velocity", "--trials", "2000"]) == 1
    out, err = capsys.readouterr()
    assert out == ""
    one_error_line(err, "reproduce velocity: baseline.sigma_mc_mps[1] is NaN (not a finite result)")


@pytest.mark.parametrize("entry, value", [((2, 2), math.nan), ((0, 0), -1.0)])
def test_track_refuses_a_nan_or_negative_variance_and_writes_nothing(
    tmp_path: Path,
    inputs: tuple[Path, Path],
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    entry: tuple[int, int],
    value: float,
) -> None:
    from radarviz.core.tracking import stream

    real = stream.StreamTracker.add_block
    seen = {"plots": 0}

    def spoiled(self, plots):
        rows = real(self, plots)
        for plot_rows in rows:
            seen["plots"] += 1
            if seen["plots"] == 7:
                method, x, P = plot_rows[0]
                P = P.copy()
                P[entry] = value
                plot_rows[0] = (method, x, P)
        return rows

    monkeypatch.setattr(stream.StreamTracker, "add_block", spoiled)
    meas, radars = inputs
    out, rrd = tmp_path / "t.csv", tmp_path / "t.rrd"
    argv = track(meas, radars, "--out", str(out), "--rrd", str(rrd), "--method", "naive")
    assert main(argv) == 1
    column = "p_yy_m2" if entry == (2, 2) else "p_xx_m2"
    what = "is NaN (not a finite result)" if math.isnan(value) else "is -1 (a negative value"
    line = one_error_line(capsys.readouterr().err, f"{column} of naive", what)
    assert line.startswith(f"radarviz: error: track: {meas} at time 60.0 s:")
    assert not out.exists() and not rrd.exists()
    assert temporaries(tmp_path) == []


def test_simulate_refuses_a_nan_plot_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import dataclasses

    import radarviz.viz_app.cli.track as cli_track

    real = cli_track.simulated_plots

    def spoiled(*args, **kwargs):
        plots, radars = real(*args, **kwargs)
        plots[3] = dataclasses.replace(plots[3], range_m=math.nan)
        return plots, radars

    monkeypatch.setattr(cli_track, "simulated_plots", spoiled)
    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    argv = ["simulate", "--preset", "prosov", "--out", str(meas), "--radars-out", str(radars)]
    assert main(argv) == 1
    one_error_line(capsys.readouterr().err, "simulate: range_m at plot 4 is NaN")
    assert list(tmp_path.iterdir()) == []


def test_sweep_refuses_a_nan_and_writes_no_table(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import radarviz.viz_app.cli.sweep as cli_sweep

    real = cli_sweep.run_sweep

    def spoiled(spec, *args, **kwargs):
        run = real(spec, *args, **kwargs)
        _spoil(run.results[0], "naive", "rmse_x_m", 3, math.nan)
        return run

    monkeypatch.setattr(cli_sweep, "run_sweep", spoiled)
    out = tmp_path / "s.parquet"
    args = ["sweep", "--grid", "sigma_beta_deg=1", "--runs", "10", "--scheduler", "serial"]
    assert main([*args, "--json", "--methods", "naive", "--out", str(out)]) == 1
    stdout, err = capsys.readouterr()
    assert stdout == ""
    one_error_line(err, "sweep: point 0: rmse_x_m of naive at scan 3 is NaN")
    assert not out.exists()


def test_bench_refuses_a_nan_figure(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import radarviz.viz_app.bench.engine as engine

    monkeypatch.setattr(
        engine,
        "run_bench",
        lambda runs, filterpy_runs, targets, **_: {"runs": list(runs), "kf_ns": [math.nan]},
    )
    assert main(["bench", "--json", "--runs", "100"]) == 1
    out, err = capsys.readouterr()
    assert out == ""
    one_error_line(err, "bench: kf_ns[0] is NaN (not a finite result)")


def test_tune_panel_shows_a_nan_as_its_error_and_keeps_the_last_good_run(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import radarviz.viz_app.tune.scenes as scenes
    from radarviz.viz_app.tune.params import TuneParams
    from radarviz.viz_app.tune.session import TuneSession
    from radarviz.viz_app.tune.worker import Coalescer

    small = TuneParams(runs=20, steps=10)
    session = TuneSession(None)
    worker = Coalescer(session.run, session.done, session.error)
    real = scenes.prosov_scene
    try:
        worker.submit(small)
        assert worker.wait_idle(60)
        good = session.last_good
        assert good is not None and session.last_error is None

        def spoiled(cfg):
            scene = real(cfg)
            _spoil(scene.result, "ukf", "nees_pos", 4, math.nan)
            return scene

        monkeypatch.setattr(scenes, "prosov_scene", spoiled)
        worker.submit(TuneParams(runs=20, steps=10, sigma_beta_deg=1.5))
        assert worker.wait_idle(60)
    finally:
        worker.stop()
    assert session.last_good is good  # still on screen
    assert session.last_error == (
        "tune prosov: nees_pos of ukf at scan 4 is NaN (not a finite result)"
    )
