"""How well an association kept simulated targets, from each plot's origin and its track.

For a simulation, every plot's origin (a target index, or ``CLUTTER`` for a false plot) is
known, and the association gave every plot a track id; the tracks ever confirmed are known
too. The figures (``plot_scores``):

* a confirmed track *holds* target i when i is the origin of most of its target plots
  (clutter plots do not count towards a target; a confirmed track of clutter alone is a
  false track);
* **tracks per target**: confirmed tracks holding a target, over the targets that have
  plots (1 is perfect; each break of a track and each duplicate adds);
* **targets never held**: the fraction of targets with plots that no confirmed track holds;
* **target plots outside confirmed tracks**: the fraction of target plots whose track was
  never confirmed;
* **purity**: over the confirmed tracks' plots, the fraction whose origin is their track's
  target (clutter taken into a track counts against it).
"""

from __future__ import annotations

from collections import Counter
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

#: The origin of a false plot.
CLUTTER = -1


class PlotScores(NamedTuple):
    """The figures of the module docstring."""

    tracks_per_target: float
    targets_never_held: float
    target_plots_outside: float
    purity: float
    false_tracks: int
    targets: int


def plot_scores(origin: NDArray[np.intp], track: list[str], confirmed: set[str]) -> PlotScores:
    """The scores of an association (module docstring).

    Args:
        origin: (P,) each plot's target index, or ``CLUTTER``.
        track: (P,) each plot's track id.
        confirmed: the ids of the tracks ever confirmed.
    """
    origin = np.asarray(origin)
    by_track: dict[str, Counter[int]] = {}
    for o, t in zip(origin.tolist(), track, strict=True):
        by_track.setdefault(t, Counter())[o] += 1
    targets = {int(o) for o in origin.tolist() if o != CLUTTER}
    held: Counter[int] = Counter()
    right = total = false = 0
    for t in confirmed:
        c = by_track.get(t)
        if not c:
            continue
        real = {o: n for o, n in c.items() if o != CLUTTER}
        total += sum(c.values())
        if not real:
            false += 1
            continue
        best = max(real, key=lambda o: real[o])
        held[best] += 1
        right += real[best]
    on_target = origin != CLUTTER
    inside = np.array([t in confirmed for t in track], dtype=bool)
    n = max(len(targets), 1)
    return PlotScores(
        tracks_per_target=sum(held.values()) / n,
        targets_never_held=len(targets - set(held)) / n,
        target_plots_outside=float(np.mean(~inside[on_target])) if on_target.any() else 0.0,
        purity=right / total if total else 1.0,
        false_tracks=false,
        targets=len(targets),
    )
