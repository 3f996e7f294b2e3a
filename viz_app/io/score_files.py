"""``radarviz score``'s inputs: the truth file and a track file, read into the arrays of
``core.tracking.scoring``.

Both are CSV (header line first) or Parquet, told apart by content: a file that starts with
Parquet's magic bytes ``PAR1`` (or is named ``*.parquet``) is read as Parquet, any other as
CSV. Row numbers in the messages count the data rows from 1 (a CSV's row N is on line N + 1
when it has no blank lines).

Truth file, one row per truth time and target::

    time_s, target, x_m, y_m [, z_m] [, vx_mps, vy_mps [, vz_mps]]

(s, any label, m, m/s; vz_mps needs z_m; no two rows of one time and target). Track file:
``radarviz track``'s (``viz_app.io.plots``), or any file with at least ``time_s``,
``method``, ``x_m`` and ``y_m``; the optional columns used are ``target`` (the track id;
without it each method is one track), ``status`` (``tentative`` or ``confirmed``), ``z_m``,
``vx_mps``, ``vy_mps``, ``vz_mps`` and the position covariance ``p_xx_m2``, ``p_xy_m2``,
``p_yy_m2`` (with ``p_xz_m2``, ``p_yz_m2``, ``p_zz_m2`` in 3D); other columns are ignored.
Every number must be finite, every time within ±``MAX_TIME_S``, every variance ≥ 0; a bad
cell is one ``ParameterError`` line naming the file, the row and the column.
"""

from __future__ import annotations

import csv
import math
import os
from typing import Any

import numpy as np
from numpy.typing import NDArray

from radarviz.core.params import PARAMETERS, ParameterError
from radarviz.core.tracking.association import CONFIRMED, TENTATIVE
from radarviz.core.tracking.scoring import TrackRows, Truth
from radarviz.viz_app.io.plots import covariance_column

#: The first bytes of a Parquet file.
PARQUET_MAGIC = b"PAR1"
#: Largest |time| accepted (the plots' bound, ``core.params`` time_s).
MAX_TIME_S = float(PARAMETERS["time_s"].high)

TRUTH_REQUIRED = ("time_s", "target", "x_m", "y_m")
TRUTH_OPTIONAL = ("z_m", "vx_mps", "vy_mps", "vz_mps")
TRACK_REQUIRED = ("time_s", "method", "x_m", "y_m")
TRACK_VELOCITY = ("vx_mps", "vy_mps", "vz_mps")
#: Position covariance columns: (column, row, col) of the 3 × 3 block; the first three needed.
TRACK_COVARIANCE = (
    *(
        (covariance_column("xyz"[i], "xyz"[j]), i, j)
        for i, j in ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))
    ),
)
STATUSES = (TENTATIVE, CONFIRMED)
#: A track file's text columns; every other column used is a number.
TEXT = frozenset({"target", "method", "status"})


def is_parquet_file(path: str | os.PathLike) -> bool:
    """Parquet by its magic bytes, or by a ``.parquet`` name (then a broken file is named)."""
    with open(path, "rb") as fh:
        head = fh.read(len(PARQUET_MAGIC))
    return head == PARQUET_MAGIC or os.fspath(path).lower().endswith(".parquet")


def _read_table(path: str) -> Any:
    """The file as a pyarrow table of strings (CSV) or of its own types (Parquet)."""
    import pyarrow as pa

    if is_parquet_file(path):
        import pyarrow.parquet as pq

        try:
            return pq.read_table(path)
        except (pa.ArrowInvalid, OSError) as exc:
            raise ParameterError(
                f"{path}: not a readable Parquet file ({_first_line(exc)})"
            ) from None
    import pyarrow.csv as pcsv

    with open(path, newline="", encoding="utf-8", errors="replace") as fh:
        header = next(csv.reader(fh), None)
    if not header:
        raise ParameterError(f"{path} line 1: missing header")
    names = [h.strip() for h in header]
    for h in names:
        if names.count(h) > 1:
            raise ParameterError(f"{path} line 1, column {h}: appears twice")
    try:
        return pcsv.read_csv(
            path,
            read_options=pcsv.ReadOptions(column_names=names, skip_rows=1),
            convert_options=pcsv.ConvertOptions(
                column_types={h: pa.string() for h in names}, strings_can_be_null=False
            ),
        )
    except pa.ArrowInvalid as exc:
        raise ParameterError(f"{path}: not a readable CSV file ({_first_line(exc)})") from None


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _numbers(
    path: str, table: Any, column: str, *, bound: float | None = None, nonnegative: bool = False
) -> NDArray[np.float64]:
    """Column ``column`` as float64, each value checked; the first bad one is named."""
    import pyarrow as pa
    import pyarrow.compute as pc

    col = table.column(column)
    try:
        values = pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False)
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
        values = np.array([_to_float(v) for v in col.to_pylist()])
    values = np.asarray(values, dtype=np.float64)
    bad = ~np.isfinite(values)
    if bound is not None:
        bad |= np.abs(values) > bound
    if nonnegative:
        bad |= values < 0
    if bad.any():
        row = int(np.argmax(bad))
        want = "a finite number"
        if bound is not None:
            want += f" in [-{bound:g}, {bound:g}]"
        if nonnegative:
            want += " >= 0"
        got = col[row].as_py()
        raise ParameterError(f"{path} row {row + 1}, column {column}: must be {want} (got {got!r})")
    return values


def _to_float(v: object) -> float:
    try:
        return float(v)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan


def _labels(path: str, table: Any, column: str) -> NDArray[np.str_]:
    """Column ``column`` as text labels (numbers as written); an empty one is named."""
    import pyarrow as pa
    import pyarrow.compute as pc

    col = table.column(column)
    if col.null_count:
        row = int(np.argmax(col.is_null().to_numpy(zero_copy_only=False)))
        raise ParameterError(f"{path} row {row + 1}, column {column}: must not be empty")
    text = pc.utf8_trim_whitespace(pc.cast(col, pa.string()))
    values = np.asarray(text.to_numpy(zero_copy_only=False), dtype=str)
    empty = values == ""
    if empty.any():
        row = int(np.argmax(empty))
        raise ParameterError(f"{path} row {row + 1}, column {column}: must not be empty")
    return values


def _require(path: str, names: list[str], required: tuple[str, ...]) -> None:
    for h in required:
        if h not in names:
            raise ParameterError(f"{path} line 1, column {h}: missing")


def read_truth(path: str) -> Truth:
    """The truth file (module docstring) as ``Truth``."""
    table = _read_table(path)
    names = list(table.column_names)
    known = TRUTH_REQUIRED + TRUTH_OPTIONAL
    for h in names:
        if h not in known:
            raise ParameterError(
                f"{path} line 1, column {h}: unknown column (expected {', '.join(known)})"
            )
    _require(path, names, TRUTH_REQUIRED)
    if ("vx_mps" in names) != ("vy_mps" in names):
        missing = "vy_mps" if "vx_mps" in names else "vx_mps"
        raise ParameterError(
            f"{path} line 1, column {missing}: missing (vx_mps and vy_mps go together)"
        )
    if "vz_mps" in names and ("vx_mps" not in names or "z_m" not in names):
        raise ParameterError(f"{path} line 1, column vz_mps: needs z_m, vx_mps and vy_mps")
    if table.num_rows == 0:
        raise ParameterError(f"{path}: no rows after the header")
    times = _numbers(path, table, "time_s", bound=MAX_TIME_S)
    targets = _labels(path, table, "target")
    pos_cols = ["x_m", "y_m"] + (["z_m"] if "z_m" in names else [])
    position = np.stack([_numbers(path, table, c) for c in pos_cols], axis=1)
    velocity = None
    if "vx_mps" in names:
        vel_cols = ["vx_mps", "vy_mps"] + (["vz_mps"] if "vz_mps" in names else [])
        velocity = np.stack([_numbers(path, table, c) for c in vel_cols], axis=1)
    _no_duplicates(path, times, targets)
    return Truth(times, targets, position, velocity)


def _no_duplicates(path: str, times: NDArray[np.float64], targets: NDArray[np.str_]) -> None:
    """Refuse two truth rows of one time and target (naming the second)."""
    order = np.lexsort((np.arange(len(times)), targets, times))
    same = (times[order][1:] == times[order][:-1]) & (targets[order][1:] == targets[order][:-1])
    if same.any():
        rows = np.sort(order[1:][same])
        row = int(rows[0])
        raise ParameterError(
            f"{path} row {row + 1}, column target: a second row of target {str(targets[row])!r} "
            f"at time {times[row]:g}"
        )


class TrackFile:
    """A track file's rows per method (module docstring).

    Attributes:
        n_rows: rows in the file.
        methods: the methods in order of first appearance.
        rows: method → its ``TrackRows``.
        has_status, has_covariance, has_velocity, has_target: which optional columns it has.
    """

    def __init__(self, path: str) -> None:
        table = _read_table(path)
        names = list(table.column_names)
        _require(path, names, TRACK_REQUIRED)
        if table.num_rows == 0:
            raise ParameterError(f"{path}: no rows after the header")
        self.has_target = "target" in names
        self.has_status = "status" in names
        self.has_velocity = "vx_mps" in names and "vy_mps" in names
        self.has_covariance = all(c in names for c, _, _ in TRACK_COVARIANCE[:3])
        self.n_rows = n = table.num_rows
        times = _numbers(path, table, "time_s", bound=MAX_TIME_S)
        methods = _labels(path, table, "method")
        tracks = _labels(path, table, "target") if self.has_target else np.full(n, "track")
        position = np.zeros((n, 3))
        for i, c in enumerate(("x_m", "y_m", "z_m")):
            if c in names:
                position[:, i] = _numbers(path, table, c)
        velocity = None
        if self.has_velocity:
            velocity = np.zeros((n, 3))
            for i, c in enumerate(TRACK_VELOCITY):
                if c in names:
                    velocity[:, i] = _numbers(path, table, c)
        cov = None
        if self.has_covariance:
            cov = np.zeros((n, 3, 3))
            for c, i, j in TRACK_COVARIANCE:
                if c in names:
                    cov[:, i, j] = cov[:, j, i] = _numbers(path, table, c, nonnegative=i == j)
        confirmed = None
        if self.has_status:
            status = _labels(path, table, "status")
            bad = ~np.isin(status, STATUSES)
            if bad.any():
                row = int(np.argmax(bad))
                raise ParameterError(
                    f"{path} row {row + 1}, column status: must be one of "
                    f"{', '.join(STATUSES)} (got {str(status[row])!r})"
                )
            confirmed = status == CONFIRMED
        _, first = np.unique(methods, return_index=True)
        self.methods: list[str] = [str(methods[i]) for i in np.sort(first)]
        self.rows: dict[str, TrackRows] = {}
        for m in self.methods:
            sel = methods == m
            self.rows[m] = TrackRows(
                times[sel],
                tracks[sel],
                position[sel],
                None if velocity is None else velocity[sel],
                None if cov is None else cov[sel],
                None if confirmed is None else confirmed[sel],
            )
