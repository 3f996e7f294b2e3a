"""The velocity experiment as a figure (``radarviz reproduce velocity --plot FILE``).

Four panels from the JSON document of :mod:`viz_app.reports.velocity`:

1. baseline σ of Vx, Vy, Vz: first order beside Monte Carlo (the Vz needle);
2. baseline correlations ρxy, ρxz, ρyz: first order beside Monte Carlo;
3. sweep: Monte Carlo σ / first-order σ (worst component) against target distance, one line per
   altitude (dashed: the robust interquartile σ), log axes, the ±5 % band shaded;
4. sweep: the geometry diagnostic m against distance, with the warning threshold.

The Monte Carlo values carry their 95% bands from the document: error bars on the baseline's
Monte Carlo bars, and in the sweep a light band in each altitude's colour around the worst
component's ratio (the same component the line shows); the titles say how many trials.

Built on :class:`matplotlib.figure.Figure` (never pyplot) and written atomically.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from radarviz.core.velocity.estimate import AXES
from radarviz.viz_app.figures.common import (
    BAND_ALPHA,
    PALETTE,
    band_label,
    write_figure_atomically,
)
from radarviz.viz_app.palette import OKABE_ITO, hex_colour

_PAIRS = ((0, 1, "ρxy"), (0, 2, "ρxz"), (1, 2, "ρyz"))
_FIRST, _MC = hex_colour(OKABE_ITO["blue"]), hex_colour(OKABE_ITO["orange"])
WIDTH_IN, HEIGHT_IN = 12.0, 8.5


def _num(v: Any) -> float:
    return np.nan if v is None else float(v)


def _bars(
    ax: Axes,
    labels: Sequence[str],
    first: Sequence[Any],
    mc: Sequence[Any],
    fmt: str,
    mc_band: tuple[Sequence[Any], Sequence[Any]] | None = None,
    trials: Any = "?",
) -> None:
    x = np.arange(len(labels))
    w = 0.38
    f = [_num(v) for v in first]
    m = [_num(v) for v in mc]
    b1 = ax.bar(x - w / 2, f, w, color=_FIRST, label="first order")
    yerr = None
    if mc_band is not None:
        lo, hi = [_num(v) for v in mc_band[0]], [_num(v) for v in mc_band[1]]
        yerr = np.array([np.subtract(m, lo), np.subtract(hi, m)])
        yerr = np.where(np.isfinite(yerr), np.maximum(yerr, 0.0), 0.0)
    b2 = ax.bar(
        x + w / 2,
        m,
        w,
        color=_MC,
        yerr=yerr,
        capsize=3,
        error_kw={"lw": 0.9},
        label="Monte Carlo" + ("" if yerr is None else f" ({band_label(trials, 'trials')})"),
    )
    for bars in (b1, b2):
        ax.bar_label(bars, fmt=fmt, fontsize=8, padding=2)
    ax.set_xticks(x, labels)
    ax.axhline(0.0, color="0.3", lw=0.6)
    ax.margins(y=0.15)
    ax.legend(fontsize=9, frameon=False)


def _sweep_series(
    sweep: Sequence[Mapping[str, Any]], key: str
) -> dict[float, tuple[list[float], list[float]]]:
    """altitude → (distances, worst-component values of ``key``), finite values only."""
    out: dict[float, tuple[list[float], list[float]]] = {}
    for p in sweep:
        vals = p.get(key)
        if isinstance(vals, Sequence):
            vals = [v for v in vals if v is not None]
            val = max(vals, key=lambda r: abs(np.log(r))) if vals else None
        else:
            val = vals
        if val is None or not np.isfinite(val) or val <= 0:
            continue
        xs, ys = out.setdefault(float(p["altitude_km"]), ([], []))
        xs.append(float(p["distance_km"]))
        ys.append(float(val))
    return out


def _worst(vals: Sequence[Any]) -> int | None:
    """Index of the component farthest from 1 on a log scale (the one ``_sweep_series`` shows)."""
    ok = [(i, float(v)) for i, v in enumerate(vals) if v is not None and float(v) > 0]
    return max(ok, key=lambda iv: abs(np.log(iv[1])))[0] if ok else None


def _sweep_bands(
    sweep: Sequence[Mapping[str, Any]], key: str
) -> dict[float, tuple[list[float], list[float], list[float]]]:
    """altitude → (distances, lo, hi) of the band of ``key`` for the component ``_worst``
    picks; points without a finite positive band are left out."""
    out: dict[float, tuple[list[float], list[float], list[float]]] = {}
    for p in sweep:
        vals, band = p.get(key), p.get(key + "_ci95")
        if not isinstance(vals, Sequence) or not isinstance(band, Mapping):
            continue
        i = _worst(vals)
        if i is None:
            continue
        lo, hi = _num(band["lo"][i]), _num(band["hi"][i])
        if not (np.isfinite(lo) and np.isfinite(hi)) or lo <= 0:
            continue
        xs, los, his = out.setdefault(float(p["altitude_km"]), ([], [], []))
        xs.append(float(p["distance_km"]))
        los.append(lo)
        his.append(hi)
    return out


def _build_figure(doc: Mapping[str, Any]) -> Figure:
    fig = Figure(figsize=(WIDTH_IN, HEIGHT_IN), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axs = fig.subplots(2, 2)
    b = doc["baseline"]
    trials = doc.get("trials", "?")
    band = b.get("sigma_mc_ci95_mps")
    _bars(
        axs[0, 0],
        AXES,
        b["sigma_first_order_mps"],
        b["sigma_mc_mps"],
        "%.2f",
        (band["lo"], band["hi"]) if band else None,
        trials,
    )
    axs[0, 0].set_ylabel("σ of the velocity error, m/s")
    axs[0, 0].set_title(
        f"Baseline σ (condition number {b['condition_number']:.2f}, m = {b['m']:.3f})", fontsize=10
    )
    cf, cm = b["corr_first_order"], b["corr_mc"]
    cb = b.get("corr_mc_ci95")
    _bars(
        axs[0, 1],
        [p[2] for p in _PAIRS],
        [cf[i][j] for i, j, _ in _PAIRS],
        [cm[i][j] for i, j, _ in _PAIRS],
        "%.3f",
        ([cb["lo"][i][j] for i, j, _ in _PAIRS], [cb["hi"][i][j] for i, j, _ in _PAIRS])
        if cb
        else None,
        trials,
    )
    axs[0, 1].set_ylabel("correlation coefficient")
    axs[0, 1].set_title("Baseline correlations of (Vx, Vy, Vz) errors", fontsize=10)

    sweep = doc.get("sweep") or []
    ratio = _sweep_series(sweep, "ratio_mc_to_linear")
    robust = _sweep_series(sweep, "ratio_robust_to_linear")
    mser = _sweep_series(sweep, "m")
    colours = {h: PALETTE[i % len(PALETTE)] for i, h in enumerate(sorted(set(ratio) | set(mser)))}
    ax = axs[1, 0]
    ax.axhspan(0.95, 1.05, color="0.9", zorder=0, label="±5 %")
    ax.axhline(1.0, color="0.4", lw=0.8)
    for h, (xs, ys) in sorted(ratio.items()):
        ax.plot(xs, ys, "o-", color=colours[h], lw=1.5, ms=4, label=f"h = {h:g} km")
    for h, (xs, ys) in sorted(robust.items()):
        ax.plot(xs, ys, "--", color=colours[h], lw=1.0)
    banded = False
    for key in ("ratio_mc_to_linear", "ratio_robust_to_linear"):
        for h, (xs, lo, hi) in sorted(_sweep_bands(sweep, key).items()):
            ax.fill_between(xs, lo, hi, color=colours[h], alpha=BAND_ALPHA, lw=0, zorder=1)
            banded = True
    ax.plot([], [], "k--", lw=1.0, label="robust (IQR) σ")
    if banded:
        ax.fill_between(
            [],
            [],
            [],
            color="0.3",
            alpha=BAND_ALPHA,
            label=band_label(doc.get("sweep_trials"), "trials"),
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("horizontal distance of the target from the radars' centroid, km")
    ax.set_ylabel("Monte Carlo σ / first-order σ (worst of Vx, Vy, Vz)")
    ax.set_title(
        f"Where the linear statistics stop holding ({doc.get('sweep_trials')} trials per point)",
        fontsize=10,
    )
    ax.legend(fontsize=8, frameon=False, loc="upper left")
    ax = axs[1, 1]
    for h, (xs, ys) in sorted(mser.items()):
        ax.plot(xs, ys, "o-", color=colours[h], lw=1.5, ms=4, label=f"h = {h:g} km")
    m_warn = doc.get("m_warn")
    if m_warn is not None:
        ax.axhline(
            float(m_warn),
            color=hex_colour(OKABE_ITO["vermillion"]),
            ls="--",
            lw=1.0,
            label=f"warning threshold m = {float(m_warn):g}",
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("horizontal distance of the target from the radars' centroid, km")
    ax.set_ylabel("m = max √(σε² + cos²ε σβ²) / σmin(C)")
    ax.set_title("Geometry diagnostic m", fontsize=10)
    ax.legend(fontsize=8, frameon=False, loc="upper left")
    for a in axs.ravel():
        a.grid(True, which="major", color="0.88", lw=0.6)
    fig.suptitle(
        f"Velocity vector from three radial velocities — {doc.get('trials')} trials, "
        f"seed {doc.get('seed')}"
    )
    return fig


def plot_velocity(doc: dict, path: str | os.PathLike) -> None:
    """Draw the velocity document ``doc`` into the image file ``path`` (format from suffix).

    Raises:
        ValueError: ``doc`` has no baseline, or the suffix is not an image format.
    """
    if not isinstance(doc, Mapping) or not isinstance(doc.get("baseline"), Mapping):
        raise ValueError("velocity document has no baseline: nothing to plot")
    out = Path(os.fsdecode(os.fspath(path)))
    write_figure_atomically(_build_figure(doc), out)
