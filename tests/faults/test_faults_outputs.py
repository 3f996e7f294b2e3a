"""A command's outputs change together or not at all (``viz_app.io.atomic.commit_together``):
``track --out --summary`` with a summary that cannot be written leaves the track file as it
was, a read-only directory is refused before any work, and so is a read-only output file."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

from radarviz.viz_app.cli.main import main


@pytest.fixture
def inputs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[Path, Path]:
    """A simulated measurement CSV and its radars TOML."""
    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    argv = ["simulate", "--preset", "prosov", "--out", str(meas), "--radars-out", str(radars)]
    assert main(argv) == 0
    capsys.readouterr()
    return meas, radars


def fail_creating(monkeypatch: pytest.MonkeyPatch, name: str, code: int) -> None:
    """Creating a temporary file for the target ``name`` fails with ``code`` (a read-only
    file system, a full disk), as root cannot be refused by permissions."""
    real = os.open

    def fake(path, flags, *args, **kwargs):
        if os.path.basename(os.fspath(path)).startswith(f".{name}.") and flags & os.O_CREAT:
            raise OSError(code, os.strerror(code))
        return real(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", fake)


@pytest.mark.parametrize("code", [errno.EROFS, errno.ENOSPC])
def test_a_summary_that_cannot_be_written_leaves_the_track_file(
    inputs: tuple[Path, Path], tmp_path: Path, capsys, monkeypatch, code: int
) -> None:
    meas, radars = inputs
    out, summary = tmp_path / "o.csv", tmp_path / "s.json"
    out.write_bytes(b"the previous run's tracks\n")
    fail_creating(monkeypatch, "s.json", code)
    argv = ["track", "--input", str(meas), "--radars", str(radars), "--method", "ucm"]
    assert main([*argv, "--out", str(out), "--summary", str(summary)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("radarviz: error: cannot write") and "s.json" in err[-1], err
    assert out.read_bytes() == b"the previous run's tracks\n"
    assert not summary.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.csv", "o.csv", "r.toml"]


def test_an_unwritable_output_directory_is_refused_before_any_work(
    inputs: tuple[Path, Path], tmp_path: Path, capsys, monkeypatch
) -> None:
    """``os.access`` says the summary's directory is not writable (as it does for a read-only
    mount, or for a user without permission): exit 2 naming the option, before tracking."""
    meas, radars = inputs
    ro = tmp_path / "ro"
    ro.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, m, **k: False if Path(p) == ro else real(p, m, **k))
    out = tmp_path / "o.csv"
    argv = ["track", "--input", str(meas), "--radars", str(radars), "--out", str(out)]
    assert main([*argv, "--summary", str(ro / "s.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--summary" in err[0] and "not writable" in err[0], err
    assert not out.exists()


def test_a_read_only_output_is_not_replaced(
    inputs: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A file its owner made read-only (0444) stays as it was: renaming over it needs only
    the directory's permission, so the check is the command's own."""
    meas, radars = inputs
    out = tmp_path / "t.csv"
    out.write_text("kept\n")
    out.chmod(0o444)
    assert main(["track", "--input", str(meas), "--radars", str(radars), "--out", str(out)]) == 2
    assert capsys.readouterr().err == (
        f"radarviz: error: --out {out} is read-only: refusing to replace it\n"
    )
    assert out.read_text() == "kept\n"


def test_a_demo_output_under_a_file_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``demo --out p.csv/x.rrd`` with ``p.csv`` a file: the file named, not "File exists"."""
    (tmp_path / "p.csv").write_text("x\n")
    assert main(["demo", "--out", str(tmp_path / "p.csv" / "x.rrd")]) == 2
    err = capsys.readouterr().err
    assert err == (
        f"radarviz: error: --out: cannot make the directory '{tmp_path / 'p.csv'}' "
        f"({tmp_path / 'p.csv'} is a file)\n"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.csv"]
