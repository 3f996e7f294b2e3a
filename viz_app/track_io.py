"""``radarviz track`` and ``radarviz simulate``: measurement files in, track files out.

Measurement file (CSV, header line first, one row per plot of one target, times
non-decreasing)::

    time_s, radar, range_m, azimuth_deg [, elevation_deg] [, radial_velocity_mps]

Radars file (TOML, read with ``tomllib``)::

    [radars.NAME]
    x_m = 0.0; y_m = 0.0; z_m = 0.0          # site, m
    sigma_range_m = 250.0                    # > 0
    sigma_azimuth_deg = 1.0                  # in (0, 20]
    sigma_elevation_deg = …                  # optional, > 0 (not used yet)
    sigma_radial_velocity_mps = …            # optional, > 0 (not used yet)

Tracking is 2D for now: elevation and radial velocity (checked if present) and the sites' z are
not used. Each method keeps one track (``core.track_stream.MethodTrack``): started from the
first plot (the spec's start), then predict over the time step and update, radar-centred.

Track file (CSV), one row per plot and method, in plot order then ``--method`` order; the first
plot's rows are the starting states::

    time_s, method, x_m, y_m, z_m, vx_mps, vy_mps, vz_mps,
    p_xx, p_xy, p_xz, p_yy, p_yz, p_zz,                    position covariance (upper triangle)
    p_vxvx, p_vxvy, p_vxvz, p_vyvy, p_vyvz, p_vzvz,        velocity covariance (upper triangle)
    p_xvx, p_xvy, p_xvz, p_yvx, p_yvy, p_yvz, p_zvx, p_zvy, p_zvz   position–velocity block

(m, m/s, m², m²/s, m²/s²). In 2D, z, vz and every covariance entry involving them are 0.
Floats are written with Python's shortest round-trip repr, so nothing is lost.

``--out`` defaults to ``tracks.csv`` in the current directory and an existing file is replaced.
Both commands write to a temporary file beside the target and rename it when complete, so a
bad input (one line on standard error naming file, line and column; exit 2) or a crash leaves
no output and an existing file untouched. The measurement file is read row by row and the
tracks written row by row: memory does not grow with the file.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import tempfile
import tomllib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np
from numpy.typing import NDArray

from core.prosov import ALL_METHODS, MAX_SIGMA_BETA_DEG
from core.track_stream import MethodTrack, Plot2D, prosov_single_run, track_groups
from core.validation import ParameterError, check_choice, check_int, check_real

REQUIRED_COLUMNS = ("time_s", "radar", "range_m", "azimuth_deg")
OPTIONAL_COLUMNS = ("elevation_deg", "radial_velocity_mps")
RADAR_KEYS = ("x_m", "y_m", "z_m", "sigma_range_m", "sigma_azimuth_deg")
OPTIONAL_RADAR_KEYS = ("sigma_elevation_deg", "sigma_radial_velocity_mps")
DEFAULT_TRACKS = "tracks.csv"
SIM_PRESETS = ("prosov",)

#: (name, index into the 6-vector (x, y, z, vx, vy, vz)) of the covariance columns.
_ORDER6 = ("x", "y", "z", "vx", "vy", "vz")
_COV_PAIRS: tuple[tuple[int, int], ...] = (
    tuple((i, j) for i in range(3) for j in range(i, 3))
    + tuple((i, j) for i in range(3, 6) for j in range(i, 6))
    + tuple((i, j) for i in range(3) for j in range(3, 6))
)
TRACK_COLUMNS: tuple[str, ...] = (
    "time_s", "method", "x_m", "y_m", "z_m", "vx_mps", "vy_mps", "vz_mps",
    *(f"p_{_ORDER6[i]}{_ORDER6[j]}" for i, j in _COV_PAIRS),
)
#: 6-vector index → index in the 2D CV state (x, ẋ, y, ẏ), or None (z, vz: zero).
_TO_CV = {0: 0, 1: 2, 2: None, 3: 1, 4: 3, 5: None}


@dataclass(frozen=True)
class Radar:
    name: str
    x_m: float
    y_m: float
    z_m: float
    sigma_range_m: float
    sigma_azimuth_deg: float


# --------------------------------------------------------------------------------------------
# Parsing and validation (pure: text in, values or one-line ParameterError out)
# --------------------------------------------------------------------------------------------


def _bad(where: str, column: str, what: str, got: object) -> ParameterError:
    return ParameterError(f"{where}, column {column}: {what} (got {got!r})")


def parse_radars(text: str, source: str) -> dict[str, Radar]:
    """Radars from TOML text; errors name ``source``, the radar and the key."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError(f"{source}: not valid TOML: {exc}") from None
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
        for key in table:
            if key not in RADAR_KEYS + OPTIONAL_RADAR_KEYS:
                raise ParameterError(
                    f"{where}, key {key}: unknown key (expected {', '.join(RADAR_KEYS)})"
                )
        vals = {}
        for key in RADAR_KEYS + OPTIONAL_RADAR_KEYS:
            if key not in table:
                if key in RADAR_KEYS:
                    raise ParameterError(f"{where}, key {key}: missing")
                continue
            v = table[key]
            if key.startswith("sigma_"):
                high = MAX_SIGMA_BETA_DEG if key == "sigma_azimuth_deg" else None
                rng = f"in (0, {high:g}]" if high else "> 0"
                ok = _is_real(v) and math.isfinite(v) and 0 < v and (high is None or v <= high)
            else:
                rng, ok = "", _is_real(v) and math.isfinite(v)
            if not ok:
                raise ParameterError(
                    f"{where}, key {key}: must be a finite number {rng}".rstrip() + f" (got {v!r})"
                )
            vals[key] = float(v)
        radars[name] = Radar(name, *(vals[k] for k in RADAR_KEYS))
    return radars


def _is_real(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _number(text: str) -> float | None:
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def read_plots(
    lines: IO[str], source: str, radars: dict[str, Radar]
) -> Iterator[tuple[Radar, Plot2D]]:
    """Validated plots of a measurement CSV, one at a time (bounded memory).

    Raises ``ParameterError`` "SOURCE line L, column C: …" at the first bad value.
    """
    reader = csv.reader(lines)
    try:
        header = next(reader, None)
    except UnicodeDecodeError:
        raise ParameterError(f"{source} line 1: not UTF-8 text") from None
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
    idx = {h: i for i, h in enumerate(header)}
    last_t = -math.inf
    count = 0
    while True:
        try:
            row = next(reader, None)
        except UnicodeDecodeError:
            raise ParameterError(f"{source} line {reader.line_num + 1}: not UTF-8 text") from None
        except csv.Error as exc:
            raise ParameterError(f"{source} line {reader.line_num}: {exc}") from None
        if row is None:
            break
        line = reader.line_num
        where = f"{source} line {line}"
        if not row or (len(row) == 1 and not row[0].strip()):
            continue  # blank line
        if len(row) != len(header):
            raise ParameterError(f"{where}: expected {len(header)} fields, got {len(row)}")
        t_text = row[idx["time_s"]]
        t = _number(t_text)
        if t is None:
            raise _bad(where, "time_s", "must be a finite number", t_text)
        if t < last_t:
            raise _bad(where, "time_s", f"must not be before the previous time {last_t!r}",
                       t_text)
        name = row[idx["radar"]].strip()
        radar = radars.get(name)
        if radar is None:
            raise _bad(where, "radar", f"unknown radar (known: {', '.join(radars)})", name)
        r_text = row[idx["range_m"]]
        r = _number(r_text)
        if r is None or r <= 0:
            raise _bad(where, "range_m", "must be a finite number > 0", r_text)
        a_text = row[idx["azimuth_deg"]]
        az = _number(a_text)
        if az is None or abs(az) > 360:
            raise _bad(where, "azimuth_deg", "must be a finite number in [-360, 360]", a_text)
        if "elevation_deg" in idx:
            e_text = row[idx["elevation_deg"]]
            e = _number(e_text)
            if e is None or abs(e) > 90:
                raise _bad(where, "elevation_deg", "must be a finite number in [-90, 90]",
                           e_text)
        if "radial_velocity_mps" in idx:
            v_text = row[idx["radial_velocity_mps"]]
            if _number(v_text) is None:
                raise _bad(where, "radial_velocity_mps", "must be a finite number", v_text)
        last_t = t
        count += 1
        yield radar, Plot2D(
            t, r, math.radians(az), radar.sigma_range_m, math.radians(radar.sigma_azimuth_deg),
            radar.x_m, radar.y_m,
        )
    if count == 0:
        raise ParameterError(f"{source}: no plots after the header")


def track_row(time_s: float, method: str, x: NDArray[np.float64], P: NDArray[np.float64]) -> list:
    """One output row from a 2D state x (4,) and P (4, 4)."""
    vec = [float(x[_TO_CV[k]]) if _TO_CV[k] is not None else 0.0 for k in range(6)]
    cov = []
    for i, j in _COV_PAIRS:
        a, b = _TO_CV[i], _TO_CV[j]
        cov.append(0.0 if a is None or b is None else float(P[a, b]))
    return [time_s, method, *vec, *cov]


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


@contextmanager
def atomic_text(path: str | os.PathLike) -> Iterator[IO[str]]:
    """A text file written beside ``path`` and renamed onto it on success, deleted on error."""
    target = Path(path)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.",
                               suffix=".tmp")
    try:
        umask = os.umask(0o022)
        os.umask(umask)
        os.chmod(fd, 0o666 & ~umask)  # mkstemp makes 0600; give the usual permissions
        with os.fdopen(fd, "w", newline="", encoding="utf-8") as fh:
            yield fh
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_radars(path: str) -> dict[str, Radar]:
    try:
        text = Path(path).read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        raise ParameterError(f"{path}: not UTF-8 text") from None
    return parse_radars(text, path)


def run_track(
    input_path: str,
    radars_path: str,
    out_path: str,
    methods: tuple[str, ...] = ALL_METHODS,
    sigma_a_mps2: float = 0.0,
    sigma_v0_mps: float = 1000.0,
) -> int:
    """Track every plot of ``input_path`` with every method into ``out_path``; returns plots."""
    if not methods:
        raise ParameterError(f"--method must name at least one of {', '.join(ALL_METHODS)}")
    for m in methods:
        check_choice("--method", m, ALL_METHODS)
    radars = load_radars(radars_path)
    tracks = [MethodTrack(g, sigma_a_mps2, sigma_v0_mps) for g in track_groups(methods)]
    # Where each method's row comes from: (group, run in the group's batch).
    where = {m: (k, i) for k, tr in enumerate(tracks) for i, m in enumerate(tr.methods)}
    plots = 0
    with open(input_path, newline="", encoding="utf-8-sig") as src, atomic_text(out_path) as out:
        w = csv.writer(out)
        w.writerow(TRACK_COLUMNS)
        for _radar, plot in read_plots(src, input_path, radars):
            states = [tr.add(plot) for tr in tracks]
            for m in methods:
                k, i = where[m]
                w.writerow(track_row(plot.time_s, m, states[k].x[i], states[k].P[i]))
            plots += 1
    return plots


def write_simulation(meas_path: str, radars_path: str, seed: int = 1,
                     sigma_beta_deg: float = 1.0) -> int:
    """The Prosov scenario's one run as a measurement file and its radars file (both atomic)."""
    times, r_hat, b_hat, cfg = prosov_single_run(seed, sigma_beta_deg)
    radar_toml = (
        "[radars.radar]\nx_m = 0.0\ny_m = 0.0\nz_m = 0.0\n"
        f"sigma_range_m = {cfg.sigma_r_m!r}\nsigma_azimuth_deg = {cfg.sigma_beta_deg!r}\n"
    )
    with atomic_text(meas_path) as fh, atomic_text(radars_path) as rh:
        w = csv.writer(fh)
        w.writerow(REQUIRED_COLUMNS)
        for t, r, b in zip(times, r_hat[0], b_hat[0], strict=True):
            w.writerow([float(t), "radar", float(r), math.degrees(float(b))])
        rh.write(radar_toml)
    return len(times)


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------


def _float_arg(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None


def add_commands(sub: argparse._SubParsersAction) -> None:
    """Register ``track`` and ``simulate`` on the ``radarviz`` parser."""
    tr = sub.add_parser("track", help="track a measurement CSV file into a track CSV file")
    tr.add_argument("--input", required=True, metavar="MEAS.csv", help="measurement CSV")
    tr.add_argument("--radars", required=True, metavar="RADARS.toml", help="radar sites, σ")
    tr.add_argument("--method", nargs="+", default=list(ALL_METHODS), metavar="METHOD",
                    help=f"methods (default all: {' '.join(ALL_METHODS)})")
    tr.add_argument("--out", default=DEFAULT_TRACKS,
                    help=f"track CSV to write, replaced if it exists (default {DEFAULT_TRACKS})")
    tr.add_argument("--sigma-a", type=_float_arg, default=0.0,
                    help="process-noise acceleration std, m/s² (default 0)")
    tr.add_argument("--sigma-v0", type=_float_arg, default=1000.0,
                    help="initial velocity std, m/s (default 1000)")

    sim = sub.add_parser("simulate", help="write a preset's measurements and radars files")
    sim.add_argument("--preset", required=True, help=f"one of {', '.join(SIM_PRESETS)}")
    sim.add_argument("--out", required=True, metavar="MEAS.csv", help="measurement CSV to write")
    sim.add_argument("--radars-out", required=True, metavar="RADARS.toml",
                     help="radars TOML to write")
    sim.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    sim.add_argument("--sigma-beta-deg", type=_float_arg, default=1.0,
                     help="azimuth noise σβ, degrees (default 1)")


def cmd_track(args: argparse.Namespace) -> int:
    check_real("--sigma-a", args.sigma_a, low=0.0, low_open=False)
    check_real("--sigma-v0", args.sigma_v0, low=0.0)
    plots = run_track(args.input, args.radars, args.out, tuple(args.method),
                      args.sigma_a, args.sigma_v0)
    print(f"tracked {plots} plots with {len(args.method)} method(s) into {args.out}")
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    check_choice("--preset", args.preset, SIM_PRESETS)
    check_int("--seed", args.seed, low=0)
    check_real("--sigma-beta-deg", args.sigma_beta_deg, low=0.0, high=MAX_SIGMA_BETA_DEG)
    n = write_simulation(args.out, args.radars_out, args.seed, args.sigma_beta_deg)
    print(f"wrote {n} plots to {args.out} and the radar to {args.radars_out}")
    return 0


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "track": cmd_track,
    "simulate": cmd_simulate,
}
