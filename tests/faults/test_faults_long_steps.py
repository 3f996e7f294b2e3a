"""Plots of a target 10⁸ s apart: every method's track stays finite and positive semi-definite.

The prediction over such a step makes P ≈ 10³¹ m² (σa² T⁴ / 4 with the IMM's σa = 12 m/s²)
against a noise R ≈ 10⁴ m²; an update that subtracts from P a term of P's size (P − K S Kᵀ, or
the Joseph form multiplied out) leaves rounding of either sign, and the run stopped at its
first negative variance (exit 1). The update is now the Joseph form on a Cholesky factor of P
(``core.filters.joseph``), a sum of squares.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from radarviz.core.filters.methods import ALL_METHODS
from radarviz.viz_app.cli.main import main

#: The time between a target's plots (s).
STEP_S = 1e8

#: fusion's scans per radar: its last plot's time stays inside the files' [−1e10, 1e10] s.
SCANS = 20

#: preset → (its time between a target's plots (s), dimensions)
PRESETS = {"prosov": (10.0, 2), "fusion": (10.0 / 3.0, 3)}


def _stretched_plots(tmp_path: Path, preset: str) -> tuple[Path, Path]:
    """The preset's simulated plots with their times scaled to ``STEP_S`` between plots."""
    meas, radars = tmp_path / f"{preset}.csv", tmp_path / f"{preset}.toml"
    argv = ["simulate", "--preset", preset, "--out", str(meas), "--radars-out", str(radars)]
    if preset == "fusion":  # prosov's 60 plots end at 5.9e9 s
        argv += ["--scans", str(SCANS)]
    assert main(argv) == 0
    period_s, _ = PRESETS[preset]
    with meas.open(newline="") as fh:
        rows = list(csv.reader(fh))
    with meas.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(rows[0])
        for r in rows[1:]:
            w.writerow([repr(float(r[0]) * STEP_S / period_s), *r[1:]])
    return meas, radars


def _covariances(path: Path, dims: int) -> np.ndarray:
    """Every row's state covariance (rows, 2·dims, 2·dims) in (x, y[, z], vx, vy[, vz]) order."""
    axes = "xyz"[:dims]
    names = [*axes, *(f"v{a}" for a in axes)]
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    n = 2 * dims
    P = np.empty((len(rows), n, n))
    unit = {(False, False): "m2", (False, True): "m2ps", (True, True): "m2ps2"}
    for i, a in enumerate(names):
        for j, b in enumerate(names[i:], start=i):
            key = f"p_{a}{b}_{unit[a.startswith('v'), b.startswith('v')]}"
            for m, row in enumerate(rows):
                P[m, i, j] = P[m, j, i] = float(row[key])
    return P


@pytest.mark.parametrize("method", ALL_METHODS)
@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_a_track_of_plots_1e8_s_apart_is_finite_and_semidefinite(
    tmp_path: Path, capsys, preset: str, method: str
) -> None:
    meas, radars = _stretched_plots(tmp_path, preset)
    out = tmp_path / "tracks.csv"
    capsys.readouterr()
    code = main(["track", "--input", str(meas), "--radars", str(radars), "--out", str(out),
                 "--method", method])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 0, err
    _, dims = PRESETS[preset]
    P = _covariances(out, dims)
    assert np.all(np.isfinite(P))
    d = np.sqrt(np.diagonal(P, axis1=-2, axis2=-1))
    assert np.all(d > 0.0)
    # Each entry of a sum of n squares and K R Kᵀ is within n rounding errors of
    # √(P_ii P_jj), so the correlation matrix is within n · n ε (its spectral norm) of one
    # that is positive semi-definite.
    n = P.shape[-1]
    corr = P / (d[..., :, None] * d[..., None, :])
    assert np.linalg.eigvalsh(corr).min() >= -n * n * np.finfo(float).eps
