"""The 2D conversions' arithmetic (``core.conversion.planar``), written once for every
engine: over numpy arrays of any shape (the numpy engine and the analysis functions of
``core.conversion.planar`` call them as they are), over Python floats in numba-compiled code
(``core.filters.kernels_2d`` compiles them; numba types numpy's elementary functions on
numbers), and over another array-API namespace's arrays (``core.filters.array_api``).

A conversion (``core.conversion.registry``) is a scale κ(s) of the naive point r̂ (cos β̂,
sin β̂), one of the ``*_scale`` functions here, and a ``Covariance`` form. The scalars that
depend on s = σβ² and σr² only (κ and most of a covariance's transcendental functions) are
formed once by ``conversion_coefficients``; ``converted_point`` then takes cos β̂ and sin β̂
(the caller evaluates them) and uses + − × ÷ only. The covariances the papers name are
functions of their own, called by the conversions and by the analysis:

* ``linearized_entries``: the first-order J diag(σr², s) Jᵀ (Prosov eq. 9);
* ``averaged_entries``: eq. 11a–c, Lerro and Bar-Shalom's posterior-averaged covariance;
* ``true_entries``: the naive point's exact covariance given the truth, times k (the exact
  forms take k = κ², the point being scaled by κ).
"""

from __future__ import annotations

from enum import IntEnum

from numpy import cosh, exp, expm1, sinh, sqrt


class Covariance(IntEnum):
    """The covariance a converted point carries, as the papers name it. A conversion is a
    scale κ(s) of the naive point and one of these (``core.conversion.registry``); the
    compiled kernels branch on these values, never on a conversion's name.

    LINEARIZED: J diag(σr², s) Jᵀ at the measurement (Prosov eq. 9), ``linearized_entries``.
    AVERAGED: eq. 11, the exact covariance averaged over the posterior of the truth (Lerro and
    Bar-Shalom), ``averaged_entries``.
    EXACT: the naive point's exact covariance given the truth, taken at the measurement and
    times κ² (the point is scaled by κ; Mo et al.), ``true_entries``.
    EXACT_AT_PREDICTION: the same at the filter's predicted position (Bordonaro et al.), so it
    needs the prediction.
    """

    LINEARIZED = 0
    AVERAGED = 1
    EXACT = 2
    EXACT_AT_PREDICTION = 3


def unit_scale(s):
    """κ = 1: the naive point (Prosov eq. 8)."""
    return 1.0 + 0.0 * s


def seed_scale(s):
    """κ = 1 − s/2: Prosov's eq. 10 as printed (the second-order term with its sign)."""
    return 1.0 - s / 2.0


def debiasing_scale(s):
    """κ = 1 − (e^(−s) − e^(−s/2)): Lerro and Bar-Shalom's additive debiasing as a scale."""
    return 1.0 - (exp(-s) - exp(-s / 2.0))


def unbiasing_scale(s):
    """κ = e^(s/2) = √(e^s) = 1 / E[cos v_β]: Mo et al.'s multiplicative unbiasing."""
    return sqrt(exp(s))


def averaged_coefficients(s):
    """The seven scalars of eq. 11 that depend on s only: e^(−2s), cosh 2s − cosh s and
    sinh 2s − sinh s (as the products 2 sinh(3s/2) sinh(s/2) and 2 cosh(3s/2) sinh(s/2): no
    cancellation at small s), 2 cosh 2s − cosh s, 2 sinh 2s − sinh s, e^(−4s), e^s − 1."""
    sh_half = sinh(0.5 * s)
    return (
        exp(-2.0 * s),
        2.0 * sinh(1.5 * s) * sh_half,
        2.0 * cosh(1.5 * s) * sh_half,
        2.0 * cosh(2.0 * s) - cosh(s),
        2.0 * sinh(2.0 * s) - sinh(s),
        exp(-4.0 * s),
        expm1(s),
    )


def true_cov_coefficients(s, sr2, k):
    """(a1, a0, b1, c1, c0) of ``true_entries`` × k: with A = a1 r² + a0, B = b1 (r² + σr²),
    C = c1 r² + c0,

        A = ½ k [σr² (1 + e^(−2s)) + r² (1 − e^(−s))²],   B = ½ k (σr² + r²)(1 − e^(−2s)),
        C = k [σr² e^(−2s) − r² e^(−s) (1 − e^(−s))]

    (1 − e^(−s) by expm1, so the O(s) variances keep full precision)."""
    e1, e2 = exp(-s), exp(-2.0 * s)
    om1, om2 = -expm1(-s), -expm1(-2.0 * s)
    return (
        (0.5 * k) * om1 * om1,
        (0.5 * k) * sr2 * (1.0 + e2),
        (0.5 * k) * om2,
        -k * e1 * om1,
        k * sr2 * e2,
    )


def conversion_coefficients(covariance, kappa, s, sr2) -> tuple:
    """The eight scalars of a conversion that depend on s = σβ² and σr² only: its scale κ
    then its covariance's (zeros where it needs fewer; always eight, so compiled code sees
    one type).

    ``Covariance.AVERAGED``: (κ, ``averaged_coefficients(s)``); ``EXACT`` and
    ``EXACT_AT_PREDICTION``: (κ, ``true_cov_coefficients(s, σr², κ²)``, 0, 0);
    ``LINEARIZED``: (κ, 0, …).
    """
    z = 0.0 * s
    if covariance == Covariance.AVERAGED:
        a = averaged_coefficients(s)
        return kappa + z, a[0], a[1], a[2], a[3], a[4], a[5], a[6]
    if covariance == Covariance.EXACT or covariance == Covariance.EXACT_AT_PREDICTION:
        t = true_cov_coefficients(s, sr2, kappa * kappa)
        return kappa + z, t[0], t[1], t[2], t[3], t[4], z, z
    return (kappa + z, z, z, z, z, z, z, z)


def linearized_entries(r, c, sn, sr2, s):
    """(R00, R01, R11) of the first-order covariance J diag(σr², s) Jᵀ of the naive point at
    range r and bearing (c, sn) = (cos β, sin β) (Prosov eq. 9):

        R00 = σr² cos²β + r² s sin²β,   R11 = σr² sin²β + r² s cos²β,
        R01 = (σr² − r² s) sin β cos β
    """
    rs = r * r * s
    return sr2 * c * c + rs * sn * sn, (sr2 - rs) * sn * c, sr2 * sn * sn + rs * c * c


def averaged_entries(r, c, sn, sr2, e2, a_c, a_s, b_c, b_s, e4, em1):
    """(c11, c12, c22) of Prosov eq. 11a–c at range r and bearing (c, sn), the scalars from
    ``averaged_coefficients``:

        c11 = r² e^(−2s) [cos²β (cosh 2s − cosh s) + sin²β (sinh 2s − sinh s)]
            + σr² e^(−2s) [cos²β (2 cosh 2s − cosh s) + sin²β (2 sinh 2s − sinh s)]
        c22 = the same with sin and cos exchanged
        c12 = sin β cos β e^(−4s) [σr² + (r² + σr²)(1 − e^s)]
    """
    c2, s2, r2 = c * c, sn * sn, r * r
    c11 = r2 * (e2 * (c2 * a_c + s2 * a_s)) + sr2 * e2 * (c2 * b_c + s2 * b_s)
    c22 = r2 * (e2 * (s2 * a_c + c2 * a_s)) + sr2 * e2 * (s2 * b_c + c2 * b_s)
    c12 = sn * c * e4 * (sr2 - (r2 + sr2) * em1)
    return c11, c12, c22


def true_entries(r, c, sn, sr2, a1, a0, b1, c1, c0):
    """(Cxx, Cxy, Cyy) of the naive point's exact covariance given the truth (r, β), β as
    (c, sn), times the k of ``true_cov_coefficients`` (whose scalars these are):

        Cxx = cos²β A + sin²β B,   Cyy = sin²β A + cos²β B,   Cxy = sin β cos β C,

    σr² E[u uᵀ] + r² Cov(u), u = (cos β̂, sin β̂), regrouped so that every term of the
    diagonal is non-negative: written as E[p pᵀ] − E[p] E[p]ᵀ the radial variance would lose
    ~eps·r²/σr² of its relative precision and could come out ≤ 0 once r/σr ≳ 5e7.
    """
    r2 = r * r
    a = r2 * a1 + a0
    b = (r2 + sr2) * b1
    cx = r2 * c1 + c0
    return c * c * a + sn * sn * b, cx * (sn * c), sn * sn * a + c * c * b


def converted_point(covariance, r, c, sn, sr2, s, co, rp, cp, sp):
    """The converted point and covariance (x, y, R00, R01, R11), radar-centred, of the
    measured range r and bearing β̂ given as c = cos β̂, sn = sin β̂: κ r̂ (c, sn) with the
    ``covariance`` form.

    Args:
        covariance: a ``Covariance``.  sr2, s: σr² and σβ².
        co: ``conversion_coefficients(covariance, κ, s, sr2)`` (κ first).
        rp, cp, sp: ``EXACT_AT_PREDICTION`` only: the predicted position's range and cos,
            sin of its bearing (any value otherwise).
    """
    kr = co[0] * r
    if covariance == Covariance.LINEARIZED:
        cov = linearized_entries(r, c, sn, sr2, s)
    elif covariance == Covariance.AVERAGED:
        cov = averaged_entries(r, c, sn, sr2, co[1], co[2], co[3], co[4], co[5], co[6], co[7])
    elif covariance == Covariance.EXACT:  # at the measurement
        cov = true_entries(r, c, sn, sr2, co[1], co[2], co[3], co[4], co[5])
    else:  # at the prediction
        cov = true_entries(rp, cp, sp, sr2, co[1], co[2], co[3], co[4], co[5])
    return kr * c, kr * sn, cov[0], cov[1], cov[2]


#: The functions to compile, for the engines that re-bind them (``core.filters.rebind``). The
#: scales are not among them: a kernel takes κ as a number (``core.filters.methods``).
CONVERSION_FUNCTIONS = (
    averaged_coefficients,
    true_cov_coefficients,
    conversion_coefficients,
    linearized_entries,
    averaged_entries,
    true_entries,
    converted_point,
)
