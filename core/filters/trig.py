"""Sine, cosine and the two-argument arc tangent as straight-line arithmetic, so that a
compiler can vectorise a loop calling them (numba, through LLVM: ``core.filters.kernels_2d``
binds them into the 2D steps for its blocks of runs).

A call to the C library's ``sin`` or ``atan2`` inside a loop stops LLVM's loop vectoriser
(it has no packed form of them). These functions use + − × ÷, comparisons and selects only,
so each lane of a packed register evaluates them at once. They are fdlibm's (Sun's freely
distributable libm, the source of most C libraries' versions) with its branches made into
selects, accurate to about one unit in the last place:

* ``sincos``: the argument reduced by the nearest multiple n of π/2, r = a − n π/2, with π/2
  split in three parts (Cody and Waite: the first two of 33 bits, so n times each is exact
  for |n| < 2²⁰), then the minimax polynomials of fdlibm's ``__kernel_sin`` and
  ``__kernel_cos`` on |r| ≤ π/4, and the quadrant n mod 4 choosing ±sin r or ±cos r. Meant
  for angles of a few turns at most (bearings, wrapped or not); far beyond (|a| ≳ 10⁵) the
  reduction loses digits.
* ``atan2``: fdlibm's ``atan`` of t = |y|/|x| (t reduced to |t'| ≤ 7/16 about one of
  atan ½, atan 1, atan 3/2 or π/2 − atan(1/t), then an odd polynomial of degree 21), placed
  in the quadrant of (x, y) with π split in two parts.

The rounding to the nearest integer adds and subtracts 1.5·2⁵², which reassociation would
cancel: compiled code must keep this module's sums in order (no fast-math ``reassoc``).
"""

from __future__ import annotations

import math

# π/2 in three parts: 33 bits, the next 33 bits, and the rest (fdlibm's pio2_1, pio2_2,
# pio2_2t); 2/π rounded.
_PIO2_1 = 1.57079632673412561417e00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_2T = 2.02226624879595063154e-21
_INV_PIO2 = 6.36619772367581382433e-01
# Adding then subtracting 1.5·2⁵² rounds a double of magnitude < 2⁵¹ to the nearest integer.
_ROUND = 6755399441055744.0

# fdlibm's __kernel_sin and __kernel_cos coefficients (|r| ≤ π/4).
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11

# fdlibm's atan: atan ½, atan 1, atan 3/2, π/2 in two parts (hi + lo), and the coefficients.
_ATAN_HI = (4.63647609000806093515e-01, 7.85398163397448278999e-01, 9.82793723247329054082e-01,
            1.57079632679489655800e00)  # fmt: skip
_ATAN_LO = (2.26987774529616870924e-17, 3.06161699786838301793e-17, 1.39033110312309984516e-17,
            6.12323399573676603587e-17)  # fmt: skip
_AT = (3.33333333333329318027e-01, -1.99999999998764832476e-01, 1.42857142725034663711e-01,
       -1.11111104054623557880e-01, 9.09088713343650656196e-02, -7.69187620504482999495e-02,
       6.66107313738753120669e-02, -5.83357013379057348645e-02, 4.97687799461593236017e-02,
       -3.65315727442169155270e-02, 1.62858201153657823623e-02)  # fmt: skip
# π in two parts (fdlibm's pi and pi_lo).
_PI, _PI_LO = 3.1415926535897931160e00, 1.2246467991473531772e-16


def sincos(a: float) -> tuple[float, float]:
    """(sin a, cos a) for |a| up to a few turns (module docstring), about 1 ulp."""
    n = (a * _INV_PIO2 + _ROUND) - _ROUND  # the nearest integer to a / (π/2)
    r = ((a - n * _PIO2_1) - n * _PIO2_2) - n * _PIO2_2T  # in [−π/4, π/4]
    z = r * r
    # sin r = r + r³ (S1 + z S2 + … ): fdlibm's __kernel_sin
    s = r + (z * r) * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    # cos r = 1 − z/2 + z² (C1 + …): fdlibm's __kernel_cos, 1 − z/2 formed with its rounding
    # error carried ((1 − w) − z/2), so the result keeps full precision near r = π/4
    w2 = z * z
    q = z * (_C1 + z * (_C2 + z * _C3)) + w2 * w2 * (_C4 + z * (_C5 + z * _C6))
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + (((1.0 - w) - hz) + z * q)
    # the quadrant k = n mod 4, as n − 4 round(n/4) ∈ {−2, −1, 0, 1, 2} (±2 the same)
    k = n - 4.0 * ((n * 0.25 + _ROUND) - _ROUND)
    odd = k == 1.0 or k == -1.0
    sin_a = c if odd else s
    cos_a = s if odd else c
    # sin is negated in quadrants 2 and 3 (k = ±2, −1), cos in 1 and 2 (k = 1, ±2)
    if k == 2.0 or k == -2.0 or k == -1.0:
        sin_a = -sin_a
    if k == 1.0 or k == 2.0 or k == -2.0:
        cos_a = -cos_a
    return sin_a, cos_a


def atan2(y: float, x: float) -> float:
    """The angle of (x, y) in [−π, π] (the C library's ``atan2``; module docstring)."""
    ax, ay = abs(x), abs(y)
    t = ay / ax
    # Reduce t = |y|/|x| about 0, ½, 1, 3/2 or ∞: t' = (k1 |y| − k2 |x|) / (k3 |x| + k4 |y|)
    # is t, (2t − 1)/(2 + t), (t − 1)/(t + 1), (t − 3/2)/(1 + 3/2 t) or −1/t (fdlibm's, formed
    # from |x| and |y| rather than the rounded t: exact numerators, and x = 0 gives −0, not NaN)
    if t < 0.4375:
        k1, k2, k3, k4, hi, lo = 1.0, 0.0, 1.0, 0.0, 0.0, 0.0
    elif t < 0.6875:
        k1, k2, k3, k4, hi, lo = 2.0, 1.0, 2.0, 1.0, _ATAN_HI[0], _ATAN_LO[0]
    elif t < 1.1875:
        k1, k2, k3, k4, hi, lo = 1.0, 1.0, 1.0, 1.0, _ATAN_HI[1], _ATAN_LO[1]
    elif t < 2.4375:
        k1, k2, k3, k4, hi, lo = 1.0, 1.5, 1.0, 1.5, _ATAN_HI[2], _ATAN_LO[2]
    else:  # t ≥ 2.4375, infinite (x = 0) or NaN (x = y = 0, or a NaN)
        k1, k2, k3, k4, hi, lo = 0.0, 1.0, 0.0, 1.0, _ATAN_HI[3], _ATAN_LO[3]
    den = k3 * ax + k4 * ay
    u = (k1 * ay - k2 * ax) / den if den != 0.0 else 0.0  # atan2(±0, ±0): 0 or π, as libm
    if den == 0.0:
        hi, lo = 0.0, 0.0
    z = u * u
    w = z * z
    s1 = z * (_AT[0] + w * (_AT[2] + w * (_AT[4] + w * (_AT[6] + w * (_AT[8] + w * _AT[10])))))
    s2 = w * (_AT[1] + w * (_AT[3] + w * (_AT[5] + w * (_AT[7] + w * _AT[9]))))
    angle = hi - ((u * (s1 + s2) - lo) - u)  # atan t, in [0, π/2]
    if x < 0.0:
        angle = _PI - (angle - _PI_LO)
    return math.copysign(angle, y)
