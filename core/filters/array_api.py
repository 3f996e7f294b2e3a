"""The 2D Monte Carlo filters written against the Python array API standard: the GPU path.

The numpy engine writes into preallocated buffers (``out=``) and the compiled kernel is
scalar CPU code; neither runs on a GPU. This module evaluates the same equations with only
array-API operations on whole batches, every state component a (m,) array (the numpy
engine's component-major layout), each operation returning a new array. So it runs on any
namespace that implements the standard: numpy, CuPy (NVIDIA GPUs), PyTorch or JAX through
``array_api_compat``, and ``array_api_strict`` (which the tests use to prove nothing outside
the standard is called).

Every method: the five conversions (``core.conversion.planar``), the polar EKF
(``core.filters.polar_ekf``) and UKF (``core.filters.polar_ukf``), each optionally followed by
the Doppler update (``core.filters.doppler``). The steps are the ones every engine runs,
written once (``core.filters.steps_2d``: the prediction, the position, EKF, UKF and Doppler
updates), here bound to the namespace's elementary functions. ``tests/test_array_api.py``
holds it to the numpy engine to 1e-9 under ``array_api_strict``. ``radarviz bench --device
gpu`` times it on CuPy when a GPU is present.

The scalar coefficients that depend only on σr, σβ (e^(−s), eq. 11's hyperbolic terms, …)
are Python floats, formed once per call; per scan a method costs a few dozen array
operations, so a GPU pays off from about 10⁵ runs.
"""

from __future__ import annotations

import functools
import math
from typing import Any

from radarviz.core.conversion.elementwise import Covariance, converted_point
from radarviz.core.filters.compiled import FilterSettings
from radarviz.core.filters.methods import Kind, conversion_table, method_named
from radarviz.core.filters.predict import predict_2d, white_acceleration
from radarviz.core.filters.state import UPPER_2D
from radarviz.core.filters.steps_2d import bind_2d

Array = Any  # an array of the caller's namespace
_TWO_PI = 2.0 * math.pi


def _wrap(xp: Any, a: Array) -> Array:
    """``core.geometry.wrap_angle``: a − 2π ceil(a/(2π) − ½), to (−π, π]."""
    return a - _TWO_PI * xp.ceil(a * (1.0 / _TWO_PI) - 0.5)


def _convert(xp: Any, form: int, r, b, sr2: float, s: float, co, px=None, py=None):
    """A 2D conversion of covariance ``form`` and scalars ``co``: (x, y, R00, R01, R11),
    radar-centred (``core.conversion.elementwise.converted_point``; (px, py) the
    prediction, for ``EXACT_AT_PREDICTION``)."""
    rp = cp = sp = None
    if form == Covariance.EXACT_AT_PREDICTION:
        rp = xp.hypot(px, py)
        cp, sp = px / rp, py / rp
    return converted_point(form, r, xp.cos(b), xp.sin(b), sr2, s, co, rp, cp, sp)


@functools.cache
def _steps(xp: Any) -> dict[str, Any]:
    """The 2D steps (``core.filters.steps_2d``) calling ``xp``'s elementary functions."""
    return bind_2d(
        {
            "sqrt": xp.sqrt,
            "where": xp.where,
            "atan2": xp.atan2,
            "wrap": functools.partial(_wrap, xp),
            "cos": xp.cos,
            "sin": xp.sin,
        }
    )


def filter_history_xp(
    method: str,
    r_hat: Array,
    beta_hat: Array,
    settings: FilterSettings,
    *,
    radial_velocity_mps: Array | None = None,
    xp: Any = None,
) -> tuple[Array, Array]:
    """Every scan's states of m runs: x (N, m, 4) and P (N, m, 4, 4) in ``xp``'s arrays.

    Args:
        method: one of ``core.filters.compiled.COMPILED_METHODS``.
        r_hat, beta_hat: (m, N) measured ranges (m) and azimuths (rad), arrays of ``xp``.
        settings: the shared scalars (``core.filters.compiled.FilterSettings``).
        radial_velocity_mps: (m, N) measured V̂r: the Doppler update after each plot's.
        xp: the array namespace (default: ``array_api_compat.array_namespace(r_hat)``).
    """
    if xp is None:
        from array_api_compat import array_namespace

        xp = array_namespace(r_hat)
    s_ = settings
    kind = method_named(method).kind
    form, start_form = (c.covariance for c in method_named(method).conversions())
    sr2, s = s_.sigma_r_m**2, s_.sigma_beta_rad**2
    # as Python floats: the scalars are numpy's numbers, which other namespaces refuse
    table = conversion_table([method], s_.sigma_r_m, s_.sigma_beta_rad)[0, 0]
    co, co_start = (tuple(float(c) for c in row) for row in table)
    sx, sy = s_.site_m
    T, q = s_.period_s, s_.sigma_a_mps2**2
    prm = s_.ukf.weights(4)
    n_scans = r_hat.shape[1]
    zx, zy, r00, r01, r11 = _convert(xp, start_form, r_hat[:, 0], beta_hat[:, 0], sr2, s, co_start)
    zero = xp.zeros_like(zx)
    v0 = zero + s_.sigma_v0_mps**2
    x = (zx + sx, zero, zy + sy, zero)
    P = (r00, zero, r01, zero, v0, zero, zero, r11, zero, v0)  # upper entries (UPPER_2D)
    steps = _steps(xp)
    xs, Ps = [x], [P]
    for n in range(1, n_scans):
        r, b = r_hat[:, n], beta_hat[:, n]
        x, P = predict_2d(x, P, T, white_acceleration(T, q))
        if kind == Kind.EKF:
            x, P = steps["ekf_update_2d"](x, P, r, b, sr2, s, sx, sy)
        elif kind == Kind.UKF:
            x, P = steps["ukf_update_2d"](x, P, r, b, sr2, s, sx, sy, *prm)
        else:
            zx, zy, r00, r01, r11 = _convert(xp, form, r, b, sr2, s, co, x[0] - sx, x[2] - sy)
            nx, ny = zx + sx - x[0], zy + sy - x[2]
            x, P = steps["position_update_2d"](x, P, nx, ny, r00, r01, r11)
        if radial_velocity_mps is not None:
            var_vr = s_.sigma_vr_mps**2
            x, P = steps["doppler_update_2d"](x, P, radial_velocity_mps[:, n], b, var_vr, s)
        xs.append(x)
        Ps.append(P)
    x_out = xp.stack([xp.stack(v, axis=-1) for v in xs])
    upper = {ij: k for k, ij in enumerate(UPPER_2D)}  # (i, j), i <= j: its place in P's tuple
    rows = [
        xp.stack(
            [
                xp.stack([Pn[upper[min(i, j), max(i, j)]] for j in range(4)], axis=-1)
                for i in range(4)
            ],
            axis=-2,
        )
        for Pn in Ps
    ]
    return x_out, xp.stack(rows)
