"""radarviz: radar target tracking research, as a Python API.

``import radarviz`` gives the functions below (``radarviz.__all__``), the stable import
surface; the command line (``radarviz reproduce …``, ``record``, ``demo``) calls the same
functions, ``simulate`` and ``write_measurements`` give the plots and the files of
``radarviz simulate``, and the notebooks in ``examples/`` use nothing else.

Quantities carry their unit in their name, for arguments and table columns alike
(``sigma_r_m``, ``period_s``, ``azimuth_rad``, ``sigma_vr_mps``); arrays are numpy arrays
whose shapes each function states. A value outside its allowed range raises
``ParameterError``, one line naming the parameter and the range.

The engine is ``radarviz.core`` (numpy and scipy only) and the adapters (files, Rerun, the
command line) are ``radarviz.viz_app``; both stay importable, but their names may change.

Example::

    import radarviz

    # Prosov's Monte Carlo at σβ = 1° and 2°, 1000 runs each.
    results = radarviz.run_prosov([1.0, 2.0], runs=1000)
    # One row per (σβ, method, scan): bias_range_m, rmse_x_m, nees_pos, …
    table = radarviz.to_table(results)
    # The embedded Rerun viewer, in a notebook cell.
    radarviz.show("prosov")
"""

from __future__ import annotations

if __name__ != "radarviz":
    # The folder also lies under radarviz.viz_app; imported from there, every module would load
    # a second time as a separate copy (two Tracks classes, patches that miss the CLI's calls).
    raise ImportError(f"{__name__} is the top-level package: import radarviz instead")

# First, before any kernel module: numba picks a function's cache locator when it is decorated,
# so the locators are installed when the first kernel module is imported (not now: numba's
# import is a third of a second; importing viz_app/numba_cache.py arranges it).
from radarviz.viz_app.numba_cache import NUMBA_IMPORTERS as _NUMBA_IMPORTERS  # noqa: F401

# isort: split
import importlib
from typing import TYPE_CHECKING, Any

#: Where each public name lives. ``import radarviz`` imports none of them: a name's module
#: is imported when the name is first used (PEP 562), so that the command line's
#: ``--help`` and a script that needs one function do not load every engine (a fifth of a
#: second more than numpy alone).
_HOMES = {
    "ParameterError": "radarviz.core.params",
    "AssociationOptions": "radarviz.core.tracking.association",
    "Plot": "radarviz.core.tracking.stream",
    **dict.fromkeys(
        (
            "GorshkovRun",
            "convert",
            "direction_cosines",
            "estimate_velocity",
            "finite_memory",
            "radar_preset",
            "run_gorshkov",
            "run_prosov",
            "run_velocity",
        ),
        "radarviz.experiments",
    ),
    **dict.fromkeys(("colour", "use_palette"), "radarviz.style"),
    **dict.fromkeys(("to_arrow", "to_columns", "to_table"), "radarviz.tables"),
    **dict.fromkeys(
        (
            "Radar",
            "ScanEnd",
            "Tracks",
            "TrackStep",
            "simulate",
            "track",
            "track_file",
            "write_measurements",
        ),
        "radarviz.tracking",
    ),
    **dict.fromkeys(("PRESETS", "record", "show", "use_offline_assets"), "radarviz.viewer"),
}

if TYPE_CHECKING:
    from radarviz.core.params import ParameterError
    from radarviz.core.tracking.association import AssociationOptions
    from radarviz.core.tracking.stream import Plot
    from radarviz.experiments import (
        GorshkovRun,
        convert,
        direction_cosines,
        estimate_velocity,
        finite_memory,
        radar_preset,
        run_gorshkov,
        run_prosov,
        run_velocity,
    )
    from radarviz.style import colour, use_palette
    from radarviz.tables import to_arrow, to_columns, to_table
    from radarviz.tracking import (
        Radar,
        ScanEnd,
        Tracks,
        TrackStep,
        simulate,
        track,
        track_file,
        write_measurements,
    )
    from radarviz.viewer import PRESETS, record, show, use_offline_assets


def __getattr__(name: str) -> Any:
    """A public name, imported from its module on first use (and kept: later uses are an
    ordinary attribute)."""
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'radarviz' has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


__version__ = "0.1.0"

__all__ = [
    "PRESETS",
    "AssociationOptions",
    "GorshkovRun",
    "ParameterError",
    "Plot",
    "Radar",
    "ScanEnd",
    "TrackStep",
    "Tracks",
    "colour",
    "convert",
    "direction_cosines",
    "estimate_velocity",
    "finite_memory",
    "radar_preset",
    "record",
    "run_gorshkov",
    "run_prosov",
    "run_velocity",
    "show",
    "simulate",
    "to_arrow",
    "to_columns",
    "to_table",
    "track",
    "track_file",
    "use_offline_assets",
    "use_palette",
    "write_measurements",
]
