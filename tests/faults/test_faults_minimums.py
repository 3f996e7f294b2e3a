"""The documented minimum of a Monte Carlo count works, or is refused up front: with two runs
every leave-out of the delete-a-group jackknife held one run, so every σ band was NaN and the
command failed after computing (exit 1). The minimum is now what gives every band."""

from __future__ import annotations

import json

import pytest

from radarviz.core.params import PARAMETERS
from radarviz.core.velocity.estimate import MIN_SWEEP_TRIALS
from radarviz.viz_app.cli.main import main


def run(capsys, *argv: str) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err.strip()


@pytest.mark.parametrize(
    ("argv", "minimum"),
    [
        (["reproduce", "prosov", "--runs"], PARAMETERS["runs"].low),
        (["reproduce", "gorshkov", "--trials"], PARAMETERS["trials"].low),
        (["reproduce", "velocity", "--trials"], MIN_SWEEP_TRIALS),
    ],
)
def test_the_minimum_count_gives_every_band_and_one_fewer_is_refused(
    capsys, argv: list[str], minimum: int
) -> None:
    code, out, err = run(capsys, *argv, str(minimum), "--json")
    assert code == 0, err
    json.loads(out)  # every value finite or null (allow_nan=False when written)
    code, out, err = run(capsys, *argv, str(minimum - 1))
    assert code == 2 and out == "", err
    (line,) = err.splitlines()
    assert line.startswith(f"radarviz: error: {argv[-1]} must be an integer "), line
    assert (f">= {minimum} " in line or f"in [{minimum}, " in line) and "(got" in line, line
