"""The velocity experiment (3D velocity from N radial velocities) as JSON and a readable table.

The JSON keys are an interface (``radarviz reproduce velocity --json``)::

    {"experiment": "velocity", "trials": N, "seed": S, "sweep_trials": n,
     "baseline": {"sigma_first_order_mps": [3], "sigma_mc_mps": [3], "bias_mc_mps": [3],
                  "bias_mc_se_mps": [3], "bias_second_order_mps": [3],
                  "bias_paper_term_mps": [3],
                  "corr_first_order": [[3x3]], "corr_mc": [[3x3]],
                  "condition_number": x, "m": x, "warning": str | null, ...},
     "sweep": [{"distance_km": x, "altitude_km": x, "m": x, "condition_number": x,
                "ratio_mc_to_linear": [3], "ratio_robust_to_linear": [3],
                "sigma_first_order_mps": [3], "warning": str | null}, ...]}

Vectors are (Vx, Vy, Vz) in m/s, as their ``_mps`` says; ``m`` is the paper's dimensionless
geometry metric (not metres), and correlations and ratios are dimensionless too.
``ratio_mc_to_linear`` is the sample σ over the first-order σ; ``ratio_robust_to_linear`` uses
the interquartile σ instead (insensitive to the heavy tails that near-singular draws of Ĉ
produce at large m). Nothing is undefined: every number passes
``core.finite.check_finite_document`` (a NaN, or a negative σ, ratio, m or condition number, is
a ``ResultError`` naming its path, never a null).

Every Monte Carlo value has its 95% band beside it as {"lo": …, "hi": …}: ``sigma_mc_ci95_mps``
and ``corr_mc_ci95`` (delete-a-group jackknife) in the baseline, ``ratio_mc_to_linear_ci95``
(the σ band over the first-order σ, a constant) and ``ratio_robust_to_linear_ci95`` (batch
means) in the sweep (``core.velocity.estimate.VelocityMC``); ``band`` names the methods.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from radarviz.core.confidence import BAND_GROUPS, BAND_LEVEL
from radarviz.core.finite import check_finite_document
from radarviz.core.velocity.estimate import (
    AXES,
    BASELINE_SIGMA_AZ_DEG,
    BASELINE_SIGMA_EL_DEG,
    BASELINE_SIGMA_VR_MPS,
    BASELINE_SITES_M,
    BASELINE_TARGET_M,
    BASELINE_VELOCITY_MPS,
    M_WARN,
    SWEEP_DIRECTION,
    VelocityExperiment,
)

#: Keys of the document whose numbers are a σ, a ratio of σ, m or a condition number.
NONNEGATIVE_KEYS = (
    "sigma_first_order_mps",
    "sigma_mc_mps",
    "bias_mc_se_mps",
    "condition_number",
    "m",
    "ratio_mc_to_linear",
    "ratio_robust_to_linear",
)


def _num(v: float) -> float:
    return float(v)


def _vec(a: np.ndarray) -> list[float]:
    return [_num(v) for v in np.asarray(a, dtype=float).ravel()]


def _mat(a: np.ndarray) -> list[list[float]]:
    return [_vec(row) for row in np.asarray(a, dtype=float)]


def _band(lo: np.ndarray, hi: np.ndarray) -> dict[str, Any]:
    if np.ndim(lo) == 2:
        return {"lo": _mat(lo), "hi": _mat(hi)}
    return {"lo": _vec(lo), "hi": _vec(hi)}


def velocity_document(
    result: VelocityExperiment, where: str = "reproduce velocity"
) -> dict[str, Any]:
    """The whole experiment as a JSON-ready dict (module docstring), every number checked
    (``check_finite_document``: a failure is a ``ResultError`` naming ``where``)."""
    st, mc = result.baseline, result.baseline_mc
    baseline = {
        "sites_m": [list(s) for s in BASELINE_SITES_M],
        "target_m": list(BASELINE_TARGET_M),
        "velocity_mps": list(BASELINE_VELOCITY_MPS),
        "sigma_vr_mps": list(BASELINE_SIGMA_VR_MPS),
        "sigma_el_deg": list(BASELINE_SIGMA_EL_DEG),
        "sigma_az_deg": list(BASELINE_SIGMA_AZ_DEG),
        "sigma_first_order_mps": _vec(st.sigma),
        "sigma_mc_mps": _vec(mc.sigma),
        "sigma_mc_ci95_mps": _band(mc.sigma_ci95_lo, mc.sigma_ci95_hi),
        "bias_mc_mps": _vec(mc.mean),
        "bias_mc_se_mps": _vec(mc.mean_se),
        "bias_second_order_mps": _vec(st.bias_second_order),
        "bias_paper_term_mps": _vec(st.bias_curvature),
        "corr_first_order": _mat(st.correlation),
        "corr_mc": _mat(mc.correlation),
        "corr_mc_ci95": _band(mc.correlation_ci95_lo, mc.correlation_ci95_hi),
        "condition_number": _num(st.geometry.condition_number),
        "m": _num(st.geometry.m),
        "warning": st.geometry.warning,
    }
    sweep = []
    for p in result.sweep:
        s = p.stats
        sweep.append(
            {
                "distance_km": p.distance_km,
                "altitude_km": p.altitude_km,
                "m": _num(s.geometry.m),
                "condition_number": _num(s.geometry.condition_number),
                "ratio_mc_to_linear": _vec(p.mc.sigma / s.sigma),
                "ratio_mc_to_linear_ci95": _band(
                    p.mc.sigma_ci95_lo / s.sigma, p.mc.sigma_ci95_hi / s.sigma
                ),
                "ratio_robust_to_linear": _vec(p.mc.sigma_robust / s.sigma),
                "ratio_robust_to_linear_ci95": _band(
                    p.mc.sigma_robust_ci95_lo / s.sigma, p.mc.sigma_robust_ci95_hi / s.sigma
                ),
                "sigma_first_order_mps": _vec(s.sigma),
                "warning": s.geometry.warning,
            }
        )
    doc = {
        "experiment": "velocity",
        "trials": result.trials,
        "seed": result.seed,
        "sweep_trials": result.sweep_trials,
        "m_warn": M_WARN,
        "band": {
            "level": BAND_LEVEL,
            "sigma": "delete-a-group jackknife",
            "correlation": "delete-a-group jackknife",
            "sigma_robust": "batch means",
            "groups": BAND_GROUPS,
        },
        "sweep_direction": list(SWEEP_DIRECTION),
        "baseline": baseline,
        "sweep": sweep,
    }
    check_finite_document(where, doc, NONNEGATIVE_KEYS)
    return doc


def format_velocity_table(doc: dict[str, Any]) -> str:
    """Plain-text report of :func:`velocity_document`."""

    def f(v: float | None, spec: str) -> str:
        return "-".rjust(len(format(0.0, spec))) if v is None else format(v, spec)

    def row(label: str, vals: list, spec: str = "10.4f") -> str:
        return f"  {label:<28}" + "".join(f(v, spec) for v in vals)

    b = doc["baseline"]
    lines = [
        f"Velocity from 3 radial velocities: {doc['trials']} trials, seed {doc['seed']}",
        f"  condition number of C = {b['condition_number']:.3f},  m = {b['m']:.4f} "
        f"(warning above {doc['m_warn']:g})",
        f"  {'':<28}" + "".join(f"{k:>10}" for k in AXES),
        row("σ first order, m/s", b["sigma_first_order_mps"]),
        row("σ Monte Carlo, m/s", b["sigma_mc_mps"]),
        row("  95% band from", b["sigma_mc_ci95_mps"]["lo"]),
        row("  to", b["sigma_mc_ci95_mps"]["hi"]),
        row("bias Monte Carlo, m/s", b["bias_mc_mps"]),
        row("  ± standard error", b["bias_mc_se_mps"]),
        row("bias 2nd order, m/s", b["bias_second_order_mps"]),
        row("  paper's term only", b["bias_paper_term_mps"]),
        "  correlation first order / Monte Carlo:",
    ]
    for i in range(3):
        lines.append(
            row("", b["corr_first_order"][i], "8.3f")
            + "   "
            + "".join(f(v, "8.3f") for v in b["corr_mc"][i])
        )
    if b.get("warning"):
        lines.append(f"  warning: {b['warning']}")
    lines += [
        "",
        f"Sweep ({doc['sweep_trials']} trials per point): MC σ / first-order σ ± its 95% band "
        "(robust σ in brackets)",
        f"  {'h km':>5} {'D km':>6} {'m':>8}  {'Vx':>21} {'Vy':>21} {'Vz':>21}",
    ]
    for p in doc["sweep"]:
        band = p["ratio_mc_to_linear_ci95"]
        halves = [
            None if lo is None or hi is None else (hi - lo) / 2
            for lo, hi in zip(band["lo"], band["hi"], strict=True)
        ]
        cells = "".join(
            f" {f(r, '6.3g')}±{f(h, '<6.2g')} ({f(q, '5.3f')})"
            for r, h, q in zip(
                p["ratio_mc_to_linear"], halves, p["ratio_robust_to_linear"], strict=True
            )
        )
        flag = "  !" if p.get("warning") else ""
        lines.append(
            f"  {p['altitude_km']:5g} {p['distance_km']:6g} {f(p['m'], '8.3f')} {cells}{flag}"
        )
    lines.append("  ! = m above the warning threshold: first-order statistics unreliable")
    return "\n".join(lines)
