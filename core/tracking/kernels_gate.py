"""The association's prefilter as a compiled loop (numba): which tracks may gate a batch's
plots, from each track's posterior at its last plot (``GNNTracker.near``, whose docstring
has the bound's mathematics). A few numpy statements over (K, P, d) arrays cost tens of
microseconds a batch at 10³ live tracks, more than the rest of a small batch's work; this
loop visits each (track, plot) pair once. Imported on first
use only.
"""

from __future__ import annotations

import math

from radarviz.core.filters.kernels_2d import _jit, coefficients, convert


@_jit
def near_pairs(slots, x, P, last_s, time_s, q_max, omega_max, points, r_ii, scale, rows, cols):
    """Write into rows, cols (N·B at most) the (track, plot) pairs, track k of ``slots``
    (N,) and plot j of the batch's B, whose bound on the gate holds; returns how many, in
    track then plot order.

    Args:
        slots: (N,) rows of x (K, n), P (K, n, n) (the state (x, ẋ, y, ẏ[, z, ż])) and
            last_s (K,) (the time of each track's last plot, s).
        time_s: (B,) the plots' times (s).
        q_max: the largest σa² of the motion model(s) (m²/s⁴).
        omega_max: the largest |ω| of the IMM's turn models (rad/s; 0 for none).
        points: (B, d) the plots' converted positions (site added); r_ii (B, d) their R_ii.
        scale: γ times the margin.

    Per axis i, with T = t_j − the track's last time: the straight-line mean
    c_i = x_i + T ẋ_i, the turns' reach δ = ω̄ T²/2 · √(|ẋ_h|² + tr P_vv,h) on the two
    horizontal axes (0 on z) and V_i(T) = (√(P_pp + 2T P_pv + T² P_vv) + δ)² + q_max T⁴/4;
    the pair holds when, on every axis, max(|z_i − c_i| − δ, 0)² < scale · (V_i(T) + R_ii)
    (``GNNTracker.near`` derives it). A NaN anywhere leaves the pair out.
    """
    d, n_p = points.shape[1], points.shape[0]
    found = 0
    for k in range(slots.shape[0]):
        s = slots[k]
        # E|v_h|²: the horizontal speed's second moment under the track's posterior.
        speed2 = x[s, 1] ** 2 + x[s, 3] ** 2 + P[s, 1, 1] + P[s, 3, 3]
        reach = 0.5 * omega_max * math.sqrt(speed2)  # a NaN state: NaN, the pair fails
        for j in range(n_p):
            T = time_s[j] - last_s[s]
            inside = True
            for a in range(d):
                p, v = 2 * a, 2 * a + 1
                delta = reach * T * T if a < 2 else 0.0
                nu = abs(points[j, a] - (x[s, p] + T * x[s, v])) - delta
                if nu < 0.0:
                    nu = 0.0
                var = P[s, p, p] + 2.0 * T * P[s, p, v] + T * T * P[s, v, v]
                if var < 0.0:  # rounding of a tiny variance
                    var = 0.0
                noise = 0.25 * q_max * T**4 + r_ii[j, a]
                # (√var + δ)² ≤ 2 var + 2 δ²: a pair outside that looser bound is outside
                # the bound itself, and most pairs are, without a square root.
                if not nu * nu < scale * (2.0 * (var + delta * delta) + noise):
                    inside = False
                    break
                sd = math.sqrt(var) + delta
                if not nu * nu < scale * (sd * sd + noise):  # a NaN fails
                    inside = False
                    break
            if inside:
                rows[found], cols[found] = k, j
                found += 1
    return found


@_jit
def plot_points_2d(code: int, r_m, az_rad, sigma_r, sigma_b, site, points, r_ii):
    """The converted plots of ``near_pairs`` in 2D: plot j's point z + s into points[j]
    (B, 2) and its R_xx, R_yy into r_ii[j] (B, 2), by the tracker kernels' conversion of
    method ``code`` (``core.filters.kernels_2d.coefficients`` and ``convert``; a method
    that converts the plot alone). r_m, az_rad, sigma_r, sigma_b (B,), site (B, 2)."""
    for j in range(r_m.shape[0]):
        sr2, s = sigma_r[j] * sigma_r[j], sigma_b[j] * sigma_b[j]
        co = coefficients(code, s, sr2)
        zx, zy, r00, _, r11 = convert(code, r_m[j], az_rad[j], sr2, s, 0.0, 0.0, co)
        points[j, 0], points[j, 1] = zx + site[j, 0], zy + site[j, 1]
        r_ii[j, 0], r_ii[j, 1] = r00, r11
