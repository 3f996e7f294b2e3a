"""The Gorshkov reproduction (finite-memory filter) as a JSON document and a readable table.

JSON keys are an interface (``radarviz reproduce gorshkov --json``); lists are per window
length k, with null where a value is undefined (e.g. range-only acceleration at k < 3).
Every Monte Carlo series has its 95% band beside it: ``sigma_ci95`` (χ², exact for these
Gaussian estimates), ``gain_ci95_percent`` (delete-a-group jackknife over the paired trials),
and in the tracking part ``ci95`` per variant; ``band`` says which method made which.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from radarviz.core.confidence import BAND_GROUPS, BAND_LEVEL
from radarviz.core.experiments.doppler_start import DopplerTrackingResult
from radarviz.core.finite import check_finite_result
from radarviz.core.finite_memory.fit import (
    STATE_NAMES,
    FilterStats,
    GorshkovRadar,
    GorshkovResult,
)
from radarviz.viz_app.reports.prosov import (
    METRIC_KEYS,
    band_document,
    check_metrics,
    json_series,
)

#: The per-parameter keys, each the parameter with its unit (the gain under them is in %).
_STATE_KEYS = STATE_NAMES


def _by_state(a: np.ndarray) -> dict[str, list[float | None]]:
    """(K, 3) → {"r_m": [...], "vr_mps": [...], "a_mps2": [...]}."""
    return {key: json_series(a[:, i]) for i, key in enumerate(_STATE_KEYS)}


def _variants(get: str, ro: FilterStats, rd: FilterStats) -> dict[str, Any]:
    return {"range_only": _by_state(getattr(ro, get)), "range_doppler": _by_state(getattr(rd, get))}


def _band_by_state(lo: np.ndarray, hi: np.ndarray) -> dict[str, dict[str, list[float | None]]]:
    """(K, 3) lo and hi → {"r_m": {"lo": [...], "hi": [...]}, "vr_mps": …, "a_mps2": …}."""
    return {key: band_document((lo[:, i], hi[:, i])) for i, key in enumerate(_STATE_KEYS)}


def _sigma_bands(ro: FilterStats, rd: FilterStats) -> dict[str, Any]:
    return {
        name: _band_by_state(st.sigma_mc_ci95_lo, st.sigma_mc_ci95_hi)
        for name, st in (("range_only", ro), ("range_doppler", rd))
    }


def range_gain_peak(rad: GorshkovRadar, ks: np.ndarray) -> dict[str, Any] | None:
    """The peak of the Monte Carlo range gain with its 95% band, and every k whose band
    reaches the peak's band (the window lengths the Monte Carlo cannot tell from the peak)."""
    gain, lo, hi = rad.gain_mc[:, 0], rad.gain_mc_ci95_lo[:, 0], rad.gain_mc_ci95_hi[:, 0]
    if not np.isfinite(gain).any():
        return None
    i = int(np.nanargmax(gain))
    tied = [int(k) for k, h in zip(ks, hi, strict=True) if np.isfinite(h) and h >= lo[i]]
    return {
        "k": int(ks[i]),
        "gain_percent": float(gain[i]),
        "gain_ci95_percent": json_series(np.array([lo[i], hi[i]])),
        "k_within_band": tied,
    }


def tracking_document(result: DopplerTrackingResult) -> dict[str, Any]:
    """The Doppler-aided tracking part: the ``core.metrics`` statistics per variant, per scan."""
    cfg = result.config
    variants = {}
    for name, m in result.metrics.items():
        entry: dict[str, Any] = {k: json_series(getattr(m, k)) for k in METRIC_KEYS}
        entry["rmse_vr_mps"] = json_series(result.rmse_vr_mps[name])
        entry["sigma_vr_filter_mps"] = json_series(result.sigma_vr_filter_mps[name])
        entry["ci95"] = {k: band_document(result.band95(name, k)) for k in METRIC_KEYS}
        entry["ci95"]["rmse_vr_mps"] = band_document(result.rmse_vr_mps_ci95[name])
        variants[name] = entry
    return {
        "radar": cfg.radar_preset().name,
        "sigma_beta_deg": cfg.sigma_beta_deg,
        "runs": cfg.runs,
        "start_scans": cfg.start_scans,
        "n": [int(v) for v in result.n],
        "variants": variants,
        "nees_pos_band95": list(result.nees_pos_band95),
    }


def fitted(stats: FilterStats) -> np.ndarray:
    """(K, 3) True where a window of k scans estimates r, Vr, a (``order``, from
    ``core.finite_memory.fit.max_order``: min(k·m, 3) parameters); elsewhere undefined."""
    return np.arange(3)[None, :] < np.asarray(stats.order)[:, None]


def check_gorshkov_result(
    where: str, result: GorshkovResult, tracking: DopplerTrackingResult | None = None
) -> None:
    """The finite-result check (``core.finite``) of everything the document reports: each
    variant's σ (Monte Carlo, analytic, χ² band; not negative) where its fit estimates the
    parameter, the gains and their band where the range-only fit does (the gain needs both),
    and the tracking part from its start scan on."""
    ks = result.ks
    for rad in result.radars:
        radar = rad.preset.name
        for variant, st in (("range_only", rad.range_only), ("range_doppler", rad.range_doppler)):
            mask = fitted(st)
            for key in ("sigma_mc", "sigma_analytic", "sigma_mc_ci95_lo", "sigma_mc_ci95_hi"):
                check_finite_result(
                    where,
                    f"{key} of {variant} ({radar})",
                    getattr(st, key),
                    defined=mask,
                    nonnegative=True,
                    index_name="k",
                    index=ks,
                )
        both = fitted(rad.range_only)
        for key in ("gain_mc", "gain_analytic", "gain_mc_ci95_lo", "gain_mc_ci95_hi"):
            check_finite_result(
                where, f"{key} ({radar})", getattr(rad, key), defined=both, index_name="k", index=ks
            )
    if tracking is None:
        return
    first = tracking.config.start_scans
    bands = {v: {k: tracking.band95(v, k) for k in METRIC_KEYS} for v in tracking.metrics}
    check_metrics(where, tracking.metrics, tracking.n, bands, first_scan=first)
    defined = np.asarray(tracking.n) >= first
    for variant in tracking.metrics:
        for key, values in (
            ("rmse_vr_mps", tracking.rmse_vr_mps[variant]),
            ("sigma_vr_filter_mps", tracking.sigma_vr_filter_mps[variant]),
        ):
            check_finite_result(
                where,
                f"{key} of {variant}",
                values,
                defined=defined,
                nonnegative=True,
                index=tracking.n,
            )
        for side, band in zip(("lo", "hi"), tracking.rmse_vr_mps_ci95[variant], strict=True):
            check_finite_result(
                where,
                f"rmse_vr_mps 95% band {side} of {variant}",
                band,
                defined=defined,
                index=tracking.n,
            )


def gorshkov_document(
    result: GorshkovResult,
    tracking: DopplerTrackingResult | None = None,
    where: str = "reproduce gorshkov",
) -> dict[str, Any]:
    """The whole experiment, one entry per radar (and the tracking part if given); its
    numbers pass ``check_gorshkov_result`` first (undefined ones become null)."""
    check_gorshkov_result(where, result, tracking)
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
                "sigma_ci95": _sigma_bands(rad.range_only, rad.range_doppler),
                "gain_percent": _by_state(rad.gain_mc),
                "gain_ci95_percent": _band_by_state(rad.gain_mc_ci95_lo, rad.gain_mc_ci95_hi),
                "range_gain_peak": range_gain_peak(rad, result.ks),
            }
        )
    doc: dict[str, Any] = {
        "experiment": "gorshkov",
        "trials": result.trials,
        "seed": result.seed,
        "band": {
            "level": BAND_LEVEL,
            "sigma": "chi-squared",
            "gain_percent": "delete-a-group jackknife",
            "tracking": "delete-a-group jackknife",
            "groups": BAND_GROUPS,
        },
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
            ("σr  range only", "range_only", "r_m"),
            ("σr  range+Vr", "range_doppler", "r_m"),
            ("σVr range only", "range_only", "vr_mps"),
            ("σVr range+Vr", "range_doppler", "vr_mps"),
            ("σa  range only", "range_only", "a_mps2"),
            ("σa  range+Vr", "range_doppler", "a_mps2"),
        ):
            vals = rad["sigma"][var][key]
            spec = "8.3f" if key == "a_mps2" else "8.1f"
            lines.append(f"  {label:<16}" + "".join(f(v, spec) for v in vals))
        sig = rad["sigma"]["range_doppler"]["r_m"]
        band = rad["sigma_ci95"]["range_doppler"]["r_m"]
        rel = [
            (h - lo) / 2 / v * 100
            for v, lo, h in zip(sig, band["lo"], band["hi"], strict=True)
            if None not in (v, lo, h) and v > 0
        ]
        if rel:
            lines.append(f"  σ: 95% χ² band ± {max(rel):.2f}% of each value")
        for key, label in (("r_m", "gain r, %"), ("vr_mps", "gain Vr, %"), ("a_mps2", "gain a, %")):
            lines.append(f"  {label:<16}" + "".join(f(v, "8.1f") for v in rad["gain_percent"][key]))
            half = _half(rad["gain_ci95_percent"][key])
            lines.append(f"  {'  ± (95%)':<16}" + "".join(f(v, "8.2f") for v in half))
        peak = rad.get("range_gain_peak")
        if peak:
            lo, hi = peak["gain_ci95_percent"]
            width = "" if lo is None or hi is None else f" ± {(hi - lo) / 2:.2f}%"
            within = peak["k_within_band"]
            tied = (
                ""
                if within == [peak["k"]]
                else f" (k = {', '.join(map(str, within))} within its band)"
            )
            gain = peak["gain_percent"]
            lines.append(f"  range gain peaks at {gain:.1f}%{width} for k = {peak['k']}{tied}")
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
                ("RMSE Vr, m/s", "rmse_vr_mps"),
                ("filter σVr, m/s", "sigma_vr_filter_mps"),
                ("RMSE x, m", "rmse_x_m"),
                ("NEES position", "nees_pos"),
            ):
                row = "".join(f(e[key][i], "9.2f") for i in cols)
                lines.append(f"  {var + ' ' + label:<34}{row}")
                if key in e["ci95"]:
                    half = _half(e["ci95"][key])
                    lines.append(f"  {'  ± (95%)':<34}" + "".join(f(half[i], "9.2f") for i in cols))
    return "\n".join(lines)


def _half(band: dict[str, list[float | None]]) -> list[float | None]:
    """Half the width of a band, None where it is undefined."""
    return [
        None if lo is None or hi is None else (hi - lo) / 2.0
        for lo, hi in zip(band["lo"], band["hi"], strict=True)
    ]
