"""The tracker on the compiled engine (``core.tracking.compiled``, ``core.filters.kernels_track``,
``core.filters.kernels_3d``) against the numpy engine, and the block-wise track file.

* Engines: for every method, 2D and 3D, with Doppler on some plots and not on others, three
  radars (sites and noise of their own), a time step per plot, the compiled tracks of many
  interleaved targets equal the numpy engine's to 1e-9 relative (absolute floor 1e-9 in the
  entry's unit), whatever the blocks; so does the consistency monitor's record of every
  track (the same windows in and out of band, the same events, NIS means to 1e-9). The two
  engines compute the same formulas in another order, so they agree to rounding.
* Per target, as alone: on the compiled engine a target's tracks in a many-target file are
  bit for bit those of its plots alone (the kernel walks the plots in order; nothing crosses
  targets).
* The IMM (``core.filters.kernels_imm``): the same, for x, for P to 1e-9 of its scale
  (``close_cov``), for μ and for the monitor's NIS of the combined prediction, whatever the
  blocks; a target of many is bit for bit its plots alone; ``radarviz track`` (the IMM by
  default) writes the numpy engine's tracks.
* The number text: the compiled formatter writes every double as pyarrow does, byte for byte,
  on 1.1·10⁷ doubles chosen where a shortest-digits formatter errs.
* The file path: ``radarviz track`` (columns read by pyarrow in blocks, tracked by arrays,
  written a block at a time) gives the tracks of the plots read row by row and tracked one
  ``Plot`` at a time, also when the blocks are cut small and the file has what the fast parser
  leaves to the row reader (a quoted cell, blank lines); an error in a later block names its
  own line.
"""

from __future__ import annotations

import csv
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_targets import TOL, close  # |a − b| ≤ 1e-9 (1 + |a|), as the many-target tests

from radarviz.core.filters.methods import ALL_METHODS, METHODS_3D
from radarviz.core.tracking import compiled
from radarviz.core.tracking.compiled import CompiledTracks, PlotBlock, TrackBlock
from radarviz.core.tracking.consistency import ConsistencyMonitor
from radarviz.core.tracking.stream import (
    Plot,
    PlotError,
    StateRow,
    StreamOptions,
    StreamTracker,
    plot_block,
)
from radarviz.core.tracking.targets import TargetTracker
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io import plot_blocks
from radarviz.viz_app.io.plots import (
    TRACK_COLUMNS,
    fusion_plots,
    prosov_plots,
    state_from_row,
    write_measurements,
)

_SITES = ((0.0, 0.0, 0.0), (15_000.0, -8_000.0, 40.0), (-5_000.0, 12_000.0, 10.0))


def scene(three_d: bool, targets: int = 5) -> list[Plot]:
    """Interleaved plots of ``targets`` targets: the prosov run (2D) or the fusion run (3D,
    Doppler) per target, each plot given to one of three radars (its site and noise), every
    fourth without Doppler, a time offset per target."""
    out = []
    for k in range(targets):
        plots, _ = fusion_plots(seed=k + 1, steps=12) if three_d else prosov_plots(seed=k + 1)
        for j, p in enumerate(plots):
            g = (j + k) % 3
            vr = p.radial_velocity_mps if three_d else 30.0 * np.sin(0.3 * j + k)
            out.append(
                replace(
                    p,
                    time_s=p.time_s + 0.37 * k,
                    target=f"T{k}",
                    site=_SITES[g] if not three_d else p.site,
                    sigma_r_m=p.sigma_r_m * (1.0 + 0.5 * g),
                    sigma_beta_rad=p.sigma_beta_rad * (1.0 + 0.25 * g),
                    radial_velocity_mps=None if (j + k) % 4 == 0 else float(vr),
                    sigma_vr_mps=1.0 + g,
                )
            )
    return sorted(out, key=lambda p: p.time_s)


def tracked(plots: list[Plot], three_d: bool, engine: str, block: int, **kw):
    monitor = ConsistencyMonitor(5)
    options = StreamOptions(sigma_a_mps2=1.0, engine=engine, monitor=monitor, **kw)
    tracker = TargetTracker(METHODS_3D if three_d else ALL_METHODS, three_d, options)
    rows = []
    for i in range(0, len(plots), block):
        rows += tracker.add_block(plots[i : i + block])
    return tracker, rows, monitor


def assert_same_rows(
    ref_rows: list[list[StateRow]],
    rows: list[list[StateRow]],
    close_P: Callable[[np.ndarray, np.ndarray], bool],
) -> None:
    """Per plot the same methods in the same order, each x ``close`` and P ``close_P``."""
    for a, b in zip(ref_rows, rows, strict=True):
        assert [m for m, _, _ in a] == [m for m, _, _ in b]
        for (m, xa, Pa), (_, xb, Pb) in zip(a, b, strict=True):
            assert close(xa, xb), m
            assert close_P(Pa, Pb), m


def assert_same_monitor(
    ref_mon: ConsistencyMonitor, mon: ConsistencyMonitor, tol: float = TOL
) -> None:
    """The two monitors' figures per track (mean NIS to ``tol``, relative) and events are the
    same."""
    want, got = ref_mon.results(), mon.results()
    assert set(want) == set(got)
    for name, w in want.items():
        g = got[name]
        assert (g.updates, g.windows, g.above, g.below) == (w.updates, w.windows, w.above, w.below)
        assert g.first_exit_s == w.first_exit_s
        assert abs(g.mean_nis_per_dof - w.mean_nis_per_dof) <= tol * w.mean_nis_per_dof
    # The numpy engine feeds the monitor wave by wave, the compiled one plot by plot: the
    # same events, listed in another order.
    key = sorted((e.track, e.time_s, e.kind) for e in ref_mon.events)
    assert key == sorted((e.track, e.time_s, e.kind) for e in mon.events)


@pytest.mark.parametrize("three_d", [False, True], ids=["2d", "3d"])
@pytest.mark.parametrize("block", [7, 4096])
def test_the_compiled_tracker_equals_the_numpy_engine(three_d: bool, block: int) -> None:
    plots = scene(three_d)
    assert any(p.radial_velocity_mps is None for p in plots)
    assert any(p.radial_velocity_mps is not None for p in plots)
    ref, ref_rows, ref_mon = tracked(plots, three_d, "numpy", block)
    fast, rows, mon = tracked(plots, three_d, "compiled", block)
    assert (ref.engine, fast.engine) == ("numpy", "compiled")
    assert fast.targets == ref.targets
    assert_same_rows(ref_rows, rows, close)
    assert_same_monitor(ref_mon, mon)


@pytest.mark.parametrize("three_d", [False, True], ids=["2d", "3d"])
def test_a_target_of_many_is_bit_for_bit_its_plots_alone(three_d: bool) -> None:
    plots = scene(three_d, targets=3)
    methods = METHODS_3D if three_d else ALL_METHODS
    _, rows, _ = tracked(plots, three_d, "compiled", 50)
    options = StreamOptions(sigma_a_mps2=1.0)
    for name in ("T0", "T1", "T2"):
        own = [p for p in plots if p.target == name]
        alone = StreamTracker(methods, three_d, options).add_block(own)
        mine = [r for p, r in zip(plots, rows, strict=True) if p.target == name]
        for a, b in zip(alone, mine, strict=True):
            for (_, xa, Pa), (_, xb, Pb) in zip(a, b, strict=True):
                assert np.array_equal(xa, xb) and np.array_equal(Pa, Pb)


def close_cov(a: np.ndarray, b: np.ndarray) -> bool:
    """|Aᵢⱼ − Bᵢⱼ| ≤ 1e-9 (1 + √(Aᵢᵢ Aⱼⱼ)): a covariance to 1e-9 of its own scale.

    The IMM's combined P is a mixture whose cross terms can cancel to 10⁻⁵ of √(Pᵢᵢ Pⱼⱼ)
    (18.8 m²/s against 82 m/s × 3370 m); two routes through the same formulas then differ by
    rounding of the scale, 10⁻¹⁴ of it, which is 10⁻⁹ of such an entry (the numpy engine
    against itself, one target alone against many: 1.7e-10 entry by entry)."""
    a, b = np.asarray(a), np.asarray(b)
    d = np.sqrt(np.abs(np.diagonal(a, axis1=-2, axis2=-1)))
    scale = d[..., :, None] * d[..., None, :]
    return bool(np.all(np.abs(a - b) <= TOL * (1.0 + scale)))


def _x_change(a: np.ndarray, b: np.ndarray) -> float:
    """The largest |aᵢ − bᵢ| / (1 + |aᵢ|): what ``close`` holds to ``TOL``."""
    return float(np.max(np.abs(a - b) / (1.0 + np.abs(a))))


def _cov_change(a: np.ndarray, b: np.ndarray) -> float:
    """The largest |Aᵢⱼ − Bᵢⱼ| / (1 + √(Aᵢᵢ Aⱼⱼ)): what ``close_cov`` holds to ``TOL``."""
    d = np.sqrt(np.abs(np.diagonal(a, axis1=-2, axis2=-1)))
    return float(np.max(np.abs(a - b) / (1.0 + d[:, None] * d[None, :])))


#: How far beyond its ``rounding_spread`` a method may differ between the engines. The spread
#: is a scale, not a bound: the engines round differently at every operation, the spread
#: moves the inputs only (measured engine difference / spread in x: 1.9 for ``ducm``, 1.1
#: for ``ekf``, 1.6 for ``ukf``). An error in a formula moves a track by the size of the term
#: it gets wrong, 10⁻³ of its scale or more, far beyond ten times a spread of 10⁻⁸.
SPREAD_FACTOR = 10.0


def rounding_spread(
    plots: list[Plot], three_d: bool, rows: list[list[StateRow]], **kw
) -> dict[str, tuple[float, float]]:
    """Per method, how far the numpy engine's own x and P (``_x_change``, ``_cov_change``) move
    when every plot's range moves by one unit in the last place, up or down (the larger):
    the rounding the scene amplifies. ``rows``: the engine's rows of ``plots``.

    The scene's 2D plots are not those of their radars' sites (``scene``), so some tracks
    diverge (velocities jumping by km/s from plot to plot) and amplify a rounding difference
    by orders of magnitude: with the default IMM's turn models the ``ducm`` tracks move by
    8.0e-9 of their scale for one ulp of the ranges, and the two engines, which round
    differently at every step, differ by 1.5e-8 there (``ekf``: 3.0e-9 and 3.3e-9; with the
    former two-model IMM every method stayed below 1e-9)."""
    out: dict[str, tuple[float, float]] = {}
    for way in (np.inf, -np.inf):
        moved = [replace(p, range_m=float(np.nextafter(p.range_m, way))) for p in plots]
        _, other, _ = tracked(moved, three_d, "numpy", 4096, **kw)
        for a, b in zip(rows, other, strict=True):
            for (m, xa, Pa), (_, xb, Pb) in zip(a, b, strict=True):
                dx, dP = out.get(m, (0.0, 0.0))
                out[m] = (max(dx, _x_change(xa, xb)), max(dP, _cov_change(Pa, Pb)))
    return out


def assert_rows_within_rounding(
    ref_rows: list[list[StateRow]],
    rows: list[list[StateRow]],
    spread: dict[str, tuple[float, float]],
) -> None:
    """``assert_same_rows`` with ``close`` / ``close_cov``, each method's tolerance TOL or,
    where the scene amplifies rounding more, ``SPREAD_FACTOR`` times its ``rounding_spread``."""
    for a, b in zip(ref_rows, rows, strict=True):
        assert [m for m, _, _ in a] == [m for m, _, _ in b]
        for (m, xa, Pa), (_, xb, Pb) in zip(a, b, strict=True):
            tol_x, tol_P = (max(TOL, SPREAD_FACTOR * v) for v in spread[m])
            assert _x_change(xa, xb) <= tol_x, m
            assert _cov_change(Pa, Pb) <= tol_P, m


def _mu(tracker: TargetTracker, method: str, target: str) -> np.ndarray:
    """The IMM's model probabilities μ (r,) of ``target``'s ``method`` track, either engine."""
    j = tracker.methods.index(method)
    if tracker._compiled is not None:
        return tracker._compiled.mus[tracker._compiled.slots[target], j]
    b, row = tracker._where[method]
    bank = tracker._banks[b]
    mu = bank.arrays[2][row] if bank.axis else bank.arrays[2]
    return mu[tracker._slot[target]]


@pytest.mark.parametrize("n", [4, 6])
@pytest.mark.parametrize("r", [2, 3])
def test_the_compiled_imm_steps_are_the_numpy_ones(r: int, n: int) -> None:
    """Mixing, combination and mode probabilities (``core.filters.kernels_imm``) against
    ``core.filters.imm`` on random tracks, with likelihoods that are not finite."""
    from radarviz.core.filters import kernels_imm as k
    from radarviz.core.filters.imm import IMMState, imm_combine, imm_mix, mode_probabilities
    from radarviz.core.filters.state import CVBatch

    rng = np.random.default_rng(r * 10 + n)
    for _ in range(20):
        x = rng.normal(0.0, 1e4, (r, n))
        A = rng.normal(0.0, 30.0, (r, n, n))
        P = A @ A.mT + np.eye(n)
        mu = rng.dirichlet(np.ones(r))
        Pi = rng.dirichlet(np.ones(r), size=r)
        mixed, c = imm_mix(IMMState(CVBatch(x, P), mu), Pi)
        x0, P0, cc, w = np.empty((r, n)), np.empty((r, n, n)), np.empty(r), np.empty((r, r))
        # The 2D and 3D forms (P read as its upper triangle: every stage leaves it symmetric)
        forms = [(k.mix_2d, k.combine_2d) if n == 4 else (k.mix_3d, k.combine_3d)]
        for mix, combine in forms:
            mix(x, P, mu, Pi, x0, P0, cc, w)
            assert close(c, cc) and close(mixed.x, x0) and close_cov(mixed.P, P0)
            assert np.array_equal(P0, P0.mT)
            xc, Pc = np.empty(n), np.empty((n, n))
            combine(x, P, mu, xc, Pc)
            want = imm_combine(CVBatch(x, P), mu)
            assert close(want.x, xc) and close_cov(want.P, Pc) and np.array_equal(Pc, Pc.T)
    for ll in (
        [-3.0, -900.0, -4.5][:r],
        [np.nan, -2.0, -1.0][:r],
        [-np.inf, np.inf, -7.0][:r],
        [np.nan] * r,
    ):
        prior = rng.dirichlet(np.ones(r))
        got = np.empty(r)
        k.mode_probabilities(prior, np.array(ll), got)
        assert np.all(np.abs(got - mode_probabilities(prior, np.array(ll))) <= TOL), ll


@pytest.mark.parametrize("three_d", [False, True], ids=["2d", "3d"])
@pytest.mark.parametrize("block", [1, 7, 4096])
def test_the_compiled_imm_equals_the_numpy_engine(three_d: bool, block: int) -> None:
    plots = scene(three_d)
    ref, ref_rows, ref_mon = tracked(plots, three_d, "numpy", block, model="imm")
    fast, rows, mon = tracked(plots, three_d, "compiled", block, model="imm")
    assert (ref.engine, fast.engine) == ("numpy", "compiled")
    assert fast.targets == ref.targets
    spread = rounding_spread(plots, three_d, ref_rows, model="imm")
    assert_rows_within_rounding(ref_rows, rows, spread)
    # μ, what the combined estimates are weighted by (moved well away from its start), to
    # TOL where the scene keeps the rounding below it.
    mus = []
    for t in ref.targets:
        for m in ref.methods:
            want, got = _mu(ref, m, t), _mu(fast, m, t)
            tol = max(TOL, SPREAD_FACTOR * max(spread[m]))
            assert np.all(np.abs(want - got) <= tol), (t, m)
            mus.append(want)
    start = StreamOptions(model="imm").motion().initial_probabilities()
    assert np.max(np.abs(np.array(mus) - start)) > 0.05
    assert_same_monitor(
        ref_mon, mon, max(TOL, SPREAD_FACTOR * max(max(v) for v in spread.values()))
    )


@pytest.mark.parametrize("three_d", [False, True], ids=["2d", "3d"])
def test_a_target_of_many_is_bit_for_bit_its_plots_alone_with_the_imm(three_d: bool) -> None:
    plots = scene(three_d, targets=3)
    methods = METHODS_3D if three_d else ALL_METHODS
    _, rows, _ = tracked(plots, three_d, "compiled", 50, model="imm")
    options = StreamOptions(model="imm")
    for name in ("T0", "T1", "T2"):
        own = [p for p in plots if p.target == name]
        tracker = StreamTracker(methods, three_d, options)
        alone = tracker.add_block(own)
        assert tracker._compiled is not None  # the IMM on the compiled engine, one target
        mine = [r for p, r in zip(plots, rows, strict=True) if p.target == name]
        for a, b in zip(alone, mine, strict=True):
            for (_, xa, Pa), (_, xb, Pb) in zip(a, b, strict=True):
                assert np.array_equal(xa, xb) and np.array_equal(Pa, Pb)


def uneven_scene(three_d: bool) -> list[Plot]:
    """``scene`` of 12 targets with 9 of them cut to their first few plots (one to three):
    most plots belong to three targets, so the split's groups are far from one target per
    thread and a block holds slots of one plot next to slots of many."""
    keep = {f"T{k}": 1 + k % 3 for k in range(3, 12)}
    plots, seen = [], dict.fromkeys(keep, 0)
    for p in scene(three_d, targets=12):
        if p.target in keep:
            seen[p.target] += 1
            if seen[p.target] > keep[p.target]:
                continue
        plots.append(p)
    return plots


@pytest.fixture
def split(monkeypatch: pytest.MonkeyPatch) -> Callable[[bool], list[int]]:
    """``split(on)``: every block of two or more targets split between the threads (on), or
    none (off), whatever the machine's cores; returns the list the split blocks' sizes are
    appended to (a check that the route was taken)."""
    sizes: list[int] = []
    run_split = compiled._run_split

    def spy(run, rows, halves, outs):  # type: ignore[no-untyped-def]
        sizes.append(sum(h.size for h in halves))
        return run_split(run, rows, halves, outs)

    def set_split(on: bool) -> list[int]:
        monkeypatch.setattr(compiled, "SPLIT_STEPS", 1 if on else 10**12)
        monkeypatch.setattr(compiled, "_cores", lambda: 2)
        monkeypatch.setattr(compiled, "_run_split", spy)
        return sizes

    return set_split


def monitor_text(mon: ConsistencyMonitor) -> str:
    """The monitor's records and events, exactly (``repr`` of the floats: every bit)."""
    return repr((sorted(mon.results().items()), mon.events))


@pytest.mark.parametrize("model", ["cv", "imm"])
@pytest.mark.parametrize("three_d", [False, True], ids=["2d", "3d"])
@pytest.mark.parametrize("uneven", [False, True], ids=["even", "uneven"])
def test_a_split_block_is_the_one_thread_block_bit_for_bit(
    split: Callable[[bool], list[int]], three_d: bool, model: str, uneven: bool
) -> None:
    plots = uneven_scene(three_d) if uneven else scene(three_d, targets=12)
    split(False)
    _, ref_rows, ref_mon = tracked(plots, three_d, "compiled", 40, model=model)
    sizes = split(True)
    _, rows, mon = tracked(plots, three_d, "compiled", 40, model=model)
    assert len(sizes) == -(-len(plots) // 40)  # every block split
    for a, b in zip(ref_rows, rows, strict=True):
        for (m, xa, Pa), (_, xb, Pb) in zip(a, b, strict=True):
            assert xa.tobytes() == xb.tobytes() and Pa.tobytes() == Pb.tobytes(), m
    assert monitor_text(ref_mon) == monitor_text(mon)
    assert sum(r.updates for r in ref_mon.results().values()) > 0


@pytest.mark.parametrize("later_first", [False, True], ids=["bad-in-first", "bad-in-second"])
def test_a_plot_out_of_order_in_a_split_block_is_named_as_in_one_thread(
    split: Callable[[bool], list[int]], later_first: bool
) -> None:
    """A block with a plot out of order in each group: the error names the first in block
    order (of the first group or of the second), and the monitor holds the updates of the
    plots before it only, as on one thread."""
    plots = scene(True, targets=12)[:120]
    halves = compiled._halves(plot_block(plots).target)
    assert halves is not None
    # Two plots out of order, one in each group, the earlier one in the first group or in
    # the second (``later_first``): the first group's kernel then runs past the second's.
    early, late = (halves[1], halves[0]) if later_first else halves
    first = int(early[early.size // 2])
    second = int(late[np.searchsorted(late, first + 5)])
    bads = (first, second)
    for i in bads:
        previous = max(j for j in range(i) if plots[j].target == plots[i].target)
        plots[i] = replace(plots[i], time_s=plots[previous].time_s - 0.5)
    errors, texts = [], []
    for on in (False, True):
        sizes = split(on)
        monitor = ConsistencyMonitor(3)
        options = StreamOptions(sigma_a_mps2=1.0, monitor=monitor)
        tracker = TargetTracker(METHODS_3D, True, options)
        with pytest.raises(PlotError) as exc:
            tracker.add_block(plots)
        errors.append((exc.value.index, str(exc.value)))
        texts.append(monitor_text(monitor))
        assert len(sizes) == int(on)
    assert errors[0] == errors[1] and errors[0][0] == first != second
    assert texts[0] == texts[1] and monitor.results()


def test_the_halves_are_disjoint_balanced_and_in_order() -> None:
    rng = np.random.default_rng(7)
    slot = rng.choice(50, size=2000, p=rng.dirichlet(np.ones(50) * 0.3))
    halves = compiled._halves(slot)
    assert halves is not None
    a, b = halves
    assert np.array_equal(np.sort(np.concatenate(halves)), np.arange(slot.size))
    assert np.all(np.diff(a) > 0) and np.all(np.diff(b) > 0)  # block order
    assert not set(slot[a]) & set(slot[b])  # no target in both
    # The groups differ by at most the plots of the target that straddles the middle.
    assert abs(a.size - b.size) <= np.bincount(slot).max()
    assert compiled._halves(np.zeros(10, dtype=np.intp)) is None  # one target


def _read_tracks(path: Path) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert rows and tuple(k for k in rows[0] if k != "target") == TRACK_COLUMNS
    return [(r["target"], r["method"], *state_from_row(r)) for r in rows]


@pytest.mark.parametrize("model", ["cv", "imm"])
@pytest.mark.parametrize("three_d", [False, True], ids=["2d", "3d"])
def test_the_block_file_path_equals_the_plots_tracked_one_by_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, three_d: bool, model: str
) -> None:
    plots = scene(three_d, targets=3)
    if not three_d:  # the file's sites come from the radars file: one radar per site here
        plots = [replace(p, radar=f"R{_SITES.index(p.site)}") for p in plots]
    meas, radars, out = tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "t.csv"
    _, radar_list = fusion_plots(steps=2) if three_d else prosov_plots()
    if not three_d:
        base = radar_list[0]
        radar_list = [
            replace(
                base,
                name=f"R{g}",
                x_m=s[0],
                y_m=s[1],
                z_m=s[2],
                sigma_r_m=base.sigma_r_m * (1.0 + 0.5 * g),
                sigma_beta_deg=base.sigma_beta_deg * (1.0 + 0.25 * g),
                sigma_vr_mps=1.0 + g,
            )
            for g, s in enumerate(_SITES)
        ]
    write_measurements(str(meas), str(radars), plots, radar_list)
    text = meas.read_text().splitlines(keepends=True)
    # A quoted label, blank lines: left to the row reader, in their blocks only.
    text[5] = text[5].replace(",T", ',"T')[:-1].rstrip() + '"\n' if not three_d else text[5]
    text.insert(9, "\n")
    meas.write_text("".join(text))
    monkeypatch.setattr(plot_blocks, "BLOCK_BYTES", 700)
    args = ["track", "--input", str(meas), "--radars", str(radars), "--out", str(out)]
    # cv with σa = 1 m/s², or the command's default: the IMM (``DEFAULT_IMM``); either on the
    # compiled engine (every block through CompiledTracks, of the model asked for).
    flags = ["--model", "cv", "--sigma-a", "1"] if model == "cv" else []
    blocks: list[bool] = []
    add = CompiledTracks.add

    def spy(self: CompiledTracks, block: PlotBlock) -> TrackBlock:
        blocks.append(self.imm is not None)
        return add(self, block)

    monkeypatch.setattr(CompiledTracks, "add", spy)
    assert main([*args, *flags]) == 0
    assert len(blocks) > 1 and set(blocks) == {model == "imm"}
    got = _read_tracks(out)
    # The reference: the plots as the row reader gives them, one Plot at a time, on numpy.
    from radarviz.viz_app.io.plots import PlotReader, load_radars

    with open(meas, encoding="utf-8", newline="") as fh:
        read = [p for _, p in PlotReader(fh, str(meas), load_radars(str(radars)))]
    options = StreamOptions(sigma_a_mps2=1.0, engine="numpy", model=model)
    tracker = TargetTracker(METHODS_3D if three_d else ALL_METHODS, three_d, options)
    want = [
        (p.target, row)
        for p, rows in zip(read, tracker.add_block(read), strict=True)
        for row in rows
    ]
    assert len(got) == len(want)
    spread: dict[str, tuple[float, float]] = {}
    if model == "imm":  # the IMM's 2D tracks of this scene amplify rounding (rounding_spread)
        _, ref_rows, _ = tracked(read, three_d, "numpy", 4096, model=model)
        spread = rounding_spread(read, three_d, ref_rows, model=model)
    for (t, m, x, P), (tw, (mw, xw, Pw)) in zip(got, want, strict=True):
        assert (t, m) == (tw, mw)
        if model == "cv":
            assert close(xw, x) and close(Pw, P)
        else:
            tol_x, tol_P = (max(TOL, SPREAD_FACTOR * v) for v in spread[m])
            assert _x_change(xw, x) <= tol_x and _cov_change(Pw, P) <= tol_P, m


@pytest.mark.parametrize(
    "bad, message",
    [
        ("range_m", "line 40, column range_m: must be a finite number in (0, "),
        ("time", "line 40, column time_s: must not be before the previous time of target"),
        ("radar", "line 40, column radar: unknown radar"),
    ],
)
def test_an_error_in_a_later_block_names_its_line(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    bad: str,
    message: str,
) -> None:
    plots = scene(False, targets=2)
    plots = [replace(p, site=(0.0,) * 3, radar="radar", radial_velocity_mps=None) for p in plots]
    meas, radars, out = tmp_path / "m.csv", tmp_path / "r.toml", tmp_path / "t.csv"
    write_measurements(str(meas), str(radars), plots, prosov_plots()[1])
    lines = meas.read_text().splitlines(keepends=True)
    cells = lines[39].split(",")
    if bad == "range_m":
        cells[2] = "-5"
    elif bad == "radar":
        cells[1] = "nowhere"
    else:  # before that target's previous plot
        target = cells[-1].strip()
        prev = next(ln for ln in reversed(lines[1:39]) if ln.strip().endswith(target))
        cells[0] = repr(float(prev.split(",")[0]) - 1.0)
    lines[39] = ",".join(cells)
    meas.write_text("".join(lines))
    monkeypatch.setattr(plot_blocks, "BLOCK_BYTES", 500)
    args = ["track", "--input", str(meas), "--radars", str(radars), "--out", str(out)]
    assert main([*args, "--model", "cv"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{meas} {message}" in err[0], err
    assert not out.exists()


def assert_pyarrows_text(x: np.ndarray) -> None:
    """The compiled formatter's text of the finite doubles ``x`` is pyarrow's CSV writer's,
    byte for byte (the first value that differs named)."""
    import io

    import pyarrow as pa
    import pyarrow.csv as pcsv

    from radarviz.viz_app.io.csv_text import format_doubles

    x = np.ascontiguousarray(x[np.isfinite(x)], dtype=np.float64)
    buf = np.empty(26 * x.size + 64, dtype=np.uint8)
    ours = bytes(buf[: format_doubles(x.view(np.uint64), buf)])
    sink = io.BytesIO()
    options = pcsv.WriteOptions(include_header=False)
    pcsv.write_csv(pa.table({"v": x}), sink, write_options=options)
    theirs = sink.getvalue()
    if ours != theirs:  # name the first value that differs
        for v, a, b in zip(x, ours.split(b"\n"), theirs.split(b"\n"), strict=False):
            assert a == b, (v, a, b)
    assert ours == theirs


def test_the_compiled_number_text_is_pyarrows_byte_for_byte() -> None:
    """``viz_app.io.csv_text`` against pyarrow's CSV writer on 10⁶ doubles: random bit
    patterns (every exponent, subnormals), the magnitudes of tracks, integers, short
    decimals, and the edges of the positional range (10⁻⁷ … 10¹⁰), ±0, the extremes."""
    rng = np.random.default_rng(3)
    edges = [10.0**k * f for k in range(-8, 12) for f in (1.0, 9.999999999999, 1.5)]
    x = np.concatenate(
        [
            rng.integers(0, 2**64, 400_000, dtype=np.uint64).view(np.float64),
            rng.normal(size=200_000) * 1e5,
            np.exp(rng.uniform(-745, 709, 200_000)),
            rng.integers(-(10**9), 10**9, 100_000).astype(np.float64),
            np.round(rng.normal(size=100_000) * 1e4, 3),
            np.array([0.0, -0.0, 5e-324, 2.2250738585072014e-308, 1.7976931348623157e308]),
            np.array(edges + [-v for v in edges]),
        ]
    )
    assert_pyarrows_text(x)


def _neighbours(v: np.ndarray, ulps: int) -> np.ndarray:
    """v and the doubles up to ``ulps`` steps below and above each (the finite ones)."""
    bits = v[np.isfinite(v) & (v > 0)].view(np.int64)
    steps = np.arange(-ulps, ulps + 1, dtype=np.int64)
    out = (bits[:, None] + steps[None, :]).ravel()
    return out[out > 0].view(np.float64)


def _short_decimals(rng: np.random.Generator, count: int) -> np.ndarray:
    """The doubles nearest to ``count`` decimals of 1 … 17 random digits, the first digit's
    place 10^X for X = −9 … 12 (Python's float of the text: correctly rounded)."""
    n = rng.integers(1, 18, count)
    first = rng.integers(-9, 13, count)
    m = rng.integers(10 ** (n - 1), 10**n)
    places = (first - n + 1).tolist()
    return np.array([float(f"{a}e{b}") for a, b in zip(m.tolist(), places, strict=True)])


def test_the_number_text_is_pyarrows_on_ten_million_doubles() -> None:
    """The same on 1.1·10⁷ doubles, a block of 10⁶ at a time, chosen where a formatter errs:
    random bit patterns; subnormals (random, and the 10⁴ smallest, whose digits are few);
    powers of ten and of two (where the spacing of doubles changes) with 3 doubles either
    side; integers up to 2⁵³ (uniform in their logarithm) and next to 2⁵³; numbers of every
    digit count 1 … 17 at every exponent −9 … 12 and their neighbours (the positional range
    −6 ≤ X ≤ 9 and past it either side); the magnitudes of tracks and short decimals; each
    also negated in part. Every case of the layout and of the digit search is met many
    times over: the distinct cases (X, digit count, sign) number about 20·17·2."""
    rng = np.random.default_rng(17)
    e10 = np.arange(-323, 309)
    powers = np.concatenate([10.0 ** e10.astype(np.float64), np.ldexp(1.0, np.arange(-1074, 1024))])
    blocks = [
        rng.integers(0, 2**64, 3_000_000, dtype=np.uint64).view(np.float64),
        rng.integers(1, 2**52, 500_000, dtype=np.uint64).view(np.float64),  # subnormals
        np.arange(1, 10_001, dtype=np.uint64).view(np.float64),
        _neighbours(powers, 3),
        np.floor(2.0 ** rng.uniform(0, 53, 1_000_000)),
        2.0**53 - np.arange(0, 100_000, dtype=np.float64),
        _neighbours(_short_decimals(rng, 500_000), 1),
        rng.normal(0, 3e4, 1_500_000),
        rng.lognormal(3, 4, 1_500_000),
        np.round(rng.normal(size=1_000_000) * 1e4, 3),
    ]
    x = np.concatenate(blocks)
    x.view(np.uint64)[rng.random(x.size) < 0.3] ^= np.uint64(1 << 63)  # the sign bit
    assert x.size >= 10_000_000
    for start in range(0, x.size, 1_000_000):
        assert_pyarrows_text(x[start : start + 1_000_000])


@pytest.mark.parametrize("n", [4, 6])
def test_first_bad_row_is_the_first_non_finite_or_negative_variance_row(n: int) -> None:
    """The writer's compiled check against the array route (isfinite over x and P, the
    diagonal of P not negative): the same first row, on blocks with NaN, ±inf, negative
    variances, negative off-diagonal entries (allowed) and clean blocks."""
    from radarviz.viz_app.io.csv_text import first_bad_row

    rng = np.random.default_rng(11)
    for trial in range(200):
        rows = int(rng.integers(1, 40))
        x = rng.normal(size=(rows, n))
        P = np.abs(rng.normal(size=(rows, n * n)))
        P[:, 1] = -P[:, 1]  # an off-diagonal entry may be negative
        for _ in range(int(rng.integers(0, 3))):
            r = int(rng.integers(rows))
            which = rng.integers(4)
            if which == 0:
                x[r, rng.integers(n)] = np.nan
            elif which == 1:
                P[r, rng.integers(n * n)] = np.inf
            elif which == 2:
                i = int(rng.integers(n))
                P[r, i * n + i] = -1e-9
            else:
                x[r, rng.integers(n)] = -np.inf
        diag = P[:, :: n + 1]
        good = np.isfinite(x).all(axis=1) & np.isfinite(P).all(axis=1) & (diag >= 0).all(axis=1)
        expected = -1 if good.all() else int(np.flatnonzero(~good)[0])
        assert first_bad_row(x, P) == expected, trial
