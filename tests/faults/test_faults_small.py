"""Small faults: each once accepted something it should have refused."""

from __future__ import annotations

import pytest

from radarviz.viz_app.tune.guard import PanelGuard, _host_name


@pytest.mark.parametrize(
    ("header", "name"),
    [
        ("[::1]:8080", "::1"),
        ("[::1]", "::1"),
        ("[::1].evil.example:8080", ""),
        ("[::1]evil:8080", ""),
        ("[::1]:80x", ""),
        ("localhost:8080", "localhost"),
    ],
)
def test_a_bracketed_host_is_an_address_and_a_port_only(header: str, name: str) -> None:
    assert _host_name(header) == name
    if not name:
        assert not PanelGuard().host_allowed(_host_name(header))


def test_simulate_prosov_refuses_scans_it_would_ignore(tmp_path, capsys) -> None:
    """``simulate --preset prosov --scans 500`` wrote the preset's 60 plots without a word."""
    from radarviz.viz_app.cli.main import main

    out, toml = tmp_path / "m.csv", tmp_path / "r.toml"
    argv = ["simulate", "--preset", "prosov", "--out", str(out), "--radars-out", str(toml)]
    assert main([*argv, "--scans", "500"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("radarviz: error: --scans is not the prosov preset's"), line
    assert not out.exists() and not toml.exists()
    assert main(argv) == 0  # without --scans: its 60 scans, as documented
