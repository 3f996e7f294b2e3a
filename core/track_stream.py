"""Plot-by-plot 2D tracking for streamed measurements (no file I/O here).

``filter_block`` (``core.prosov``) runs one method over a whole (M, N) array of scans with a
fixed period. A measurement file is different: plots come one at a time, from radars that need
not sit at the origin, with any time step. ``MethodTrack`` keeps one track (M = 1) of one method
and takes one plot at a time:

* first plot: the spec's start (``filter_block``'s): the method's converted point (``ducm``
  starts like ``ucm``; ``ekf``/``ukf`` from the naive point with its linearized covariance),
  velocity 0 with std ``sigma_v0``, then shifted by the radar site;
* later plots: predict with dt = t − t_previous (``cv_predict``; dt = 0, equal times, skips the
  prediction), then update. The update works radar-centred: the prediction is shifted by −site,
  updated with the same functions as ``filter_block`` (so ``ducm``, ``ekf`` and ``ukf`` linearise
  about the prediction as seen from the radar), and shifted back. A shift by a site at the
  origin is exact, so a file from a radar at the origin gives ``filter_block``'s tracks.

Only 2D: elevation, radial velocity and the sites' z are not used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.conversion import convert_parts
from core.kalman_cv import CVBatch, cv_init, cv_predict, cv_update_parts
from core.polar_filters import ekf_update, init_from_polar, ukf_update
from core.prosov import ALL_METHODS, POLAR_METHODS, TrackingConfig
from core.scenario import polar_measurements, prosov_target
from core.validation import check_choice, check_int, check_real


@dataclass(frozen=True)
class Plot2D:
    """One measurement: time (s), range (m), azimuth (rad), the radar's σr (m), σβ (rad) and
    site (x, y) in m."""

    time_s: float
    range_m: float
    azimuth_rad: float
    sigma_r_m: float
    sigma_beta_rad: float
    site_x_m: float = 0.0
    site_y_m: float = 0.0


class MethodTrack:
    """One track (M = 1) per method of a group, updated plot by plot (see the module docstring).

    ``methods`` is either one polar method (``ekf``, ``ukf``) or any number of converted-
    measurement methods (``METHODS_2D``): those share one batch of M = len(methods) runs, so the
    prediction and the Kalman update are one set of vector operations for all of them (only
    the conversion is per method). The batched arithmetic is elementwise, so each run's result
    is bit for bit that of a batch of one.
    """

    def __init__(
        self, methods: tuple[str, ...], sigma_a_mps2: float = 0.0, sigma_v0_mps: float = 1000.0
    ):
        for m in methods:
            check_choice("method", m, ALL_METHODS)
        if not methods or (any(m in POLAR_METHODS for m in methods) and len(methods) > 1):
            raise ValueError("methods must be one polar method or only converted methods")
        self.methods = tuple(methods)
        self.sigma_a = check_real("sigma_a_mps2", sigma_a_mps2, low=0.0, low_open=False)
        self.sigma_v0 = check_real("sigma_v0_mps", sigma_v0_mps, low=0.0)
        self.state: CVBatch | None = None
        self.time_s: float | None = None

    def _converted(
        self, r: NDArray[np.float64], b: NDArray[np.float64], sr: float, sb: float,
        rel: CVBatch | None,
    ) -> tuple[NDArray[np.float64], ...]:
        """Every method's converted point and covariance as five (M,) vectors."""
        parts = np.empty((5, len(self.methods)))
        for i, m in enumerate(self.methods):
            if rel is None:  # the start: ducm has no prediction yet and starts like ucm
                c = convert_parts("ucm" if m == "ducm" else m, r, b, sr, sb)
            else:
                predicted = (rel.x[i : i + 1, 0], rel.x[i : i + 1, 2]) if m == "ducm" else None
                c = convert_parts(m, r, b, sr, sb, predicted)
            parts[:, i] = np.concatenate(np.broadcast_arrays(*c))
        return tuple(parts)

    def add(self, p: Plot2D) -> CVBatch:
        """Filter one plot; returns the updated states (x (M, 4), P (M, 4, 4)), absolute frame."""
        r = np.array([p.range_m])
        b = np.array([p.azimuth_rad])
        sr, sb, m = p.sigma_r_m, p.sigma_beta_rad, self.methods[0]
        if self.state is None:
            if m in POLAR_METHODS:
                state = init_from_polar(r, b, sr, sb, self.sigma_v0)
            else:
                zx, zy, r00, r01, r11 = self._converted(r, b, sr, sb, None)
                R = np.stack([np.stack([r00, r01], -1), np.stack([r01, r11], -1)], -2)
                state = cv_init(np.stack([zx, zy], -1), R, self.sigma_v0)
        else:
            assert self.time_s is not None
            dt = p.time_s - self.time_s
            if dt < 0:
                raise ValueError(f"times must not decrease (got {p.time_s} after {self.time_s})")
            pred = cv_predict(self.state, dt, self.sigma_a) if dt > 0 else self.state
            rel = CVBatch(pred.x.copy(), pred.P)
            rel.x[:, 0] -= p.site_x_m
            rel.x[:, 2] -= p.site_y_m
            if m == "ekf":
                state = ekf_update(rel, r, b, sr, sb)
            elif m == "ukf":
                state = ukf_update(rel, r, b, sr, sb)
            else:
                state = cv_update_parts(rel, *self._converted(r, b, sr, sb, rel))
        state.x[:, 0] += p.site_x_m
        state.x[:, 2] += p.site_y_m
        self.state, self.time_s = state, p.time_s
        return state


def track_groups(methods: tuple[str, ...]) -> list[tuple[str, ...]]:
    """Split methods into ``MethodTrack`` groups: the converted ones together, each polar alone."""
    converted = tuple(m for m in methods if m not in POLAR_METHODS)
    return ([converted] if converted else []) + [(m,) for m in methods if m in POLAR_METHODS]


def prosov_single_run(
    seed: int = 1, sigma_beta_deg: float = 1.0
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], TrackingConfig]:
    """The Prosov scenario's one displayed run (the viewer's seed stream ``[seed, 7]``).

    Returns times (N,) in s, r̂ (1, N) in m, β̂ (1, N) in rad and the configuration, ready for
    ``core.prosov.track_history``.
    """
    check_int("seed", seed, low=0)
    config = TrackingConfig(sigma_beta_deg=sigma_beta_deg, seed=seed, target=prosov_target())
    truth = config.target.truth()
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7]))
    r_hat, b_hat = polar_measurements(truth, config.sigma_r_m, config.sigma_beta_rad, 1, rng)
    times = np.arange(truth.shape[0]) * config.target.period_s
    return times, r_hat, b_hat, config
