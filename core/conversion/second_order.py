"""The second-order correction of a converted measurement, for any vector function (Prosov).

A radar measures a vector θ̂ = θ + v of n parameters (range, azimuth, elevation, …) with
v ~ N(0, Σ), and the tracker wants α = h(θ), an m-vector (a Cartesian position). Prosov
(eqs. 2–4) expands h to second order about θ̂,

    h(θ) ≈ h(θ̂) + J (θ − θ̂) + ½ [(θ − θ̂)ᵀ H_i (θ − θ̂)]_i,   J = ∂h/∂θ,  H_i = ∂²h_i/∂θ²,

and takes the expectation (eqs. 5–7): the mean moves by the second-order term

    t_i = ½ tr(H_i Σ) = ½ Σ_jk (H_i)_jk Σ_jk          (eq. 7; ½ Σ_j (H_i)_jj D_j, uncorrelated)

Which way to apply it is the paper's finding (docs/conversion.md, section 6). The mean of the
naive point given the truth is E[h(θ̂)] ≈ h(θ) + t, so the frequentist correction subtracts t
(``sign="debiased"``: an approximately unbiased measurement). The paper adds it (eq. 10 as
printed, ``sign="printed"``): to second order that is the posterior mean E[h(θ) | θ̂] under a
flat prior, and as a measurement it doubles the naive bias. For the 2D polar map it is
exactly radarviz's ``seed`` point, r̂ (1 − s/2)(cos β̂, sin β̂).

The matching covariance of h(θ̂) for Gaussian v, to the same order, is

    C_ij = (J Σ Jᵀ)_ij + ½ tr(H_i Σ H_j Σ)

(the second term is Var of the quadratic form: for Gaussian v, Cov(vᵀA v, vᵀB v) =
2 tr(AΣBΣ), with A = ½ H_i, B = ½ H_j; the cross term E[J v · vᵀ H v] vanishes because odd
moments of v are zero). Both formulas are exact when h is quadratic; for the polar map the
mean term is the leading bias, and the covariance term adds the along-range spread ½ r² s² that
the first-order form lacks, but not the O(s²) terms from third derivatives.

Shapes: θ (..., n), Σ (..., n, n), J (..., m, n), H (..., m, n, n) with H[..., i, j, k] =
∂²h_i/∂θ_j∂θ_k; every function broadcasts over the leading axes. The analytic derivatives of
the radar maps are here (``spherical_*`` for (r, β, ε) → (x, y, z), ``polar_*`` for
(r, β) → (x, y)), and ``numerical_jacobian`` / ``numerical_hessians`` check them (and give the
derivatives of any other h).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.geometry import direction_cosines, unit_vector_partials

Sign = Literal["debiased", "printed"]
SIGNS: tuple[str, ...] = ("debiased", "printed")

Arr = NDArray[np.float64]


def _f(a: ArrayLike) -> Arr:
    return np.asarray(a, dtype=np.float64)


class SecondOrder(NamedTuple):
    """A second-order converted measurement.

    Attributes:
        point: (..., m) h(θ̂) plus the signed second-order term.
        cov: (..., m, m) J Σ Jᵀ + ½ tr(H_i Σ H_j Σ).
    """

    point: Arr
    cov: Arr


def second_order_term(hessians: ArrayLike, cov: ArrayLike) -> Arr:
    """t_i = ½ tr(H_i Σ) (Prosov eq. 7): (..., m, n, n) and (..., n, n) → (..., m)."""
    return 0.5 * np.einsum("...ijk,...jk->...i", _f(hessians), _f(cov))


def second_order_correction(hessians: ArrayLike, cov: ArrayLike, *, sign: Sign) -> Arr:
    """The correction added to h(θ̂): −t (``"debiased"``) or +t (``"printed"``, eq. 10)."""
    if sign not in SIGNS:
        raise ValueError(f"sign must be one of {', '.join(SIGNS)} (got {sign!r})")
    t = second_order_term(hessians, cov)
    return -t if sign == "debiased" else t


def second_order_cov(jacobian: ArrayLike, hessians: ArrayLike, cov: ArrayLike) -> Arr:
    """C = J Σ Jᵀ + ½ tr(H_i Σ H_j Σ), the Gaussian second-order covariance.  (..., m, m)."""
    J, H, S = _f(jacobian), _f(hessians), _f(cov)
    first = J @ S @ np.swapaxes(J, -1, -2)
    hs = H @ S[..., None, :, :]  # (..., m, n, n): H_i Σ for each component i
    second = 0.5 * np.einsum("...iab,...jba->...ij", hs, hs)
    return first + second


def second_order_convert(
    value: ArrayLike, jacobian: ArrayLike, hessians: ArrayLike, cov: ArrayLike, *, sign: Sign
) -> SecondOrder:
    """h(θ̂) ± ½ tr(H_i Σ) and its second-order covariance, from h's value and derivatives at
    θ̂ (value (..., m), jacobian (..., m, n), hessians (..., m, n, n), cov (..., n, n))."""
    point = _f(value) + second_order_correction(hessians, cov, sign=sign)
    return SecondOrder(point, second_order_cov(jacobian, hessians, cov))


# --------------------------------------------------------------------------------------------
# The radar maps and their analytic derivatives
# --------------------------------------------------------------------------------------------


def spherical_map(theta: ArrayLike) -> Arr:
    """(r, β, ε) (..., 3) → r u(β, ε) = r (cos ε cos β, cos ε sin β, sin ε)  (..., 3), m."""
    t = _f(theta)
    return t[..., 0, None] * direction_cosines(t[..., 1], t[..., 2])


def spherical_jacobian(theta: ArrayLike) -> Arr:
    """∂(x, y, z)/∂(r, β, ε) = [u, r ∂u/∂β, r ∂u/∂ε] (``core.geometry``).  (..., 3, 3)."""
    t = _f(theta)
    r = t[..., 0, None]
    u = direction_cosines(t[..., 1], t[..., 2])
    d_b, d_e = unit_vector_partials(t[..., 1], t[..., 2])
    return np.stack([u, r * d_b, r * d_e], axis=-1)


def spherical_hessians(theta: ArrayLike) -> Arr:
    """H[..., i, j, k] = ∂²(r u_i)/∂θ_j∂θ_k, θ = (r, β, ε).  (..., 3, 3, 3).

        ∂²/∂r² = 0,   ∂²/∂r∂β = ∂u/∂β,   ∂²/∂r∂ε = ∂u/∂ε
        ∂²/∂β² = −r cos ε (cos β, sin β, 0),   ∂²/∂ε² = −r u,
        ∂²/∂β∂ε = r sin ε (sin β, −cos β, 0)

    (u is linear in r, and in each angle a rotation: its second derivative in an angle is minus
    the part of u that rotates with it.)
    """
    t = _f(theta)
    r, az, el = t[..., 0], t[..., 1], t[..., 2]
    ca, sa, ce, se = np.cos(az), np.sin(az), np.cos(el), np.sin(el)
    H = np.zeros((*t.shape[:-1], 3, 3, 3))  # [..., i, j, k]; ∂²/∂r² = 0 and z's ∂/∂β = 0
    # ∂u/∂β = cos ε (−sin β, cos β, 0) and ∂u/∂ε = (−sin ε cos β, −sin ε sin β, cos ε)
    # (``core.geometry.unit_vector_partials``), in the (r, β) and (r, ε) places.
    for j, k in ((0, 1), (1, 0)):
        H[..., 0, j, k], H[..., 1, j, k] = -ce * sa, ce * ca
    for j, k in ((0, 2), (2, 0)):
        H[..., 0, j, k], H[..., 1, j, k], H[..., 2, j, k] = -se * ca, -se * sa, ce
    rce, rse = r * ce, r * se
    H[..., 0, 1, 1], H[..., 1, 1, 1] = -rce * ca, -rce * sa  # −r cos ε (cos β, sin β, 0)
    H[..., 0, 2, 2], H[..., 1, 2, 2], H[..., 2, 2, 2] = -rce * ca, -rce * sa, -rse  # −r u
    for j, k in ((1, 2), (2, 1)):
        H[..., 0, j, k], H[..., 1, j, k] = rse * sa, -rse * ca  # r sin ε (sin β, −cos β, 0)
    return H


def polar_map(theta: ArrayLike) -> Arr:
    """(r, β) (..., 2) → r (cos β, sin β)  (..., 2): ``spherical_map`` at ε = 0, z dropped."""
    return spherical_map(_zero_elevation(theta))[..., :2]


def polar_jacobian(theta: ArrayLike) -> Arr:
    """∂(x, y)/∂(r, β)  (..., 2, 2): the (x, y) × (r, β) block of ``spherical_jacobian``."""
    return spherical_jacobian(_zero_elevation(theta))[..., :2, :2]


def polar_hessians(theta: ArrayLike) -> Arr:
    """∂²(x, y)/∂(r, β)²  (..., 2, 2, 2): the 2D block of ``spherical_hessians`` at ε = 0."""
    return spherical_hessians(_zero_elevation(theta))[..., :2, :2, :2]


def _zero_elevation(theta: ArrayLike) -> Arr:
    t = _f(theta)
    return np.concatenate([t, np.zeros_like(t[..., :1])], axis=-1)


# --------------------------------------------------------------------------------------------
# Finite differences (to check analytic derivatives, or for an h without them)
# --------------------------------------------------------------------------------------------


def numerical_jacobian(h: Callable[[Arr], Arr], theta: ArrayLike, step: ArrayLike) -> Arr:
    """Central differences J[..., :, k] = (h(θ + δ_k e_k) − h(θ − δ_k e_k)) / (2 δ_k).

    h maps (..., n) → (..., m); ``step`` δ is (n,) or (..., n). Error O(δ² h''').
    """
    t, d = _f(theta), np.broadcast_to(_f(step), np.shape(theta))
    cols = []
    for k in range(t.shape[-1]):
        e = np.zeros_like(t)
        e[..., k] = d[..., k]
        cols.append((h(t + e) - h(t - e)) / (2.0 * d[..., k, None]))
    return np.stack(cols, axis=-1)


def numerical_hessians(h: Callable[[Arr], Arr], theta: ArrayLike, step: ArrayLike) -> Arr:
    """Central second differences, H[..., i, j, k] ≈ ∂²h_i/∂θ_j∂θ_k  (..., m, n, n):

        [h(θ + δ_j e_j + δ_k e_k) − h(θ + δ_j e_j − δ_k e_k)
         − h(θ − δ_j e_j + δ_k e_k) + h(θ − δ_j e_j − δ_k e_k)] / (4 δ_j δ_k)

    (j = k included: then it is the second difference with step 2δ_j). Error O(δ² h'''').
    """
    t, d = _f(theta), np.broadcast_to(_f(step), np.shape(theta))
    n = t.shape[-1]

    def shift(j: int, k: int, sj: float, sk: float) -> Arr:
        e = np.zeros_like(t)
        e[..., j] += sj * d[..., j]
        e[..., k] += sk * d[..., k]
        return h(t + e)

    m = np.shape(h(t))[-1]
    out = np.empty((*t.shape[:-1], m, n, n))
    for j in range(n):
        for k in range(j, n):
            v = shift(j, k, 1, 1) - shift(j, k, 1, -1) - shift(j, k, -1, 1) + shift(j, k, -1, -1)
            out[..., j, k] = out[..., k, j] = v / (4.0 * d[..., j, None] * d[..., k, None])
    return out
