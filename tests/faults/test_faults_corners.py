"""Corners of the documented ranges that gave NaN.

``reproduce prosov`` at σβ = 10⁻⁶° failed with "nees_state of ukf at scan 2 is NaN": the UKF's
semi-definite Cholesky took every pivot below 10⁻⁹ of its diagonal for a null direction, and
the cross-range velocity given the position, (r σβ / T)² = 7·10⁻¹⁴ of σv0², is such a pivot;
zeroed, it left P⁺ singular. A positive pivot is now kept (only a slightly negative one is
rounding). At σr = 10⁻³ m against σβ = 20° (r σβ = 52 km), and at σr = 10⁵ m against
σβ = 10⁻⁵°, the state covariance is singular to rounding whatever the filter (naive, ekf and
ukf NaN): the minimums of σr and σβ are now the smallest at which every corner is finite, and
a run whose σr / (r σβ) leaves the interval probed finite (a sweep's range or period takes r far
from 150 km) is refused in one line.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from radarviz.core.experiments.prosov import MAX_RANGE_CROSS_RATIO, MIN_RANGE_CROSS_RATIO
from radarviz.core.params import PARAMETERS
from radarviz.viz_app.cli.main import main

SR, SB = PARAMETERS["sigma_r_m"], PARAMETERS["sigma_beta_deg"]


def run(capsys, *argv: str) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err.strip()


@pytest.mark.parametrize("sigma_r_m", [SR.low, SR.high])
@pytest.mark.parametrize("sigma_beta_deg", [SB.low, SB.high])
def test_every_method_is_finite_at_each_corner_of_sigma_r_and_sigma_beta(
    capsys, sigma_r_m: float, sigma_beta_deg: float
) -> None:
    # The default number of runs: a singular covariance shows in a few runs of 1000, not in 20.
    code, out, err = run(
        capsys,
        "reproduce",
        "prosov",
        "--sigma-r-m",
        f"{sigma_r_m:g}",
        "--sigma-beta-deg",
        f"{sigma_beta_deg:g}",
        "--json",
    )
    assert code == 0, err
    json.loads(out)  # written with allow_nan=False: every value finite or null


@pytest.mark.parametrize(("flag", "spec"), [("--sigma-r-m", SR), ("--sigma-beta-deg", SB)])
def test_half_the_minimum_is_refused_in_one_line(capsys, flag: str, spec) -> None:
    code, out, err = run(capsys, "reproduce", "prosov", flag, f"{spec.low / 2:g}")
    assert code == 2 and out == "", err
    assert err == (
        f"radarviz: error: {flag} must be a finite number in [{spec.low:g}, {spec.high:g}] "
        f"(got {spec.low / 2!r})"
    )


def test_a_sweep_at_the_corners_of_its_grid_is_finite_or_refused_up_front(
    tmp_path: Path, capsys
) -> None:
    """The grid's range axis runs from 1 m to 10⁵ km and T to an hour, so σr against r σβ
    spans far more than the ranges of σr and σβ alone: the grid corner σr = 10⁵ m, r0 = 1 m
    gave NaN (naive, ekf, ukf), as did σr = 2 m, σβ = 20° with T = 3600 s (the target 42 000 km
    out by the last scan). ``TrackingConfig`` now refuses, in one line before any run, a point
    whose σr / (r σβ) leaves the interval probed finite; a corner inside it is finite."""
    out = tmp_path / "s.parquet"
    high_km = PARAMETERS["target_range_m"].high / 1000.0
    grid = [f"range_km=0.001,{high_km:g}", "period_s=0.001,3600"]
    common = ["sweep", "--scheduler", "serial", "--out", str(out), "--json", "--grid", *grid]
    code, _, err = run(capsys, *common, "--sigma-r-m", f"{SR.high:g}", "--sigma-beta-deg", "20")
    assert code == 0, err
    assert out.exists()
    out.unlink()
    code, _, err = run(capsys, *common, "--sigma-r-m", f"{SR.high:g}", "--runs", "3")
    assert code == 2, err
    (line,) = err.splitlines()
    assert line.startswith(
        f"radarviz: error: --sigma-r-m must be {MIN_RANGE_CROSS_RATIO:g} to "
        f"{MAX_RANGE_CROSS_RATIO:g} times the cross-range σ r σβ along the run "
    ), line
    assert not out.exists()


def test_prosov_refuses_a_period_that_takes_the_target_out_of_the_finite_interval(
    capsys,
) -> None:
    argv = ["reproduce", "prosov", "--sigma-r-m", "2", "--sigma-beta-deg", "20"]
    code, out, err = run(capsys, *argv, "--period", "3600")
    assert code == 2 and out == "", err
    assert "at r = 4.26e+07 m): the position covariance would be singular" in err, err


def test_a_3d_track_straight_overhead_with_doppler_stays_finite(tmp_path: Path, capsys) -> None:
    """Every elevation 89.9999°, with Doppler, the default IMM: the ukf rows were NaN from the
    third plot. The IMM's mode probabilities are updated once per stage of a plot (position,
    then Doppler); the first stage left one model at μ = 0 (its likelihood e⁻⁷⁴⁵ below the
    other's), the second favoured that model as strongly, and with only the likelihoods shifted
    by their maximum both weights were 0: μ = 0 / 0. The prior now enters the shift. The track
    is where the plots put it: over the radar, at the measured range."""
    rng = np.random.default_rng(5)
    sigma_r_m, sigma_deg, sigma_vr_mps = 150.0, 0.3, 1.0
    lines = ["time_s,radar,range_m,azimuth_deg,elevation_deg,radial_velocity_mps"]
    for k in range(20):
        r = 10000.0 + 50.0 * k + sigma_r_m * rng.standard_normal()
        vr = 5.0 + sigma_vr_mps * rng.standard_normal()
        az = 30.0 + sigma_deg * rng.standard_normal()
        lines.append(f"{10.0 * k!r},a,{r!r},{az!r},89.9999,{vr!r}")
    meas, radars, out = tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "t.csv"
    meas.write_text("\n".join(lines) + "\n")
    radars.write_text(
        "[radars.a]\nx_m = 0.0\ny_m = 0.0\nz_m = 0.0\n"
        f"sigma_r_m = {sigma_r_m!r}\nsigma_beta_deg = {sigma_deg!r}\n"
        f"sigma_elevation_deg = {sigma_deg!r}\nsigma_vr_mps = {sigma_vr_mps!r}\n"
    )
    code, _, err = run(
        capsys, "track", "--input", str(meas), "--radars", str(radars), "--out", str(out)
    )
    assert code == 0, err
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["method"] for r in rows} >= {"ukf", "ekf", "naive"}
    # A plot's horizontal σ at the pole is r σε (52 m at 10 km); the truth is at x = y = 0 and
    # z = r: every filtered position within 5 plot σ of it (the filters only average plots).
    # Not the ukf's: its sigma points, 2.4 σ ≈ 25 km apart horizontally after the 1000 m/s
    # start, straddle the pole, so their azimuths span every direction and its track wanders
    # off by hundreds of km (finite, but no estimate; the conversions and the ekf are not).
    horizontal_m = 5.0 * 11000.0 * math.radians(sigma_deg)
    for r in (r for r in rows if r["method"] != "ukf"):
        t = float(r["time_s"])
        assert abs(float(r["x_m"])) < horizontal_m and abs(float(r["y_m"])) < horizontal_m, r
        assert abs(float(r["z_m"]) - (10000.0 + 5.0 * t)) < 5.0 * sigma_r_m, r
