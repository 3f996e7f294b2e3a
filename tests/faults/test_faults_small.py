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
