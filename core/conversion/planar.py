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

from radarviz.core.conversion import elementwise
from radarviz.core.conversion.elementwise import (
    averaged_coefficients,
    converted_point,
    true_cov_coefficients,
    true_entries,
)
from radarviz.core.conversion.registry import CONVERSIONS, conversion_named
from radarviz.core.geometry import polar_coordinates

METHODS_2D: tuple[str, ...] = tuple(CONVERSIONS)


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
# The naive point given the truth (used by ``core.conversion.modified`` and the tests)
# --------------------------------------------------------------------------------------------


def scale_factor(method: str, *, sigma_beta_rad: ArrayLike) -> NDArray[np.float64]:
    """The scale κ a 2D method applies to the naive point ``r̂ (cos β̂, sin β̂)``
    (its ``core.conversion.registry.Conversion.scale``)."""
    return np.asarray(conversion_named(method).scale(_f(sigma_beta_rad) ** 2))


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
    thing with the O(r²) cancellation removed (``core.conversion.elementwise.true_entries``).
    """
    r, beta = _f(r), _f(beta)
    s, sr2 = _f(sigma_beta_rad) ** 2, _f(sigma_r_m) ** 2
    co = true_cov_coefficients(s, sr2, 1.0)
    return _sym2(*true_entries(r, np.cos(beta), np.sin(beta), sr2, *co))


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
    sr2, s = _f(sigma_r_m) ** 2, _f(sigma_beta_rad) ** 2
    return _sym2(*elementwise.linearized_entries(r, np.cos(beta), np.sin(beta), sr2, s))


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
    sr2, s = _f(sigma_r_m) ** 2, _f(sigma_beta_rad) ** 2
    co = averaged_coefficients(s)
    return _sym2(*elementwise.averaged_entries(r, np.cos(beta), np.sin(beta), sr2, *co))


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
    conversion = conversion_named(method)
    r, beta = _f(r), _f(beta)
    sr2, s = _f(sigma_r_m) ** 2, _f(sigma_beta_rad) ** 2
    rp = cp = sp = None
    if conversion.about_prediction:  # the covariance at the filter's predicted position
        if predicted_xy is None:
            raise ValueError(
                f"method {method} needs predicted_xy (the filter's predicted position)"
            )
        if isinstance(predicted_xy, tuple):
            px, py = _f(predicted_xy[0]), _f(predicted_xy[1])
        else:
            p = _f(predicted_xy)
            px, py = p[..., 0], p[..., 1]
        rp = polar_coordinates([px, py])[0]
        cp, sp = px / rp, py / rp
    co = conversion.coefficients(s, sr2)
    return ConvertedParts(
        *converted_point(
            conversion.covariance, r, np.cos(beta), np.sin(beta), sr2, s, co, rp, cp, sp
        )
    )


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
