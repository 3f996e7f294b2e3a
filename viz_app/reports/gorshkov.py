"""The Gorshkov reproduction (finite-memory filter) as a JSON document and a readable table.

JSON keys are an interface (``radarviz reproduce gorshkov --json``); lists are per window
length k, with null where a value is undefined (e.g. range-only acceleration at k < 3).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from radarviz.core.experiments.doppler_start import DopplerTrackingResult
from radarviz.core.finite_memory.fit import FilterStats, GorshkovResult
from radarviz.viz_app.reports.prosov import METRIC_KEYS, json_series

_STATE_KEYS = ("r", "vr", "a")


def _by_state(a: np.ndarray) -> dict[str, list[float | None]]:
    """(K, 3) → {"r": [...], "vr": [...], "a": [...]}."""
    return {key: json_series(a[:, i]) for i, key in enumerate(_STATE_KEYS)}


def _variants(get: str, ro: FilterStats, rd: FilterStats) -> dict[str, Any]:
    return {"range_only": _by_state(getattr(ro, get)), "range_doppler": _by_state(getattr(rd, get))}


def tracking_document(result: DopplerTrackingResult) -> dict[str, Any]:
    """The Doppler-aided tracking part: the ``core.metrics`` statistics per variant, per scan."""
    cfg = result.config
    variants = {}
    for name, m in result.metrics.items():
        entry = {k: json_series(getattr(m, k)) for k in METRIC_KEYS}
        entry["rmse_vr"] = json_series(result.rmse_vr[name])
        entry["sigma_vr_filter"] = json_series(result.sigma_vr_filter[name])
        variants[name] = entry
    return {
        "radar": cfg.radar,
        "sigma_beta_deg": cfg.sigma_beta_deg,
        "runs": cfg.runs,
        "start_scans": cfg.start_scans,
        "n": [int(v) for v in result.n],
        "variants": variants,
        "nees_pos_band95": list(result.nees_pos_band95),
    }


def gorshkov_document(
    result: GorshkovResult, tracking: DopplerTrackingResult | None = None
) -> dict[str, Any]:
    """The whole experiment, one entry per radar (and the tracking part if given)."""
    radars = []
    for rad in result.radars:
        p = rad.preset
        radars.append(
            {
                "name": p.name,
                "sigma_r_m": p.sigma_r_m,
                "sigma_vr_mps": p.sigma_vr_mps,
                "period_s": p.period_s,
                "c0": p.c0,
                "k": [int(k) for k in result.ks],
                "sigma": _variants("sigma_mc", rad.range_only, rad.range_doppler),
                "sigma_analytic": _variants("sigma_analytic", rad.range_only, rad.range_doppler),
                "gain_percent": _by_state(rad.gain_mc),
            }
        )
    doc: dict[str, Any] = {
        "experiment": "gorshkov",
        "trials": result.trials,
        "seed": result.seed,
        "radars": radars,
    }
    if tracking is not None:
        doc["tracking"] = tracking_document(tracking)
    return doc


def format_gorshkov_table(doc: dict[str, Any]) -> str:
    """Plain-text report: σ per k for both variants, gains, and the tracking summary."""

    def f(v: float | None, spec: str) -> str:
        return "     -" if v is None else format(v, spec)

    lines = [f"Gorshkov reproduction: {doc['trials']} trials per radar, seed {doc['seed']}", ""]
    for rad in doc["radars"]:
        ks = rad["k"]
        lines.append(
            f"{rad['name']}: σr = {rad['sigma_r_m']:g} m, σVr = {rad['sigma_vr_mps']:g} m/s, "
            f"T = {rad['period_s']:g} s, C0 = {rad['c0']:.2f}"
        )
        lines.append("   k " + "".join(f"{k:>8}" for k in ks))
        for label, var, key in (
            ("σr  range only", "range_only", "r"),
            ("σr  range+Vr", "range_doppler", "r"),
            ("σVr range only", "range_only", "vr"),
            ("σVr range+Vr", "range_doppler", "vr"),
            ("σa  range only", "range_only", "a"),
            ("σa  range+Vr", "range_doppler", "a"),
        ):
            vals = rad["sigma"][var][key]
            spec = "8.3f" if key == "a" else "8.1f"
            lines.append(f"  {label:<16}" + "".join(f(v, spec) for v in vals))
        for key, label in (("r", "gain r, %"), ("vr", "gain Vr, %"), ("a", "gain a, %")):
            lines.append(f"  {label:<16}" + "".join(f(v, "8.1f") for v in rad["gain_percent"][key]))
        gains = [(v, k) for v, k in zip(rad["gain_percent"]["r"], ks, strict=True) if v is not None]
        if gains:
            peak, kp = max(gains)
            lines.append(f"  range gain peaks at {peak:.1f}% for k = {kp}")
        lines.append("")
    tr = doc.get("tracking")
    if tr:
        lines.append(
            f"Track start from the first {tr['start_scans']} scans ({tr['radar']}, "
            f"σβ = {tr['sigma_beta_deg']:g}°, {tr['runs']} runs); NEES_pos 95% band "
            f"[{tr['nees_pos_band95'][0]:.3f}, {tr['nees_pos_band95'][1]:.3f}]"
        )
        n = tr["n"]
        cols = [i for i in range(len(n)) if n[i] in (tr["start_scans"], 5, 10, 20, 40, 60)]
        lines.append(f"  {'':<34}" + "".join(f"{'n=' + str(n[i]):>9}" for i in cols))
        for var, e in tr["variants"].items():
            for label, key in (
                ("RMSE Vr, m/s", "rmse_vr"),
                ("filter σVr, m/s", "sigma_vr_filter"),
                ("RMSE x, m", "rmse_x"),
                ("NEES position", "nees_pos"),
            ):
                row = "".join(f(e[key][i], "9.2f") for i in cols)
                lines.append(f"  {var + ' ' + label:<34}{row}")
    return "\n".join(lines)
