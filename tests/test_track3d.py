"""3D tracks (``core.filters`` in 3D, ``core.tracking.stream``) and ``radarviz track`` on 3D
files.

* EKF + Doppler: the ``ekf`` rows of a 3-radar file (one site above the ground, irregular
  steps with one dt = 0, a climbing target, seeded noise) equal filterpy's
  ``ExtendedKalmanFilter(dim_x=6, dim_z=3)`` followed by a scalar ``filterpy.kalman.update``
  along the measured line of sight, written here from the formulas (rtol 1e-9).
* UKF: the ``ukf`` rows equal filterpy's ``UnscentedKalmanFilter`` with Merwe points
  (α = 1, β = 2, κ = 0) and our own azimuth mean / residual (dt = 0: no prediction, sigma
  points redrawn from the current state, as radarviz does).
* Zero elevation: a 3D file with ε̂ = 0 everywhere (target and sites at z = 0) gives the 2D
  file's x–y rows; z, ż stay 0. With Doppler only in the limit σε → 0: the 3D Doppler
  variance has the extra σε² (v̂z² + P_vzvz) of an unknown vertical velocity.
* the 3D finite-memory start against an independent weighted least squares.
* Monte Carlo on the ``fusion`` preset: Doppler reduces the velocity RMSE by many standard
  errors and the velocity NEES with Doppler lies in its χ² band.
* Errors: exit 2, one line naming line and column, no output file.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import (
    ExtendedKalmanFilter,
    MerweScaledSigmaPoints,
    UnscentedKalmanFilter,
)
from filterpy.kalman import update as kf_update
from scipy.stats import chi2

from radarviz.core.filters.methods import METHODS_3D
from radarviz.core.finite_memory.fit import finite_memory_fit
from radarviz.core.finite_memory.start import finite_memory_start
from radarviz.core.tracking.stream import Plot, StreamOptions, StreamTracker
from radarviz.core.velocity.estimate import BASELINE_VELOCITY_MPS
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io.plots import (
    TRACK_COLUMNS,
    covariance_column,
    fusion_plots,
    state_from_row,
)

# Deterministic cross-checks: the same arithmetic in a different order (filterpy's explicit
# (I − KH) P (I − KH)ᵀ against the multiplied-out Joseph form, inv(S) against solve, degrees
# → radians identical on both sides) differs by a few ulps per step, amplified by at most the
# condition of the updates over ≈ 40 plots: 1e-9 relative leaves ~10⁵ ulps of margin and is
# still far below any modelling difference (a wrong term moves results by ≥ 1e-6 relative).
RTOL = 1e-9

POS = [0, 2, 4]
VEL = [1, 3, 5]

# name: site (m), σr (m), σβ (deg), σε (deg), σVr (m/s)
SITES: dict[str, tuple[tuple[float, float, float], float, float, float, float]] = {
    "a": ((0.0, 0.0, 0.0), 150.0, 0.3, 0.3, 1.0),
    "b": ((60000.0, -20000.0, 0.0), 100.0, 0.2, 0.4, 2.0),
    "c": ((20000.0, 50000.0, 1200.0), 200.0, 0.5, 0.5, 3.0),
}


def radars_toml(sites: dict = SITES, skip: tuple[tuple[str, str], ...] = ()) -> str:
    """The radars file; ``skip`` drops (radar, key) pairs."""
    keys = (
        "sigma_r_m",
        "sigma_beta_deg",
        "sigma_elevation_deg",
        "sigma_vr_mps",
    )
    out = []
    for name, (site, *sigmas) in sites.items():
        out.append(f"[radars.{name}]")
        out += [f"{k} = {v!r}" for k, v in zip(("x_m", "y_m", "z_m"), site, strict=True)]
        out += [f"{k} = {v!r}" for k, v in zip(keys, sigmas, strict=True) if (name, k) not in skip]
        out.append("")
    return "\n".join(out)


def write_meas(
    path: Path,
    times: list[float],
    names: list[str],
    p0: tuple[float, float, float],
    v: tuple[float, float, float],
    seed: int,
    elevation: bool = True,
    doppler: bool = True,
    sites: dict = SITES,
    zero_elevation: bool = False,
) -> None:
    """A CV target p0 + v t seen by ``names[k]`` at ``times[k]``, seeded Gaussian noise
    (``zero_elevation``: every elevation cell an exact 0.0, the rest drawn as usual)."""
    rng = np.random.default_rng(seed)
    header = ["time_s", "radar", "range_m", "azimuth_deg"]
    header += ["elevation_deg"] * elevation + ["radial_velocity_mps"] * doppler
    lines = [",".join(header) + "\n"]
    for t, name in zip(times, names, strict=True):
        (sx, sy, sz), sr, sigma_beta_deg, se, svr = sites[name]
        e = rng.standard_normal(4).tolist()
        d = [p0[0] + v[0] * t - sx, p0[1] + v[1] * t - sy, p0[2] + v[2] * t - sz]
        rho = math.hypot(d[0], d[1])
        r = math.hypot(rho, d[2])
        cells = [
            repr(float(t)),
            name,
            repr(r + sr * e[0]),
            repr(math.degrees(math.atan2(d[1], d[0])) + sigma_beta_deg * e[1]),
        ]
        if elevation:
            el = math.degrees(math.atan2(d[2], rho)) + se * e[2]
            cells.append("0.0" if zero_elevation else repr(el))
        if doppler:
            cells.append(repr(sum(a * b for a, b in zip(d, v, strict=True)) / r + svr * e[3]))
        lines.append(",".join(cells) + "\n")
    path.write_text("".join(lines))


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def read_tracks(path: Path) -> list[dict[str, str]]:
    rows = read_csv(path)
    assert rows and tuple(rows[0]) == TRACK_COLUMNS
    return rows


def close(a: np.ndarray, b: np.ndarray, rtol: float = RTOL) -> None:
    """Relative to the largest entry of b (a covariance's small off-diagonals are rounding
    residues of the large entries, so an entrywise rtol would be meaningless for them)."""
    np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * np.abs(b).max())


def run_track(tmp_path: Path, meas: Path, radars: Path, *args: str) -> list[dict[str, str]]:
    out = tmp_path / "t.csv"
    assert (
        main(["track", "--input", str(meas), "--radars", str(radars), "--out", str(out), *args])
        == 0
    )
    return read_tracks(out)


# --------------------------------------------------------------------------------------------
# Independent reference pieces (formulas, not radarviz calls)
# --------------------------------------------------------------------------------------------


def transition(dt: float) -> np.ndarray:
    F = np.eye(6)
    F[0, 1] = F[2, 3] = F[4, 5] = dt
    return F


def plot_values(plot: dict[str, str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Site (3,), z = (r, β, ε) in rad, σ = (σr, σβ, σε) in rad of one measurement row."""
    site, sr, sigma_beta_deg, se, _ = SITES[plot["radar"]]
    z = np.array(
        [
            float(plot["range_m"]),
            math.radians(float(plot["azimuth_deg"])),
            math.radians(float(plot["elevation_deg"])),
        ]
    )
    return np.array(site), z, np.array([sr, math.radians(sigma_beta_deg), math.radians(se)])


def first_plot_start(
    site: np.ndarray, z: np.ndarray, sig: np.ndarray, sigma_v0: float
) -> tuple[np.ndarray, np.ndarray]:
    """Naive 3D point, covariance J diag(σ²) Jᵀ, velocity 0 ± σv0 on each axis."""
    r, b, e = z
    cb, sigma_beta_deg, ce, se = math.cos(b), math.sin(b), math.cos(e), math.sin(e)
    J = np.array(
        [
            [ce * cb, -r * ce * sigma_beta_deg, -r * se * cb],
            [ce * sigma_beta_deg, r * ce * cb, -r * se * sigma_beta_deg],
            [se, 0.0, r * ce],
        ]
    )
    x = np.zeros(6)
    x[POS] = site + r * np.array([ce * cb, ce * sigma_beta_deg, se])
    P = np.zeros((6, 6))
    P[np.ix_(POS, POS)] = J @ np.diag(sig**2) @ J.T
    P[VEL, VEL] = sigma_v0**2
    return x, P


def hx_polar(site: np.ndarray):
    def hx(x: np.ndarray) -> np.ndarray:
        dx, dy, dz = x[0] - site[0], x[2] - site[1], x[4] - site[2]
        rho = math.hypot(dx, dy)
        return np.array([math.hypot(rho, dz), math.atan2(dy, dx), math.atan2(dz, rho)])

    return hx


def jac_polar(site: np.ndarray):
    def jac(x: np.ndarray) -> np.ndarray:
        dx, dy, dz = x[0] - site[0], x[2] - site[1], x[4] - site[2]
        rho2 = dx * dx + dy * dy
        rho = math.sqrt(rho2)
        r2 = rho2 + dz * dz
        r = math.sqrt(r2)
        H = np.zeros((3, 6))
        H[0, POS] = [dx / r, dy / r, dz / r]
        H[1, POS] = [-dy / rho2, dx / rho2, 0.0]
        H[2, POS] = [-dx * dz / (r2 * rho), -dy * dz / (r2 * rho), rho / r2]
        return H

    return jac


def residual_polar(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    y = np.asarray(a, dtype=float) - b
    y[1] = math.remainder(y[1], 2.0 * math.pi)
    return y


def doppler_reference(
    x: np.ndarray, P: np.ndarray, plot: dict[str, str]
) -> tuple[np.ndarray, np.ndarray]:
    """filterpy's linear update with V̂r = u(β̂, ε̂)·v + e, var e from the docstring."""
    _, _, sb_deg, se_deg, svr = SITES[plot["radar"]]
    b = math.radians(float(plot["azimuth_deg"]))
    e = math.radians(float(plot["elevation_deg"]))
    sigma_beta_deg, se = math.radians(sb_deg), math.radians(se_deg)
    u = np.array([math.cos(e) * math.cos(b), math.cos(e) * math.sin(b), math.sin(e)])
    du_db = np.array([-math.cos(e) * math.sin(b), math.cos(e) * math.cos(b), 0.0])
    du_de = np.array([-math.sin(e) * math.cos(b), -math.sin(e) * math.sin(b), math.cos(e)])
    v, Pvv = x[VEL], P[np.ix_(VEL, VEL)]
    var = svr**2
    for g, s in ((du_db, sigma_beta_deg), (du_de, se)):
        var += s * s * (float(g @ v) ** 2 + float(g @ Pvv @ g))
    H = np.zeros((1, 6))
    H[0, VEL] = u
    return kf_update(x, P, np.array([float(plot["radial_velocity_mps"])]), np.array([[var]]), H)


# --------------------------------------------------------------------------------------------
# 1. EKF + Doppler against filterpy
# --------------------------------------------------------------------------------------------

P0 = (140e3, 10e3, 6e3)
V0 = (-150.0, 80.0, 15.0)  # climbing


def three_radar_times(seed: int = 11, n: int = 45) -> tuple[list[float], list[str]]:
    rng = np.random.default_rng(seed)
    times = np.concatenate([[0.0], np.cumsum(rng.uniform(0.5, 12.0, n - 1))])
    times[10] = times[9]  # two plots (radars b and c) at the same time: dt = 0
    return times.tolist(), ["abc"[k % 3] for k in range(n)]


@pytest.mark.parametrize("doppler", ["use", "ignore"])
def test_ekf_doppler_matches_filterpy(tmp_path: Path, doppler: str) -> None:
    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    times, names = three_radar_times()
    write_meas(meas, times, names, P0, V0, seed=12)
    radars.write_text(radars_toml())
    sigma_a, sigma_v0 = 0.3, 1000.0
    rows = run_track(
        tmp_path, meas, radars, "--method", "ekf", "--sigma-a", str(sigma_a), "--doppler", doppler
    )
    plots = read_csv(meas)
    assert len(rows) == len(plots)
    use = doppler == "use"

    f = ExtendedKalmanFilter(dim_x=6, dim_z=3)
    last_t = None
    for row, plot in zip(rows, plots, strict=True):
        assert row["method"] == "ekf"
        t = float(plot["time_s"])
        site, z, sig = plot_values(plot)
        if last_t is None:
            f.x, f.P = first_plot_start(site, z, sig, sigma_v0)
        else:
            dt = t - last_t
            if dt > 0:
                f.F = transition(dt)
                # State (x, ẋ, y, ẏ, z, ż): three (p, ṗ) blocks, order_by_dim=True.
                f.Q = Q_discrete_white_noise(2, dt=dt, var=sigma_a**2, block_size=3)
                f.predict()
            f.update(z, jac_polar(site), hx_polar(site), R=np.diag(sig**2), residual=residual_polar)
        if use:
            f.x, f.P = doppler_reference(f.x, f.P, plot)
        last_t = t
        x, P = state_from_row(row)
        assert float(row["time_s"]) == t
        close(x, f.x)
        close(P, f.P)
    # The target climbs: the track's vertical velocity must have been estimated.
    assert abs(f.x[5] - V0[2]) < 10.0


# --------------------------------------------------------------------------------------------
# 2. UKF against filterpy
# --------------------------------------------------------------------------------------------


def ukf_z_mean(sigmas: np.ndarray, Wm: np.ndarray) -> np.ndarray:
    """Weighted mean with the azimuth averaged relative to the central point's azimuth."""
    s = np.array(sigmas, dtype=float)
    b0 = s[0, 1]
    s[:, 1] = b0 + np.array([math.remainder(b - b0, 2.0 * math.pi) for b in s[:, 1]])
    return Wm @ s


def test_ukf_matches_filterpy(tmp_path: Path) -> None:
    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    times, names = three_radar_times(seed=21, n=40)
    write_meas(meas, times, names, P0, V0, seed=22, doppler=False)
    radars.write_text(radars_toml())
    sigma_a, sigma_v0 = 0.3, 1000.0
    rows = run_track(tmp_path, meas, radars, "--method", "ukf", "--sigma-a", str(sigma_a))
    plots = read_csv(meas)
    assert len(rows) == len(plots)

    points = MerweScaledSigmaPoints(6, alpha=1.0, beta=2.0, kappa=0.0)
    f = UnscentedKalmanFilter(
        dim_x=6,
        dim_z=3,
        dt=1.0,
        hx=None,
        fx=lambda x, dt: transition(dt) @ x,
        points=points,
        z_mean_fn=ukf_z_mean,
        residual_z=residual_polar,
    )
    last_t = None
    for row, plot in zip(rows, plots, strict=True):
        t = float(plot["time_s"])
        site, z, sig = plot_values(plot)
        if last_t is None:
            f.x, f.P = first_plot_start(site, z, sig, sigma_v0)
        else:
            dt = t - last_t
            if dt > 0:
                f.Q = Q_discrete_white_noise(2, dt=dt, var=sigma_a**2, block_size=3)
                f.predict(dt=dt)  # redraws the sigma points from the predicted (x, P)
            else:
                # radarviz skips the prediction at dt = 0; filterpy's documented way to
                # update twice without a prediction: sigma points of the current (x, P).
                f.compute_process_sigmas(0.0)
            f.update(z, R=np.diag(sig**2), hx=hx_polar(site))
        last_t = t
        x, P = state_from_row(row)
        close(x, f.x)
        # P: filterpy predicts P as Σ Wc (Fχ − x̄)(Fχ − x̄)ᵀ + Q (13 outer products of points
        # at ±√6 σ) where radarviz forms F P Fᵀ + Q, and takes an upper instead of a lower
        # Cholesky factor; both are exact for a linear fx, so only rounding differs, as for x.
        close(P, f.P)


# --------------------------------------------------------------------------------------------
# 3. Zero elevation: 3D = 2D
# --------------------------------------------------------------------------------------------

FLAT_SITES = {
    "a": ((0.0, 0.0, 0.0), 150.0, 0.3, 0.5, 1.0),
    "b": ((60000.0, -20000.0, 0.0), 100.0, 0.2, 0.5, 2.0),
}
XY = ["x", "y", "vx", "vy"]
ZS = ["z", "vz"]


def pair_key(row: dict[str, str], a: str, b: str) -> str:
    return covariance_column(a, b) if covariance_column(a, b) in row else covariance_column(b, a)


@pytest.mark.parametrize("init", ["first-plot", "finite-memory"])
@pytest.mark.parametrize("doppler", ["use", "ignore"])
def test_zero_elevation_reduces_to_2d(tmp_path: Path, init: str, doppler: str) -> None:
    # Radar a every 5 s (its first three plots equally spaced for the finite-memory start),
    # radar b in between at irregular times; the target flies level at z = 0.
    times, names = [], []
    for k in range(16):
        times.append(5.0 * k)
        names.append("a")
        if k % 2:
            times.append(5.0 * k + 1.0 + 0.25 * k)
            names.append("b")
    p0, v = (90e3, 30e3, 0.0), (-120.0, 60.0, 0.0)
    # With Doppler the 3D row's variance has σε² (v̂z² + P_vzvz) more than the 2D one (the
    # elevation error tilts the measured line of sight; doppler_update's docstring: equal to
    # the 2D update only for σε = 0): at the start P_vzvz = σv0², so with σε = 0.5° the 3D
    # rows differ from the 2D ones by up to ~1e-4 of the state's scale (≈ 2 m, 0.8 m/s on
    # this file). Hence σε → 0 (1e-6°, the smallest the radars file allows) for that case:
    # the term is then ~1e-10 of σVr², below the comparison's 1e-9.
    se_deg = 0.5 if doppler == "ignore" else 1e-6
    sites = {n: (*s[:3], se_deg, s[4]) for n, s in FLAT_SITES.items()}
    m2, m3, radars = tmp_path / "m2.csv", tmp_path / "m3.csv", tmp_path / "r.toml"
    write_meas(m2, times, names, p0, v, seed=31, elevation=False, sites=sites)
    write_meas(m3, times, names, p0, v, seed=31, sites=sites, zero_elevation=True)
    # Identical measurements but for the exact-zero elevation column.
    r2, r3 = read_csv(m2), read_csv(m3)
    assert all(
        a.items() <= b.items() and b["elevation_deg"] == "0.0" for a, b in zip(r2, r3, strict=True)
    )
    radars.write_text(radars_toml(sites))
    args = ("--method", "naive", "ekf", "--init", init, "--doppler", doppler, "--sigma-a", "0.5")
    rows2 = run_track(tmp_path, m2, radars, *args)
    rows3 = run_track(tmp_path, m3, radars, *args)
    # Finite memory: no rows before a's third plot (plots a, a, b, then a: index 3).
    assert len(rows2) == len(rows3) == 2 * (len(times) - (3 if init == "finite-memory" else 0))
    for a, b in zip(rows2, rows3, strict=True):
        assert (a["time_s"], a["method"]) == (b["time_s"], b["method"])
        x2 = np.array([float(a[f"{c}_m" if c in "xy" else f"{c}_mps"]) for c in XY])
        x3 = np.array([float(b[f"{c}_m" if c in "xy" else f"{c}_mps"]) for c in XY])
        close(x3, x2)
        cov2 = np.array([[float(a[pair_key(a, p, q)]) for q in XY] for p in XY])
        cov3 = np.array([[float(b[pair_key(b, p, q)]) for q in XY] for p in XY])
        close(cov3, cov2)
        assert float(b["z_m"]) == 0.0 and float(b["vz_mps"]) == 0.0
        # z and ż are decoupled from the x–y block exactly.
        assert all(float(b[pair_key(b, p, q)]) == 0.0 for p in XY for q in ZS)
        assert float(b["p_vzvz_m2ps2"]) > 0.0
        # (with σε = 1e-6° the measured z has variance ~1e-12 m² against a predicted 1e7 m²:
        # below rounding, so p_zz_m2 is only checked for the realistic σε)
        assert float(b["p_zz_m2"]) > 0.0 or se_deg < 1e-6


# --------------------------------------------------------------------------------------------
# 4. the 3D finite-memory start against an independent least squares
# --------------------------------------------------------------------------------------------


def wls(
    k: int, T: float, ranges: np.ndarray, vrs: np.ndarray | None, sr: float, svr: float
) -> tuple[np.ndarray, np.ndarray]:
    """θ̂ = (r, Vr, a) at the newest plot and its covariance, by whitened lstsq."""
    j = np.arange(k - 1, -1, -1, dtype=float)  # lag of plot i = 1 (oldest) … k
    A = np.stack([np.ones(k), -T * j, 0.5 * (T * j) ** 2], -1) / sr
    z = ranges / sr
    if vrs is not None:
        A = np.concatenate([A, np.stack([np.zeros(k), np.ones(k), -T * j], -1) / svr])
        z = np.concatenate([z, vrs / svr])
    theta = np.linalg.lstsq(A, z, rcond=None)[0]
    return theta, np.linalg.inv(A.T @ A)


def los_frame(b: float, e: float) -> np.ndarray:
    """Columns u, e_β, e_ε."""
    return np.array(
        [
            [math.cos(e) * math.cos(b), -math.sin(b), -math.sin(e) * math.cos(b)],
            [math.cos(e) * math.sin(b), math.cos(b), -math.sin(e) * math.sin(b)],
            [math.sin(e), 0.0, math.cos(e)],
        ]
    )


def check_start_in_los_frame(
    x: np.ndarray,
    P: np.ndarray,
    site: np.ndarray,
    b: float,
    e: float,
    theta: np.ndarray,
    R: np.ndarray,
    sigma_beta_deg: float,
    se: float,
    sigma_v0: float,
    rtol: float = RTOL,
) -> None:
    """x = (site + r̂ u, V̂r u); P in the frame (u, e_β, e_ε): diag(R11, (r̂ cos ε σβ)²,
    (r̂ σε)²) for the position, diag(R22, σv0², σv0²) for the velocity, R12 between the
    along-line components and nothing else."""
    G = los_frame(b, e)
    u = G[:, 0]
    close(x[POS], site + theta[0] * u, rtol)
    close(x[VEL], theta[1] * u, rtol)
    Lpp = G.T @ P[np.ix_(POS, POS)] @ G
    Lvv = G.T @ P[np.ix_(VEL, VEL)] @ G
    Lpv = G.T @ P[np.ix_(POS, VEL)] @ G
    close(
        Lpp,
        np.diag([R[0, 0], (theta[0] * math.cos(e) * sigma_beta_deg) ** 2, (theta[0] * se) ** 2]),
        rtol,
    )
    close(Lvv, np.diag([R[1, 1], sigma_v0**2, sigma_v0**2]), rtol)
    expected_pv = np.zeros((3, 3))
    expected_pv[0, 0] = R[0, 1]
    np.testing.assert_allclose(Lpv, expected_pv, rtol=rtol, atol=rtol * abs(R[0, 1]))


@pytest.mark.parametrize("k,doppler", [(2, True), (5, True), (4, False), (7, False)])
def test_finite_memory_start_3d_vs_lstsq(k: int, doppler: bool) -> None:
    rng = np.random.default_rng(41 + k)
    T, sr, svr, sigma_beta_deg, se, sigma_v0 = (
        4.0,
        120.0,
        1.5,
        math.radians(0.4),
        math.radians(0.7),
        500.0,
    )
    site = np.array([1000.0, -2000.0, 300.0])
    tt = T * np.arange(k)
    # A range with curvature (so a ≠ 0 is fitted) plus noise.
    ranges = 80e3 - 150.0 * tt + 0.8 * tt**2 + sr * rng.standard_normal(k)
    vrs = -150.0 + 1.6 * tt + svr * rng.standard_normal(k) if doppler else None
    b, e = math.radians(33.0), math.radians(12.0)  # newest measured line of sight
    fit = finite_memory_fit(
        k, sigma_r_m=sr, sigma_vr_mps=svr if doppler else None, period_s=T, with_doppler=doppler
    )
    assert fit.order == 3  # k = 2 with Doppler: 4 equations, still the full (r, Vr, a)
    start = finite_memory_start(
        fit,
        ranges,
        vrs,
        b,
        e,
        sigma_beta_rad=sigma_beta_deg,
        sigma_elevation_rad=se,
        sigma_v0_mps=sigma_v0,
        site=site,
    )
    theta, R = wls(k, T, ranges, vrs, sr, svr)
    # Closed forms (eqs. 7–12, 15–20) against the LS solve: same numbers by another route,
    # agreeing to ~1e-14 here (k ≤ 7, T = 4 s), so RTOL. R's entries are compared relative to
    # √(Rii Rjj) (R13 is an exact 0 at k = 2 and a rounding residue in the LS solve).
    scale = np.sqrt(np.outer(np.diag(R), np.diag(R)))
    np.testing.assert_allclose(fit.R / scale, R / scale, rtol=0.0, atol=RTOL)
    zvec = ranges if vrs is None else np.concatenate([ranges, vrs])
    theta_fit = fit.W @ zvec
    np.testing.assert_allclose(
        theta_fit / np.sqrt(np.diag(R)), theta / np.sqrt(np.diag(R)), rtol=RTOL, atol=RTOL
    )
    check_start_in_los_frame(start.x, start.P, site, b, e, theta, R, sigma_beta_deg, se, sigma_v0)


@pytest.mark.parametrize("doppler", ["use", "ignore"])
def test_finite_memory_start_on_the_file(tmp_path: Path, doppler: str) -> None:
    # Radar c (above ground) every 6 s, radar a in between: the window is c's first k plots.
    k, T = 4, 6.0
    times, names = [], []
    for n in range(10):
        times.append(T * n)
        names.append("c")
        times.append(T * n + 2.5)
        names.append("a")
    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    write_meas(meas, times, names, P0, V0, seed=51)
    radars.write_text(radars_toml())
    rows = run_track(
        tmp_path,
        meas,
        radars,
        "--method",
        "ukf",
        "ekf",
        "--init",
        "finite-memory",
        "--init-k",
        str(k),
        "--doppler",
        doppler,
        "--sigma-v0",
        "700",
    )
    plots = read_csv(meas)
    kth = 2 * (k - 1)  # index of c's k-th plot
    assert len(rows) == 2 * (len(plots) - kth)
    assert [r["method"] for r in rows[:2]] == ["ukf", "ekf"]
    assert float(rows[0]["time_s"]) == float(plots[kth]["time_s"])
    win = [plots[2 * i] for i in range(k)]
    site, sr, sigma_beta_deg, se, svr = SITES["c"]
    ranges = np.array([float(p["range_m"]) for p in win])
    vrs = np.array([float(p["radial_velocity_mps"]) for p in win]) if doppler == "use" else None
    theta, R = wls(k, T, ranges, vrs, sr, svr)
    b = math.radians(float(win[-1]["azimuth_deg"]))
    e = math.radians(float(win[-1]["elevation_deg"]))
    for row in rows[:2]:
        x, P = state_from_row(row)
        check_start_in_los_frame(
            x,
            P,
            np.array(site),
            b,
            e,
            theta,
            R,
            math.radians(sigma_beta_deg),
            math.radians(se),
            700.0,
        )


# --------------------------------------------------------------------------------------------
# 5. Doppler helps, consistently (Monte Carlo on the fusion preset)
# --------------------------------------------------------------------------------------------

MC_RUNS = 200
MC_SCANS = 3  # 9 plots: with Doppler 5.9 m/s against 10.7 m/s, ~10 SE apart


def test_doppler_reduces_velocity_error_and_is_consistent() -> None:
    truth_v = np.array(BASELINE_VELOCITY_MPS)
    err = {True: [], False: []}
    nees = []
    for seed in range(MC_RUNS):
        plots, _ = fusion_plots(seed, MC_SCANS)
        t_last = plots[-1].time_s
        assert t_last < 200.0  # still on the straight, constant-velocity leg
        for use in (True, False):
            tracker = StreamTracker(("ekf",), True, StreamOptions(use_doppler=use))
            ((_, x, P),) = tracker.add_block(plots)[-1]
            e = x[VEL] - truth_v
            err[use].append(e)
            if use:
                nees.append(float(e @ np.linalg.solve(P[np.ix_(VEL, VEL)], e)))
    sq_d = np.sum(np.square(err[True]), 1)
    sq_n = np.sum(np.square(err[False]), 1)
    rmse_d, rmse_n = math.sqrt(sq_d.mean()), math.sqrt(sq_n.mean())
    # Paired (common random numbers) difference of squared errors: its mean's standard error
    # from the runs. Doppler must win by more than 5 SE (a chance win of 5 SE has p < 3e-7).
    diff = sq_n - sq_d
    se_diff = diff.std(ddof=1) / math.sqrt(MC_RUNS)
    print(
        f"velocity RMSE with Doppler {rmse_d:.3f} m/s, without {rmse_n:.3f} m/s, "
        f"mean Δ(|e|²) {diff.mean():.2f} ± {se_diff:.2f}"
    )
    assert rmse_d < rmse_n
    assert diff.mean() > 5.0 * se_diff
    # Velocity NEES (3 dof): Σ over runs ~ χ²(3 N) if consistent; two-sided 99.9% band.
    lo, hi = chi2.ppf([0.0005, 0.9995], 3 * MC_RUNS) / MC_RUNS
    mean_nees = float(np.mean(nees))
    print(f"velocity NEES mean with Doppler {mean_nees:.3f}, 99.9% band [{lo:.3f}, {hi:.3f}]")
    assert lo <= mean_nees <= hi


# --------------------------------------------------------------------------------------------
# 6. Errors
# --------------------------------------------------------------------------------------------


def expect_error(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    meas_text: str,
    radars_text: str,
    args: list[str],
    expected: list[str],
) -> str:
    (tmp_path / "m.csv").write_text(meas_text)
    (tmp_path / "r.toml").write_text(radars_text)
    capsys.readouterr()
    status = main(
        [
            "track",
            "--input",
            str(tmp_path / "m.csv"),
            "--radars",
            str(tmp_path / "r.toml"),
            "--out",
            str(tmp_path / "t.csv"),
            *args,
        ]
    )
    out, err = capsys.readouterr()
    assert status == 2
    assert out == ""
    assert err.count("\n") == 1 and err.startswith("radarviz: error: "), err
    for s in expected:
        assert s in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.csv", "r.toml"]
    return err


HEADER3 = "time_s,radar,range_m,azimuth_deg,elevation_deg,radial_velocity_mps\n"


def test_unknown_method_on_3d_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Every method exists in 3D (tests/test_conversion_3d.py runs each); a name that is none
    of them is one line listing them all."""
    text = HEADER3 + "0,a,100000,10,3,-100\n10,b,90000,20,4,-90\n"
    expect_error(
        tmp_path,
        capsys,
        text,
        radars_toml(),
        ["--method", "ekf", "magic"],
        ["magic", "naive, seed, cmkf_d, ucm, ducm, ekf, ukf"],
    )


def test_finite_memory_unequal_steps(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # Radar a at 0, 10, 25 s (b's plots in between): a's third plot is line 5.
    text = HEADER3 + (
        "0,a,100000,10,3,-100\n4,b,90000,20,4,-90\n10,a,99000,10,3,-100\n"
        "25,a,97500,10,3,-100\n30,a,97000,10,3,-100\n"
    )
    expect_error(
        tmp_path,
        capsys,
        text,
        radars_toml(),
        ["--init", "finite-memory"],
        ["m.csv line 5, column time_s"],
    )


def test_elevation_without_sigma_elevation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = HEADER3 + "0,a,100000,10,3,-100\n10,b,90000,20,4,-90\n20,a,98000,10,3,-100\n"
    expect_error(
        tmp_path,
        capsys,
        text,
        radars_toml(skip=(("b", "sigma_elevation_deg"),)),
        [],
        ["m.csv line 3, column elevation_deg", "sigma_elevation_deg", "'b'"],
    )


# --------------------------------------------------------------------------------------------
# The target at the radar's pole or site (the UKF's square root of a semi-definite P)
# --------------------------------------------------------------------------------------------


def overhead_plots(
    height_m: float, speed_mps: float = 10.0, period_s: float = 1.0, n: int = 20
) -> list[Plot]:
    """Noise-free plots (σr 1 m, σβ = σε = 1°) of a target that starts straight above
    (height > 0) or below the radar, elevation exactly ±90°, and flies off along +x: the
    first-plot start's position covariance is singular there (the azimuth column of the
    conversion Jacobian, r cos ε ∂u/∂β, vanishes)."""
    sigma = math.radians(1.0)
    out = []
    for k in range(n):
        dx = speed_mps * k * period_s
        el = math.atan2(height_m, dx)
        r = math.hypot(dx, height_m)
        out.append(Plot(k * period_s, r, 0.0, 1.0, sigma, (0.0, 0.0, 0.0), "a", el, sigma))
    return out


@pytest.mark.parametrize("height_m", [100.0, -100.0, 5.0, 3000.0])
def test_ukf_starting_at_the_pole_stays_finite_and_semidefinite(height_m: float) -> None:
    """Before the semi-definite square root and the Joseph-form P⁺ every one of these raised
    LinAlgError ("not positive definite") at the second or third plot."""
    plots = overhead_plots(height_m)
    dense = StreamTracker(("ukf",), True, StreamOptions()).add_block(plots)
    for rows in dense:
        _, x, P = rows[0]
        assert np.isfinite(x).all() and np.isfinite(P).all()
        np.testing.assert_array_equal(P, P.T)
        # Positive semi-definite to rounding: eigvalsh's own error is ~ eps · |P|.
        assert np.linalg.eigvalsh(P).min() >= -1e-13 * np.abs(P).max()


def test_track_3d_file_starting_at_the_pole(tmp_path: Path) -> None:
    """``radarviz track`` on a 3D file whose first plot is straight above the radar: every
    3D method writes finite tracks (the UKF used to end in a LinAlgError traceback)."""
    meas, radars = tmp_path / "m.csv", tmp_path / "r.toml"
    lines = ["time_s,radar,range_m,azimuth_deg,elevation_deg"]
    for p in overhead_plots(100.0):
        assert p.elevation_rad is not None
        lines.append(f"{p.time_s!r},a,{p.range_m!r},0.0,{math.degrees(p.elevation_rad)!r}")
    meas.write_text("\n".join(lines) + "\n")
    radars.write_text(radars_toml({"a": ((0.0, 0.0, 0.0), 2.0, 1.0, 1.0, 1.0)}))
    rows = run_track(tmp_path, meas, radars)
    assert {r["method"] for r in rows} == set(METHODS_3D)
    assert len(rows) == 20 * len(METHODS_3D)
    values = np.array([[float(r[c]) for c in TRACK_COLUMNS[2:]] for r in rows])
    assert np.isfinite(values).all()
