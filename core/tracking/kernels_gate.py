"""The association's prefilter as a compiled loop (numba): which tracks may gate a batch's
plots, from each track's posterior at its last plot (``GNNTracker.near``, whose docstring
has the bound's mathematics). A few numpy statements over (K, P, d) arrays cost tens of
microseconds a batch at 10³ live tracks, more than the rest of a small batch's work; this
loop visits each (track, plot) pair once. Imported on first
use only.
"""

from __future__ import annotations

import math

import numpy as np

from radarviz.core.filters.kernels_2d import _inline, _jit, convert


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


#: How long a track's box (``track_box``) serves, s: past it, or after the track's next
#: plot, the box is drawn again. Longer boxes are drawn less often and admit more tracks.
BOX_HORIZON_S = 1.0
#: The rows of a box column: its x and y bounds (m), and the plot times it holds for (s).
BOX_X_LO, BOX_X_HI, BOX_Y_LO, BOX_Y_HI, BOX_FROM_S, BOX_UNTIL_S = 0, 1, 2, 3, 4, 5
BOX_COLUMNS = 6


@_jit
def track_box(x, P, last_s, s, t_from, t_until, q_max, omega_max, scale, boxes, q):
    """Draw slot s's box into column q of boxes (``BOX_COLUMNS``, K): a horizontal box
    holding, for every plot time in [t_from, t_until], every 2D point that ``near_pairs``'
    bound admits for slot s
    (x (K, n), P (K, n, n), last_s (K,) as there) once the box is widened on each axis by
    √(scale R_ii) of the plot (``boxes_near``).

    With T between T₀ = t_from − last and T₁ = t_until − last, the mean c_i(T) = x_i + T ẋ_i
    lies between c_i(T₀) and c_i(T₁) (it is linear in T); δ (∝ T²) and q_max T⁴/4 are at
    most their values at T̄ = max(|T₀|, |T₁|), and P_pp + 2T P_pv + T² P_vv (convex in T)
    at most V̄, its larger end value. A pair that passes ``near_pairs``' looser test,
    (|z_i − c_i| − δ)₊² < scale · (2 (V + δ²) + q_max T⁴/4 + R_ii), then has
    |z_i − c_i| < δ̄ + √(scale · (2 (V̄ + δ̄²) + q_max T̄⁴/4)) + √(scale R_ii) (as
    √(a + b) ≤ √a + √b): inside [min c_i − w_i, max c_i + w_i] widened by √(scale R_ii),
    w_i the first two terms, plus an allowance of 10⁻⁹ for rounding. A NaN state gives a
    NaN box, which ``boxes_near`` keeps (the exact test then rejects it)."""
    speed2 = x[s, 1] ** 2 + x[s, 3] ** 2 + P[s, 1, 1] + P[s, 3, 3]
    t0, t1 = t_from - last_s[s], t_until - last_s[s]
    tt = max(t0 * t0, t1 * t1)
    delta = 0.5 * omega_max * math.sqrt(speed2) * tt
    for a in range(2):
        p, v = 2 * a, 2 * a + 1
        c0, c1 = x[s, p] + t0 * x[s, v], x[s, p] + t1 * x[s, v]
        v0 = P[s, p, p] + 2.0 * t0 * P[s, p, v] + t0 * t0 * P[s, v, v]
        v1 = P[s, p, p] + 2.0 * t1 * P[s, p, v] + t1 * t1 * P[s, v, v]
        var = max(v0, v1, 0.0)
        w = delta + math.sqrt(scale * (2.0 * (var + delta * delta) + 0.25 * q_max * tt * tt))
        w += 1e-9 * (w + abs(c0) + abs(c1) + 1.0)
        boxes[2 * a, q] = min(c0, c1) - w
        boxes[2 * a + 1, q] = max(c0, c1) + w
    boxes[BOX_FROM_S, q], boxes[BOX_UNTIL_S, q] = t_from, t_until


@_inline
def _far(boxes, q, lo_x, hi_x, lo_y, hi_y) -> bool:
    """Box column q misses [lo_x, hi_x] × [lo_y, hi_y] (a NaN box does not: one condition
    without a branch per bound, the four taken at random)."""
    return (
        (boxes[BOX_X_HI, q] < lo_x)
        | (boxes[BOX_X_LO, q] > hi_x)
        | (boxes[BOX_Y_HI, q] < lo_y)
        | (boxes[BOX_Y_LO, q] > hi_y)
    )


@_jit
def boxes_near(slots, x, P, last_s, t_lo, t_hi, q_max, omega_max, points, r_ii, scale,
               boxes, out):  # fmt: skip
    """Write into out (N at most) the tracks of ``slots`` (N,) whose box (``track_box``;
    slots[q]'s in column q of boxes (``BOX_COLUMNS``, K)) meets a batch's 2D plots, points
    (B, 2) and r_ii (B, 2) as ``near_pairs`` takes them, times from t_lo to t_hi: each
    plot's point inside the box widened by √(scale R_ii); in ``slots`` order; returns how
    many. A box that does not hold for the batch's times (the track has had a plot since,
    or it was drawn for earlier times) is drawn again first, for
    [t_lo, t_lo + ``BOX_HORIZON_S``] (at least to t_hi). A track left out has no pair in
    ``near_pairs`` (``track_box``), so ``near_pairs`` over the tracks kept finds the same
    pairs; the test costs a few comparisons a track, whatever the batch's size.

    Two passes: the first reads the boxes in order and flags, without a branch, each box
    that is stale or meets the batch's bounds (a NaN box meets them: the exact test rejects
    it); the second draws the stale ones again and keeps those that meet."""
    lo_x, lo_y, hi_x, hi_y = math.inf, math.inf, -math.inf, -math.inf
    for j in range(points.shape[0]):
        ex = math.sqrt(scale * r_ii[j, 0]) * (1.0 + 1e-9)
        ey = math.sqrt(scale * r_ii[j, 1]) * (1.0 + 1e-9)
        lo_x, hi_x = min(lo_x, points[j, 0] - ex), max(hi_x, points[j, 0] + ex)
        lo_y, hi_y = min(lo_y, points[j, 1] - ey), max(hi_y, points[j, 1] + ey)
    until = max(t_lo + BOX_HORIZON_S, t_hi)
    n = slots.shape[0]
    b_from, b_until = boxes[BOX_FROM_S], boxes[BOX_UNTIL_S]
    flag = np.empty(n, np.bool_)
    for q in range(n):
        held = (b_from[q] <= t_lo) & (t_hi <= b_until[q])  # NaN times: not held
        far = _far(boxes, q, lo_x, hi_x, lo_y, hi_y)
        flag[q] = not (held and far)
    kept = 0
    for q in range(n):
        if not flag[q]:
            continue
        if not (b_from[q] <= t_lo and t_hi <= b_until[q]):
            track_box(x, P, last_s, slots[q], t_lo, until, q_max, omega_max, scale, boxes, q)
            if _far(boxes, q, lo_x, hi_x, lo_y, hi_y):
                continue
        out[kept] = slots[q]
        kept += 1
    return kept


@_jit
def plot_points_2d(form, co, r_m, az_rad, sigma_r_m, sigma_beta_rad, site, points, r_ii):
    """The converted plots of ``near_pairs`` in 2D: plot j's point z + s into points[j]
    (B, 2) and its R_xx, R_yy into r_ii[j] (B, 2), by the tracker kernels' conversion
    (``core.filters.kernels_2d.convert``) of covariance ``form`` with plot j's scalars co[j]
    (B, 8) (``core.filters.methods.conversion_table``; a conversion of the plot alone).
    r_m, az_rad, sigma_r_m, sigma_beta_rad (B,), site (B, 2)."""
    for j in range(r_m.shape[0]):
        sr2, s = sigma_r_m[j] * sigma_r_m[j], sigma_beta_rad[j] * sigma_beta_rad[j]
        zx, zy, r00, _, r11 = convert(form, r_m[j], az_rad[j], sr2, s, 0.0, 0.0, co[j])
        points[j, 0], points[j, 1] = zx + site[j, 0], zy + site[j, 1]
        r_ii[j, 0], r_ii[j, 1] = r00, r11
