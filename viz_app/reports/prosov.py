"""The Prosov reproduction as a JSON document and as a readable table.

The JSON keys are an interface (``radarviz reproduce prosov --json``); lists are per scan n.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from radarviz.core.experiments.prosov import TrackingResult

#: Per-method series in the document, in this order.
METRIC_KEYS: tuple[str, ...] = (
    "sigma_x_filter",
    "rmse_x",
    "std_x",
    "bias_range",
    "bias_cross",
    "nees_pos",
    "nees_state",
)


def json_series(values: np.ndarray) -> list[float | None]:
    """A JSON list: floats, with None where a value is undefined (NaN or infinite)."""
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, dtype=float)]


def case_document(result: TrackingResult) -> dict[str, Any]:
    """One σβ case of the document."""
    cfg = result.config
    case: dict[str, Any] = {
        "sigma_beta_deg": cfg.sigma_beta_deg,
        "sigma_r_m": cfg.sigma_r_m,
        "n": [int(v) for v in result.n],
        "methods": {
            name: {k: json_series(getattr(m, k)) for k in METRIC_KEYS}
            for name, m in result.metrics.items()
        },
    }
    if "seed" in result.metrics and "naive" in result.metrics:
        case["delta_x_percent"] = {k: json_series(v) for k, v in result.delta_x_percent().items()}
    case["nees_pos_band95"] = list(result.nees_pos_band95)
    return case


def prosov_document(results: Sequence[TrackingResult]) -> dict[str, Any]:
    """The whole experiment: one case per σβ, all with the same runs, seed and period."""
    first = results[0].config
    return {
        "experiment": "prosov",
        "runs": first.runs,
        "seed": first.seed,
        "period_s": first.target.period_s,
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
        head = "".join(f"{'n=' + str(n[i]):>9}" for i in cols)
        lines.append(
            f"σβ = {case['sigma_beta_deg']:g}°, σr = {case['sigma_r_m']:g} m"
            f"   (NEES_pos 95% band for the run average: "
            f"[{case['nees_pos_band95'][0]:.3f}, {case['nees_pos_band95'][1]:.3f}])"
        )
        if "delta_x_percent" in case:
            lines.append(f"  Δx(n) of seed vs naive, %   {head}")
            for reading in ("filter", "rmse", "std"):
                vals = case["delta_x_percent"][reading]
                row = "".join(f"{fmt(vals[i], '9.2f')}" for i in cols)
                lines.append(f"    {reading + ' reading':<26}{row}")
        for label, key, spec in (
            ("range bias, m", "bias_range", "9.1f"),
            ("RMSE x, m", "rmse_x", "9.1f"),
            ("filter σx, m", "sigma_x_filter", "9.1f"),
            ("NEES position (2 dof)", "nees_pos", "9.2f"),
            ("NEES state (4 dof)", "nees_state", "9.2f"),
        ):
            lines.append(f"  {label:<28}{head}")
            for name, m in case["methods"].items():
                row = "".join(f"{fmt(m[key][i], spec)}" for i in cols)
                lines.append(f"    {name:<26}{row}")
        lines.append("")
    lines.append(
        "Reading guide: the paper's claim (|Δx| ≤ 2.1% at 1°, up to 18% at 2°) holds for the RMSE"
    )
    lines.append(
        "reading over its first 20 scans; naive is biased by about +r·s/2, seed by about 0,"
    )
    lines.append("cmkf_d and ucm by about +r·s, and ducm (decorrelated) stays small.")
    return "\n".join(lines)
