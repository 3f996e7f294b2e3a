"""The consistency monitor's update as a compiled loop (numba), for the compiled tracker.

``core.tracking.consistency.ConsistencyMonitor.add`` is a few Python statements per update;
a file of 10⁶ plots and seven methods makes 7·10⁶ of them, more than the filtering. This
kernel makes the same updates, in the same order and with the same floating-point
operations (running sums added to and subtracted from as the monitor does), over arrays that
hold every track's monitor state; ``core.tracking.compiled.MonitorFeed`` moves that state to
and from the monitor's own records. Imported on first use only.
"""

from __future__ import annotations

import math

import numpy as np

from radarviz.core.filters.kernels_2d import _jit


@_jit
def monitor_updates(
    track, time_s, nis, dof, window, sustain, lo_tab, hi_tab, ring_nis, ring_dof, count,
    nis_sum, dof_sum, total_nis, total_dof, updates, windows, above, below, run_out, left,
    first_exit, ev_track, ev_time, ev_kind, ev_q, ev_lo, ev_hi,
):  # fmt: skip
    """Feed updates u = 0 … U − 1 (track[u], time_s[u], nis[u], dof[u]) in order; returns
    the number of events written to ev_* (track, time, kind 1 leaves / 0 returns, q and
    the band lo, hi).

    Per track T: ring_nis, ring_dof (T, window) the window oldest first, count (T,) its
    length; the sums and counters of ``consistency._Track``; first_exit NaN before the first.
    lo_tab, hi_tab: the band of each window dof D (``nis_band(D)``, indexed by D)."""
    n_ev = 0
    for u in range(track.shape[0]):
        t = track[u]
        v = nis[u]
        if not math.isfinite(v):
            v = math.inf  # a broken track is as far out of its band as it gets
        d = dof[u]
        updates[t] += 1
        total_nis[t] += v
        total_dof[t] += d
        nis_sum[t] += v
        dof_sum[t] += d
        c = count[t]
        if c == window:  # the oldest leaves: shift the window (w is ~10)
            nis_sum[t] -= ring_nis[t, 0]
            dof_sum[t] -= ring_dof[t, 0]
            for a in range(window - 1):
                ring_nis[t, a] = ring_nis[t, a + 1]
                ring_dof[t, a] = ring_dof[t, a + 1]
            c -= 1
        ring_nis[t, c] = v
        ring_dof[t, c] = d
        count[t] = c + 1
        if c + 1 < window:
            continue
        if math.isinf(nis_sum[t]):  # a running sum does not recover from inf: recompute
            acc = 0.0
            for a in range(window):
                acc += ring_nis[t, a]
            nis_sum[t] = acc
        q = nis_sum[t] / dof_sum[t]
        lo, hi = lo_tab[dof_sum[t]], hi_tab[dof_sum[t]]
        windows[t] += 1
        out = not (lo <= q <= hi)
        if q > hi:
            above[t] += 1
        if q < lo:
            below[t] += 1
        run_out[t] = run_out[t] + 1 if out else 0
        if run_out[t] == sustain or (left[t] and not out):
            left[t] = out
            if out and np.isnan(first_exit[t]):
                first_exit[t] = time_s[u]
            ev_track[n_ev], ev_time[n_ev], ev_q[n_ev] = t, time_s[u], q
            ev_kind[n_ev] = 1 if out else 0
            ev_lo[n_ev], ev_hi[n_ev] = lo, hi
            n_ev += 1
    return n_ev
