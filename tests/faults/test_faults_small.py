"""Small faults: each once accepted something it should have refused."""

from __future__ import annotations

import pytest

from radarviz.viz_app.tune.guard import PanelGuard, _host_name


@pytest.mark.parametrize(
    ("header", "name"),
    [
        ("[::1]:8080", "::1"),
        ("[::1]", "::1"),
        ("[::1].evil.example:8080", ""),
        ("[::1]evil:8080", ""),
        ("[::1]:80x", ""),
        ("localhost:8080", "localhost"),
    ],
)
def test_a_bracketed_host_is_an_address_and_a_port_only(header: str, name: str) -> None:
    assert _host_name(header) == name
    if not name:
        assert not PanelGuard().host_allowed(_host_name(header))


def test_simulate_prosov_refuses_scans_it_would_ignore(tmp_path, capsys) -> None:
    """``simulate --preset prosov --scans 500`` wrote the preset's 60 plots without a word."""
    from radarviz.viz_app.cli.main import main

    out, toml = tmp_path / "m.csv", tmp_path / "r.toml"
    argv = ["simulate", "--preset", "prosov", "--out", str(out), "--radars-out", str(toml)]
    assert main([*argv, "--scans", "500"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("radarviz: error: --scans is not the prosov preset's"), line
    assert not out.exists() and not toml.exists()
    assert main(argv) == 0  # without --scans: its 60 scans, as documented


def test_a_reader_that_stops_reading_is_not_an_error_of_the_command(tmp_path) -> None:
    """``track --json | head -c 5``: the summary's write to a pipe whose reader had gone was
    reported as "radarviz: error: [Errno 32] Broken pipe", status 2, after the track file was
    written. Now the command ends as a pipeline's writer does: silent, status 128 + SIGPIPE."""
    import os
    import subprocess
    import sys

    from radarviz.viz_app.cli.main import EXIT_PIPE, main

    meas, toml, out = tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "t.csv"
    argv = ["simulate", "--preset", "prosov", "--out", str(meas), "--radars-out", str(toml)]
    assert main(argv) == 0
    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader is gone before the command writes
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "radarviz.viz_app.cli.main", "track", "--input", str(meas),
             "--radars", str(toml), "--out", str(out), "--method", "ucm", "--json"],
            stdout=write_end, stderr=subprocess.PIPE, text=True, timeout=600,
        )  # fmt: skip
    finally:
        os.close(write_end)
    assert (proc.returncode, proc.stderr) == (EXIT_PIPE, "")
    assert out.exists()  # the track file is written before the summary is printed
