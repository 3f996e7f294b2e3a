"""The compiled (numba) kernel behind ``core.filters.compiled``: the numpy engine's equations
(see that module's table) on each track's state as scalars (x and the ten upper entries of
P), so a whole step is straight-line code on numbers. The Monte Carlo kernel
``filter_scans_2d`` runs these steps on blocks of runs held as structure of arrays, in loops
over the runs of a block that LLVM vectorises (one run per lane of a packed register).

The per-step functions come in two forms: ``*_s`` on (x, p) tuples, which the kernels chain
(``filter_scans_2d`` a binding of them to vectorisable sine, cosine and arc tangent,
``core.filters.trig``), and the array forms (``start``, ``predict``,
``position_update``, ``ukf_update``, ``doppler_update``, ``track_terms``) that load a track
from arrays, call them and store it, for callers holding one track in arrays.

Imported only by ``core.filters.compiled._kernel`` on first use, so importing numba (and
loading the cached machine code) is paid only by commands that filter a Monte Carlo.
"""

from __future__ import annotations

import math
from math import atan2, cos, sin, sqrt

import numba
import numpy as np

from radarviz.core.confidence import BAND_GROUPS
from radarviz.core.conversion.elementwise import CONVERSION_FUNCTIONS, Covariance
from radarviz.core.filters import tuples
from radarviz.core.filters.methods import Kind
from radarviz.core.filters.predict import (
    add_process_noise,
    predict_2d,
    predict_components,
    white_acceleration,
)
from radarviz.core.filters.rebind import rebind
from radarviz.core.filters.steps_2d import bind_2d
from radarviz.core.filters.trig import atan2 as trig_atan2
from radarviz.core.filters.trig import sincos
from radarviz.core.filters.tuples import load_2d, store_2d

# error_model="numpy": a division by zero or a negative pivot gives inf / NaN for that track,
# as the numpy engine does, instead of raising. cache=True: compiled once per machine.
# nogil=True: blocks of runs filter in parallel threads (``core.experiments.prosov``).
# fastmath: fused multiply-adds and reordered sums (results move by rounding only, far inside
# the 1e-9 the tests hold the kernel to); never "nnan"/"ninf", which NaN tracks rely on.
# _inline marks the small scalar functions the kernels call per step: each is typed and
# compiled once, and marked for LLVM to inline into every caller (forceinline: the LLVM
# attribute alwaysinline), where its tuples become registers. numba's own inlining
# (inline="always") types a function again at every call site (the 2D IMM tracker kernel
# alone took 30 s of CPU to compile); left to LLVM's cost model, the larger steps (the
# Joseph update, the UKF) stay calls that pass their tuples through memory, and the Monte
# Carlo kernel took 1.8x the time per track-step (docs/performance.md, section 10).
_FAST = {"contract", "reassoc", "nsz", "arcp"}
_jit = numba.njit(cache=True, error_model="numpy", nogil=True, fastmath=_FAST)
_inline = numba.njit(cache=True, error_model="numpy", nogil=True, fastmath=_FAST, forceinline=True)


_TWO_PI = 2.0 * math.pi


@_inline
def wrap(a: float) -> float:
    # core.geometry.wrap_angle: a − 2π ceil(a/(2π) − ½), to (−π, π]; numpy's ceil, a float
    # (math.ceil's is an integer, whose conversions a vectorised loop would pay for)
    return a - _TWO_PI * np.ceil(a * (1.0 / _TWO_PI) - 0.5)


# The conversions' arithmetic lives in ``core.conversion.elementwise`` (the numpy engine's and
# the array-API path's too), compiled here. A conversion reaches a kernel as its covariance
# form (a ``Covariance``) and its scalars (``core.filters.methods.conversion_table``, κ
# first), never as a name: the kernels branch on the form only.
conversion_steps = rebind(CONVERSION_FUNCTIONS, {}, _inline)
_converted_point = conversion_steps["converted_point"]


@_inline
def row_tuple(co):
    """An (8,) row of conversion scalars as a tuple (registers, not loads, in a loop)."""
    return (co[0], co[1], co[2], co[3], co[4], co[5], co[6], co[7])


@_inline
def convert_cs(form, r: float, cos_b: float, sin_b: float, sr2: float, s: float, px, py, co):
    # A conversion's point and covariance (radar-centred) of the plot (r, β̂), cos_b = cos β̂,
    # sin_b = sin β̂; ``form`` its ``Covariance``, ``co`` its scalars (a row of
    # ``conversion_table``, or its tuple); (px, py) the radar-centred prediction (read by
    # ``EXACT_AT_PREDICTION`` only).
    rp = cp = sp = 0.0
    if form == Covariance.EXACT_AT_PREDICTION:  # the covariance at the predicted position
        rp = norm(px, py)
        cp, sp = px / rp, py / rp
    return _converted_point(form, r, cos_b, sin_b, sr2, s, co, rp, cp, sp)


@_inline
def convert(form, r: float, b: float, sr2: float, s: float, px: float, py: float, co):
    # ``convert_cs`` with the C library's cos β̂, sin β̂
    return convert_cs(form, r, cos(b), sin(b), sr2, s, px, py, co)


# The state of one track as scalars: x = (x, ẋ, y, ẏ) and p = the ten upper entries of the
# symmetric P, (p00, p01, p02, p03, p11, p12, p13, p22, p23, p33). A kernel walking one track
# keeps them in registers over its scans; the array forms below (``start``, ``predict``,
# ``position_update``, ``ukf_update``, ``doppler_update``: x (4,), P (4, 4) updated in place,
# for callers holding one track in arrays) load, call these and store.


# A track's arrays to tuples and back (``core.filters.tuples``, the numpy engine's IMM too).
load = _inline(load_2d)
store = _inline(store_2d)
load_3d = _inline(tuples.load_3d)
store_3d = _inline(tuples.store_3d)


@_inline
def load_row(state, m):
    """(x, p) of row m of a (runs, 14) state array: x then p. (Indexed in place: a view
    per call would cost a reference count per track-step.)"""
    return (state[m, 0], state[m, 1], state[m, 2], state[m, 3]), (
        state[m, 4], state[m, 5], state[m, 6], state[m, 7], state[m, 8], state[m, 9],
        state[m, 10], state[m, 11], state[m, 12], state[m, 13],
    )  # fmt: skip


@_inline
def store_row(xt, p, state, m):
    for i in range(4):
        state[m, i] = xt[i]
    for i in range(10):
        state[m, 4 + i] = p[i]


@_inline
def store_at(xt, p, xs, Ps, i, j):
    """Write (x, p) into xs[i, j] (4,) and the symmetric Ps[i, j] (4, 4), in place."""
    for a in range(4):
        xs[i, j, a] = xt[a]
    k = 0
    for a in range(4):
        for b_ in range(a, 4):
            Ps[i, j, a, b_] = p[k]
            Ps[i, j, b_, a] = p[k]
            k += 1


@_inline
def start_s(zx: float, zy: float, r00: float, r01: float, r11: float, sigma_v0_mps: float):
    # cv_init: position z with covariance R, velocity 0 with variance σv0²
    v = sigma_v0_mps * sigma_v0_mps
    return (zx, 0.0, zy, 0.0), (r00, 0.0, r01, 0.0, v, 0.0, 0.0, r11, 0.0, v)


# The prediction's arithmetic lives in ``core.filters.predict`` (the numpy engine and the
# array-API path call the same functions), compiled here once for every kernel module.
_predict_2d = _inline(predict_2d)
white_acceleration_c = _inline(white_acceleration)
predict_components_c = _inline(predict_components)
add_process_noise_c = _inline(add_process_noise)


@_inline
def predict_s(xt, p, T: float, q: float):
    # cv_predict: x⁻ = F x, P⁻ = F P Fᵀ + Q, σa² = q (``core.filters.predict.predict_2d``)
    return _predict_2d(xt, p, T, white_acceleration_c(T, q))


@_inline
def _select(c: bool, a: float, b: float) -> float:
    # ``where`` for numbers
    return a if c else b


# The 2D updates (position, EKF, UKF, Doppler: ``core.filters.steps_2d``), written once as
# plain arithmetic (the numpy engine's and the array-API path's too), compiled here with the
# scalar elementary functions.
_steps = bind_2d(
    {"sqrt": sqrt, "where": _select, "atan2": atan2, "wrap": wrap, "cos": cos, "sin": sin},
    _inline,
)
_add_outer = _steps["_add_outer"]
norm = _steps["_norm"]  # √(x² + y²) (``core.filters.ukf_2d``), ducm's range too
position_update_s = _steps["position_update_2d"]
ekf_measurement_s = _steps["ekf_measurement_2d"]
ukf_update_s = _steps["ukf_update_2d"]
doppler_update_s = _steps["doppler_update_2d"]


@_inline
def terms_s(xt, p, t, c: float, s: float):
    """The metric terms of one track at one scan (``core.metrics.scan_terms``, in
    ``SUM_NAMES`` order): xt, p the state, t the true state (a 4-tuple), (c, s) the true line
    of sight.

    The NEES by blocks: with A = P_pos (x, y), B = P_vel, C their cross-covariance and
    S = B − Cᵀ A⁻¹ C (the Schur complement), eᵀ P⁻¹ e = e_posᵀ A⁻¹ e_pos + rᵀ S⁻¹ r with
    r = e_vel − Cᵀ A⁻¹ e_pos: two 2 × 2 inverses, no square root (a Cholesky factor's chain
    of roots and divisions costs more than the filter's update). NaN unless P is positive
    definite (A and S are), as ``core.filters.state.quad_form_inv`` gives."""
    ex, ey = xt[0] - t[0], xt[2] - t[2]
    ev, ew = xt[1] - t[1], xt[3] - t[3]
    p00, p01, p02, p03, p11, p12, p13, p22, p23, p33 = p
    det_a = p00 * p22 - p02 * p02
    ia = 1.0 / det_a
    a0, a1 = (p22 * ex - p02 * ey) * ia, (p00 * ey - p02 * ex) * ia  # A⁻¹ e_pos
    nees_pos = ex * a0 + ey * a1
    # M = A⁻¹ C, C = [[p01, p03], [p12, p23]] (rows x, y; columns ẋ, ẏ)
    m00, m10 = (p22 * p01 - p02 * p12) * ia, (p00 * p12 - p02 * p01) * ia
    m01, m11 = (p22 * p03 - p02 * p23) * ia, (p00 * p23 - p02 * p03) * ia
    s00 = p11 - (p01 * m00 + p12 * m10)
    s01 = p13 - (p01 * m01 + p12 * m11)
    s11 = p33 - (p03 * m01 + p23 * m11)
    det_s = s00 * s11 - s01 * s01
    r0, r1 = ev - (p01 * a0 + p12 * a1), ew - (p03 * a0 + p23 * a1)
    nees = nees_pos + (s11 * r0 * r0 - 2.0 * s01 * r0 * r1 + s00 * r1 * r1) / det_s
    if not (p00 > 0.0 and det_a > 0.0 and s00 > 0.0 and det_s > 0.0):
        nees = math.nan
    return (
        ex, ex * ex, ey, ey * ey, c * ex + s * ey, c * ey - s * ex, p00, p22, nees_pos, nees,
    )  # fmt: skip


# The per-step functions on arrays: x (4,), P (4, 4) updated in place (P written symmetric),
# for callers that hold a track in arrays. K, V, L, Z, E: scratch arrays the signatures keep
# (the scalar forms above need none).


@_inline
def start(x, P, zx: float, zy: float, r00: float, r01: float, r11: float, sigma_v0_mps: float):
    # cv_init: position z with covariance R, velocity 0 with variance σv0²
    xt, p = start_s(zx, zy, r00, r01, r11, sigma_v0_mps)
    store(xt, p, x, P)


@_inline
def predict(x, P, T: float, q: float):
    # cv_predict: x⁻ = F x, P⁻ = F P Fᵀ + Q
    xt, p = load(x, P)
    xt, p = predict_s(xt, p, T, q)
    store(xt, p, x, P)


@_inline
def position_update(x, P, nx: float, ny: float, r00: float, r01: float, r11: float, K, V):
    # core.filters.position: the Joseph-form update by the innovation ν = (nx, ny), R
    xt, p = load(x, P)
    xt, p = position_update_s(xt, p, nx, ny, r00, r01, r11)
    store(xt, p, x, P)


@_inline
def ukf_update(x, P, r, b, vr, vb, sx, sy, prm, L, Z, K, E):
    # core.filters.polar_ukf with prm = (c, Wm0, Wc0, W) (``UKFParams.weights``)
    xt, p = load(x, P)
    xt, p = ukf_update_s(xt, p, r, b, vr, vb, sx, sy, prm[0], prm[1], prm[2], prm[3])
    store(xt, p, x, P)


@_inline
def doppler_update(x, P, vr_hat: float, b: float, var_vr: float, vb: float, K):
    # core.filters.doppler: the update by V̂r along the measured line of sight
    xt, p = load(x, P)
    xt, p = doppler_update_s(xt, p, vr_hat, b, var_vr, vb)
    store(xt, p, x, P)


@_jit
def track_terms(x, P, t, c, s, out, k, m, L, y, e):
    """The terms of one track at one scan into out[:, k, m]: x (4,), P (4, 4), t the (4,)
    truth, (c, s) the true line of sight (``terms_s``; L, y, e unused scratch)."""
    xt, p = load(x, P)
    tm = terms_s(xt, p, (t[0], t[1], t[2], t[3]), c, s)
    for a in range(10):
        out[a, k, m] = tm[a]


# The Monte Carlo kernel works on blocks of ``LANES`` runs in structure-of-arrays form: one
# buffer of ``_ROWS`` rows × ``LANES`` (row k of lane j at k·LANES + j): the state (x then
# the upper entries of P, as ``load_row``), the scan's plot (r̂, β̂, V̂r) and the metric terms.
# Each stage of a scan is one loop over the lanes that loads a lane's numbers, calls the
# steps above on them and stores them, so LLVM vectorises it: consecutive runs go side by
# side in a packed register. One buffer and a constant row stride let it prove the rows
# apart (no run-time alias checks), and a block always has ``LANES`` lanes (a short block's
# last lanes repeat its first run), so the loops have a constant count and no scalar tail.
# 256 lanes keep the buffer (55 kB) within the second-level cache's closest part with the
# block's measurement rows.

#: Runs filtered side by side: the lanes of the structure-of-arrays blocks (a multiple of
#: ``BAND_GROUPS``, so each block deals its runs to the groups the same way).
LANES = 256
assert LANES % BAND_GROUPS == 0
_STATE, _R, _B, _V, _TERMS = 0, 14, 15, 16, 17
_ROWS = _TERMS + 10


# The steps again, for the vectorised loops: the same functions bound to elementary functions
# that are plain arithmetic (``core.filters.trig``), since a call to the C library's cos or
# atan2 keeps LLVM from vectorising a loop. The trig functions keep their sums in order (no
# "reassoc": the rounding to an integer adds and subtracts 1.5·2⁵²). The bound copies carry
# the original functions' names, so they are not cached on their own (two bindings of one
# name would share a cache entry); the kernels that inline them are.
_exact = numba.njit(
    cache=True, error_model="numpy", nogil=True, fastmath={"contract", "nsz"}, forceinline=True
)
_sincos = _exact(sincos)
_atan2_v = _exact(trig_atan2)
_inline_v = numba.njit(
    cache=False, error_model="numpy", nogil=True, fastmath=_FAST, forceinline=True
)


@_inline
def _sin_v(a: float) -> float:
    return _sincos(a)[0]


@_inline
def _cos_v(a: float) -> float:
    return _sincos(a)[1]


_vsteps = bind_2d(
    {"sqrt": sqrt, "where": _select, "atan2": _atan2_v, "wrap": wrap, "cos": _cos_v, "sin": _sin_v},
    _inline_v,
)
position_update_v = _vsteps["position_update_2d"]
ekf_update_v = _vsteps["ekf_update_2d"]
ukf_update_v = _vsteps["ukf_update_2d"]
doppler_update_v = _vsteps["doppler_update_2d"]


@_inline
def _lane(buf, j):
    """(x, p) of lane j of a block buffer."""
    return (buf[j], buf[LANES + j], buf[2 * LANES + j], buf[3 * LANES + j]), (
        buf[4 * LANES + j], buf[5 * LANES + j], buf[6 * LANES + j], buf[7 * LANES + j],
        buf[8 * LANES + j], buf[9 * LANES + j], buf[10 * LANES + j], buf[11 * LANES + j],
        buf[12 * LANES + j], buf[13 * LANES + j],
    )  # fmt: skip


@_inline
def _store_lane(xt, p, buf, j):
    for k in range(4):
        buf[k * LANES + j] = xt[k]
    for k in range(10):
        buf[(4 + k) * LANES + j] = p[k]


# The kinds and covariance forms as plain integers for the Monte Carlo kernel's dispatch: numba
# compiles ``_update_lanes`` once per literal integer it is passed, its other branches pruned
# before LLVM vectorises the loop. An IntEnum member has no literal type (nor do arguments
# passed as ``*args``), and the one loop compiled with every branch in it took 1.7× the
# time per track-step.
_CONVERTED, _EKF, _UKF = int(Kind.CONVERTED), int(Kind.EKF), int(Kind.UKF)
_LINEARIZED, _AVERAGED = int(Covariance.LINEARIZED), int(Covariance.AVERAGED)
_EXACT, _AT_PREDICTION = int(Covariance.EXACT), int(Covariance.EXACT_AT_PREDICTION)


@_inline
def _update_lanes(kind, form, buf, sr2, s, T, q, sx, sy, co, c, wm0, wc0, w):
    # Every lane of a block one scan on: predict, then the method's update on the lane's plot
    # (the steps' vectorisable binding). ``kind`` (a ``Kind``) and ``form`` (a converted
    # method's ``Covariance``) are literal integers where this is called (above).
    for j in range(LANES):
        xt, p = _lane(buf, j)
        r, b = buf[_R * LANES + j], buf[_B * LANES + j]
        xt, p = predict_s(xt, p, T, q)
        if kind == _EKF:
            xt, p = ekf_update_v(xt, p, r, b, sr2, s, sx, sy)
        elif kind == _UKF:
            xt, p = ukf_update_v(xt, p, r, b, sr2, s, sx, sy, c, wm0, wc0, w)
        else:
            sin_b, cos_b = _sincos(b)
            zx, zy, r00, r01, r11 = convert_cs(
                form, r, cos_b, sin_b, sr2, s, xt[0] - sx, xt[2] - sy, co
            )
            xt, p = position_update_v(xt, p, zx + sx - xt[0], zy + sy - xt[2], r00, r01, r11)
        _store_lane(xt, p, buf, j)


@_inline
def _doppler_lanes(buf, var_vr, s):
    # Every lane's Doppler update by its V̂r along its measured line of sight
    for j in range(LANES):
        xt, p = _lane(buf, j)
        xt, p = doppler_update_v(xt, p, buf[_V * LANES + j], buf[_B * LANES + j], var_vr, s)
        _store_lane(xt, p, buf, j)


@_inline
def _terms_lanes(buf, t, c, s):
    # Every lane's metric terms (``terms_s``) into the buffer's term rows
    for j in range(LANES):
        xt, p = _lane(buf, j)
        tm = terms_s(xt, p, t, c, s)
        for a in range(10):
            buf[(_TERMS + a) * LANES + j] = tm[a]


@_exact
def _add_terms(buf, sums, i, m0, n_sum):
    # The terms of lanes 0 … n_sum − 1 (runs m0 + j) into sums[i, a·G + (m0 + j) mod G], run
    # after run, as each group's sum takes them (in the order of m). ``_exact``: no
    # reassociation, so each sum is that sequence of additions. A full block of the prosov
    # groups (G = BAND_GROUPS, which divides LANES and so m0): group q of the block takes
    # lanes q, q + G, …, in one loop over q that LLVM vectorises; otherwise lane by lane.
    groups = sums.shape[1] // 10
    if groups == BAND_GROUPS and n_sum == LANES:
        for a in range(10):
            row = (_TERMS + a) * LANES
            for q in range(BAND_GROUPS):
                v = sums[i, a * BAND_GROUPS + q]
                for k in range(LANES // BAND_GROUPS):
                    v += buf[row + k * BAND_GROUPS + q]
                sums[i, a * BAND_GROUPS + q] = v
    else:
        for j in range(n_sum):
            q = (m0 + j) % groups
            for a in range(10):
                sums[i, a * groups + q] += buf[(_TERMS + a) * LANES + j]


@_jit
def filter_scans_2d(plan, conversions, plots, options, first, last, runs, terms):
    """Scans ``first … last − 1`` of every run; scan 0 starts a track from its plot, later
    scans continue from ``runs.state`` (runs, 14): each run's x then the upper entries of P
    (``load_row``), updated in place.

    plan (3,), conversions (2, 8): the method's row of ``core.filters.methods.method_plan``
    and of ``conversion_table`` (its update's scalars, then its start's). plots: the
    measurements (``core.filters.kernel_args.ScanMeasurements``); options: the shared numbers
    (``FilterOptions``). Runs m < ``terms.runs`` add their metric terms (``terms_s``) at
    scan n into terms.group_sums[g, n − first] ((G, K, 10)), g = (terms.group_offset + m)
    mod G (``core.confidence.group_sums``' dealing), in the order of m; with ``runs.keep``
    the others write their states into runs.x[n − first, m − terms.runs], runs.P[…]
    (``RunStates``, ``TermSums``).

    Block-major: ``LANES`` runs at a time (the comment above ``LANES``), scan after scan, a
    stage of a scan one vectorised loop over the block's lanes; the block's states stay in
    its buffer over the chunk's scans and go through ``state`` once a chunk. Each run is
    filtered on its own, so its result does not depend on the block it falls in."""
    r_hat, b_hat, vr_hat, doppler = plots
    sigma_r_m, sigma_beta_rad, sigma_vr_mps, T, sigma_a_mps2, sigma_v0_mps, sx, sy, wt = options
    c, wm0, wc0, w = wt[0], wt[1], wt[2], wt[3]
    state, keep, xs, Ps = runs
    n_terms, truth, cos_los, sin_los, group_sums, group_offset = terms
    sr2, s, q = sigma_r_m * sigma_r_m, sigma_beta_rad * sigma_beta_rad, sigma_a_mps2 * sigma_a_mps2
    var_vr = sigma_vr_mps * sigma_vr_mps
    kind, form, start_form = plan[0], plan[1], plan[2]
    co, co_start = row_tuple(conversions[0]), row_tuple(conversions[1])
    groups = group_sums.shape[0]
    n_runs = r_hat.shape[0]
    buf = np.empty(_ROWS * LANES)
    # The sums by run phase m mod G (group (group_offset + m) mod G): sums[i, a·G + phase], so
    # a block's lanes add to consecutive entries (``_add_terms``)
    sums = np.empty((last - first, 10 * groups))
    for ph in range(groups):
        g = (group_offset + ph) % groups
        for i in range(last - first):
            for a in range(10):
                sums[i, a * groups + ph] = group_sums[g, i, a]
    for m0 in range(0, n_runs, LANES):
        nb = min(LANES, n_runs - m0)
        for j in range(LANES):
            m = m0 + j if j < nb else m0  # a short block's spare lanes repeat its first run
            if first == 0:
                zx, zy, r00, r01, r11 = convert(
                    start_form, r_hat[m, 0], b_hat[m, 0], sr2, s, 0.0, 0.0, co_start
                )
                xt, p = start_s(zx + sx, zy + sy, r00, r01, r11, sigma_v0_mps)
            else:
                xt, p = load_row(state, m)
            _store_lane(xt, p, buf, j)
        for n in range(first, last):
            if n > 0:
                for j in range(LANES):
                    m = m0 + j if j < nb else m0
                    buf[_R * LANES + j] = r_hat[m, n]
                    buf[_B * LANES + j] = b_hat[m, n]
                    buf[_V * LANES + j] = vr_hat[m, n] if doppler else 0.0
                # one loop per kind and form, each compiled for its literal (``_update_lanes``)
                if kind == _EKF:
                    _update_lanes(_EKF, _LINEARIZED, buf, sr2, s, T, q, sx, sy, co, c, wm0, wc0, w)
                elif kind == _UKF:
                    _update_lanes(_UKF, _LINEARIZED, buf, sr2, s, T, q, sx, sy, co, c, wm0, wc0, w)
                elif form == _LINEARIZED:
                    _update_lanes(
                        _CONVERTED, _LINEARIZED, buf, sr2, s, T, q, sx, sy, co, c, wm0, wc0, w
                    )
                elif form == _AVERAGED:
                    _update_lanes(
                        _CONVERTED, _AVERAGED, buf, sr2, s, T, q, sx, sy, co, c, wm0, wc0, w
                    )
                elif form == _EXACT:
                    _update_lanes(_CONVERTED, _EXACT, buf, sr2, s, T, q, sx, sy, co, c, wm0, wc0, w)
                else:
                    _update_lanes(
                        _CONVERTED, _AT_PREDICTION, buf, sr2, s, T, q, sx, sy, co, c, wm0, wc0, w
                    )
                if doppler:
                    _doppler_lanes(buf, var_vr, s)
            i = n - first
            n_sum = min(max(n_terms - m0, 0), nb)  # the block's runs that give terms
            if n_sum > 0:
                t = (truth[n, 0], truth[n, 1], truth[n, 2], truth[n, 3])
                _terms_lanes(buf, t, cos_los[n, 0], sin_los[n, 0])
                _add_terms(buf, sums, i, m0, n_sum)
            if keep:
                for j in range(n_sum, nb):
                    xt, p = _lane(buf, j)
                    store_at(xt, p, xs, Ps, i, m0 + j - n_terms)
        for j in range(nb):
            xt, p = _lane(buf, j)
            store_row(xt, p, state, m0 + j)
    for ph in range(groups):
        g = (group_offset + ph) % groups
        for i in range(last - first):
            for a in range(10):
                group_sums[g, i, a] = sums[i, a * groups + ph]
