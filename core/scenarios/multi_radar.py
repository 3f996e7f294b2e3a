"""A 3D multi-radar scenario: radar sites with their own accuracies and scan periods, and a
target trajectory that may manoeuvre.

The trajectory is piecewise: each :class:`Segment` lasts ``duration`` seconds and is either
constant velocity (``turn_rate = 0``) or a coordinated turn in the horizontal plane at turn rate
ω (rad/s, positive counter-clockwise from x towards y), with the vertical velocity held. Over
a segment started at (p₀, v₀), with τ = t − t₀ and v_h = (vx, vy):

    v(τ) = (R(ωτ) v_h, vz),      R(θ) = [[cos θ, −sin θ], [sin θ, cos θ]]
    p(τ) = p₀ + ([[sin ωτ, −(1 − cos ωτ)], [1 − cos ωτ, sin ωτ]] v_h / ω, vz τ)

so the speed is constant during a turn. After the last segment the motion continues as in it.

Radar k at site s_k scans at t = t0_k + j T_k (its own period and phase) and measures

    r = |p − s|,  β = atan2(dy, dx),  ε = atan2(dz, √(dx² + dy²)),  Vr = (p − s) · v / r

plus independent Gaussian noise (σr, σβ, σε, σVr: ``SIGMA_FIELDS``). Angles are radians.
Measurements are seeded: radar k of ``scenario.radars`` draws from child k of
``SeedSequence(seed)``.
"""

from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.geometry import polar_coordinates
from radarviz.core.params import ParameterError, check, check_int, check_real
from radarviz.core.velocity.estimate import (
    BASELINE_SIGMA_AZ_DEG,
    BASELINE_SIGMA_EL_DEG,
    BASELINE_SIGMA_VR_MPS,
    BASELINE_SITES_M,
    BASELINE_TARGET_M,
    BASELINE_VELOCITY_MPS,
)

#: The accuracy fields of a :class:`RadarSite`, in the order its noise is drawn.
SIGMA_FIELDS: tuple[str, ...] = (
    "sigma_r_m",
    "sigma_beta_rad",
    "sigma_elevation_rad",
    "sigma_vr_mps",
)


@dataclass(frozen=True)
class RadarSite:
    """A radar: name, site (m, ECS), accuracies, scan period and phase.

    The accuracies and timing are keyword-only (``RadarSite("R1", (0, 0, 0), sigma_r_m=50,
    sigma_beta_rad=…, sigma_elevation_rad=…, sigma_vr_mps=1, period_s=10)``) so two angle
    σ's cannot be swapped by position. A σ of 0 means that measurement is exact.
    """

    name: str
    position: tuple[float, float, float]
    _: KW_ONLY
    sigma_r_m: float
    sigma_beta_rad: float
    sigma_elevation_rad: float
    sigma_vr_mps: float
    period_s: float
    t0_s: float = 0.0

    def __post_init__(self) -> None:
        if len(self.position) != 3 or not all(math.isfinite(float(c)) for c in self.position):
            raise ParameterError(f"position of radar {self.name!r} must be 3 finite numbers")
        for field in SIGMA_FIELDS:
            check_real(
                f"{field} of radar {self.name!r}",
                getattr(self, field),
                low=0.0,
                low_open=False,
                parameter=field,
            )
        check("period_s", self.period_s)
        check_real(f"t0_s of radar {self.name!r}", self.t0_s, low=None, parameter="t0_s")


@dataclass(frozen=True)
class Segment:
    """A piece of trajectory: ``duration`` s at turn rate ``turn_rate`` rad/s (0: straight)."""

    duration: float
    turn_rate: float = 0.0

    def __post_init__(self) -> None:
        check_real("duration", self.duration, low=0.0)
        check_real("turn_rate", self.turn_rate, low=-1.0, high=1.0, low_open=False)


def _advance(p: NDArray, v: NDArray, tau: NDArray, omega: float) -> tuple[NDArray, NDArray]:
    """State after τ (...,) seconds of a segment with turn rate ω from (p, v) (3,)."""
    tau = np.asarray(tau, dtype=np.float64)
    if omega == 0.0:
        return p + tau[..., None] * v, np.broadcast_to(v, (*tau.shape, 3)).copy()
    th = omega * tau
    c, s = np.cos(th), np.sin(th)
    vx, vy, vz = v
    # (1 − cos θ)/ω and sin θ/ω, written to stay accurate for small θ.
    one_minus_c = 2.0 * np.sin(0.5 * th) ** 2
    px = p[0] + (s * vx - one_minus_c * vy) / omega
    py = p[1] + (one_minus_c * vx + s * vy) / omega
    pos = np.stack([px, py, p[2] + vz * tau], axis=-1)
    vel = np.stack([c * vx - s * vy, s * vx + c * vy, np.full_like(th, vz)], axis=-1)
    return pos, vel


@dataclass(frozen=True)
class Trajectory3D:
    """Initial position (m) and velocity (m/s) at t = 0, then the segments in order."""

    position: tuple[float, float, float]
    velocity: tuple[float, float, float]
    segments: tuple[Segment, ...] = ()

    def _starts(self) -> tuple[NDArray, NDArray, NDArray]:
        """Start time, position and velocity of each segment: (S,), (S, 3), (S, 3)."""
        t, p, v = 0.0, np.array(self.position, float), np.array(self.velocity, float)
        ts, ps, vs = [], [], []
        for seg in self.segments or (Segment(math.inf),):
            ts.append(t)
            ps.append(p)
            vs.append(v)
            if math.isfinite(seg.duration):
                p, v = _advance(p, v, np.asarray(seg.duration), seg.turn_rate)
                t += seg.duration
        return np.array(ts), np.array(ps), np.array(vs)

    def state(self, t: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """True position and velocity at times ``t`` (...,) ≥ 0: two (..., 3) arrays."""
        t = np.asarray(t, dtype=np.float64)
        if np.any(t < 0.0) or not np.all(np.isfinite(t)):
            raise ParameterError("times must be finite and >= 0")
        segs = self.segments or (Segment(math.inf),)
        ts, ps, vs = self._starts()
        idx = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(ts) - 1)
        pos = np.empty((*t.shape, 3))
        vel = np.empty((*t.shape, 3))
        for i, seg in enumerate(segs):
            mask = idx == i
            if np.any(mask):
                pos[mask], vel[mask] = _advance(ps[i], vs[i], t[mask] - ts[i], seg.turn_rate)
        return pos, vel


@dataclass(frozen=True)
class Scenario3D:
    """Radars and one target trajectory."""

    radars: tuple[RadarSite, ...]
    trajectory: Trajectory3D

    def __post_init__(self) -> None:
        names = [r.name for r in self.radars]
        if not names:
            raise ParameterError("a scenario needs at least one radar")
        if len(set(names)) != len(names):
            raise ParameterError(f"radar names must be unique (got {names})")


@dataclass(frozen=True)
class RadarMeasurements:
    """One radar's scans: times (n,), measured r, β, ε, Vr (n,) and the truth (n, 3)."""

    radar: RadarSite
    t: NDArray[np.float64]
    range: NDArray[np.float64]
    azimuth: NDArray[np.float64]
    elevation: NDArray[np.float64]
    radial_velocity: NDArray[np.float64]
    true_position: NDArray[np.float64]
    true_velocity: NDArray[np.float64]


def polar_measurement(
    site: ArrayLike, position: ArrayLike, velocity: ArrayLike
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Noise-free (r, β, ε, Vr) of (..., 3) position and velocity seen from ``site`` (3,)."""
    d = np.asarray(position, float) - np.asarray(site, float)
    r, azimuth, elevation = polar_coordinates([d[..., 0], d[..., 1], d[..., 2]])
    vr = np.sum(d * np.asarray(velocity, float), axis=-1) / r
    return r, azimuth, elevation, vr


def scan_times(radar: RadarSite, t_end: float) -> NDArray[np.float64]:
    """t0 + j T for j = 0, 1, … while ≤ t_end (and ≥ 0)."""
    j0 = max(0, math.ceil(-radar.t0_s / radar.period_s))
    j1 = math.floor((t_end - radar.t0_s) / radar.period_s + 1e-9)
    return radar.t0_s + radar.period_s * np.arange(j0, j1 + 1, dtype=np.float64)


def generate_measurements(
    scenario: Scenario3D, t_end: float, seed: int | None = 0
) -> dict[str, RadarMeasurements]:
    """Every radar's measurements over [0, t_end], keyed by radar name.

    ``seed=None`` gives noise-free measurements; otherwise radar k draws δr, δβ, δε, δVr (in
    that order, each (n,)) from child k of ``SeedSequence(seed)``.
    """
    t_end = check_real("t_end", t_end, low=0.0, low_open=False)
    children = (
        None
        if seed is None
        else np.random.SeedSequence(check_int("seed", seed, low=0)).spawn(len(scenario.radars))
    )
    out = {}
    for k, radar in enumerate(scenario.radars):
        t = scan_times(radar, t_end)
        pos, vel = scenario.trajectory.state(t)
        r, az, el, vr = polar_measurement(radar.position, pos, vel)
        if children is not None:
            z = np.random.default_rng(children[k]).standard_normal((4, t.size))
            r = r + radar.sigma_r_m * z[0]
            az = az + radar.sigma_beta_rad * z[1]
            el = el + radar.sigma_elevation_rad * z[2]
            vr = vr + radar.sigma_vr_mps * z[3]
        out[radar.name] = RadarMeasurements(radar, t, r, az, el, vr, pos, vel)
    return out


def fusion_scenario(
    period_s: float = 10.0,
    *,
    sigma_r_m: float | None = None,
    sigma_beta_rad: float | None = None,
    sigma_elevation_rad: float | None = None,
    sigma_vr_mps: float | None = None,
) -> Scenario3D:
    """The velocity paper's baseline radars and target; the target turns for 100 s mid-way.

    Three radars at the baseline sites (``core.velocity.estimate.BASELINE_SITES_M``) with
    σr = 50, 100, 150 m and the baseline angle and radial-velocity accuracies, all scanning at
    ``period_s``; the target flies the baseline track for 200 s, turns at 0.02 rad/s for 100 s,
    then flies straight on. ``sigma_r_m``, ``sigma_beta_rad``, ``sigma_elevation_rad`` and
    ``sigma_vr_mps``, when given, replace the baseline accuracies of every radar (the tuning
    panel's values); each is checked against ``core.params``.
    """
    if sigma_r_m is not None:
        check("sigma_r_m", sigma_r_m)
    if sigma_vr_mps is not None:
        check("sigma_vr_mps", sigma_vr_mps)
    if sigma_beta_rad is not None:
        check("sigma_beta_deg", float(np.rad2deg(sigma_beta_rad)))
    if sigma_elevation_rad is not None:
        check("sigma_elevation_deg", float(np.rad2deg(sigma_elevation_rad)))
    check("period_s", period_s)
    radars = tuple(
        RadarSite(
            f"R{k + 1}",
            tuple(site),
            sigma_r_m=sigma_r_m if sigma_r_m is not None else 50.0 * (k + 1),
            sigma_beta_rad=sigma_beta_rad
            if sigma_beta_rad is not None
            else float(np.deg2rad(BASELINE_SIGMA_AZ_DEG[k])),
            sigma_elevation_rad=sigma_elevation_rad
            if sigma_elevation_rad is not None
            else float(np.deg2rad(BASELINE_SIGMA_EL_DEG[k])),
            sigma_vr_mps=sigma_vr_mps if sigma_vr_mps is not None else BASELINE_SIGMA_VR_MPS[k],
            period_s=period_s,
        )
        for k, site in enumerate(BASELINE_SITES_M)
    )
    trajectory = Trajectory3D(
        BASELINE_TARGET_M,
        BASELINE_VELOCITY_MPS,
        (Segment(200.0), Segment(100.0, turn_rate=0.02), Segment(1e6)),
    )
    return Scenario3D(radars, trajectory)
