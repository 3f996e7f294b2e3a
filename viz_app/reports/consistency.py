"""``radarviz track``'s consistency figures: the JSON summary (``--summary``, ``--json``) and
the warning lines on standard error.

The figures are the monitor's (``core.tracking.consistency``), per track (one per method, and
none for the finite-memory track, which has no prediction to test). JSON keys are an
interface; a value that is not finite (a track whose innovation blew up) is null.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from typing import Any

from radarviz.core.tracking.consistency import (
    INCONSISTENT_FRACTION,
    ConsistencyEvent,
    ConsistencyMonitor,
)
from radarviz.core.tracking.stream import StreamOptions
from radarviz.core.tracking.targets import track_name

#: Band exits reported on standard error per track; later ones only count in the summary.
MAX_EXIT_WARNINGS = 3


def _num(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


def motion_document(options: StreamOptions) -> dict[str, Any]:
    """The motion model of a run as the summary prints it."""
    if options.model == "imm":
        return {
            "kind": "imm",
            "sigma_a_mps2": list(options.imm_sigma_a_mps2),
            "transition_prob": [list(r) for r in options.transition_prob],
            "turn_rate_degps": list(
                options.imm_turn_rate_degps or [0.0] * len(options.imm_sigma_a_mps2)
            ),
        }
    return {"kind": "cv", "sigma_a_mps2": options.sigma_a_mps2}


def track_summary_document(
    monitor: ConsistencyMonitor,
    options: StreamOptions,
    *,
    input_path: str,
    plots: int,
    rows: int,
    three_d: bool,
    methods: tuple[str, ...],
    targets: tuple[str, ...] = (),
    input_counts: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The summary of one ``track`` run; ``targets``: a file of many targets' labels (its
    tracks are named ``core.tracking.targets.track_name(target, method)``); ``input_counts``:
    what the reader counted (``viz_app.io.asterix.AsterixReader.input_summary``: records
    skipped and dropped, a capture's packets, each radar's scan timing; None for a CSV)."""
    tracks = {}
    names = [track_name(t, m) for t in targets for m in methods] if targets else methods
    known = set(monitor.tracks)
    exits = Counter(e.track for e in monitor.events if e.kind == "leaves")
    for name in names:
        if name not in known:
            continue  # a track with no update after its start has nothing to test
        r = monitor.result(name)
        w = r.windows
        tracks[name] = {
            "updates": r.updates,
            "windows": w,
            "fraction_out_of_band": _num(r.fraction_out),
            "fraction_above": _num(r.above / w) if w else None,
            "fraction_below": _num(r.below / w) if w else None,
            "mean_nis_per_dof": _num(r.mean_nis_per_dof),
            "first_exit_s": _num(r.first_exit_s),
            "band_exits": exits[name],
            "inconsistent": r.inconsistent,
        }
    return {
        "input": input_path,
        "input_counts": input_counts,
        "plots": plots,
        "rows": rows,
        "dims": 3 if three_d else 2,
        "methods": list(methods),
        "targets": len(targets) or None,
        "model": motion_document(options),
        "doppler_update": options.doppler_update if options.use_doppler else None,
        "finite_memory_k": options.finite_memory_k or None,
        "nis_window": monitor.window,
        "nis_band_level": monitor.level,
        "inconsistent_fraction": INCONSISTENT_FRACTION,
        "tracks": tracks,
        "inconsistent_tracks": [k for k, v in tracks.items() if v["inconsistent"]],
    }


def exit_warner(emit: Callable[[str], None]) -> Callable[[ConsistencyEvent], None]:
    """An ``on_event`` for the monitor: each track's first ``MAX_EXIT_WARNINGS`` band exits
    as warning lines, then one line saying that further ones are not shown."""
    shown: dict[str, int] = {}

    def on_event(event: ConsistencyEvent) -> None:
        if event.kind != "leaves":
            return
        n = shown.get(event.track, 0) + 1
        shown[event.track] = n
        if n <= MAX_EXIT_WARNINGS:
            emit(event.message())
        elif n == MAX_EXIT_WARNINGS + 1:
            emit(f"track {event.track}: further exits from its NIS band are not shown")

    return on_event


def inconsistency_lines(doc: dict[str, Any]) -> list[str]:
    """One warning line per track the summary calls inconsistent."""
    out = []
    for name in doc["inconsistent_tracks"]:
        t = doc["tracks"][name]
        above = t["fraction_above"] or 0.0
        frac = t["fraction_out_of_band"] or 0.0
        why = (
            "its errors are larger than its covariance says (the motion model does not fit "
            "the target: try the IMM, --model imm, or a larger --sigma-a)"
            if above >= frac / 2
            else "its covariance is larger than its errors (too much process noise)"
        )
        out.append(
            f"track {name} was outside its NIS band {frac:.0%} of the time (a consistent "
            f"track: about {1 - doc['nis_band_level']:.0%}): {why}"
        )
    return out
