"""Pieces every ``radarviz`` subcommand shares: argparse value types and report printing."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from typing import Any


def number(text: str) -> float:
    """argparse type: any float text, NaN included, so the range check can name the flag."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None


def integer(text: str) -> int:
    """argparse type: integer text; the range check names the flag."""
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None


def print_report(
    doc: dict[str, Any],
    as_json: bool,
    table: Callable[[dict[str, Any]], str],
    allow_nan: bool = True,
) -> None:
    """Print ``doc`` as one JSON line (``--json``) or as the human-readable ``table(doc)``."""
    if as_json:
        json.dump(doc, sys.stdout, allow_nan=allow_nan)
        sys.stdout.write("\n")
    else:
        print(table(doc))
