"""The Doppler-update comparison as a JSON document and a plain-text table.

``radarviz reproduce doppler``: for each radar preset, the Doppler-aided Monte Carlo
(``core.experiments.doppler_start``) with the line-of-sight Doppler update beside the
converted one (r̂ V̂r), and which of the two keeps its position NEES in the χ² band.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from radarviz.core.confidence import BAND_GROUPS, BAND_LEVEL
from radarviz.core.experiments.doppler_start import (
    DOPPLER_UPDATE,
    DopplerTrackingResult,
    doppler_consistency,
)
from radarviz.viz_app.reports.prosov import band_document, json_series

#: How each variant is named in the table and the figure.
UPDATE_LABEL: dict[str, str] = {
    "range_doppler": "line of sight (V̂r along û)",
    "range_converted_doppler": "converted (r̂·V̂r)",
    "range_joint_doppler": "joint (correlated EKF+V̂r)",
}


def _finite(v: float) -> float | None:
    return v if v == v and abs(v) != float("inf") else None


def doppler_document(results: Sequence[DopplerTrackingResult]) -> dict[str, Any]:
    """One case per radar: per Doppler variant the per-scan position NEES with its 95% band,
    and the consistency summary (``doppler_consistency``)."""
    first = results[0].config
    cases = []
    for res in results:
        radar = res.config.radar_preset()
        variants = {}
        for v in res.metrics:
            if v not in DOPPLER_UPDATE:
                continue
            variants[v] = {
                "nees_pos": json_series(res.metrics[v].nees_pos),
                "nees_pos_ci95": band_document(res.band95(v, "nees_pos")),
            }
        summary = [
            {
                "variant": c.variant,
                "update": DOPPLER_UPDATE[c.variant],
                "nees_mean": _finite(c.nees_mean),
                "nees_mean_ci95": [_finite(x) for x in c.nees_mean_ci95],
                "nees_last": _finite(c.nees_last),
                "nees_last_ci95": [_finite(x) for x in c.nees_last_ci95],
                "verdict": c.verdict,
            }
            for c in doppler_consistency(res)
        ]
        cases.append(
            {
                "radar": radar.name,
                "sigma_r_m": radar.sigma_r_m,
                "sigma_vr_mps": radar.sigma_vr_mps,
                "period_s": radar.period_s,
                "n": [int(v) for v in res.n],
                "start_scans": res.config.start_scans,
                "nees_pos_band95": list(res.nees_pos_band95),
                "variants": variants,
                "consistency": summary,
            }
        )
    return {
        "experiment": "doppler",
        "runs": first.runs,
        "seed": first.seed,
        "sigma_beta_deg": first.sigma_beta_deg,
        "band": {"level": BAND_LEVEL, "method": "delete-a-group jackknife", "groups": BAND_GROUPS},
        "cases": cases,
    }


def format_doppler_table(doc: dict[str, Any]) -> str:
    """One line per radar and Doppler update: mean and last-scan position NEES with bands."""

    def fmt(v: float | None) -> str:
        return "-" if v is None else f"{v:.2f}"

    def band(b: list[float | None]) -> str:
        return f"[{fmt(b[0])}, {fmt(b[1])}]"

    lines = [
        f"Doppler updates compared: {doc['runs']} runs, seed {doc['seed']},"
        f" σβ = {doc['sigma_beta_deg']:g}°; position NEES (2 dof) of the EKF + each Doppler"
        " update, averaged over the runs (95% Monte Carlo band in brackets)",
        "",
        f"  {'radar':<6}{'Doppler update':<30}{'mean over scans':>30}{'last scan':>30}"
        f"{'χ² band':>18}  verdict",
    ]
    for case in doc["cases"]:
        lo, hi = case["nees_pos_band95"]
        for c in case["consistency"]:
            lines.append(
                f"  {case['radar']:<6}{UPDATE_LABEL.get(c['variant'], c['variant']):<30}"
                f"{fmt(c['nees_mean']) + ' ' + band(c['nees_mean_ci95']):>30}"
                f"{fmt(c['nees_last']) + ' ' + band(c['nees_last_ci95']):>30}"
                f"{f'[{lo:.2f}, {hi:.2f}]':>18}  {c['verdict']}"
            )
    lines.append("")
    lines.append(
        "Verdict from the last scan: consistent if its Monte Carlo band overlaps the χ² band of a"
    )
    lines.append("consistent filter's run average, over-/under-confident if it lies above/below.")
    return "\n".join(lines)
