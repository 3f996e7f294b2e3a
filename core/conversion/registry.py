"""The conversion registry: each polar-to-Cartesian conversion as a scale and a covariance.

Every conversion the papers compare is the naive point r̂ u(β̂[, ε̂]) scaled by κ(s), s the
angle noise variance (rad²), with a covariance of one of four forms
(``core.conversion.elementwise.Covariance``):

=========  ====================================  ==============================================
name       scale κ(s)                            covariance
=========  ====================================  ==============================================
naive      1                                     LINEARIZED (Prosov eqs. 8–9)
seed       1 − s/2                               AVERAGED (Prosov eqs. 10–11 as printed)
cmkf_d     1 − (e^(−s) − e^(−s/2))               AVERAGED (Lerro & Bar-Shalom 1993)
ucm        e^(s/2)                               EXACT, at the measurement (Mo et al. 1998)
ducm       e^(s/2)                               EXACT_AT_PREDICTION (Bordonaro et al. 2014)
=========  ====================================  ==============================================

In 3D the scale is applied per axis, s = σβ² + σε² on x and y and s = σε² on z
(``Conversion.scales``). The numpy functions (``core.conversion.planar``,
``core.conversion.spatial``) and the compiled kernels read a conversion only through this
table: its κ, computed here once per radar, and its covariance form, the one thing the
kernels branch on. A new conversion is a new entry (with a new scale function in
``core.conversion.elementwise`` if none fits); see docs/architecture.md, "Adding a method".
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from radarviz.core.conversion.elementwise import (
    Covariance,
    conversion_coefficients,
    debiasing_scale,
    seed_scale,
    unbiasing_scale,
    unit_scale,
)


@dataclass(frozen=True)
class Conversion:
    """One conversion.

    Attributes:
        name: its name everywhere (CLI, files, recordings).
        scale: κ(s), elementwise over numbers or arrays (``core.conversion.elementwise``).
        covariance: the ``Covariance`` form its point carries.
    """

    name: str
    scale: Callable[[Any], Any]
    covariance: Covariance

    @property
    def about_prediction(self) -> bool:
        """Whether its covariance is taken at the filter's predicted position."""
        return self.covariance == Covariance.EXACT_AT_PREDICTION

    def coefficients(self, s: Any, sr2: Any) -> tuple:
        """Its eight scalars that depend on the noise only, at s = σβ² and σr² (numbers or
        arrays): κ(s), then its covariance form's (``conversion_coefficients``)."""
        return conversion_coefficients(self.covariance, self.scale(s), s, sr2)

    def scales(self, sigma_beta_rad: Any, sigma_elevation_rad: Any = 0.0) -> tuple[Any, Any]:
        """(κxy, κz) = (κ(σβ² + σε²), κ(σε²)): the scale per axis (in 2D κxy is κ(σβ²))."""
        sb2, se2 = sigma_beta_rad * sigma_beta_rad, sigma_elevation_rad * sigma_elevation_rad
        return self.scale(sb2 + se2), self.scale(se2)


CONVERSIONS: dict[str, Conversion] = {
    c.name: c
    for c in (
        Conversion("naive", unit_scale, Covariance.LINEARIZED),
        Conversion("seed", seed_scale, Covariance.AVERAGED),
        Conversion("cmkf_d", debiasing_scale, Covariance.AVERAGED),
        Conversion("ucm", unbiasing_scale, Covariance.EXACT),
        Conversion("ducm", unbiasing_scale, Covariance.EXACT_AT_PREDICTION),
    )
}


def conversion_named(name: str) -> Conversion:
    """The registered conversion ``name`` (ValueError naming the choices otherwise)."""
    try:
        return CONVERSIONS[name]
    except KeyError:
        choices = ", ".join(CONVERSIONS)
        raise ValueError(f"method must be one of {choices} (got {name!r})") from None
