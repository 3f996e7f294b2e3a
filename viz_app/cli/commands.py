"""The ``radarviz`` commands: each one's line of help and the module that builds its flags.

This table is the one home of a command's one-line help. ``radarviz --help`` prints it
without importing the command modules (their imports reach the engine: ``track`` alone
costs more than numpy's import), and a command's module, which builds its flags
(``add_commands``) and runs it (``COMMANDS``), is imported only when that command is run or
its own ``--help`` is asked for (``viz_app.cli.main.build_parser``).
"""

from __future__ import annotations

import argparse
import importlib
from types import ModuleType
from typing import Any, NamedTuple, Protocol


class Command(NamedTuple):
    """A command of ``radarviz``.

    Attributes:
        help: its line in ``radarviz --help``.
        module: the module of ``viz_app.cli`` that registers its flags (``add_commands``)
            and maps its name to the function running it (``COMMANDS``); ``"main"`` for the
            commands that ``viz_app.cli.main`` builds and runs itself.
    """

    help: str
    module: str


#: The commands in the order ``radarviz --help`` lists them.
COMMANDS: dict[str, Command] = {
    "reproduce": Command("reproduce a paper's experiment", "main"),
    "demo": Command("headless demo: write a recording of every estimator", "recording"),
    "record": Command("write one preset's recording", "recording"),
    "view": Command("serve the Rerun web viewer for a recording", "recording"),
    "track": Command("track a measurement file into a track CSV file", "track"),
    "simulate": Command("write a preset's measurements and radars files", "track"),
    "sweep": Command("the Prosov Monte Carlo over a parameter grid, on Dask (resumable)", "sweep"),
    "bench-sweep": Command("scaling of a sweep over 1, 2, … local Dask workers", "sweep"),
    "score": Command(
        "score a track file against the truth: GOSPA, purity, fragmentation, swaps, RMSE, NEES",
        "score",
    ),
    "live": Command("track an ASTERIX feed as it arrives (UDP or a growing .ast file)", "live"),
    "replay": Command(
        "send a capture's or .ast file's ASTERIX datagrams to a UDP address at its pace", "live"
    ),
    "compile": Command(
        "compile the numba kernels of demo and track now (set-up), so that their first runs "
        "load cached code",
        "compile_kernels",
    ),
    "tune": Command(
        "Viser panel that re-runs a scene (Prosov, Gorshkov, velocity) into Rerun", "main"
    ),
    "bench": Command("speed of the batched filters vs filterpy", "main"),
}


def command_module(name: str) -> ModuleType | None:
    """The module building and running command ``name``, imported now; None for the commands
    of ``viz_app.cli.main`` itself."""
    module = COMMANDS[name].module
    return None if module == "main" else importlib.import_module(f"radarviz.viz_app.cli.{module}")


class Registrar(Protocol):
    """What a command module's ``add_commands`` registers its commands on: ``add_parser(name,
    **settings)`` gives the parser of that command (its help is this module's)."""

    def add_parser(self, name: str, **settings: Any) -> argparse.ArgumentParser: ...


def command_of(argv: list[str]) -> str | None:
    """The command an argument list names (its first argument not an option), or None when it
    names none (``radarviz``, ``radarviz --help``); the top-level parser has no option that
    takes a value, so the first positional argument is the command."""
    for arg in argv:
        if arg == "--":
            return None
        if not arg.startswith("-"):
            return arg
    return None
