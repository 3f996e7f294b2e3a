"""Every command and flag the README and ``docs/*.md`` show exists on the command line.

The documents show ``radarviz`` invocations in code (inline spans, indented and fenced blocks):
``radarviz track --input M.csv --model cv``, a usage block whose continuation lines start with
``[``, or a span that names a command without the program (``track --associate gnn``) or only
a flag (``--sigma-v0``). This test reads each one, resolves its command (and the experiment of
``reproduce``) on the parser of ``viz_app/cli/main.py`` and checks that the command exists,
that every ``--flag`` after it is one of that command's options, and that a literal value
given to an option whose parser fixes its choices (``bench --only asterix|association``,
``sweep --dims 3``) is one of them (the other options' values are checked by the commands
themselves, which ``tests/test_cli.py`` covers). A span that is only flags is checked
against the flags of every command. Code of other programs (``pip``, ``python -m sphinx``,
``rerun``) and Python code blocks are not the command line's and are left alone.
"""

from __future__ import annotations

import argparse
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

from radarviz.viz_app.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = ["README.md", *sorted(f"docs/{p.name}" for p in (ROOT / "docs").glob("*.md"))]

#: The program, possibly by path (``.venv/bin/radarviz``), followed by a command word.
PROGRAM = re.compile(r"(?:^|(?<=[\s(`]))(?:\S*/)?radarviz[ \t]+([a-z][\w|-]*)")
FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
#: A literal value of an option: lower-case words, numbers, alternatives joined by | or ,.
LITERAL = re.compile(r"[a-z0-9_.-]+(?:[|,][a-z0-9_.-]+)*")


@dataclass(frozen=True)
class Shown:
    """One piece of command-line text of a document: where it is and what it says."""

    where: str
    text: str


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _options(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {o: a for a in parser._actions for o in a.option_strings}


PARSER = build_parser()
COMMANDS = _subparsers(PARSER)


def _all_flags() -> set[str]:
    flags: set[str] = set()
    stack = [PARSER]
    while stack:
        parser = stack.pop()
        flags |= set(_options(parser))
        stack.extend(_subparsers(parser).values())
    return flags


ALL_FLAGS = _all_flags()


def _code_pieces(name: str, text: str) -> list[Shown]:
    """The command-line text of a Markdown document: block lines (with their continuation
    lines joined) and inline code spans, each with its line number."""
    pieces: list[Shown] = []
    lines = text.splitlines()
    prose: list[str] = []
    fence: str | None = None
    current: list[str] = []
    start = 0

    def flush() -> None:
        if current:
            pieces.append(Shown(f"{name}:{start}", " ".join(current)))
            current.clear()

    for number, line in enumerate(lines, 1):
        stripped = line.strip()
        if stripped.startswith("```"):
            flush()
            fence = None if fence is not None else stripped[3:].strip() or "shell"
            prose.append("")
            continue
        in_block = fence is not None or line.startswith("    ")
        if fence is not None and not fence.startswith(("shell", "bash", "console", "text")):
            prose.append("")  # Python, reStructuredText: not the command line
            continue
        if in_block:
            prose.append("")
            body = stripped.removeprefix("$ ")
            continues = current and (
                body.startswith(("[", "--", "|")) or current[-1].endswith("\\")
            )
            if continues:
                current.append(body.rstrip("\\"))
                continue
            flush()
            if PROGRAM.match(body):
                current.append(body.rstrip("\\"))
                start = number
            continue
        flush()
        prose.append(line)
    flush()
    # Inline spans, which may wrap over one line break.
    joined = "\n".join(prose)
    for match in re.finditer(r"`([^`\n]+(?:\n[^`\n]+)?)`", joined):
        number = joined.count("\n", 0, match.start()) + 1
        pieces.append(Shown(f"{name}:{number}", match.group(1).replace("\n", " ")))
    return pieces


def _invocations(piece: Shown) -> list[tuple[list[str], str]]:
    """(command path, the text after it) for each invocation in a piece; a piece that names a
    command without the program, or only flags, gives its own (path, text)."""
    found: list[tuple[list[str], str]] = []
    for segment in re.split(r"&&|;", piece.text):
        segment = segment.strip()
        matches = list(PROGRAM.finditer(segment))
        if matches:
            for m, after in zip(matches, [*matches[1:], None], strict=True):
                tail = segment[m.end() : after.start() if after else None]
                found.append(([m.group(1)], tail))
            continue
        first = segment.split(" ", 1)[0]
        if first in COMMANDS:
            found.append(([first], segment[len(first) :]))
        elif first.startswith("--"):
            found.append(([], segment))
    return found


def _problems(piece: Shown) -> list[str]:
    """What in one piece of text the command line does not have."""
    problems: list[str] = []
    for path, tail in _invocations(piece):
        if not path:  # only flags: each must be some command's
            problems += [
                f"{piece.where}: {flag} is no option of any radarviz command"
                for flag in FLAG.findall(tail)
                if flag not in ALL_FLAGS
            ]
            continue
        parsers: list[argparse.ArgumentParser] = []
        names = path[0].split("|")
        unknown = [n for n in names if n not in COMMANDS]
        if unknown:
            problems.append(f"{piece.where}: `radarviz {'|'.join(unknown)}` is no command")
            continue
        parsers = [COMMANDS[n] for n in names]
        words = tail.split()
        subs = _subparsers(parsers[0])
        if subs and words and not words[0].startswith(("-", "[", "…")):
            experiment = words[0].strip("`,.;:)")
            wrong = [e for e in re.split(r"[|,]", experiment) if e and e not in subs]
            if wrong:
                problems.append(f"{piece.where}: `radarviz {names[0]} {experiment}`: no {wrong}")
                continue
            parsers = [subs[e] for e in re.split(r"[|,]", experiment) if e]
            tail = tail.split(experiment, 1)[1]
        problems += _flag_problems(piece.where, " ".join(names), parsers, tail)
    return problems


def _flag_problems(
    where: str, command: str, parsers: list[argparse.ArgumentParser], tail: str
) -> list[str]:
    problems: list[str] = []
    tokens = re.sub(r"[\[\]{}]", " ", tail).split()
    for i, token in enumerate(tokens):
        flag = token.split("=", 1)[0].rstrip(".,;:)`'\"")
        if not FLAG.fullmatch(flag):
            continue
        for parser in parsers:
            options = _options(parser)
            action = options.get(flag)
            if action is None:
                problems.append(f"{where}: `{command} {flag}`: no such option")
                continue
            if action.choices is None:
                continue
            values = [token.split("=", 1)[1]] if "=" in token else []
            if not values:
                many = action.nargs in ("+", "*") or isinstance(action.nargs, int)
                for value in tokens[i + 1 :]:
                    if value.startswith("-") or not LITERAL.fullmatch(value.rstrip(".,;:)")):
                        break
                    values.append(value.rstrip(".,;:)"))
                    if not many:
                        break
            allowed = {str(c) for c in action.choices}
            for value in values:
                wrong = [v for v in re.split(r"[|,]", value) if v and v not in allowed]
                if wrong:
                    problems.append(
                        f"{where}: `{command} {flag} {value}`: {wrong} not in {sorted(allowed)}"
                    )
    return problems


def _document_problems(name: str) -> tuple[int, list[str]]:
    text = (ROOT / name).read_text(encoding="utf-8")
    pieces = _code_pieces(name, text)
    problems = [p for piece in pieces for p in _problems(piece)]
    shown = sum(len(_invocations(piece)) for piece in pieces)
    return shown, problems


@pytest.mark.parametrize("name", DOCUMENTS)
def test_every_command_and_flag_shown_exists(name: str) -> None:
    _, problems = _document_problems(name)
    assert not problems, "\n".join(problems)


def test_the_documents_show_every_command() -> None:
    """The reading covers the documents: each command appears in them at least once, so a
    reader that found nothing (a broken pattern) fails instead of passing."""
    seen: set[str] = set()
    for name in DOCUMENTS:
        text = (ROOT / name).read_text(encoding="utf-8")
        for piece in _code_pieces(name, text):
            for path, _ in _invocations(piece):
                if path:
                    seen |= set(path[0].split("|"))
    assert set(COMMANDS) <= seen, f"no document shows {sorted(set(COMMANDS) - seen)}"


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("radarviz track --input m.csv --model cv", None),
        ("radarviz trak --input m.csv", "no command"),
        ("radarviz track --imput m.csv", "no such option"),
        ("radarviz bench --only asterix|gpu", "not in"),
        ("radarviz sweep --dims 4 --grid elevation_deg=0:60:30", "not in"),
        ("radarviz sweep [--dims {2,3}]", None),
        ("radarviz reproduce prosov --runs 20000 --plot p.png", None),
        ("radarviz reproduce prosov --trials 3", "no such option"),
        ("radarviz reproduce prosovv", "no ['prosovv']"),
        ("track --associate gnn", None),
        ("track --associat gnn", "no such option"),
        ("--sigma-v0", None),
        ("--server-memory-limit", "no option of any"),
        (".venv/bin/radarviz demo --out x.rrd --overwrite", None),
        (".venv/bin/pip install -e . && .venv/bin/radarviz demo --outt x", "no such option"),
        ("rerun --server-memory-limit 4MiB", None),
    ],
)
def test_the_check_catches_what_it_must(text: str, expected: str | None) -> None:
    problems = _problems(Shown("example", text))
    if expected is None:
        assert not problems, problems
    else:
        assert any(expected in p for p in problems), (text, problems)


def test_blocks_and_wrapped_spans_are_read() -> None:
    """A usage block's continuation lines and a span wrapped over a line break are read."""
    doc = (
        "Run it:\n\n"
        "    radarviz track --input M.csv\n"
        "                   [--modell cv]\n\n"
        "and then `radarviz sweep --grid a=1:2:1\n--workerz 2` in prose.\n"
    )
    problems = [p for piece in _code_pieces("doc.md", doc) for p in _problems(piece)]
    assert any("--modell" in p for p in problems), problems
    assert any("--workerz" in p for p in problems), problems
