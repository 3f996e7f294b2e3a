"""Inputs that once ended in a traceback: a CSV whose lines end in a bare CR (old Mac text),
a radars file nested thousands deep, and run counts too large to hold (OverflowError,
MemoryError). Each is now one line naming the file or the flag, exit status 2, and no output
written."""

from __future__ import annotations

from pathlib import Path

import pytest

from radarviz.viz_app.cli.main import main

RADARS = """[radars.radar]
x_m = 0.0
y_m = 0.0
z_m = 0.0
sigma_r_m = 250.0
sigma_beta_deg = 1.0
"""
PLOTS = [
    "time_s,radar,range_m,azimuth_deg",
    "0.0,radar,150000.0,1.0",
    "10.0,radar,152000.0,1.0",
    "20.0,radar,154000.0,1.0",
]


def one_line(capsys) -> str:
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and out == "", err
    return lines[0]


@pytest.mark.parametrize("out_name", ["t.csv", "t.parquet"])
def test_a_csv_of_bare_cr_line_ends_is_refused_in_one_line(
    tmp_path: Path, capsys, out_name: str
) -> None:
    """The csv module's "new-line character seen in unquoted field" traceback."""
    meas, radars, out = tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / out_name
    meas.write_bytes("\r".join(PLOTS).encode() + b"\r")
    radars.write_text(RADARS)
    out.write_text("previous")
    argv = ["track", "--input", str(meas), "--radars", str(radars), "--out", str(out)]
    assert main(argv) == 2
    line = one_line(capsys)
    assert line.startswith(f"radarviz: error: {meas} line 1: "), line
    assert "bare CR" in line, line
    assert out.read_text() == "previous"
    # the same plots with LF or CRLF line ends are tracked
    for end in ("\n", "\r\n"):
        meas.write_bytes(end.join(PLOTS).encode() + end.encode())
        assert (
            main(["track", "--input", str(meas), "--radars", str(radars), "--out", str(out)]) == 0
        )


def test_a_radars_file_nested_thousands_deep_is_one_line(tmp_path: Path, capsys) -> None:
    """tomllib recursed into a RecursionError traceback."""
    meas, radars, out = tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "t.csv"
    meas.write_text("\n".join(PLOTS) + "\n")
    radars.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")
    assert main(["track", "--input", str(meas), "--radars", str(radars), "--out", str(out)]) == 2
    line = one_line(capsys)
    assert line.startswith(f"radarviz: error: {radars}: not valid TOML: "), line
    assert "nested" in line, line
    assert not out.exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["reproduce", "prosov", "--runs"],
        ["sweep", "--scheduler", "serial", "--runs"],
    ],
    ids=lambda a: a[1],
)
@pytest.mark.parametrize("runs", [10**30, 10**15, 10**8 + 1])
def test_a_run_count_beyond_the_maximum_is_refused_up_front(
    tmp_path: Path, capsys, argv: list[str], runs: int
) -> None:
    """``--runs 10**30`` raised OverflowError and ``--runs 10**15`` MemoryError, from the list
    of blocks, before the first run."""
    out = tmp_path / "s.parquet"
    extra = ["--out", str(out)] if argv[0] == "sweep" else []
    assert main([*argv, str(runs), *extra]) == 2
    line = one_line(capsys)
    assert line.startswith("radarviz: error: --runs must be an integer in [3, "), line
    assert f"(got {runs})" in line, line
    assert not out.exists() and not Path(f"{out}.chunks").exists()


def test_a_sweep_of_more_chunks_than_it_can_hold_is_refused_up_front(
    tmp_path: Path, capsys
) -> None:
    """Runs within their maximum, but cut into blocks of one run: 10⁸ tasks to schedule."""
    from radarviz.core.experiments.sweep import MAX_CHUNKS

    out = tmp_path / "s.parquet"
    argv = ["sweep", "--scheduler", "serial", "--out", str(out), "--block", "1"]
    assert main([*argv, "--runs", str(MAX_CHUNKS + 1)]) == 2
    line = one_line(capsys)
    assert line.startswith(f"radarviz: error: --runs must make at most {MAX_CHUNKS} chunks"), line
    assert f"{MAX_CHUNKS + 1} chunks)" in line, line
    assert not out.exists() and not Path(f"{out}.chunks").exists()
