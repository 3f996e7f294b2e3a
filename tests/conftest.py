"""Helpers shared by the test modules (pytest imports this file; tests never import each other)."""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import pyarrow as pa
import pytest

RrdContents = tuple[dict[str, int], dict[str, dict[str, list]]]


def read_rrd(path: Path) -> RrdContents:
    """Temporal rows per entity, and the temporal columns of each entity, of a ``.rrd`` file."""
    from rerun.chunk import RrdReader

    rows: dict[str, int] = defaultdict(int)
    cols: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for chunk in RrdReader(str(path)).stream():
        if chunk.is_static:
            rows.setdefault(chunk.entity_path, 0)
            continue
        rows[chunk.entity_path] += chunk.num_rows
        rb = chunk.to_record_batch()
        for name, field in zip(rb.schema.names, rb.schema, strict=True):
            col = rb.column(name)
            if pa.types.is_timestamp(field.type):
                continue  # log time: not ours to check
            if pa.types.is_duration(field.type):
                col = col.cast(pa.int64())  # nanoseconds
            cols[chunk.entity_path][name].extend(col.to_pylist())
    return rows, cols


@pytest.fixture
def rrd_contents() -> Callable[[Path], RrdContents]:
    """``read_rrd`` as a fixture, for tests that read a recording back."""
    return read_rrd
