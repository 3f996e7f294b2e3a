"""The 2D Monte Carlo filters as compiled loops (numba), blocks of runs side by side.

The numpy engine (``core.filters.methods`` and the update modules) evaluates each scan as a
few hundred vector operations over the whole batch. At the tuning panel's few hundred runs
that is all call overhead (~1 ms per scan and method group); at 10⁴–10⁵ runs it streams
every intermediate through memory. This module runs the *same equations* as one compiled
loop over blocks of a few hundred runs and their scans, a block's states held as structure
of arrays in cache and each step vectorised over the block's runs
(``core.filters.kernels_2d``):

=========  =======================================================================
kind       the lines it mirrors
=========  =======================================================================
start      ``Method.start`` → ``start_from_parts`` → ``cv_init``
predict    ``core.filters.predict.cv_predict`` (F P Fᵀ + Q, white-noise acceleration)
converted  ``core.conversion.planar`` (the five conversions) →
           ``core.filters.position.innovation_update`` (Joseph form as products)
ekf        ``core.filters.polar_ekf.ekf_update`` (ν' = J ν, R' = J R Jᵀ, then Joseph)
ukf        ``core.filters.polar_ukf.ukf_update`` (Van der Merwe points, Cholesky of P⁻)
doppler    ``core.filters.doppler.doppler_update`` (after any of them, when V̂r is given)
=========  =======================================================================

The numpy engine stays the reference: ``tests/test_compiled.py`` checks every method against
it to 1e-9 relative, including a track whose covariance has lost definiteness (NaN there,
as in numpy). The arithmetic is the same but not in the same order, so results agree to
rounding, not bit for bit.

numba is imported on first use, and the compiled kernel is cached on disk
(``cache=True``), so commands that never filter a Monte Carlo pay nothing and later runs
load the kernel instead of compiling it (the first ever call compiles for a few seconds).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.confidence import BAND_GROUPS
from radarviz.core.filters.kernel_args import (
    FilterOptions,
    RunStates,
    ScanMeasurements,
    TermSums,
)
from radarviz.core.filters.methods import METHODS, conversion_table, method_plan
from radarviz.core.filters.polar_ukf import UKFParams
from radarviz.core.filters.state import CVBatch
from radarviz.core.filters.terms import SUM_NAMES

#: The methods the compiled Monte Carlo runs: every registered 2D method (the kernel reads a
#: method only through ``method_plan`` and ``conversion_table``).
COMPILED_METHODS: tuple[str, ...] = tuple(n for n, m in METHODS.items() if 2 in m.dims)
#: Chunks of fewer scans read the measurements scan-major (``filter_scans``).
SCAN_MAJOR_BELOW = 8
#: The Monte Carlo engines an experiment can run on: this module, or the numpy engine (the
#: reference the tests hold this one to).
ENGINES: tuple[str, ...] = ("compiled", "numpy")


class FilterSettings(NamedTuple):
    """The scalars every track of a block shares.

    Attributes:
        sigma_r_m, sigma_beta_rad: measurement noise std σr (m), σβ (rad).
        period_s: scan period T (s).  sigma_a_mps2: process-noise acceleration std σa.
        sigma_v0_mps: initial velocity std of every track.
        site_m: the radar's (x, y) position, m.
        ukf: the UKF's sigma-point parameters.
        sigma_vr_mps: Doppler noise std σVr (m/s), used with radial velocities.
    """

    sigma_r_m: float
    sigma_beta_rad: float
    period_s: float
    sigma_a_mps2: float
    sigma_v0_mps: float
    site_m: tuple[float, float] = (0.0, 0.0)
    ukf: UKFParams = UKFParams()
    sigma_vr_mps: float = 1.0


class ScanChunk(NamedTuple):
    """Scans ``first … first + K − 1``: the states x (K, m', 4), P (K, m', 4, 4) of the runs
    that give states and, when ``filter_scans`` was asked for metric terms, their sums per
    group of runs (else None).

    Attributes:
        group_sums: (G, K, len(SUM_NAMES)) sums of the first runs' metric terms
            (``core.metrics.scan_terms``) at each scan, run j in group (offset + j) mod G,
            G = ``core.confidence.BAND_GROUPS`` (``MetricsAccumulator.add_group_sums``).

    The arrays are reused for the next chunk: copy what must be kept."""

    first: int
    x: NDArray[np.float64]
    P: NDArray[np.float64]
    group_sums: NDArray[np.float64] | None = None


class TermsRequest(NamedTuple):
    """Ask ``filter_scans`` for the sums of the metric terms (``core.metrics.scan_terms``) of
    the first ``runs`` runs per group of runs instead of their states: formed in the kernel as
    each state is, so the states of a Monte Carlo never go through memory.

    Attributes:
        runs: how many of the first runs give terms.
        truth: (N, 4) true states; los: ``core.metrics.truth_line_of_sight(truth)``.
        offset: runs already counted at these scans: run j goes to group (offset + j) mod G.
    """

    runs: int
    truth: NDArray[np.float64]
    los: tuple[NDArray[np.float64], NDArray[np.float64]]
    offset: int = 0


def filter_scans(
    method: str,
    r_hat: NDArray[np.float64],
    beta_hat: NDArray[np.float64],
    settings: FilterSettings,
    chunk_scans: int,
    *,
    radial_velocity_mps: NDArray[np.float64] | None = None,
    start: tuple[int, CVBatch] | None = None,
    terms: TermsRequest | None = None,
    states: bool = True,
) -> Iterator[ScanChunk]:
    """Filter every run's scans, ``chunk_scans`` at a time.

    Without ``start``, every track starts at scan 0 from its plot (the method's start
    conversion) and scans 1 … N − 1 follow; with ``start = (k, state)`` the (m,) batch
    ``state`` is the estimate at scan k and scans k + 1 … N − 1 follow (the Doppler-aided
    experiment's finite-memory start).

    Args:
        method: one of ``COMPILED_METHODS``.
        r_hat, beta_hat: (m, N) measured ranges (m) and azimuths (rad) of m runs.
        settings: the shared scalars.
        chunk_scans: scans per yielded chunk (≥ 1): bounds the memory to chunk × m states.
        radial_velocity_mps: (m, N) measured V̂r: after each plot's update, the Doppler update
            along the measured line of sight (``core.filters.doppler``) with σVr
            ``settings.sigma_vr_mps``.
        terms: the sums of the metric terms of the first runs instead of their states.
        states: False: the other runs give no states either (the chunks' x, P hold 0 runs):
            the filter alone, for timing it.

    Yields:
        ``ScanChunk`` s covering the filtered scans in order (a start at scan 0 included).
    """
    kernel = _kernel()
    runs, steps = np.shape(r_hat)
    begin = 0 if start is None else start[0] + 1
    k = max(1, min(int(chunk_scans), steps - begin))
    # The kernel walks blocks of runs, each over the chunk's scans, reading one scan of a
    # block's runs at a time. Over many scans the rows of a block's (m, N) arrays stay in
    # cache from scan to scan, and a transposed copy would cost more than it saves; over a
    # few, the scan-major (column-major) copy puts the block's plots side by side instead
    # (a run-major row per run and scan would cost a cache line for 8 bytes).
    layout = np.asfortranarray if k < SCAN_MAJOR_BELOW else np.ascontiguousarray
    r_runs = layout(r_hat, dtype=np.float64)
    b_runs = layout(beta_hat, dtype=np.float64)
    doppler = radial_velocity_mps is not None
    vr_runs = layout(radial_velocity_mps, dtype=np.float64) if doppler else layout(np.zeros((1, 1)))
    state = np.empty((runs, 14))  # each run's x, then the upper entries of P (row-major)
    if start is not None:
        state[:, :4] = start[1].x
        state[:, 4:] = start[1].P[:, *np.triu_indices(4)]
    n_terms = 0 if terms is None else int(terms.runs)
    kept = runs - n_terms if states else 0
    xs = np.empty((k, kept, 4))
    Ps = np.empty((k, kept, 4, 4))
    sums = np.empty((BAND_GROUPS, k, len(SUM_NAMES)))
    if terms is None:
        truth, cos_los, sin_los = np.zeros((1, 4)), np.zeros((1, 1)), np.zeros((1, 1))
        offset = 0
    else:
        truth = np.ascontiguousarray(terms.truth, dtype=np.float64)
        cos_los, sin_los = terms.los
        offset = int(terms.offset)
    s = settings
    c, wm0, wc0, w = s.ukf.weights(4)
    plan = method_plan([method])[0]
    conversions = conversion_table([method], s.sigma_r_m, s.sigma_beta_rad)[0, 0]
    plots = ScanMeasurements(r_runs, b_runs, vr_runs, doppler)
    options = FilterOptions(
        float(s.sigma_r_m),
        float(s.sigma_beta_rad),
        float(s.sigma_vr_mps),
        float(s.period_s),
        float(s.sigma_a_mps2),
        float(s.sigma_v0_mps),
        float(s.site_m[0]),
        float(s.site_m[1]),
        np.array([c, wm0, wc0, w], dtype=np.float64),
    )
    run_states = RunStates(state, states, xs, Ps)
    term_sums = TermSums(n_terms, truth, cos_los, sin_los, sums, offset)
    for first in range(begin, steps, k):
        last = min(first + k, steps)
        sums[...] = 0.0
        kernel(plan, conversions, plots, options, first, last, run_states, term_sums)
        n = last - first
        yield ScanChunk(first, xs[:n], Ps[:n], sums[:, :n] if terms is not None else None)


def filter_history(
    method: str,
    r_hat: NDArray[np.float64],
    beta_hat: NDArray[np.float64],
    settings: FilterSettings,
    **kw: Any,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Every filtered scan's states at once: x (K, m, 4) and P (K, m, 4, 4) (``filter_scans``
    in one chunk; for tests and small batches)."""
    (chunk,) = list(filter_scans(method, r_hat, beta_hat, settings, np.shape(r_hat)[1], **kw))
    return chunk.x, chunk.P


@functools.cache
def _kernel() -> Callable[..., None]:
    """The compiled kernel, compiled (or loaded from numba's cache) on first use."""
    from radarviz.core.filters.kernels_2d import filter_scans_2d

    return filter_scans_2d
