"""Where ``radarviz track --associate``'s plots went, per radar: the summary's ``association``
section and the lines on standard error (and in the recording's log).

A plot is *in a confirmed track* when its track was confirmed (at the end, or before it was
deleted), *tentative* when its track is still tentative at the end of the file, and *never*
when its track was deleted without being confirmed. Clutter belongs in the last two; a
target's plots belong in the first. When more than ``UNTRACKED_WARNING_FRACTION`` of the plots
are outside confirmed tracks, either the file is mostly clutter or the tracking is failing
(a wrong radars file, a revisit the tracks cannot bridge, a gate too tight): the run says so
and prints no all-clear.
"""

from __future__ import annotations

from typing import Any

from radarviz.core.tracking.association import AssociationReport

#: Fraction of plots outside confirmed tracks above which the run warns.
UNTRACKED_WARNING_FRACTION = 0.10

#: How ``estimated`` quantities print: (name, unit, scale from SI).
_ESTIMATED: tuple[tuple[str, str, float], ...] = (
    ("rotation_period_s", "s", 1.0),
    ("min_range_m", "km", 1e-3),
    ("max_range_m", "km", 1e-3),
    ("min_elevation_rad", "deg", 57.29577951308232),
    ("max_elevation_rad", "deg", 57.29577951308232),
)


def untracked_fraction(report: AssociationReport) -> float | None:
    """Plots outside confirmed tracks over all plots (None without plots)."""
    total = sum(sum(c.values()) for c in report.plots.values())
    if not total:
        return None
    outside = sum(c["tentative"] + c["never"] for c in report.plots.values())
    return outside / total


def association_document(report: AssociationReport) -> dict[str, Any]:
    """The summary's ``association`` section (JSON keys are an interface)."""
    frac = untracked_fraction(report)
    return {
        "tracks_started": report.started,
        "tracks_confirmed": report.confirmed,
        "plots_outside_confirmed_fraction": frac,
        "radars": {
            name: {
                "plots": dict(counts),
                "scan_stamped": report.scan_stamped[name],
                "estimated": dict(report.estimated[name]),
            }
            for name, counts in report.plots.items()
        },
    }


def association_lines(report: AssociationReport) -> list[str]:
    """Per radar one line of where its plots went, and what was estimated from its plots."""
    lines = []
    for name, c in report.plots.items():
        total = sum(c.values())
        pct = {k: f"{100 * v / total:.1f}%" if total else "n/a" for k, v in c.items()}
        line = (
            f"radar {name}: {total} plots, {c['confirmed']} in confirmed tracks "
            f"({pct['confirmed']}), {c['tentative']} tentative ({pct['tentative']}), "
            f"{c['never']} never in a confirmed track ({pct['never']})"
        )
        est = [
            f"{label.rsplit('_', 1)[0].replace('_', ' ')} {v * scale:.4g} {unit}"
            for label, unit, scale in _ESTIMATED
            if (v := report.estimated[name].get(label)) is not None
        ]
        if est:
            line += "; estimated from its plots (not in the radars file): " + ", ".join(est)
        if report.scan_stamped[name]:
            line += "; its plots of a scan share one time stamp (whole scans)"
        lines.append(line)
    return lines


def untracked_warning(report: AssociationReport) -> str | None:
    """The warning when more than ``UNTRACKED_WARNING_FRACTION`` of the plots never reached
    a confirmed track, else None."""
    frac = untracked_fraction(report)
    if frac is None or frac <= UNTRACKED_WARNING_FRACTION:
        return None
    return (
        f"{100 * frac:.1f}% of the plots are outside confirmed tracks (more than "
        f"{100 * UNTRACKED_WARNING_FRACTION:.0f}%): the file is mostly clutter, or the tracking "
        "is failing (check the radars file's sites, accuracies and coverage, and the per-radar "
        "counts above)"
    )
