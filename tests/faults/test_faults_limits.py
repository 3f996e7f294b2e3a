"""Documented maximums that failed: ``reproduce association --gospa-order 100`` raised an
OverflowError (c^p beyond a float), and ``simulate --scans 10000000`` ran a minute before a
MemoryError (its plots are made in memory). Each maximum is now one that works, and one past
it is refused in one line before any work."""

from __future__ import annotations

import json
from pathlib import Path

from radarviz.core.params import PARAMETERS
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io.plots import MAX_SIMULATE_STEPS


def run(capsys, *argv: str) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err.strip()


def test_the_largest_gospa_order_works_at_the_largest_cutoff(capsys) -> None:
    order = PARAMETERS["gospa_order"].high
    cutoff = PARAMETERS["gospa_cutoff_m"].high
    argv = ["reproduce", "association", "--runs", "3", "--scans", "10", "--methods", "ucm"]
    code, out, err = run(
        capsys, *argv, "--gospa-order", f"{order:g}", "--gospa-cutoff-m", f"{cutoff:g}", "--json"
    )
    assert code == 0, err
    doc = json.loads(out)  # written with allow_nan=False: every value finite or null
    assert doc["gospa"] == {"cutoff_m": cutoff, "order": order}
    code, out, err = run(capsys, *argv, "--gospa-order", f"{order + 1:g}")
    assert code == 2 and out == "", err
    (line,) = err.splitlines()
    assert line == (
        f"radarviz: error: --gospa-order must be a finite number in [1, {order:g}] "
        f"(got {order + 1!r})"
    )


def test_simulate_refuses_more_scans_than_it_can_hold(tmp_path: Path, capsys) -> None:
    out, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    argv = ["simulate", "--preset", "fusion", "--out", str(out), "--radars-out", str(radars)]
    code, _, err = run(capsys, *argv, "--scans", str(MAX_SIMULATE_STEPS + 1))
    assert code == 2, err
    (line,) = err.splitlines()
    assert line == (
        f"radarviz: error: --scans must be an integer in [2, {MAX_SIMULATE_STEPS}] "
        f"(got {MAX_SIMULATE_STEPS + 1})"
    )
    assert not out.exists() and not radars.exists()
