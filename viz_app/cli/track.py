"""``radarviz track`` and ``radarviz simulate``: the flags and the two commands.

The work is in ``viz_app.io.plots`` (files in, tracks out); this module only turns flags into
its arguments. ``--rrd`` hands ``run_track`` a Rerun recorder, so the Rerun SDK is imported
only by a ``track --rrd`` run, never by ``simulate`` or a plain ``track``.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterable
from contextlib import AbstractContextManager

from radarviz.core.params import check_choice
from radarviz.core.tracking.stream import INIT_MODES, METHODS_3D, StreamOptions
from radarviz.viz_app.cli.args import integer
from radarviz.viz_app.cli.params import add_parameter, map_flag
from radarviz.viz_app.io.atomic import check_outputs
from radarviz.viz_app.io.plots import (
    DEFAULT_TRACKS,
    DOPPLER_MODES,
    MAX_SIMULATE_STEPS,
    SIM_PRESETS,
    ObserverFactory,
    Radar,
    RowObserver,
    run_track,
    simulated_plots,
    write_measurements,
)
from radarviz.viz_app.runtime import peak_rss_mb


def add_commands(sub: argparse._SubParsersAction) -> None:
    """Register ``track`` and ``simulate`` on the ``radarviz`` parser."""
    tr = sub.add_parser("track", help="track a measurement CSV file into a track CSV file")
    tr.add_argument("--input", required=True, metavar="MEAS.csv", help="measurement CSV")
    tr.add_argument("--radars", required=True, metavar="RADARS.toml", help="radar sites, σ")
    tr.add_argument(
        "--method",
        nargs="+",
        default=None,
        metavar="METHOD",
        help=f"methods, 2D or 3D plots alike (default all: {' '.join(METHODS_3D)})",
    )
    tr.add_argument(
        "--out",
        default=DEFAULT_TRACKS,
        help=f"track CSV to write, replaced if it exists (default {DEFAULT_TRACKS})",
    )
    tr.add_argument(
        "--rrd",
        default=None,
        metavar="OUT.rrd",
        help="also write a Rerun recording of the plots and tracks (replaced)",
    )
    tr.add_argument(
        "--init",
        default="first-plot",
        metavar="MODE",
        help=f"track start: {' or '.join(INIT_MODES)} (default first-plot)",
    )
    map_flag(tr, "init", "--init")
    tr.add_argument(
        "--init-k",
        type=integer,
        default=3,
        help="plots in the finite-memory start window (default 3)",
    )
    map_flag(tr, "init_k", "--init-k")
    tr.add_argument(
        "--doppler",
        default="use",
        metavar="MODE",
        help="radial velocities: use (line-of-sight update), converted (the r̂·V̂r"
        " pseudo-measurement) or ignore (default use)",
    )
    add_parameter(tr, "sigma_a_mps2", "--sigma-a", "--sigma-a-mps2")
    add_parameter(tr, "sigma_v0_mps", "--sigma-v0", "--sigma-v0-mps")

    sim = sub.add_parser("simulate", help="write a preset's measurements and radars files")
    sim.add_argument(
        "--preset",
        required=True,
        help="prosov (one 2D radar, the Prosov run) or fusion (three 3D radars with Doppler)",
    )
    map_flag(sim, "preset", "--preset")
    sim.add_argument("--out", required=True, metavar="MEAS.csv", help="measurement CSV to write")
    sim.add_argument(
        "--radars-out", required=True, metavar="RADARS.toml", help="radars TOML to write"
    )
    add_parameter(sim, "seed")
    add_parameter(sim, "sigma_beta_deg", note="prosov")
    add_parameter(
        sim, "steps", "--scans", "--steps", high=MAX_SIMULATE_STEPS, note="fusion: per radar"
    )


def _recorder(path: str) -> ObserverFactory:
    """A factory of the Rerun recorder writing ``path`` (Rerun is imported when it is called)."""

    def factory(radars: Iterable[Radar]) -> AbstractContextManager[RowObserver]:
        from radarviz.viz_app.rerun.track_recording import TrackRecorder

        return TrackRecorder.to_file(path, radars)

    return factory


def cmd_track(args: argparse.Namespace) -> int:
    check_outputs(
        [("--out", args.out), ("--rrd", args.rrd)],
        [("--input", args.input), ("--radars", args.radars)],
    )
    options = StreamOptions(
        sigma_a_mps2=args.sigma_a_mps2,
        sigma_v0_mps=args.sigma_v0_mps,
        use_doppler=check_choice("--doppler", args.doppler, DOPPLER_MODES) != "ignore",
        doppler_update="converted" if args.doppler == "converted" else "line_of_sight",
        init=args.init,
        init_k=args.init_k,
    )
    methods = None if args.method is None else tuple(args.method)
    observer = None if args.rrd is None else _recorder(args.rrd)
    s = run_track(args.input, args.radars, args.out, methods, options, observer)
    rate = s.plots / s.seconds if s.seconds > 0 else math.inf
    extra = f" and {args.rrd}" if args.rrd else ""
    print(
        f"tracked {s.plots} plots ({'3D' if s.three_d else '2D'}) with {len(s.methods)} "
        f"method(s) into {args.out}{extra}: {s.rows} rows, {s.seconds:.2f} s, "
        f"{rate:.0f} plots/s, peak RSS {peak_rss_mb():.0f} MB"
    )
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    check_choice("--preset", args.preset, SIM_PRESETS)
    check_outputs([("--out", args.out), ("--radars-out", args.radars_out)])
    plots, radars = simulated_plots(args.preset, args.seed, args.sigma_beta_deg, args.steps)
    n = write_measurements(args.out, args.radars_out, plots, radars)
    print(f"wrote {n} plots to {args.out} and {len(radars)} radar(s) to {args.radars_out}")
    return 0


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "track": cmd_track,
    "simulate": cmd_simulate,
}
