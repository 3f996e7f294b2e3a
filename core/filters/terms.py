"""The per-run metric terms a filter pass forms as it goes, by name and in order.

The Monte Carlo engine (``core.filters.compiled``) can sum each run's terms scan by scan
without storing the states; ``core.metrics`` turns the sums into the per-scan statistics.
Both read the names and their order here, the engine below the statistics built on it.
"""

from __future__ import annotations

#: Names of the running sums, in the row order of ``core.metrics.MetricsAccumulator.to_arrays``:
#: the errors and squared errors in x, y, range and cross-range, the filter's own variances in
#: x and y, and the position and state NEES.
SUM_NAMES: tuple[str, ...] = (
    "ex",
    "ex2",
    "ey",
    "ey2",
    "er",
    "ec",
    "pxx",
    "pyy",
    "nees_pos",
    "nees_state",
)
