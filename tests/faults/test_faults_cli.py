"""Refusals before computing: a figure path whose format matplotlib cannot write was found
only when the figure was written, after the whole experiment, as a traceback."""

from __future__ import annotations

from pathlib import Path

import pytest

from radarviz.viz_app.cli.main import main

#: Each reproduce command with a count that would take minutes to compute.
COMMANDS = [
    ["reproduce", "prosov", "--runs", "10000000"],
    ["reproduce", "doppler", "--runs", "10000000"],
    ["reproduce", "gorshkov", "--trials", "100000000"],
    ["reproduce", "velocity", "--trials", "100000000"],
    ["reproduce", "association"],
]


@pytest.mark.parametrize("argv", COMMANDS, ids=lambda a: a[1])
def test_a_figure_format_matplotlib_cannot_write_is_refused_up_front(
    tmp_path: Path, capsys, argv: list[str]
) -> None:
    figure = tmp_path / "f.xyz"
    assert main([*argv, "--plot", str(figure)]) == 2
    out, err = capsys.readouterr()
    (line,) = err.strip().splitlines()
    assert line.startswith("radarviz: error: --plot: cannot write a figure as .xyz"), line
    assert ".png" in line and out == "" and not figure.exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["reproduce", "prosov", "--runs", "3"],
        ["reproduce", "association", "--runs", "2", "--scans", "8"],
    ],
    ids=lambda a: a[1],
)
def test_a_method_named_twice_is_refused(capsys, argv: list[str]) -> None:
    """``--methods ucm ucm``: a traceback from the statistics' accumulator (prosov), or the
    method's row twice (association)."""
    assert main([*argv, "--methods", "ucm", "ucm"]) == 2
    out, err = capsys.readouterr()
    assert err.strip().splitlines() == [
        "radarviz: error: --methods must name each one once (got ucm more than once)"
    ]
    assert out == ""
