"""The interacting multiple model (IMM) filter over a batch of constant-velocity tracks.

Blom and Bar-Shalom's IMM (Bar-Shalom, Li and Kirubarajan 2001, sec. 11.6.6), for r models
that share the state (x, ẋ, y, ẏ[, z, ż]) and differ in their prediction (``core.filters.
models.IMMModel``: σa per model). The r model-conditioned estimates of every track are one
batch with a *trailing model axis*: x (..., r, n), P (..., r, n, n), so a batch of k methods ×
M runs × r models is one ``CVBatch`` of shape (k, M, r) and every model-conditioned update is
the engine's own (``core.filters.measurement``: the plot's arrays broadcast over the models).
Per plot, with model probabilities μᵢ and the transition matrix Π::

    mixing        c̄ⱼ = Σᵢ πᵢⱼ μᵢ,   μᵢ|ⱼ = πᵢⱼ μᵢ / c̄ⱼ
                  x⁰ⱼ = Σᵢ μᵢ|ⱼ xᵢ,   P⁰ⱼ = Σᵢ μᵢ|ⱼ (Pᵢ + (xᵢ − x⁰ⱼ)(xᵢ − x⁰ⱼ)ᵀ)
    prediction    x⁻ⱼ, P⁻ⱼ = model j's prediction of (x⁰ⱼ, P⁰ⱼ)       (``cv_predict`` with σa,j)
    update        each stage: Λⱼ = N(νⱼ; 0, Sⱼ),  μⱼ ∝ Λⱼ c̄ⱼ,  then the stage's update
    combination   x = Σⱼ μⱼ xⱼ,   P = Σⱼ μⱼ (Pⱼ + (xⱼ − x)(xⱼ − x)ᵀ)

filterpy's ``IMMEstimator`` runs the same recursion (its ``update`` ends with the mixing that
its next ``predict`` uses); ``tests/test_imm.py`` checks the two against each other.

The innovation statistics the consistency monitor sees (``imm_step``) are those of the
combined prediction x̄⁻ = Σⱼ c̄ⱼ x⁻ⱼ, P̄⁻ (moment matched): for a position measurement with one
R this is exactly the mixture's innovation mean and covariance.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.filters.imm_moments import (
    combine_2d,
    combine_3d,
    mix_2d,
    mix_3d,
    updated_probabilities,
)
from radarviz.core.filters.innovation import InnovationStats
from radarviz.core.filters.models import IMMModel
from radarviz.core.filters.predict import add_process_noise, cv_predict, white_acceleration
from radarviz.core.filters.state import CVBatch, cov_components, empty_batch, mean_components
from radarviz.core.filters.step import Stage, moves
from radarviz.core.filters.turn import turn_factors, turn_predict


class IMMState(NamedTuple):
    """The IMM estimate of a batch of tracks.

    Attributes:
        models: model-conditioned estimates, batch (..., r): x (..., r, n), P (..., r, n, n).
        probabilities: μ (..., r), summing to 1 over the last axis.
    """

    models: CVBatch
    probabilities: NDArray[np.float64]


def imm_start(state: CVBatch, model: IMMModel) -> IMMState:
    """Every model starts at the track's start (..., n); μ = the model's initial one."""
    r = model.models
    x = np.repeat(state.x[..., None, :], r, axis=-2)
    P = np.repeat(state.P[..., None, :, :], r, axis=-3)
    mu = np.broadcast_to(model.initial_probabilities(), (*state.batch_shape, r)).copy()
    return IMMState(CVBatch(x, P), mu)


def _model_views(models: CVBatch) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The models' component-major views: x (..., r, n) as (r, n, ...), P as (r, n, n, ...)."""
    return np.moveaxis(models.x, (-2, -1), (0, 1)), np.moveaxis(models.P, (-3, -2, -1), (0, 1, 2))


def imm_combine(models: CVBatch, mu: NDArray[np.float64]) -> CVBatch:
    """The moment-matched estimate Σⱼ μⱼ N(xⱼ, Pⱼ): x (..., n), P (..., n, n)
    (``core.filters.imm_moments``, every engine's)."""
    xm, Pm = _model_views(models)
    n = models.x.shape[-1]
    out = empty_batch(models.batch_shape[:-1], n // 2)
    mu_c = np.moveaxis(np.broadcast_to(mu, models.batch_shape), -1, 0)
    if n == 4:
        combine_2d(xm, Pm, mu_c, mean_components(out.x), cov_components(out.P))
    else:
        combine_3d(xm, Pm, mu_c, mean_components(out.x), cov_components(out.P))
    return out


def imm_mix(imm: IMMState, transition: NDArray[np.float64]) -> tuple[CVBatch, NDArray[np.float64]]:
    """The mixed initial conditions (x⁰ⱼ, P⁰ⱼ), batch (..., r), and c̄ (..., r)
    (``core.filters.imm_moments``, every engine's)."""
    models = imm.models
    xm, Pm = _model_views(models)
    n, r = models.x.shape[-1], models.x.shape[-2]
    shape = models.batch_shape[:-1]
    out = empty_batch((*shape, r), n // 2)
    c = np.empty((r, *shape))
    w = np.empty((r, r, *shape))
    mu_c = np.moveaxis(np.broadcast_to(imm.probabilities, models.batch_shape), -1, 0)
    x0, P0 = _model_views(out)
    Pi = np.asarray(transition, dtype=np.float64)
    if n == 4:
        mix_2d(xm, Pm, mu_c, Pi, x0, P0, c, w)
    else:
        mix_3d(xm, Pm, mu_c, Pi, x0, P0, c, w)
    return out, np.moveaxis(c, 0, -1)


def imm_predict(mixed: CVBatch, dt_s: float | NDArray[np.float64], model: IMMModel) -> CVBatch:
    """Model j's prediction (σa,j) of its mixed estimate, every j: constant velocity, or for
    a model with a turn rate ωj ≠ 0 the coordinated turn at ωj (``core.filters.turn``);
    ``dt_s`` one step or one per track (broadcasting against the batch without its model
    axis)."""
    xs, Ps = [], []
    omegas = model.turn_rates_radps()
    n = mixed.x.shape[-1]
    for j, sigma_a_mps2 in enumerate(model.sigma_a_mps2):
        one = CVBatch(mixed.x[..., j, :], mixed.P[..., j, :, :])
        omega = float(omegas[j])
        if omega == 0.0:
            pred = cv_predict(one, dt_s, sigma_a_mps2)
        else:
            pred = CVBatch(one.x.copy(), one.P.copy())
            T = np.asarray(dt_s, dtype=np.float64)
            theta = omega * T
            k = turn_factors(omega, np.sin(theta), np.sin(0.5 * theta))
            x_c = np.moveaxis(pred.x, -1, 0)  # components first: x_c[i], P_c[i, j]
            P_c = np.moveaxis(pred.P, (-2, -1), (0, 1))
            turn_predict(x_c, P_c, n, T, k)
            add_process_noise(P_c, n, white_acceleration(T, float(sigma_a_mps2) ** 2))
        xs.append(pred.x)
        Ps.append(pred.P)
    return CVBatch(np.stack(xs, axis=-2), np.stack(Ps, axis=-3))


def mode_probabilities(
    prior: NDArray[np.float64], log_likelihood: NDArray[np.float64]
) -> NDArray[np.float64]:
    """μⱼ ∝ Λⱼ c̄ⱼ over the last axis (the models) of the prior c̄ and the models'
    log-likelihoods, each (..., r) (``core.filters.imm_moments.updated_probabilities``: the
    shift that keeps a far-off plot from underflowing, and the models that get no weight)."""
    prior, log_likelihood = np.broadcast_arrays(prior, log_likelihood)
    mu = np.empty(prior.shape)
    # written once for every engine (``core.filters.imm_moments``), on the models' axis first
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        updated_probabilities(
            np.moveaxis(prior, -1, 0), np.moveaxis(log_likelihood, -1, 0), np.moveaxis(mu, -1, 0)
        )
    return mu


def imm_step(
    imm: IMMState,
    dt_s: float | NDArray[np.float64],
    model: IMMModel,
    stages: Sequence[Stage],
    with_stats: bool = True,
) -> tuple[IMMState, CVBatch, InnovationStats | None]:
    """One plot: mix, predict over ``dt_s`` (0: no prediction), then each stage (module
    docstring). Returns the new IMM state, its combined estimate (...) and, with
    ``with_stats``, the innovation statistics of the combined prediction."""
    mixed, mu = imm_mix(imm, model.transition_matrix())
    pred = imm_predict(mixed, dt_s, model) if moves(dt_s) else mixed
    total: InnovationStats | None = None
    for stage in stages:
        if with_stats:
            s = stage.innovation(imm_combine(pred, mu))
            total = s if total is None else total + s
        mu = mode_probabilities(mu, stage.innovation(pred, models=True).log_likelihood())
        pred = stage.update(pred, models=True)
    return IMMState(pred, mu), imm_combine(pred, mu), total
