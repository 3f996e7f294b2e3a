"""``radarviz track`` and ``radarviz simulate``: the flags and the two commands.

The work is in ``viz_app.io.plots`` (files in, tracks out); this module only turns flags into
its arguments. ``--rrd`` hands ``run_track`` a Rerun recorder, so the Rerun SDK is imported
only by a ``track --rrd`` run, never by ``simulate`` or a plain ``track``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Iterable
from contextlib import AbstractContextManager

from radarviz.core.filters.models import DEFAULT_IMM
from radarviz.core.params import ParameterError, check, check_choice, default
from radarviz.core.tracking.consistency import ConsistencyMonitor
from radarviz.core.tracking.stream import INIT_MODES, METHODS_3D, StreamOptions
from radarviz.viz_app.cli.args import integer, number
from radarviz.viz_app.cli.params import add_parameter, map_flag
from radarviz.viz_app.cli.presets import ALL_PRESETS, FLIGHT_NAMES, manoeuvre_file_plots
from radarviz.viz_app.io.atomic import atomic_write, check_outputs
from radarviz.viz_app.io.plot_blocks import run_track
from radarviz.viz_app.io.plots import (
    DEFAULT_TRACKS,
    DOPPLER_MODES,
    MAX_SIMULATE_STEPS,
    ObserverFactory,
    Radar,
    RowObserver,
    simulated_plots,
    write_measurements,
)
from radarviz.viz_app.reports.consistency import (
    exit_warner,
    inconsistency_lines,
    track_summary_document,
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
    map_flag(tr, "method", "--method")
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
    tr.add_argument(
        "--model",
        default=None,
        metavar="MODEL",
        help="motion model: imm (the default: an IMM of a quiet and a manoeuvre model, "
        "consistent on manoeuvring aircraft) or cv (constant velocity with --sigma-a; the "
        "default when --sigma-a is given; --model cv --sigma-a 0 is the papers' Q = 0)",
    )
    map_flag(tr, "model", "--model")
    add_parameter(
        tr,
        "sigma_a_mps2",
        "--sigma-a",
        "--sigma-a-mps2",
        default=None,
        shown_default=0.0,
        note="cv model",
    )
    add_parameter(
        tr,
        "imm_sigma_a_mps2",
        "--imm-sigma-a",
        nargs="+",
        default=None,
        shown_default=list(DEFAULT_IMM.sigma_a_mps2),
        note="one per IMM model",
    )
    tr.add_argument(
        "--imm-transition",
        nargs="+",
        type=number,
        default=None,
        metavar="P",
        help="the IMM's transition probabilities per update, row by row (r × r numbers for r "
        "models, each in (0, 1), rows summing to 1; default "
        + " ".join(f"{p:g}" for row in DEFAULT_IMM.transition for p in row)
        + ")",
    )
    map_flag(tr, "transition_prob", "--imm-transition")
    add_parameter(tr, "nis_window", "--nis-window")
    tr.add_argument(
        "--finite-memory",
        type=integer,
        default=0,
        metavar="K",
        help="also a sliding-window finite-memory track over the last K plots of the first "
        "radar (rows named finite-memory; 0: none, the default)",
    )
    map_flag(tr, "finite_memory_k", "--finite-memory")
    add_parameter(tr, "sigma_v0_mps", "--sigma-v0", "--sigma-v0-mps")
    tr.add_argument(
        "--summary",
        default=None,
        metavar="SUMMARY.json",
        help="also write the consistency summary (per track: time outside the NIS band) as JSON",
    )
    tr.add_argument(
        "--json", action="store_true", help="print the consistency summary as JSON on stdout"
    )

    sim = sub.add_parser("simulate", help="write a preset's measurements and radars files")
    sim.add_argument(
        "--preset",
        required=True,
        help="prosov (one 2D radar, the Prosov run), fusion (three 3D radars with Doppler) or "
        "manoeuvre (a manoeuvring aircraft seen by three 3D radars, one with Doppler)",
    )
    map_flag(sim, "preset", "--preset")
    sim.add_argument(
        "--flight",
        default=FLIGHT_NAMES[0],
        metavar="NAME",
        help=f"manoeuvre: the flight, one of {', '.join(FLIGHT_NAMES)} (default {FLIGHT_NAMES[0]})",
    )
    map_flag(sim, "flight", "--flight")
    sim.add_argument("--out", required=True, metavar="MEAS.csv", help="measurement CSV to write")
    sim.add_argument(
        "--radars-out", required=True, metavar="RADARS.toml", help="radars TOML to write"
    )
    add_parameter(sim, "seed")
    add_parameter(sim, "sigma_beta_deg", note="prosov")
    add_parameter(
        sim,
        "steps",
        "--scans",
        "--steps",
        default=None,
        shown_default=f"{default('steps')} (manoeuvre: the whole flight, 241)",
        high=MAX_SIMULATE_STEPS,
        note="fusion and manoeuvre: per radar",
    )


def _recorder(path: str, monitor: ConsistencyMonitor | None = None) -> ObserverFactory:
    """A factory of the Rerun recorder writing ``path`` (Rerun is imported when it is called);
    ``monitor``'s band exits go to the recording's log."""

    def factory(radars: Iterable[Radar]) -> AbstractContextManager[RowObserver]:
        from radarviz.viz_app.rerun.track_recording import TrackRecorder

        return TrackRecorder.to_file(path, radars, monitor=monitor)

    return factory


def _warn(text: str) -> None:
    print(f"radarviz: warning: {text}", file=sys.stderr)


def _motion_options(args: argparse.Namespace) -> dict:
    """The motion-model fields of ``StreamOptions`` from the flags (checked by it)."""
    model = args.model
    if model is None:
        model = "cv" if args.sigma_a_mps2 is not None else "imm"
    # A flag of the other model would be ignored without a word: refuse it instead.
    if model == "imm" and args.sigma_a_mps2 is not None:
        raise ParameterError("--sigma-a is the cv model's; with --model imm use --imm-sigma-a")
    if model == "cv":
        for flag, value in (
            ("--imm-sigma-a", args.imm_sigma_a_mps2),
            ("--imm-transition", args.imm_transition),
        ):
            if value is not None:
                raise ParameterError(f"{flag} is the imm model's; it needs --model imm")
    sigmas = tuple(
        DEFAULT_IMM.sigma_a_mps2 if args.imm_sigma_a_mps2 is None else args.imm_sigma_a_mps2
    )
    transition = DEFAULT_IMM.transition
    if args.imm_transition is not None:
        r = len(sigmas)
        if len(args.imm_transition) != r * r:
            raise ParameterError(
                f"--imm-transition must give {r * r} probabilities ({r} rows of {r}, one per "
                f"model of --imm-sigma-a) (got {len(args.imm_transition)})"
            )
        values = tuple(args.imm_transition)
        transition = tuple(values[i * r : (i + 1) * r] for i in range(r))
    return {
        "model": model,
        "sigma_a_mps2": 0.0 if args.sigma_a_mps2 is None else args.sigma_a_mps2,
        "imm_sigma_a_mps2": sigmas,
        "transition_prob": transition,
    }


def cmd_track(args: argparse.Namespace) -> int:
    check_outputs(
        [("--out", args.out), ("--rrd", args.rrd), ("--summary", args.summary)],
        [("--input", args.input), ("--radars", args.radars)],
    )
    monitor = ConsistencyMonitor(args.nis_window, on_event=exit_warner(_warn))
    options = StreamOptions(
        sigma_v0_mps=args.sigma_v0_mps,
        use_doppler=check_choice("--doppler", args.doppler, DOPPLER_MODES) != "ignore",
        init=args.init,
        init_k=args.init_k,
        finite_memory_k=args.finite_memory,
        monitor=monitor,
        **_motion_options(args),
    )
    methods = None if args.method is None else tuple(args.method)
    observer = None if args.rrd is None else _recorder(args.rrd, monitor)
    s = run_track(args.input, args.radars, args.out, methods, options, observer)
    doc = track_summary_document(
        monitor,
        options,
        input_path=args.input,
        plots=s.plots,
        rows=s.rows,
        three_d=s.three_d,
        methods=s.methods,
        targets=s.targets,
    )
    if args.summary:
        with atomic_write(args.summary, "w", encoding="utf-8") as fh:
            json.dump(doc, fh, allow_nan=False, indent=1)
            fh.write("\n")
    for line in inconsistency_lines(doc):
        _warn(line)
    if args.json:
        json.dump(doc, sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
        return 0
    rate = s.plots / s.seconds if s.seconds > 0 else math.inf
    extra = f" and {args.rrd}" if args.rrd else ""
    extra += f" and {args.summary}" if args.summary else ""
    bad = doc["inconsistent_tracks"]
    of = f" of {len(s.targets)} targets" if s.targets else ""
    print(
        f"tracked {s.plots} plots{of} ({'3D' if s.three_d else '2D'}) with {len(s.methods)} "
        f"method(s), model {options.model}, into {args.out}{extra}: {s.rows} rows, "
        f"{s.seconds:.2f} s, {rate:.0f} plots/s, peak RSS {peak_rss_mb():.0f} MB; "
        + (_inconsistent(bad, len(doc["tracks"])) if bad else "every track within its NIS band")
    )
    return 0


#: Inconsistent tracks named in the summary line; more are counted (the summary names all).
MAX_NAMED_TRACKS = 10


def _inconsistent(bad: list[str], tracks: int) -> str:
    if len(bad) <= MAX_NAMED_TRACKS:
        return f"inconsistent: {', '.join(bad)}"
    return f"inconsistent: {len(bad)} of {tracks} tracks (each named in --summary)"


def cmd_simulate(args: argparse.Namespace) -> int:
    check_choice("--preset", args.preset, ALL_PRESETS)
    check_outputs([("--out", args.out), ("--radars-out", args.radars_out)])
    if args.preset == "manoeuvre":
        check("sigma_beta_deg", args.sigma_beta_deg)
        check_choice("flight", args.flight, FLIGHT_NAMES)
        if args.steps is not None:
            check("steps", args.steps, high=MAX_SIMULATE_STEPS)
        plots, radars = manoeuvre_file_plots(args.flight, args.seed, args.steps)
    else:
        steps = default("steps") if args.steps is None else args.steps
        plots, radars = simulated_plots(args.preset, args.seed, args.sigma_beta_deg, steps)
    n = write_measurements(args.out, args.radars_out, plots, radars)
    print(f"wrote {n} plots to {args.out} and {len(radars)} radar(s) to {args.radars_out}")
    return 0


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "track": cmd_track,
    "simulate": cmd_simulate,
}
