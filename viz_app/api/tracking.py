"""Tracking plots: a thin layer over the streaming tracker (``radarviz.core.tracking.stream``)."""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.state import position_index
from radarviz.core.params import ParameterError, check, default
from radarviz.core.tracking.association import AssociationOptions, AssociationReport
from radarviz.core.tracking.stream import (
    Plot,
    PlotError,
    StateRow,
    StreamOptions,
    motion_fields,
)
from radarviz.viz_app.io.plots import (
    Radar,
    RowObserver,
    _open_input,
    bad_plot_field,
    labels_refused,
    load_radars,
    radar_coverage,
    simulated_plots,
    track_plots,
)
from radarviz.viz_app.io.plots import write_measurements as _write_measurements


@dataclass(frozen=True)
class TrackStep:
    """One method's state after one plot.

    Attributes:
        plot: index of the plot in ``Tracks.plots``.
        time_s: the plot's time, s.
        method: the filter.
        x: state (x, vx, y, vy, z, vz), shape (6,), m and m/s (2D plots: z = vz = 0).
        P: its covariance, shape (6, 6), in m², m²/s, m²/s².
        target: the plot's target label ("" for plots of one target), or its track id when
            ``track_file`` associates.
        status: the track's status after the plot when associated (``tentative``,
            ``confirmed``, ...), else "".
    """

    plot: int
    time_s: float
    method: str
    x: NDArray[np.float64]
    P: NDArray[np.float64]
    target: str = ""
    status: str = ""


@dataclass(frozen=True)
class ScanEnd:
    """The end of one scan of the association (``track_file(..., association=...)``).

    The association takes a scan's plots together and only then knows which tracks it has
    deleted (a track is deleted at a scan it misses); ``Tracks.scans`` keeps that account,
    which no ``TrackStep`` holds, so that ``Tracks.replay`` (and with it ``record``) can hand
    it on where ``radarviz track --associate gnn`` does.

    Attributes:
        plots: how many plots of ``Tracks.plots`` there are up to and including the scan's
            last (the scan's plots are ``plots[previous.plots : plots]``).
        deleted: ids of the tracks deleted at the scan.
    """

    plots: int
    deleted: tuple[str, ...] = ()


@dataclass(frozen=True)
class Tracks:
    """What ``track`` returns: the plots it was given and every method's states.

    Attributes:
        plots: the plots in the order they were tracked.
        steps: one ``TrackStep`` per (plot, method) once the track has started.
        methods: the filters run.
        three_d: the plots carry elevations.
        radars: the radar sites (for a recording), empty when plots came without them.
        scans: with the association, one ``ScanEnd`` per batch in order (the tracks it
            deleted); empty without.
        association: with the association, its account (where each radar's plots went,
            what was estimated of each radar), else None.
    """

    plots: tuple[Plot, ...]
    steps: tuple[TrackStep, ...]
    methods: tuple[str, ...]
    three_d: bool
    radars: tuple[Radar, ...] = ()
    scans: tuple[ScanEnd, ...] = ()
    association: AssociationReport | None = None

    def positions_m(self, method: str) -> NDArray[np.float64]:
        """The method's estimated positions, shape (K, 3), m (one row per tracked plot)."""
        pos = list(position_index(3))
        rows = [s.x[pos] for s in self.steps if s.method == method]
        return np.array(rows, dtype=float).reshape(-1, 3)

    def rows_by_plot(self) -> list[list[StateRow]]:
        """For each plot, its (method, x (6,), P (6, 6)) rows: what the tracker returned."""
        out: list[list[StateRow]] = [[] for _ in self.plots]
        for s in self.steps:
            out[s.plot].append((s.method, s.x, s.P))
        return out

    def statuses_by_plot(self) -> list[str]:
        """For each plot, the status of its track after its scan (``TrackStep.status``: every
        method's step of a plot has the same); "" without the association."""
        out = [""] * len(self.plots)
        for s in self.steps:
            out[s.plot] = s.status
        return out

    def replay(self, observer: RowObserver) -> None:
        """Hand every plot to ``observer`` as ``radarviz track`` hands its recorder the plots
        it tracks (``viz_app.io.plots.run_track``): ``add(plot, rows, status)`` per plot in
        order and, with the association, ``end_scan(deleted)`` after each batch's last plot
        and ``report(account)`` after the last.

        ``record`` and ``show`` replay into the recorder of ``radarviz track --rrd``
        (``viz_app.rerun.track_recording.TrackRecorder``), so the recording of the same plots
        is the command's: with the association, tentative tracks faint, deleted tracks
        cleared, paths and time series for confirmed tracks only.
        """
        ends = iter(self.scans)
        end = next(ends, None)
        rows, statuses = self.rows_by_plot(), self.statuses_by_plot()
        for n, (plot, plot_rows, status) in enumerate(
            zip(self.plots, rows, statuses, strict=True), start=1
        ):
            observer.add(plot, plot_rows, status)
            while end is not None and end.plots == n:
                observer.end_scan(list(end.deleted))
                end = next(ends, None)
        if self.association is not None:
            observer.report(self.association)


def _options(**kwargs: object) -> StreamOptions:
    return StreamOptions(**kwargs)  # type: ignore[arg-type]  # each field is checked there


def track(
    plots: Iterable[Plot],
    methods: Sequence[str] | None = None,
    *,
    model: str | None = None,
    sigma_a_mps2: float | None = None,
    imm_sigma_a_mps2: Sequence[float] | None = None,
    transition_prob: Sequence[Sequence[float]] | Sequence[float] | None = None,
    imm_turn_rate_degps: Sequence[float] | None = None,
    sigma_v0_mps: float = 1000.0,
    use_doppler: bool = True,
    doppler_update: str = "line_of_sight",
    init: str = "first-plot",
    init_k: int = 3,
    radars: Iterable[Radar] = (),
    association: AssociationOptions | None = None,
) -> Tracks:
    """Track plots with every requested filter: one target, many by their labels, or many
    unlabelled by the association.

    The plots go to the trackers of ``radarviz track`` in blocks: ``StreamTracker`` when no
    plot has a ``target`` label, else ``TargetTracker`` (one track per target and method, all
    targets on the batch axis; it needs the first-plot start). With ``association`` they go
    scan by scan to the association of ``radarviz track --associate gnn``, by the very route
    ``track_file(..., association=...)`` takes (``viz_app.io.plots.track_plots`` reading the
    plots from memory instead of a file), so the same plots give the same tracks, step for
    step, and the same ``Tracks.scans``.

    Args:
        plots: ``Plot`` records in time order (2D, or all with elevations for 3D); for many
            targets, each with its ``target`` label and in time order within its target, or
            none labelled with ``association``.
        methods: filters (default every one of the plots' kind).
        model: ``imm`` or ``cv``; by default, as ``radarviz track``: ``cv`` when
            ``sigma_a_mps2`` is given, else ``imm`` (the IMM of a quiet, two turning and a
            manoeuvre model, consistent on manoeuvring aircraft;
            ``core.tracking.stream.motion_fields`` is the one rule). ``model="cv"`` with
            ``sigma_a_mps2=0`` is the papers' filter (Q = 0).
        sigma_a_mps2: process-noise acceleration std of ``cv``, m/s² (default 0: constant
            velocity exactly); refused with ``imm``.
        imm_sigma_a_mps2, transition_prob, imm_turn_rate_degps: the IMM's σa per model
            (m/s²), its transition probabilities (rows, or r × r numbers row by row) and
            each model's turn rate (°/s, 0 constant velocity), as ``--imm-sigma-a``,
            ``--imm-transition`` and ``--imm-turn-rate``; default the IMM of
            ``radarviz track``; refused with ``cv``.
        sigma_v0_mps: velocity std of the start, m/s.
        use_doppler: use the plots' radial velocities where they have them.
        doppler_update: how they update the tracks: ``line_of_sight`` (along the measured
            line of sight) or ``converted`` (the r̂·V̂r pseudo-measurement).
        init: ``first-plot`` or ``finite-memory`` (Gorshkov and Zavizhenets' window fit).
        init_k: plots in the finite-memory start window.
        radars: the sites, kept for ``record`` and ``show``.
        association: for plots of many targets without ``target`` labels: the
            global-nearest-neighbour association of ``radarviz track --associate gnn``
            (``AssociationOptions``: gating method, gate probability, M of N, misses to
            delete, scan window; a scan is a run of one radar's plots within the window).
            Each step's ``target`` is then its track id, its ``status`` the track's status
            after the scan, ``Tracks.plots`` are the plots labelled with their track ids, and
            ``Tracks.scans`` tells where each scan ends and which tracks it deleted. It takes
            the first-plot start only, and refuses labelled plots (their targets are known:
            track them without it).

    Returns:
        ``Tracks`` (``to_table`` gives one row per plot and method).
    """
    from radarviz.core.experiments.prosov import ALL_METHODS
    from radarviz.core.filters.methods import METHODS_3D
    from radarviz.core.tracking.stream import StreamTracker
    from radarviz.core.tracking.targets import TargetTracker

    options = _options(
        **motion_fields(
            model, sigma_a_mps2, imm_sigma_a_mps2, transition_prob, imm_turn_rate_degps
        ),
        sigma_v0_mps=sigma_v0_mps,
        use_doppler=use_doppler,
        doppler_update=doppler_update,
        init=init,
        init_k=init_k,
    )
    plots = tuple(plots)
    three_d = bool(plots) and plots[0].elevation_rad is not None
    used = tuple(methods) if methods is not None else (METHODS_3D if three_d else ALL_METHODS)
    if association is not None:
        return _associate(plots, used, three_d, options, association, tuple(radars))
    many = any(p.target for p in plots)
    tracker = (TargetTracker if many else StreamTracker)(used, three_d, options)
    steps: list[TrackStep] = []
    block = 1000
    for i in range(0, len(plots), block):
        chunk = list(plots[i : i + block])
        try:
            rows_of = tracker.add_block(chunk)
        except PlotError as exc:
            raise ParameterError(f"{_index(i + exc.index, exc.column)}: {exc}", "plots") from None
        for j, (p, rows) in enumerate(zip(chunk, rows_of, strict=True)):
            steps += [
                TrackStep(i + j, p.time_s, m, x.copy(), P.copy(), p.target) for m, x, P in rows
            ]
    return Tracks(plots, tuple(steps), used, three_d, tuple(radars))


def _associate(
    plots: tuple[Plot, ...],
    methods: tuple[str, ...],
    three_d: bool,
    options: StreamOptions,
    association: AssociationOptions,
    radars: tuple[Radar, ...],
) -> Tracks:
    """``track`` with the association: ``track_plots`` of the plots in memory."""
    from radarviz.core.tracking.stream import check_methods

    labelled = next((i for i, p in enumerate(plots) if p.target), None)
    if labelled is not None:
        where = f"plots[{labelled}].target is {plots[labelled].target!r}"
        raise ParameterError(labels_refused("association", where), "association")
    # Checked here as ``track`` checks it without the association: ``track_plots`` would name
    # the command's flag (--method) for this one error about no single parameter.
    check_methods(methods, three_d)
    kept = _Collector()
    track_plots(
        _PlotList(plots, three_d),
        "",
        methods,
        options,
        kept.add,
        None,
        _index,
        association,
        kept.end_scan,
        {r.name: radar_coverage(r) for r in radars},
        kept.report,
    )
    return Tracks(
        tuple(kept.plots),
        tuple(kept.steps),
        methods,
        three_d,
        radars,
        tuple(kept.scans),
        kept.account,
    )


class _PlotList:
    """Plots in memory as a ``viz_app.io.plots.PlotSource`` (position: the index), checked
    for time order as ``PlotReader`` checks a file's: the association cuts scans in order."""

    targets = False  # the association takes only unlabelled plots (``_associate`` checks)

    def __init__(self, plots: tuple[Plot, ...], three_d: bool) -> None:
        self.plots, self.three_d = plots, three_d

    def __iter__(self) -> Iterator[tuple[int, Plot]]:
        last = -math.inf
        for i, p in enumerate(self.plots):
            if p.time_s < last:
                raise ParameterError(
                    f"plots[{i}].time_s: must not be before the previous time {last!r} "
                    f"(got {p.time_s!r})",
                    "plots",
                )
            last = p.time_s
            yield i, p


def _index(i: int, column: str) -> str:
    """Where a plot's value is: ``plots[i].column`` (``track``'s words for its errors)."""
    return f"plots[{i}].{column}"


def track_file(
    measurements: str,
    radars: str,
    methods: Sequence[str] | None = None,
    *,
    model: str | None = None,
    sigma_a_mps2: float | None = None,
    imm_sigma_a_mps2: Sequence[float] | None = None,
    transition_prob: Sequence[Sequence[float]] | Sequence[float] | None = None,
    imm_turn_rate_degps: Sequence[float] | None = None,
    sigma_v0_mps: float = 1000.0,
    use_doppler: bool = True,
    doppler_update: str = "line_of_sight",
    init: str = "first-plot",
    init_k: int = 3,
    association: AssociationOptions | None = None,
    input_format: str = "auto",
) -> Tracks:
    """Track a measurement file (CSV or ASTERIX CAT048) with its radars TOML file (the formats
    of ``radarviz track``, described in ``docs/tracking.md``); nothing is written.

    Args:
        measurements: path of the measurement CSV or ASTERIX file.
        radars: path of the radars TOML file (sites in m, accuracies).
        methods: see ``track``.
        model: see ``track``.
        sigma_a_mps2: see ``track``.
        imm_sigma_a_mps2, transition_prob, imm_turn_rate_degps: see ``track``.
        sigma_v0_mps: see ``track``.
        use_doppler: see ``track``.
        doppler_update: see ``track``.
        init: see ``track``.
        init_k: see ``track``.
        association: for a file of many targets without a ``target`` column: the
            global-nearest-neighbour association of ``radarviz track --associate gnn``
            (``AssociationOptions``: gating method, gate probability, M of N, misses to
            delete, scan window). Each step's ``target`` is then its track id, its
            ``status`` the track's status, and ``Tracks.scans`` tells where each scan ends
            and which tracks it deleted.
        input_format: "csv", "asterix", "pcap" (a pcap or pcapng capture of ASTERIX over
            UDP) or "auto" (a capture by its magic, else by the suffix: ``.ast``,
            ``.asterix`` are ASTERIX), as ``radarviz track --format``.

    Returns:
        ``Tracks``, with the file's radars.
    """
    options = _options(
        **motion_fields(
            model, sigma_a_mps2, imm_sigma_a_mps2, transition_prob, imm_turn_rate_degps
        ),
        sigma_v0_mps=sigma_v0_mps,
        use_doppler=use_doppler,
        doppler_update=doppler_update,
        init=init,
        init_k=init_k,
    )
    sites = load_radars(radars)
    kept = _Collector()

    from radarviz.viz_app.io.asterix import source_for

    open_source = source_for(measurements, input_format)
    with _open_input(measurements) as fh:
        reader, locate = open_source(fh, measurements, sites)
        used_methods = None if methods is None else tuple(methods)
        _, three_d, used, _ = track_plots(
            reader,
            measurements,
            used_methods,
            options,
            kept.add,
            None,
            locate,
            association,
            kept.end_scan,
            {name: radar_coverage(r) for name, r in sites.items()},
            kept.report,
        )
    return Tracks(
        tuple(kept.plots),
        tuple(kept.steps),
        tuple(used),
        three_d,
        tuple(sites.values()),
        tuple(kept.scans),
        kept.account,
    )


class _Collector:
    """The ``RowObserver`` that ``track_file`` (and ``track`` with the association) hands
    ``track_plots``'s calls to: it keeps the plots, their rows as ``TrackStep`` and the
    scans' ends, for ``Tracks``."""

    def __init__(self) -> None:
        self.plots: list[Plot] = []
        self.steps: list[TrackStep] = []
        self.scans: list[ScanEnd] = []
        self.account: AssociationReport | None = None

    def add(self, plot: Plot, rows: list[StateRow], status: str = "") -> None:
        n = len(self.plots)
        self.steps.extend(
            TrackStep(n, plot.time_s, m, x.copy(), P.copy(), plot.target, status)
            for m, x, P in rows
        )
        self.plots.append(plot)

    def end_scan(self, deleted: list[str]) -> None:
        self.scans.append(ScanEnd(len(self.plots), tuple(deleted)))

    def report(self, account: AssociationReport) -> None:
        self.account = account


def simulate(
    preset: str = "fusion",
    *,
    seed: int = default("seed"),
    sigma_beta_deg: float = default("sigma_beta_deg"),
    steps: int = default("steps"),
) -> tuple[list[Plot], list[Radar]]:
    """The plots and radars of one of ``radarviz simulate``'s scenes, in memory.

    Tracking them with ``track`` gives what tracking the files ``simulate`` writes gives (the
    angles are already rounded through degrees, as the file stores them).

    Args:
        preset: ``fusion`` (three 3D radars with Doppler, scans staggered by a third of a
            period, one turning target; ``steps`` scans per radar) or ``prosov`` (one 2D
            radar at the origin, the Prosov run of 60 scans at ``sigma_beta_deg``).
        seed: root of the random numbers.
        sigma_beta_deg: azimuth noise σβ of ``prosov``, degrees.
        steps: scans per radar of ``fusion``.

    Returns:
        (plots, radars): the plots in time order and the radars they come from, ready for
        ``track`` or ``write_measurements``.

    Raises:
        ParameterError: an unknown preset or a value outside its range (every value is
            checked, whichever preset uses it).
    """
    check("seed", seed)
    return simulated_plots(preset, seed, sigma_beta_deg, steps)


def _check_plot_values(i: int, plot: Plot) -> None:
    """``ParameterError`` naming ``plots[i].field`` when a value could not be read back (the
    fields of ``viz_app.io.plots.PLOT_FIELDS``)."""
    field = bad_plot_field(plot)
    if field is not None:
        want = "a finite number > 0" if field.positive else "a finite number"
        got = getattr(plot, field.name)
        raise ParameterError(f"plots[{i}].{field.name} must be {want} (got {got!r})", "plots")


def write_measurements(
    measurements: str | os.PathLike[str],
    radars: str | os.PathLike[str],
    plots: Sequence[Plot],
    sites: Sequence[Radar],
) -> int:
    """Write plots as a measurement CSV and their radars as a radars TOML file, the input
    ``track_file`` and ``radarviz track`` read (``docs/tracking.md``).

    Both files are written under temporary names and renamed together when both are
    complete, so a failure leaves neither half-written.

    Args:
        measurements: path of the CSV (time_s, radar, range_m, azimuth_deg, …), replaced if
            it exists.
        radars: path of the TOML file, replaced if it exists.
        plots: the plots (from ``simulate``, or ``Plot`` values of your own), each naming its
            radar in ``Plot.radar``.
        sites: the radars the plots name.

    Returns:
        The number of plots written.

    Raises:
        ParameterError: no plots, no radars, a plot naming a radar not in ``sites``, or a
            plot value that is not finite (or not > 0 for a range or an accuracy).
    """
    if not plots:
        raise ParameterError("plots must hold at least one plot (got none)", "plots")
    if not sites:
        raise ParameterError("sites must hold at least one radar (got none)", "sites")
    names = {r.name for r in sites}
    for i, p in enumerate(plots):
        if p.radar not in names:
            raise ParameterError(
                f"plots[{i}].radar must be one of {sorted(names)} (got {p.radar!r})", "plots"
            )
        _check_plot_values(i, p)
    return _write_measurements(os.fspath(measurements), os.fspath(radars), list(plots), list(sites))
