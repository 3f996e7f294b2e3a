"""The association experiment as a figure (``radarviz reproduce association --plot FILE``).

Three panels from the JSON document of :mod:`viz_app.reports.association`:

1. mean GOSPA per scan, one line per method, with its 95% band shaded (the crossing is at the
   middle scan, marked);
2. the GOSPA parts per method: mean localisation, missed and false parts per scan (m^p),
   stacked, with the 95% band of each part as an error bar;
3. track swaps and false tracks per run, per method, with their 95% bands.

Built on :class:`matplotlib.figure.Figure` (never pyplot) and written atomically.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from radarviz.viz_app.figures.common import PALETTE, band_label, fill_band, write_figure_atomically

WIDTH_IN, HEIGHT_IN = 15.0, 4.8
_PARTS = (("localisation_m_p", "localisation"), ("missed_m_p", "missed"), ("false_m_p", "false"))


def _err(b: dict[str, Any]) -> list[float]:
    return [max(b["mean"] - b["lo"], 0.0), max(b["hi"] - b["mean"], 0.0)]


def plot_association(doc: dict[str, Any], path: str | os.PathLike) -> None:
    """Write the three panels (module docstring) to ``path``, in the format its suffix names."""
    fig = Figure(figsize=(WIDTH_IN, HEIGHT_IN), layout="constrained")
    FigureCanvasAgg(fig)
    ax1, ax2, ax3 = fig.subplots(1, 3)
    times = doc["times_s"]
    methods = list(doc["methods"])
    runs = doc["runs"]
    for k, m in enumerate(methods):
        e = doc["methods"][m]["gospa_per_scan_m"]
        colour = PALETTE[k % len(PALETTE)]
        ax1.plot(times, e["mean"], color=colour, lw=1.4, label=m)
        fill_band(ax1, times, e, colour)
    ax1.axvline((times[0] + times[-1]) / 2.0, color="0.5", lw=0.8, ls=":", label="crossing")
    ax1.set(
        xlabel="time (s)", ylabel="GOSPA (m)", title=f"mean GOSPA per scan ({band_label(runs)})"
    )
    ax1.legend(fontsize=8, ncol=2)

    x = np.arange(len(methods))
    bottom = np.zeros(len(methods))
    for j, (key, label) in enumerate(_PARTS):
        bands = [doc["methods"][m][key] for m in methods]
        vals = np.array([b["mean"] for b in bands])
        err = np.array([_err(b) for b in bands]).T
        ax2.bar(x, vals, 0.6, bottom=bottom, color=PALETTE[(j + 3) % len(PALETTE)], label=label)
        ax2.errorbar(x, bottom + vals, yerr=err, fmt="none", ecolor="0.2", capsize=3, lw=0.8)
        bottom += vals
    p = doc["gospa"]["order"]
    ax2.set_xticks(x, methods)
    ax2.set(ylabel=f"mean part per scan (m^{p:g})", title="GOSPA^p = localisation + missed + false")
    ax2.legend(fontsize=8)

    w = 0.38
    for j, (key, label) in enumerate((("swaps", "track swaps"), ("false_tracks", "false tracks"))):
        bands = [doc["methods"][m][key] for m in methods]
        vals = [b["mean"] for b in bands]
        err = np.array([_err(b) for b in bands]).T
        ax3.bar(x + (j - 0.5) * w, vals, w, yerr=err, capsize=3, color=PALETTE[j + 1], label=label)
    ax3.set_xticks(x, methods)
    ax3.set(ylabel="per run", title="swaps and false tracks per run")
    ax3.legend(fontsize=8)
    s = doc["scene"]
    fig.suptitle(
        f"GNN association: {s['targets']} targets crossing at {s['crossing_angle_deg']:g}°, "
        f"P_D {s['detection_prob']:g}, {s['clutter_per_scan']:g} false plots per scan"
    )
    write_figure_atomically(fig, Path(path))
