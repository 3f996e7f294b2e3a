"""One 3D constant-velocity track, updated plot by plot (no batching, no file I/O).

The Monte Carlo engines (``core.experiments.prosov``, ``core.filters.cv``) are 2D and batched over
runs. A measurement file with elevations needs one track in 3D, so this module keeps a single state

    x = (x, ẋ, y, ẏ, z, ż)  (6,),   P (6, 6)

(the 2D state (x, ẋ, y, ẏ) with ż appended, the layout ``viz_app.rerun.recording`` draws) and
implements, for a radar at ``site`` measuring range r, azimuth β (from +x towards +y) and
elevation ε (above the x–y plane)::

    x − xs = r cos ε cos β,   y − ys = r cos ε sin β,   z − zs = r sin ε

* ``cv6_predict``: x⁻ = F x, P⁻ = F P Fᵀ + Q, F = blockdiag([[1, T], [0, 1]] × 3), Q the
  discrete white-noise acceleration of ``core.filters.cv.process_noise`` on each axis.
* ``position_update``: the converted-measurement Kalman update, z = (x, y, z) with covariance
  R from ``core.conversion.planar.convert_naive_3d`` / ``convert_ucm_3d``, Joseph form.
* ``ekf3_update``: EKF on (r̂, β̂, ε̂), H the Jacobian of the map above at the prediction.
* ``ukf3_update``: the filterpy unscented update (``UKFParams``, 13 sigma points).
* ``doppler_update``: Doppler V̂r as a linear measurement of the velocity along the *measured*
  line of sight, the 3D form of ``core.experiments.doppler_start.doppler_los_update`` (that module's
  docstring says why not the textbook EKF row).
* ``finite_memory_start3``: the issue-3 start (Gorshkov's least-squares window) in 3D.

Every covariance update is the Joseph form P⁺ = (I − KH) P (I − KH)ᵀ + K R Kᵀ (or, for the
UKF, P − K S Kᵀ), symmetrised, so P stays symmetric positive definite over 10⁶ updates.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.polar import UKFParams, wrap_angle
from radarviz.core.finite_memory.fit import FiniteMemoryFit
from radarviz.core.geometry import line_of_sight

Vec = NDArray[np.float64]
Mat = NDArray[np.float64]

#: Indexes of the position and the velocity in the state.
POS = np.array([0, 2, 4])
VEL = np.array([1, 3, 5])
_I6 = np.eye(6)


class Track6(NamedTuple):
    """A 3D CV state: x (6,) = (x, ẋ, y, ẏ, z, ż) in m, m/s; P (6, 6) its covariance."""

    x: Vec
    P: Mat


@functools.lru_cache(maxsize=64)
def _transition(dt: float, sigma_a: float) -> tuple[Mat, Mat]:
    """F and Q for one (dt, σa): a file's steps repeat (a few scan periods), so they are made
    once (read-only arrays)."""
    F = np.eye(6)
    F[POS, VEL] = dt
    g = np.array([dt * dt / 2.0, dt])
    q = sigma_a * sigma_a * np.outer(g, g)
    Q = np.zeros((6, 6))
    for k in range(3):
        Q[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = q
    F.flags.writeable = Q.flags.writeable = False
    return F, Q


def cv6_transition(dt: float) -> Mat:
    """F (6, 6): each axis (p, ṗ) ← (p + T ṗ, ṗ)."""
    return _transition(float(dt), 0.0)[0]


def cv6_process_noise(dt: float, sigma_a: float) -> Mat:
    """Q (6, 6): σa² g gᵀ on each axis, g = (T²/2, T) (filterpy ``Q_discrete_white_noise``)."""
    return _transition(float(dt), float(sigma_a))[1]


def cv6_predict(track: Track6, dt: float, sigma_a: float) -> Track6:
    """Prediction over dt ≥ 0 seconds: x⁻ = F x, P⁻ = F P Fᵀ + Q."""
    F, Q = _transition(float(dt), float(sigma_a))
    P = F @ track.P @ F.T
    if sigma_a > 0.0:
        P += Q
    return Track6(F @ track.x, P)


def cv6_init(z: Vec, R: Mat, sigma_v0: float) -> Track6:
    """The spec's start: position z (3,) with covariance R (3, 3), velocity 0 ± σv0 per axis."""
    x = np.zeros(6)
    x[POS] = z
    P = np.zeros((6, 6))
    P[np.ix_(POS, POS)] = R
    P[VEL, VEL] = sigma_v0 * sigma_v0
    return Track6(x, P)


def _symmetric(P: Mat) -> Mat:
    return 0.5 * (P + P.T)


def joseph_update(track: Track6, nu: Vec, H: Mat, R: Mat) -> Track6:
    """Kalman update with innovation ν (k,), measurement matrix H (k, 6) and noise R (k, k).

        S = H P Hᵀ + R,  K = P Hᵀ S⁻¹,  x⁺ = x + K ν,
        P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ = P − K Uᵀ + (K S − U) Kᵀ,   U = P Hᵀ

    The Joseph form multiplied out (as ``core.filters.cv.joseph_update_position``): an identity
    for any gain, so a rounding error in K changes P only at second order, at a third of the
    6 × 6 products of forming (I − K H) P (I − K H)ᵀ.
    """
    P = track.P
    U = P @ H.T
    S = H @ U + R
    K = np.linalg.solve(S, U.T).T  # P Hᵀ S⁻¹ (S symmetric)
    P_new = P - K @ U.T + (K @ S - U) @ K.T
    return Track6(track.x + K @ nu, _symmetric(P_new))


_H_POS = np.zeros((3, 6))
_H_POS[[0, 1, 2], POS] = 1.0


def position_update(track: Track6, z: Vec, R: Mat) -> Track6:
    """Converted-measurement update: z (3,) a Cartesian point with covariance R (3, 3)."""
    return joseph_update(track, z - track.x[POS], _H_POS, R)


def polar3_jacobian(d: Vec) -> Mat:
    """∂(r, β, ε)/∂state (3, 6) at the offset d (velocity columns are 0).

    ∂r = (x, y, z)/r,  ∂β = (−y, x, 0)/ρ²,  ∂ε = (−x z, −y z, ρ²)/(r² ρ),  ρ = √(x² + y²)
    """
    x, y, z = d
    rho2 = x * x + y * y
    rho = np.sqrt(rho2)
    r2 = rho2 + z * z
    r = np.sqrt(r2)
    H = np.zeros((3, 6))
    H[0, POS] = (x / r, y / r, z / r)
    H[1, POS] = (-y / rho2, x / rho2, 0.0)
    H[2, POS] = (-x * z / (r2 * rho), -y * z / (r2 * rho), rho / r2)
    return H


def ekf3_update(track: Track6, site: Vec, z: Vec, sigmas: Vec) -> Track6:
    """EKF update with z = (r̂, β̂, ε̂) from a radar at ``site`` (3,); σ = (σr, σβ, σε).

    h(x) = (r, β, ε) of the predicted position minus the site, H = ∂h/∂x there
    (``polar3_jacobian``); the azimuth residual is wrapped to (−π, π].
    """
    pos = track.x[POS]
    nu = z - np.concatenate(line_of_sight(site[None], pos))  # (r, β, ε) of the prediction
    nu[1] = wrap_angle(nu[1])
    return joseph_update(track, nu, polar3_jacobian(pos - site), np.diag(np.square(sigmas)))


def ukf3_update(
    track: Track6, site: Vec, z: Vec, sigmas: Vec, params: UKFParams | None = None
) -> Track6:
    """UKF update with z = (r̂, β̂, ε̂): filterpy's ``UnscentedKalmanFilter.update`` in 3D.

    2n + 1 = 13 Merwe sigma points χ = x⁻, x⁻ ± [√((n + λ) P⁻)]_k (Cholesky columns), through
    h = (r, β, ε); the azimuth mean is taken relative to the central point's azimuth and every
    azimuth difference wrapped (see ``core.filters.polar.ukf_update``, whose weights and
    default α = 1, β = 2, κ = 0 this shares)::

        ẑ = Σ Wm_i ζ_i,  S = Σ Wc_i (ζ_i ⊖ ẑ)(ζ_i ⊖ ẑ)ᵀ + R,  Pxz = Σ Wc_i (χ_i − x⁻)(ζ_i ⊖ ẑ)ᵀ
        K = Pxz S⁻¹,  x⁺ = x⁻ + K (z ⊖ ẑ),  P⁺ = P⁻ − K S Kᵀ
    """
    p = params or UKFParams()
    n = 6
    c, wm0, wc0, w = p.weights(n)
    x, P = track.x, track.P
    L = np.linalg.cholesky(c * P)  # lower: its columns are filterpy's rows of the upper factor
    chi = np.concatenate([x[None], x + L.T, x - L.T])  # (13, 6)
    zeta = np.concatenate(line_of_sight(site[None], chi[:, POS]), axis=1)  # (13, 3): r, β, ε
    wm = np.full(2 * n + 1, w)
    wm[0] = wm0
    wc = wm.copy()
    wc[0] = wc0
    b0 = zeta[0, 1]
    zeta[:, 1] = b0 + wrap_angle(zeta[:, 1] - b0)  # unwrap around the central azimuth
    z_mean = wm @ zeta
    dz = zeta - z_mean
    dx = chi - x
    S = (wc[:, None] * dz).T @ dz + np.diag(np.square(sigmas))
    Pxz = (wc[:, None] * dx).T @ dz
    K = np.linalg.solve(S, Pxz.T).T
    nu = z - z_mean
    nu[1] = wrap_angle(nu[1])
    return Track6(x + K @ nu, _symmetric(P - K @ S @ K.T))


def los_frame(azimuth: float, elevation: float) -> tuple[Vec, Vec, Vec]:
    """The orthonormal frame of a line of sight: u (along it), e_β = ∂u/∂β / cos ε and
    e_ε = ∂u/∂ε."""
    ca, sa, ce, se = np.cos(azimuth), np.sin(azimuth), np.cos(elevation), np.sin(elevation)
    return (
        np.array([ce * ca, ce * sa, se]),
        np.array([-sa, ca, 0.0]),
        np.array([-se * ca, -se * sa, ce]),
    )


def doppler_update(
    track: Track6,
    vr: float,
    azimuth: float,
    elevation: float,
    sigma_vr: float,
    sigma_azimuth: float,
    sigma_elevation: float,
) -> Track6:
    """Doppler V̂r as a linear velocity measurement along the measured line of sight u(β̂, ε̂).

        V̂r = u·v + e,   H = u on the velocity,
        var e = σVr² + Σ_k σ_k² ((g_k·v̂)² + g_kᵀ P_vv g_k),   g_β = ∂u/∂β = cos ε e_β,  g_ε = ∂u/∂ε

    (a small angle error δ tilts u by g δ, so V̂r moves by g·v δ). With ε = 0 and σε = 0 this
    is ``core.experiments.doppler_start.doppler_los_update`` exactly.
    """
    x, P = track.x, track.P
    ca, sa = math.cos(azimuth), math.sin(azimuth)
    ce, se = math.cos(elevation), math.sin(elevation)
    u = np.array([ce * ca, ce * sa, se])
    vx, vy, vz = x[1], x[3], x[5]
    # g_β = ∂u/∂β = cos ε (−sin β, cos β, 0),  g_ε = ∂u/∂ε = (−sin ε cos β, −sin ε sin β, cos ε);
    # written out in floats: three-vectors are cheaper in Python than as numpy calls.
    gb = (-ce * sa, ce * ca)
    ge = (-se * ca, -se * sa, ce)
    pxx, pxy, pxz, pyy, pyz, pzz = P[1, 1], P[1, 3], P[1, 5], P[3, 3], P[3, 5], P[5, 5]
    gb_v = gb[0] * vx + gb[1] * vy
    gb_P_gb = gb[0] * gb[0] * pxx + 2.0 * gb[0] * gb[1] * pxy + gb[1] * gb[1] * pyy
    ge_v = ge[0] * vx + ge[1] * vy + ge[2] * vz
    ge_P_ge = (
        ge[0] * ge[0] * pxx
        + ge[1] * ge[1] * pyy
        + ge[2] * ge[2] * pzz
        + 2.0 * (ge[0] * ge[1] * pxy + ge[0] * ge[2] * pxz + ge[1] * ge[2] * pyz)
    )
    r_e = (
        sigma_vr * sigma_vr
        + sigma_azimuth**2 * (gb_v * gb_v + gb_P_gb)
        + sigma_elevation**2 * (ge_v * ge_v + ge_P_ge)
    )
    v = x[VEL]
    # Scalar Joseph update with h = u on the velocity: U = P h, S = hᵀ U + r_e, K = U / S,
    # P⁺ = P − K Uᵀ + (K S − U) Kᵀ (see ``joseph_update``).
    U = P[:, 1::2] @ u
    S = float(u @ U[1::2]) + r_e
    K = U / S
    P_new = P - np.outer(K, U) + np.outer(K * S - U, K)
    return Track6(x + K * (vr - float(u @ v)), _symmetric(P_new))


def finite_memory_start3(
    fit: FiniteMemoryFit,
    ranges: Vec,
    radial_velocities: Vec | None,
    azimuth: float,
    elevation: float,
    sigma_azimuth: float,
    sigma_elevation: float,
    sigma_v0: float,
    site: Vec,
) -> Track6:
    """The issue-3 start in 3D: Gorshkov's window fit, placed on the newest line of sight.

    The fit over k plots (oldest first; ``ranges`` (k,), ``radial_velocities`` (k,) or None)
    gives r̂, V̂r at the newest plot with covariance R (``fit.R``). In the frame (u, e_β, e_ε)
    of the newest measured line of sight (``los_frame``)::

        position = site + r̂ u,  var along = R11,  across: (r̂ cos ε σβ)², (r̂ σε)²
        velocity = V̂r u,        var along = R22,  across: σv0² each (nothing observed)
        cov(position along, velocity along) = R12

    then rotated into (x, ẋ, y, ẏ, z, ż). With ε = σε = 0 this is the 2D
    ``core.experiments.doppler_start.finite_memory_start`` plus z = zs ± 0.
    """
    if fit.order < 2:
        raise ValueError(
            f"a track start needs range and radial velocity; k = {fit.k} fits only "
            f"{fit.order} parameter"
        )
    z = ranges if radial_velocities is None else np.concatenate([ranges, radial_velocities])
    r_hat, vr_hat = fit.W[:2] @ z
    u, e_b, e_e = los_frame(azimuth, elevation)
    G = np.stack([u, e_b, e_e], -1)  # columns: the frame's axes in x, y, z
    cov_p = np.diag(
        [
            fit.R[0, 0],
            (r_hat * np.cos(elevation) * sigma_azimuth) ** 2,
            (r_hat * sigma_elevation) ** 2,
        ]
    )
    cov_v = np.diag([fit.R[1, 1], sigma_v0**2, sigma_v0**2])
    cov_pv = np.zeros((3, 3))
    cov_pv[0, 0] = fit.R[0, 1]
    x = np.zeros(6)
    x[POS] = site + r_hat * u
    x[VEL] = vr_hat * u
    P = np.zeros((6, 6))
    P[np.ix_(POS, POS)] = G @ cov_p @ G.T
    P[np.ix_(VEL, VEL)] = G @ cov_v @ G.T
    P[np.ix_(POS, VEL)] = G @ cov_pv @ G.T
    P[np.ix_(VEL, POS)] = P[np.ix_(POS, VEL)].T
    return Track6(x, _symmetric(P))
