"""The Gorshkov reproduction as a figure (the paper's Figs. 1–3).

Drawn from the JSON document of ``radarviz reproduce gorshkov --json`` (see
:mod:`viz_app.reports.gorshkov`): three rows, one per state component (range r, radial
velocity Vr, radial acceleration a), two columns:

* left: σ of the finite-memory filter's error against the window length k on a log axis, every
  radar in its own colour — Monte Carlo σ as small markers (hollow: range only, filled:
  range + Doppler), analytic sqrt(R_ii) as lines (dashed: range only, solid: range + Doppler);
* right: the gain K(k) = (σ_range-only − σ_range+Vr) / σ_range-only · 100 % per radar; in the
  range row each radar's peak is marked and listed beside the paper's claims.

The Monte Carlo σ and gains carry their 95% bands (the document's ``sigma_ci95`` and
``gain_ci95_percent``), shaded lightly in the radar's colour; the styles legend says how many
trials they come from.

Radars whose analytic curves coincide exactly (range-only σr depends on σr alone, range-only σVr
and σa on σr and T) are drawn in interleaved dashes, so every colour stays visible.

The figure is built on :class:`matplotlib.figure.Figure` directly, so importing or calling this
module never touches pyplot or the global backend, and it is written atomically.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import LogFormatter, MaxNLocator

from radarviz.viz_app.figures.common import (
    BAND_ALPHA,
    PALETTE,
    band_label,
    fill_band,
    finite_points,
    write_figure_atomically,
)

#: Radar presets in display order; each keeps its colour in every panel (and in any subset).
RADAR_ORDER: tuple[str, ...] = ("RLS1", "RLS2", "RLS3", "RLS4", "RLS5", "RLS6")
#: Rows: key in the document, symbol, unit.
_STATES: tuple[tuple[str, str, str], ...] = (
    ("r_m", "r", "m"),
    ("vr_mps", "Vr", "m/s"),
    ("a_mps2", "a", "m/s²"),
)
_VARIANTS: tuple[str, ...] = ("range_only", "range_doppler")
#: Dashed analytic line and hollow MC marker (range only) or solid and filled; legend label.
_DASHED = {"range_only": True, "range_doppler": False}
_VARIANT_LABEL = {"range_only": "range only", "range_doppler": "range + Doppler Vr"}
#: Dash length in points for the analytic lines (and the gap of the dashed variant).
DASH_PT = 5.0
GAP_PT = 3.0
LINE_WIDTH = 1.4
MARKER_SIZE = 3.2
#: The paper's claims on the range gain: (radar, peak %, k).
PAPER_RANGE_PEAKS: tuple[tuple[str, float, int], ...] = (("RLS1", 20.0, 3), ("RLS6", 55.0, 9))
#: Two analytic series coincide when every value agrees to this relative tolerance.
COINCIDE_RTOL = 1e-9
#: Fraction of the axes' height left between the data and the legend above it.
LEGEND_PAD = 0.04

WIDTH_IN = 12.0
HEIGHT_IN = 11.0
DPI = 120


def _broken(
    xs: Sequence[Any], ys: Sequence[Any] | None, *, positive: bool = False
) -> tuple[list[float], list[float]]:
    """Like :func:`_points`, but an undefined value becomes NaN so that the line breaks there."""
    px: list[float] = []
    py: list[float] = []
    for x, y in zip(xs, ys or (), strict=False):
        fx = _number(x)
        if fx is None:
            continue
        fy = _number(y)
        if fy is None or (positive and fy <= 0.0):
            fy = math.nan
        px.append(fx)
        py.append(fy)
    return px, py


def _number(v: Any) -> float | None:
    if v is None or isinstance(v, bool):
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _get(mapping: Any, *keys: str) -> Any:
    """``mapping[k1][k2]...`` or None when any level is missing or not a mapping."""
    for key in keys:
        if not isinstance(mapping, Mapping):
            return None
        mapping = mapping.get(key)
    return mapping


def _name(radar: Mapping[str, Any], i: int) -> str:
    name = radar.get("name")
    return str(name) if name is not None else f"radar {i + 1}"


def _radar_colours(names: Sequence[str]) -> dict[str, str]:
    """One colour per radar: presets keep their slot even when others are absent."""
    colours: dict[str, str] = {}
    extra = 0
    for name in names:
        if name in colours:
            continue
        if name in RADAR_ORDER:
            colours[name] = PALETTE[RADAR_ORDER.index(name)]
        else:
            colours[name] = PALETTE[(len(RADAR_ORDER) + extra) % len(PALETTE)]
            extra += 1
    return colours


def _fmt(v: Any, unit: str) -> str | None:
    f = _number(v)
    return None if f is None else f"{f:g} {unit}"


def _radar_label(radar: Mapping[str, Any], name: str) -> str:
    parts: list[str] = []
    for prefix, key, unit in (
        ("σr", "sigma_r_m", "m"),
        ("σVr", "sigma_vr_mps", "m/s"),
        ("T", "period_s", "s"),
    ):
        text = _fmt(radar.get(key), unit)
        if text is not None:
            parts.append(f"{prefix} {text}")
    c0 = _number(radar.get("c0"))
    head = f"{name}  C0 = {c0:.3g}" if c0 is not None else name
    return head + ("\n" + ", ".join(parts) if parts else "")


def _same(a: tuple[list[float], list[float]], b: tuple[list[float], list[float]]) -> bool:
    (xa, ya), (xb, yb) = a, b
    if len(xa) != len(xb) or xa != xb:
        return False
    for u, v in zip(ya, yb, strict=True):
        if math.isnan(u) != math.isnan(v):
            return False
        if not math.isnan(u) and not math.isclose(u, v, rel_tol=COINCIDE_RTOL, abs_tol=0.0):
            return False
    return True


def _groups(series: Mapping[str, tuple[list[float], list[float]]]) -> list[list[str]]:
    """Radars grouped by identical series, in the order they first appear."""
    groups: list[list[str]] = []
    for name, s in series.items():
        for g in groups:
            if _same(series[g[0]], s):
                g.append(name)
                break
        else:
            groups.append([name])
    return groups


def _dashes(dashed: bool, index: int, count: int) -> Any:
    """Line style of member ``index`` of ``count`` coinciding lines.

    A single line is plain dashed or solid. Coinciding lines share one dash period and each
    draws its own slot of it, so the colours alternate along the common curve (with gaps if the
    variant is dashed, without if it is solid).
    """
    if count <= 1:
        return (0, (DASH_PT, GAP_PT)) if dashed else "-"
    gap = GAP_PT if dashed else 0.0
    slot = DASH_PT + gap
    period = count * slot
    return ((period - index * slot) % period, (DASH_PT, period - DASH_PT))


def _note(ax: Axes, text: str) -> None:
    """An empty panel that says why it is empty."""
    ax.set_axis_off()
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", color="0.4")


class _PlainLogFormatter(LogFormatter):
    """LogFormatter's choice of which ticks to label, written as plain numbers ("0.01", "30")."""

    def __call__(self, x: float, pos: int | None = None) -> str:
        return f"{x:.6g}" if super().__call__(x, pos) else ""


def _log_axis(ax: Axes) -> None:
    ax.set_yscale("log")
    # Plain numbers rather than 1e−02 or 3×10¹; minor labels only on short ranges.
    ax.yaxis.set_major_formatter(_PlainLogFormatter(labelOnlyBase=False))
    ax.yaxis.set_minor_formatter(
        _PlainLogFormatter(labelOnlyBase=False, minor_thresholds=(1.0, 0.5))
    )


def _plot_sigma(
    ax: Axes,
    radars: Sequence[tuple[str, Mapping[str, Any]]],
    key: str,
    symbol: str,
    unit: str,
    colours: Mapping[str, str],
) -> bool:
    """Left column: σ of one component against k, MC markers and analytic lines."""
    ax.set_title(f"σ of {symbol} — Monte Carlo (markers) and analytic (lines)", fontsize=10)
    ax.set_ylabel(f"σ{symbol} [{unit}]")
    drawn = False
    for variant in _VARIANTS:
        dashed = _DASHED[variant]
        analytic = {
            name: _broken(
                rad.get("k") or [], _get(rad, "sigma_analytic", variant, key), positive=True
            )
            for name, rad in radars
        }
        analytic = {n: s for n, s in analytic.items() if any(not math.isnan(v) for v in s[1])}
        for group in _groups(analytic):
            for i, name in enumerate(group):
                x, y = analytic[name]
                ax.plot(
                    x,
                    y,
                    color=colours[name],
                    lw=LINE_WIDTH,
                    ls=_dashes(dashed, i, len(group)),
                    zorder=3 if dashed else 4,
                )
                drawn = True
        for name, rad in radars:
            x, y = finite_points(
                rad.get("k") or [], _get(rad, "sigma", variant, key), positive=True
            )
            if not x:
                continue
            fill_band(
                ax,
                rad.get("k") or [],
                _get(rad, "sigma_ci95", variant, key),
                colours[name],
                positive=True,
            )
            ax.plot(
                x,
                y,
                ls="none",
                marker="o",
                ms=MARKER_SIZE,
                mew=0.9,
                mec=colours[name],
                mfc="white" if dashed else colours[name],
                alpha=0.9,
                zorder=5,
            )
            drawn = True
    if not drawn:
        _note(ax, f"no σ{symbol} values")
        return False
    _log_axis(ax)
    return True


def _peak(x: Sequence[float], y: Sequence[float]) -> tuple[float, float] | None:
    """(k, value) of the largest value; the smallest k on a tie."""
    best: tuple[float, float] | None = None
    for xv, yv in zip(x, y, strict=True):
        if not math.isnan(yv) and (best is None or yv > best[1]):
            best = (xv, yv)
    return best


def _plot_gain(
    ax: Axes,
    radars: Sequence[tuple[str, Mapping[str, Any]]],
    key: str,
    symbol: str,
    colours: Mapping[str, str],
    *,
    mark_peaks: bool,
) -> bool:
    """Right column: gain K(k) of one component per radar (peaks marked in the range row)."""
    ax.set_title(f"gain of range + Doppler over range only, {symbol}", fontsize=10)
    ax.set_ylabel(f"K [%]  (σ{symbol})")
    peaks: list[tuple[str, float, float]] = []
    for name, rad in radars:
        x, y = _broken(rad.get("k") or [], _get(rad, "gain_percent", key))
        if not any(not math.isnan(v) for v in y):
            continue
        fill_band(ax, rad.get("k") or [], _get(rad, "gain_ci95_percent", key), colours[name])
        ax.plot(x, y, color=colours[name], lw=LINE_WIDTH, zorder=3)
        peak = _peak(x, y)
        if mark_peaks and peak is not None:
            peaks.append((name, *peak))
    if not ax.lines:
        _note(ax, f"no gain values for {symbol}")
        return False
    ax.axhline(0.0, color="black", lw=0.6, zorder=1)
    if peaks:
        handles = []
        for name, kp, vp in peaks:
            ax.plot(
                [kp],
                [vp],
                ls="none",
                marker="o",
                ms=6,
                mfc="white",
                mec=colours[name],
                mew=1.5,
                zorder=6,
            )
            handles.append(
                Line2D(
                    [],
                    [],
                    ls="none",
                    marker="o",
                    ms=5,
                    mfc="white",
                    mec=colours[name],
                    mew=1.3,
                    label=f"{name} {vp:.0f}% @ k={kp:g}",
                )
            )
        names = {p[0] for p in peaks}
        claims = [f"{n} ≈{v:g}% @ k={k}" for n, v, k in PAPER_RANGE_PEAKS if n in names]
        title = "peak of range gain"
        leg = ax.legend(
            handles=handles,
            loc="upper center",
            fontsize=7.5,
            title=title,
            title_fontsize=7.5,
            framealpha=0.85,
            edgecolor="0.8",
            handletextpad=0.3,
            borderpad=0.4,
            labelspacing=0.25,
            ncol=min(len(handles), 3),
            columnspacing=1.0,
        )
        if claims:
            leg.set_title(title + "  (paper: " + ", ".join(claims) + ")")
    return True


def _headroom_for_legend(ax: Axes) -> None:
    """Raise the top of a linear y-axis so that its legend (upper centre) sits above the data.

    Needs a drawn figure: the legend's height is measured against the axes' height.
    """
    legend = ax.get_legend()
    if legend is None:
        return
    ys = [v for line in ax.lines for v in line.get_ydata() if math.isfinite(v)]
    if not ys:
        return
    renderer = ax.figure.canvas.get_renderer()
    frac = (
        legend.get_window_extent(renderer).height / ax.get_window_extent(renderer).height
        + LEGEND_PAD
    )
    if not 0.0 < frac < 0.6:
        return
    lo, _ = ax.get_ylim()
    data_hi = max(ys)
    ax.set_ylim(lo, lo + (data_hi - lo) / (1.0 - frac))


def _build_figure(
    doc: Mapping[str, Any], radars: Sequence[tuple[str, Mapping[str, Any]]]
) -> Figure:
    fig = Figure(figsize=(WIDTH_IN, HEIGHT_IN), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(3, 2, squeeze=False, sharex=True)
    colours = _radar_colours([name for name, _ in radars])
    k_all = [k for _, rad in radars for v in rad.get("k") or [] if (k := _number(v)) is not None]
    for row, (key, symbol, unit) in enumerate(_STATES):
        _plot_sigma(axes[row, 0], radars, key, symbol, unit, colours)
        _plot_gain(axes[row, 1], radars, key, symbol, colours, mark_peaks=key == "r_m")
        for ax in axes[row]:
            ax.grid(True, which="major", color="0.88", lw=0.6)
            ax.tick_params(labelbottom=True, labelsize=8.5)
            ax.set_xlabel("window length k [scans]")
    for ax in axes.flat:
        if ax.axison:
            ax.xaxis.set_major_locator(MaxNLocator(nbins=20, integer=True))
            if k_all:
                ax.set_xlim(min(k_all) - 0.5, max(k_all) + 0.5)
            break  # shared x: one locator and limit serve every panel
    radar_handles = [
        Line2D([], [], color=colours[name], lw=2.0, label=_radar_label(rad, name))
        for name, rad in radars
    ]
    ms = MARKER_SIZE + 0.5
    style_handles = [
        Line2D(
            [],
            [],
            color="0.2",
            lw=LINE_WIDTH,
            ls=_dashes(_DASHED[v], 0, 1),
            marker="o",
            ms=ms,
            mec="0.2",
            mfc="white" if _DASHED[v] else "0.2",
            label=_VARIANT_LABEL[v],
        )
        for v in _VARIANTS
    ]
    style_handles += [
        Line2D([], [], color="0.2", lw=LINE_WIDTH, label="line: analytic √R_ii"),
        Line2D([], [], color="0.2", ls="none", marker="o", ms=ms, label="marker: Monte Carlo σ"),
        Patch(
            color="0.3",
            alpha=BAND_ALPHA,
            label=band_label(doc.get("trials", "?"), "trials"),
        ),
    ]
    fig.legend(
        handles=radar_handles,
        loc="outside lower left",
        fontsize=8,
        frameon=False,
        ncol=min(len(radar_handles), 3),
        title="radars",
        title_fontsize=9,
        columnspacing=1.2,
    )
    fig.legend(
        handles=style_handles,
        loc="outside lower right",
        fontsize=8,
        frameon=False,
        ncol=2,
        title="styles (σ panels; coinciding radars share interleaved dashes)",
        title_fontsize=9,
        columnspacing=1.2,
        handlelength=3.6,
    )
    # Lay the figure out once to measure the peak legend, then make room for it.
    fig.draw_without_rendering()
    _headroom_for_legend(axes[0, 1])
    trials = doc.get("trials", "?")
    trials_s = f"{trials:,}".replace(",", " ") if isinstance(trials, int) else str(trials)
    fig.suptitle(
        "Gorshkov & Zavizhenets: sliding-window least squares of r, Vr, a from the last k scans,"
        f" range only vs range + Doppler\n{trials_s} Monte Carlo trials per radar,"
        f" seed {doc.get('seed', '?')}; K(k) = (σ_range-only − σ_range+Vr) / σ_range-only · 100%",
        fontsize=11,
    )
    return fig


def _check_doc(doc: Any) -> list[tuple[str, Mapping[str, Any]]]:
    """The (name, radar) pairs of ``doc``; ValueError with one line when it cannot be drawn."""
    if not isinstance(doc, Mapping):
        raise ValueError(f"gorshkov document must be a dict, got {type(doc).__name__}")
    experiment = doc.get("experiment")
    if experiment is not None and experiment != "gorshkov":
        raise ValueError(f"not a gorshkov document: experiment is {experiment!r}")
    radars = doc.get("radars")
    if not isinstance(radars, Sequence) or isinstance(radars, str | bytes) or not radars:
        raise ValueError("gorshkov document has no radars: nothing to plot")
    out: list[tuple[str, Mapping[str, Any]]] = []
    seen: set[str] = set()
    for i, rad in enumerate(radars):
        if not isinstance(rad, Mapping):
            raise ValueError(f"gorshkov document: radar {i + 1} must be a JSON object")
        name = _name(rad, i)
        if name in seen:
            raise ValueError(f"gorshkov document: radar {name!r} appears twice")
        seen.add(name)
        ks = rad.get("k")
        if not isinstance(ks, Sequence) or isinstance(ks, str | bytes) or not ks:
            raise ValueError(f"gorshkov document: radar {name!r} has no window lengths k")
        out.append((name, rad))
    return out


def plot_gorshkov(doc: dict, path: str | os.PathLike) -> None:
    """Draw the Gorshkov reproduction document ``doc`` into the image file ``path``.

    ``doc`` is the output of ``radarviz reproduce gorshkov --json`` (its optional ``tracking``
    part is not drawn); the format follows the suffix of ``path`` (.png, .pdf, .svg, ...; PNG
    when there is none). Null values are skipped and break the line there.

    Raises:
        ValueError: the document is not a gorshkov document, has no radars, a radar is not an
            object, has no k or a duplicate name, or the suffix is not an image format
            matplotlib can write.
    """
    radars = _check_doc(doc)
    out = Path(os.fsdecode(os.fspath(path)))
    fig = _build_figure(doc, radars)
    write_figure_atomically(fig, out, DPI)
