"""The association's prefilter as a compiled loop (numba): which tracks may gate a batch's
plots, from each track's posterior at its last plot (``GNNTracker.near``, whose docstring
has the bound's mathematics). A few numpy statements over (K, P, d) arrays cost tens of
microseconds a batch at 10³ live tracks, more than the rest of a small batch's work; this
loop visits each track once and stops at its first plot inside the bound. Imported on first
use only.
"""

from __future__ import annotations

import numpy as np

from radarviz.core.filters.kernels_2d import _jit


@_jit
def near_tracks(slots, x, P, last_s, first_s, end_s, q_max, points, r_ii, scale, keep):
    """Mark in ``keep`` (N,) the slots (N,) whose bounded gate box holds a plot; returns
    how many.

    Args:
        slots: (N,) rows of x (K, n), P (K, n, n) (the state (x, ẋ, y, ẏ[, z, ż])) and
            last_s (K,) (the time of each track's last plot, s).
        first_s, end_s: the batch's first and last plot time (s).
        q_max: the largest σa² of the motion model(s) (m²/s⁴).
        points: (B, d) the plots' converted positions (site added); r_ii (B, d) their R_ii.
        scale: γ times the margin.

    Per axis i and end time T ∈ {first_s, end_s} − last_s: the mean x_i + T ẋ_i and
    V_i(T) = P_pp + 2T P_pv + T² P_vv + q_max T⁴/4; a plot z is inside when, on every axis,
    its distance beyond the segment between the two means, squared, is below
    scale · (max_T V_i(T) + R_ii). A NaN anywhere leaves the pair outside.
    """
    d, n_p = points.shape[1], points.shape[0]
    found = 0
    lo, hi, var = np.empty(d), np.empty(d), np.empty(d)
    for k in range(slots.shape[0]):
        s = slots[k]
        ta, tb = first_s - last_s[s], end_s - last_s[s]
        for a in range(d):
            p, v = 2 * a, 2 * a + 1
            ma, mb = x[s, p] + ta * x[s, v], x[s, p] + tb * x[s, v]
            lo[a], hi[a] = min(ma, mb), max(ma, mb)
            va = P[s, p, p] + 2.0 * ta * P[s, p, v] + ta * ta * P[s, v, v]
            vb = P[s, p, p] + 2.0 * tb * P[s, p, v] + tb * tb * P[s, v, v]
            var[a] = max(va + 0.25 * q_max * ta**4, vb + 0.25 * q_max * tb**4)
        keep[k] = False
        for j in range(n_p):
            inside = True
            for a in range(d):
                z = points[j, a]
                out = max(lo[a] - z, z - hi[a], 0.0)
                if not out * out < scale * (var[a] + r_ii[j, a]):  # a NaN fails too
                    inside = False
                    break
            if inside:
                keep[k] = True
                found += 1
                break
    return found
