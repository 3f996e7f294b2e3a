"""The radars file's deprecated key names (``viz_app.io.plots.DEPRECATED_RADAR_KEYS``).

* A file using an old name (``sigma_azimuth_deg``) reads as the same file with the new name
  (``sigma_beta_deg``), and ``radarviz track`` gives the same tracks from it, with one line on
  standard error per file and old name, however many radars use it.
* A radar giving both names is an error naming both.
* Written radars files (``simulate``, ``write_measurements``) use the new names only.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from radarviz.core.params import ParameterError
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io.plots import (
    DEPRECATED_RADAR_KEYS,
    OPTIONAL_RADAR_KEYS,
    RADAR_KEYS,
    load_radars,
    parse_radars,
    simulated_plots,
    write_measurements,
)

NEW_RADARS = """\
[radars.a]
x_m = 0.0
y_m = 0.0
z_m = 0.0
sigma_range_m = 250.0
sigma_beta_deg = 1.0

[radars.b]
x_m = 60000.0
y_m = -20000.0
z_m = 15.0
sigma_range_m = 100.0
sigma_beta_deg = 0.5
"""
OLD_RADARS = NEW_RADARS.replace("sigma_beta_deg", "sigma_azimuth_deg")
MEASUREMENTS = (
    "time_s,radar,range_m,azimuth_deg\n"
    "0,a,150000,0.5\n"
    "10,b,94000,10.0\n"
    "20,a,152000,0.4\n"
    "30,b,95000,10.2\n"
)
DEPRECATION = "radarviz: {}: key sigma_azimuth_deg is deprecated, read as sigma_beta_deg\n"


def test_the_alias_map_names_retired_keys_of_the_current_ones() -> None:
    keys = RADAR_KEYS + OPTIONAL_RADAR_KEYS
    assert DEPRECATED_RADAR_KEYS == {"sigma_azimuth_deg": "sigma_beta_deg"}
    assert all(new in keys and old not in keys for old, new in DEPRECATED_RADAR_KEYS.items())


def test_old_name_reads_as_the_new_one_with_one_deprecation_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert OLD_RADARS.count("sigma_azimuth_deg") == 2  # two radars use the old name
    (tmp_path / "new.toml").write_text(NEW_RADARS)
    (tmp_path / "old.toml").write_text(OLD_RADARS)
    capsys.readouterr()
    new = load_radars(str(tmp_path / "new.toml"))
    assert capsys.readouterr().err == ""
    old = load_radars(str(tmp_path / "old.toml"))
    assert capsys.readouterr().err == DEPRECATION.format(tmp_path / "old.toml")
    assert old == new
    assert [r.sigma_beta_deg for r in old.values()] == [1.0, 0.5]

    # parse_radars itself prints nothing: it hands the lines to its caller.
    lines: list[str] = []
    assert parse_radars(OLD_RADARS, "r.toml", lines) == parse_radars(NEW_RADARS, "r.toml")
    assert lines == ["r.toml: key sigma_azimuth_deg is deprecated, read as sigma_beta_deg"]
    assert capsys.readouterr().err == ""


def test_track_reads_an_old_radars_file_as_the_new_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "m.csv").write_text(MEASUREMENTS)
    (tmp_path / "new.toml").write_text(NEW_RADARS)
    (tmp_path / "radars.toml").write_text(OLD_RADARS)
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    assert main(["track", "--input", "m.csv", "--radars", "new.toml", "--out", "new.csv"]) == 0
    assert capsys.readouterr().err == ""
    assert main(["track", "--input", "m.csv", "--radars", "radars.toml", "--out", "old.csv"]) == 0
    assert capsys.readouterr().err == DEPRECATION.format("radars.toml")
    assert (tmp_path / "old.csv").read_bytes() == (tmp_path / "new.csv").read_bytes()


def test_old_and_new_name_together_is_an_error_naming_both(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    both = NEW_RADARS.replace(
        "sigma_beta_deg = 0.5\n", "sigma_beta_deg = 0.5\nsigma_azimuth_deg = 0.5\n"
    )
    with pytest.raises(ParameterError) as exc:
        parse_radars(both, "r.toml")
    message = str(exc.value)
    assert "radar 'b'" in message, message
    assert "sigma_azimuth_deg" in message and "sigma_beta_deg" in message, message

    (tmp_path / "m.csv").write_text(MEASUREMENTS)
    (tmp_path / "r.toml").write_text(both)
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    assert main(["track", "--input", "m.csv", "--radars", "r.toml", "--out", "t.csv"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("radarviz: error: "), err
    assert "sigma_azimuth_deg" in err and "sigma_beta_deg" in err, err
    assert not (tmp_path / "t.csv").exists()


def test_a_bad_value_under_the_old_name_names_the_old_name() -> None:
    with pytest.raises(ParameterError, match=r"radar 'a', key sigma_azimuth_deg: must be"):
        parse_radars(OLD_RADARS.replace("sigma_azimuth_deg = 1.0", "sigma_azimuth_deg = 90.0"), "r")


@pytest.mark.parametrize("preset", ["prosov", "fusion"])
def test_written_radars_files_use_the_new_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], preset: str
) -> None:
    plots, radars = simulated_plots(preset, 1, 1.0, 5)
    toml = tmp_path / "r.toml"
    write_measurements(str(tmp_path / "m.csv"), str(toml), plots, radars)
    text = toml.read_text()
    assert text.count("sigma_beta_deg = ") == len(radars)
    assert not any(old in text for old in DEPRECATED_RADAR_KEYS)
    capsys.readouterr()
    assert list(load_radars(str(toml)).values()) == radars
    assert capsys.readouterr().err == ""

    out = tmp_path / "sim.toml"
    args = ["simulate", "--preset", preset, "--out", str(tmp_path / "s.csv"), "--radars-out"]
    assert main([*args, str(out)]) == 0
    assert "sigma_beta_deg = " in out.read_text()
    assert not any(old in out.read_text() for old in DEPRECATED_RADAR_KEYS)
