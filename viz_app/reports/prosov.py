"""The Prosov reproduction as a JSON document and as a readable table.

The JSON keys are an interface (``radarviz reproduce prosov --json``); lists are per scan n.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from radarviz.core.confidence import BAND_GROUPS, BAND_LEVEL
from radarviz.core.experiments.prosov import TrackingResult, check_delta_x_claims
from radarviz.core.finite import check_finite_result
from radarviz.core.metrics import NONNEGATIVE_METRICS, TrackMetrics

#: Per-method series in the document, in this order.
METRIC_KEYS: tuple[str, ...] = (
    "sigma_x_filter_m",
    "rmse_x_m",
    "std_x_m",
    "bias_range_m",
    "bias_cross_m",
    "nees_pos",
    "nees_state",
)
#: Series that are a σ, an RMSE or a NEES: negative is a failure, not a value.
NONNEGATIVE_KEYS: frozenset[str] = NONNEGATIVE_METRICS


def check_metrics(
    where: str,
    metrics: dict[str, TrackMetrics],
    n: np.ndarray,
    bands: dict[str, Any],
    first_scan: int = 1,
) -> None:
    """Every ``METRIC_KEYS`` series of every method (``core.finite.check_finite_result``):
    finite from ``first_scan`` on (a track started from k scans has none before scan k),
    σ / RMSE / NEES not negative; ``bands[name][key]`` (lo, hi) finite wherever the series is,
    for the methods that have groups of runs (without them every band is undefined)."""
    defined = np.asarray(n) >= first_scan
    for name, m in metrics.items():
        for key in METRIC_KEYS:
            check_finite_result(
                where,
                f"{key} of {name}",
                getattr(m, key),
                defined=defined,
                nonnegative=key in NONNEGATIVE_KEYS,
                index=n,
            )
            if name in bands:
                for side, band in zip(("lo", "hi"), bands[name][key], strict=True):
                    check_finite_result(
                        where,
                        f"{key} 95% band {side} of {name}",
                        band,
                        defined=defined,
                        nonnegative=key in NONNEGATIVE_KEYS,
                        index=n,
                    )


def check_tracking_result(where: str, result: TrackingResult) -> None:
    """The finite-result check of one Prosov case before it is printed, written or shown:
    the metrics and their bands (``check_metrics``), Δx and its band, the NEES χ² bands."""
    bands = {
        name: {key: result.band95(name, key) for key in METRIC_KEYS}
        for name in result.metrics
        if name in result.leave_one_out
    }
    check_metrics(where, result.metrics, result.n, bands)
    if "seed" in result.metrics and "naive" in result.metrics:
        grouped = "seed" in result.leave_one_out and "naive" in result.leave_one_out
        ci = result.delta_x_ci95_percent()
        for reading, values in result.delta_x_percent().items():
            check_finite_result(where, f"delta_x_percent ({reading})", values, index=result.n)
            for side, band in zip(("lo", "hi"), ci[reading], strict=True):
                check_finite_result(
                    where,
                    f"delta_x_percent ({reading}) 95% band {side}",
                    band,
                    defined=grouped,
                    index=result.n,
                )
    for label, band in (("pos", result.nees_pos_band95), ("state", result.nees_state_band95)):
        check_finite_result(
            where,
            f"nees_{label}_band95",
            band,
            nonnegative=True,
            index_name="the",
            index=("low end", "high end"),
        )


def json_series(values: np.ndarray) -> list[float | None]:
    """A JSON list: floats, with None where a value is undefined (NaN or infinite)."""
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, dtype=float)]


def band_document(band: tuple[np.ndarray, np.ndarray]) -> dict[str, list[float | None]]:
    """A (lo, hi) band as {"lo": [...], "hi": [...]}, null where undefined."""
    return {"lo": json_series(band[0]), "hi": json_series(band[1])}


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def case_document(result: TrackingResult) -> dict[str, Any]:
    """One σβ case of the document.

    Besides the series: ``methods[name]["ci95"][key]`` the 95% Monte Carlo band of each
    series (``TrackingResult.band95``), ``delta_x_ci95_percent[reading]`` that of Δx, and ``claims``
    the paper's claims checked against each reading (``check_delta_x_claims``).
    """
    cfg = result.config
    methods = {}
    for name, m in result.metrics.items():
        entry: dict[str, Any] = {k: json_series(getattr(m, k)) for k in METRIC_KEYS}
        entry["ci95"] = {k: band_document(result.band95(name, k)) for k in METRIC_KEYS}
        methods[name] = entry
    case: dict[str, Any] = {
        "sigma_beta_deg": cfg.sigma_beta_deg,
        "sigma_r_m": cfg.sigma_r_m,
        "dims": cfg.dims,
        "n": [int(v) for v in result.n],
        "methods": methods,
    }
    if "seed" in result.metrics and "naive" in result.metrics:
        case["delta_x_percent"] = {k: json_series(v) for k, v in result.delta_x_percent().items()}
        case["delta_x_ci95_percent"] = {
            k: band_document(v) for k, v in result.delta_x_ci95_percent().items()
        }
        case["claims"] = [
            {
                "reading": c.reading,
                "bound_percent": c.claim.bound_percent,
                "scans": c.claim.scans,
                "verdict": c.verdict,
                "peak_scan": c.peak_scan,
                "peak_percent": _finite(c.peak_percent),
                "peak_ci95": [_finite(c.peak_lo), _finite(c.peak_hi)],
            }
            for c in check_delta_x_claims(result)
        ]
    if cfg.dims == 3:
        case["elevation_deg"] = cfg.target.elevation_deg
        case["sigma_elevation_deg"] = cfg.sigma_elevation_deg
    case["nees_pos_band95"] = list(result.nees_pos_band95)
    case["nees_state_band95"] = list(result.nees_state_band95)
    return case


def prosov_document(
    results: Sequence[TrackingResult], where: str = "reproduce prosov"
) -> dict[str, Any]:
    """The whole experiment: one case per σβ, all with the same runs, seed and period.

    Every case passes ``check_tracking_result`` first: a NaN or a negative NEES is a
    ``ResultError`` naming ``where``, never a null in the document."""
    for r in results:
        check_tracking_result(where, r)
    first = results[0].config
    return {
        "experiment": "prosov",
        "runs": first.runs,
        "seed": first.seed,
        "period_s": first.target.period_s,
        "band": {"level": BAND_LEVEL, "method": "delete-a-group jackknife", "groups": BAND_GROUPS},
        "cases": [case_document(r) for r in results],
    }


def _scan_columns(n: Sequence[int]) -> list[int]:
    """Indices of the scans shown in the table: 1, 5, 10, 20, 40, 60 … and the last."""
    wanted = [1, 2, 5, 10, 20, 30, 40, 60, 100, 200, 500, 1000]
    last = n[-1]
    idx = [i for i, v in enumerate(n) if v in wanted]
    if not idx or n[idx[-1]] != last:
        idx.append(len(n) - 1)
    return idx


def format_prosov_table(doc: dict[str, Any]) -> str:
    """A plain-text report of the document, one block per σβ case."""
    lines = [
        f"Prosov reproduction: {doc['runs']} runs, seed {doc['seed']}, T = {doc['period_s']:g} s",
        "",
    ]

    def fmt(v: float | None, spec: str) -> str:
        return "-" if v is None else format(v, spec)

    for case in doc["cases"]:
        n = case["n"]
        cols = _scan_columns(n)
        labels = [f"n={n[i]}" for i in cols]
        dims = int(case.get("dims", 2))
        where = (
            f", 3D: elevation {case['elevation_deg']:g}°, σε = {case['sigma_elevation_deg']:g}°"
            if dims == 3
            else ""
        )
        lines.append(
            f"σβ = {case['sigma_beta_deg']:g}°, σr = {case['sigma_r_m']:g} m{where}"
            f"   (NEES_pos 95% band for the run average: "
            f"[{case['nees_pos_band95'][0]:.3f}, {case['nees_pos_band95'][1]:.3f}])"
        )
        if "delta_x_percent" in case:
            rows: list[tuple[str, list[str]]] = []
            for reading in ("filter", "rmse", "std"):
                vals = case["delta_x_percent"][reading]
                rows.append((reading + " reading", [fmt(vals[i], ".2f") for i in cols]))
                half = _half_widths(case["delta_x_ci95_percent"][reading])
                rows.append(("  ± (95%)", [fmt(half[i], ".2f") for i in cols]))
            lines += _block("Δx(n) of seed vs naive, %", labels, rows)
        for label, key, spec in (
            ("range bias, m", "bias_range_m", ".1f"),
            ("RMSE x, m", "rmse_x_m", ".1f"),
            ("filter σx, m", "sigma_x_filter_m", ".1f"),
            (f"NEES position ({dims} dof)", "nees_pos", ".2f"),
            (f"NEES state ({2 * dims} dof)", "nees_state", ".2f"),
        ):
            rows = []
            for name, m in case["methods"].items():
                rows.append((name, [fmt(m[key][i], spec) for i in cols]))
                half = _half_widths(m["ci95"][key])
                rows.append(("  ±", [fmt(half[i], spec) for i in cols]))
            lines += _block(label + " (± 95%)", labels, rows)
        if case.get("claims"):
            lines.append(f"  The paper's claims, from the 95% bands of {doc['runs']} runs:")
            for c in case["claims"]:
                lines.append("    " + format_claim(c, doc["runs"]))
        lines.append("")
    lines.append(
        "Expected range biases (docs/conversion.md): naive about +r·s/2, seed about 0, cmkf_d and"
    )
    lines.append("ucm about +r·s, ducm small (s = σβ² in rad²); compare the rows with their bands.")
    return "\n".join(lines)


def _block(title: str, labels: list[str], rows: list[tuple[str, list[str]]]) -> list[str]:
    """A table block: a header line (``title`` and the column labels) and one line per row,
    every column as wide as its widest cell (at least 8) with a space before it, so large
    values (``98858.03`` then ``164647.62``) never run together."""
    width = max(8, *(len(c) for c in labels), *(len(c) for _, cells in rows for c in cells))
    line = lambda cells: "".join(f" {c:>{width}}" for c in cells)  # noqa: E731
    return [f"  {title:<28}{line(labels)}"] + [f"    {name:<26}{line(c)}" for name, c in rows]


def _half_widths(band: dict[str, list[float | None]]) -> list[float | None]:
    """Half the width of a band per scan, None where it is undefined."""
    return [
        None if lo is None or hi is None else (hi - lo) / 2.0
        for lo, hi in zip(band["lo"], band["hi"], strict=True)
    ]


def format_claim(claim: dict[str, Any], runs: int) -> str:
    """One claim of a case's ``claims`` as a sentence:
    "rmse reading, |Δx| ≤ 2.1% over scans 1–20: not resolved at 1000 runs (Δx(20) = …)"."""
    verdict = claim["verdict"]
    if verdict == "not resolved":
        verdict = f"not resolved at {runs} runs"
    peak, (lo, hi) = claim["peak_percent"], claim["peak_ci95"]
    if peak is None:
        at = "no value"
    elif lo is None or hi is None:
        at = f"Δx({claim['peak_scan']}) = {peak:.2f}%, no band"
    else:
        half = (hi - lo) / 2
        at = f"Δx({claim['peak_scan']}) = {peak:.2f}% ± {half:.2g}%, [{lo:.2f}, {hi:.2f}]"
    return (
        f"{claim['reading']} reading, |Δx| ≤ {claim['bound_percent']:g}% over scans "
        f"1–{claim['scans']}: {verdict} ({at})"
    )
