"""The ``radarviz`` command line.

Bad input gets one line on standard error naming the flag and its allowed range, and exit
status 2; no traceback. The flags of table parameters (σr, σβ, T, scans, runs, seed, …) are
built from ``core.params.PARAMETERS`` (``viz_app.cli.params.add_parameter``) and checked once,
by the core config that receives them; the ``ParameterError`` it raises names the parameter,
which is printed as the flag of this command. Outputs are checked before any work
(``viz_app.io.atomic.check_outputs``: not an input, not each other, not a special file); an
output that cannot be written is one line naming it, exit status 1, its previous file intact.
A result that is not finite (a NaN figure, a negative NEES or variance; ``core.finite``) is one
line naming where it appeared, exit status 1, and nothing is printed or written.

Only numpy-level modules are imported to build the parser: matplotlib, Rerun, Viser, Dask and
scipy.stats load when a command needs them (``tests/test_cli.py`` checks this). A command's
module is imported only when that command is run or asked for its ``--help``: ``radarviz
--help`` lists the commands from ``viz_app.cli.commands`` alone.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

from radarviz.core.filters.methods import ALL_METHODS
from radarviz.core.finite import ResultError, check_finite_document
from radarviz.core.params import ParameterError, check_int, check_real
from radarviz.viz_app.cli.args import integer, number, print_report
from radarviz.viz_app.cli.commands import COMMANDS, command_module, command_of
from radarviz.viz_app.cli.params import add_parameter, cli_message, map_flag
from radarviz.viz_app.io.atomic import WriteError
from radarviz_entry import EXIT_INTERRUPTED, STARTUP_INTERRUPTED

EXIT_USAGE = 2
#: The shell's status for a writer ended by SIGPIPE (128 + 13): standard output's reader
#: stopped reading (``radarviz track --json | head -c 5``), as for any command of a pipeline.
EXIT_PIPE = 141
#: Exit status when an output could not be written (``viz_app.io.atomic.WriteError``).
EXIT_WRITE = 1
#: Exit status when a computed result is not finite (``core.finite.ResultError``).
EXIT_RESULT = 1
#: Runs × cases above which a progress bar is drawn on standard error.
PROGRESS_MIN_RUNS = 20_000


class _Parser(argparse.ArgumentParser):
    """argparse, but errors are one line (no usage dump) and exit with status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"radarviz: error: {message}\n")


def _fail(message: str) -> int:
    print(f"radarviz: error: {message}", file=sys.stderr)
    return EXIT_USAGE


class _Registrar:
    """The subparsers action as a command module's ``add_commands`` sees it: the parser it
    asks for by name is the one already listed (with its help from ``COMMANDS``), or, for a
    command whose flags are not wanted, a parser of its own that nothing parses."""

    def __init__(self, parsers: dict[str, argparse.ArgumentParser], wanted: set[str]) -> None:
        self.parsers, self.wanted = parsers, wanted

    def add_parser(self, name: str, **settings: Any) -> argparse.ArgumentParser:
        if "help" in settings:
            raise TypeError(f"{name}: a command's help lives in viz_app.cli.commands.COMMANDS")
        parser = self.parsers[name] if name in self.wanted else _Parser(prog=name)
        for key, value in settings.items():  # description, epilog, …
            setattr(parser, key, value)
        return parser


def build_parser(flags_of: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``radarviz`` parser: every command listed with its help, and the flags of the
    commands ``flags_of`` (None: of every command; the others are parsed as no command)."""
    parser = _Parser(
        prog="radarviz",
        description="Radar target-tracking research: converted measurements, Doppler, fusion.",
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    parsers = {name: sub.add_parser(name, help=c.help) for name, c in COMMANDS.items()}
    wanted = set(COMMANDS) if flags_of is None else set(flags_of) & set(COMMANDS)
    registrar = _Registrar(parsers, wanted)
    for module in dict.fromkeys(command_module(name) for name in wanted):
        if module is not None:
            module.add_commands(registrar)
    if "reproduce" in wanted:
        _add_reproduce(parsers["reproduce"])
    if "tune" in wanted:
        _add_tune(parsers["tune"])
    if "bench" in wanted:
        _add_bench(parsers["bench"])
    return parser


def _add_reproduce(rep: argparse.ArgumentParser) -> None:
    rep_sub = rep.add_subparsers(dest="experiment", required=True, parser_class=_Parser)
    pro = rep_sub.add_parser(
        "prosov", help="converted-measurement Kalman filters (Prosov), Monte Carlo"
    )
    add_parameter(pro, "sigma_beta_deg", nargs="+", default=[1.0, 2.0], note="one case each")
    add_parameter(pro, "sigma_r_m")
    add_parameter(pro, "runs")
    add_parameter(pro, "seed")
    add_parameter(pro, "period_s", "--period", "--period-s")
    add_parameter(pro, "steps")
    map_flag(pro, "methods", "--methods")
    pro.add_argument(
        "--dims",
        type=int,
        choices=(2, 3),
        default=2,
        help="2: the paper's plane; 3: the same target at an elevation, every method in 3D",
    )
    add_parameter(pro, "target_elevation_deg", "--elevation-deg", note="with --dims 3")
    add_parameter(pro, "sigma_elevation_deg", default=1.0, shown_default=1.0, note="with --dims 3")
    pro.add_argument(
        "--methods",
        nargs="+",
        default=list(ALL_METHODS),
        metavar="METHOD",
        help=f"methods to run (default all: {' '.join(ALL_METHODS)})",
    )
    pro.add_argument(
        "--json", action="store_true", help="print only the JSON document on standard output"
    )
    pro.add_argument("--plot", metavar="FILE.png", help="write the figure (Figs. 1-2, bias, NEES)")

    dop = rep_sub.add_parser(
        "doppler",
        help="EKF + Doppler: the line-of-sight, converted (r̂·V̂r) and joint (correlated) "
        "updates, RLS1-RLS6",
    )
    dop.add_argument(
        "--radars",
        nargs="+",
        default=None,
        metavar="RLS",
        help="radar presets (default all: RLS1 ... RLS6)",
    )
    add_parameter(dop, "sigma_beta_deg")
    add_parameter(dop, "runs")
    add_parameter(dop, "seed")
    dop.add_argument(
        "--json", action="store_true", help="print only the JSON document on standard output"
    )
    dop.add_argument("--plot", metavar="FILE.png", help="write the figure (NEES per radar)")

    gor = rep_sub.add_parser(
        "gorshkov", help="finite-memory range / radial-velocity filter (Gorshkov), Monte Carlo"
    )
    add_parameter(gor, "trials", note="per radar")
    add_parameter(gor, "seed")
    gor.add_argument(
        "--radars",
        nargs="+",
        default=None,
        metavar="RLS",
        help="radar presets (default all: RLS1 … RLS6)",
    )
    for name in ("radars", "k_max", "tracking_radar", "tracking_runs"):
        map_flag(gor, name, "--" + name.replace("_", "-"))
    gor.add_argument(
        "--k-max",
        type=integer,
        default=20,
        help="largest window length k (default 20; the experiment has 20 scans)",
    )
    gor.add_argument(
        "--custom",
        nargs=3,
        type=number,
        metavar=("SIGMA_R_M", "C0", "PERIOD_S"),
        help="add a radar 'custom' with σr (m), C0 and T (s); σVr follows from "
        "C0 = σr² / (T² σVr²)",
    )
    gor.add_argument(
        "--tracking-radar",
        default="RLS3",
        help="preset of the Doppler-aided tracking comparison (default RLS3)",
    )
    gor.add_argument(
        "--tracking-runs",
        type=integer,
        default=1000,
        help="Monte Carlo runs of the tracking comparison (0 to skip; default 1000)",
    )
    add_parameter(gor, "sigma_beta_deg", note="of the tracking comparison")
    gor.add_argument(
        "--json", action="store_true", help="print only the JSON document on standard output"
    )
    gor.add_argument("--plot", metavar="FILE.png", help="write the figure (Figs. 1-3)")

    vel = rep_sub.add_parser(
        "velocity", help="3D velocity from the radial velocities of 3 radars, Monte Carlo"
    )
    add_parameter(
        vel, "trials", default=200_000, note="of the baseline; the sweep uses at most 20000 a point"
    )
    add_parameter(vel, "seed")
    vel.add_argument(
        "--json", action="store_true", help="print only the JSON document on standard output"
    )
    vel.add_argument(
        "--plot", metavar="FILE.png", help="write the figure (baseline σ and correlations, sweep)"
    )

    man = rep_sub.add_parser(
        "manoeuvre",
        help="manoeuvring aircraft: methods × motion models (Q = 0, σa = 1, IMM), Monte Carlo",
    )
    add_parameter(man, "runs", default=8, note="noise runs per flight, 6 flights")
    add_parameter(man, "seed")
    man.add_argument(
        "--straight-runs",
        type=integer,
        default=256,
        help="runs of the straight-line check, IMM against the matched filter (0: skip; "
        "default 256)",
    )
    man.add_argument(
        "--finite-memory",
        type=integer,
        default=5,
        metavar="K",
        help="window of the finite-memory tracks (0: skip them; default 5)",
    )
    man.add_argument(
        "--json", action="store_true", help="print only the JSON document on standard output"
    )

    _add_association(rep_sub)


def _add_tune(tune: argparse.ArgumentParser) -> None:
    tune.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to bind (default 127.0.0.1; anything else is exposed)",
    )
    tune.add_argument("--port", type=integer, default=0, help="panel port (default: a free one)")
    tune.add_argument(
        "--viewer-port", type=integer, default=0, help="web viewer port (default: a free one)"
    )
    tune.add_argument("--no-browser", action="store_true", help="do not open a browser")


def _add_bench(bench: argparse.ArgumentParser) -> None:
    bench.add_argument("--json", action="store_true", help="print only JSON")
    bench.add_argument(
        "--runs",
        type=integer,
        nargs="+",
        default=[10_000, 100_000],
        help="run counts to time the batched filter at (default 10000 100000)",
    )
    bench.add_argument(
        "--filterpy-runs",
        type=integer,
        default=200,
        help="runs of the filterpy subsample (default 200)",
    )
    bench.add_argument(
        "--device",
        choices=("cpu", "gpu"),
        default="cpu",
        help="cpu: the engines against filterpy (default); gpu: the array-API path on CuPy",
    )
    bench.add_argument(
        "--targets",
        type=integer,
        default=1000,
        help="targets of the many-target tracker figure (default 1000)",
    )
    bench.add_argument(
        "--asterix-plots",
        type=integer,
        default=20_000,
        help="plots of the ASTERIX reading and track figures (default 20000)",
    )
    bench.add_argument(
        "--asterix-targets",
        type=integer,
        default=200,
        help="targets of the ASTERIX track figure (default 200; I048/161 holds up to 4095)",
    )
    bench.add_argument(
        "--only",
        choices=("asterix", "association", "live", "tune"),
        default=None,
        help="run one section: asterix (ASTERIX CAT048 reading vs CSV, track end to end), "
        "association (GNN at --targets targets, sparse vs dense route), live (a feed "
        "replayed into radarviz live with its viewer: counts, latency) or tune (radarviz "
        "tune in headless Chromium: each scene's change to its first complete frame, median "
        "and spread over --tune-changes changes); default all but tune",
    )
    bench.add_argument(
        "--tune-changes",
        type=integer,
        default=5,
        help="with --only tune: changes timed per scene (default 5)",
    )
    bench.add_argument(
        "--live-rate",
        type=number,
        default=2000.0,
        help="plots/s of the live section's replay (default 2000)",
    )
    bench.add_argument(
        "--live-seconds",
        type=number,
        default=20.0,
        help="seconds of the live section's replay (default 20)",
    )
    bench.add_argument(
        "--live-soak-s",
        type=number,
        default=None,
        help="with --only live: a soak this long (e.g. 600) at --live-rate instead of "
        "--live-seconds, the live process's memory sampled and its trend per hour said "
        "(not in CI)",
    )
    bench.add_argument(
        "--live-targets",
        type=integer,
        default=300,
        help="targets of the live section's scene of four radars (default 300)",
    )
    bench.add_argument(
        "--track-plots",
        type=integer,
        default=1_000_000,
        help="plots of the radarviz track figure's air-traffic file (default 1000000)",
    )
    bench.add_argument(
        "--markdown",
        metavar="PAGE.md",
        default=None,
        help="also write the figures, the machine and the load average into PAGE.md between "
        "its marker comments (docs/performance.md holds them); the full CPU bench only",
    )


def _add_association(rep_sub: argparse._SubParsersAction) -> None:
    """``reproduce association``: its flags (the scene's and the association's from the
    parameter table)."""
    from radarviz.core.experiments.association import MAX_RUNS

    aso = rep_sub.add_parser(
        "association",
        help="GNN association of crossing targets in clutter: GOSPA, swaps, false tracks",
    )
    add_parameter(aso, "runs", default=20, high=MAX_RUNS)
    add_parameter(aso, "seed")
    add_parameter(aso, "steps", "--scans", default=40, note="per run")
    from radarviz.viz_app.cli import track  # its crossing and association flags

    track.add_crossing_flags(aso)
    for name, flag in track.ASSOCIATION_FLAGS[:-1]:  # one radar, one time per scan: no window
        add_parameter(aso, name, flag)
    add_parameter(aso, "gospa_cutoff_m", "--gospa-cutoff-m")
    add_parameter(aso, "gospa_order", "--gospa-order")
    add_parameter(aso, "sigma_a_mps2", "--sigma-a", default=1.0, note="cv model")
    add_parameter(aso, "sigma_v0_mps", "--sigma-v0", default=300.0)
    map_flag(aso, "methods", "--methods")
    aso.add_argument(
        "--methods",
        nargs="+",
        default=list(ALL_METHODS),
        metavar="METHOD",
        help=f"methods, each gating its own tracks (default all: {' '.join(ALL_METHODS)})",
    )
    aso.add_argument(
        "--json", action="store_true", help="print only the JSON document on standard output"
    )
    aso.add_argument(
        "--plot", metavar="FILE.png", help="write the figure (GOSPA per scan, parts, swaps)"
    )


def _cmd_reproduce_association(args: argparse.Namespace) -> int:
    from radarviz.core.experiments.association import AssociationConfig, run_association
    from radarviz.core.tracking.association import AssociationOptions
    from radarviz.viz_app.cli import track

    scene = track.crossing_scene(args, args.steps)
    cfg = AssociationConfig(
        scene=scene,
        runs=args.runs,
        seed=args.seed,
        methods=tuple(args.methods),
        association=AssociationOptions(
            gate_probability=args.gate_probability,
            confirm_m=args.confirm_m,
            confirm_n=args.confirm_n,
            delete_misses=args.delete_misses,
        ),
        sigma_a_mps2=args.sigma_a_mps2,
        sigma_v0_mps=args.sigma_v0_mps,
        gospa_cutoff_m=args.gospa_cutoff_m,
        gospa_order=args.gospa_order,
    )
    from radarviz.viz_app.figures.common import check_figure_outputs  # matplotlib: late

    check_figure_outputs("--plot", args.plot)
    from radarviz.viz_app.reports.association import (
        association_document,
        format_association_table,
    )

    return _emit(
        args,
        association_document(run_association(cfg)),
        format_association_table,
        "radarviz.viz_app.figures.association:plot_association",
    )


def _emit(
    args: argparse.Namespace,
    doc: dict[str, Any],
    table: Callable[[dict[str, Any]], str],
    plot: str,
) -> int:
    """Write the figure if asked, then print the JSON document or the table.

    ``plot`` names the figure function as "module:function"; it is imported only when a
    figure is asked for, so a table or JSON run does not load matplotlib.
    """
    if args.plot:
        module, func = plot.split(":")
        getattr(importlib.import_module(module), func)(doc, args.plot)
    print_report(doc, args.json, table, allow_nan=False)
    if args.plot and not args.json:
        print(f"\nfigure written to {args.plot}")
    return 0


def _cmd_reproduce_prosov(args: argparse.Namespace) -> int:
    import radarviz
    from radarviz.viz_app.figures.common import check_figure_outputs  # matplotlib: late

    check_figure_outputs("--plot", args.plot)
    from radarviz.viz_app.reports.prosov import format_prosov_table, prosov_document
    from radarviz.viz_app.runtime import tune_allocator

    tune_allocator()
    progress = None
    if args.runs * len(args.sigma_beta_deg) >= PROGRESS_MIN_RUNS:
        from radarviz.viz_app.cli.progress import ProgressBar

        def progress(sigma_beta_deg: float) -> ProgressBar:
            return ProgressBar(f"prosov{' 3D' if args.dims == 3 else ''} σβ={sigma_beta_deg:g}°")

    results = radarviz.run_prosov(
        args.sigma_beta_deg,
        runs=args.runs,
        seed=args.seed,
        period_s=args.period_s,
        steps=args.steps,
        sigma_r_m=args.sigma_r_m,
        methods=args.methods,
        dims=args.dims,
        elevation_deg=args.target_elevation_deg,
        sigma_elevation_deg=args.sigma_elevation_deg if args.dims == 3 else None,
        progress=progress,
    )
    return _emit(
        args,
        prosov_document(results),
        format_prosov_table,
        "radarviz.viz_app.figures.prosov:plot_prosov",
    )


def _cmd_reproduce_gorshkov(args: argparse.Namespace) -> int:
    import radarviz
    from radarviz.core.finite_memory.fit import PRESETS, RadarPreset

    radars: list = args.radars if args.radars is not None else list(PRESETS)
    if args.custom is not None:
        sigma_r_m = check_real("--custom SIGMA_R_M", args.custom[0], low=0.0, high=1e6)
        c0 = check_real("--custom C0", args.custom[1], low=0.0, high=1e8)
        T = check_real("--custom PERIOD_S", args.custom[2], low=0.0, high=3600.0)
        radars = [*radars, RadarPreset("custom", "-", sigma_r_m, sigma_r_m / (T * c0**0.5), T)]
    from radarviz.viz_app.figures.common import check_figure_outputs  # matplotlib: late

    check_figure_outputs("--plot", args.plot)
    from radarviz.viz_app.reports.gorshkov import format_gorshkov_table, gorshkov_document
    from radarviz.viz_app.runtime import tune_allocator

    tune_allocator()
    run = radarviz.run_gorshkov(
        radars,
        trials=args.trials,
        seed=args.seed,
        k_max=args.k_max,
        tracking_radar=args.tracking_radar,
        tracking_runs=args.tracking_runs,
        sigma_beta_deg=args.sigma_beta_deg,
    )
    return _emit(
        args,
        gorshkov_document(run.fits, run.tracking),
        format_gorshkov_table,
        "radarviz.viz_app.figures.gorshkov:plot_gorshkov",
    )


def _cmd_reproduce_doppler(args: argparse.Namespace) -> int:
    from radarviz.core.experiments.doppler_start import compare_doppler_updates
    from radarviz.core.finite_memory.fit import PRESETS

    radars: list[str] = args.radars if args.radars is not None else list(PRESETS)
    for name in radars:
        if name not in PRESETS:
            raise ParameterError(f"--radars must be among {', '.join(PRESETS)} (got {name!r})")
    from radarviz.viz_app.figures.common import check_figure_outputs  # matplotlib: late

    check_figure_outputs("--plot", args.plot)
    from radarviz.viz_app.reports.doppler import doppler_document, format_doppler_table
    from radarviz.viz_app.runtime import tune_allocator

    tune_allocator()
    results = compare_doppler_updates(
        tuple(radars), sigma_beta_deg=args.sigma_beta_deg, runs=args.runs, seed=args.seed
    )
    return _emit(
        args,
        doppler_document(results),
        format_doppler_table,
        "radarviz.viz_app.figures.doppler:plot_doppler",
    )


def _cmd_reproduce_velocity(args: argparse.Namespace) -> int:
    import radarviz
    from radarviz.viz_app.figures.common import check_figure_outputs  # matplotlib: late

    check_figure_outputs("--plot", args.plot)
    from radarviz.viz_app.reports.velocity import format_velocity_table, velocity_document
    from radarviz.viz_app.runtime import tune_allocator

    tune_allocator()
    doc = velocity_document(radarviz.run_velocity(args.trials, args.seed))
    return _emit(
        args, doc, format_velocity_table, "radarviz.viz_app.figures.velocity:plot_velocity"
    )


def _cmd_reproduce_manoeuvre(args: argparse.Namespace) -> int:
    from radarviz.core.experiments.manoeuvre import ManoeuvreConfig, run_manoeuvre

    check_int("--runs", args.runs, low=2, high=10_000)
    if args.straight_runs != 0:
        check_int("--straight-runs", args.straight_runs, low=2, high=100_000)
    if args.finite_memory != 0:
        check_int("--finite-memory", args.finite_memory, low=3, high=100)
    cfg = ManoeuvreConfig(
        runs=args.runs,
        seed=args.seed,
        straight_runs=args.straight_runs,
        finite_memory_k=args.finite_memory,
    )
    from radarviz.viz_app.reports.manoeuvre import format_manoeuvre_table, manoeuvre_document

    doc = manoeuvre_document(run_manoeuvre(cfg))
    print_report(doc, args.json, format_manoeuvre_table, allow_nan=False)
    return 0


def _check_bench(doc: dict[str, Any]) -> None:
    """Every figure of a bench document finite, and >= 0 but for the signed ones (times,
    rates and ratios; a memory slope may be negative)."""
    from radarviz.viz_app.bench.live import SIGNED_FIGURES

    check_finite_document("bench", doc, nonnegative=True, signed=SIGNED_FIGURES)


def _cmd_bench(args: argparse.Namespace) -> int:
    for m in args.runs:
        check_int("--runs", m, low=100, high=10_000_000)
    check_int("--filterpy-runs", args.filterpy_runs, low=1, high=100_000)
    check_int("--targets", args.targets, low=1, high=100_000)
    from radarviz.viz_app.io.plots import MAX_SIMULATE_STEPS

    # the files are simulate's fusion preset: three radars of at most MAX_SIMULATE_STEPS scans
    check_int("--asterix-plots", args.asterix_plots, low=100, high=3 * MAX_SIMULATE_STEPS)
    check_int("--asterix-targets", args.asterix_targets, low=1, high=4095)
    check_real("--live-rate", args.live_rate, low=1.0, high=100_000.0, low_open=False)
    check_real("--live-seconds", args.live_seconds, low=1.0, high=3600.0, low_open=False)
    check_int("--live-targets", args.live_targets, low=1, high=4095)
    if args.live_soak_s is not None:
        check_real("--live-soak-s", args.live_soak_s, low=60.0, high=86_400.0, low_open=False)
        if args.only != "live":
            raise ParameterError("--live-soak-s needs --only live", "--live-soak-s")
    if args.markdown is not None:
        from radarviz.viz_app.bench.markdown import check_markdown_target

        if args.only is not None or args.device != "cpu":
            raise ParameterError(
                "--markdown writes the full CPU bench's figures: leave out --only and --device",
                "--markdown",
            )
        check_markdown_target(args.markdown)  # before minutes of timing, not after
    if args.only == "asterix":
        from radarviz.viz_app.bench.asterix import bench_asterix, format_asterix

        doc = {"asterix": bench_asterix(args.asterix_plots, targets=args.asterix_targets)}
        _check_bench(doc)
        print_report(doc, args.json, lambda d: format_asterix(d["asterix"]))
        return 0
    if args.only == "live":
        from radarviz.viz_app.bench.live import bench_live, format_live

        soak = args.live_soak_s is not None
        seconds = args.live_soak_s if soak else args.live_seconds
        doc = {"live": bench_live(args.live_rate, seconds, args.live_targets, soak=soak)}
        _check_bench(doc)
        print_report(doc, args.json, lambda d: format_live(d["live"]))
        return 0
    if args.only == "tune":
        from radarviz.viz_app.bench.tune_frame import bench_tune_frames, format_tune_frames

        check_int("--tune-changes", args.tune_changes, low=1, high=50)
        doc = {"tune": bench_tune_frames(args.tune_changes)}
        _check_bench(doc)
        print_report(doc, args.json, lambda d: format_tune_frames(d["tune"]))
        return 0
    if args.only == "association":
        from radarviz.viz_app.bench.association import bench_association, format_association

        doc = {"association": bench_association(args.targets)}
        _check_bench(doc)
        print_report(doc, args.json, lambda d: format_association(d["association"]))
        return 0
    check_int("--track-plots", args.track_plots, low=1000, high=10_000_000)
    if args.device == "gpu":
        from radarviz.viz_app.bench.device import NoGPUError, bench_gpu, format_gpu

        try:
            doc = bench_gpu(runs=args.runs[0])
        except NoGPUError as exc:
            print(f"radarviz: error: bench --device gpu: {exc}", file=sys.stderr)
            return 1
        print_report(doc, args.json, format_gpu)
        return 0
    from radarviz.viz_app.bench.engine import format_bench, run_bench
    from radarviz.viz_app.runtime import tune_allocator

    tune_allocator()
    doc = run_bench(
        runs=args.runs,
        filterpy_runs=args.filterpy_runs,
        targets=args.targets,
        asterix_plots=args.asterix_plots,
        asterix_targets=args.asterix_targets,
        track_plots=args.track_plots,
        live=(args.live_rate, args.live_seconds, args.live_targets),
    )
    _check_bench(doc)
    print_report(doc, args.json, format_bench)
    if args.markdown is not None:
        from radarviz.viz_app.bench.markdown import bench_section, write_bench_section

        # The command as run, every size spelled out (defaults too), so a reduced run says so.
        argv = ["bench", "--runs", *map(str, args.runs)]
        sizes = ("filterpy_runs", "targets", "asterix_plots", "asterix_targets")
        for flag in (*sizes, "live_rate", "live_seconds", "live_targets", "track_plots"):
            value = getattr(args, flag)
            argv += [
                "--" + flag.replace("_", "-"),
                f"{value:g}" if isinstance(value, float) else str(value),
            ]
        argv += ["--markdown", args.markdown]
        write_bench_section(args.markdown, bench_section(doc, argv))
    return 0


def _stdout_closed() -> bool:
    """Whether standard output is a pipe whose reader has gone (poll's POLLERR on its write
    end); if so it is pointed at /dev/null, so the interpreter's last flush of what is still
    buffered does not fail again ("Exception ignored … BrokenPipeError")."""
    import os
    import select

    try:
        fd = sys.stdout.fileno()
        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        closed = any(ev & select.POLLERR for _, ev in poller.poll(0))
    except (AttributeError, OSError, ValueError):  # no file descriptor (a test's capture)
        return False
    if closed:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)
    return closed


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``radarviz`` console script; returns the exit status."""
    try:
        arguments = sys.argv[1:] if argv is None else list(argv)
        command = command_of(arguments)
        args = build_parser(flags_of=[command] if command else []).parse_args(arguments)
    except KeyboardInterrupt:
        print(STARTUP_INTERRUPTED, file=sys.stderr)
        return EXIT_INTERRUPTED
    try:
        if args.command == "reproduce" and args.experiment == "prosov":
            return _cmd_reproduce_prosov(args)
        if args.command == "reproduce" and args.experiment == "doppler":
            return _cmd_reproduce_doppler(args)
        if args.command == "reproduce" and args.experiment == "gorshkov":
            return _cmd_reproduce_gorshkov(args)
        if args.command == "reproduce" and args.experiment == "velocity":
            return _cmd_reproduce_velocity(args)
        if args.command == "reproduce" and args.experiment == "manoeuvre":
            return _cmd_reproduce_manoeuvre(args)
        if args.command == "reproduce" and args.experiment == "association":
            return _cmd_reproduce_association(args)
        if args.command == "bench":
            return _cmd_bench(args)
        if args.command == "tune":
            from radarviz.viz_app.tune.serve import cmd_tune

            return cmd_tune(args.host, args.port, args.viewer_port, args.no_browser)
        module = command_module(args.command)
        if module is not None:
            return module.COMMANDS[args.command](args)
    except ParameterError as exc:
        return _fail(cli_message(args, exc))
    except WriteError as exc:  # an output could not be written; the previous file is intact
        print(f"radarviz: error: {exc}", file=sys.stderr)
        return EXIT_WRITE
    except ResultError as exc:  # a NaN or a negative NEES: nothing printed, nothing written
        print(f"radarviz: error: {exc}", file=sys.stderr)
        return EXIT_RESULT
    except BrokenPipeError as exc:
        if _stdout_closed():  # nothing to say, and no one to say it to on standard output
            return EXIT_PIPE
        return _fail(f"{exc.strerror or exc}: {exc.filename}" if exc.filename else str(exc))
    except OSError as exc:
        return _fail(f"{exc.strerror or exc}: {exc.filename}" if exc.filename else str(exc))
    except KeyboardInterrupt:
        # Ctrl-C: every writer has removed its temporary file on the way out (the outputs are
        # atomic), so the targets are as before; 130 is the shell's status for SIGINT.
        print(f"radarviz: interrupted: {args.command} stopped, no output written", file=sys.stderr)
        return EXIT_INTERRUPTED
    return _fail(f"unknown command {args.command!r}")


if __name__ == "__main__":
    sys.exit(main())
