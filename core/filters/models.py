"""Motion models of a track: the constant-velocity filter and the IMM of constant-velocity
and fixed-rate coordinated-turn models, as small validated containers (the filtering is in
``core.filters.predict``, ``core.filters.turn`` and ``core.filters.imm``).

* :class:`CVModel`: one constant-velocity model with white-noise acceleration of std σa on
  each axis (``core.filters.predict``; σa = 0 is the papers' Q = 0 straight-line target).
* :class:`IMMModel`: r models, each constant velocity or a coordinated turn at a fixed rate
  ωj (``core.filters.turn``), each with its σa (a quiet model for straight flight, turn
  models, a lively one for manoeuvres), and the Markov transition matrix Π between them, per
  update: πij = P(model j at this update | model i at the previous one). Each row sums to 1
  and every πij is in (0, 1): a zero would forbid a switch for ever, a one would freeze a model.
  Π is per *update*, not per second: with several radars the updates come every T/(radars)
  seconds and the chosen switching probabilities reflect that rate (``docs/manoeuvre.md``).

All models share the state (x, ẋ, y, ẏ[, z, ż]), so the IMM mixes them without any change of
coordinates; a turn model's rate is fixed, not estimated. A coordinated turn at 3°/s is an
acceleration of v ω ≈ 13 m/s² at 250 m/s: white noise of that σa covers it in the mean but
lags behind it (the error in a turn is a bias, not noise), while a turn model at a rate near
the target's predicts it (``docs/manoeuvre.md``, "Turn models").
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
        turn_rate_degps: (r,) each model's turn rate ω, °/s (positive counter-clockwise);
            0 is constant velocity, any other value a coordinated turn at that fixed rate
            (``core.filters.turn``). None: every model constant velocity.
    """

    sigma_a_mps2: tuple[float, ...]
    transition: tuple[tuple[float, ...], ...]
    initial: tuple[float, ...] | None = None
    turn_rate_degps: tuple[float, ...] | None = None

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
        if self.turn_rate_degps is not None:
            if len(self.turn_rate_degps) != r:
                raise ParameterError(
                    f"imm_turn_rate_degps must have one entry per model, {r} "
                    f"(got {len(self.turn_rate_degps)})",
                    "imm_turn_rate_degps",
                )
            for w in self.turn_rate_degps:
                check("imm_turn_rate_degps", w)

    @property
    def models(self) -> int:
        return len(self.sigma_a_mps2)

    def turn_rates_radps(self) -> NDArray[np.float64]:
        """ω of each model (r,), rad/s (0: constant velocity)."""
        if self.turn_rate_degps is None:
            return np.zeros(self.models)
        return np.radians(np.array(self.turn_rate_degps, dtype=np.float64))

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


#: The IMM ``track`` uses on a user's file unless told otherwise (``docs/manoeuvre.md``, "Turn
#: models"): four models on the shared state,
#:
#: * a quiet constant-velocity model (σa = 0.1 m/s²: straight flight with small speed and
#:   heading drift),
#: * two coordinated turns at ω = ±2.25°/s (σa = 3 m/s², which covers the 1.5–3°/s of
#:   airliners' turns: 0.75°/s × 230 m/s = 3 m/s² of mismatch), and
#: * a lively constant-velocity model (σa = 12 m/s²) for what neither describes: turn
#:   entries, speed changes, climbs,
#:
#: entering a manoeuvre with probability 0.005 per update (0.002 into each turn, 0.001 into
#: the lively model, the former default's 0.005 in all) and leaving it with 0.05. Chosen by
#: measurement against the former default of two constant-velocity models (σa 0.1 and
#: 12 m/s², Π 0.005 / 0.05), kept as ``CV_IMM``: in turns the position RMSE is 18–27% lower
#: and the NEES closer to its dof, on straight legs the RMSE no worse; a likelier entry
#: (0.02) loses fewer plots at turn entries but costs 17% RMSE on Prosov's straight line.
DEFAULT_IMM = IMMModel(
    (0.1, 3.0, 3.0, 12.0),
    (
        (0.995, 0.002, 0.002, 0.001),
        (0.05, 0.93, 0.01, 0.01),
        (0.05, 0.01, 0.93, 0.01),
        (0.05, 0.02, 0.02, 0.91),
    ),
    turn_rate_degps=(0.0, 2.25, -2.25, 0.0),
)

#: The former default, two constant-velocity models (σa 0.1 and 12 m/s², switching with
#: probability 0.005 per update into the manoeuvre model and 0.05 out of it): the reference
#: the turn models are measured against (``core.experiments.turns``).
CV_IMM = IMMModel((0.1, 12.0), ((0.995, 0.005), (0.05, 0.95)))
