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

import copy
import uuid
from dataclasses import dataclass

import rerun as rr
import rerun.blueprint as rrb

from radarviz.core.params import check_choice
from radarviz.viz_app.rerun import gorshkov_scene, manoeuvre_scene, prosov_scene, velocity_scene
from radarviz.viz_app.rerun.preset_names import PRESETS

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


# --- narrow windows (a notebook cell) --------------------------------------------------------

#: How much page height a view takes in the stacked layout (3D scenes need more than a chart),
#: and how much one page holds: at a notebook's ~600 px, three charts of ~170 px each, which
#: is what the charts' labels are sized for.
VIEW_UNITS = {"Spatial3DView": 2}
PAGE_UNITS = 3
#: Small multiples per page in the stacked layout: two columns of two.
GRID_PAGE = 4
#: A legend's row share on a page whose content has ``PAGE_UNITS`` shares.
LEGEND_SHARE = 0.6


def _is_legend(view: object) -> bool:
    """A legend view (``shapes.legend_view``: contents ``$origin/…legend/**``)."""
    return any(str(c).endswith("legend/**") for c in getattr(view, "contents", None) or [])


def _is_container(node: object) -> bool:
    return hasattr(node, "kind") and getattr(node, "contents", None) is not None


def _units(node: object) -> int:
    if _is_container(node):
        return max(_units(k) for k in node.contents)  # type: ignore[attr-defined]
    return VIEW_UNITS.get(type(node).__name__, 1)


def _copy_view(view: object) -> object:
    """The same view under a new id: a blueprint holds each view once, and the stacked
    layout repeats a tab's legend on each of its pages."""
    twin = copy.copy(view)
    twin.id = uuid.uuid4()  # type: ignore[attr-defined]
    return twin


def _pieces(node: object) -> tuple[list[object], list[list[object]], list[object]]:
    """(legends, grids' views, other pieces) of a tab, in order. A piece is a view or a row
    of at most two views side by side (kept together: at a notebook's width each gets half);
    wider rows and columns come apart."""
    legends: list[object] = []
    grids: list[list[object]] = []
    pieces: list[object] = []

    def walk(n: object) -> None:
        if not _is_container(n):
            (legends if _is_legend(n) else pieces).append(n)
            return
        kind = str(n.kind).lower()  # type: ignore[attr-defined]
        kids = list(n.contents)  # type: ignore[attr-defined]
        if "grid" in kind:
            grids.append(kids)
        elif "horizontal" in kind and len(kids) == 2 and not any(map(_is_container, kids)):
            pieces.append(rrb.Horizontal(*kids))
        else:
            for k in kids:
                walk(k)

    walk(node)
    return legends, grids, pieces


def narrow_tabs(tab: rrb.Container) -> list[rrb.Container]:
    """One tab of a wide layout as tabs of a narrow window (about 900 px, a notebook cell):
    its views stacked on pages instead of squeezed side by side, each page holding at most
    ``PAGE_UNITS`` of height (``VIEW_UNITS``) or ``GRID_PAGE`` small multiples in two columns,
    the tab's legend repeated at the top of each page of small multiples (or of its first
    page, without any). A tab that fits one page stays whole (its views stacked)."""
    legends, grids, pieces = _pieces(tab)
    pages: list[tuple[list[object], list[float]]] = []
    for views in grids:
        for i in range(0, len(views), GRID_PAGE):
            chunk = views[i : i + GRID_PAGE]
            pages.append(([rrb.Grid(*chunk, grid_columns=min(2, len(chunk)))], [PAGE_UNITS]))
    grid_pages = len(pages)
    page: list[object] = []
    for piece in pieces:
        used = sum(_units(p) for p in page)
        if page and used + _units(piece) > PAGE_UNITS:
            pages.append((page, [float(_units(p)) for p in page]))
            page = []
        page.append(piece)
    if page:
        pages.append((page, [float(_units(p)) for p in page]))
    name = str(tab.name or "")
    short = name.split(":")[0] if len(pages) > 1 else name
    out: list[rrb.Container] = []
    # The legend tops the pages of small multiples (they name no colour themselves); pages of
    # charts, which name their curves, get their height instead, unless the tab has no grid.
    for i, (content, shares) in enumerate(pages):
        keyed = i < grid_pages or (grid_pages == 0 and i == 0)
        head = [_copy_view(v) if i else v for v in legends] if keyed else []
        out.append(
            rrb.Vertical(
                *head,
                *content,
                row_shares=[LEGEND_SHARE] * len(head) + shares,
                name=f"{short} {i + 1}/{len(pages)}" if len(pages) > 1 else short,
            )
        )
    return out


def narrow_layout(layout: PresetLayout) -> PresetLayout:
    """``layout`` for a narrow window (``narrow_tabs`` of each tab), always with a tab bar."""
    tabs = [t for tab in layout.tabs for t in narrow_tabs(tab)]
    return PresetLayout(tuple(tabs), layout.timeline, tabbed=True)


def log_preset(rec: rr.RecordingStream, preset: str, seed: int = 1) -> PresetLayout:
    """Fill ``rec`` with one of the presets; returns its layout (no blueprint sent)."""
    check_choice("preset", preset, PRESETS)
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
