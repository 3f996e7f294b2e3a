"""The association experiment (``radarviz reproduce association``) as JSON and a table.

The JSON keys are an interface (``--json``)::

    {"experiment": "association", "runs": R, "seed": S,
     "scene": {"targets", "crossing_angle_deg", "detection_prob", "clutter_per_scan", "scans",
               "period_s", "speed_mps", "crossing_range_m", "sigma_r_m", "sigma_beta_deg"},
     "association": {"gate_probability", "gate", "confirm_m", "confirm_n", "delete_misses"},
     "filters": {"model": "cv", "sigma_a_mps2", "sigma_v0_mps"},
     "gospa": {"cutoff_m": c, "order": p},
     "times_s": [N],
     "methods": {METHOD: {
         "gospa_per_scan_m": {"mean": [N], "lo": [N], "hi": [N]},
         "gospa_m": {"mean", "lo", "hi"},                 the per-run mean over scans
         "localisation_m_p" | "missed_m_p" | "false_m_p": {"mean", "lo", "hi"},  per scan
         "swaps" | "false_tracks" | "tracks": {"mean", "lo", "hi"},      per run
         "minus_reference": {"gospa_m" | "swaps" | "false_tracks": {"delta", "lo", "hi"}}}},
     "reference": METHOD}

A key's suffix is its unit: ``_m`` metres, ``_m_p`` metres to the GOSPA order p (the parts of
d^p, as ``radarviz score`` names them); swaps and tracks are counts.

``minus_reference`` is the method's per-run value minus the reference method's on the same
run (``ucm`` when it is run, else the first method), averaged: the paired difference, whose
band is far narrower than either method's own when the two follow each other run by run.

Every band is the 95% band of a mean over the runs (``core.experiments.association.
mean_band``). Every number passes ``core.finite.check_finite_document`` (nothing is undefined:
at least two runs, and every GOSPA part is finite by construction).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from radarviz.core.experiments.association import (
    GOSPA_PARTS,
    AssociationResult,
    mean_band,
)
from radarviz.core.finite import check_finite_document
from radarviz.core.tracking.association import gate_threshold

#: Keys whose numbers are never negative (GOSPA, its parts and counts; the bands' lower
#: ends of a count may be, so only the means are named).
NONNEGATIVE_KEYS = ("mean", "times_s")


def _band(values: np.ndarray, axis: int = 0, name: str = "mean") -> dict[str, Any]:
    """{name: mean, "lo", "hi"} over the runs (``name`` "delta" for a difference, which may
    be negative)."""
    mb = mean_band(values, axis=axis)
    return {name: mb.mean.tolist(), "lo": mb.lo.tolist(), "hi": mb.hi.tolist()}


def association_document(
    result: AssociationResult, where: str = "reproduce association"
) -> dict[str, Any]:
    """The experiment as a JSON-ready dict (module docstring), every number checked finite."""
    cfg = result.config
    s, a = cfg.scene, cfg.association
    methods: dict[str, Any] = {}
    ref = cfg.methods.index("ucm") if "ucm" in cfg.methods else 0
    per_run = {
        "gospa_m": result.gospa[..., 0].mean(axis=2),
        "swaps": result.swaps.astype(np.float64),
        "false_tracks": result.false_tracks.astype(np.float64),
    }
    for i, m in enumerate(cfg.methods):
        g = result.gospa[i]  # (runs, N, 4)
        entry: dict[str, Any] = {
            "gospa_per_scan_m": _band(g[..., 0]),
            "gospa_m": _band(g[..., 0].mean(axis=1)),
        }
        for k, part in enumerate(GOSPA_PARTS[1:], start=1):
            entry[f"{part}_m_p"] = _band(g[..., k].mean(axis=1))
        for key, counts in (
            ("swaps", result.swaps[i]),
            ("false_tracks", result.false_tracks[i]),
            ("tracks", result.tracks[i]),
        ):
            entry[key] = _band(counts.astype(np.float64))
        entry["minus_reference"] = {
            k: _band(v[i] - v[ref], name="delta") for k, v in per_run.items()
        }
        methods[m] = entry
    doc = {
        "experiment": "association",
        "runs": cfg.runs,
        "seed": cfg.seed,
        "scene": {
            "targets": s.targets,
            "crossing_angle_deg": s.crossing_angle_deg,
            "detection_prob": s.detection_prob,
            "clutter_per_scan": s.clutter_per_scan,
            "scans": s.scans,
            "period_s": s.period_s,
            "speed_mps": s.speed_mps,
            "crossing_range_m": s.crossing_range_m,
            "sigma_r_m": s.sigma_r_m,
            "sigma_beta_deg": s.sigma_beta_deg,
        },
        "association": {
            "gate_probability": a.gate_probability,
            "gate": gate_threshold(a.gate_probability, 2),
            "confirm_m": a.confirm_m,
            "confirm_n": a.confirm_n,
            "delete_misses": a.delete_misses,
        },
        "filters": {
            "model": "cv",
            "sigma_a_mps2": cfg.sigma_a_mps2,
            "sigma_v0_mps": cfg.sigma_v0_mps,
        },
        "gospa": {"cutoff_m": cfg.gospa_cutoff_m, "order": cfg.gospa_order},
        "times_s": result.times_s.tolist(),
        "methods": methods,
        "reference": cfg.methods[ref],
    }
    check_finite_document(where, doc, NONNEGATIVE_KEYS)
    return doc


def _pm(b: dict[str, Any], fmt: str) -> str:
    mid = b["mean"] if "mean" in b else b["delta"]
    half = max(b["hi"] - mid, mid - b["lo"])
    digits = int(fmt.lstrip("+").split(".")[-1].rstrip("f"))
    mid = round(mid, digits) + 0.0  # no "-0.0" for a difference that rounds to zero
    return f"{mid:{fmt}} ± {half:.{digits}f}"


def format_association_table(doc: dict[str, Any]) -> str:
    """The document as a readable table: one row per method."""
    s, a, g = doc["scene"], doc["association"], doc["gospa"]
    p = g["order"]
    lines = [
        f"Association (GNN, each method gating its own tracks): {s['targets']} targets crossing "
        f"at {s['crossing_angle_deg']:g}°, P_D {s['detection_prob']:g}, "
        f"{s['clutter_per_scan']:g} false plots per scan, {s['scans']} scans of "
        f"{s['period_s']:g} s; σr {s['sigma_r_m']:g} m, σβ {s['sigma_beta_deg']:g}°",
        f"gate P_G {a['gate_probability']:g} (d² < {a['gate']:.2f}), confirm "
        f"{a['confirm_m']} of {a['confirm_n']}, delete after {a['delete_misses']} misses; "
        f"GOSPA c = {g['cutoff_m']:g} m, p = {p:g}, α = 2; {doc['runs']} runs, seed "
        f"{doc['seed']}; ± is the 95% band of the mean over runs",
        "",
        f"{'method':<8} {'GOSPA (m)':>16} {'loc %':>6} {'miss %':>7} {'false %':>8} "
        f"{'swaps/run':>14} {'false tr./run':>14} {'tracks/run':>14}   "
        f"{'− ' + doc['reference'] + ': GOSPA':>18} {'false tr.':>13}",
    ]
    for m, e in doc["methods"].items():
        parts = [e[k]["mean"] for k in ("localisation_m_p", "missed_m_p", "false_m_p")]
        total = sum(parts) or 1.0
        share = [100.0 * v / total for v in parts]
        lines.append(
            f"{m:<8} {_pm(e['gospa_m'], '.1f'):>16} {share[0]:>6.1f} {share[1]:>7.1f} "
            f"{share[2]:>8.1f} {_pm(e['swaps'], '.2f'):>14} {_pm(e['false_tracks'], '.2f'):>14} "
            f"{_pm(e['tracks'], '.2f'):>14}   {_pm(e['minus_reference']['gospa_m'], '+.1f'):>18} "
            f"{_pm(e['minus_reference']['false_tracks'], '+.2f'):>13}"
        )
    lines += [
        "",
        f"GOSPA: the mean over scans of d_p per scan; loc/miss/false: the parts' shares of the "
        f"mean d^{p:g} (localisation of matched tracks, c^p/2 per missed target, per false "
        "track). Swaps: identity switches of the CLEAR MOT matching; false tracks: confirmed "
        "tracks matched to a target at under half of their scans. − REF: the paired difference "
        "from the reference method on the same runs.",
    ]
    return "\n".join(lines)
