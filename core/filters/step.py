"""One plot's filtering step for a constant-velocity batch: predict, then each measurement
stage (``core.filters.measurement``) in turn, with the innovation statistics on the way.

The IMM's step is ``core.filters.imm.imm_step``; both take the same stages, so a method's
update is written once (``core.filters.methods``) and used by either motion model.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.innovation import InnovationStats
from radarviz.core.filters.predict import cv_predict
from radarviz.core.filters.state import CVBatch


def moves(dt_s: float | NDArray[np.float64]) -> bool:
    """Whether a step of ``dt_s`` (s; one, or one per track) predicts at all (some dt > 0)."""
    return bool(np.any(np.asarray(dt_s) > 0))


class Stage(Protocol):
    """A measurement stage of one plot (``core.filters.measurement``)."""

    def innovation(self, state: CVBatch, models: bool = False) -> InnovationStats: ...

    def update(self, state: CVBatch, models: bool = False) -> CVBatch: ...


def cv_step(
    state: CVBatch,
    dt_s: float | NDArray[np.float64],
    sigma_a_mps2: float,
    stages: Sequence[Stage],
    with_stats: bool = True,
) -> tuple[CVBatch, InnovationStats | None]:
    """Predict over ``dt_s`` (0: no prediction, two plots at one time) and apply ``stages``.

    ``dt_s`` may be one step per track (an array broadcasting against the batch shape, as
    ``cv_predict`` takes it); a track whose step is 0 is then predicted over 0 s, unchanged.

    Returns the posterior and, with ``with_stats``, the plot's innovation statistics (the sum
    over its stages, each taken on the state the stage updates: ``core.filters.innovation``).
    """
    pred = cv_predict(state, dt_s, sigma_a_mps2) if moves(dt_s) else state
    total: InnovationStats | None = None
    for stage in stages:
        if with_stats:
            s = stage.innovation(pred)
            total = s if total is None else total + s
        pred = stage.update(pred)
    return pred, total
