"""Command-line flags built from the parameter table (``core.params.PARAMETERS``).

``add_parameter(parser, "sigma_beta_deg")`` adds ``--sigma-beta-deg`` with the table's type
(float or int), default and a help line showing unit, range and default::

    --sigma-beta-deg SIGMA_BETA_DEG   σβ, azimuth noise std (deg), in (0, 20], default 1

The value is *not* checked here: the core config that receives it checks it against the same
table, once, and raises ``ParameterError`` naming the parameter (``sigma_beta_deg must be …``).
:func:`cli_message` turns that into the flag the user typed (``--sigma-beta-deg must be …``):
each ``add_parameter`` records, as a parser default, which flag stands for which parameter in
that subcommand.
"""

from __future__ import annotations

import argparse
from typing import Any

from radarviz.core.params import PARAMETERS, ParameterError
from radarviz.viz_app.cli.args import integer, number

#: Namespace attribute prefix recording the flag of a table parameter in the parsed command.
_FLAG_PREFIX = "_flag_for_"
_FROM_TABLE: Any = object()


def flag_name(name: str) -> str:
    """The flag of a table parameter by default: ``sigma_beta_deg`` → ``--sigma-beta-deg``."""
    return "--" + name.replace("_", "-")


def add_parameter(
    parser: argparse.ArgumentParser,
    name: str,
    *flags: str,
    default: Any = _FROM_TABLE,
    shown_default: Any = None,
    nargs: str | int | None = None,
    high: float | None = None,
    note: str = "",
) -> argparse.Action:
    """Add the flag(s) of table parameter ``name``; the value lands in ``args.<name>``.

    Args:
        flags: the flag and its aliases (default ``--name-with-dashes``); the first one is the
            one errors name.
        default: the flag's default (default: the table's). ``None`` means "not given", for a
            caller that then takes the value from elsewhere; ``shown_default`` is what the help
            says in that case.
        nargs: as for argparse (``"+"``: one case per value).
        high: the upper end the help shows, for a command whose core check uses its own
            (``core.params.check(name, value, high=…)``).
        note: appended to the help line.
    """
    p = PARAMETERS[name]
    flags = flags or (flag_name(name),)
    value = p.default if default is _FROM_TABLE else default
    text = p.help(value if shown_default is None else shown_default, high=high)
    if note:
        text += f" ({note})"
    map_flag(parser, name, flags[0])
    return parser.add_argument(
        *flags,
        dest=name,
        type=integer if p.kind == "int" else number,
        default=value,
        nargs=nargs,
        metavar=name.upper(),
        help=text.replace("%", "%%"),
    )


def map_flag(parser: argparse.ArgumentParser, parameter: str, flag: str) -> None:
    """Record that ``flag`` gives core's ``parameter`` in this subcommand (for a flag whose
    bounds are not in the table, e.g. a choice, but which core checks by that name)."""
    parser.set_defaults(**{_FLAG_PREFIX + parameter: flag})


def cli_message(args: argparse.Namespace | None, exc: ParameterError) -> str:
    """The error line with the parameter's name replaced by its flag in this command, if any."""
    flag = getattr(args, _FLAG_PREFIX + exc.parameter, None) if exc.parameter else None
    return exc.renamed(flag) if flag else str(exc)


def parameter_flags(args: argparse.Namespace) -> dict[str, str]:
    """Parameter name → flag for the parsed command (what :func:`cli_message` uses)."""
    return {k[len(_FLAG_PREFIX) :]: v for k, v in vars(args).items() if k.startswith(_FLAG_PREFIX)}
