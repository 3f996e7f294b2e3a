"""The parameter table: one name per quantity, flags and panel controls built from it, one
check on each path, and a start-up that loads no heavy library."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from radarviz.core.experiments.doppler_start import DopplerTrackingConfig
from radarviz.core.experiments.prosov import TrackingConfig
from radarviz.core.params import MIN_MONTE_CARLO_RUNS, PARAMETERS, ParameterError, check
from radarviz.core.scenarios.planar import prosov_target
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.tune.panel import control_spec
from radarviz.viz_app.tune.params import TuneParams

HEAVY = ("scipy.stats", "scipy.linalg", "matplotlib", "rerun", "viser", "dask", "pyarrow")


def _help(capsys: pytest.CaptureFixture[str], *command: str) -> str:
    with pytest.raises(SystemExit):
        main([*command, "--help"])
    return " ".join(capsys.readouterr().out.split())  # argparse wraps lines: undo it


@pytest.mark.parametrize(
    ("command", "name", "flag"),
    [
        (("reproduce", "prosov"), "sigma_beta_deg", "--sigma-beta-deg"),
        (("reproduce", "prosov"), "period_s", "--period"),
        (("track",), "sigma_a_mps2", "--sigma-a"),
        (("sweep",), "sigma_r_m", "--sigma-r-m"),
    ],
)
def test_help_shows_the_table_bounds(
    capsys: pytest.CaptureFixture[str], command: tuple[str, ...], name: str, flag: str
) -> None:
    p = PARAMETERS[name]
    text = _help(capsys, *command)
    unit = f" ({p.unit})" if p.unit else ""
    line = f"{p.symbol}, {p.meaning}{unit}, {p.interval()}"
    assert flag in text and line in text, text
    # The interval is the one the check enforces: just outside each end is rejected.
    assert p.low is not None
    with pytest.raises(ParameterError):
        check(name, p.low if p.low_open else p.low - 1e-9)
    if p.high is not None:
        with pytest.raises(ParameterError):
            check(name, p.high * (1 + 1e-9))
        check(name, p.high)


def test_bad_value_names_the_flag_in_the_cli_and_the_parameter_in_core(capsys) -> None:
    assert main(["reproduce", "prosov", "--sigma-beta-deg", "1", "-1", "--runs", "10"]) == 2
    assert capsys.readouterr().err == (
        "radarviz: error: --sigma-beta-deg must be a finite number in [5e-05, 20] (got -1.0)\n"
    )
    with pytest.raises(ParameterError) as info:
        TrackingConfig(sigma_beta_deg=-1)
    assert info.value.parameter == "sigma_beta_deg"
    assert str(info.value) == "sigma_beta_deg must be a finite number in [5e-05, 20] (got -1)"
    # The same check behind the alias flag of another command, and behind the panel.
    assert main(
        ["simulate", "--preset", "fusion", "--out", "m", "--radars-out", "r", "--scans", "1"]
    )
    assert capsys.readouterr().err.startswith("radarviz: error: --scans must be an integer in [2,")
    with pytest.raises(
        ParameterError, match=r"^sigma_r_m must be a finite number in \[2, 100000\]"
    ):
        TuneParams(sigma_r_m=-5.0)


def test_configs_take_their_defaults_from_the_table() -> None:
    cfg = TrackingConfig()
    for name in ("sigma_r_m", "sigma_beta_deg", "runs", "seed", "sigma_a_mps2", "sigma_v0_mps"):
        assert getattr(cfg, name) == PARAMETERS[name].default, name
    assert cfg.target == prosov_target()
    assert cfg.target.period_s == PARAMETERS["period_s"].default
    assert cfg.target.steps == PARAMETERS["steps"].default
    assert cfg.target.x0_m == PARAMETERS["target_range_m"].default
    assert cfg.target.vx_mps == PARAMETERS["target_speed_mps"].default
    dop = DopplerTrackingConfig()
    assert dop.sigma_beta_deg == cfg.sigma_beta_deg and dop.steps == cfg.target.steps


def test_panel_controls_come_from_the_table() -> None:
    beta = control_spec("sigma_beta_deg")
    p = PARAMETERS["sigma_beta_deg"]
    assert (beta["label"], beta["min"], beta["max"]) == ("σβ (deg)", p.low, p.high)
    assert beta["hint"] == p.help()
    assert control_spec("runs")["max"] < PARAMETERS["runs"].default * 10  # the panel's limit
    with pytest.raises(
        ParameterError, match=rf"^runs must be an integer in \[{MIN_MONTE_CARLO_RUNS}, "
    ):
        TuneParams(runs=control_spec("runs")["max"] + 1)


def _loaded(code: str) -> list[str]:
    """The ``HEAVY`` modules a fresh interpreter holds after running ``code``."""
    probe = (
        f"{code}\nimport sys\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in "
        "{'scipy','matplotlib','rerun','viser','dask','pyarrow'} and m.count('.')<2))"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout
    return [m for m in ast.literal_eval(out.splitlines()[-1]) if m in HEAVY]


def test_cli_start_up_imports_no_heavy_library() -> None:
    assert _loaded("import radarviz.viz_app.cli.main") == []


def test_simulating_a_csv_imports_no_rerun(tmp_path: Path) -> None:
    code = (
        "from radarviz.viz_app.cli.main import main\n"
        f"assert main(['simulate', '--preset', 'fusion', '--scans', '3', '--out', "
        f"{str(tmp_path / 'm.csv')!r}, '--radars-out', {str(tmp_path / 'r.toml')!r}]) == 0"
    )
    assert _loaded(code) == []
    assert (tmp_path / "m.csv").read_text().count("\n") == 1 + 3 * 3
