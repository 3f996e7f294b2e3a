"""Writing matplotlib figures: atomically, in the format the file suffix names."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from radarviz.core.params import ParameterError
from radarviz.viz_app.io.atomic import atomic_write, check_outputs
from radarviz.viz_app.palette import RADAR_SEQUENCE, hex_colour

DPI = 120


#: The series colours of every figure, in order: the radar sequence of ``viz_app.palette``
#: (Okabe–Ito). A series keeps its position, hence its colour, in every panel.
PALETTE: tuple[str, ...] = tuple(hex_colour(c) for c in RADAR_SEQUENCE)


def figure_format(path: str | Path, flag: str = "--plot") -> str:
    """The matplotlib format a figure file's suffix names ("png" without one); a
    ``ParameterError`` naming ``flag`` and the formats there are otherwise. Checked before any
    work (``check_figure_outputs``) and again when writing, from the one list matplotlib has."""
    from matplotlib.backend_bases import FigureCanvasBase

    fmt = Path(path).suffix.lstrip(".").lower() or "png"
    supported = FigureCanvasBase.get_supported_filetypes()
    if fmt not in supported:
        raise ParameterError(
            f"{flag}: cannot write a figure as .{fmt} ({path}); use one of "
            + ", ".join("." + k for k in sorted(supported))
        )
    return fmt


def check_figure_outputs(flag: str, path: str | None) -> None:
    """``check_outputs`` of a figure file and its format, before any computing: a bad
    suffix was found only when the figure was written, after the whole experiment."""
    check_outputs([(flag, path)])
    if path is not None:
        figure_format(path, flag)


def write_figure_atomically(fig: Figure, path: Path, dpi: int = DPI) -> None:
    """Render into a staged file beside ``path`` (``viz_app.io.atomic``), then rename it onto
    ``path`` once fsynced and checked.

    Raises ``ParameterError`` (one line, ``figure_format``) if matplotlib cannot write the
    suffix's format; on any error the temporary file is removed and ``path`` is untouched.
    """
    fmt = figure_format(path)
    with atomic_write(path) as fh:
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


#: Opacity of a Monte Carlo band drawn in its series' colour (``fill_band``).
BAND_ALPHA = 0.2


def band_label(runs: Any, unit: str = "runs") -> str:
    """The legend entry of every Monte Carlo band: "95% band from N runs" (or trials)."""
    return f"95% band from {runs} {unit}"


def fill_band(
    ax: Any,
    xs: Sequence[Any],
    band: Any,
    colour: str,
    *,
    positive: bool = False,
    zorder: float = 2,
) -> bool:
    """Shade a document's {"lo": [...], "hi": [...]} band over ``xs`` in ``colour`` (light);
    points where x, lo or hi is missing or non-finite (or lo ≤ 0 with ``positive``) are left
    out. Returns whether anything was drawn."""
    if not isinstance(band, dict):
        return False
    x_lo, lo = finite_points(xs, band.get("lo"), positive=positive)
    x_hi, hi = finite_points(xs, band.get("hi"), positive=positive)
    his = dict(zip(x_hi, hi, strict=True))
    pts = [(x, y, his[x]) for x, y in zip(x_lo, lo, strict=True) if x in his]
    if not pts:
        return False
    px, plo, phi = zip(*pts, strict=True)
    ax.fill_between(px, plo, phi, color=colour, alpha=BAND_ALPHA, lw=0, zorder=zorder)
    return True
