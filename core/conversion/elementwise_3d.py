"""The 3D conversions' arithmetic (``core.conversion.spatial``), plain arithmetic, written once for
every engine: over numpy arrays of any shape (``core.conversion.spatial`` calls them as they
are) and over Python floats in numba-compiled code (``core.filters.kernels_3d`` compiles them;
numba types numpy's elementary functions on numbers).

A radar's noise-only factors (``noise_table``: each angle's exponentials) and a
conversion's per-axis scales are formed once per radar; ``converted_point_3d`` then takes a
plot's range and the cosines and sines of its angles. Each covariance is built from
one-angle moments (``angle_moments`` given the truth, ``posterior_moments`` averaged over
the flat-prior posterior) combined by ``combined_entries``, with no O(r²) terms that
cancel.
"""

from __future__ import annotations

from numpy import arctan2, cos, exp, expm1, hypot, sin, sqrt

from radarviz.core.conversion.elementwise import Covariance


def exponentials(s):
    """The noise-only factors of ``angle_moments`` for an angle variance s: (e^(−s/2), e^(−s),
    e^(−2s), 1 − e^(−s), 1 − e^(−2s)), the last two by expm1 (the O(s) variances keep full
    precision)."""
    return exp(-s / 2.0), exp(-s), exp(-2.0 * s), -expm1(-s), -expm1(-2.0 * s)


def noise_table(sb2, se2):
    """A radar's noise-only factors of the covariances, four rows of five: the
    ``exponentials`` of σβ², σε², 2σβ², 2σε²."""
    return exponentials(sb2), exponentials(se2), exponentials(2.0 * sb2), exponentials(2.0 * se2)


def angle_moments(c, sn, ex):
    """(E[cos² θ̂], E[sin² θ̂], E[sin θ̂ cos θ̂], Var cos θ̂, Var sin θ̂, Cov(sin θ̂, cos θ̂),
    E[cos θ̂], E[sin θ̂], E[cos θ̂]²) of θ̂ ~ N(θ, s), (c, sn) = (cos θ, sin θ), ex the
    ``exponentials`` of s:

        E[cos θ̂] = e^(−s/2) cos θ,       E[cos² θ̂] = ½ (1 + e^(−2s) cos 2θ),
        Var cos θ̂ = ½ cos²θ (1 − e^(−s))² + ½ sin²θ (1 − e^(−2s)),
        Cov(sin θ̂, cos θ̂) = −sin θ cos θ e^(−s) (1 − e^(−s))      (sine: exchanged)
    """
    cc, ss, sc = c * c, sn * sn, sn * c
    e_half, e1, e2, om1, om2 = ex[0], ex[1], ex[2], ex[3], ex[4]
    mc = e_half * c
    return (
        0.5 * (cc * (1.0 + e2) + ss * om2),
        0.5 * (ss * (1.0 + e2) + cc * om2),
        e2 * sc,
        0.5 * (cc * om1 * om1 + ss * om2),
        0.5 * (ss * om1 * om1 + cc * om2),
        -e1 * om1 * sc,
        mc,
        e_half * sn,
        mc * mc,
    )


def posterior_moments(c, sn, ex, ex2):
    """``angle_moments`` averaged over the truth θ ~ N(θ̂, s) (the flat-prior posterior),
    (c, sn) = (cos θ̂, sin θ̂), ex and ex2 the ``exponentials`` of s and 2s.

    Averaging twice over N(0, s) is one average over N(0, 2s), so the second moments are those
    of variance 2s at θ̂; the others are linear in cos²θ, sin²θ, sin θ cos θ, cos θ, sin θ:

        E[e^(−s/2) cos θ] = e^(−s) cos θ̂,         E[(e^(−s/2) cos θ)²] = e^(−s) E[cos² θ̂]
        E[Var cos] = ½ (1 − e^(−s))² E[cos² θ̂] + ½ (1 − e^(−2s)) E[sin² θ̂]   (sin: exchanged)
        E[Cov(sin, cos)] = −e^(−s) (1 − e^(−s)) E[sin θ̂ cos θ̂]

    with E[·²] the one-angle moments at variance s (each term non-negative or a product, so
    nothing cancels).
    """
    m2 = angle_moments(c, sn, ex2)
    m = angle_moments(c, sn, ex)
    e1, om1, om2 = ex[1], ex[3], ex[4]
    half1, half2 = 0.5 * om1 * om1, 0.5 * om2
    return (
        m2[0],
        m2[1],
        m2[2],
        half1 * m[0] + half2 * m[1],
        half1 * m[1] + half2 * m[0],
        -e1 * om1 * m[2],
        e1 * c,
        e1 * sn,
        e1 * m[0],
    )


def combined_entries(range_sq, var_r, e, b):
    """The upper entries (xx, xy, xz, yy, yz, zz) of σr² E[u uᵀ] + range_sq · Cov(u),
    u = (cos ε̂ cos β̂, cos ε̂ sin β̂, sin ε̂), from elevation moments ``e`` and azimuth moments
    ``b`` (each as ``angle_moments`` orders them).

    Each entry of Cov(u) is Cov(XY, X'Y') = Cov(X, X') E[YY'] + E[X] E[X'] Cov(Y, Y') for the
    independent elevation (X) and azimuth (Y) factors, so no O(r²) terms cancel. With the
    moments given the truth and range_sq = r² this is the naive point's exact covariance; with
    their posterior averages and range_sq = r̂² + σr² (E[r²] under the posterior) it is that
    covariance averaged over the posterior, Lerro and Bar-Shalom's averaged covariance.
    """
    return (
        var_r * (e[0] * b[0]) + range_sq * (e[3] * b[0] + e[8] * b[3]),
        var_r * (e[0] * b[2]) + range_sq * (e[3] * b[2] + e[8] * b[5]),
        var_r * (e[2] * b[6]) + range_sq * (e[5] * b[6]),
        var_r * (e[0] * b[1]) + range_sq * (e[3] * b[1] + e[8] * b[4]),
        var_r * (e[2] * b[7]) + range_sq * (e[5] * b[7]),
        var_r * e[1] + range_sq * e[4],
    )


def linearized_entries_3d(r, cos_b, sin_b, cos_e, sin_e, sr2, sb2, se2):
    """The upper entries (xx, xy, xz, yy, yz, zz) of the naive point's first-order covariance
    J diag(σr², σβ², σε²) Jᵀ, J = [u, r ∂u/∂β, r ∂u/∂ε] at (r, β, ε)."""
    u0, u1, u2 = cos_e * cos_b, cos_e * sin_b, sin_e
    jb0, jb1 = r * (-cos_e * sin_b), r * (cos_e * cos_b)
    je0, je1, je2 = r * (-sin_e * cos_b), r * (-sin_e * sin_b), r * cos_e
    return (
        sr2 * u0 * u0 + sb2 * jb0 * jb0 + se2 * je0 * je0,
        sr2 * u0 * u1 + sb2 * jb0 * jb1 + se2 * je0 * je1,
        sr2 * u0 * u2 + se2 * je0 * je2,
        sr2 * u1 * u1 + sb2 * jb1 * jb1 + se2 * je1 * je1,
        sr2 * u1 * u2 + se2 * je1 * je2,
        sr2 * u2 * u2 + se2 * je2 * je2,
    )


def true_entries_3d(r, cos_b, sin_b, cos_e, sin_e, sr2, table):
    """The upper entries of the naive point's exact covariance given the truth (r, β, ε):
    σr² E[u uᵀ] + r² Cov(u) (``combined_entries`` of ``angle_moments``); ``table`` the radar's
    ``noise_table``."""
    e = angle_moments(cos_e, sin_e, table[1])
    b = angle_moments(cos_b, sin_b, table[0])
    return combined_entries(r * r, sr2, e, b)


def averaged_entries_3d(r, cos_b, sin_b, cos_e, sin_e, sr2, table):
    """The upper entries of Prosov's eq. 11 in 3D at the measurement: ``true_entries_3d`` averaged
    over the posterior r ~ N(r̂, σr²), β ~ N(β̂, σβ²), ε ~ N(ε̂, σε²) (``posterior_moments``,
    E[r²] = r̂² + σr²)."""
    e = posterior_moments(cos_e, sin_e, table[1], table[3])
    b = posterior_moments(cos_b, sin_b, table[0], table[2])
    return combined_entries(r * r + sr2, sr2, e, b)


def converted_point_3d(
    covariance, kxy, kz, r, cos_b, sin_b, cos_e, sin_e, sr2, sb2, se2, table, px, py, pz
):
    """The converted point and covariance (x, y, z, Rxx, Rxy, Rxz, Ryy, Ryz, Rzz),
    radar-centred, of the plot (r̂, β̂, ε̂) given as r and the cosines and sines of its angles:
    D r̂ u, D = diag(κxy, κxy, κz), with the ``covariance`` form.

    Args:
        covariance: a ``core.conversion.elementwise.Covariance``.
        kxy, kz: the conversion's scale per axis, κ(σβ² + σε²) and κ(σε²) (a 3D scale is the
            2D one with s the summed variance of the angles in that axis).
        sr2, sb2, se2: σr², σβ², σε².  table: the radar's ``noise_table(sb2, se2)``.
        px, py, pz: ``EXACT_AT_PREDICTION`` only: the predicted position, radar-centred (any
            value otherwise).

    LINEARIZED: J diag(σr², σβ², σε²) Jᵀ; AVERAGED: the averaged covariance (eq. 11 in 3D),
    as the papers give it, not scaled; EXACT: D C D, C the exact covariance at the
    measurement; EXACT_AT_PREDICTION: C at the prediction.
    """
    u0, u1, u2 = cos_e * cos_b, cos_e * sin_b, sin_e
    x, y, z = kxy * (r * u0), kxy * (r * u1), kz * (r * u2)
    if covariance == Covariance.LINEARIZED:
        c = linearized_entries_3d(r, cos_b, sin_b, cos_e, sin_e, sr2, sb2, se2)
        return x, y, z, c[0], c[1], c[2], c[3], c[4], c[5]
    if covariance == Covariance.AVERAGED:
        c = averaged_entries_3d(r, cos_b, sin_b, cos_e, sin_e, sr2, table)
        return x, y, z, c[0], c[1], c[2], c[3], c[4], c[5]
    if covariance == Covariance.EXACT:  # at the measurement
        c = true_entries_3d(r, cos_b, sin_b, cos_e, sin_e, sr2, table)
    else:  # at the prediction
        rho = hypot(px, py)
        bp, ep = arctan2(py, px), arctan2(pz, rho)
        rp = sqrt(rho * rho + pz * pz)
        c = true_entries_3d(rp, cos(bp), sin(bp), cos(ep), sin(ep), sr2, table)
    return (
        x,
        y,
        z,
        kxy * c[0] * kxy,
        kxy * c[1] * kxy,
        kxy * c[2] * kz,
        kxy * c[3] * kxy,
        kxy * c[4] * kz,
        kz * c[5] * kz,
    )


#: The functions to compile, for the engines that re-bind them (``core.filters.rebind``).
CONVERSION_FUNCTIONS_3D = (
    exponentials,
    noise_table,
    angle_moments,
    posterior_moments,
    combined_entries,
    linearized_entries_3d,
    true_entries_3d,
    averaged_entries_3d,
    converted_point_3d,
)
