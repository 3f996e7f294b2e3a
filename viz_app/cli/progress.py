"""A minimal progress bar on standard error for long Monte Carlo runs."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """Callable as ``bar(done, total)``; redraws in place on a terminal, else prints every 10%.

    Args:
        label: text before the bar.
        stream: where to draw (standard error by default, so ``--json`` stdout stays clean).
    """

    def __init__(self, label: str, stream: TextIO | None = None) -> None:
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.start = time.perf_counter()
        self._tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self._last_decile = -1

    def __call__(self, done: int, total: int) -> None:
        frac = done / total if total else 1.0
        elapsed = time.perf_counter() - self.start
        eta = elapsed / frac - elapsed if frac > 0 else float("nan")
        if self._tty:
            width = 30
            filled = round(width * frac)
            bar = "#" * filled + "-" * (width - filled)
            self.stream.write(
                f"\r{self.label} [{bar}] {done}/{total} runs  {elapsed:5.1f} s  eta {eta:5.1f} s"
            )
            if done >= total:
                self.stream.write("\n")
            self.stream.flush()
            return
        decile = int(frac * 10)
        if decile > self._last_decile:
            self._last_decile = decile
            self.stream.write(
                f"{self.label}: {done}/{total} runs ({100 * frac:.0f}%), {elapsed:.1f} s\n"
            )
            self.stream.flush()
