"""Innovation statistics of a measurement update: NIS and Gaussian log-likelihood.

For a predicted batch (x⁻, P⁻) and a measurement with innovation ν = z − ẑ (m components)
and covariance S = H P⁻ Hᵀ + R::

    NIS = νᵀ S⁻¹ ν                                    (~ χ²(m) for a consistent filter)
    log L = −½ (NIS + log det S + m log 2π)           (the IMM's model likelihood)

(Bar-Shalom, Li and Kirubarajan 2001, sec. 5.4.2 for the NIS test; sec. 11.6.6 for the IMM
likelihood.) A plot updated in two stages (position, then Doppler on the position posterior)
has the joint statistics of the sum of its stages: p(z₁, z₂) = p(z₁) p(z₂ | z₁), and the
stages' innovations are independent for a consistent filter.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.position_2d import position_stats_2d
from radarviz.core.filters.position_3d import position_stats_3d
from radarviz.core.filters.state import CVBatch, Vec, cov_components, quad_form_inv

_LOG_2PI = math.log(2.0 * math.pi)


class InnovationStats(NamedTuple):
    """Per-track innovation statistics of one update (or of several stages, summed).

    Attributes:
        nis: (...) νᵀ S⁻¹ ν.
        log_det_s: (...) log det S (S in m² and m²/s²).
        dof: number of measured components m (χ² degrees of freedom of ``nis``).
    """

    nis: NDArray[np.float64]
    log_det_s: NDArray[np.float64]
    dof: int

    def log_likelihood(self) -> NDArray[np.float64]:
        """log N(ν; 0, S) = −½ (NIS + log det S + m log 2π), (...)."""
        return -0.5 * (self.nis + self.log_det_s + self.dof * _LOG_2PI)

    def __add__(self, other: object) -> InnovationStats:  # type: ignore[override]
        """The statistics of two sequential stages of one plot (module docstring)."""
        if not isinstance(other, InnovationStats):
            return NotImplemented
        return InnovationStats(
            self.nis + other.nis, self.log_det_s + other.log_det_s, self.dof + other.dof
        )


def gaussian_stats(nu: NDArray[np.float64], S: NDArray[np.float64]) -> InnovationStats:
    """NIS and log det S for ν (..., m) and S (..., m, m) symmetric positive definite.

    A track whose S is not positive definite (a broken track) gets NaN for both and leaves
    the others alone: the monitor counts it out of band, the IMM gives that model no weight.
    """
    with np.errstate(invalid="ignore", divide="ignore"):
        nis = quad_form_inv(S, nu)  # written-out Cholesky: NaN, not an exception
        sign, log_det = np.linalg.slogdet(S)
    return InnovationStats(nis, np.where(sign > 0, log_det, np.nan), nu.shape[-1])


def position_innovation(
    state: CVBatch, innovation: Sequence[Vec], R: dict[tuple[int, int], Vec]
) -> InnovationStats:
    """The statistics of a position measurement (``core.filters.position``): H = H_pos,
    S = H P⁻ Hᵀ + R; ``innovation`` has d components, ``R`` upper entries, each (...).

    Written once for every engine: ``position_stats_2d`` (``core.filters.position_2d``) and
    ``position_stats_3d`` (``core.filters.position_3d``), on the batch's components."""
    Pc = cov_components(state.P)
    with np.errstate(invalid="ignore", divide="ignore"):
        if state.dims == 2:
            nu_x, nu_y = innovation
            stats = position_stats_2d(
                Pc[0, 0], Pc[0, 2], Pc[2, 2], nu_x, nu_y, R[0, 0], R[0, 1], R[1, 1]
            )
        else:
            stats = position_stats_3d(Pc, innovation, R)
    return innovation_stats(stats, state.batch_shape, state.dims)


def innovation_stats(stats: tuple, shape: tuple[int, ...], dof: int) -> InnovationStats:
    """(νᵀ S⁻¹ ν, log det S) of a step's statistics as ``InnovationStats`` of the batch's
    shape (a measurement given as scalars broadcasts over the batch)."""
    nis, log_det = (np.array(np.broadcast_to(v, shape), dtype=np.float64) for v in stats)
    return InnovationStats(nis, log_det, dof)


def linear_innovation(
    state: CVBatch, nu: NDArray[np.float64], H: NDArray[np.float64], R: NDArray[np.float64]
) -> InnovationStats:
    """The statistics of a linear measurement: ν (..., m), H (..., m, n), R (..., m, m)."""
    S = H @ state.P @ H.mT + R
    return gaussian_stats(nu, 0.5 * (S + S.mT))
