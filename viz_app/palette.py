"""The one categorical palette of radarviz: the viewer, the figures and the panel use it.

Okabe & Ito's eight colours ("Color Universal Design", 2008) stay distinguishable under the
common forms of colour blindness. There are seven methods and seven non-black colours, so each
method owns one; black is the truth. Radars take the same seven colours in their own order
(radars and methods never share a view). The finite-memory variants reuse two method colours
in views of their own.

A name keeps its colour everywhere: ``rgb(name)`` for Rerun and Viser (0–255 triples),
``hex_colour(name)`` for matplotlib.
"""

from __future__ import annotations

#: Okabe–Ito, as 0–255 RGB.
OKABE_ITO: dict[str, tuple[int, int, int]] = {
    "black": (0, 0, 0),
    "orange": (230, 159, 0),
    "sky_blue": (86, 180, 233),
    "bluish_green": (0, 158, 115),
    "yellow": (240, 228, 66),
    "blue": (0, 114, 178),
    "vermillion": (213, 94, 0),
    "reddish_purple": (204, 121, 167),
}

#: Method → colour. The naive conversion (biased) is the warm vermillion; its debiased
#: rivals are the blues and greens; the linearised filters (EKF, UKF) purple and yellow.
METHOD_COLOURS: dict[str, tuple[int, int, int]] = {
    "naive": OKABE_ITO["vermillion"],
    "seed": OKABE_ITO["blue"],
    "cmkf_d": OKABE_ITO["sky_blue"],
    "ucm": OKABE_ITO["bluish_green"],
    "ducm": OKABE_ITO["orange"],
    "ekf": OKABE_ITO["reddish_purple"],
    "ukf": OKABE_ITO["yellow"],
}

#: The order radars take colours in (the Gorshkov presets RLS1 … RLS6, the fusion radars
#: R1 … R4, or the radars of a measurement file in file order).
RADAR_SEQUENCE: tuple[tuple[int, int, int], ...] = (
    OKABE_ITO["blue"],
    OKABE_ITO["vermillion"],
    OKABE_ITO["bluish_green"],
    OKABE_ITO["orange"],
    OKABE_ITO["reddish_purple"],
    OKABE_ITO["sky_blue"],
    OKABE_ITO["yellow"],
)

#: Other named things drawn in several places.
OTHER_COLOURS: dict[str, tuple[int, int, int]] = {
    "truth": OKABE_ITO["black"],
    "measurement": (110, 110, 110),
    "band": (150, 150, 150),
    "range_only": OKABE_ITO["vermillion"],
    "range_doppler": OKABE_ITO["blue"],
    "fused": OKABE_ITO["reddish_purple"],
    # Motion models (the manoeuvre scene).
    "cv-q0": OKABE_ITO["vermillion"],
    "imm": OKABE_ITO["blue"],
}

FALLBACK: tuple[int, int, int] = (100, 100, 100)


def rgb(name: str) -> tuple[int, int, int]:
    """The colour of a method or other named thing (grey for an unknown name)."""
    return METHOD_COLOURS.get(name) or OTHER_COLOURS.get(name) or FALLBACK


def radar_rgb(index: int) -> tuple[int, int, int]:
    """The colour of the ``index``-th radar of a scene (cycling after seven)."""
    return RADAR_SEQUENCE[index % len(RADAR_SEQUENCE)]


def hex_colour(c: tuple[int, int, int]) -> str:
    """``#rrggbb`` for matplotlib."""
    return "#{:02x}{:02x}{:02x}".format(*c)


#: Radar colours once every palette colour is taken by something else in the view: dark to
#: light greys (a radar's label names it).
RADAR_GREYS: tuple[tuple[int, int, int], ...] = ((60, 60, 60), (105, 105, 105), (150, 150, 150))


def radar_rgb_avoiding(index: int, avoid: list[tuple[int, int, int]]) -> tuple[int, int, int]:
    """The ``index``-th radar's colour in a view that also draws the colours ``avoid`` (its
    methods or motion models): the radar sequence without them, so a radar never looks like
    a method; greys (cycling) when no colour is left over."""
    free = [c for c in RADAR_SEQUENCE if c not in set(avoid)]
    return free[index] if index < len(free) else RADAR_GREYS[(index - len(free)) % 3]


#: Colours of tracks told apart by their ids (one method, many targets): the palette's seven
#: colours, then darker shades of them.
TRACK_SEQUENCE: tuple[tuple[int, int, int], ...] = RADAR_SEQUENCE + tuple(
    (r * 3 // 5, g * 3 // 5, b * 3 // 5) for r, g, b in RADAR_SEQUENCE
)


def track_rgb(ordinal: int) -> tuple[int, int, int]:
    """The colour of the ``ordinal``-th track (in order of appearance), cycling after 14."""
    return TRACK_SEQUENCE[ordinal % len(TRACK_SEQUENCE)]
