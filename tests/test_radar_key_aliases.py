"""The radars file's deprecated key names (``viz_app.io.plots.DEPRECATED_RADAR_KEYS``).

* A file using an old name (``sigma_range_m``, ``sigma_azimuth_deg``,
  ``sigma_radial_velocity_mps``) reads as the same file with the new name (``sigma_r_m``,
  ``sigma_beta_deg``, ``sigma_vr_mps``), and ``radarviz track`` gives the same tracks from it,
  with one line on standard error per file and old name, however many radars use it.
* A radar giving both names is an error naming both.
* Written radars files (``simulate``, ``write_measurements``) use the new names only.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

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
sigma_r_m = 250.0
sigma_beta_deg = 1.0
sigma_vr_mps = 1.5

[radars.b]
x_m = 60000.0
y_m = -20000.0
z_m = 15.0
sigma_r_m = 100.0
sigma_beta_deg = 0.5
sigma_vr_mps = 0.5
"""


class Alias(NamedTuple):
    """A deprecated key: its old and new name, and the new name's value in radars a and b
    of ``NEW_RADARS``."""

    old: str
    new: str
    a: float
    b: float

    def old_radars(self) -> str:
        """``NEW_RADARS`` with the old name for the new one."""
        return NEW_RADARS.replace(f"{self.new} = ", f"{self.old} = ")


ALIASES = [
    Alias("sigma_range_m", "sigma_r_m", 250.0, 100.0),
    Alias("sigma_azimuth_deg", "sigma_beta_deg", 1.0, 0.5),
    Alias("sigma_radial_velocity_mps", "sigma_vr_mps", 1.5, 0.5),
]
each_alias = pytest.mark.parametrize("key", ALIASES, ids=[k.old for k in ALIASES])


MEASUREMENTS = (
    "time_s,radar,range_m,azimuth_deg\n"
    "0,a,150000,0.5\n"
    "10,b,94000,10.0\n"
    "20,a,152000,0.4\n"
    "30,b,95000,10.2\n"
)
DEPRECATION = "radarviz: {}: key {} is deprecated, read as {}\n"


def test_the_alias_map_names_retired_keys_of_the_current_ones() -> None:
    keys = RADAR_KEYS + OPTIONAL_RADAR_KEYS
    assert DEPRECATED_RADAR_KEYS == {k.old: k.new for k in ALIASES}
    assert all(new in keys and old not in keys for old, new in DEPRECATED_RADAR_KEYS.items())


@each_alias
def test_old_name_reads_as_the_new_one_with_one_deprecation_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], key: Alias
) -> None:
    old, new = key.old, key.new
    old_text = key.old_radars()
    assert old_text.count(f"{old} = ") == 2  # two radars use the old name
    (tmp_path / "new.toml").write_text(NEW_RADARS)
    (tmp_path / "old.toml").write_text(old_text)
    capsys.readouterr()
    expected = load_radars(str(tmp_path / "new.toml"))
    assert capsys.readouterr().err == ""
    read = load_radars(str(tmp_path / "old.toml"))
    assert capsys.readouterr().err == DEPRECATION.format(tmp_path / "old.toml", old, new)
    assert read == expected
    assert [getattr(r, new) for r in read.values()] == [key.a, key.b]

    # parse_radars itself prints nothing: it hands the lines to its caller.
    lines: list[str] = []
    assert parse_radars(old_text, "r.toml", lines) == parse_radars(NEW_RADARS, "r.toml")
    assert lines == [f"r.toml: key {old} is deprecated, read as {new}"]
    assert capsys.readouterr().err == ""


@each_alias
def test_track_reads_an_old_radars_file_as_the_new_one(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    key: Alias,
) -> None:
    old, new = key.old, key.new
    (tmp_path / "m.csv").write_text(MEASUREMENTS)
    (tmp_path / "new.toml").write_text(NEW_RADARS)
    (tmp_path / "radars.toml").write_text(key.old_radars())
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    assert main(["track", "--input", "m.csv", "--radars", "new.toml", "--out", "new.csv"]) == 0
    assert capsys.readouterr().err == ""
    assert main(["track", "--input", "m.csv", "--radars", "radars.toml", "--out", "old.csv"]) == 0
    assert capsys.readouterr().err == DEPRECATION.format("radars.toml", old, new)
    assert (tmp_path / "old.csv").read_bytes() == (tmp_path / "new.csv").read_bytes()


@each_alias
def test_old_and_new_name_together_is_an_error_naming_both(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    key: Alias,
) -> None:
    old, new = key.old, key.new
    both = NEW_RADARS.replace(f"{new} = {key.b!r}\n", f"{new} = {key.b!r}\n{old} = {key.b!r}\n")
    assert both.count(f"{old} = ") == 1
    with pytest.raises(ParameterError) as exc:
        parse_radars(both, "r.toml")
    message = str(exc.value)
    assert "radar 'b'" in message, message
    assert old in message and new in message, message

    (tmp_path / "m.csv").write_text(MEASUREMENTS)
    (tmp_path / "r.toml").write_text(both)
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    assert main(["track", "--input", "m.csv", "--radars", "r.toml", "--out", "t.csv"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("radarviz: error: "), err
    assert old in err and new in err, err
    assert not (tmp_path / "t.csv").exists()


@each_alias
def test_a_bad_value_under_the_old_name_names_the_old_name(
    key: Alias,
) -> None:
    old = key.old
    bad = key.old_radars().replace(f"{old} = {key.a!r}", f"{old} = -1.0")
    with pytest.raises(ParameterError, match=rf"radar 'a', key {old}: must be"):
        parse_radars(bad, "r")


@pytest.mark.parametrize("preset", ["prosov", "fusion"])
def test_written_radars_files_use_the_new_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], preset: str
) -> None:
    plots, radars = simulated_plots(preset, 1, 1.0, 5)
    toml = tmp_path / "r.toml"
    write_measurements(str(tmp_path / "m.csv"), str(toml), plots, radars)
    text = toml.read_text()
    assert text.count("sigma_beta_deg = ") == text.count("sigma_r_m = ") == len(radars)
    assert not any(old in text for old in DEPRECATED_RADAR_KEYS)
    capsys.readouterr()
    assert list(load_radars(str(toml)).values()) == radars
    assert capsys.readouterr().err == ""

    out = tmp_path / "sim.toml"
    args = ["simulate", "--preset", preset, "--out", str(tmp_path / "s.csv"), "--radars-out"]
    assert main([*args, str(out)]) == 0
    assert "sigma_beta_deg = " in out.read_text() and "sigma_r_m = " in out.read_text()
    assert not any(old in out.read_text() for old in DEPRECATED_RADAR_KEYS)
