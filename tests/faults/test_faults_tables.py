"""A heavy-tailed case's report: bands of a NEES or σ never below 0, table columns never
running together (``core.experiments.prosov.TrackingResult.band95``,
``viz_app.reports.prosov.format_prosov_table``)."""

from __future__ import annotations

import json

from radarviz.core.metrics import NONNEGATIVE_METRICS
from radarviz.viz_app.cli.main import main

ARGV = ["reproduce", "prosov", "--runs", "300", "--sigma-beta-deg", "20"]


def test_at_20_degrees_no_band_of_a_nees_or_sigma_is_negative(capsys) -> None:
    """At σβ = 20° the ukf's NEES runs to 10⁴ in a few runs: its symmetric jackknife band
    reached −11 212 while every value was ≥ 1.36."""
    assert main([*ARGV, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    (case,) = doc["cases"]
    checked = 0
    for name, m in case["methods"].items():
        for key in NONNEGATIVE_METRICS & set(m["ci95"]):
            lo = [v for v in m["ci95"][key]["lo"] if v is not None]
            assert min(lo) >= 0.0, (name, key, min(lo))
            checked += 1
    assert checked >= 7 * 4


def test_the_text_table_keeps_a_space_between_columns(capsys) -> None:
    assert main(ARGV) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("    ") and "n=" not in line]
    assert rows
    for line in rows:
        cells = line[30:].split()
        assert len(cells) == 8, line  # eight scan columns, each its own word
        for cell in cells:
            assert cell == "-" or cell.count(".") == 1, line  # one number per cell
