"""Writing matplotlib figures: atomically, in the format the file suffix names."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from radarviz.viz_app.io.atomic import atomic_write
from radarviz.viz_app.palette import RADAR_SEQUENCE, hex_colour

DPI = 120


#: The series colours of every figure, in order: the radar sequence of ``viz_app.palette``
#: (Okabe–Ito). A series keeps its position, hence its colour, in every panel.
PALETTE: tuple[str, ...] = tuple(hex_colour(c) for c in RADAR_SEQUENCE)


def write_figure_atomically(fig: Figure, path: Path, dpi: int = DPI) -> None:
    """Render into a temporary file beside ``path``, then rename it onto ``path``.

    Raises ValueError (one line) if matplotlib cannot write the suffix's format; on any error
    the temporary file is removed and ``path`` is untouched.
    """
    fmt = path.suffix.lstrip(".").lower() or "png"
    supported = fig.canvas.get_supported_filetypes()
    if fmt not in supported:
        raise ValueError(
            f"cannot write a figure as .{fmt} ({path}); use one of "
            + ", ".join("." + k for k in sorted(supported))
        )
    with atomic_write(path, fsync=True) as fh:
        fig.savefig(fh, format=fmt, dpi=dpi)


def finite_points(
    xs: Sequence[Any], ys: Sequence[Any] | None, *, positive: bool = False
) -> tuple[list[float], list[float]]:
    """The (x, y) pairs of a JSON series where both are finite numbers (and y > 0 if
    ``positive``): nulls, booleans and non-numbers are skipped."""
    px: list[float] = []
    py: list[float] = []
    for x, y in zip(xs, ys or (), strict=False):
        if x is None or y is None or isinstance(x, bool) or isinstance(y, bool):
            continue
        try:
            fx, fy = float(x), float(y)
        except (TypeError, ValueError):
            continue
        if not (math.isfinite(fx) and math.isfinite(fy)) or (positive and fy <= 0.0):
            continue
        px.append(fx)
        py.append(fy)
    return px, py
