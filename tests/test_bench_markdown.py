"""``radarviz bench --markdown PAGE.md``: the figures go between the page's marker comments and
nowhere else, the rest of the page is kept byte for byte, and a page without markers (or a
bench that is not the full CPU one) is refused before any timing, in one line, exit 2."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

import radarviz.viz_app.bench.engine as engine
from radarviz.core.params import ParameterError
from radarviz.viz_app.bench.markdown import (
    BEGIN,
    END,
    bench_section,
    replace_section,
    write_bench_section,
)
from radarviz.viz_app.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
PAGE = f"# Title\n\nprose before\n\n{BEGIN}\nold figures\n{END}\n\nprose after, `a` ✓\n"


def _doc() -> dict[str, Any]:
    machine = {"cpu": "Test CPU", "cores": 2, "memory_gib": 4.0, "python": "3.11.7"}
    return {"machine": {**machine, "load_avg_1min": 0.5, "load_avg_1min_after": 1.25}}


def test_section_names_the_command_machine_and_load(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(engine, "format_bench", lambda doc: "the report's text")
    section = bench_section(_doc(), ["bench", "--runs", "1000", "--markdown", "docs/p.md"])
    assert section.startswith(BEGIN) and section.endswith(END)
    assert "`radarviz bench --runs 1000 --markdown docs/p.md`" in section
    assert "Test CPU, 2 cores, 4.0 GiB" in section
    assert "0.5 at the start, 1.25 at the end" in section
    assert "```text\nthe report's text\n```" in section


def test_only_the_section_changes(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text(PAGE, encoding="utf-8")
    write_bench_section(page, f"{BEGIN}\nnew figures\n{END}")
    text = page.read_text(encoding="utf-8")
    assert text == PAGE.replace("old figures", "new figures")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["page.md"]  # no temporary left


@pytest.mark.parametrize(
    "text",
    [
        "no markers at all\n",
        f"{END}\n{BEGIN}\n",  # out of order
        f"{BEGIN}\n{END}\n{BEGIN}\n{END}\n",  # twice
    ],
)
def test_a_page_without_one_pair_of_markers_is_refused(text: str) -> None:
    with pytest.raises(ParameterError, match=r"^--markdown: p\.md must hold the marker lines"):
        replace_section(text, "x", "p.md")


def test_cli_refuses_before_timing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_bench(**_: object) -> dict[str, Any]:
        raise AssertionError("the bench ran although its output page was refused")

    monkeypatch.setattr(engine, "run_bench", no_bench)
    plain = tmp_path / "plain.md"
    plain.write_text("no markers\n", encoding="utf-8")
    for argv, message in (
        (["--markdown", str(tmp_path / "absent.md")], "--markdown: cannot read"),
        (["--markdown", str(plain)], f"--markdown: {plain} must hold the marker lines"),
        (["--markdown", str(plain), "--only", "asterix"], "--markdown writes the full CPU"),
    ):
        assert main(["bench", *argv]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err.startswith(f"radarviz: error: {message}"), err
        assert err.count("\n") == 1
    assert plain.read_text(encoding="utf-8") == "no markers\n"


def test_cli_writes_the_section(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(engine, "run_bench", lambda **_: _doc())
    monkeypatch.setattr(engine, "format_bench", lambda doc: "the report's text")
    page = tmp_path / "page.md"
    page.write_text(PAGE, encoding="utf-8")
    assert main(["bench", "--runs", "1000", "--track-plots", "10000", "--markdown", str(page)]) == 0
    assert capsys.readouterr().out == "the report's text\n"
    text = page.read_text(encoding="utf-8")
    assert text.startswith("# Title\n\nprose before\n\n") and text.endswith(
        "\n\nprose after, `a` ✓\n"
    )
    assert "old figures" not in text and "the report's text" in text
    assert "--runs 1000 --filterpy-runs 200 --targets 1000" in text  # every size spelled out
    assert f"--track-plots 10000 --markdown {page}" in text


def test_performance_page_holds_one_generated_section() -> None:
    text = (ROOT / "docs" / "performance.md").read_text(encoding="utf-8")
    assert text.count(BEGIN) == 1 and text.count(END) == 1
    section = text[text.index(BEGIN) : text.index(END)]
    assert "Produced by `radarviz bench" in section and "- machine: " in section
    assert "load average (1 min): " in section and "```text\nmachine: " in section
