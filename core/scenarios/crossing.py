"""Crossing targets in clutter: the scene of the association experiment.

One 2D radar at the origin scans every ``period_s``. ``targets`` targets fly straight at
``speed_mps`` and all pass through one point, at range ``crossing_range_m`` on the x axis, at
the middle scan; their headings are spread by ``crossing_angle_deg`` about the inbound line
of sight, so neighbouring paths cross at that angle and part in the cross-range direction,
where the radar is least accurate (σβ r against σr)::

    ψ_i = 180° + (i − (n − 1)/2) θ,   p_i(t) = c + v (cos ψ_i, sin ψ_i)(t − t_c),
    c = (r_c, 0),   t_c = (N − 1) T / 2.

Each scan, each target is detected with probability P_D, its plot r̂ = r + σr w₁,
β̂ = β + σβ w₂ (w standard normal); and the scan holds Poisson(λ) false plots uniform in range
and azimuth over the surveillance region (what a constant-false-alarm-rate detector gives:
the same false-alarm probability in every range–azimuth cell). The region is the range–
azimuth sector spanned by the paths, widened by ``margin_m`` in range and by
``margin_m / r_c`` in azimuth. All plots of a scan share its time stamp and are shuffled, so
their order tells nothing of their origin. Pure numpy; every draw from the caller's
``numpy.random.Generator``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.params import check, check_int, check_real, default

#: ``CrossingScan.origin`` of a false plot.
CLUTTER = -1


@dataclass(frozen=True)
class CrossingScene:
    """The crossing scene (module docstring). Distances m, angles deg, speeds m/s, time s."""

    targets: int = default("crossing_targets")
    crossing_angle_deg: float = default("crossing_angle_deg")
    detection_prob: float = default("detection_prob")
    clutter_per_scan: float = default("clutter_per_scan")
    scans: int = 40
    period_s: float = 5.0
    speed_mps: float = 250.0
    crossing_range_m: float = 40e3
    sigma_r_m: float = 50.0
    sigma_beta_deg: float = 0.3
    margin_m: float = 5e3

    def __post_init__(self) -> None:
        check("crossing_targets", self.targets)
        check("crossing_angle_deg", self.crossing_angle_deg)
        check("detection_prob", self.detection_prob)
        check("clutter_per_scan", self.clutter_per_scan)
        check("steps", self.scans)
        check("period_s", self.period_s)
        check_real("speed_mps", self.speed_mps, low=0.0, high=1e4)
        check("sigma_r_m", self.sigma_r_m)
        check("sigma_beta_deg", self.sigma_beta_deg)
        check_real("margin_m", self.margin_m, low=0.0, high=1e7, low_open=False)
        check_real("crossing_range_m", self.crossing_range_m, low=self.margin_m, high=1e7)
        # Each target flies half its path to the crossing point and half beyond it; the path
        # must stay margin_m clear of the radar, which bounds the scans at this range.
        step_m = self.speed_mps * self.period_s
        if step_m * (self.scans - 1) / 2.0 + self.margin_m >= self.crossing_range_m:
            most = math.ceil(2.0 * (self.crossing_range_m - self.margin_m) / step_m)
            check_int("steps", self.scans, low=2, high=max(2, most))

    @property
    def times_s(self) -> NDArray[np.float64]:
        """(N,) scan times."""
        return np.arange(self.scans) * self.period_s

    def truth(self) -> NDArray[np.float64]:
        """True states (N, n, 4) as (x, ẋ, y, ẏ) per scan and target."""
        n = self.targets
        psi = np.radians(180.0 + (np.arange(n) - (n - 1) / 2.0) * self.crossing_angle_deg)
        v = self.speed_mps * np.stack([np.cos(psi), np.sin(psi)], axis=-1)  # (n, 2)
        dt = self.times_s - self.times_s[-1] / 2.0
        pos = np.array([self.crossing_range_m, 0.0]) + dt[:, None, None] * v[None]
        out = np.empty((self.scans, n, 4))
        out[..., 0], out[..., 2] = pos[..., 0], pos[..., 1]
        out[..., 1], out[..., 3] = v[:, 0], v[:, 1]
        return out

    def region(self) -> tuple[float, float, float, float]:
        """The surveillance sector (r_min, r_max, β_min, β_max): m, m, rad, rad."""
        t = self.truth()
        r = np.hypot(t[..., 0], t[..., 2])
        b = np.arctan2(t[..., 2], t[..., 0])
        db = self.margin_m / self.crossing_range_m
        return (
            max(float(r.min()) - self.margin_m, 1.0),
            float(r.max()) + self.margin_m,
            float(b.min()) - db,
            float(b.max()) + db,
        )


class CrossingScan(NamedTuple):
    """The plots of one scan, (P,) each, shuffled.

    Attributes:
        range_m, azimuth_rad: the plots.
        origin: the target index a plot came from, or ``CLUTTER``.
    """

    range_m: NDArray[np.float64]
    azimuth_rad: NDArray[np.float64]
    origin: NDArray[np.intp]


def crossing_scans(scene: CrossingScene, rng: np.random.Generator) -> list[CrossingScan]:
    """One run of the scene: the N scans' plots (module docstring)."""
    truth = scene.truth()
    r_lo, r_hi, b_lo, b_hi = scene.region()
    sigma_beta_rad = math.radians(scene.sigma_beta_deg)
    out = []
    for k in range(scene.scans):
        x, y = truth[k, :, 0], truth[k, :, 2]
        seen = rng.random(scene.targets) < scene.detection_prob
        idx = np.flatnonzero(seen)
        r = np.hypot(x[idx], y[idx]) + scene.sigma_r_m * rng.standard_normal(idx.size)
        b = np.arctan2(y[idx], x[idx]) + sigma_beta_rad * rng.standard_normal(idx.size)
        q = int(rng.poisson(scene.clutter_per_scan))
        rc = rng.uniform(r_lo, r_hi, q)
        bc = rng.uniform(b_lo, b_hi, q)
        order = rng.permutation(idx.size + q)
        rr = np.concatenate([r, rc])[order]
        bb = np.concatenate([b, bc])[order]
        origin = np.concatenate([idx, np.full(q, CLUTTER)]).astype(np.intp)[order]
        # A range of 0 or less (σr ≫ r) is not a plot: the radar cannot report it.
        ok = rr > 0
        out.append(CrossingScan(rr[ok], bb[ok], origin[ok]))
    return out
