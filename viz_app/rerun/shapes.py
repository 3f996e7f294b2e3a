"""Drawing helpers shared by the scenes: covariance outlines, marker sizes, view transforms.

Rerun's 2D views draw y downwards (image convention). A scene that wants y up (north, or
down-range) logs a static ``Transform3D`` with a negative y scale on its root entity and puts
the view's origin one level above it, so the transform applies; positions stay in metres,
which is what hover shows.
"""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from numpy.typing import NDArray

#: Marker radii in screen points: they stay visible at any zoom.
MARKER = rr.Radius.ui_points(5.0)
SMALL_MARKER = rr.Radius.ui_points(3.0)
CLOUD_MARKER = rr.Radius.ui_points(1.5)
LINE = rr.Radius.ui_points(1.5)
THIN_LINE = rr.Radius.ui_points(0.8)

#: Points on a drawn ellipse outline.
ELLIPSE_SEGMENTS = 64


def ellipse_outline(
    centre: NDArray[np.float64], cov: NDArray[np.float64], n_sigma: float = 1.0
) -> NDArray[np.float64]:
    """Closed outlines of the nσ ellipses of 2×2 covariances: (..., ELLIPSE_SEGMENTS + 1, 2).

    With cov = L Lᵀ (Cholesky), the points c + n L (cos t, sin t) trace {x : (x − c)ᵀ cov⁻¹
    (x − c) = n²}. ``Ellipses2D`` has no rotation, hence line strips. Shapes: centre
    (..., 2), cov (..., 2, 2); a singular covariance is drawn through its eigen-decomposition.
    """
    w, v = np.linalg.eigh(cov)
    half = np.sqrt(np.clip(w, 0.0, None))  # (..., 2)
    t = np.linspace(0.0, 2.0 * np.pi, ELLIPSE_SEGMENTS + 1)
    circle = np.stack([np.cos(t), np.sin(t)], axis=-1)  # (S, 2)
    # x = c + n V diag(half) u for u on the unit circle.
    scaled = circle[..., None, :, :] * half[..., None, :]  # (..., S, 2)
    return centre[..., None, :] + n_sigma * (scaled @ np.swapaxes(v, -1, -2))


def flip_y(scale: float = 1.0) -> rr.Transform3D:
    """A transform drawing a child's (x, y) as (scale x, −scale y): y up in a 2D view."""
    return rr.Transform3D(mat3x3=np.diag([scale, -scale, 1.0]))


def pale(rgb: tuple[int, int, int], amount: float = 0.6) -> tuple[int, int, int]:
    """``rgb`` mixed with white: a cloud in a method's hue that never hides its outline."""
    return tuple(round(c + (255 - c) * amount) for c in rgb)  # type: ignore[return-value]


#: The track recording's 3D background (a solid colour: faint drawing needs a known one; the
#: viewer's own follows its theme, dark or light).
LIGHT = (250, 250, 250)
#: A faint (tentative) track's marker and path line.
FAINT_MARKER = rr.Radius.ui_points(2.5)
FAINT_LINE = rr.Radius.ui_points(0.5)


def faint(rgb: tuple[int, int, int], amount: float = 0.65) -> tuple[int, int, int]:
    """``rgb`` mixed with the background ``LIGHT``: the same hue, drawn faint.

    Rerun ignores alpha on points and lines (it darkens a point without making it
    see-through), so faintness is a mix towards the background instead."""
    mixed = (round(c + (d - c) * amount) for c, d in zip(rgb, LIGHT, strict=True))
    return tuple(mixed)  # type: ignore[return-value]


def colours(rgb: tuple[int, int, int], n: int) -> NDArray[np.uint8]:
    """``n`` copies of one colour as an (n, 3) array (Rerun converts arrays ~20× faster than
    lists of tuples, which matters for the panel's latency)."""
    return np.tile(np.asarray(rgb, dtype=np.uint8), (n, 1))


def radii(radius: float, n: int) -> NDArray[np.float32]:
    """``n`` copies of one radius (screen units stay negative, as ``rr.Radius`` encodes them)."""
    return np.full(n, float(radius), dtype=np.float32)


#: Spacing of legend swatches (drawn units) and the legend views' margin.
LEGEND_STEP = 100.0


def log_legend(
    rec: rr.RecordingStream,
    entity: str,
    labels: list[str],
    colours_: list[tuple[int, int, int]],
) -> None:
    """A legend as an entity of its own (with its y-up transform: one chunk): one labelled
    swatch per label, in a row, so a view of it (``legend_view``) names the colours without
    covering any data."""
    rec.log(
        entity,
        flip_y(1.0),
        rr.Points2D(
            [[i * LEGEND_STEP, 0.0] for i in range(len(labels))],
            radii=[MARKER],
            colors=colours_,
            labels=labels,
            show_labels=True,
        ),
        static=True,
    )


def legend_view(origin: str, entity: str, count: int, name: str) -> rrb.Spatial2DView:
    """The view of a ``log_legend`` row of ``count`` swatches at ``origin``/``entity``."""
    return rrb.Spatial2DView(
        origin=origin,
        contents=[f"$origin/{entity}/**"],
        name=name,
        visual_bounds=rrb.VisualBounds2D(
            x_range=[-0.4 * LEGEND_STEP, LEGEND_STEP * (count - 0.6)], y_range=[-10.0, 30.0]
        ),
    )
