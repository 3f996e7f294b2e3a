"""Polar-to-Cartesian converted measurements and their covariances.

A radar at the origin measures range and azimuth ``r̂ = r + v_r``, ``β̂ = β + v_β`` with
``v_r ~ N(0, σr²)`` and ``v_β ~ N(0, σβ²)`` independent; write ``s = σβ²`` (rad²). The tracker
works in Cartesian coordinates, so each measurement is converted to ``x = r̂ cos β̂``,
``y = r̂ sin β̂`` (Prosov, eq. 8). Because the map is nonlinear the converted point is biased:

    E[cos β̂] = e^(−s/2) cos β,              E[sin β̂] = e^(−s/2) sin β
    E[cos² β̂] = ½(1 + e^(−2s) cos 2β),       E[sin² β̂] = ½(1 − e^(−2s) cos 2β)
    E[sin β̂ cos β̂] = ½ e^(−2s) sin 2β,      E[r̂²] = r² + σr²

so ``E[r̂ cos β̂] = r cos β · e^(−s/2)``: the naive point is pulled towards the radar by ≈ r s/2.

Every conversion here is a scale κ applied to the naive point plus a covariance R:

=========  =================================  ===============================================
name       point                              covariance
=========  =================================  ===============================================
naive      κ = 1 (eq. 8)                      first order J diag(σr², r̂² s) Jᵀ (eq. 9)
seed       κ = 1 − s/2 (eq. 10 as printed)    eq. 11a–c (Lerro & Bar-Shalom averaged cov.)
cmkf_d     κ = 1 − (e^(−s) − e^(−s/2))        eq. 11a–c
ucm        κ = e^(s/2)                        exact true-conditioned cov., at the measurement
ducm       κ = e^(s/2)                        exact true-conditioned cov., at the prediction
=========  =================================  ===============================================

What the analysis found (``docs/conversion.md``), and what users should know:

* eq. 10 (``seed``) has the opposite sign to the frequentist correction:
  E[x_seed] ≈ r cos β (1 − s), twice the naive bias. It is the second-order posterior mean
  of the true position given the measurement, not an unbiased measurement.
* eq. 11 is exactly the posterior average of the naive point's true-conditioned covariance
  (Lerro and Bar-Shalom 1993), which belongs with the opposite-sign correction (``cmkf_d``).
* A covariance evaluated at the *measured* bearing correlates the Kalman gain with the
  measurement error; ``ducm`` (Bordonaro, Willett, Bar-Shalom 2014) evaluates it at the
  filter's predicted position instead.

All functions broadcast over any leading batch shape ``(...)``. Angles are radians.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.geometry import polar_coordinates

METHODS_2D: tuple[str, ...] = ("naive", "seed", "cmkf_d", "ucm", "ducm")


class Converted(NamedTuple):
    """A batch of converted measurements.

    Attributes:
        z: (..., d) Cartesian points, d = 2 or 3.
        R: (..., d, d) their covariances.
    """

    z: NDArray[np.float64]
    R: NDArray[np.float64]


def _sym2(r11: NDArray, r12: NDArray, r22: NDArray) -> NDArray[np.float64]:
    """Stack three (...) arrays into (..., 2, 2) symmetric matrices."""
    r11, r12, r22 = np.broadcast_arrays(r11, r12, r22)
    row0 = np.stack([r11, r12], axis=-1)
    row1 = np.stack([r12, r22], axis=-1)
    return np.stack([row0, row1], axis=-2)


def _f(a: ArrayLike) -> NDArray[np.float64]:
    return np.asarray(a, dtype=np.float64)


# --------------------------------------------------------------------------------------------
# Exact moments (used by ucm / ducm and by the tests)
# --------------------------------------------------------------------------------------------


class _AngleMoments(NamedTuple):
    """Moments of (cos θ̂, sin θ̂) for θ̂ ~ N(θ, s), written without cancellation."""

    mc: NDArray[np.float64]  # E[cos θ̂] = e^(−s/2) cos θ
    ms: NDArray[np.float64]  # E[sin θ̂] = e^(−s/2) sin θ
    ecc: NDArray[np.float64]  # E[cos² θ̂] = ½(1 + e^(−2s) cos 2θ)
    ess: NDArray[np.float64]  # E[sin² θ̂] = ½(1 − e^(−2s) cos 2θ)
    esc: NDArray[np.float64]  # E[sin θ̂ cos θ̂] = ½ e^(−2s) sin 2θ
    vcc: NDArray[np.float64]  # Var(cos θ̂) = ½ cos²θ (1 − e^(−s))² + ½ sin²θ (1 − e^(−2s))
    vss: NDArray[np.float64]  # Var(sin θ̂) = ½ sin²θ (1 − e^(−s))² + ½ cos²θ (1 − e^(−2s))
    csc: NDArray[np.float64]  # Cov(sin θ̂, cos θ̂) = −sin θ cos θ e^(−s) (1 − e^(−s))


def _angle_moments(theta: NDArray, s: NDArray) -> _AngleMoments:
    """One-angle moments; 1 − e^(−s) via expm1 so the O(s) variances keep full precision."""
    return _angle_moments_cs(np.cos(theta), np.sin(theta), s)


def _angle_moments_cs(c: NDArray, sn: NDArray, s: NDArray) -> _AngleMoments:
    """``_angle_moments`` from cos θ and sin θ (callers often have them without trigonometry)."""
    cc, ss, sc = c * c, sn * sn, sn * c
    e_half, e1, e2 = np.exp(-s / 2.0), np.exp(-s), np.exp(-2.0 * s)
    om1, om2 = -np.expm1(-s), -np.expm1(-2.0 * s)
    return _AngleMoments(
        mc=e_half * c,
        ms=e_half * sn,
        ecc=0.5 * (cc * (1.0 + e2) + ss * om2),
        ess=0.5 * (ss * (1.0 + e2) + cc * om2),
        esc=e2 * sc,
        vcc=0.5 * (cc * om1 * om1 + ss * om2),
        vss=0.5 * (ss * om1 * om1 + cc * om2),
        csc=-e1 * om1 * sc,
    )


#: The scale κ(s), s = σβ², that each 2D method applies to the naive point.
_SCALES = {
    "naive": lambda s: np.ones_like(s),
    "seed": lambda s: 1.0 - s / 2.0,  # Prosov eq. 10 as printed
    "cmkf_d": lambda s: 1.0 - (np.exp(-s) - np.exp(-s / 2.0)),  # Lerro & Bar-Shalom debiasing
    "ucm": lambda s: np.exp(s / 2.0),  # Mo et al. 1998: 1 / E[cos v_β]
    "ducm": lambda s: np.exp(s / 2.0),
}


def scale_factor(method: str, *, sigma_beta_rad: ArrayLike) -> NDArray[np.float64]:
    """The scale κ a 2D method applies to the naive point ``r̂ (cos β̂, sin β̂)``."""
    return _SCALES[_method(method)](_f(sigma_beta_rad) ** 2)


def _method(method: str) -> str:
    if method not in METHODS_2D:
        raise ValueError(f"method must be one of {', '.join(METHODS_2D)} (got {method!r})")
    return method


def naive_mean_given_truth(
    r: ArrayLike, beta: ArrayLike, *, sigma_beta_rad: ArrayLike
) -> NDArray[np.float64]:
    """E[r̂ (cos β̂, sin β̂) | r, β] = r e^(−s/2) (cos β, sin β).  Shape (..., 2)."""
    r, beta, s = _f(r), _f(beta), _f(sigma_beta_rad) ** 2
    a = r * np.exp(-s / 2.0)
    return np.stack([a * np.cos(beta), a * np.sin(beta)], axis=-1)


def naive_cov_given_truth(
    r: ArrayLike, beta: ArrayLike, *, sigma_r_m: ArrayLike, sigma_beta_rad: ArrayLike
) -> NDArray[np.float64]:
    """Exact covariance of the naive point given the true (r, β).  Shape (..., 2, 2).

    From the moments in the module docstring:

        Cxx = (r² + σr²) ½(1 + e^(−2s) cos 2β) − r² e^(−s) cos² β
        Cyy = (r² + σr²) ½(1 − e^(−2s) cos 2β) − r² e^(−s) sin² β
        Cxy = (r² + σr²) ½ e^(−2s) sin 2β     − r² e^(−s) sin β cos β

    Scaling the point by κ scales this by κ², so it also gives the ucm covariance.

    Numerics: evaluated as σr² E[u uᵀ] + r² Cov(u), u = (cos β̂, sin β̂), which is the same
    thing with the O(r²) cancellation removed (as written above, the radial variance loses
    ~eps·r²/σr² relative precision and can come out ≤ 0 once r/σr ≳ 5e7 at small s).
    """
    r, beta = _f(r), _f(beta)
    return _sym2(*_true_cov_parts(r, np.cos(beta), np.sin(beta), _f(sigma_r_m), _f(sigma_beta_rad)))


CovParts = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


def _true_cov_parts(
    r: NDArray,
    c: NDArray,
    sn: NDArray,
    sigma_r_m: NDArray,
    sigma_beta_rad: NDArray,
    scale: ArrayLike = 1.0,
) -> CovParts:
    """(Cxx, Cxy, Cyy) of ``naive_cov_given_truth`` × ``scale``, bearing given by cos c, sin sn.

    σr² E[u uᵀ] + r² Cov(u) regrouped by cos²β, sin²β and sin β cos β (every term of the
    diagonal is non-negative, so nothing cancels), with the scalar coefficients folded first:

        Cxx = cos²β · A + sin²β · B,   Cyy = sin²β · A + cos²β · B,   Cxy = sin β cos β · C
        A = ½[σr² (1 + e^(−2s)) + r² (1 − e^(−s))²],   B = ½ (σr² + r²)(1 − e^(−2s))
        C = σr² e^(−2s) − r² e^(−s) (1 − e^(−s))
    """
    s = sigma_beta_rad * sigma_beta_rad
    k = _f(scale)
    e1, e2 = np.exp(-s), np.exp(-2.0 * s)
    om1, om2 = -np.expm1(-s), -np.expm1(-2.0 * s)
    sr2 = sigma_r_m * sigma_r_m
    r2 = r * r
    a_const = (0.5 * k) * sr2 * (1.0 + e2)
    A = r2 * ((0.5 * k) * om1 * om1)
    A += a_const
    B = r2 + sr2
    B *= (0.5 * k) * om2
    C = r2 * (-k * e1 * om1)
    C += k * sr2 * e2
    cc, ss = c * c, sn * sn
    cxx = cc * A
    cxx += ss * B
    cyy = ss * A
    cyy += cc * B
    C = C * (sn * c)  # not in place: r and the bearing may broadcast against each other
    return cxx, C, cyy


# --------------------------------------------------------------------------------------------
# Covariances named by the papers
# --------------------------------------------------------------------------------------------


def linearized_cov(
    r: ArrayLike, beta: ArrayLike, *, sigma_r_m: ArrayLike, sigma_beta_rad: ArrayLike
) -> NDArray[np.float64]:
    """First-order covariance J diag(σr², σβ²) Jᵀ of the naive point (Prosov eq. 9).

    R11 = σr² cos²β + r² s sin²β
    R22 = σr² sin²β + r² s cos²β
    R12 = (σr² − r² s) sin β cos β
    """
    r, beta = _f(r), _f(beta)
    return _sym2(
        *_linearized_parts(r, np.cos(beta), np.sin(beta), _f(sigma_r_m), _f(sigma_beta_rad))
    )


def _linearized_parts(
    r: NDArray, c: NDArray, sn: NDArray, sigma_r_m: NDArray, sigma_beta_rad: NDArray
) -> CovParts:
    sr2, rs = sigma_r_m * sigma_r_m, r * r * (sigma_beta_rad * sigma_beta_rad)
    return sr2 * c * c + rs * sn * sn, (sr2 - rs) * sn * c, sr2 * sn * sn + rs * c * c


def averaged_cov(
    r: ArrayLike, beta: ArrayLike, *, sigma_r_m: ArrayLike, sigma_beta_rad: ArrayLike
) -> NDArray[np.float64]:
    """Prosov eq. 11a–c, evaluated at the measurement (r, β) = (r̂, β̂).

        c11 = r² e^(−2s) [cos²β (cosh 2s − cosh s) + sin²β (sinh 2s − sinh s)]
            + σr² e^(−2s) [cos²β (2 cosh 2s − cosh s) + sin²β (2 sinh 2s − sinh s)]
        c22 = the same with sin and cos exchanged
        c12 = sin β cos β e^(−4s) [σr² + (r² + σr²)(1 − e^s)]

    This is Lerro and Bar-Shalom's (1993) average of the naive point's true-conditioned
    covariance over the posterior of (r, β) given the measurement (flat prior); the tests check
    that identity by quadrature.
    """
    r, beta = _f(r), _f(beta)
    return _sym2(*_averaged_parts(r, np.cos(beta), np.sin(beta), _f(sigma_r_m), _f(sigma_beta_rad)))


def _averaged_parts(
    r: NDArray, c: NDArray, sn: NDArray, sigma_r_m: NDArray, sigma_beta_rad: NDArray
) -> CovParts:
    sr2, s = sigma_r_m * sigma_r_m, sigma_beta_rad * sigma_beta_rad
    c2, s2 = c * c, sn * sn
    e2 = np.exp(-2.0 * s)
    ch1, ch2, sh1, sh2 = np.cosh(s), np.cosh(2.0 * s), np.sinh(s), np.sinh(2.0 * s)
    r2 = r * r
    # cosh 2s − cosh s and sinh 2s − sinh s as products (no cancellation at small s).
    sh_half = np.sinh(0.5 * s)
    a_c, a_s = 2.0 * np.sinh(1.5 * s) * sh_half, 2.0 * np.cosh(1.5 * s) * sh_half
    b_c, b_s = 2.0 * ch2 - ch1, 2.0 * sh2 - sh1
    c11 = r2 * (e2 * (c2 * a_c + s2 * a_s)) + sr2 * e2 * (c2 * b_c + s2 * b_s)
    c22 = r2 * (e2 * (s2 * a_c + c2 * a_s)) + sr2 * e2 * (s2 * b_c + c2 * b_s)
    c12 = sn * c * np.exp(-4.0 * s) * (sr2 - (r2 + sr2) * np.expm1(s))
    return c11, c12, c22


# --------------------------------------------------------------------------------------------
# The five 2D conversions
# --------------------------------------------------------------------------------------------


class ConvertedParts(NamedTuple):
    """A batch of 2D converted measurements as separate (...) components.

    The Monte Carlo filter loop uses this form directly (no (..., 2, 2) arrays to build and
    take apart); ``Converted`` is the stacked form.
    """

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    r00: NDArray[np.float64]
    r01: NDArray[np.float64]
    r11: NDArray[np.float64]

    def stacked(self) -> Converted:
        """(z (..., 2), R (..., 2, 2)) with one batch shape for both (all parts broadcast)."""
        x, y, r00, r01, r11 = np.broadcast_arrays(self.x, self.y, self.r00, self.r01, self.r11)
        return Converted(np.stack([x, y], axis=-1), _sym2(r00, r01, r11))


def _naive(r, c, sn, sigma_r_m, sigma_beta_rad, predicted) -> ConvertedParts:
    """Naive conversion (eq. 8) with the linearized covariance (eq. 9)."""
    return ConvertedParts(r * c, r * sn, *_linearized_parts(r, c, sn, sigma_r_m, sigma_beta_rad))


def _averaged(method: str):
    """Prosov's correction as printed (``seed``: κ = 1 − s/2, eq. 10; it *doubles* the bias of
    the converted point, see the module docstring) or Lerro & Bar-Shalom's (``cmkf_d``:
    κ = 1 − (e^(−s) − e^(−s/2))), both with the averaged covariance of eq. 11."""

    def parts(r, c, sn, sigma_r_m, sigma_beta_rad, predicted) -> ConvertedParts:
        kr = _SCALES[method](sigma_beta_rad * sigma_beta_rad) * r
        return ConvertedParts(
            kr * c, kr * sn, *_averaged_parts(r, c, sn, sigma_r_m, sigma_beta_rad)
        )

    return parts


def _ucm(r, c, sn, sigma_r_m, sigma_beta_rad, predicted) -> ConvertedParts:
    """Unbiased conversion (Mo, Song, Zhou, Sun, Bar-Shalom 1998): κ = e^(s/2); covariance the
    exact true-conditioned covariance of the unbiased point, e^s · ``naive_cov_given_truth``,
    evaluated at the measured (r̂, β̂)."""
    es = np.exp(sigma_beta_rad * sigma_beta_rad)
    kr = np.sqrt(es) * r
    return ConvertedParts(
        kr * c, kr * sn, *_true_cov_parts(r, c, sn, sigma_r_m, sigma_beta_rad, es)
    )


def _ducm(r, c, sn, sigma_r_m, sigma_beta_rad, predicted) -> ConvertedParts:
    """Decorrelated unbiased conversion (Bordonaro, Willett, Bar-Shalom 2014): ucm's point,
    the covariance evaluated at the filter's predicted position (radar-centred), so the gain
    is independent of this measurement's error."""
    if predicted is None:
        raise ValueError("method ducm needs predicted_xy (the filter's predicted position)")
    px, py = _f(predicted[0]), _f(predicted[1])
    r_p = polar_coordinates([px, py])[0]
    es = np.exp(sigma_beta_rad * sigma_beta_rad)
    kr = np.sqrt(es) * r
    return ConvertedParts(
        kr * c, kr * sn, *_true_cov_parts(r_p, px / r_p, py / r_p, sigma_r_m, sigma_beta_rad, es)
    )


_CONVERSIONS = {
    "naive": _naive,
    "seed": _averaged("seed"),
    "cmkf_d": _averaged("cmkf_d"),
    "ucm": _ucm,
    "ducm": _ducm,
}


def convert_parts(
    method: str,
    r: ArrayLike,
    beta: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    predicted_xy: ArrayLike | tuple[ArrayLike, ArrayLike] | None = None,
) -> ConvertedParts:
    """Any of ``METHODS_2D`` as components; ``ducm`` needs ``predicted_xy``.

    Args:
        r, beta: (...) measured range (m) and azimuth (rad).
        sigma_r_m, sigma_beta_rad: σr and σβ, scalars or broadcastable to (...).
        predicted_xy: the filter's predicted position, radar-centred: two (...) arrays, or one
            (..., 2) array.
    """
    r, beta = _f(r), _f(beta)
    c, sn = np.cos(beta), np.sin(beta)
    predicted = predicted_xy
    if predicted is not None and not isinstance(predicted, tuple):
        p = _f(predicted)
        predicted = (p[..., 0], p[..., 1])
    fn = _CONVERSIONS[_method(method)]
    return fn(r, c, sn, _f(sigma_r_m), _f(sigma_beta_rad), predicted)


def convert(
    method: str,
    r: ArrayLike,
    beta: ArrayLike,
    *,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    predicted_xy: ArrayLike | None = None,
) -> Converted:
    """``convert_parts`` stacked: z (..., 2) and R (..., 2, 2)."""
    return convert_parts(
        method,
        r,
        beta,
        sigma_r_m=sigma_r_m,
        sigma_beta_rad=sigma_beta_rad,
        predicted_xy=predicted_xy,
    ).stacked()
