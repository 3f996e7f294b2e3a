"""Corners of the documented ranges that gave NaN.

``reproduce prosov`` at σβ = 10⁻⁶° failed with "nees_state of ukf at scan 2 is NaN": the UKF's
semi-definite Cholesky took every pivot below 10⁻⁹ of its diagonal for a null direction, and
the cross-range velocity given the position, (r σβ / T)² = 7·10⁻¹⁴ of σv0², is such a pivot;
zeroed, it left P⁺ singular. A positive pivot is now kept (only a slightly negative one is
rounding). At σr = 10⁻³ m against σβ = 20° (r σβ = 52 km), and at σr = 10⁵ m against
σβ = 10⁻⁵°, the state covariance is singular to rounding whatever the filter (naive, ekf and
ukf NaN): the minimums of σr and σβ are now the smallest at which every corner is finite.
"""

from __future__ import annotations

import json

import pytest

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
