"""The Prosov reproduction as a figure (``radarviz reproduce prosov --plot FILE``).

One column per σβ case of the JSON document (see :mod:`viz_app.reports.prosov`), three rows:

1. the paper's Figs. 1–2: Δx(n) = (σ̂x_seed − σ̂x_naive) / σ̂x_naive in percent under the three
   readings of σ̂x (filter-reported, empirical RMSE, empirical std), with the paper's window
   n ≤ ``paper_scans`` shaded, its stated bound (2.1% at 1°, 18% at 2°) marked and the
   verdict of the report (``core.experiments.prosov.check_delta_x_claims``) written in;
2. range bias of every method against n (cross-range bias summarised in a note);
3. position NEES (2 dof) of every method against n on a log axis, with the χ² range of a
   consistent filter's run average.

Every Monte Carlo curve carries its 95% band (the document's ``ci95`` / ``delta_x_ci95_percent``,
shaded lightly in the curve's colour; the legends say "95% band from N runs").

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
from matplotlib.ticker import LogFormatter

from radarviz.core.experiments.prosov import PROSOV_CLAIMS
from radarviz.viz_app.figures.common import (
    BAND_ALPHA,
    PALETTE,
    band_label,
    fill_band,
    finite_points,
    write_figure_atomically,
)
from radarviz.viz_app.palette import OKABE_ITO, hex_colour, rgb

#: Methods in display order; each keeps its colour in every panel.
METHOD_ORDER: tuple[str, ...] = ("naive", "seed", "cmkf_d", "ucm", "ducm", "ekf", "ukf")
#: The three readings of σ̂x in Δx(n): key in the document, label, colour.
_READINGS: tuple[tuple[str, str, str], ...] = (
    ("filter", "filter (P-based)", hex_colour(OKABE_ITO["blue"])),
    ("rmse", "RMSE", hex_colour(OKABE_ITO["vermillion"])),
    ("std", "std", hex_colour(OKABE_ITO["bluish_green"])),
)
#: The paper's stated bound on |Δx| over its window, by σβ in degrees.
PAPER_BOUND_PERCENT: dict[float, float] = {c.sigma_beta_deg: c.bound_percent for c in PROSOV_CLAIMS}
NOMINAL_NEES_POS = 2.0
#: Bias panels: the first max(TRANSIENT_MIN_SCANS, TRANSIENT_FRACTION · scans) scans are the
#: initial transient; the y-axis leaves them off-scale if they would stretch it this many times.
TRANSIENT_MIN_SCANS = 3
TRANSIENT_FRACTION = 0.1
TRANSIENT_STRETCH = 1.5
#: Fraction of a bias panel's height kept free above the data per line of its note.
NOTE_LINE_FRACTION = 0.07
#: Dashed methods: each nearly coincides with another one (ucm with cmkf_d, ukf with ekf/seed),
#: so the dashes let the line underneath show through.
_DASHED_METHODS: frozenset[str] = frozenset({"ucm", "ukf"})
_WINDOW_COLOUR = "0.9"

CASE_WIDTH_IN = 6.0
HEIGHT_IN = 11.0
DPI = 120


def _method_colours(cases: Sequence[Mapping[str, Any]]) -> dict[str, str]:
    """One colour per method over all cases: known methods first in their usual order."""
    present: list[str] = []
    for case in cases:
        for name in case.get("methods") or {}:
            if name not in present:
                present.append(name)
    known = [m for m in METHOD_ORDER if m in present]
    extra = [m for m in present if m not in METHOD_ORDER]
    # Known methods keep their slot even when others are absent; extras come after them.
    colours = {m: hex_colour(rgb(m)) for m in known}
    for i, m in enumerate(extra):
        colours[m] = PALETTE[i % len(PALETTE)]
    return colours


def _style(method: str) -> str | tuple[int, tuple[int, int]]:
    """Line style of a method: dashed for those drawn over a near-identical one."""
    return (0, (4, 2)) if method in _DASHED_METHODS else "-"


def _sigma_label(case: Mapping[str, Any]) -> str:
    sigma_beta_deg = case.get("sigma_beta_deg")
    text = f"σβ = {float(sigma_beta_deg):g}°" if sigma_beta_deg is not None else "σβ = ?"
    if case.get("dims") == 3:
        text += f", E = {case['elevation_deg']:g}°, σε = {case['sigma_elevation_deg']:g}°"
    return text


def _note(ax: Axes, text: str) -> None:
    """An empty panel that says why it is empty."""
    ax.set_axis_off()
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", color="0.4")


def _paper_bound(case: Mapping[str, Any]) -> float | None:
    sigma_beta_deg = case.get("sigma_beta_deg")
    if sigma_beta_deg is None:
        return None
    for deg, bound in PAPER_BOUND_PERCENT.items():
        if math.isclose(float(sigma_beta_deg), deg, rel_tol=1e-9, abs_tol=1e-9):
            return bound
    return None


def _plot_delta(ax: Axes, case: Mapping[str, Any], paper_scans: int, doc_runs: Any) -> None:
    """Row 1: Δx(n) in percent, three readings, the paper's window and bound."""
    ns = case.get("n") or []
    ax.set_title(f"Δx(n), seed vs naive — {_sigma_label(case)}")
    ax.set_ylabel("Δx [%]")
    delta = case.get("delta_x_percent")
    if not delta:
        _note(ax, "Δx needs both naive and seed")
        return
    readings = {key: finite_points(ns, delta.get(key)) for key, _, _ in _READINGS}
    if not any(x for x, _ in readings.values()):
        _note(ax, "no Δx values")
        return
    n_num = [float(v) for v in ns if v is not None]
    if paper_scans > 0 and n_num:
        ax.axvspan(min(n_num) - 0.5, paper_scans + 0.5, color=_WINDOW_COLOUR, zorder=0)
    bound = _paper_bound(case)
    if bound is not None:
        for sign in (-1.0, 1.0):
            ax.axhline(sign * bound, color="0.45", ls="--", lw=0.9, zorder=1)
        ax.annotate(
            f"paper: |Δx| ≤ {bound:g}%",
            xy=(1.0, bound),
            xycoords=("axes fraction", "data"),
            xytext=(-3, 2),
            textcoords="offset points",
            ha="right",
            va="bottom",
            fontsize=8,
            color="0.3",
        )
    ax.axhline(0.0, color="black", lw=0.6, zorder=1)
    bands = case.get("delta_x_ci95_percent") or {}
    for key, label, colour in _READINGS:
        x, y = readings[key]
        if x:
            fill_band(ax, ns, bands.get(key), colour)
            ax.plot(x, y, color=colour, lw=1.6, label=label, zorder=3)
    verdicts = {c.get("reading"): c.get("verdict") for c in case.get("claims") or []}
    if verdicts and bound is not None:
        text = f"|Δx| ≤ {bound:g}% over n ≤ {paper_scans}, from the 95% bands:\n" + "\n".join(
            f"{label}: {verdicts[key]}"
            + (f" at {doc_runs} runs" if verdicts[key] == "not resolved" else "")
            for key, label, _ in _READINGS
            if key in verdicts
        )
        ax.text(
            0.02,
            0.03,
            text,
            transform=ax.transAxes,
            ha="left",
            va="bottom",
            fontsize=8,
            bbox={"facecolor": "white", "edgecolor": "0.7", "alpha": 0.85},
        )


def _fit_past_transient(
    ax: Axes, series: Sequence[tuple[list[float], list[float]]], first_n: float
) -> str | None:
    """Fit the y-axis to the scans after the initial transient if the transient would squash them.

    The filters start from a single converted point with a vague velocity, so the first few scans
    can be an order of magnitude off the steady-state values the panel is about. When including
    them would stretch the y-range more than ``TRANSIENT_STRETCH`` times, the axis is fitted to
    n > ``first_n + skip`` and a note saying what is off-scale is returned.
    """
    ys_all = [v for _, y in series for v in y]
    n_total = len({xv for x, _ in series for xv in x})
    skip = max(TRANSIENT_MIN_SCANS, math.ceil(TRANSIENT_FRACTION * n_total))
    ys_core = [v for x, y in series for xv, v in zip(x, y, strict=True) if xv > first_n + skip]
    if not ys_all or len(ys_core) < 2:
        return None
    lo, hi = min(*ys_core, 0.0), max(*ys_core, 0.0)
    full_lo, full_hi = min(ys_all), max(ys_all)
    if hi - lo <= 0.0 or (max(full_hi, hi) - min(full_lo, lo)) <= TRANSIENT_STRETCH * (hi - lo):
        return None
    pad = 0.08 * (hi - lo)
    ax.set_ylim(lo - pad, hi + pad)
    worst = full_lo if (lo - full_lo) >= (full_hi - hi) else full_hi
    return f"y fitted to n > {first_n + skip:g}; first scans off-scale (to {worst:+.0f} m)"


def _plot_bias(ax: Axes, case: Mapping[str, Any], colours: Mapping[str, str]) -> None:
    """Row 2: range bias per method, with a note on the cross-range bias.

    The cross-range bias is not drawn: for the preset's geometry (β0 = 0) it is zero in
    expectation, and what the runs show is sampling noise shared by all methods (they filter the
    same measurements), as large as the range biases themselves, so seven dashed copies of it
    would hide the range-bias story. The note gives its largest magnitude and the largest spread
    between methods at one scan.
    """
    ns = case.get("n") or []
    methods = case.get("methods") or {}
    ax.set_title(f"range bias — {_sigma_label(case)}")
    ax.set_ylabel("range bias [m]")
    if not methods:
        _note(ax, "no methods in this case")
        return
    ranges: dict[str, tuple[list[float], list[float]]] = {}
    cross_by_n: dict[float, list[float]] = {}
    for name in colours:
        series = methods.get(name)
        if series is None:
            continue
        ranges[name] = finite_points(ns, series.get("bias_range_m"))
        for xv, v in zip(*finite_points(ns, series.get("bias_cross_m")), strict=True):
            cross_by_n.setdefault(xv, []).append(v)
    if not any(x for x, _ in ranges.values()):
        _note(ax, "no range-bias values")
        return
    ax.axhline(0.0, color="black", lw=0.6, zorder=1)
    for name, (x, y) in ranges.items():
        if x:
            fill_band(ax, ns, (methods[name].get("ci95") or {}).get("bias_range_m"), colours[name])
            ax.plot(x, y, color=colours[name], lw=1.6, ls=_style(name), zorder=3)
    notes: list[str] = []
    if cross_by_n:
        max_cross = max(abs(v) for vs in cross_by_n.values() for v in vs)
        text = f"cross-range bias (not drawn): |b| ≤ {max_cross:.0f} m"
        spread = max(max(vs) - min(vs) for vs in cross_by_n.values())
        if any(len(vs) > 1 for vs in cross_by_n.values()):
            text += f", methods within {spread:.0f} m of each other"
        notes.append(text)
    first_n = min(xv for x, _ in ranges.values() for xv in x)
    clipped = _fit_past_transient(ax, list(ranges.values()), first_n)
    if clipped:
        notes.append(clipped)
    if notes:
        # Headroom above the data for the note, so that it never covers a line.
        frac = 0.02 + NOTE_LINE_FRACTION * len(notes)
        lo, hi = ax.get_ylim()
        ax.set_ylim(lo, hi + (hi - lo) * frac / (1.0 - frac))
        ax.text(
            0.01,
            0.985,
            "\n".join(notes),
            transform=ax.transAxes,
            ha="left",
            va="top",
            fontsize=7.5,
            color="0.25",
            zorder=4,
        )


def _plot_nees(ax: Axes, case: Mapping[str, Any], colours: Mapping[str, str]) -> None:
    """Row 3: position NEES per method on a log axis, with the 95% band and the nominal 2."""
    ns = case.get("n") or []
    methods = case.get("methods") or {}
    ax.set_title(f"position NEES ({int(case.get('dims', 2))} dof) — {_sigma_label(case)}")
    ax.set_ylabel("NEES")
    ax.set_xlabel("scan n")
    if not methods:
        _note(ax, "no methods in this case")
        return
    nees = {
        name: finite_points(ns, methods[name].get("nees_pos"), positive=True)
        for name in colours
        if methods.get(name) is not None
    }
    plotted = any(x for x, _ in nees.values())
    if not plotted:
        _note(ax, "no position NEES values")
        return
    band = case.get("nees_pos_band95")
    handles: list[Any] = []
    if (
        isinstance(band, Sequence)
        and len(band) == 2
        and all(isinstance(v, int | float) and math.isfinite(v) for v in band)
    ):
        lo, hi = float(band[0]), float(band[1])
        if 0.0 < lo <= hi:
            handles.append(
                ax.axhspan(
                    lo,
                    hi,
                    color="0.75",
                    alpha=0.6,
                    zorder=0,
                    label=f"consistent filter's 95% range [{lo:.3g}, {hi:.3g}]",
                )
            )
    nominal = float(case.get("dims", NOMINAL_NEES_POS))  # the position NEES's dof
    handles.append(
        ax.axhline(
            nominal,
            color="black",
            lw=0.8,
            ls=":",
            zorder=1,
            label=f"nominal {nominal:g}",
        )
    )
    for name, (x, y) in nees.items():
        if x:
            band = (methods[name].get("ci95") or {}).get("nees_pos")
            fill_band(ax, ns, band, colours[name], positive=True)
            ax.plot(x, y, color=colours[name], lw=1.6, ls=_style(name), zorder=3)
    ax.set_yscale("log")
    # Plain numbers ("3", "20") rather than 3×10⁰; minor labels only on short ranges.
    ax.yaxis.set_major_formatter(LogFormatter(labelOnlyBase=False))
    ax.yaxis.set_minor_formatter(LogFormatter(labelOnlyBase=False, minor_thresholds=(1.0, 0.5)))
    ax.legend(handles=handles, loc="best", fontsize=8, framealpha=0.85)


def _build_figure(
    doc: Mapping[str, Any], cases: Sequence[Mapping[str, Any]], paper_scans: int
) -> Figure:
    ncases = len(cases)
    fig = Figure(figsize=(CASE_WIDTH_IN * ncases, HEIGHT_IN), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    # Two subfigures so that each legend sits beside its own rows: a figure-level "outside
    # upper" legend would collide with the suptitle.
    sub_delta, sub_tracks = fig.subfigures(2, 1, height_ratios=[1.2, 2.15])
    delta_axes = sub_delta.subplots(1, ncases, squeeze=False)[0]
    track_axes = sub_tracks.subplots(2, ncases, squeeze=False, sharex="col")
    colours = _method_colours(cases)
    for j, case in enumerate(cases):
        _plot_delta(delta_axes[j], case, paper_scans, doc.get("runs", "?"))
        _plot_bias(track_axes[0, j], case, colours)
        _plot_nees(track_axes[1, j], case, colours)
        for ax in (delta_axes[j], *track_axes[:, j]):
            ax.grid(True, which="major", color="0.88", lw=0.6)
            ax.tick_params(labelbottom=True)
        delta_axes[j].set_xlabel("scan n")
    if any(c.get("delta_x_percent") for c in cases):
        top: list[Any] = [Line2D([], [], color=col, lw=1.6, label=lab) for _, lab, col in _READINGS]
        if paper_scans > 0:
            top.append(Patch(color=_WINDOW_COLOUR, label=f"paper's window n ≤ {paper_scans}"))
        if any(_paper_bound(c) is not None for c in cases):
            top.append(Line2D([], [], color="0.45", ls="--", lw=0.9, label="paper's bound on |Δx|"))
        if any(c.get("delta_x_ci95_percent") for c in cases):
            top.append(Patch(color="0.3", alpha=BAND_ALPHA, label=band_label(doc.get("runs", "?"))))
        sub_delta.legend(
            handles=top,
            loc="outside upper center",
            fontsize=9,
            frameon=False,
            ncol=len(top) if ncases > 1 else 3,
            title="Δx = (σx[seed] − σx[naive]) / σx[naive] in %, with σx read as",
            title_fontsize=9,
        )
    if colours:
        handles = [
            Line2D([], [], color=c, lw=1.6, ls=_style(m), label=m) for m, c in colours.items()
        ]
        handles.append(Patch(color="0.3", alpha=BAND_ALPHA, label=band_label(doc.get("runs", "?"))))
        sub_tracks.legend(
            handles=handles,
            loc="outside lower center",
            fontsize=9,
            frameon=False,
            ncol=min(len(handles), 6 * ncases),
            title="methods (bias and NEES)",
            title_fontsize=9,
        )
    first = cases[0]
    sigma_r_m = first.get("sigma_r_m")
    parts = [
        f"{doc.get('runs', '?')} Monte Carlo runs",
        f"seed {doc.get('seed', '?')}",
        f"T = {float(doc['period_s']):g} s" if doc.get("period_s") is not None else "T = ?",
    ]
    if sigma_r_m is not None:
        parts.append(f"σr = {float(sigma_r_m):g} m")
    sep = "\n" if ncases == 1 else " — "
    fig.suptitle("Prosov: converted-measurement Kalman filters" + sep + ", ".join(parts))
    return fig


def plot_prosov(doc: dict, path: str | os.PathLike, paper_scans: int = 20) -> None:
    """Draw the Prosov reproduction document ``doc`` into the image file ``path``.

    ``doc`` is the output of ``radarviz reproduce prosov --json``; the format follows the suffix
    of ``path`` (.png, .pdf, .svg, ...; PNG when there is none). ``paper_scans`` is the length of
    the paper's window of scans, shaded in the Δx panels. Null values are skipped.

    Raises:
        ValueError: the document has no cases, ``paper_scans`` is negative, or the suffix is not
            an image format matplotlib can write.
    """
    if not isinstance(doc, Mapping):
        raise ValueError(f"prosov document must be a dict, got {type(doc).__name__}")
    cases = doc.get("cases")
    if not isinstance(cases, Sequence) or isinstance(cases, str | bytes) or not cases:
        raise ValueError("prosov document has no cases: nothing to plot")
    if not all(isinstance(c, Mapping) for c in cases):
        raise ValueError("prosov document: every case must be a JSON object")
    if isinstance(paper_scans, bool) or not isinstance(paper_scans, int) or paper_scans < 0:
        raise ValueError(f"paper_scans must be a non-negative integer, got {paper_scans!r}")
    out = Path(os.fsdecode(os.fspath(path)))
    fig = _build_figure(doc, cases, paper_scans)
    write_figure_atomically(fig, out, DPI)
