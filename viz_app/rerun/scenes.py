"""What each recording preset shows: the scenes it logs and the tabs it opens on.

One scene per paper, each in its own tab, never two scenes of different scale in one view:

    prosov     Prosov: converted measurements (``prosov_scene``)
    prosov3d   the same in 3D, the target frame down-range, cross-range, up with every
               method's 1σ ellipsoid (``prosov_scene.log_prosov3d``)
    gorshkov   Gorshkov: finite memory against k (charts of their own, on any timeline),
               and the Doppler-aided track start on ``scan`` (``gorshkov_scene``)
    velocity   Velocity: several radars' radial velocities (``velocity_scene``)
    manoeuvre  a manoeuvring flight, Q = 0 against the IMM, the NIS monitor
               (``manoeuvre_scene``)
    demo       all four, opening on an overview tab: the naive and a debiased method side by
               side in the target frame, the velocity vector and its error ellipsoid, the
               situations and the Doppler start's error
"""

from __future__ import annotations

from dataclasses import dataclass

import rerun as rr
import rerun.blueprint as rrb

from radarviz.viz_app.rerun import gorshkov_scene, manoeuvre_scene, prosov_scene, velocity_scene

PRESETS: tuple[str, ...] = ("demo", "prosov", "prosov3d", "gorshkov", "velocity", "manoeuvre")
#: The debiased method set beside ``naive`` in the overview.
OVERVIEW_DEBIASED = "ucm"


def text_log_view() -> rrb.TextLogView:
    return rrb.TextLogView(origin="log", name="log")


def blueprint(*tabs: rrb.Container, timeline: str = "scan") -> rrb.Blueprint:
    """Tabs (the first one open), the time panel on ``timeline``, side panels collapsed."""
    return rrb.Blueprint(
        rrb.Tabs(*tabs, active_tab=0),
        rrb.TimePanel(timeline=timeline, state="collapsed"),
        collapse_panels=True,
    )


def overview(vframe: velocity_scene.VelocityFrame) -> rrb.Container:
    """The demo's first tab: what each paper is about, at a glance."""
    v = velocity_scene.views(vframe)
    vector, error, situation = v.vector, v.error, v.situation
    return rrb.Horizontal(
        rrb.Vertical(
            prosov_scene.method_legend_view(),
            rrb.Horizontal(
                prosov_scene.method_view("naive"),
                prosov_scene.method_view(OVERVIEW_DEBIASED),
            ),
            prosov_scene.map_view(),
            gorshkov_scene.start_view(
                "rmse_vr_mps",
                "Gorshkov: radial-velocity RMSE of a Doppler-aided track start, m/s (log)",
            ),
            row_shares=[1, 6, 4, 4],
        ),
        rrb.Vertical(
            velocity_scene.radar_legend_view(vframe),
            rrb.Horizontal(vector, error),
            situation,
            row_shares=[1, 7, 7],
        ),
        column_shares=[1, 1],
        name="Overview",
    )


@dataclass(frozen=True)
class PresetLayout:
    """What a preset's blueprint is built from: its tabs (in order) and the timeline it opens
    on. ``blueprint_of`` makes a blueprint of it opening on any tab and timeline."""

    tabs: tuple[rrb.Container, ...]
    timeline: str = "scan"
    #: Where the tabs sit: the ``Tabs`` container (a tab bar) or, for one tab, the tab alone.
    tabbed: bool = True

    @property
    def names(self) -> tuple[str, ...]:
        """The tabs' names, in order (the tab bar's labels)."""
        return tuple(str(t.name) for t in self.tabs)


def blueprint_of(
    layout: PresetLayout, active_tab: int = 0, timeline: str | None = None
) -> rrb.Blueprint:
    """The blueprint of ``layout`` with tab ``active_tab`` open and the time panel on
    ``timeline`` (the layout's own unless given)."""
    root = rrb.Tabs(*layout.tabs, active_tab=active_tab) if layout.tabbed else layout.tabs[0]
    return rrb.Blueprint(
        root,
        rrb.TimePanel(timeline=timeline or layout.timeline, state="collapsed"),
        collapse_panels=True,
    )


def log_preset(rec: rr.RecordingStream, preset: str, seed: int = 1) -> PresetLayout:
    """Fill ``rec`` with one of the presets; returns its layout (no blueprint sent)."""
    tabs: list[rrb.Container] = []
    if preset in ("demo", "prosov"):
        prosov_scene.log_prosov(rec, seed=seed)
        tabs.append(prosov_scene.views(prosov_scene.METHODS_SHOWN))
    if preset == "prosov3d":
        axis = prosov_scene.log_prosov3d(rec, seed=seed)
        tabs.append(prosov_scene.views_3d(axis))
    if preset in ("demo", "velocity"):
        vframe = velocity_scene.log_velocity_scene(rec, seed=seed)
        tabs.append(velocity_scene.views(vframe).tab)
    if preset in ("demo", "gorshkov"):
        radars = gorshkov_scene.log_gorshkov(rec, seed=seed)
        k_tab, start_tab = gorshkov_scene.views(radars), gorshkov_scene.start_views()
        # The k curves are static charts: both tabs show on any timeline.
        tabs += [k_tab, start_tab] if preset == "gorshkov" else [start_tab, k_tab]
    if preset in ("demo", "manoeuvre"):
        manoeuvre_scene.log_manoeuvre(rec, seed=seed)
        tabs.append(manoeuvre_scene.views())
    if preset == "demo":
        tabs.insert(0, overview(vframe))
    tabs.append(rrb.Vertical(text_log_view(), name="log"))
    return PresetLayout(tuple(tabs))


def record_preset(rec: rr.RecordingStream, preset: str, seed: int = 1) -> PresetLayout:
    """Fill ``rec`` with one of the presets and send its blueprint (opening on its first tab);
    returns the layout."""
    layout = log_preset(rec, preset, seed)
    rec.send_blueprint(blueprint_of(layout))
    return layout
