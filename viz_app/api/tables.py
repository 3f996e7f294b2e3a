"""Results as tables: one row per observation, columns named with their units.

A column is its quantity's name with the unit's suffix (``_m``, ``_mps``, ``_mps2``, ``_rad``,
``_deg``, ``_s``, ``_percent``), the same name the result's field, the JSON document of the
command line and the sweep's Parquet table give it. Dimensionless statistics carry none: a
NEES or NIS (``nees_pos``, ``nees_state``), a count (``scan``, ``k``), a condition number.

``to_columns`` gives plain numpy columns, ``to_arrow`` a ``pyarrow.Table`` and ``to_table`` a
``pandas.DataFrame`` (pandas comes with the ``notebook`` extra).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from radarviz.core.experiments.prosov import TrackingResult
from radarviz.core.finite_memory.fit import STATES, GorshkovResult
from radarviz.core.metrics import TrackMetrics
from radarviz.core.params import ParameterError
from radarviz.core.velocity.estimate import VelocityEstimate
from radarviz.experiments import GorshkovRun
from radarviz.tracking import Tracks

Columns = dict[str, NDArray[Any]]
#: The state components of a track row, in the order of the state vector (x, vx, y, vy, z, vz).
STATE_COLUMNS = ("x_m", "vx_mps", "y_m", "vy_mps", "z_m", "vz_mps")


def _stack(parts: Sequence[Columns]) -> Columns:
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} if parts else {}


def _prosov(results: Sequence[TrackingResult]) -> Columns:
    parts = []
    for res in results:
        n = res.n.astype(np.int64)
        for method, m in res.metrics.items():
            part: Columns = {
                "sigma_beta_deg": np.full(n.size, res.config.sigma_beta_deg),
                "method": np.full(n.size, method, dtype=object),
                "scan": n,
            }
            for field in TrackMetrics._fields:
                part[field] = np.asarray(getattr(m, field), dtype=float)
            parts.append(part)
    return _stack(parts)


def _gorshkov(result: GorshkovResult) -> Columns:
    # Wide, one row per (radar, variant, k): σ of r, Vr and a have three different units, so
    # each parameter's values get columns of their own, named with the unit (``STATES``).
    parts = []
    ks = result.ks.astype(np.int64)
    for rad in result.radars:
        for variant, stats in (
            ("range_only", rad.range_only),
            ("range_doppler", rad.range_doppler),
        ):
            part: Columns = {
                "radar": np.full(ks.size, rad.preset.name, dtype=object),
                "variant": np.full(ks.size, variant, dtype=object),
                "k": ks,
            }
            for j, (name, unit) in enumerate(STATES):
                part[f"sigma_analytic_{name}_{unit}"] = stats.sigma_analytic[:, j]
                part[f"sigma_mc_{name}_{unit}"] = stats.sigma_mc[:, j]
                part[f"sigma_mc_ci95_lo_{name}_{unit}"] = stats.sigma_mc_ci95_lo[:, j]
                part[f"sigma_mc_ci95_hi_{name}_{unit}"] = stats.sigma_mc_ci95_hi[:, j]
                part[f"bias_mc_{name}_{unit}"] = stats.bias_mc[:, j]
                part[f"gain_analytic_{name}_percent"] = rad.gain_analytic[:, j]
                part[f"gain_mc_{name}_percent"] = rad.gain_mc[:, j]
            parts.append(part)
    return _stack(parts)


def _tracks(tracks: Tracks) -> Columns:
    steps = tracks.steps
    x = np.array([s.x for s in steps], dtype=float).reshape(-1, 6)
    sd = np.sqrt(np.array([np.diag(s.P) for s in steps], dtype=float).reshape(-1, 6))
    cols: Columns = {
        "plot": np.array([s.plot for s in steps], dtype=np.int64),
        "time_s": np.array([s.time_s for s in steps], dtype=float),
        "method": np.array([s.method for s in steps], dtype=object),
    }
    if any(s.target for s in steps):
        cols["target"] = np.array([s.target for s in steps], dtype=object)
    if any(s.status for s in steps):
        cols["status"] = np.array([s.status for s in steps], dtype=object)
    for j, name in enumerate(STATE_COLUMNS):
        cols[name] = x[:, j]
    for j, name in enumerate(STATE_COLUMNS):
        cols["sigma_" + name] = sd[:, j]
    return cols


def _velocity(est: VelocityEstimate) -> Columns:
    sd = np.sqrt(np.diag(est.covariance))
    cols: Columns = {}
    for j, axis in enumerate("xyz"):
        cols[f"v{axis}_mps"] = np.array([est.velocity[j]])
        cols[f"sigma_v{axis}_mps"] = np.array([sd[j]])
    cols["condition_number"] = np.array([est.condition_number])
    cols["geometry_metric"] = np.array([est.m])
    return cols


def to_columns(result: object) -> Columns:
    """The columns of a result, each a numpy array of one length.

    Args:
        result: a ``run_prosov`` list (or one ``TrackingResult``): one row per (σβ, method,
            scan); a ``GorshkovRun`` or ``GorshkovResult``: one row per (radar, variant, k),
            each statistic in a column per parameter (``sigma_mc_r_m``, ``sigma_mc_vr_mps``,
            ``sigma_mc_a_mps2``, ``gain_mc_r_percent``, …); ``Tracks``: one row per (plot,
            method) with the state and its 1σ (and the target, for plots of many targets); a
            ``VelocityEstimate``: one row.

    Returns:
        Column name → (rows,) array.
    """
    if isinstance(result, TrackingResult):
        return _prosov([result])
    if (
        isinstance(result, list | tuple)
        and result
        and all(isinstance(r, TrackingResult) for r in result)
    ):
        return _prosov(result)
    if isinstance(result, GorshkovRun):
        return _gorshkov(result.fits)
    if isinstance(result, GorshkovResult):
        return _gorshkov(result)
    if isinstance(result, Tracks):
        return _tracks(result)
    if isinstance(result, VelocityEstimate):
        return _velocity(result)
    raise ParameterError(
        "result must be what run_prosov, run_gorshkov, track or estimate_velocity returned "
        f"(got {type(result).__name__})",
        "result",
    )


def to_arrow(result: object) -> Any:
    """``to_columns`` as a ``pyarrow.Table``."""
    import pyarrow as pa

    return pa.table(
        {k: pa.array(list(v) if v.dtype == object else v) for k, v in to_columns(result).items()}
    )


def to_table(result: object) -> Any:
    """``to_columns`` as a ``pandas.DataFrame`` (needs pandas: ``pip install -e '.[notebook]'``)."""
    try:
        import pandas as pd
    except ModuleNotFoundError:
        raise ParameterError(
            "to_table needs pandas (install radarviz with the notebook extra); to_arrow does not",
            "result",
        ) from None
    return pd.DataFrame(to_columns(result))
