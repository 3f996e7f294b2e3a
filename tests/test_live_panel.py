"""The live panel drives the live tracker (``viz_app.live.control``, ``viz_app.live.panel``).

A rotating-radar scene's plots go through ``track_feed`` (the tracker of ``radarviz live``)
from a queue, with a ``LiveControl`` and a ``LivePanel`` on a real guarded Viser server. After
the first runs of the tracker, the test sets the panel's controls (their server-side
handles, as a browser's change would) and checks, at the run after:

* P_G, M of N, the deletion rule and the IMM's σa: the same tracker takes them before the
  next run (its gate γ is ``gate_threshold(P_G)``, its book's and kernel's rules the new ones)
  and every track live at the change is still live when they apply (nothing dropped);
* a bad value (P_G = 1.5): the panel's error line names it, the tracker's settings stay;
* another motion model (imm → cv): a new tracker, the old tracks sent to the viewer as
  deleted, the new tracks named ``g1-<id>``;
* the methods shown: only the recorder's ``shown`` changes.

A stock tracker fed the same plots with no change gives the same tracks as the controlled one
up to the change (the control is not in the way).
"""

from __future__ import annotations

import queue
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from radarviz.core.experiments.association import rotating_scene_plots
from radarviz.core.scenarios.rotating import RotatingRadar, air_traffic, rotating_plots
from radarviz.core.tracking.association import (
    PREFILTER_MARGIN,
    AssociationOptions,
    GNNTracker,
    gate_threshold,
)
from radarviz.core.tracking.stream import Plot, StreamOptions, motion_fields
from radarviz.viz_app.live.control import LiveControl
from radarviz.viz_app.live.session import FeedCounts, track_feed

SITES = ((-30e3, 0.0), (30e3, 0.0))
#: The run after which the test changes the settings.
CHANGE_AT = 12


@dataclass
class Run:
    """What ``run_with_changes`` saw: each run's (tracker, live ids at its end), the plots
    tracked by the end of each run, every plot's track id, the ids the viewer was told are
    deleted, and (tracker, live ids) when each change applied."""

    runs: list[tuple[GNNTracker, list[str]]]
    tracked: list[int]
    ids: list[str]
    deleted: list[str]
    applied: list[tuple[GNNTracker, list[str]]]


def scene_plots(targets: int = 40, duration_s: float = 40.0) -> list[Plot]:
    """Two radars' plots of ``targets`` aircraft (some turning)."""
    radars = [
        RotatingRadar(f"r{j}", x, y, period_s=4.0 + 0.5 * j, phase_rad=1.1 * j)
        for j, (x, y) in enumerate(SITES)
    ]
    rng = np.random.default_rng(3)
    traffic = air_traffic(rng, targets, duration_s, turn_deg=30.0, turn_rate_dps=1.5)
    return rotating_scene_plots(radars, rotating_plots(rng, radars, traffic, duration_s))


def new_control() -> LiveControl:
    """A control of a tracker as ``radarviz live`` builds it (the default IMM)."""
    options = StreamOptions(**motion_fields())
    association = AssociationOptions()

    def make(o: StreamOptions, a: AssociationOptions) -> GNNTracker:
        return GNNTracker(("ucm", "ukf"), False, o, a)

    return LiveControl(make(options, association), options, association, make)


def feed(plots: list[Plot]) -> queue.Queue:
    """The plots as the reader queues them, then its end mark."""
    q: queue.Queue = queue.Queue()
    for k, p in enumerate(plots):
        q.put((0.0, k, p))
    q.put(None)
    return q


def run_with_changes(control: LiveControl, plots: list, changes: dict[int, Callable]) -> Run:
    """``track_feed`` over ``plots``, one batch a run (a budget of 1 µs); ``changes[k]`` is
    called after run k."""
    out = Run([], [], [], [], [])

    def told(c: LiveControl) -> None:
        if c.applied > len(out.applied):  # a change applied (not only submitted)
            out.applied.append((c.tracker, c.tracker.live()))

    control.listeners.append(told)

    def after_run() -> None:
        out.runs.append((control.tracker, control.tracker.live()))
        out.tracked.append(len(out.ids))
        change = changes.get(len(out.runs))
        if change is not None:
            change()

    def rows(plot: Plot, rows: list, status: str = "") -> None:
        out.ids.append(plot.target)

    track_feed(feed(plots), control, FeedCounts(), 30.0, 0.0, 1e-6, rows, out.deleted.extend,
               after_run)  # fmt: skip
    return out


@pytest.fixture(scope="module")
def server() -> Iterator[Any]:
    from radarviz.viz_app.tune.guard import PanelGuard, guarded_viser_server

    srv = guarded_viser_server(PanelGuard(), 0, verbose=False)
    yield srv
    srv.stop()


def test_a_panel_change_applies_from_the_next_run_and_keeps_the_tracks(server: Any) -> None:
    from radarviz.viz_app.live.panel import LivePanel

    plots = scene_plots()
    control = new_control()
    panel = LivePanel(server, control)

    def change() -> None:
        panel.numbers["gate_probability"].value = 0.99
        panel.numbers["confirm_m"].value = 2
        panel.numbers["confirm_n"].value = 3
        panel.numbers["delete_misses"].value = 7
        panel.imm_sigmas.value = "0.5, 4, 4, 40"
        assert panel.submit() == ""

    def bad() -> None:
        panel.numbers["gate_probability"].value = 1.5
        assert "gate_probability" in panel.submit()
        assert "gate_probability" in panel.error_md.content

    got = run_with_changes(control, plots, {CHANGE_AT: change, CHANGE_AT + 2: bad})
    panel.close()
    assert len(got.runs) > CHANGE_AT + 5 and len(got.ids) == len(plots)
    # Applied once, before the run after the change, by the same tracker, every track kept.
    assert len(got.applied) == 1
    tracker, live_then = got.applied[0]
    before, live_before = got.runs[CHANGE_AT - 1]
    assert tracker is before and live_then == live_before and live_then
    assert all(t is tracker for t, _ in got.runs)
    assert tracker.gate == pytest.approx(gate_threshold(0.99, 2))
    assert (tracker.book.m, tracker.book.n, tracker.book.kdel) == (2, 3, 7)
    assert tracker.tracker.options.imm_sigma_a_mps2 == (0.5, 4.0, 4.0, 40.0)
    assert tracker._compiled is not None
    rules = tracker._compiled.rules
    assert (rules.gate, rules.scale) == (tracker.gate, tracker.gate * PREFILTER_MARGIN)
    assert (rules.confirm_m, rules.confirm_n, rules.delete_misses) == (2, 3, 7)
    assert tracker._compiled.tracks.imm_sigma_a_mps2.tolist() == [0.5, 4.0, 4.0, 40.0]
    assert rules.q_max == pytest.approx(40.0**2)
    # The bad value changed nothing, and said so.
    assert control.settings.gate_probability == 0.99 and "gate_probability" in control.error
    # Up to the change, the tracks of a tracker left alone (the control is not in the way);
    # after it, other ones (the change took effect).
    stock = run_with_changes(new_control(), plots, {})
    cut = got.tracked[CHANGE_AT - 1]
    assert got.ids[:cut] == stock.ids[:cut] and got.ids[cut:] != stock.ids[cut:]


def test_a_new_motion_model_starts_the_tracks_again() -> None:
    plots = scene_plots(targets=20, duration_s=24.0)
    control = new_control()

    def to_cv() -> None:
        raw = {
            "model": "cv", "sigma_a_mps2": 5.0, "imm_sigma_a_mps2": "0.5, 4, 4, 40",
            "gate_probability": 0.999, "confirm_m": 3, "confirm_n": 4, "delete_misses": 5,
            "shown": ("ucm",),
        }  # fmt: skip
        assert control.submit(raw) == ""

    got = run_with_changes(control, plots, {CHANGE_AT: to_cv})
    old_tracker, old_live = got.runs[CHANGE_AT - 1]
    assert control.generation == 1 and control.tracker is not old_tracker
    assert control.tracker.model == "cv" and control.settings.shown == ("ucm",)
    assert "started again" in control.status
    assert old_live and set(old_live) <= set(got.deleted)  # the old tracks left the viewer
    cut = got.tracked[CHANGE_AT - 1]
    assert not any(t.startswith("g1-") for t in got.ids[:cut])
    assert all(t.startswith("g1-") for t in got.ids[cut:]) and got.ids[cut:]
