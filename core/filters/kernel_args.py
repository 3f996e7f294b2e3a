"""The compiled kernels' arguments, packed: the tracker kernels' (``core.filters.kernels_track``,
``kernels_3d``, ``kernels_imm``) one record per plot block, radar table, options, track
state and output; the Monte Carlo kernel's (``core.filters.kernels_2d.filter_scans_2d``) one
per measurement block, options, run states and metric sums.

Each is a NamedTuple of arrays and numbers, which numba takes as it is (its fields read by
name in the kernels). ``core.tracking.compiled.CompiledTracks`` builds them for a block of
plots; the association's kernel builds them for a batch. A 2D block has no elevations: its
``elevation_rad`` and ``sigma_elevation_rad`` are empty and never read.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray


class PlotColumns(NamedTuple):
    """A block's plots in plot order, each field (B,): the plot's target slot, time (s),
    range (m), azimuth and elevation (rad; 3D only), radial velocity (m/s, read where
    ``has_vr``) and radar (an index into the ``RadarArrays``)."""

    slot: NDArray[np.intp]
    time_s: NDArray[np.float64]
    range_m: NDArray[np.float64]
    azimuth_rad: NDArray[np.float64]
    elevation_rad: NDArray[np.float64]
    radial_velocity_mps: NDArray[np.float64]
    has_vr: NDArray[np.bool_]
    radar: NDArray[np.intp]

    def take(self, index: NDArray[np.intp]) -> PlotColumns:
        """The plots at ``index`` (an absent elevation stays absent)."""
        return PlotColumns(*(c[index] if c.shape[0] else c for c in self))


class RadarArrays(NamedTuple):
    """Each radar's site (R, d) (m) and noise std (R,): σr (m), σβ, σε (rad; 3D only),
    σVr (m/s)."""

    site_m: NDArray[np.float64]
    sigma_r_m: NDArray[np.float64]
    sigma_beta_rad: NDArray[np.float64]
    sigma_elevation_rad: NDArray[np.float64]
    sigma_vr_mps: NDArray[np.float64]


class CVOptions(NamedTuple):
    """The constant-velocity tracker's options: σa (m/s²), a new track's velocity std σv0
    (m/s) and the UKF's weights (λ + n, Wm₀, Wc₀, W) (``core.filters.polar_ukf``)."""

    sigma_a_mps2: float
    sigma_v0_mps: float
    ukf_weights: NDArray[np.float64]


class IMMOptions(NamedTuple):
    """The IMM tracker's options: each model's σa (r,) (m/s²) and turn rate ω (r,) (rad/s,
    0: constant velocity), the transition matrix Π (r, r), a new track's μ (r,), σv0 (m/s),
    the UKF's weights, and whether to compute the monitor's NIS."""

    sigma_a_mps2: NDArray[np.float64]
    turn_rate_radps: NDArray[np.float64]
    transition: NDArray[np.float64]
    mu0: NDArray[np.float64]
    sigma_v0_mps: float
    ukf_weights: NDArray[np.float64]
    with_stats: bool


class TrackState(NamedTuple):
    """Every slot's tracks, updated in place: x (K, M[, r], n), P (K, M[, r], n, n), the
    IMM's μ (K, M, r) (empty for the cv model), whether each slot has started (K,) and its
    last plot's time (K,) (s)."""

    x: NDArray[np.float64]
    P: NDArray[np.float64]
    mu: NDArray[np.float64]
    started: NDArray[np.bool_]
    last_t: NDArray[np.float64]


class PlotOutputs(NamedTuple):
    """Each plot's posterior per method, x (B, M, n) and P (B, M, n, n), and the update's
    NIS (B, M) (NaN at a start)."""

    x: NDArray[np.float64]
    P: NDArray[np.float64]
    nis: NDArray[np.float64]


class ScanMeasurements(NamedTuple):
    """A Monte Carlo block's measurements, one run a row (m, N), any memory layout: r̂ (m),
    β̂ (rad) and V̂r (m/s), the last read only with ``doppler``."""

    range_m: NDArray[np.float64]
    azimuth_rad: NDArray[np.float64]
    radial_velocity_mps: NDArray[np.float64]
    doppler: bool


class FilterOptions(NamedTuple):
    """The numbers every run of a Monte Carlo block shares: the noise std σr (m), σβ (rad),
    σVr (m/s), the scan period T (s), σa (m/s²), σv0 (m/s), the radar's site (m) and the
    UKF's weights (λ + n, Wm₀, Wc₀, W)."""

    sigma_r_m: float
    sigma_beta_rad: float
    sigma_vr_mps: float
    period_s: float
    sigma_a_mps2: float
    sigma_v0_mps: float
    site_x_m: float
    site_y_m: float
    ukf_weights: NDArray[np.float64]


class RunStates(NamedTuple):
    """Each run's state between chunks of scans, (runs, 14): x then the upper entries of P;
    with ``keep``, the states of the runs that give no terms at each scan of the chunk into
    x (K, kept, 4) and P (K, kept, 4, 4)."""

    state: NDArray[np.float64]
    keep: bool
    x: NDArray[np.float64]
    P: NDArray[np.float64]


class TermSums(NamedTuple):
    """The metric terms the first ``runs`` runs add (``core.metrics.scan_terms``): the true
    states (N, 4), the true line of sight's cosine and sine (N, 1), the sums per group
    (G, K, 10) and the runs already counted (run j goes to group (offset + j) mod G)."""

    runs: int
    truth: NDArray[np.float64]
    cos_los: NDArray[np.float64]
    sin_los: NDArray[np.float64]
    group_sums: NDArray[np.float64]
    group_offset: int
