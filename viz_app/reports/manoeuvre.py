"""The manoeuvre reproduction as a JSON document and a readable table.

JSON keys are an interface (``radarviz reproduce manoeuvre --json``). Every Monte Carlo
figure is ``{"value": v, "ci95": [lo, hi]}`` (delete-a-group jackknife over the runs,
``core.confidence``); null where a value is undefined. ``targets`` states the two claims the
reproduction checks for the default motion model (``imm``) and whether each method meets
them; ``flags_q0`` whether the monitor flags the Q = 0 filter on every run.
"""

from __future__ import annotations

import math
from typing import Any

from radarviz.core.confidence import BAND_GROUPS, BAND_LEVEL
from radarviz.core.experiments.manoeuvre import Figure, ManoeuvreResult
from radarviz.core.filters.models import CVModel, IMMModel
from radarviz.core.tracking.consistency import INCONSISTENT_FRACTION, NIS_BAND_LEVEL

#: The reproduction's targets for the default motion model.
RMSE_RATIO_TARGET = 0.6
NEES_TARGET = (0.7, 1.5)  # × the 3 degrees of freedom
NEES_DOF = 3


def _num(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def figure_document(f: Figure) -> dict[str, Any]:
    return {"value": _num(f.value), "ci95": [_num(f.lo), _num(f.hi)]}


def _model_document(m: CVModel | IMMModel) -> dict[str, Any]:
    if isinstance(m, IMMModel):
        return {
            "kind": "imm",
            "sigma_a_mps2": list(m.sigma_a_mps2),
            "transition_prob": [list(r) for r in m.transition],
            "turn_rate_degps": list(m.turn_rate_degps or [0.0] * m.models),
        }
    return {"kind": "cv", "sigma_a_mps2": m.sigma_a_mps2}


def manoeuvre_document(res: ManoeuvreResult) -> dict[str, Any]:
    cfg = res.config
    models: dict[str, Any] = {}
    for label, per_method in res.results.items():
        models[label] = {
            "model": _model_document(cfg.models[label]),
            "methods": {
                name: {
                    "rmse_m": figure_document(r.rmse_m),
                    "rmse_over_raw": figure_document(r.rmse_ratio),
                    "nees_pos": figure_document(r.nees),
                    "nees_plots_in_band": _num(r.nees_plots_in_band),
                    "nis_out_of_band": figure_document(r.nis_out_fraction),
                    "runs_flagged": _num(r.flagged_runs),
                }
                for name, r in per_method.items()
            },
        }
    lo, hi = NEES_TARGET
    imm = res.results.get("imm", {})
    targets = {
        "rmse_over_raw_max": RMSE_RATIO_TARGET,
        "nees_pos_range": [lo * NEES_DOF, hi * NEES_DOF],
        "imm_meets": {
            name: bool(
                r.rmse_ratio.hi <= RMSE_RATIO_TARGET
                and lo * NEES_DOF <= r.nees.lo
                and r.nees.hi <= hi * NEES_DOF
            )
            for name, r in imm.items()
        },
    }
    q0 = res.results.get("cv-q0", {})
    doc: dict[str, Any] = {
        "experiment": "manoeuvre",
        "flights": list(res.flights),
        "plots_per_flight": res.plots_per_flight,
        "runs_per_flight": cfg.runs,
        "seed": cfg.seed,
        "burn_in_plots": cfg.burn_in_plots,
        "nis_window": cfg.nis_window,
        "nis_band_level": NIS_BAND_LEVEL,
        "inconsistent_fraction": INCONSISTENT_FRACTION,
        "band": f"{BAND_LEVEL:.0%} delete-a-group jackknife over runs, {BAND_GROUPS} groups",
        "raw_rmse_m": figure_document(res.raw_rmse_m),
        "nees_band_per_plot": [res.nees_band_per_plot[0], res.nees_band_per_plot[1]],
        "models": models,
        "targets": targets,
        "flags_q0": bool(q0) and all(r.flagged_runs == 1.0 for r in q0.values()),
    }
    if res.finite_memory:
        doc["finite_memory"] = [
            {
                "radar": f.radar,
                "k": f.k,
                "with_doppler": f.with_doppler,
                "rmse_m": figure_document(f.rmse_m),
                "raw_rmse_m": figure_document(f.raw_rmse_m),
                "rmse_over_raw": figure_document(f.rmse_ratio),
                "nees_pos": figure_document(f.nees),
            }
            for f in res.finite_memory
        ]
    if res.straight is not None:
        s = res.straight
        doc["straight_line"] = {
            "runs": s.runs,
            "scans": "31-60",
            "rmse_cv_q0_m": {k: _num(v) for k, v in s.rmse_cv_m.items()},
            "rmse_imm_m": {k: _num(v) for k, v in s.rmse_imm_m.items()},
            "imm_over_cv": {k: figure_document(v) for k, v in s.ratio.items()},
        }
    return doc


def _fig(d: dict[str, Any], fmt: str = ".3g") -> str:
    v, (lo, hi) = d["value"], d["ci95"]
    if v is None:
        return "n/a"
    band = "" if lo is None or hi is None else f" [{lo:{fmt}}, {hi:{fmt}}]"
    return f"{v:{fmt}}{band}"


def format_manoeuvre_table(doc: dict[str, Any]) -> str:
    lines = [
        f"Manoeuvring aircraft: {len(doc['flights'])} flights × {doc['runs_per_flight']} runs, "
        f"{doc['plots_per_flight']} plots each (3 radars), first {doc['burn_in_plots']} plots "
        "left out of RMSE and NEES",
        f"raw converted measurements (ucm): RMSE {_fig(doc['raw_rmse_m'], '.0f')} m",
        f"({doc['band']}; NIS window {doc['nis_window']} updates, band "
        f"{doc['nis_band_level']:.0%}; flagged: out of band > {doc['inconsistent_fraction']:.0%})",
        "",
        f"{'model':8} {'method':6} {'RMSE, m':>22} {'RMSE/raw':>22} {'NEES (3 dof)':>26} "
        f"{'NIS out':>22} {'flagged':>8}",
    ]
    for label, m in doc["models"].items():
        for name, r in m["methods"].items():
            lines.append(
                f"{label:8} {name:6} {_fig(r['rmse_m'], '.4g'):>22} "
                f"{_fig(r['rmse_over_raw']):>22} {_fig(r['nees_pos']):>26} "
                f"{_fig(r['nis_out_of_band'], '.2f'):>22} {r['runs_flagged']:>8.0%}"
            )
    t = doc["targets"]
    lines.append("")
    lines.append(
        f"targets (imm): RMSE/raw ≤ {t['rmse_over_raw_max']}, NEES in "
        f"[{t['nees_pos_range'][0]:.2g}, {t['nees_pos_range'][1]:.2g}] (bands inside): "
        + ", ".join(f"{k} {'met' if v else 'NOT met'}" for k, v in t["imm_meets"].items())
    )
    lines.append(f"monitor flags cv-q0 on every run: {'yes' if doc['flags_q0'] else 'no'}")
    for f in doc.get("finite_memory", []):
        lines.append(
            f"finite-memory track, radar {f['radar']}, k = {f['k']} "
            f"({'range + Doppler' if f['with_doppler'] else 'range only'}): RMSE "
            f"{_fig(f['rmse_m'], '.4g')} m against its radar's raw plots "
            f"{_fig(f['raw_rmse_m'], '.4g')} m (ratio {_fig(f['rmse_over_raw'])}), "
            f"NEES {_fig(f['nees_pos'])}"
        )
    s = doc.get("straight_line")
    if s:
        lines.append("")
        lines.append(
            f"Straight-line target (Prosov, 2D, {s['runs']} runs, scans {s['scans']}): "
            "IMM RMSE / matched CV (Q = 0) RMSE"
        )
        for k, v in s["imm_over_cv"].items():
            lines.append(
                f"  {k:7} {_fig(v)}   (CV {s['rmse_cv_q0_m'][k]:.0f} m, "
                f"IMM {s['rmse_imm_m'][k]:.0f} m)"
            )
    return "\n".join(lines)
