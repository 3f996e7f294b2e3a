"""``radarviz track --out X.parquet``: the track file as Parquet.

* The Parquet file read back with pyarrow is the CSV track file of the same run value for
  value: the same columns in the same order, the same text cells, and every number the
  same float64 exactly (the CSV's numbers are shortest round-trip text, so they parse back
  to the very doubles the Parquet file stores). On the block path (a labelled file of many
  targets, cut into many blocks) and on the row path (the association, ASTERIX input).
* The file is streamed: a row group per block of plots, whatever the file's length.
* An error in the middle of the input leaves no output (nor a temporary file).
"""

from __future__ import annotations

import csv
import itertools
from pathlib import Path

import numpy as np
import pytest

from radarviz.viz_app.bench.track_file import air_traffic_file
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io import plot_blocks
from radarviz.viz_app.io.plots import is_parquet

TEXT = {"target", "status", "method"}


def assert_same_tracks(csv_path: Path, parquet_path: Path) -> int:
    """The Parquet track file equals the CSV one value for value; returns the rows."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    with open(csv_path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader)
        rows = list(reader)
    table = pq.read_table(parquet_path)
    assert table.column_names == header
    assert table.num_rows == len(rows) > 0
    for k, name in enumerate(header):
        cells = [row[k] for row in rows]
        column = table.column(name)
        if name in TEXT:
            assert column.type == pa.string()
            assert column.to_pylist() == cells, name
        else:
            assert column.type == pa.float64() and column.null_count == 0
            got = column.to_numpy()
            want = np.array([float(c) for c in cells])
            assert np.array_equal(got, want), name  # exact: shortest round-trip text
    return len(rows)


def no_temporaries(directory: Path) -> bool:
    return not [p for p in directory.iterdir() if p.name.startswith(".")]


def test_the_suffix_chooses_parquet() -> None:
    assert is_parquet("t.parquet") and is_parquet("a/T.PARQUET")
    assert not is_parquet("t.csv") and not is_parquet("t.parquet.csv") and not is_parquet("t")


@pytest.mark.parametrize("three_d", [False, True], ids=["2d", "3d"])
def test_the_block_path_parquet_equals_the_csv(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, three_d: bool
) -> None:
    import pyarrow.parquet as pq

    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    plots = air_traffic_file(meas, radars, 12, 600, three_d)
    monkeypatch.setattr(plot_blocks, "BLOCK_BYTES", 4096)  # many blocks
    args = ["track", "--input", str(meas), "--radars", str(radars), "--model", "cv"]
    assert main([*args, "--out", str(tmp_path / "t.csv")]) == 0
    assert main([*args, "--out", str(tmp_path / "t.parquet")]) == 0
    rows = assert_same_tracks(tmp_path / "t.csv", tmp_path / "t.parquet")
    methods = 7  # all seven methods, 2D and 3D
    assert rows == plots * methods
    # Streamed: one row group per block of plots (whole plots, every method's row).
    meta = pq.ParquetFile(tmp_path / "t.parquet").metadata
    sizes = [meta.row_group(i).num_rows for i in range(meta.num_row_groups)]
    per_block = 4096 // 40  # a plot's line is over 40 bytes: at most this many per block
    assert len(sizes) > 5 and sum(sizes) == rows
    assert all(0 < s <= per_block * methods and s % methods == 0 for s in sizes), sizes
    # Only the text columns carry a dictionary (the floats' first try at one is wasted work).
    chunks = [meta.row_group(0).column(k) for k in range(meta.num_columns)]
    for c in chunks:
        assert c.has_dictionary_page == (c.path_in_schema in TEXT), c.path_in_schema
    assert no_temporaries(tmp_path)


@pytest.mark.parametrize("parquet", [False, True], ids=["csv", "parquet"])
def test_the_writer_starts_the_disk_writes_as_it_goes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, parquet: bool
) -> None:
    """Every ``WRITEBACK_BYTES`` written, the track file's pages so far are handed to the
    disk (``posix_fadvise`` DONTNEED on the staged file), CSV and Parquet alike, so that the
    final fsync does not wait for the whole file; the file is the same as without it."""
    import os

    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    air_traffic_file(meas, radars, 12, 600, False)
    args = ["track", "--input", str(meas), "--radars", str(radars), "--model", "cv"]
    suffix = "parquet" if parquet else "csv"
    assert main([*args, "--out", str(tmp_path / f"plain.{suffix}")]) == 0
    calls: list[tuple[int, int, int]] = []
    real = os.posix_fadvise

    def spy(fd: int, offset: int, length: int, advice: int) -> None:
        assert advice == os.POSIX_FADV_DONTNEED
        calls.append((os.fstat(fd).st_size, offset, length))
        real(fd, offset, length, advice)

    monkeypatch.setattr(plot_blocks, "BLOCK_BYTES", 4096)
    monkeypatch.setattr(plot_blocks, "WRITEBACK_BYTES", 20_000)
    monkeypatch.setattr(os, "posix_fadvise", spy)
    assert main([*args, "--out", str(tmp_path / f"t.{suffix}")]) == 0
    size = (tmp_path / f"t.{suffix}").stat().st_size
    # As the file grows, each time at least WRITEBACK_BYTES more of it is written.
    sizes = [0] + [s for s, _, _ in calls]
    assert len(calls) >= 5 and sizes[-1] <= size, (len(calls), size)
    assert all(b - a >= 20_000 for a, b in itertools.pairwise(sizes)), sizes
    if parquet:
        import pyarrow.parquet as pq

        assert pq.read_table(tmp_path / "t.parquet").equals(
            pq.read_table(tmp_path / "plain.parquet")
        )
    else:
        assert (tmp_path / "t.csv").read_bytes() == (tmp_path / "plain.csv").read_bytes()


def test_the_associated_row_path_parquet_equals_the_csv(tmp_path: Path) -> None:
    m, r = tmp_path / "m.csv", tmp_path / "r.toml"
    sim = ["simulate", "--preset", "crossing", "--out", str(m), "--radars-out", str(r)]
    assert main([*sim, "--scans", "20", "--clutter-per-scan", "1"]) == 0
    args = ["track", "--input", str(m), "--radars", str(r), "--associate", "gnn"]
    args += ["--method", "ucm", "ekf", "--model", "cv"]
    assert main([*args, "--out", str(tmp_path / "t.csv")]) == 0
    assert main([*args, "--out", str(tmp_path / "t.parquet")]) == 0
    assert_same_tracks(tmp_path / "t.csv", tmp_path / "t.parquet")
    import pyarrow.parquet as pq

    names = pq.read_schema(tmp_path / "t.parquet").names
    assert names[:4] == ["time_s", "target", "status", "method"]


def test_the_asterix_row_path_parquet_equals_the_csv(tmp_path: Path) -> None:
    ast, r = tmp_path / "m.ast", tmp_path / "r.toml"
    sim = ["simulate", "--preset", "fusion", "--out", str(ast), "--radars-out", str(r)]
    assert main([*sim, "--scans", "20", "--seed", "3"]) == 0
    args = ["track", "--input", str(ast), "--radars", str(r), "--method", "ucm", "ekf"]
    assert main([*args, "--out", str(tmp_path / "t.csv")]) == 0
    assert main([*args, "--out", str(tmp_path / "t.parquet")]) == 0
    assert_same_tracks(tmp_path / "t.csv", tmp_path / "t.parquet")


@pytest.mark.parametrize("path", ["block", "row"])
def test_an_error_mid_file_leaves_no_parquet(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    path: str,
) -> None:
    from radarviz.viz_app.io import plots

    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    extra: list[str] = []
    if path == "block":
        air_traffic_file(meas, radars, 12, 600, False)
    else:  # the association: the row path
        sim = ["simulate", "--preset", "crossing", "--out", str(meas), "--radars-out", str(radars)]
        assert main([*sim, "--scans", "40"]) == 0
        extra = ["--associate", "gnn", "--method", "ucm"]
    lines = meas.read_text().splitlines(keepends=True)
    assert len(lines) > 100
    header = lines[0].strip().replace('"', "").split(",")
    bad = len(lines) * 2 // 3
    cells = lines[bad].split(",")
    cells[header.index("range_m")] = "-5"
    lines[bad] = ",".join(cells)
    meas.write_text("".join(lines))
    # Row groups written before the error, on either path.
    monkeypatch.setattr(plot_blocks, "BLOCK_BYTES", 4096)
    monkeypatch.setattr(plots, "WRITE_BLOCK", 16)
    out = tmp_path / "t.parquet"
    args = ["track", "--input", str(meas), "--radars", str(radars), "--out", str(out), *extra]
    capsys.readouterr()
    assert main([*args, "--model", "cv"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{meas} line {bad + 1}, column range_m" in err[0], err
    assert not out.exists() and no_temporaries(tmp_path)
