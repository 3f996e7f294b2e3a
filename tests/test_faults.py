"""Nothing is lost at an output: full disks, killed runs, races, outputs that are inputs,
special files and permissions (``viz_app.io.atomic``, ``viz_app.rerun.recording``).

Every case checks that the data that were there are still there, byte for byte, and that
the error is one line: exit status 2 naming the option for an output refused before any
work, exit status 1 naming the target for a write that failed.
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

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


def test_a_recording_that_does_not_read_back_is_not_renamed(tmp_path: Path) -> None:
    """Verification before the rename: a recording cut short by one byte is refused."""
    good = tmp_path / "good.rrd"
    with recording_file(good) as rec:
        rec.log("log", __import__("rerun").TextLog("hello"))
    data = good.read_bytes()
    out = tmp_path / "x.rrd"
    out.write_bytes(b"previous")
    with pytest.raises(WriteError, match="does not read back whole"):
        with atomic_write(out, verify=verify_recording) as fh:
            fh.write(data[:-1])
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
