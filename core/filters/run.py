"""The scan loop: start, then predict and update once per scan, for a whole batch.

Every Monte Carlo experiment and the benchmark run their batches through ``run_scans``; what
differs between them is only the update of one scan (a method's, or a method's plus Doppler).
"""

from __future__ import annotations

from collections.abc import Callable

from radarviz.core.filters.predict import cv_predict
from radarviz.core.filters.state import CVBatch, empty_batch

#: ``update(n, predicted, out)``: the posterior of scan n written into ``out`` (or a new batch).
ScanUpdate = Callable[[int, CVBatch, CVBatch], CVBatch]


def run_scans(
    state: CVBatch,
    steps: int,
    period_s: float,
    update: ScanUpdate,
    *,
    sigma_a_mps2: float = 0.0,
    first_scan: int = 0,
    on_scan: Callable[[int, CVBatch], None] | None = None,
) -> CVBatch:
    """Filter scans ``first_scan + 1 … steps − 1`` from ``state`` (the estimate at
    ``first_scan``); ``on_scan(n, state)`` sees the start and every filtered state.

    Two buffers: the prediction is written into one and the update into the other, every
    scan, so a long run allocates nothing per scan. A state given to ``on_scan`` is
    overwritten two scans later: copy what must be kept.
    """
    if on_scan is not None:
        on_scan(first_scan, state)
    pred_buf = empty_batch(state.batch_shape, state.dims)
    post_buf = empty_batch(state.batch_shape, state.dims)
    for n in range(first_scan + 1, steps):
        pred = cv_predict(state, period_s, sigma_a_mps2, out=pred_buf)
        state = update(n, pred, post_buf)
        if on_scan is not None:
            on_scan(n, state)
    return state
