"""Figure of ``radarviz reproduce doppler``: one panel per radar, the position NEES of the EKF
with each Doppler update against the scan, with its 95% Monte Carlo band and the χ² range of a
consistent filter (grey), on a log axis."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from matplotlib.ticker import LogFormatter

from radarviz.viz_app.figures.common import (
    DPI,
    PALETTE,
    band_label,
    fill_band,
    finite_points,
    write_figure_atomically,
)
from radarviz.viz_app.reports.doppler import UPDATE_LABEL

_COLOUR = {
    "range_doppler": PALETTE[0],
    "range_converted_doppler": PALETTE[1],
    "range_joint_doppler": PALETTE[2],
}


def _panel(ax: Any, case: Mapping[str, Any], runs: Any) -> None:
    ns = case.get("n") or []
    lo, hi = case["nees_pos_band95"]
    ax.axhspan(lo, hi, color="0.75", alpha=0.6, zorder=0, label="consistent filter's 95% range")
    ax.axhline(2.0, color="black", lw=0.8, ls=":", zorder=1, label="nominal 2")
    for v, series in (case.get("variants") or {}).items():
        colour = _COLOUR.get(v, PALETTE[2])
        fill_band(ax, ns, series.get("nees_pos_ci95"), colour, positive=True)
        x, y = finite_points(ns, series.get("nees_pos"), positive=True)
        ax.plot(x, y, color=colour, lw=1.6, zorder=3, label=UPDATE_LABEL.get(v, v))
    ax.set_yscale("log")
    # Plain numbers ("2", "10") rather than 2×10⁰.
    ax.yaxis.set_major_formatter(LogFormatter(labelOnlyBase=False))
    ax.yaxis.set_minor_formatter(LogFormatter(labelOnlyBase=False, minor_thresholds=(1.0, 0.5)))
    ax.set_title(
        f"{case['radar']}: σr = {case['sigma_r_m']:g} m, σVr = {case['sigma_vr_mps']:g} m/s,"
        f" T = {case['period_s']:g} s",
        fontsize=10,
    )
    ax.set_xlabel("scan n")
    ax.set_ylabel("position NEES")
    ax.grid(True, which="both", alpha=0.3)


def plot_doppler(doc: dict, path: str | os.PathLike) -> None:
    """Draw the document of ``radarviz reproduce doppler --json`` into the image ``path``.

    Raises:
        ValueError: the document has no cases, or the suffix is not an image format.
    """
    cases = doc.get("cases") if isinstance(doc, Mapping) else None
    if not cases:
        raise ValueError("doppler document has no cases: nothing to plot")
    cols = min(3, len(cases))
    rows = math.ceil(len(cases) / cols)
    fig = Figure(figsize=(5.0 * cols, 3.6 * rows + 1.2), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax, case in zip(axes.flat, cases, strict=False):
        _panel(ax, case, doc.get("runs"))
    for ax in list(axes.flat)[len(cases) :]:
        ax.set_visible(False)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    handles.append(Patch(color=PALETTE[0], alpha=0.2))
    labels.append(band_label(doc.get("runs")) + " (shaded, per update)")
    fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=9)
    fig.suptitle(
        "EKF + Doppler: line-of-sight, converted r̂·V̂r and joint (correlated) updates"
        f" — σβ = {doc.get('sigma_beta_deg')}°, {doc.get('runs')} runs"
    )
    write_figure_atomically(fig, Path(os.fsdecode(os.fspath(path))), DPI)
