"""Motion models of a track: the constant-velocity filter and the IMM of constant-velocity
models, as small validated containers (the filtering is in ``core.filters.predict`` and
``core.filters.imm``).

* :class:`CVModel`: one constant-velocity model with white-noise acceleration of std σa on
  each axis (``core.filters.predict``; σa = 0 is the papers' Q = 0 straight-line target).
* :class:`IMMModel`: r constant-velocity models with σa,1 < … (a quiet model for straight
  flight, a lively one for manoeuvres) and the Markov transition matrix Π between them, per
  update: πij = P(model j at this update | model i at the previous one). Each row sums to 1
  and every πij is in (0, 1): a zero would forbid a switch for ever, a one would freeze a model.
  Π is per *update*, not per second: with several radars the updates come every T/(radars)
  seconds and the chosen switching probabilities reflect that rate (``docs/manoeuvre.md``).

The IMM's models differ only in their process noise, so there is no turn-rate parameter: a
coordinated turn at up to 3°/s is, for a track updated every 1.7 s, an acceleration of at
most v ω ≈ 13 m/s² that the lively model's σa covers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from radarviz.core.params import ParameterError, check, check_real

#: The names ``StreamOptions.model`` accepts.
MOTION_MODELS: tuple[str, ...] = ("cv", "imm")
#: Largest |row sum − 1| of a transition matrix accepted (rounding of typed decimals).
ROW_SUM_TOLERANCE = 1e-9


@dataclass(frozen=True)
class CVModel:
    """Constant velocity with white-noise acceleration σa (m/s²) on each axis."""

    sigma_a_mps2: float = 0.0

    def __post_init__(self) -> None:
        check("sigma_a_mps2", self.sigma_a_mps2)


@dataclass(frozen=True)
class IMMModel:
    """An IMM of constant-velocity models (module docstring).

    Attributes:
        sigma_a_mps2: (r,) σa of each model, m/s² (r >= 2).
        transition: (r, r) Π, row-major; row i is the distribution of the next model given i.
        initial: (r,) model probabilities of a new track (default: Π's stationary one).
    """

    sigma_a_mps2: tuple[float, ...]
    transition: tuple[tuple[float, ...], ...]
    initial: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        r = len(self.sigma_a_mps2)
        if r < 2:
            raise ParameterError(
                f"imm_sigma_a_mps2 must give at least 2 models (got {r})", "imm_sigma_a_mps2"
            )
        for v in self.sigma_a_mps2:
            check("imm_sigma_a_mps2", v)
        check_transition(self.transition, r)
        if self.initial is not None:
            check_probabilities("initial", self.initial, r)

    @property
    def models(self) -> int:
        return len(self.sigma_a_mps2)

    def transition_matrix(self) -> NDArray[np.float64]:
        """Π as an (r, r) array."""
        return np.array(self.transition, dtype=np.float64)

    def initial_probabilities(self) -> NDArray[np.float64]:
        """μ of a new track: ``initial``, or the stationary distribution of Π (μ Π = μ)."""
        if self.initial is not None:
            return np.array(self.initial, dtype=np.float64)
        Pi = self.transition_matrix()
        w, v = np.linalg.eig(Pi.T)
        mu = np.real(v[:, np.argmin(np.abs(w - 1.0))])
        return mu / mu.sum()


def check_probabilities(name: str, row: tuple[float, ...], r: int) -> None:
    """``row`` must be r probabilities in (0, 1) summing to 1 (one line naming ``name``)."""
    if len(row) != r:
        raise ParameterError(f"{name} must have {r} entries (got {len(row)})", name)
    for p in row:
        check_real(name, p, low=0.0, high=1.0, high_open=True)
    total = math.fsum(row)
    if abs(total - 1.0) > ROW_SUM_TOLERANCE:
        raise ParameterError(
            f"{name} must sum to 1 (got {' '.join(f'{p:g}' for p in row)}, sum {total:.12g})",
            name,
        )


def check_transition(transition: tuple[tuple[float, ...], ...], r: int) -> None:
    """Π must be r × r with entries in (0, 1) and rows summing to 1."""
    name = "transition_prob"
    if len(transition) != r:
        raise ParameterError(
            f"{name} must be a {r} × {r} matrix, one row per model (got {len(transition)} rows)",
            name,
        )
    for i, row in enumerate(transition):
        if len(row) != r:
            raise ParameterError(f"{name} row {i + 1} must have {r} entries (got {len(row)})", name)
        for p in row:
            check(name, p)  # the table's (0, 1)
        total = math.fsum(row)
        if abs(total - 1.0) > ROW_SUM_TOLERANCE:
            raise ParameterError(
                f"{name} row {i + 1} must sum to 1 (got {' '.join(f'{p:g}' for p in row)}, "
                f"sum {total:.12g})",
                name,
            )


#: The IMM ``track`` uses on a user's file unless told otherwise (``docs/manoeuvre.md``): a
#: quiet model (σa = 0.1 m/s²: straight flight with small speed and heading drift) and a
#: manoeuvre model (σa = 12 m/s²: a 3°/s turn at 230 m/s), switching with probability 0.005
#: per update into a manoeuvre and 0.05 out of one. Chosen on the manoeuvre scenario and the
#: straight-line target together (``reproduce manoeuvre``): a likelier switch into the
#: manoeuvre model costs more on a straight line (0.02: +30% RMSE against the matched filter)
#: and buys little on the turns.
DEFAULT_IMM = IMMModel((0.1, 12.0), ((0.995, 0.005), (0.05, 0.95)))
