"""``radarviz score``: the JSON document of the scores and its text table.

Every undefined figure is ``null`` in JSON with a ``reason`` beside it, and ``n/a (reason)``
in the table; no NaN or infinity is ever printed (``core.finite`` checks the document).
"""

from __future__ import annotations

from typing import Any

from radarviz.core.tracking.scoring import BAND_LEVEL, Band, MethodScore, Nees, ScoreOptions


def band_document(band: Band) -> dict[str, Any]:
    """{"value", "band": [lo, hi] or null, "reason" when something is null}."""
    doc: dict[str, Any] = {"value": band.value}
    doc["band"] = None if band.lo is None or band.hi is None else [band.lo, band.hi]
    if band.reason and (band.value is None or doc["band"] is None):
        doc["reason"] = band.reason
    return doc


def nees_document(nees: Nees | None, reason: str) -> dict[str, Any]:
    """The position NEES: mean, the consistent filter's χ² band, pairs, dof, verdict."""
    if nees is None:
        return {"mean": None, "band": None, "reason": reason}
    return {
        "mean": nees.mean,
        "band": [nees.lo, nees.hi],
        "pairs": nees.pairs,
        "dof": nees.dof,
        "verdict": nees.verdict,
        "excluded_pairs": nees.excluded,
    }


def method_document(s: MethodScore) -> dict[str, Any]:
    """One method's scores (``core.tracking.scoring.MethodScore``) as JSON-ready values."""
    no_velocity = {
        "value": None,
        "band": None,
        "reason": "the truth or the tracks have no velocity",
    }
    return {
        "dims": s.dims,
        "tracks": s.tracks,
        "pairs": s.pairs,
        "gospa": {
            "mean_m": band_document(s.gospa),
            "localisation_m_p": band_document(s.localisation),
            "missed_m_p": band_document(s.missed),
            "false_m_p": band_document(s.false),
        },
        "purity": {
            **band_document(s.purity),
            "tracks": {
                name: {"purity": t.purity, "times": t.times, "target": t.target}
                for name, t in s.track_purity.items()
            },
        },
        "fragmentation": {"total": s.fragmentation, "segments": s.target_segments},
        "swaps": {
            "total": s.swaps,
            "per_target": s.target_swaps,
            "clear_mot": s.clear_mot_swaps,
        },
        "false_tracks_clear_mot": s.clear_mot_false_tracks,
        "position_rmse_m": band_document(s.position_rmse),
        "velocity_rmse_mps": (
            no_velocity if s.velocity_rmse is None else band_document(s.velocity_rmse)
        ),
        "nees_position": nees_document(s.nees, s.nees_reason),
    }


def score_document(
    tracks_path: str,
    truth_path: str,
    options: ScoreOptions,
    truth_rows: int,
    track_columns: dict[str, Any],
    scores: dict[str, MethodScore],
) -> dict[str, Any]:
    """The whole report: inputs, parameters, the truth's size, what the track file holds
    (``track_columns``: rows, and whether it has status, velocity and covariance columns),
    and each method's scores."""
    first = next(iter(scores.values()))
    return {
        "tracks_file": tracks_path,
        "truth_file": truth_path,
        "track_file_columns": track_columns,
        "parameters": {
            "gospa_cutoff_m": options.gospa_cutoff_m,
            "gospa_order": options.gospa_order,
            "gospa_alpha": 2,
            "score_max_gap_s": options.score_max_gap_s,
            "confirmed_only": options.confirmed_only,
            "band_level": BAND_LEVEL,
        },
        "truth": {"rows": truth_rows, "times": first.times, "targets": first.targets},
        "methods": {m: method_document(s) for m, s in scores.items()},
    }


def _num(v: float) -> str:
    """Four significant digits; from 1000 up, whole units (no exponent)."""
    return f"{v:.0f}" if abs(v) >= 1000 else f"{v:.4g}"


def _band_text(b: dict[str, Any], unit: str) -> str:
    if b["value"] is None:
        return f"n/a ({b['reason']})"
    text = f"{_num(b['value'])}{unit}"
    if b["band"] is None:
        return text + (f" ({b['reason']})" if "reason" in b else "")
    lo, hi = b["band"]
    return text + f"  [{_num(lo)}, {_num(hi)}]"


def format_score_table(doc: dict[str, Any]) -> str:
    """The document as text: a header line, then a block per method."""
    p, t = doc["parameters"], doc["truth"]
    which = "every track"
    if p["confirmed_only"]:
        status = doc["track_file_columns"]["status"]
        which = "confirmed tracks only" if status else "every track (the file has no status)"
    level = f"{100 * p['band_level']:g}%"
    lines = [
        f"score {doc['tracks_file']} against {doc['truth_file']}: {t['times']} truth times, "
        f"{t['targets']} targets; GOSPA c = {p['gospa_cutoff_m']:g} m, p = {p['gospa_order']:g}, "
        f"α = 2; {which}, predicted up to {p['score_max_gap_s']:g} s from their last row; "
        f"[{level} bands]"
    ]
    for method, m in doc["methods"].items():
        g = m["gospa"]
        unit_p = f" m^{p['gospa_order']:g}"
        nees = m["nees_position"]
        if nees["mean"] is None:
            nees_text = f"n/a ({nees['reason']})"
        else:
            lo, hi = nees["band"]
            nees_text = (
                f"{_num(nees['mean'])}, {nees['verdict']} the χ² {level} band "
                f"[{_num(lo)}, {_num(hi)}] of {nees['pairs']} pairs × {nees['dof']} dof"
            )
        purity = m["purity"]
        purity_text = (
            f"n/a ({purity['reason']})"
            if purity["value"] is None
            else f"{purity['value']:.3f} over {len(purity['tracks'])} tracks"
        )
        lines += [
            "",
            f"{method} ({m['dims']}D): {m['tracks']} tracks reported, {m['pairs']} assigned pairs",
            f"  GOSPA            {_band_text(g['mean_m'], ' m')}",
            f"    localisation   {_band_text(g['localisation_m_p'], unit_p)}",
            f"    missed         {_band_text(g['missed_m_p'], unit_p)}",
            f"    false          {_band_text(g['false_m_p'], unit_p)}",
            f"  purity           {purity_text}",
            f"  fragmentation    {m['fragmentation']['total']}",
            f"  swaps            {m['swaps']['total']} (CLEAR MOT matching: "
            f"{m['swaps']['clear_mot']}; false tracks {m['false_tracks_clear_mot']})",
            f"  RMSE position    {_band_text(m['position_rmse_m'], ' m')}",
            f"  RMSE velocity    {_band_text(m['velocity_rmse_mps'], ' m/s')}",
            f"  NEES position    {nees_text}",
        ]
    return "\n".join(lines)
