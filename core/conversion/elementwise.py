"""The five 2D conversions (``core.conversion.planar``) as plain arithmetic, for any number
type: Python floats in numba-compiled code (``core.filters.kernels_2d`` compiles these two
functions) and arrays of any array-API namespace (``core.filters.array_api``). One home for
the compiled and the array-API paths; ``core.conversion.planar`` is the numpy reference both
are tested against.

The scalars that depend on s = σβ² and σr² only (most of a conversion's transcendental
functions) are formed once by ``conversion_coefficients``; ``converted_point`` then takes
cos β̂ and sin β̂ (the caller's namespace evaluates them) and uses + − × ÷ only.
"""

from __future__ import annotations

import math

#: Conversion codes, the ``core.filters.compiled.METHOD_CODES`` of the converted methods.
NAIVE, SEED, CMKF_D, UCM, DUCM = 0, 1, 2, 3, 4


def conversion_coefficients(code: int, s: float, sr2: float) -> tuple[float, ...]:
    """The eight scalars of conversion ``code`` that depend on s = σβ² and σr² only (zeros
    where a conversion needs fewer; always eight, so compiled code sees one type).

    seed / cmkf_d: κ (seed 1 − s/2, eq. 10 as printed; cmkf_d 1 − (e^(−s) − e^(−s/2))), then
    eq. 11's e^(−2s), cosh 2s − cosh s and sinh 2s − sinh s (as the products
    2 sinh(3s/2) sinh(s/2) and 2 cosh(3s/2) sinh(s/2): no cancellation at small s),
    2 cosh 2s − cosh s, 2 sinh 2s − sinh s, e^(−4s), e^s − 1
    (``core.conversion.planar._averaged_parts``).

    ucm / ducm: κ = e^(s/2) and the true-conditioned covariance × e^s
    (``core.conversion.planar._true_cov_parts``) as A = a1 r² + a0, B = b1 (r² + σr²),
    C = c1 r² + c0: (κ, a1, a0, b1, c1, c0, 0, 0).
    """
    if code == SEED or code == CMKF_D:
        kappa = 1.0 - s / 2.0 if code == SEED else 1.0 - (math.exp(-s) - math.exp(-s / 2.0))
        sh_half = math.sinh(0.5 * s)
        return (
            kappa,
            math.exp(-2.0 * s),
            2.0 * math.sinh(1.5 * s) * sh_half,
            2.0 * math.cosh(1.5 * s) * sh_half,
            2.0 * math.cosh(2.0 * s) - math.cosh(s),
            2.0 * math.sinh(2.0 * s) - math.sinh(s),
            math.exp(-4.0 * s),
            math.expm1(s),
        )
    if code == UCM or code == DUCM:
        k = math.exp(s)
        e1, e2 = math.exp(-s), math.exp(-2.0 * s)
        om1, om2 = -math.expm1(-s), -math.expm1(-2.0 * s)
        return (
            math.sqrt(k),
            (0.5 * k) * om1 * om1,
            (0.5 * k) * sr2 * (1.0 + e2),
            (0.5 * k) * om2,
            -k * e1 * om1,
            k * sr2 * e2,
            0.0,
            0.0,
        )
    return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def converted_point(code, r, c, sn, sr2, s, co, rp, cp, sp):
    """The converted point and covariance (x, y, R00, R01, R11), radar-centred, of the
    measured range r and bearing β̂ given as c = cos β̂, sn = sin β̂.

    Args:
        code: ``NAIVE`` … ``DUCM``.  sr2, s: σr² and σβ².
        co: ``conversion_coefficients(code, s, sr2)``.
        rp, cp, sp: ducm only: the predicted position's range and cos, sin of its bearing
            (any value for the others).

    naive: eq. 8 with the linearised covariance eq. 9; seed / cmkf_d: κ r̂ û with eq. 11 at
    the measurement; ucm: e^(s/2) r̂ û with the exact covariance at the measurement; ducm:
    the same point, the covariance at the prediction.
    """
    if code == NAIVE:
        rs = r * r * s
        return (
            r * c,
            r * sn,
            sr2 * c * c + rs * sn * sn,
            (sr2 - rs) * sn * c,
            sr2 * sn * sn + rs * c * c,
        )
    kr = co[0] * r
    if code == SEED or code == CMKF_D:
        c2, s2, r2 = c * c, sn * sn, r * r
        e2, a_c, a_s, b_c, b_s = co[1], co[2], co[3], co[4], co[5]
        c11 = r2 * (e2 * (c2 * a_c + s2 * a_s)) + sr2 * e2 * (c2 * b_c + s2 * b_s)
        c22 = r2 * (e2 * (s2 * a_c + c2 * a_s)) + sr2 * e2 * (s2 * b_c + c2 * b_s)
        c12 = sn * c * co[6] * (sr2 - (r2 + sr2) * co[7])
        return kr * c, kr * sn, c11, c12, c22
    if code == UCM:  # the covariance at the measurement
        rc, cc, sc = r, c, sn
    else:  # ducm: at the prediction
        rc, cc, sc = rp, cp, sp
    r2 = rc * rc
    a = r2 * co[1] + co[2]
    b = (r2 + sr2) * co[3]
    cx = r2 * co[4] + co[5]
    return kr * c, kr * sn, cc * cc * a + sc * sc * b, cx * (sc * cc), sc * sc * a + cc * cc * b
