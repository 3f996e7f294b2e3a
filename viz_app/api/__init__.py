"""radarviz: radar target tracking research, as a Python API.

The functions below are the stable import surface (``__all__``); the command line
(``radarviz reproduce …``, ``record``, ``demo``) calls the same functions. Quantities carry
their unit in their name (``sigma_r_m``, ``period_s``, ``azimuth_rad``); a bad value raises
``ParameterError`` with one line naming the parameter and its allowed range.

The engine is ``radarviz.core`` (numpy and scipy only) and the adapters (files, Rerun, the
command line) are ``radarviz.viz_app``; both stay importable as before.

Example::

    import radarviz
    results = radarviz.run_prosov([1.0, 2.0], runs=1000)
    radarviz.to_table(results)            # one row per (σβ, method, scan)
    radarviz.show("prosov")               # the embedded Rerun viewer, in a notebook
"""

from __future__ import annotations

if __name__ != "radarviz":
    # The folder also lies under radarviz.viz_app; imported from there, every module would load
    # a second time as a separate copy (two Tracks classes, patches that miss the CLI's calls).
    raise ImportError(f"{__name__} is the top-level package: import radarviz instead")

# First, before any kernel module: numba picks a function's cache locator when it is decorated
# (viz_app/numba_cache.py; importing it installs the locators).
from radarviz.viz_app.numba_cache import INSTALLED as _NUMBA_CACHE  # noqa: F401

# isort: split
from radarviz.core.params import ParameterError
from radarviz.core.tracking.association import AssociationOptions
from radarviz.core.tracking.stream import Plot
from radarviz.experiments import (
    GorshkovRun,
    convert,
    estimate_velocity,
    finite_memory,
    run_gorshkov,
    run_prosov,
    run_velocity,
)
from radarviz.style import colour, use_palette
from radarviz.tables import to_arrow, to_columns, to_table
from radarviz.tracking import ScanEnd, Tracks, TrackStep, track, track_file
from radarviz.viewer import PRESETS, record, show, use_offline_assets

__version__ = "0.1.0"

__all__ = [
    "PRESETS",
    "AssociationOptions",
    "GorshkovRun",
    "ParameterError",
    "Plot",
    "ScanEnd",
    "TrackStep",
    "Tracks",
    "colour",
    "convert",
    "estimate_velocity",
    "finite_memory",
    "record",
    "run_gorshkov",
    "run_prosov",
    "run_velocity",
    "show",
    "to_arrow",
    "to_columns",
    "to_table",
    "track",
    "track_file",
    "use_offline_assets",
    "use_palette",
]
