"""One plot's measurement stages as objects a scan step can apply to any batch.

A plot updates a track in stages: its position (a method's converted point, or the polar
measurement for ``ekf``/``ukf``), then, when it has one, its Doppler radial velocity. Each
stage here knows its plot and offers two things on a predicted batch:

* ``innovation(state)``: the innovation statistics (``core.filters.innovation``), for the
  consistency monitor and the IMM likelihoods;
* ``update(state)``: the posterior, by the engine's own update functions
  (``MethodGroup.update``, ``doppler_update``, ``converted_doppler_update``); nothing is
  re-implemented here.

A plot's Doppler enters by one of ``DOPPLER_UPDATES``: ``"line_of_sight"``
(``DopplerMeasurement``, ``core.filters.doppler``) or ``"converted"``
(``ConvertedDopplerMeasurement``, the r̂ V̂r pseudo-measurement of
``core.filters.converted_doppler``).

``models=True`` says the batch has one more, trailing axis than the plot's arrays were made
for (the IMM's model axis, ``core.filters.imm``): every array of the plot gets a trailing
axis of 1 and broadcasts over the models. The same stage so serves the IMM's model-
conditioned updates (batch (..., r)) and its combined estimate (batch (...)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from radarviz.core.filters.converted_doppler import (
    converted_doppler_terms,
    converted_doppler_update,
)
from radarviz.core.filters.doppler import doppler_innovation, doppler_update
from radarviz.core.filters.innovation import (
    InnovationStats,
    linear_innovation,
    position_innovation,
)
from radarviz.core.filters.methods import MethodGroup, Parts, PolarNoise, PolarPlot
from radarviz.core.filters.position import innovation_update
from radarviz.core.filters.state import CVBatch, Vec, position_index

#: How a plot's radial velocity updates a track: along the measured line of sight
#: (``core.filters.doppler``) or as the converted r̂ V̂r (``core.filters.converted_doppler``).
DOPPLER_UPDATES: tuple[str, ...] = ("line_of_sight", "converted")


def _expand(value: ArrayLike | None, models: bool) -> ArrayLike | None:
    """``value`` with a trailing axis of 1 when the batch has a model axis."""
    if value is None or not models:
        return value
    return np.asarray(value, dtype=np.float64)[..., None]


@dataclass(frozen=True)
class PositionMeasurement:
    """A Cartesian position measurement z (d components, m) with noise R (upper entries, m²),
    each broadcasting against the batch: the linear measurement of ``core.filters.position``."""

    z: tuple[Vec, ...]
    R: dict[tuple[int, int], Vec]

    def _innovation(self, state: CVBatch, models: bool) -> tuple[list[Vec], dict]:
        pos = position_index(state.dims)
        nu = [_expand(self.z[a], models) - state.x[..., p] for a, p in enumerate(pos)]
        return nu, {k: _expand(v, models) for k, v in self.R.items()}

    def innovation(self, state: CVBatch, models: bool = False) -> InnovationStats:
        return position_innovation(state, *self._innovation(state, models))

    def update(self, state: CVBatch, models: bool = False) -> CVBatch:
        return innovation_update(state, *self._innovation(state, models))


@dataclass(frozen=True)
class PlotMeasurement:
    """The position stage of one scan for a method group (``MethodGroup``).

    Attributes:
        group: the methods of the batch (its leading axis for a converted group).
        plot, noise: the plot's polar values and noise std, arrays broadcasting against the
            batch shape (without the model axis).
        site: the radar's position (d,), or one per track (..., d) (many targets, each seen
            by its own radar).
        parts: the converted methods' precomputed conversions (``MethodGroup.start_parts``),
            or None.
    """

    group: MethodGroup
    plot: PolarPlot
    noise: PolarNoise
    site: ArrayLike | None = None
    parts: Parts | None = None

    def _for(
        self, state: CVBatch, models: bool
    ) -> tuple[PolarPlot, PolarNoise, Parts | None, ArrayLike | None]:
        if not models:  # the arrays were made for this batch
            return self.plot, self.noise, self.parts, self.site
        shape = state.batch_shape
        # An IMM step asks twice per stage (likelihoods, update): expand the arrays once.
        cache = self.__dict__.setdefault("_expansions", {})
        if shape not in cache:
            cache[shape] = self._expanded(shape)
        return cache[shape]

    def _expanded(
        self, shape: tuple[int, ...]
    ) -> tuple[PolarPlot, PolarNoise, Parts | None, ArrayLike | None]:
        plot = PolarPlot(*(_expand(v, True) for v in self.plot))
        if not self.group.converted:  # the polar updates take arrays of the batch's shape
            plot = PolarPlot(*(None if v is None else np.broadcast_to(v, shape) for v in plot))
        noise = PolarNoise(*(_expand(v, True) for v in self.noise))
        parts = self.parts
        if parts is not None:
            z, R = parts
            if any(k.about_prediction for k in self.group.kinds):
                # ``ducm`` rewrites its row per model: the parts need the batch's full shape.
                parts = (
                    [np.broadcast_to(np.asarray(v)[..., None], shape) for v in z],
                    {k: np.broadcast_to(np.asarray(v)[..., None], shape) for k, v in R.items()},
                )
            else:
                parts = (
                    [np.asarray(v)[..., None] for v in z],
                    {k: np.asarray(v)[..., None] for k, v in R.items()},
                )
        site = self.site
        if site is not None and np.ndim(site) > 1:  # a site per track (..., d): over the models
            site = np.asarray(site, dtype=np.float64)[..., None, :]
        return plot, noise, parts, site

    def innovation(self, state: CVBatch, models: bool = False) -> InnovationStats:
        plot, noise, parts, site = self._for(state, models)
        nu, R = self.group.measurement(state, plot, noise, site=site, parts=parts)
        return position_innovation(state, nu, R)

    def update(self, state: CVBatch, models: bool = False) -> CVBatch:
        plot, noise, parts, site = self._for(state, models)
        return self.group.update(state, plot, noise, site=site, parts=parts)


@dataclass(frozen=True)
class DopplerMeasurement:
    """The Doppler stage of one plot: V̂r along the measured line of sight
    (``core.filters.doppler``); arrays broadcast against the batch (scalars for one plot)."""

    radial_velocity_mps: ArrayLike
    azimuth_rad: ArrayLike
    elevation_rad: ArrayLike
    sigma_vr_mps: ArrayLike
    sigma_beta_rad: ArrayLike
    sigma_elevation_rad: ArrayLike

    def _args(self, models: bool) -> tuple[list, dict]:
        vals = [_expand(v, models) for v in (self.radial_velocity_mps, self.azimuth_rad)]
        vals.append(_expand(self.elevation_rad, models))
        kw = {
            "sigma_vr_mps": _expand(self.sigma_vr_mps, models),
            "sigma_beta_rad": _expand(self.sigma_beta_rad, models),
            "sigma_elevation_rad": _expand(self.sigma_elevation_rad, models),
        }
        return vals, kw

    def innovation(self, state: CVBatch, models: bool = False) -> InnovationStats:
        vals, kw = self._args(models)
        return doppler_innovation(state, *vals, **kw)

    def update(self, state: CVBatch, models: bool = False) -> CVBatch:
        vals, kw = self._args(models)
        return doppler_update(state, *vals, **kw)


@dataclass(frozen=True)
class ConvertedDopplerMeasurement:
    """The Doppler stage of one plot as the converted pseudo-measurement η̂ = r̂ V̂r
    (``core.filters.converted_doppler``): measured range and radial velocity, their noise
    std and the radar's site ((d,) or one per track (..., d)), broadcasting against the batch.
    """

    range_m: ArrayLike
    radial_velocity_mps: ArrayLike
    sigma_r_m: ArrayLike
    sigma_vr_mps: ArrayLike
    site: ArrayLike | None = None

    def _args(self, models: bool) -> tuple[list, dict]:
        site = self.site
        if models and site is not None and np.ndim(site) > 1:  # over the models
            site = np.asarray(site, dtype=np.float64)[..., None, :]
        vals = [_expand(v, models) for v in (self.range_m, self.radial_velocity_mps)]
        kw = {
            "sigma_r_m": _expand(self.sigma_r_m, models),
            "sigma_vr_mps": _expand(self.sigma_vr_mps, models),
            "site": site,
        }
        return vals, kw

    def innovation(self, state: CVBatch, models: bool = False) -> InnovationStats:
        vals, kw = self._args(models)
        return linear_innovation(state, *converted_doppler_terms(state, *vals, **kw))

    def update(self, state: CVBatch, models: bool = False) -> CVBatch:
        vals, kw = self._args(models)
        return converted_doppler_update(state, *vals, **kw)


def doppler_measurement(
    update: str,
    *,
    radial_velocity_mps: ArrayLike,
    range_m: ArrayLike,
    azimuth_rad: ArrayLike,
    elevation_rad: ArrayLike,
    sigma_vr_mps: ArrayLike,
    sigma_r_m: ArrayLike,
    sigma_beta_rad: ArrayLike,
    sigma_elevation_rad: ArrayLike,
    site: ArrayLike | None = None,
) -> DopplerMeasurement | ConvertedDopplerMeasurement:
    """The Doppler stage of a plot by ``update`` (one of ``DOPPLER_UPDATES``), from the plot's
    measured values and noise std (elevation 0 for a 2D plot). The line-of-sight update is
    linear in the velocity and needs no site; the converted one uses the offset from it."""
    if update == "converted":
        return ConvertedDopplerMeasurement(
            range_m, radial_velocity_mps, sigma_r_m, sigma_vr_mps, site
        )
    if update != "line_of_sight":
        raise ValueError(f"Doppler update must be one of {', '.join(DOPPLER_UPDATES)}: {update!r}")
    return DopplerMeasurement(
        radial_velocity_mps,
        azimuth_rad,
        elevation_rad,
        sigma_vr_mps,
        sigma_beta_rad,
        sigma_elevation_rad,
    )
