"""``radarviz track`` and ``radarviz simulate``: measurement files in, track files out.

(This module is the CSV's; ASTERIX CAT048 files are ``viz_app.io.asterix``'s, handed to
``run_track`` as its ``open_source``.)

Measurement file (CSV, header line first, one row per plot, times non-decreasing)::

    time_s, radar, range_m, azimuth_deg [, elevation_deg] [, radial_velocity_mps] [, target]

Without ``target`` every plot is of one target, or, with ``track --associate gnn``, of any
number of targets and clutter, associated scan by scan (``core.tracking.association``; the
track file then has ``target``, the track id, and ``status``, tentative or confirmed, after
``time_s``). With it (the radar's own track number, or any
label; no cell may be empty) the file holds many targets, interleaved: each target gets its
own tracks, all targets advancing as one batch (``core.tracking.targets``); times need only
not decrease within a target, and a target may change radar from plot to plot. The
finite-memory start and track are for files of one target.

With ``elevation_deg`` the track is 3D (every row needs an elevation; methods ``naive``,
``ucm``, ``ekf``, ``ukf``), without it 2D in the x–y plane (all seven methods; the sites' z is
not used). A ``radial_velocity_mps`` cell may be left empty for a plot without Doppler (e.g. a
radar that has none); a filled one is used as a second, scalar update (``--doppler ignore``
turns that off).

Radars file (TOML, read with ``tomllib``)::

    [radars.NAME]
    x_m = 0.0; y_m = 0.0; z_m = 0.0          # site, m
    sigma_r_m = 250.0                        # > 0
    sigma_beta_deg = 1.0                     # in (0, 20]
    sigma_elevation_deg = 0.5                # in (0, 20]; needed by plots with an elevation
    sigma_vr_mps = 1.0                       # > 0; needed by plots with a radial velocity
    sac = 25; sic = 201                      # ASTERIX data source, integers in [0, 255]; both
                                             # or neither; needed to read ASTERIX files

Each method keeps one track (``core.tracking.stream.StreamTracker``): started from the first plot
(the first-plot start: converted point, velocity 0 ± ``--sigma-v0``) or, with ``--init
finite-memory``, from Gorshkov's least-squares fit over the first ``--init-k`` plots (one
radar, one period), then predicted over each time step and updated, radar-centred.

Track file (CSV), one row per plot and method, in plot order then ``--method`` order; the first
plot's rows are the starting states (with ``--init finite-memory`` rows begin at the k-th
plot); a file of many targets has the plot's ``target`` after ``time_s``::

    time_s, [target,] method, x_m, y_m, z_m, vx_mps, vy_mps, vz_mps,
    p_xx_m2, p_xy_m2, …, p_zz_m2                 position covariance (upper triangle), m²
    p_vxvx_m2ps2, p_vxvy_m2ps2, …, p_vzvz_m2ps2  velocity covariance (upper triangle), m²/s²
    p_xvx_m2ps, p_xvy_m2ps, …, p_zvz_m2ps        position–velocity block, m²/s

(``covariance_column``; p_xvy_m2ps is cov(x, vy)). In 2D, z, vz and every covariance entry
involving them are 0. Floats are written in their shortest round-trip form (pyarrow's CSV
writer, a block of rows at a time; text cells quoted), so nothing is lost.

``--out`` defaults to ``tracks.csv`` in the current directory and an existing file is replaced;
``--rrd OUT.rrd`` also writes a Rerun recording (``viz_app.rerun.track_recording``, handed in by
the command, ``viz_app.cli.track``: this module never imports Rerun). Both commands
write to a temporary file beside the target and rename it when complete, so a bad input (one line on
standard error naming file, line and column; exit 2) or a crash leaves no output and an
existing file untouched. Here the measurement file is read row by row and the tracks written
row by row (``run_track``: with a recording, or the finite-memory start or track); the command
otherwise reads, tracks and writes blocks of columns (``viz_app.io.plot_blocks.run_track``,
the same checks and messages). Either way memory does not grow with the file (the recording
buffers at most ``RRD_CHUNK`` plots).
"""

from __future__ import annotations

import contextlib
import csv
import math
import os
import re
import sys
import time
import tomllib
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import AbstractContextManager, ExitStack
from dataclasses import dataclass, replace
from pathlib import Path
from typing import IO, Any, NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from radarviz.core.experiments.prosov import ALL_METHODS, TrackingConfig, displayed_measurements
from radarviz.core.filters.methods import METHODS_3D
from radarviz.core.finite import check_finite_result
from radarviz.core.params import PARAMETERS, ParameterError, check, check_choice, default
from radarviz.core.scenarios.multi_radar import (
    Scenario3D,
    Segment,
    Trajectory3D,
    fusion_scenario,
    generate_measurements,
)
from radarviz.core.tracking.association import (
    AssociationOptions,
    AssociationReport,
    GNNTracker,
    LatePlotError,
    plot_batches,
    scan_groups,
    time_ordered,
)
from radarviz.core.tracking.compiled import RadarTable
from radarviz.core.tracking.coverage import RadarCoverage
from radarviz.core.tracking.stream import (
    Plot,
    PlotError,
    StateRow,
    StreamOptions,
    StreamTracker,
)
from radarviz.core.tracking.targets import TargetTracker
from radarviz.core.velocity.estimate import BASELINE_TARGET_M, BASELINE_VELOCITY_MPS
from radarviz.viz_app.io.atomic import atomic_write, commit_together

REQUIRED_COLUMNS = ("time_s", "radar", "range_m", "azimuth_deg")
OPTIONAL_COLUMNS = ("elevation_deg", "radial_velocity_mps", "target")
RADAR_KEYS = ("x_m", "y_m", "z_m", "sigma_r_m", "sigma_beta_deg")
OPTIONAL_RADAR_KEYS = (
    "sigma_elevation_deg",
    "sigma_vr_mps",
    # Coverage and rotation (``core.tracking.coverage``): estimated from the plots if absent.
    "rotation_period_s",
    "min_range_m",
    "max_range_m",
    "min_elevation_deg",
    "max_elevation_deg",
)
#: Former names of radars-file keys, still read as the key they map to: each file using one
#: gets one deprecation line on standard error (``load_radars``); a table giving both names
#: is an error. Files are written with the new names only.
DEPRECATED_RADAR_KEYS: dict[str, str] = {
    "sigma_range_m": "sigma_r_m",
    "sigma_azimuth_deg": "sigma_beta_deg",
    "sigma_radial_velocity_mps": "sigma_vr_mps",
}
#: The ASTERIX data source identifier of a radar (I048/010): integers in [0, 255], both or
#: neither; no two radars may share a pair.
SOURCE_KEYS = ("sac", "sic")
DEFAULT_TRACKS = "tracks.csv"
#: Measurement file formats of ``track --format`` ("auto" picks by a capture's magic, else by
#: suffix; ``simulate --format`` writes ``OUTPUT_FORMATS``).
FILE_FORMATS = ("auto", "csv", "asterix", "pcap")
#: File name suffixes taken as ASTERIX by "auto" (any other: CSV).
ASTERIX_SUFFIXES = (".ast", ".asterix")
#: Suffixes of a packet capture (pcap, pcapng) of ASTERIX datagrams; a capture of another
#: name is told by its magic (``input_format_of``).
CAPTURE_SUFFIXES = (".pcap", ".pcapng")
SIM_PRESETS = ("prosov", "fusion")
#: ``track --doppler``: the Doppler update each mode asks for
#: (``core.tracking.stream.StreamOptions.doppler_update``), None for "ignore".
DOPPLER_MODES: dict[str, str | None] = {
    "use": "line_of_sight",
    "converted": "converted",
    "ignore": None,
}
#: Most scans per radar ``simulate`` writes (the Monte Carlo limit does not apply). The plots
#: are made in memory before the file is written, about 520 bytes each: 10⁶ scans of the
#: fusion preset's three radars peak at 1.7 GB and take two minutes; 10⁷ scans (16 GB of
#: plots) ran out of memory after a minute.
MAX_SIMULATE_STEPS = 1_000_000
#: Physically meaningful ends of a plot's values (``core.params``: range_m, radial_velocity_mps,
#: time_s): beyond them squares overflow and the filters return NaN without a word.
MAX_RANGE_M = float(PARAMETERS["range_m"].high)
MAX_RADIAL_VELOCITY_MPS = float(PARAMETERS["radial_velocity_mps"].high)
MAX_TIME_S = float(PARAMETERS["time_s"].high)
#: Plots read before they are tracked as one block (the bounded buffer: conversions are
#: vectorised over a block).
READ_BLOCK = 1024

#: (name, index into the state (x, ẋ, y, ẏ, z, ż)) of the six output components.
_COMPONENTS = (("x", 0), ("y", 2), ("z", 4), ("vx", 1), ("vy", 3), ("vz", 5))
_PAIRS: tuple[tuple[int, int], ...] = (
    tuple((i, j) for i in range(3) for j in range(i, 3))
    + tuple((i, j) for i in range(3, 6) for j in range(i, 6))
    + tuple((i, j) for i in range(3) for j in range(3, 6))
)


def covariance_column(a: str, b: str) -> str:
    """The track file's column of cov(a, b), components ``x`` … ``vz``, with its unit:
    ``p_xy_m2``, ``p_xvy_m2ps`` (m²/s), ``p_vxvy_m2ps2`` (m²/s²)."""
    velocities = a.startswith("v") + b.startswith("v")
    return f"p_{a}{b}_{('m2', 'm2ps', 'm2ps2')[velocities]}"


TRACK_COLUMNS: tuple[str, ...] = (
    "time_s",
    "method",
    "x_m",
    "y_m",
    "z_m",
    "vx_mps",
    "vy_mps",
    "vz_mps",
    *(covariance_column(_COMPONENTS[i][0], _COMPONENTS[j][0]) for i, j in _PAIRS),
)
_STATE_INDEX = np.array([k for _, k in _COMPONENTS])
_COV_ROWS = np.array([_COMPONENTS[i][1] for i, _ in _PAIRS])
_COV_COLS = np.array([_COMPONENTS[j][1] for _, j in _PAIRS])


@dataclass(frozen=True)
class Radar:
    """One radar of the radars file: site (m) and accuracies (m, degrees, m/s; None: absent)."""

    name: str
    x_m: float
    y_m: float
    z_m: float
    sigma_r_m: float
    sigma_beta_deg: float
    sigma_elevation_deg: float | None = None
    sigma_vr_mps: float | None = None
    #: The antenna's revolution (s) and the coverage (m, degrees) the association's misses
    #: count in (``core.tracking.coverage``); None: estimated from the radar's plots.
    rotation_period_s: float | None = None
    min_range_m: float | None = None
    max_range_m: float | None = None
    min_elevation_deg: float | None = None
    max_elevation_deg: float | None = None
    #: The ASTERIX data source (I048/010 SAC, SIC) whose records are this radar's; None: the
    #: radar is not in ASTERIX files (``viz_app.io.asterix``).
    sac: int | None = None
    sic: int | None = None


# --------------------------------------------------------------------------------------------
# Parsing and validation (pure: text in, values or one-line ParameterError out)
# --------------------------------------------------------------------------------------------


def _bad(where: str, column: str, what: str, got: object) -> ParameterError:
    return ParameterError(f"{where}, column {column}: {what} (got {got!r})")


#: The ``core.params`` entry bounding each radars-file key (site coordinates: ``site_m``).
RADAR_KEY_PARAMETERS: dict[str, str] = {
    "sigma_r_m": "sigma_r_m",
    "sigma_beta_deg": "sigma_beta_deg",
    "sigma_elevation_deg": "sigma_elevation_deg",
    "sigma_vr_mps": "sigma_vr_mps",
    "rotation_period_s": "rotation_period_s",
    "min_range_m": "min_range_m",
    "max_range_m": "max_range_m",
    "min_elevation_deg": "min_elevation_deg",
    "max_elevation_deg": "max_elevation_deg",
}


def radar_coverage(radar: Radar) -> RadarCoverage:
    """The radars file's coverage and rotation of ``radar`` (None where not given)."""
    el = [
        None if v is None else math.radians(v)
        for v in (radar.min_elevation_deg, radar.max_elevation_deg)
    ]
    return RadarCoverage(radar.rotation_period_s, radar.min_range_m, radar.max_range_m, *el)


def parse_radars(text: str, source: str, deprecated: list[str] | None = None) -> dict[str, Radar]:
    """Radars from TOML text; errors name ``source``, the radar and the key.

    A key of ``DEPRECATED_RADAR_KEYS`` is read as its new name; each such name used adds one
    line to ``deprecated`` (when given), however many radars use it."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError(f"{source}: not valid TOML: {exc}") from None
    except RecursionError:
        # tomllib parses arrays and inline tables by recursion: ~1000 levels exhaust the stack
        raise ParameterError(f"{source}: not valid TOML: nested too deeply") from None
    extra = sorted(set(doc) - {"radars"})
    if extra:
        raise ParameterError(
            f"{source}: unknown top-level key {extra[0]!r} (expected [radars.NAME] tables)"
        )
    tables = doc.get("radars")
    if not isinstance(tables, dict) or not tables:
        raise ParameterError(f"{source}: no radars (expected [radars.NAME] tables)")
    radars = {}
    for name, table in tables.items():
        where = f"{source}, radar {name!r}"
        if not isinstance(table, dict):
            raise ParameterError(f"{where}: must be a table [radars.{name}]")
        known = RADAR_KEYS + OPTIONAL_RADAR_KEYS + SOURCE_KEYS
        for key in table:
            if key not in known and key not in DEPRECATED_RADAR_KEYS:
                raise ParameterError(
                    f"{where}, key {key}: unknown key (expected {', '.join(known)})"
                )
        # The key each value is read as -> the key the file gave it under (for the errors).
        spelled: dict[str, str] = {}
        for old, new in DEPRECATED_RADAR_KEYS.items():
            if old not in table:
                continue
            if new in table:
                raise ParameterError(
                    f"{where}, key {old}: both {old} (deprecated) and {new} given; give only {new}"
                )
            table = {(new if k == old else k): v for k, v in table.items()}
            spelled[new] = old
            line = f"{source}: key {old} is deprecated, read as {new}"
            if deprecated is not None and line not in deprecated:
                deprecated.append(line)
        vals: dict[str, float] = {}
        for key in RADAR_KEYS + OPTIONAL_RADAR_KEYS:
            if key not in table:
                if key in RADAR_KEYS:
                    raise ParameterError(f"{where}, key {key}: missing")
                continue
            v = table[key]
            given = spelled.get(key, key)
            # Each key's physically meaningful range is its parameter's (``core.params``).
            entry = PARAMETERS[RADAR_KEY_PARAMETERS.get(key, "site_m")]
            low, high = entry.low, entry.high
            rng = f"in [{low:g}, {high:g}]"
            ok = _is_real(v) and math.isfinite(v) and low <= v <= high
            if not ok:
                raise ParameterError(
                    f"{where}, key {given}: must be a finite number {rng}".rstrip()
                    + f" (got {v!r})"
                )
            vals[key] = float(v)
        for lo, hi in (("min_range_m", "max_range_m"), ("min_elevation_deg", "max_elevation_deg")):
            if lo in vals and hi in vals and vals[lo] >= vals[hi]:
                raise ParameterError(
                    f"{where}, key {hi}: must be above {lo} = {vals[lo]:g} (got {vals[hi]:g})"
                )
        sac, sic = _source_id(where, table, radars.values())
        radars[name] = Radar(
            name, *(vals.get(k) for k in RADAR_KEYS + OPTIONAL_RADAR_KEYS), sac=sac, sic=sic
        )
    return radars


def _source_id(
    where: str, table: dict[str, Any], others: Iterable[Radar]
) -> tuple[int | None, int | None]:
    """A radar table's (sac, sic), checked: integers in [0, 255], both or neither, a pair no
    earlier radar has; (None, None) when the table has neither."""
    given = [k for k in SOURCE_KEYS if k in table]
    if not given:
        return None, None
    if len(given) == 1:
        missing = "sic" if given[0] == "sac" else "sac"
        raise ParameterError(f"{where}, key {missing}: missing (sac and sic go together)")
    for key in SOURCE_KEYS:
        v = table[key]
        if not (isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 255):
            raise ParameterError(f"{where}, key {key}: must be an integer in [0, 255] (got {v!r})")
    sac, sic = table["sac"], table["sic"]
    for other in others:
        if (other.sac, other.sic) == (sac, sic):
            raise ParameterError(
                f"{where}, key sic: data source SAC {sac} SIC {sic} is radar {other.name!r}'s too"
            )
    return sac, sic


def _is_real(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _number(text: str) -> float | None:
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


class PlotReader:
    """Validated plots of a measurement CSV, one at a time (bounded memory).

    The header is read on construction (``three_d``, ``doppler`` tell which optional columns
    it has); iterating yields (line number, ``Plot``). Raises ``ParameterError``
    "SOURCE line L, column C: …" at the first bad value.
    """

    def __init__(self, lines: Iterable[str], source: str, radars: dict[str, Radar]):
        self.source, self.radars = source, radars
        self._reader = reader = csv.reader(lines)
        try:
            header = next(reader, None)
        except UnicodeDecodeError:
            raise ParameterError(f"{source} line 1: not UTF-8 text") from None
        except csv.Error as exc:
            raise ParameterError(f"{source} line 1: {csv_error_text(exc)}") from None
        if not header:
            raise ParameterError(f"{source} line 1: missing header ({', '.join(REQUIRED_COLUMNS)})")
        header = [h.strip() for h in header]
        known = REQUIRED_COLUMNS + OPTIONAL_COLUMNS
        for h in header:
            if h not in known:
                raise ParameterError(
                    f"{source} line 1, column {h}: unknown column (expected {', '.join(known)})"
                )
            if header.count(h) > 1:
                raise ParameterError(f"{source} line 1, column {h}: appears twice")
        for h in REQUIRED_COLUMNS:
            if h not in header:
                raise ParameterError(f"{source} line 1, column {h}: missing")
        self.header = header
        self.three_d = "elevation_deg" in header
        self.doppler = "radial_velocity_mps" in header
        #: The file labels its plots' targets (a ``target`` column): many targets.
        self.targets = "target" in header

        #: Validation state carried from row to row (and block to block, ``PlotBlockReader``):
        #: the previous time, of each target with a target column, and the plots so far.
        self.last_t = -math.inf
        self.last_of: dict[str, float] = {}
        self.count = 0

    def __iter__(self) -> Iterator[tuple[int, Plot]]:
        yield from self.plots(self._reader, 0)
        if self.count == 0:
            raise ParameterError(f"{self.source}: no plots after the header")

    def plots(self, reader: Any, first_line: int) -> Iterator[tuple[int, Plot]]:
        """The validated plots of the rows of a ``csv.reader`` whose line 1 is the file's
        line ``first_line`` + 1 (0: the reader is the file's, header read)."""
        source, radars, header = self.source, self.radars, self.header
        idx = {h: i for i, h in enumerate(header)}
        i_t, i_radar, i_r, i_az = (idx[h] for h in REQUIRED_COLUMNS)
        i_el = idx.get("elevation_deg")
        i_vr = idx.get("radial_velocity_mps")
        i_target = idx.get("target")
        width = len(header)
        last_t = self.last_t
        # With a target column, times need only not decrease within each target.
        last_of = self.last_of
        target = ""
        while True:
            try:
                row = next(reader, None)
            except UnicodeDecodeError:
                raise ParameterError(
                    f"{source} line {first_line + reader.line_num + 1}: not UTF-8 text"
                ) from None
            except csv.Error as exc:
                raise ParameterError(
                    f"{source} line {first_line + reader.line_num}: {csv_error_text(exc)}"
                ) from None
            if row is None:
                break
            line = first_line + reader.line_num
            if not row or (len(row) == 1 and not row[0].strip()):
                continue  # blank line
            where = f"{source} line {line}"
            if len(row) != width:
                raise ParameterError(f"{where}: expected {width} fields, got {len(row)}")
            t = _number(row[i_t])
            if t is None or abs(t) > MAX_TIME_S:
                raise _bad(
                    where,
                    "time_s",
                    f"must be a finite number in [−{MAX_TIME_S:g}, {MAX_TIME_S:g}]",
                    row[i_t],
                )
            if i_target is not None:
                target = row[i_target].strip()
                if not target:
                    raise _bad(where, "target", "must not be empty (a label per plot)", "")
                last_t = last_of.get(target, -math.inf)
            if t < last_t:
                of = f" of target {target!r}" if i_target is not None else ""
                raise _bad(
                    where,
                    "time_s",
                    f"must not be before the previous time{of} {last_t!r}",
                    row[i_t],
                )
            name = row[i_radar].strip()
            radar = radars.get(name)
            if radar is None:
                raise _bad(where, "radar", f"unknown radar (known: {', '.join(radars)})", name)
            r = _number(row[i_r])
            if r is None or not 0 < r <= MAX_RANGE_M:
                raise _bad(
                    where, "range_m", f"must be a finite number in (0, {MAX_RANGE_M:g}]", row[i_r]
                )
            az = _number(row[i_az])
            if az is None or abs(az) > 360:
                raise _bad(
                    where, "azimuth_deg", "must be a finite number in [-360, 360]", row[i_az]
                )
            el = sigma_elevation_deg = None
            if i_el is not None:
                el = _number(row[i_el])
                if el is None or abs(el) > 90:
                    raise _bad(
                        where, "elevation_deg", "must be a finite number in [-90, 90]", row[i_el]
                    )
                sigma_elevation_deg = radar.sigma_elevation_deg
                if sigma_elevation_deg is None:
                    raise _bad(
                        where,
                        "elevation_deg",
                        f"radar {name!r} has no sigma_elevation_deg in the radars file",
                        row[i_el],
                    )
            vr = sigma_vr_mps = None
            if i_vr is not None and row[i_vr].strip():  # an empty cell: no Doppler here
                vr = _number(row[i_vr])
                if vr is None or abs(vr) > MAX_RADIAL_VELOCITY_MPS:
                    raise _bad(
                        where,
                        "radial_velocity_mps",
                        f"must be a finite number in [−{MAX_RADIAL_VELOCITY_MPS:g}, "
                        f"{MAX_RADIAL_VELOCITY_MPS:g}] or empty",
                        row[i_vr],
                    )
                sigma_vr_mps = radar.sigma_vr_mps
                if sigma_vr_mps is None:
                    raise _bad(
                        where,
                        "radial_velocity_mps",
                        f"radar {name!r} has no sigma_vr_mps in the radars file",
                        row[i_vr],
                    )
            last_t = self.last_t = t
            if i_target is not None:
                last_of[target] = t
            self.count += 1
            yield (
                line,
                Plot(
                    t,
                    r,
                    math.radians(az),
                    radar.sigma_r_m,
                    math.radians(radar.sigma_beta_deg),
                    (radar.x_m, radar.y_m, radar.z_m),
                    name,
                    None if el is None else math.radians(el),
                    0.0 if sigma_elevation_deg is None else math.radians(sigma_elevation_deg),
                    vr,
                    0.0 if sigma_vr_mps is None else sigma_vr_mps,
                    target,
                ),
            )


def track_columns(
    targets: bool, status: bool = False, radar_tracks: bool = False
) -> tuple[str, ...]:
    """The track file's header: ``TRACK_COLUMNS``, with ``target`` after ``time_s`` for a
    measurement file of many targets, and ``status`` after it for associated tracks
    (``track --associate``: the track's status after the plot, tentative or confirmed), then
    with ``radar_tracks`` ``RADAR_TRACK_COLUMN`` (associated plots of an ASTERIX input with
    I048/161: the radar's own track number, kept beside the association's track id)."""
    if not targets:
        return TRACK_COLUMNS
    extra = (("status",) if status else ()) + ((RADAR_TRACK_COLUMN,) if radar_tracks else ())
    return (TRACK_COLUMNS[0], "target", *extra, *TRACK_COLUMNS[1:])


#: The track file's column of the radar's own track number (an integer; empty when a plot
#: has none).
RADAR_TRACK_COLUMN = "radar_track_number"


#: Track rows written to the track file at a time (one pyarrow table).
WRITE_BLOCK = 8192
#: The ``--out`` suffix (any case) of a Parquet track file; any other name is a CSV one.
PARQUET_SUFFIX = ".parquet"


def is_parquet(path: str | os.PathLike) -> bool:
    """Whether the track file ``path`` is written as Parquet (its suffix is
    ``PARQUET_SUFFIX``) rather than CSV."""
    return Path(path).suffix.lower() == PARQUET_SUFFIX


#: The track file's text columns (the others are float64).
TEXT_COLUMNS = ("target", "status", "method")


def track_schema(targets: bool, status: bool = False, radar_tracks: bool = False) -> Any:
    """The Parquet track file's schema: the columns of ``track_columns``, in its order, the
    text ones (``TEXT_COLUMNS``) strings, ``RADAR_TRACK_COLUMN`` int64, the others float64."""
    import pyarrow as pa

    kind = {c: pa.string() for c in TEXT_COLUMNS} | {RADAR_TRACK_COLUMN: pa.int64()}
    return pa.schema(
        [(c, kind.get(c, pa.float64())) for c in track_columns(targets, status, radar_tracks)]
    )


def parquet_writer(
    fh: IO[bytes], targets: bool, status: bool = False, radar_tracks: bool = False
) -> Any:
    """A ``pyarrow.parquet.ParquetWriter`` of the track file on ``fh`` (``atomic_write``'s
    staged file; closing the writer leaves ``fh`` open). Each written table is one row
    group.

    Only the text columns are dictionary-encoded: a few labels repeat on every row, while
    the states and covariances rarely repeat, and trying a dictionary on them first (pyarrow's
    default) cost 2.6× the CPU time of the whole write for a larger file (measured on a
    2D air-traffic track file: 720 against 270 ns per row, 129 against 108 bytes)."""
    import pyarrow.parquet as pq

    schema = track_schema(targets, status, radar_tracks)
    text = [c for c in schema.names if c in TEXT_COLUMNS]
    return pq.ParquetWriter(fh, schema, use_dictionary=text)


def verify_track_parquet(path: str | os.PathLike, columns: tuple[str, ...], rows: int) -> None:
    """The check of a staged Parquet track file before it is renamed (``atomic_write``'s
    ``verify``): its footer reads back with the ``columns`` and the ``rows`` written."""
    import pyarrow.parquet as pq

    meta = pq.ParquetFile(path).metadata
    names = tuple(meta.schema.to_arrow_schema().names)
    if names != columns or meta.num_rows != rows:
        raise ValueError(
            f"the Parquet file reads back with {meta.num_rows} rows of {len(names)} columns, "
            f"not {rows} of {len(columns)}"
        )


class TrackWriter:
    """The track file written a block of rows at a time with pyarrow's CSV writer (or, with
    ``parquet``, its Parquet writer: a row group per block, the same columns and values).

    A row is (time_s, [target,] method, the six state components, the 21 covariance
    entries); a block's states x (N, 6) and P (N, 6, 6) become the columns through the index
    tables that ``state_from_row`` reads them back with, and pyarrow formats the floats (shortest
    round trip, like Python's repr, but ``0`` for 0.0) and quotes the text columns. Memory
    holds at most ``WRITE_BLOCK`` rows.

    Args:
        fh: the binary file to write (``atomic_write``'s).
        targets: the file has a ``target`` column (``track_columns``).
        status: and a ``status`` column (associated tracks).
        parquet: write Parquet (``parquet_writer``) instead of CSV.
        radar_tracks: and a ``RADAR_TRACK_COLUMN`` (each plot's ``radar_track``).
    """

    def __init__(
        self,
        fh: IO[bytes],
        targets: bool,
        status: bool = False,
        parquet: bool = False,
        radar_tracks: bool = False,
    ):
        self.fh = fh
        self.parquet = parquet
        self.targets = targets
        self.status = targets and status
        self.radar_tracks = self.status and radar_tracks
        self.columns = track_columns(targets, self.status, self.radar_tracks)
        self._statuses: list[str] = []
        self._radar_tracks: list[int | None] = []
        self.rows = 0
        self._writer: Any = None
        self._times: list[float] = []
        self._labels: list[str] = []
        self._methods: list[str] = []
        self._x: list[NDArray[np.float64]] = []
        self._P: list[NDArray[np.float64]] = []

    def add(self, plot: Plot, rows: list[StateRow], status: str = "") -> None:
        """One plot's rows (method, x (6,), P (6, 6)); ``status``: its track's, if the file
        has the column."""
        for m, x, P in rows:
            self._times.append(plot.time_s)
            self._methods.append(m)
            self._x.append(x)
            self._P.append(P)
        if self.targets:
            self._labels.extend([plot.target] * len(rows))
        if self.status:
            self._statuses.extend([status] * len(rows))
        if self.radar_tracks:
            self._radar_tracks.extend([plot.radar_track] * len(rows))
        self.rows += len(rows)
        if len(self._times) >= WRITE_BLOCK:
            self.flush()

    def flush(self) -> None:
        """Write the buffered rows (the header with the first block)."""
        import pyarrow as pa
        import pyarrow.csv as pcsv

        if not self._times:
            return
        x = np.stack(self._x)[:, _STATE_INDEX]
        P = np.stack(self._P)[:, _COV_ROWS, _COV_COLS]
        text = [pa.array(self._labels, pa.string())] if self.targets else []
        if self.status:
            text.append(pa.array(self._statuses, pa.string()))
        if self.radar_tracks:
            text.append(pa.array(self._radar_tracks, pa.int64()))
        columns = [
            pa.array(self._times, pa.float64()),
            *text,
            pa.array(self._methods, pa.string()),
            *(pa.array(x[:, k]) for k in range(x.shape[1])),
            *(pa.array(P[:, k]) for k in range(P.shape[1])),
        ]
        table = pa.Table.from_arrays(columns, names=list(self.columns))
        if self._writer is None:
            if self.parquet:
                self._writer = parquet_writer(self.fh, self.targets, self.status, self.radar_tracks)
            else:
                options = pcsv.WriteOptions(quoting_style="needed")
                self._writer = pcsv.CSVWriter(self.fh, table.schema, write_options=options)
        self._writer.write_table(table)
        for buf in (self._times, self._labels, self._statuses, self._radar_tracks):
            buf.clear()
        for buf in (self._methods, self._x, self._P):
            buf.clear()

    def close(self) -> None:
        """Write what is buffered and finish the file (a Parquet file without rows still
        gets its schema)."""
        self.flush()
        if self._writer is None and self.parquet:
            self._writer = parquet_writer(self.fh, self.targets, self.status, self.radar_tracks)
        if self._writer is not None:
            self._writer.close()

    def abandon(self) -> None:
        """After an error (the staged file is then removed): release a Parquet writer, which
        would otherwise finish the file when collected, after the file is closed. Quiet."""
        if self.parquet and self._writer is not None:
            with contextlib.suppress(Exception):
                self._writer.close()

    def verify(self, path: str | os.PathLike) -> None:
        """``atomic_write``'s check of the staged file (Parquet: ``verify_track_parquet``;
        a CSV file is checked by its size alone)."""
        if self.parquet:
            verify_track_parquet(path, self.columns, self.rows)


#: The variances among the track columns: they must not be negative.
VARIANCE_COLUMNS = frozenset(covariance_column(c, c) for c, _ in _COMPONENTS)
_ROW_NONNEGATIVE = np.array([c in VARIANCE_COLUMNS for c in TRACK_COLUMNS[2:]])


def check_track_rows(where: str, rows: list[StateRow]) -> None:
    """The finite-result check (``core.finite``) of one plot's track rows before they are
    written: every state and covariance entry finite, every variance not negative. Nothing
    in a track is undefined (before its start a method has no row at all)."""
    for method, x, P in rows:
        values = np.concatenate([x[_STATE_INDEX], P[_COV_ROWS, _COV_COLS]])
        if np.isfinite(values).all() and (values[_ROW_NONNEGATIVE] >= 0).all():
            continue  # the usual case, without building names
        for column, v, positive in zip(TRACK_COLUMNS[2:], values, _ROW_NONNEGATIVE, strict=True):
            check_finite_result(where, f"{column} of {method}", v, nonnegative=bool(positive))


def state_from_row(values: dict[str, str]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The state x (6,) and P (6, 6) of one track-file row (the inverse of ``TrackWriter``)."""
    x = np.zeros(6)
    x[_STATE_INDEX] = [float(values[c]) for c in TRACK_COLUMNS[2:8]]
    P = np.zeros((6, 6))
    P[_COV_ROWS, _COV_COLS] = [float(values[c]) for c in TRACK_COLUMNS[8:]]
    P[_COV_COLS, _COV_ROWS] = P[_COV_ROWS, _COV_COLS]
    return x, P


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def atomic_text(path: str | os.PathLike) -> AbstractContextManager[IO[str]]:
    """A UTF-8 text file (csv newlines) that appears at ``path`` only when complete."""
    return atomic_write(path, "w", newline="", encoding="utf-8")


#: Longest line a measurement file may have (a plot's line is under 200 bytes): longer lines
#: are refused as they are read, so a file without newlines never fills the memory.
MAX_LINE_BYTES = 65_536
#: Largest radars file read (a radar is ~200 bytes).
MAX_RADARS_BYTES = 1_000_000
#: How long an input FIFO may stay without a writer before the command gives up, s.
FIFO_WAIT_S = 10.0


def load_radars(path: str) -> dict[str, Radar]:
    with open(path, "rb") as fh:
        raw = fh.read(MAX_RADARS_BYTES + 1)
    if len(raw) > MAX_RADARS_BYTES:
        raise ParameterError(f"{path}: larger than {MAX_RADARS_BYTES} bytes: not a radars file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise ParameterError(f"{path} line {line}: not UTF-8 text") from None
    deprecated: list[str] = []
    radars = parse_radars(text, path, deprecated)
    for line in deprecated:
        print(f"radarviz: {line}", file=sys.stderr)
    return radars


def radar_table(radars: dict[str, Radar]) -> RadarTable:
    """The radars file as a ``RadarTable`` (radians; 0 for an absent σε or σVr: a plot that
    would need it is refused by the reader)."""
    rs = list(radars.values())
    return RadarTable(
        np.array([(r.x_m, r.y_m, r.z_m) for r in rs], dtype=np.float64).reshape(-1, 3),
        np.array([r.sigma_r_m for r in rs], dtype=np.float64),
        np.radians([r.sigma_beta_deg for r in rs]),
        np.radians([r.sigma_elevation_deg or 0.0 for r in rs]),
        np.array([r.sigma_vr_mps or 0.0 for r in rs], dtype=np.float64),
    )


def _open_input(path: str) -> Any:
    """``path`` opened for binary reading; a FIFO waits at most ``FIFO_WAIT_S`` for a writer
    (a plain open would block forever)."""
    import select
    import stat

    if not stat.S_ISFIFO(os.stat(path).st_mode):
        return open(path, "rb")
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    try:
        ready, _, _ = select.select([fd], [], [], FIFO_WAIT_S)
        if not ready:
            raise ParameterError(f"{path}: a FIFO with no writer after {FIFO_WAIT_S:g} s")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


#: What a line that ends in a bare CR is told: lines are split at LF (a CRLF's CR is dropped
#: with it), so a file of old Mac line ends is one long line with CRs inside.
BARE_CR_TEXT = "a line ends in a bare CR (old Mac text): write the file with LF or CRLF line ends"


def csv_error_text(exc: Exception) -> str:
    """The words for a ``csv.Error``: the csv module's "new-line character seen in unquoted
    field" is a bare CR inside a line (``BARE_CR_TEXT``)."""
    return BARE_CR_TEXT if "new-line character" in str(exc) else str(exc)


def long_line_error(source: str, number: int, raw: bytes) -> ParameterError:
    """The error for a line of more than ``MAX_LINE_BYTES``: a file of bare-CR line ends is
    one such line, and is told so."""
    if re.search(rb"\r[^\n]", raw):
        return ParameterError(f"{source} line {number}: {BARE_CR_TEXT}")
    return ParameterError(
        f"{source} line {number}: longer than {MAX_LINE_BYTES} bytes (not a plots file?)"
    )


def bounded_lines(fh: Any, source: str) -> Iterator[str]:
    """The lines of a binary file, decoded as UTF-8 (a leading BOM dropped), each at most
    ``MAX_LINE_BYTES``: a longer line or bytes that are not UTF-8 are a ParameterError naming
    the line."""
    number = 0
    while True:
        raw = fh.readline(MAX_LINE_BYTES + 1)
        if not raw:
            return
        number += 1
        if len(raw) > MAX_LINE_BYTES:
            raise long_line_error(source, number, raw)
        if number == 1 and raw.startswith(b"\xef\xbb\xbf"):
            raw = raw[3:]
        try:
            yield raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ParameterError(
                f"{source} line {number}: not UTF-8 text (byte {raw[exc.start]:#04x} at "
                f"column {exc.start + 1})"
            ) from None


@dataclass(frozen=True)
class TrackSummary:
    """What ``run_track`` did: plots read, rows written, 2D/3D, methods, wall time (s), and
    the targets in order of their first plot (() for a file without a target column), and
    what the reader counted on the way (``input_summary``; None for a CSV)."""

    plots: int
    rows: int
    three_d: bool
    methods: tuple[str, ...]
    seconds: float
    targets: tuple[str, ...] = ()
    input: dict[str, Any] | None = None
    #: The association's account (``track --associate``), or None.
    association: AssociationReport | None = None


def input_summary(reader: object) -> dict[str, Any] | None:
    """What a reader counted (ASTERIX's ``AsterixReader.input_summary``: records skipped or
    dropped, a capture's packets, the scan timing), or None for one that counts nothing."""
    summary = getattr(reader, "input_summary", None)
    return None if summary is None else summary()


def radar_track_numbers(reader: object) -> bool:
    """Whether a reader's target labels are radars' own track numbers (ASTERIX I048/161,
    ``AsterixReader.radar_tracks``): the association accepts them (each plot keeps its number
    as ``Plot.radar_track``) where it refuses a CSV's target labels."""
    return bool(getattr(reader, "radar_tracks", False))


class PlotSource(Protocol):
    """What ``track_plots`` reads: a measurement file's plots, with what its start told.

    ``PlotReader`` (CSV) and ``viz_app.io.asterix.AsterixReader`` (ASTERIX CAT048) are the
    files'; ``radarviz.track`` hands its plots in memory as one (the association's route).
    Iterating yields (position, ``Plot``), the position being what ``track_plots``'s
    ``locate`` turns into words (a line number; a byte offset; an index).
    """

    #: Plots carry elevations (3D).
    three_d: bool
    #: Plots carry target labels (a file of many targets).
    targets: bool

    def __iter__(self) -> Iterator[tuple[int, Plot]]: ...


#: Where a plot's value is in its file, from the reader's position and the input column.
Locate = Callable[[int, str], str]
#: Given the opened binary input, its name and the radars: the plots' reader and its
#: ``Locate``. ``csv_source`` is the CSV's; ``viz_app.io.asterix.asterix_source`` ASTERIX's.
SourceFactory = Callable[[IO[bytes], str, dict[str, Radar]], tuple[PlotSource, Locate]]


def _csv_locate(line: int, column: str) -> str:
    return f"line {line}, column {column}"


def csv_source(fh: IO[bytes], source: str, radars: dict[str, Radar]) -> tuple[PlotSource, Locate]:
    """The plots of a measurement CSV (``PlotReader``) and their "line L, column C"."""
    return PlotReader(bounded_lines(fh, source), source, radars), _csv_locate


def track_lines(
    lines: Iterable[str],
    source: str,
    radars: dict[str, Radar],
    methods: tuple[str, ...] | None,
    options: StreamOptions,
    on_rows: Callable[..., None],
    on_start: Callable[[bool], None] | None = None,
    association: AssociationOptions | None = None,
) -> tuple[int, bool, tuple[str, ...], tuple[str, ...]]:
    """Track a measurement CSV given as lines (``track_plots`` of its ``PlotReader``)."""
    reader = PlotReader(lines, source, radars)
    return track_plots(
        reader, source, methods, options, on_rows, on_start, _csv_locate, association
    )


def track_plots(
    reader: PlotSource,
    source: str,
    methods: tuple[str, ...] | None,
    options: StreamOptions,
    on_rows: Callable[..., None],
    on_start: Callable[[bool], None] | None = None,
    locate: Locate = _csv_locate,
    association: AssociationOptions | None = None,
    on_scan: Callable[[list[str]], None] | None = None,
    coverage: Mapping[str, RadarCoverage] | None = None,
    on_report: Callable[[AssociationReport], None] | None = None,
) -> tuple[int, bool, tuple[str, ...], tuple[str, ...]]:
    """Track a file's plots; ``on_rows(plot, rows)`` after every plot.

    ``reader`` is a ``PlotSource`` (its ``three_d`` and ``targets`` known before the first
    plot). Plots are read and tracked ``READ_BLOCK`` at a time, so at most that many are held.
    A file with target labels is tracked by ``core.tracking.targets.TargetTracker`` (one track
    per target and method, all targets in one batch), one without by ``StreamTracker``;
    ``on_start(targets)`` is called once the reader has told which.

    ``methods`` None: every method of the file's kind (``ALL_METHODS`` in 2D, ``METHODS_3D``
    in 3D). Returns (plots, three_d, methods, targets). Tracker errors come back as
    "SOURCE " + ``locate(position, column)`` + ": …" (without "SOURCE " for ``source`` "").

    With ``association`` (``track --associate gnn``) a file without target labels is
    associated batch by batch (``core.tracking.association.GNNTracker``; batches by radar
    and azimuth sector, ``plot_batches``, or with ``scan_window_s`` by time, ``scan_groups``),
    each radar's misses counted in its ``coverage`` (by radar name; estimated from the plots
    where absent): ``on_rows(plot, rows, status)`` then gets the plot labelled with its track
    id and the track's status after the batch, ``on_scan(deleted)`` the ids of the tracks
    deleted at the batch after its last plot's ``on_rows``, ``on_report`` the association's
    account at the end, and ``targets`` are the ids of the tracks ever confirmed. Memory holds
    the batches of about ``READ_BLOCK`` plots.
    """
    three_d, labelled = reader.three_d, reader.targets
    if methods is None:
        methods = METHODS_3D if three_d else ALL_METHODS
    if association is not None:
        return _associate_plots(
            reader,
            source,
            methods,
            options,
            association,
            on_rows,
            on_start,
            locate,
            on_scan,
            coverage,
            on_report,
        )
    tracker: StreamTracker | TargetTracker
    try:
        if labelled:
            tracker = TargetTracker(methods, three_d, options)
        else:
            tracker = StreamTracker(methods, three_d, options)
    except ParameterError as exc:  # errors about the options: the CLI names the flag
        if exc.parameter:
            raise
        raise ParameterError(f"--{exc}") from None
    if on_start is not None:
        on_start(labelled)
    plots = 0
    block: list[tuple[int, Plot]] = []

    def run_block() -> None:
        try:
            rows = tracker.add_block([plot for _, plot in block])
        except PlotError as exc:
            where = _place(source, locate(block[exc.index][0], exc.column))
            raise ParameterError(f"{where}: {exc}") from None
        for (_, plot), plot_rows in zip(block, rows, strict=True):
            on_rows(plot, plot_rows)
        block.clear()

    for position, plot in reader:
        block.append((position, plot))
        plots += 1
        if len(block) == READ_BLOCK:
            run_block()
    if block:
        run_block()
    targets = tracker.targets if isinstance(tracker, TargetTracker) else ()
    return plots, three_d, methods, targets


def input_format_of(path: str, file_format: str = "auto") -> str:
    """``"csv"``, ``"asterix"`` or ``"pcap"`` (a pcap or pcapng capture of ASTERIX datagrams):
    ``file_format`` itself, or with ``"auto"`` a capture by its magic (a regular file's first
    octets; ``viz_app.io.pcap.is_capture``) or ``CAPTURE_SUFFIXES``, else by the suffix of
    ``path`` (``ASTERIX_SUFFIXES``: ASTERIX; anything else: CSV)."""
    check_choice("format", file_format, FILE_FORMATS)
    if file_format != "auto":
        return file_format
    if path.lower().endswith(CAPTURE_SUFFIXES) or _capture_magic(path):
        return "pcap"
    return "asterix" if path.lower().endswith(ASTERIX_SUFFIXES) else "csv"


#: ``simulate --format``: what it writes (a capture is read, not written).
OUTPUT_FORMATS = ("auto", "csv", "asterix")


def output_format_of(path: str, file_format: str = "auto") -> str:
    """``"csv"`` or ``"asterix"``, the format ``simulate`` writes ``path`` in: ``file_format``
    itself, or with ``"auto"`` by the suffix (``ASTERIX_SUFFIXES``: ASTERIX; else CSV)."""
    check_choice("format", file_format, OUTPUT_FORMATS)
    if file_format != "auto":
        return file_format
    return "asterix" if path.lower().endswith(ASTERIX_SUFFIXES) else "csv"


def _capture_magic(path: str) -> bool:
    """Whether the regular file ``path`` starts with a capture's magic (a FIFO is not opened
    here: its octets would be lost to the reader; a missing file is for the reader to name)."""
    from radarviz.viz_app.io.pcap import is_capture

    try:
        if not os.path.isfile(path):
            return False
        with open(path, "rb") as fh:
            return is_capture(fh.read(12))
    except OSError:
        return False


def labels_refused(name: str, labelled: str) -> str:
    """Why the association (``name``: ``--associate``, or the API's ``association``) refuses
    plots with target labels, in words: it is what decides which plots are one target's, so
    plots whose targets are already known are tracked without it (one track per label).
    ``labelled`` says where the labels are ("this file labels them")."""
    return f"{name} is for plots without target labels ({labelled}: track them without {name})"


def _place(source: str, where: str) -> str:
    """``where`` (a ``Locate``'s words) in ``source``; a source without a name (the API's
    plots in memory) is located by ``where`` alone."""
    return f"{source} {where}" if source else where


def _associate_plots(
    reader: PlotSource,
    source: str,
    methods: tuple[str, ...],
    options: StreamOptions,
    association: AssociationOptions,
    on_rows: Callable[..., None],
    on_start: Callable[[bool], None] | None,
    locate: Locate,
    on_scan: Callable[[list[str]], None] | None = None,
    coverage: Mapping[str, RadarCoverage] | None = None,
    on_report: Callable[[AssociationReport], None] | None = None,
) -> tuple[int, bool, tuple[str, ...], tuple[str, ...]]:
    """``track_plots`` with the association (its docstring)."""
    if reader.targets and not radar_track_numbers(reader):
        where = _place(source, locate(1, "target"))
        raise ParameterError(f"{where}: {labels_refused('--associate', 'this file labels them')}")
    try:
        tracker = GNNTracker(methods, reader.three_d, options, association, coverage=coverage)
    except ParameterError as exc:
        if exc.parameter:
            raise
        raise ParameterError(f"--{exc}") from None
    if on_start is not None:
        on_start(True)
    plots = 0
    window = association.scan_window_s
    # A file is in time order (the readers check it), a feed of several radars nearly so.
    ordered = time_ordered(reader)
    batches = (
        plot_batches(ordered, association.batch_sector_deg)
        if window is None
        else scan_groups(ordered, window)
    )
    # A capture's CAT034 messages time the antennas (``AsterixReader.scan_timing``): a period
    # they give replaces the one estimated from the plots.
    timing = getattr(reader, "scan_timing", None)
    runner = BatchRunner(tracker, source, locate, on_rows, on_scan)
    while True:
        try:
            scan = next(batches)
        except StopIteration:
            break
        except LatePlotError as exc:
            raise ParameterError(f"{_place(source, locate(exc.key, exc.column))}: {exc}") from None
        runner.hold(scan, scan_period(timing, scan))
        plots += len(scan)
        if runner.held >= READ_BLOCK:
            runner.run()
    runner.run()
    if on_report is not None:
        on_report(tracker.report())
    return plots, reader.three_d, methods, tuple(tracker.ever_confirmed)


def scan_period(timing: Mapping[str, Any] | None, scan: list[tuple[Any, Plot]]) -> float | None:
    """The antenna period of a batch's radar that CAT034 messages give (``timing``: radar →
    ``ScanTiming``, as ``AsterixReader.scan_timing``), None without: the one the batch is
    held with (``BatchRunner.hold``), replacing the one estimated from the plots."""
    if not timing:
        return None
    return getattr(timing.get(scan[0][1].radar), "rotation_period_s", None)


class BatchRunner:
    """The association's batches, held and associated in one compiled call
    (``GNNTracker.add_batches``) when asked: ``track --associate`` runs them ``READ_BLOCK``
    plots at a time, ``radarviz live`` also when its time budget is spent.

    ``hold(batch, period)`` keeps a batch of (key, plot) pairs with its radar's antenna period
    as the feed measured it by then (or None); ``run()`` associates what is held, hands every
    plot to ``on_rows(plot labelled with its track id, rows, status)`` and each batch's
    deleted tracks to ``on_scan``, and returns the keys of the plots it ran. A tracker error
    is a ``ParameterError`` naming the plot (``locate``).
    """

    def __init__(
        self,
        tracker: GNNTracker,
        source: str,
        locate: Locate,
        on_rows: Callable[..., None],
        on_scan: Callable[[list[str]], None] | None = None,
    ):
        self.tracker = tracker
        self.source = source
        self.locate = locate
        self.on_rows = on_rows
        self.on_scan = on_scan
        self.chunk: list[list[tuple[Any, Plot]]] = []
        self.periods: list[float | None] = []
        #: Plots held.
        self.held = 0

    def hold(self, batch: list[tuple[Any, Plot]], period: float | None = None) -> None:
        self.chunk.append(batch)
        self.periods.append(period)
        self.held += len(batch)

    def run(self) -> list[Any]:
        chunk, keys = self.chunk, []
        if not chunk:
            return keys
        try:
            results = self.tracker.add_batches([[p for _, p in b] for b in chunk], self.periods)
        except PlotError as exc:
            scan = chunk[getattr(exc, "batch", 0)]
            where = _place(self.source, self.locate(scan[exc.index][0], exc.column))
            raise ParameterError(f"{where}: {exc}") from None
        for scan, result in zip(chunk, results, strict=True):
            for (key, plot), track, status, rows in zip(
                scan, result.track_ids, result.statuses, result.rows, strict=True
            ):
                self.on_rows(replace(plot, target=track), rows, status)
                keys.append(key)
            if self.on_scan is not None:
                self.on_scan(result.deleted)
        self.chunk, self.periods, self.held = [], [], 0
        return keys


class RowObserver(Protocol):
    """What ``run_track`` can hand every plot and its track rows to (e.g. a Rerun recorder).

    With the association, ``add`` also gets the status of the plot's track after its scan
    (``tentative`` or ``confirmed``; "" without the association) and ``end_scan`` the ids of
    the tracks deleted at the scan, after the scan's last plot (``track_plots``'s
    ``on_scan``), and ``report`` the association's account after the last plot.
    ``radarviz.Tracks.replay`` hands one the same calls from a kept result."""

    def add(self, plot: Plot, rows: list[StateRow], status: str = "") -> None: ...

    def end_scan(self, deleted: list[str]) -> None: ...

    def report(self, account: AssociationReport) -> None: ...


#: Given the radars, a context manager yielding a :class:`RowObserver`; it is entered before the
#: first plot and left (flushed, closed) after the last, or on an error.
ObserverFactory = Callable[[Iterable[Radar]], AbstractContextManager[RowObserver]]


def run_track(
    input_path: str,
    radars_path: str,
    out_path: str,
    methods: tuple[str, ...] | None = None,
    options: StreamOptions | None = None,
    observer: ObserverFactory | None = None,
    open_source: SourceFactory | None = None,
    association: AssociationOptions | None = None,
) -> TrackSummary:
    """Track every plot of ``input_path`` into ``out_path``, a ``Plot`` at a time;
    ``observer`` also sees each plot (``viz_app.io.plot_blocks.run_track`` is the command's
    entry: this path for a recording, a finite-memory start or the association; blocks of
    columns otherwise, CSV or ASTERIX).

    ``open_source`` reads the input's plots (``csv_source`` by default; the command hands in
    ``viz_app.io.asterix.asterix_source`` for an ASTERIX file, see ``input_format_of``).
    ``association``: associate unlabelled plots (``track_plots``); the track file then has
    ``target`` (the track id) and ``status`` columns."""
    options = options or StreamOptions()
    open_source = open_source or csv_source
    radars = load_radars(radars_path)
    start = time.perf_counter()
    with ExitStack() as stack:
        stack.enter_context(commit_together())  # the tracks and the recording: both or neither
        fh = stack.enter_context(_open_input(input_path))
        reader, locate = open_source(fh, input_path, radars)
        writer: TrackWriter | None = None

        def verify(path: Path) -> None:
            if writer is not None:
                writer.verify(path)

        out = stack.enter_context(atomic_write(out_path, "wb", verify=verify))
        logger = None if observer is None else stack.enter_context(observer(radars.values()))

        def on_start(targets: bool) -> None:
            nonlocal writer
            status = association is not None
            numbers = status and radar_track_numbers(reader)
            writer = TrackWriter(out, targets, status, is_parquet(out_path), numbers)
            stack.callback(writer.abandon)  # before the stage's end (a no-op once closed)

        def on_rows(plot: Plot, rows: list[StateRow], status: str = "") -> None:
            assert writer is not None
            check_track_rows(f"track: {input_path} at time {plot.time_s!r} s", rows)
            writer.add(plot, rows, status)
            if logger is not None:
                logger.add(plot, rows, status)

        reports: list[AssociationReport] = []
        plots, three_d, used, targets = track_plots(
            reader,
            input_path,
            methods,
            options,
            on_rows,
            on_start,
            locate,
            association,
            None if logger is None else logger.end_scan,
            {name: radar_coverage(r) for name, r in radars.items()},
            reports.append,
        )
        if reports and logger is not None:
            logger.report(reports[0])
        assert writer is not None
        writer.close()
        written = writer.rows
        if plots and not written:
            # Raised inside the block: the output is abandoned, not written empty.
            raise ParameterError(
                f"init_k must leave plots to track: the finite-memory start needs "
                f"{options.init_k} plots of one radar and {input_path} has {plots} plot(s) "
                "in all, so no track started (lower --init-k or use --init first-plot)",
                "init_k",
            )
    seconds = time.perf_counter() - start
    return TrackSummary(
        plots,
        written,
        three_d,
        tuple(used),
        seconds,
        targets,
        input_summary(reader),
        reports[0] if reports else None,
    )


# --------------------------------------------------------------------------------------------
# Simulation presets
# --------------------------------------------------------------------------------------------


def _radar_toml(radars: Iterable[Radar]) -> str:
    out = []
    for r in radars:
        out.append(f"[radars.{r.name}]")
        for key in RADAR_KEYS + OPTIONAL_RADAR_KEYS:
            v = getattr(r, key)
            if v is not None:
                out.append(f"{key} = {float(v)!r}")
        if r.sac is not None and r.sic is not None:
            out.append(f"sac = {r.sac}")
            out.append(f"sic = {r.sic}")
        out.append("")
    return "\n".join(out)


def prosov_plots(seed: int = 1, sigma_beta_deg: float = 1.0) -> tuple[list[Plot], list[Radar]]:
    """The Prosov scene's displayed run (``displayed_measurements``): one 2D radar at the
    origin."""
    cfg = TrackingConfig(sigma_beta_deg=sigma_beta_deg, seed=seed)
    r_hat, b_hat = displayed_measurements(cfg)
    times = np.arange(cfg.target.steps) * cfg.target.period_s
    radar = Radar("radar", 0.0, 0.0, 0.0, cfg.sigma_r_m, cfg.sigma_beta_deg)
    plots = [
        Plot(
            float(t),
            float(r),
            math.radians(math.degrees(float(b))),
            cfg.sigma_r_m,
            math.radians(cfg.sigma_beta_deg),
            radar="radar",
        )
        for t, r, b in zip(times, r_hat[0], b_hat[0], strict=True)
    ]
    return plots, [radar]


def fusion_plots(seed: int = 1, steps: int = 60) -> tuple[list[Plot], list[Radar]]:
    """The velocity paper's three 3D radars with Doppler, scans staggered by T/3, one target.

    The target flies the paper's baseline track for 200 s, then holds a 0.005 rad/s turn (a
    circle of ≈ 50 km radius) for as long as ``steps`` (scans per radar) asks, so long files
    stay in coverage. Each radar's measurements come from
    ``core.scenarios.multi_radar.generate_measurements``.
    """
    steps = int(check("steps", steps, high=MAX_SIMULATE_STEPS))
    base = fusion_scenario()
    period = base.radars[0].period_s
    n_radars = len(base.radars)
    sites = tuple(replace(r, t0_s=k * period / n_radars) for k, r in enumerate(base.radars))
    trajectory = Trajectory3D(
        BASELINE_TARGET_M, BASELINE_VELOCITY_MPS, (Segment(200.0), Segment(1e12, turn_rate=0.005))
    )
    scenario = Scenario3D(sites, trajectory)
    meas = generate_measurements(scenario, (steps - 1) * period + 2 * period / 3, seed=seed)
    radars = [
        Radar(
            s.name,
            *map(float, s.position),
            s.sigma_r_m,
            math.degrees(s.sigma_beta_rad),
            math.degrees(s.sigma_elevation_rad),
            s.sigma_vr_mps,
        )
        for s in sites
    ]
    plots = []
    for s in sites:
        m = meas[s.name]
        # Angles and σ through degrees and back, exactly as the file will give them.
        sigma_beta_rad, sigma_elevation_rad = (
            math.radians(math.degrees(v)) for v in (s.sigma_beta_rad, s.sigma_elevation_rad)
        )
        for k in range(min(steps, m.t.size)):
            plots.append(
                Plot(
                    float(m.t[k]),
                    float(m.range[k]),
                    math.radians(math.degrees(float(m.azimuth[k]))),
                    s.sigma_r_m,
                    sigma_beta_rad,
                    tuple(map(float, s.position)),
                    s.name,
                    math.radians(math.degrees(float(m.elevation[k]))),
                    sigma_elevation_rad,
                    float(m.radial_velocity[k]),
                    s.sigma_vr_mps,
                )
            )
    plots.sort(key=lambda p: p.time_s)  # stable: radars in order at equal times
    return plots, radars


class PlotField(NamedTuple):
    """One numeric field of a ``Plot`` that a measurement file's row is made of or checked
    against: its name, whether it must be > 0 (a range, an accuracy; else only finite) and
    whether it may be None (the plot has no elevation, no radial velocity)."""

    name: str
    positive: bool
    optional: bool


#: A plot's numeric fields, checked before plots are written (``PLOT_FIELDS`` is the one list:
#: ``bad_plot_field`` finds a user's bad value, ``check_plots_finite`` a simulated one).
PLOT_FIELDS: tuple[PlotField, ...] = (
    PlotField("time_s", positive=False, optional=False),
    PlotField("range_m", positive=True, optional=False),
    PlotField("azimuth_rad", positive=False, optional=False),
    PlotField("sigma_r_m", positive=True, optional=False),
    PlotField("sigma_beta_rad", positive=True, optional=False),
    PlotField("elevation_rad", positive=False, optional=True),
    PlotField("radial_velocity_mps", positive=False, optional=True),
)


def bad_plot_field(plot: Plot) -> PlotField | None:
    """The first of ``PLOT_FIELDS`` whose value in ``plot`` is not a finite number (or not > 0
    where it must be), or None: a None is allowed for an optional field only."""
    for field in PLOT_FIELDS:
        v = getattr(plot, field.name)
        if v is None and field.optional:
            continue
        if not isinstance(v, int | float) or not math.isfinite(v) or (field.positive and v <= 0):
            return field
    return None


def check_plots_finite(plots: list[Plot]) -> None:
    """The finite-result check (``core.finite``) of plots about to be written (``simulate``):
    every field of ``PLOT_FIELDS`` finite, the positive ones not below 0, an optional one
    where the plot has it."""
    for field in PLOT_FIELDS:
        values = [getattr(p, field.name) for p in plots]
        if field.optional:
            values = [v for v in values if v is not None]
        check_finite_result(
            "simulate", field.name, values, nonnegative=field.positive, index_name="plot"
        )


def write_measurements(
    meas_path: str, radars_path: str, plots: list[Plot], radars: list[Radar]
) -> int:
    """Plots as a measurement CSV and their radars as TOML, committed together; returns
    plots (with a ``target`` column when any plot has a target label). Every plot's values
    pass the finite-result check first (a range or an angle that came out NaN is an error,
    not a row; ranges must be > 0 to be read back)."""
    check_plots_finite(plots)
    three_d = plots[0].elevation_rad is not None
    doppler = any(p.radial_velocity_mps is not None for p in plots)
    labelled = any(p.target for p in plots)
    header = (
        list(REQUIRED_COLUMNS)
        + (["elevation_deg"] if three_d else [])
        + (["radial_velocity_mps"] if doppler else [])
        + (["target"] if labelled else [])
    )
    # Both files change together or neither does (``commit_together``).
    with commit_together(), atomic_text(meas_path) as fh, atomic_text(radars_path) as rh:
        w = csv.writer(fh)
        w.writerow(header)
        for p in plots:
            row = [p.time_s, p.radar, p.range_m, math.degrees(p.azimuth_rad)]
            if three_d:
                assert p.elevation_rad is not None
                row.append(math.degrees(p.elevation_rad))
            if doppler:
                row.append("" if p.radial_velocity_mps is None else p.radial_velocity_mps)
            if labelled:
                row.append(p.target)
            w.writerow(row)
        rh.write(_radar_toml(radars))
    return len(plots)


def simulated_plots(
    preset: str,
    seed: int = default("seed"),
    sigma_beta_deg: float = default("sigma_beta_deg"),
    steps: int = default("steps"),
) -> tuple[list[Plot], list[Radar]]:
    """A preset's plots and radars (the plots' angles already rounded through degrees, so
    tracking them equals tracking the file ``simulate`` writes).

    ``prosov`` uses ``sigma_beta_deg`` (its run has 60 scans), ``fusion`` uses ``steps``; the
    other value is still checked, so a bad one is an error whatever the preset.
    """
    check_choice("preset", preset, SIM_PRESETS)
    if preset == "prosov":
        check("steps", steps, high=MAX_SIMULATE_STEPS)
        return prosov_plots(seed, sigma_beta_deg)
    check("sigma_beta_deg", sigma_beta_deg)
    return fusion_plots(seed, steps)
