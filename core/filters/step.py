"""One plot's filtering step for a constant-velocity batch: predict, then each measurement
stage (``core.filters.measurement``) in turn, with the innovation statistics on the way.

The IMM's step is ``core.filters.imm.imm_step``; both take the same stages, so a method's
update is written once (``core.filters.methods``) and used by either motion model.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from radarviz.core.filters.innovation import InnovationStats
from radarviz.core.filters.predict import cv_predict
from radarviz.core.filters.state import CVBatch


class Stage(Protocol):
    """A measurement stage of one plot (``core.filters.measurement``)."""

    def innovation(self, state: CVBatch, models: bool = False) -> InnovationStats: ...

    def update(self, state: CVBatch, models: bool = False) -> CVBatch: ...


def cv_step(
    state: CVBatch,
    dt_s: float,
    sigma_a_mps2: float,
    stages: Sequence[Stage],
    with_stats: bool = True,
) -> tuple[CVBatch, InnovationStats | None]:
    """Predict over ``dt_s`` (0: no prediction, two plots at one time) and apply ``stages``.

    Returns the posterior and, with ``with_stats``, the plot's innovation statistics (the sum
    over its stages, each taken on the state the stage updates: ``core.filters.innovation``).
    """
    pred = cv_predict(state, dt_s, sigma_a_mps2) if dt_s > 0 else state
    total: InnovationStats | None = None
    for stage in stages:
        if with_stats:
            s = stage.innovation(pred)
            total = s if total is None else total + s
        pred = stage.update(pred)
    return pred, total
