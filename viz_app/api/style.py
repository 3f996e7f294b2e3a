"""The shared palette for your own figures: the colours the viewer and the CLI's figures use.

``use_palette()`` makes matplotlib draw unnamed series in the palette's order (Okabe & Ito,
readable under the common forms of colour blindness); ``colour("ucm")`` is a method's (or a
radar's, the truth's, …) colour as ``#rrggbb``, the same as in the viewer.
"""

from __future__ import annotations

from radarviz.viz_app.palette import METHOD_COLOURS, OTHER_COLOURS, hex_colour, rgb


def colour(name: str) -> str:
    """The palette colour of a method (``naive``, ``seed``, …, ``ukf``) or another named thing
    (``truth``, ``measurement``, ``band``, ``range_only``, ``range_doppler``, ``imm``, …) as
    ``#rrggbb``, for matplotlib's ``color=``.

    Raises:
        ParameterError: ``name`` is not in the palette.
    """
    from radarviz.core.params import ParameterError

    if name not in METHOD_COLOURS and name not in OTHER_COLOURS:
        known = ", ".join([*METHOD_COLOURS, *OTHER_COLOURS])
        raise ParameterError(f"name must be one of {known} (got {name!r})", "name")
    return hex_colour(rgb(name))


def use_palette() -> None:
    """Set matplotlib's colour cycle to the palette's series order (the figures' and the
    viewer's radars: blue, vermillion, bluish green, orange, …), for every later figure."""
    import matplotlib as mpl
    from cycler import cycler

    from radarviz.viz_app.figures.common import PALETTE

    mpl.rcParams["axes.prop_cycle"] = cycler(color=list(PALETTE))
