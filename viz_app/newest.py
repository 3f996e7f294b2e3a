"""The newest values of a stream of numbers, in memory that does not grow with the stream.

A session that runs for hours (``radarviz live``) keeps its latencies and the values that
frame its views this way: a ring of ``kept`` values allocated and written at the start, so the
memory it will ever hold is taken at once and stays the same.
"""

from __future__ import annotations

from array import array

import numpy as np


class NewestValues:
    """The newest ``kept`` values of a stream of numbers, or every one (``kept`` None).

    Bounded (``kept`` given): a ring of ``kept`` values allocated and written at the start,
    so the memory it will ever hold is taken at once and stays the same; a stream that runs
    for hours (``radarviz live``) neither fills nor frees anything as it goes. (A list of
    every call's small arrays, trimmed when it reached twice ``kept``, rose for minutes
    before its first trim and then swung up and down with it.) Unbounded: packed values
    (``array``), every one, for a file's whole run."""

    def __init__(self, kept: int | None, dtype: type = np.float64):
        self.kept = kept
        self.dtype = np.dtype(dtype)
        self._ring = None if kept is None else np.full(kept, np.nan, dtype=self.dtype)
        self._packed = array("f" if self.dtype == np.float32 else "d") if kept is None else None
        self._n = 0

    def add(self, values: np.ndarray | list[float]) -> None:
        v = np.ravel(np.asarray(values, dtype=self.dtype))
        if self._ring is None:
            assert self._packed is not None
            self._packed.frombytes(v.tobytes())
            self._n += v.shape[0]
            return
        ring, k = self._ring, self._ring.shape[0]
        v = v[-k:]
        at = self._n % k
        head = min(v.shape[0], k - at)
        ring[at : at + head] = v[:head]
        ring[: v.shape[0] - head] = v[head:]
        self._n += v.shape[0]

    def values(self) -> np.ndarray:
        """The values kept (a copy; in no particular order once a ring has wrapped)."""
        if self._ring is None:
            return np.frombuffer(self._packed, dtype=self.dtype).copy()
        return self._ring[: min(self._n, self._ring.shape[0])].copy()

    def __len__(self) -> int:
        return self._n if self._ring is None else min(self._n, self._ring.shape[0])
