"""``radarviz track`` and ``radarviz simulate``: the flags and the two commands.

The work is in ``viz_app.io.plots`` (files in, tracks out); this module only turns flags into
its arguments. ``--rrd`` hands ``run_track`` a Rerun recorder, so the Rerun SDK is imported
only by a ``track --rrd`` run, never by ``simulate`` or a plain ``track``.
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import sys
from collections.abc import Callable, Iterable
from contextlib import AbstractContextManager

from radarviz.core.filters.methods import METHODS_3D
from radarviz.core.filters.models import DEFAULT_IMM
from radarviz.core.params import ParameterError, check, check_choice, default, parameter
from radarviz.core.scenarios.crossing import CrossingScene
from radarviz.core.tracking.association import ASSOCIATE_MODES, AssociationOptions
from radarviz.core.tracking.consistency import ConsistencyMonitor
from radarviz.core.tracking.scoring import Truth
from radarviz.core.tracking.stream import (
    INIT_MODES,
    Plot,
    StreamOptions,
    motion_fields,
)
from radarviz.viz_app.cli.args import integer, number
from radarviz.viz_app.cli.commands import Registrar
from radarviz.viz_app.cli.params import add_parameter, map_flag, parameter_flags
from radarviz.viz_app.cli.presets import (
    ALL_PRESETS,
    FLIGHT_NAMES,
    crossing_file_plots,
    manoeuvre_file_plots,
    write_crossing_truth,
)
from radarviz.viz_app.io.atomic import atomic_write, check_outputs, commit_together
from radarviz.viz_app.io.plot_blocks import run_track
from radarviz.viz_app.io.plots import (
    DEFAULT_TRACKS,
    DOPPLER_MODES,
    MAX_SIMULATE_STEPS,
    ObserverFactory,
    Radar,
    RowObserver,
    output_format_of,
    simulated_plots,
    write_measurements,
)
from radarviz.viz_app.reports.consistency import (
    exit_warner,
    inconsistency_lines,
    track_summary_document,
)
from radarviz.viz_app.reports.plot_account import (
    association_document,
    association_lines,
    untracked_warning,
)
from radarviz.viz_app.runtime import peak_rss_mb


def add_commands(sub: Registrar) -> None:
    """Register ``track`` and ``simulate`` on the ``radarviz`` parser."""
    tr = sub.add_parser("track")
    tr.add_argument(
        "--input",
        required=True,
        metavar="MEAS",
        help="measurement file: CSV, ASTERIX CAT048 (.ast), or a pcap/pcapng capture of it",
    )
    tr.add_argument(
        "--format",
        default="auto",
        metavar="FORMAT",
        help="the input's format: csv, asterix (CAT048 target reports; radars need sac and "
        "sic), pcap (a pcap or pcapng capture of ASTERIX over UDP) or auto (the default: a "
        "capture by its magic or .pcap/.pcapng; .ast and .asterix are ASTERIX; else CSV)",
    )
    map_flag(tr, "format", "--format")
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
        help="track file to write, replaced if it exists: Parquet if its name ends in "
        f".parquet (the CSV's columns and float64 values, a row group per block), else CSV "
        f"(default {DEFAULT_TRACKS})",
    )
    tr.add_argument(
        "--rrd",
        default=None,
        metavar="OUT.rrd",
        help="also write a Rerun recording of the plots and tracks (replaced)",
    )
    tr.add_argument(
        "--truth",
        default=None,
        metavar="TRUTH.csv",
        help="the truth, drawn in the --rrd recording (needs --rrd): CSV or Parquet with "
        "time_s, target, x_m, y_m [, z_m] (simulate --truth-out writes one)",
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
        help="radial velocities: use (the update along the measured line of sight), "
        "converted (the r̂·V̂r pseudo-measurement) or ignore (default use)",
    )
    tr.add_argument(
        "--model",
        default=None,
        metavar="MODEL",
        help="motion model: imm (the default: an IMM of a quiet, two turning and a manoeuvre "
        "model, consistent on manoeuvring aircraft) or cv (constant velocity with --sigma-a; the "
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
    add_parameter(
        tr,
        "imm_turn_rate_degps",
        "--imm-turn-rate",
        nargs="+",
        default=None,
        shown_default=list(DEFAULT_IMM.turn_rate_degps or ()),
        note="one per IMM model, 0 constant velocity; all 0 when --imm-sigma-a is given alone",
    )
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
    _add_association_flags(tr)

    sim = sub.add_parser("simulate")
    sim.add_argument(
        "--preset",
        required=True,
        help="prosov (one 2D radar, the Prosov run), fusion (three 3D radars with Doppler), "
        "manoeuvre (a manoeuvring aircraft seen by three 3D radars, one with Doppler) or "
        "crossing (crossing targets in clutter, P_D < 1, unlabelled plots of one 2D radar: "
        "for track --associate gnn)",
    )
    map_flag(sim, "preset", "--preset")
    sim.add_argument(
        "--flight",
        default=FLIGHT_NAMES[0],
        metavar="NAME",
        help=f"manoeuvre: the flight, one of {', '.join(FLIGHT_NAMES)} (default {FLIGHT_NAMES[0]})",
    )
    map_flag(sim, "flight", "--flight")
    sim.add_argument(
        "--out", required=True, metavar="MEAS", help="measurement file to write (CSV or .ast)"
    )
    sim.add_argument(
        "--format",
        default="auto",
        metavar="FORMAT",
        help="the output's format: csv, asterix (CAT048, at the items' resolution; the radars "
        "get sac 0 and sic 1, 2, …) or auto (by suffix; the default)",
    )
    map_flag(sim, "format", "--format")
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
        note="fusion and manoeuvre: per radar; crossing: 40",
    )
    add_crossing_flags(sim, given_only=True)
    sim.add_argument(
        "--truth-out",
        default=None,
        metavar="TRUTH.csv",
        help="crossing: also write the true states per scan and target (time_s, target, x_m, "
        "y_m, vx_mps, vy_mps)",
    )


#: The crossing scene's table parameters and their flags.
CROSSING_FLAGS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("crossing_targets", ("--targets",)),
    ("crossing_angle_deg", ("--crossing-angle-deg",)),
    ("detection_prob", ("--pd", "--detection-prob")),
    ("clutter_per_scan", ("--clutter-per-scan",)),
)


def add_crossing_flags(parser: argparse.ArgumentParser, given_only: bool = False) -> None:
    """The crossing scene's flags (``simulate --preset crossing``, ``reproduce association``);
    ``given_only``: None unless given (``simulate`` refuses them for another preset)."""
    for name, flags in CROSSING_FLAGS:
        if given_only:
            add_parameter(
                parser, name, *flags, default=None, shown_default=default(name), note="crossing"
            )
        else:
            add_parameter(parser, name, *flags)


def crossing_scene(args: argparse.Namespace, scans: int | None) -> CrossingScene:
    """The crossing scene of the flags (checked by ``CrossingScene``; a flag not given: the
    table's default)."""
    kw = {name: getattr(args, name) for name, _ in CROSSING_FLAGS}
    kw = {k: v for k, v in kw.items() if v is not None}
    if scans is not None:
        kw["scans"] = scans
    return CrossingScene(
        **{("targets" if k == "crossing_targets" else k): v for k, v in kw.items()}
    )


#: The association's table parameters and their ``track`` flags (given only with --associate).
ASSOCIATION_FLAGS: tuple[tuple[str, str], ...] = (
    ("gate_probability", "--gate-probability"),
    ("confirm_m", "--confirm-m"),
    ("confirm_n", "--confirm-n"),
    ("delete_misses", "--delete-misses"),
    ("scan_window_s", "--scan-window-s"),
    ("batch_sector_deg", "--batch-sector-deg"),
    ("max_speed_mps", "--max-speed"),
)
#: The ones ``live`` takes: all but the scan window (a live feed is cut by radar and sector,
#: ``plot_batches``).
LIVE_ASSOCIATION_FLAGS = tuple((n, f) for n, f in ASSOCIATION_FLAGS if n != "scan_window_s")


def _add_association_flags(tr: argparse.ArgumentParser) -> None:
    """``track``'s association flags (``core.tracking.association``)."""
    tr.add_argument(
        "--associate",
        default="none",
        metavar="MODE",
        help="plots without a target column: none (one target, the default) or gnn (many "
        "targets and clutter: global-nearest-neighbour association, M-of-N confirmation; the "
        "track file's target column is the track id, status tentative or confirmed)",
    )
    map_flag(tr, "associate", "--associate")
    tr.add_argument(
        "--associate-method",
        default=None,
        metavar="METHOD",
        help="with --associate gnn: the method whose prediction gates the plots; every "
        "--method follows its assignment (default ucm)",
    )
    map_flag(tr, "associate_method", "--associate-method")
    for name, flag in ASSOCIATION_FLAGS:
        shown = parameter(name).default
        add_parameter(tr, name, flag, default=None, shown_default=shown, note="--associate gnn")


def association_options(args: argparse.Namespace) -> AssociationOptions | None:
    """The ``AssociationOptions`` of ``--associate gnn`` (checked there), or None; a flag of
    the association without it is refused rather than ignored."""
    mode = check_choice("associate", args.associate, ASSOCIATE_MODES)
    given = {name: getattr(args, name) for name, _ in ASSOCIATION_FLAGS}
    if mode == "none":
        for (_, flag), value in zip(ASSOCIATION_FLAGS, given.values(), strict=True):
            if value is not None:
                raise ParameterError(f"{flag} is the association's; it needs --associate gnn")
        if args.associate_method is not None:
            raise ParameterError("--associate-method needs --associate gnn")
        return None
    kw = {k: v for k, v in given.items() if v is not None}
    if args.associate_method is not None:
        kw["method"] = args.associate_method
    return AssociationOptions(**kw)


def _recorder(
    path: str, monitor: ConsistencyMonitor | None = None, truth: Truth | None = None
) -> ObserverFactory:
    """A factory of the Rerun recorder writing ``path`` (Rerun is imported when it is called);
    ``monitor``'s band exits go to the recording's log; ``truth`` is drawn in it."""

    def factory(radars: Iterable[Radar]) -> AbstractContextManager[RowObserver]:
        from radarviz.viz_app.rerun.track_recording import TrackRecorder

        return TrackRecorder.to_file(path, radars, monitor=monitor, truth=truth)

    return factory


def _warn(text: str) -> None:
    print(f"radarviz: warning: {text}", file=sys.stderr)


def _motion_options(args: argparse.Namespace) -> dict:
    """The motion-model fields of ``StreamOptions`` from the flags (``motion_fields``, the
    rule ``radarviz.track`` follows too; errors name the flags)."""
    return motion_fields(
        args.model,
        args.sigma_a_mps2,
        args.imm_sigma_a_mps2,
        args.imm_transition,
        args.imm_turn_rate_degps,
        names=parameter_flags(args),
    )


def cmd_track(args: argparse.Namespace) -> int:
    check_outputs(
        [("--out", args.out), ("--rrd", args.rrd), ("--summary", args.summary)],
        [("--input", args.input), ("--radars", args.radars)]
        + ([("--truth", args.truth)] if args.truth is not None else []),
    )
    truth = None
    if args.truth is not None:
        if args.rrd is None:
            raise ParameterError("--truth is drawn in the --rrd recording: give --rrd too")
        from radarviz.viz_app.io.score_files import read_truth

        truth = read_truth(args.truth)
    association = association_options(args)
    monitor = ConsistencyMonitor(args.nis_window, on_event=exit_warner(_warn))
    doppler_update = DOPPLER_MODES[check_choice("--doppler", args.doppler, DOPPLER_MODES)]
    options = StreamOptions(
        sigma_v0_mps=args.sigma_v0_mps,
        use_doppler=doppler_update is not None,
        doppler_update=doppler_update or "line_of_sight",
        init=args.init,
        init_k=args.init_k,
        finite_memory_k=args.finite_memory,
        monitor=monitor,
        **_motion_options(args),
    )
    methods = None if args.method is None else tuple(args.method)
    observer = None if args.rrd is None else _recorder(args.rrd, monitor, truth)
    from radarviz.viz_app.io.asterix import source_for

    open_source = source_for(args.input, args.format)
    import pyarrow as pa

    # pyarrow's default pool (jemalloc or mimalloc) keeps what the blocks free, so the peak
    # grew with the file's length; the system allocator hands it back.
    pa.set_memory_pool(pa.system_memory_pool())
    # What is loaded by now (numpy, numba, scipy, pyarrow, Rerun) lives to the end: frozen out
    # of the cycle collector's reach, its full passes walk only what the tracking makes (a
    # pass over every object of those modules took a fifth of the association's time).
    gc.collect()
    gc.freeze()
    # The track file, the recording and the summary change together or not at all: a summary
    # that cannot be written (a read-only directory, a full disk) leaves the track file as
    # it was (``commit_together``; ``run_track``'s own unit joins this one).
    with commit_together():
        s = run_track(
            args.input, args.radars, args.out, methods, options, observer, open_source, association
        )
        doc = track_summary_document(
            monitor,
            options,
            input_path=args.input,
            plots=s.plots,
            rows=s.rows,
            three_d=s.three_d,
            methods=s.methods,
            targets=s.targets,
            input_counts=s.input,
        )
        if s.association is not None:
            doc["association"] = association_document(s.association)
        if args.summary:
            with atomic_write(args.summary, "w", encoding="utf-8") as fh:
                json.dump(doc, fh, allow_nan=False, indent=1)
                fh.write("\n")
    if s.input is not None:
        from radarviz.viz_app.io.asterix import input_line

        print(f"radarviz: input: {input_line(args.input, s.input)}", file=sys.stderr)
    untracked = None
    if s.association is not None:
        for line in association_lines(s.association):
            print(f"radarviz: {line}", file=sys.stderr)
        untracked = untracked_warning(s.association)
        if untracked is not None:
            _warn(untracked)
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
    if association is not None:
        of = f" into {len(s.targets)} confirmed tracks (gnn, gate {association.method})"
    if bad:
        verdict = _inconsistent(bad, len(doc["tracks"]))
    elif untracked is not None:
        # The NIS of the tracks that exist says nothing of the plots no track took.
        verdict = "see the warning: too many plots outside confirmed tracks"
    else:
        verdict = "every track within its NIS band"
    print(
        f"tracked {s.plots} plots{of} ({'3D' if s.three_d else '2D'}) with {len(s.methods)} "
        f"method(s), model {options.model}, into {args.out}{extra}: {s.rows} rows, "
        f"{s.seconds:.2f} s, {rate:.0f} plots/s, peak RSS {peak_rss_mb():.0f} MB; " + verdict
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
    if args.preset != "crossing":
        extra = [("--truth-out", args.truth_out)] + [
            (flags[0], getattr(args, name)) for name, flags in CROSSING_FLAGS
        ]
        for flag, value in extra:
            if value is not None:
                raise ParameterError(f"{flag} is the crossing preset's (--preset crossing)")
    if args.preset == "prosov" and args.steps is not None:
        # The prosov preset is the paper's one run of 60 scans: --scans was ignored silently.
        raise ParameterError(
            f"--scans is not the prosov preset's (its run has {default('steps')} scans; "
            "--preset fusion, manoeuvre or crossing take --scans)"
        )
    fmt = output_format_of(args.out, args.format)
    check_outputs(
        [("--out", args.out), ("--radars-out", args.radars_out), ("--truth-out", args.truth_out)]
    )
    kind = " (ASTERIX CAT048)" if fmt == "asterix" else ""
    if args.preset == "crossing":
        check("sigma_beta_deg", args.sigma_beta_deg)  # the prosov preset's: checked, not used
        scene = crossing_scene(args, args.steps)
        plots, radars = crossing_file_plots(scene, args.seed)
        with commit_together():
            n = _write_plots(fmt, args.out, args.radars_out, plots, radars)
            if args.truth_out is not None:
                write_crossing_truth(args.truth_out, scene)
        extra = f" and the truth to {args.truth_out}" if args.truth_out else ""
        print(
            f"wrote {n} plots ({scene.targets} crossing targets at {scene.crossing_angle_deg:g}°, "
            f"P_D {scene.detection_prob:g}, {scene.clutter_per_scan:g} false plots per scan, "
            f"{scene.scans} scans) to {args.out}{kind} and 1 radar to {args.radars_out}{extra}"
        )
        return 0
    if args.preset == "manoeuvre":
        check("sigma_beta_deg", args.sigma_beta_deg)
        check_choice("flight", args.flight, FLIGHT_NAMES)
        if args.steps is not None:
            check("steps", args.steps, high=MAX_SIMULATE_STEPS)
        plots, radars = manoeuvre_file_plots(args.flight, args.seed, args.steps)
    else:
        steps = default("steps") if args.steps is None else args.steps
        plots, radars = simulated_plots(args.preset, args.seed, args.sigma_beta_deg, steps)
    n = _write_plots(fmt, args.out, args.radars_out, plots, radars)
    print(f"wrote {n} plots to {args.out}{kind} and {len(radars)} radar(s) to {args.radars_out}")
    return 0


def _write_plots(
    fmt: str, out: str, radars_out: str, plots: list[Plot], radars: list[Radar]
) -> int:
    """Write plots and their radars as a measurement CSV or an ASTERIX CAT048 file."""
    if fmt == "asterix":
        from radarviz.viz_app.io.asterix import write_asterix

        return write_asterix(out, radars_out, plots, radars)
    return write_measurements(out, radars_out, plots, radars)


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "track": cmd_track,
    "simulate": cmd_simulate,
}
