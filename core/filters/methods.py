"""The method registry: each tracking method's start and update, in one table.

A method is one way to bring a polar radar plot (r̂, β̂[, ε̂]) into the constant-velocity
filter (``core.filters.state``, ``core.filters.predict``):

=========  =========  ====  ===========================================================
name       kind       dims  what it does
=========  =========  ====  ===========================================================
naive      converted  2, 3  r̂ u(β̂, ε̂), first-order covariance (Prosov eqs. 8–9)
seed       converted  2, 3  × (1 − s/2), covariance eq. 11 (Prosov eqs. 10–11 as printed)
cmkf_d     converted  2, 3  × (1 − e^(−s) + e^(−s/2)), eq. 11 (Lerro & Bar-Shalom 1993)
ucm        converted  2, 3  × e^(s/2), exact covariance at the measurement (Mo et al. 1998)
ducm       converted  2, 3  ucm's point, covariance at the prediction (Bordonaro et al. 2014)
ekf        ekf        2, 3  polar measurement filtered directly, linearised at the prediction
ukf        ukf        2, 3  polar measurement filtered directly, scaled sigma points
=========  =========  ====  ===========================================================

(s = σβ², rad²; in 3D the same forms per axis, ``core.conversion.spatial``.) Every method
starts a track from its first plot the same way: the method's converted point and covariance
(``ducm``, having no prediction yet, starts like ``ucm``; ``ekf`` and ``ukf`` from the naive
point), velocity 0 with std σv0. Converted methods then update with the position update
(``core.filters.position``), the polar ones with ``core.filters.polar_ekf`` /
``core.filters.polar_ukf``. Doppler, when a plot has it, is a second update of the same kind
for every method (``core.filters.doppler``).

Every function works on a batch of any leading shape and takes the radar's ``site``, so a
Monte Carlo of 10⁵ runs, the streaming tracker's single track (a batch of one) and the panel
all run the same code.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radarviz.core.conversion.planar import convert_parts
from radarviz.core.conversion.registry import CONVERSIONS, Conversion
from radarviz.core.conversion.spatial import UPPER_3D, convert_parts_3d
from radarviz.core.filters.polar_ekf import ekf_pseudo_measurement, ekf_update, site_offsets
from radarviz.core.filters.polar_ukf import ukf_update
from radarviz.core.filters.position import cv_update_parts, innovation_update
from radarviz.core.filters.state import CVBatch, Vec, cv_init, position_index

Parts = tuple[list[Vec], dict[tuple[int, int], Vec]]


class PolarPlot(NamedTuple):
    """Measured polar coordinates of a batch of plots, each (...): m, rad; 2D: no elevation."""

    range_m: ArrayLike
    azimuth_rad: ArrayLike
    elevation_rad: ArrayLike | None = None

    @property
    def dims(self) -> int:
        return 2 if self.elevation_rad is None else 3

    def vectors(self) -> list[ArrayLike]:
        out = [self.range_m, self.azimuth_rad]
        return out if self.elevation_rad is None else [*out, self.elevation_rad]


class PolarNoise(NamedTuple):
    """Measurement noise std of the plots: σr (m), σβ (rad), σε (rad; 0 in 2D)."""

    sigma_r_m: ArrayLike
    sigma_beta_rad: ArrayLike
    sigma_elevation_rad: ArrayLike = 0.0


def _parts_2d(name: str, plot: PolarPlot, noise: PolarNoise, predicted: list[Vec] | None) -> Parts:
    c = convert_parts(
        name,
        plot.range_m,
        plot.azimuth_rad,
        sigma_r_m=noise.sigma_r_m,
        sigma_beta_rad=noise.sigma_beta_rad,
        predicted_xy=None if predicted is None else (predicted[0], predicted[1]),
    )
    return [c.x, c.y], {(0, 0): c.r00, (0, 1): c.r01, (1, 1): c.r11}


def _parts_3d(name: str, plot: PolarPlot, noise: PolarNoise, predicted: list[Vec] | None) -> Parts:
    c = convert_parts_3d(
        name,
        plot.range_m,
        plot.azimuth_rad,
        plot.elevation_rad,
        **noise._asdict(),
        predicted_xyz=None if predicted is None else np.stack(np.broadcast_arrays(*predicted), -1),
    )
    return list(c[:3]), dict(zip(UPPER_3D, c[3:], strict=True))


class Kind(IntEnum):
    """How a method brings a plot into the filter; the compiled kernels branch on these.

    CONVERTED: its conversion's point and covariance, then the position update.
    EKF: the polar measurement itself, linearised at the prediction.
    UKF: the polar measurement itself, through scaled sigma points.
    """

    CONVERTED = 0
    EKF = 1
    UKF = 2


@dataclass(frozen=True)
class Method:
    """One tracking method.

    Attributes:
        name: the name used everywhere (CLI, files, recordings).
        kind: which update it uses (``Kind``).
        dims: the dimensions it exists in (2: (r, β); 3: (r, β, ε)).
        conversion: a converted method's conversion (``core.conversion.registry``); None for
            the polar filters.
        start_conversion: the conversion of its first plot.
        summary: one line for help texts.
    """

    name: str
    kind: Kind
    dims: tuple[int, ...]
    conversion: str | None
    start_conversion: str
    summary: str

    @property
    def about_prediction(self) -> bool:
        """Whether its covariance is taken at the predicted position (``ducm``)."""
        return self.conversion is not None and CONVERSIONS[self.conversion].about_prediction

    def conversions(self) -> tuple[Conversion, Conversion]:
        """(its update's conversion, its start's); a polar filter's update row is its
        start's (the kernels read it for nothing but a uniform table)."""
        start = CONVERSIONS[self.start_conversion]
        return CONVERSIONS[self.conversion] if self.conversion else start, start

    def convert(
        self,
        plot: PolarPlot,
        noise: PolarNoise,
        predicted: list[Vec] | None = None,
        conversion: str | None = None,
    ) -> Parts:
        """Radar-centred converted point (d components) and covariance (upper entries).

        ``predicted``: the predicted position minus the site, needed by ``ducm``.
        ``conversion``: another conversion than the method's own (the start's).
        """
        name = conversion or self.conversion or self.start_conversion
        if plot.dims == 2:
            return _parts_2d(name, plot, noise, predicted)
        return _parts_3d(name, plot, noise, predicted)

    def start(
        self,
        plot: PolarPlot,
        noise: PolarNoise,
        *,
        sigma_v0_mps: float,
        site: ArrayLike | None = None,
    ) -> CVBatch:
        """Tracks started at their first plot (module docstring)."""
        parts = self.convert(plot, noise, conversion=self.start_conversion)
        return start_from_parts(parts, sigma_v0_mps=sigma_v0_mps, site=site)

    def update(
        self,
        pred: CVBatch,
        plot: PolarPlot,
        noise: PolarNoise,
        *,
        site: ArrayLike | None = None,
        out: CVBatch | None = None,
    ) -> CVBatch:
        """The measurement update of the predicted batch ``pred`` with this scan's plots."""
        if self.kind == Kind.EKF:
            return ekf_update(pred, plot.vectors(), site=site, out=out, **noise._asdict())
        if self.kind == Kind.UKF:
            return ukf_update(pred, plot.vectors(), site=site, out=out, **noise._asdict())
        predicted = site_offsets(pred, site) if self.about_prediction else None
        z, R = self.convert(plot, noise, predicted)
        return cv_update_parts(pred, _shifted(z, site), R, out)


def start_from_parts(
    parts: Parts, *, sigma_v0_mps: float, site: ArrayLike | None = None
) -> CVBatch:
    """Tracks started at converted points: position z + site with covariance R, velocity 0
    with std σv0 (``cv_init``)."""
    z, R = parts
    d = len(z)
    zs = np.stack(np.broadcast_arrays(*_shifted(z, site)), axis=-1)
    Rm = np.empty((*zs.shape[:-1], d, d))
    for (i, j), v in R.items():
        Rm[..., i, j] = Rm[..., j, i] = v
    return cv_init(zs, Rm, sigma_v0_mps)


def _shifted(z: list[Vec], site: ArrayLike | None) -> list[Vec]:
    """Radar-centred components z plus the site (unchanged for a radar at the origin)."""
    if site is None:
        return z
    s = np.asarray(site, dtype=np.float64)
    return [z[i] + s[..., i] for i in range(len(z))]


_C = Kind.CONVERTED
METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method("naive", _C, (2, 3), "naive", "naive", "converted point, linearised cov."),
        Method("seed", _C, (2, 3), "seed", "seed", "Prosov's eq. 10 correction, eq. 11"),
        Method("cmkf_d", _C, (2, 3), "cmkf_d", "cmkf_d", "Lerro & Bar-Shalom debiased"),
        Method("ucm", _C, (2, 3), "ucm", "ucm", "Mo et al. unbiased conversion"),
        Method("ducm", _C, (2, 3), "ducm", "ucm", "Bordonaro et al. decorrelated ucm"),
        Method("ekf", Kind.EKF, (2, 3), None, "naive", "polar EKF"),
        Method("ukf", Kind.UKF, (2, 3), None, "naive", "polar UKF"),
    )
}
#: Every method, in display order.
ALL_METHODS: tuple[str, ...] = tuple(METHODS)
#: The methods that filter the polar measurement directly.
POLAR_METHODS: tuple[str, ...] = tuple(n for n, m in METHODS.items() if m.kind != _C)
#: The methods that exist in 3D.
METHODS_3D: tuple[str, ...] = tuple(n for n, m in METHODS.items() if 3 in m.dims)


def method_names(dims: int | None = None) -> tuple[str, ...]:
    """The registered methods now (of dimension ``dims``, or all), in display order: what
    the validators accept. ``ALL_METHODS`` and ``METHODS_3D`` are the same at import."""
    return tuple(n for n, m in METHODS.items() if dims is None or dims in m.dims)


def method_named(name: str) -> Method:
    """The registered method ``name`` (ValueError naming the choices otherwise)."""
    try:
        return METHODS[name]
    except KeyError:
        choices = ", ".join(method_names())
        raise ValueError(f"method must be one of {choices} (got {name!r})") from None


#: The columns of ``method_plan``: a method's ``Kind``, its update's ``Covariance``, its
#: start's.
PLAN_KIND, PLAN_COVARIANCE, PLAN_START = 0, 1, 2


def method_plan(names: Sequence[str]) -> NDArray[np.int64]:
    """What the compiled kernels branch on, a row per method (M, 3): its kind, the covariance
    form of its update's conversion and of its start's (``PLAN_*``)."""
    rows = []
    for name in names:
        method = method_named(name)
        update, start = method.conversions()
        rows.append((int(method.kind), int(update.covariance), int(start.covariance)))
    return np.array(rows, dtype=np.int64).reshape(len(rows), 3)


def _radar_columns(*sigmas: ArrayLike) -> list[NDArray[np.float64]]:
    """Noise std given per radar, each (R,) or a number, as (R,) arrays of one length."""
    return np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in sigmas))


def _rows(values: tuple) -> NDArray[np.float64]:
    """Scalars of a conversion, each (R,) or a number, as one row per radar (R, k)."""
    return np.stack(np.broadcast_arrays(*values), axis=-1)


def conversion_table(
    names: Sequence[str], sigma_r_m: ArrayLike, sigma_beta_rad: ArrayLike
) -> NDArray[np.float64]:
    """The 2D conversions' scalars of each radar (σr, σβ: (R,) or scalars), per method, for
    its update then its start: (R, M, 2, 8), each row ``Conversion.coefficients`` (κ first).

    The compiled kernels take these in place of a conversion's name: formed here once per
    radar, they are the only place a conversion's scale enters compiled code."""
    sr, sb = _radar_columns(sigma_r_m, sigma_beta_rad)
    s, sr2 = sb * sb, sr * sr
    out = np.empty((sr.shape[0], len(names), 2, 8))
    for j, name in enumerate(names):
        for k, conversion in enumerate(method_named(name).conversions()):
            out[:, j, k, :] = _rows(conversion.coefficients(s, sr2))
    return out


def update_coefficients(
    name: str, sigma_r_m: ArrayLike, sigma_beta_rad: ArrayLike
) -> NDArray[np.float64]:
    """``conversion_table``'s update rows of one method alone, (R, 8): for callers that
    convert plot by plot with each plot's noise (the gates), which never start a track."""
    sr, sb = _radar_columns(sigma_r_m, sigma_beta_rad)
    update, _ = method_named(name).conversions()
    return _rows(update.coefficients(sb * sb, sr * sr))


def scale_table(
    names: Sequence[str], sigma_beta_rad: ArrayLike, sigma_elevation_rad: ArrayLike
) -> NDArray[np.float64]:
    """The 3D conversions' scales of each radar (σβ, σε: (R,) or scalars), per method, for its
    update then its start: (R, M, 2, 2), each row (κxy, κz) (``Conversion.scales``)."""
    sb, se = _radar_columns(sigma_beta_rad, sigma_elevation_rad)
    out = np.empty((sb.shape[0], len(names), 2, 2))
    for j, name in enumerate(names):
        for k, conversion in enumerate(method_named(name).conversions()):
            out[:, j, k, :] = _rows(conversion.scales(sb, se))
    return out


def stack_parts(parts: Sequence[Parts]) -> Parts:
    """Several methods' converted parts, each (...), stacked along a new leading axis (k, ...).

    One method's parts become views with a leading axis of 1 (no copy: the Monte Carlo's
    single-method loop converts every scan)."""
    d = len(parts[0][0])
    if len(parts) == 1:
        z1, R1 = parts[0]
        keys = list(R1)
        arrays = np.broadcast_arrays(*z1, *(R1[k] for k in keys))
        return [a[None] for a in arrays[:d]], {
            k: a[None] for k, a in zip(keys, arrays[d:], strict=True)
        }
    z = [np.stack(np.broadcast_arrays(*(p[0][i] for p in parts))) for i in range(d)]
    R = {key: np.stack(np.broadcast_arrays(*(p[1][key] for p in parts))) for key in parts[0][1]}
    return z, R


def method_groups(names: Sequence[str], max_group: int | None = None) -> list[tuple[str, ...]]:
    """Split methods into groups that share one batch: the converted ones together (one
    position update for all of them; at most ``max_group`` per group), each polar method alone.

    Batching methods pays where numpy's per-call cost dominates (a few hundred tracks); with
    10⁴ tracks per method a group's working set would leave the cache, so callers with large
    batches pass a small ``max_group``.
    """
    converted = [n for n in names if METHODS[n].kind == _C]
    size = max(1, len(converted) if max_group is None else max_group)
    groups = [tuple(converted[i : i + size]) for i in range(0, len(converted), size)]
    return groups + [(n,) for n in names if METHODS[n].kind != _C]


class MethodGroup:
    """Methods that share an update kind, filtered as one batch with a leading method axis.

    For converted methods the batch is (k, ...): row i is method i, and the prediction and the
    position update are one set of operations for all of them (only the conversions are per
    method); rows do not interact. A polar group has one method and no extra axis.

    Args:
        names: one polar method, or any number of converted ones (``method_groups``).
    """

    def __init__(self, names: Sequence[str]):
        self.names = tuple(names)
        self.kinds = [method_named(n) for n in self.names]
        self.converted = all(k.kind == _C for k in self.kinds)
        if not self.names or (not self.converted and len(self.names) > 1):
            raise ValueError("a method group is one polar method or only converted methods")

    @staticmethod
    def _predicted(pred: CVBatch, row: int, site: ArrayLike | None) -> list[Vec]:
        """Row ``row``'s predicted position minus the site."""
        return site_offsets(CVBatch(pred.x[row], pred.P[row]), site)

    def start_parts(self, plot: PolarPlot, noise: PolarNoise) -> Parts:
        """Every method's start conversion, stacked (k, ...) (converted groups only)."""
        return stack_parts(
            [k.convert(plot, noise, conversion=k.start_conversion) for k in self.kinds]
        )

    def start(
        self,
        plot: PolarPlot,
        noise: PolarNoise,
        *,
        sigma_v0_mps: float,
        site: ArrayLike | None = None,
        parts: Parts | None = None,
    ) -> CVBatch:
        """The group's tracks started at their first plot; ``parts``: ``start_parts`` if
        the caller has them already."""
        if not self.converted:
            return self.kinds[0].start(plot, noise, sigma_v0_mps=sigma_v0_mps, site=site)
        parts = parts if parts is not None else self.start_parts(plot, noise)
        return start_from_parts(parts, sigma_v0_mps=sigma_v0_mps, site=site)

    def update(
        self,
        pred: CVBatch,
        plot: PolarPlot,
        noise: PolarNoise,
        *,
        site: ArrayLike | None = None,
        out: CVBatch | None = None,
        parts: Parts | None = None,
    ) -> CVBatch:
        """The update of the group's predicted batch with this scan's plots.

        ``parts``: the methods' conversions of these plots, stacked (k, ...), if the caller
        has them (``start_parts``: a method converted about the prediction is redone here).
        """
        if not self.converted:
            return self.kinds[0].update(pred, plot, noise, site=site, out=out)
        nu, R = self.measurement(pred, plot, noise, site=site, parts=parts)
        return innovation_update(pred, nu, R, out)

    def measurement(
        self,
        pred: CVBatch,
        plot: PolarPlot,
        noise: PolarNoise,
        *,
        site: ArrayLike | None = None,
        parts: Parts | None = None,
    ) -> tuple[Sequence[Vec], dict[tuple[int, int], Vec]]:
        """This scan's measurement as a position measurement of the predicted batch: the
        innovation ν (d components, m) and its noise R (upper entries, m²), each (...).

        Converted methods: ν = z + site − H x⁻ with the conversion's R (what their update
        uses). ``ekf``: its ν' = J ν and R' = J R Jᵀ at the prediction (the EKF update is the
        position update of these, ``core.filters.polar_ekf``). ``ukf``: the same linearised
        measurement; its own update uses sigma points, so for the UKF these are the EKF's
        statistics of the same plot (``core.filters.innovation`` uses them for the NIS and
        the IMM likelihood).
        """
        if not self.converted:
            return ekf_pseudo_measurement(pred, plot.vectors(), site=site, **noise._asdict())
        if parts is None:
            z, R = stack_parts(
                [
                    k.convert(plot, noise, self._predicted(pred, i, site))
                    if k.about_prediction
                    else k.convert(plot, noise)
                    for i, k in enumerate(self.kinds)
                ]
            )
        else:
            z, R = parts
            if any(k.about_prediction for k in self.kinds):
                z, R = [v.copy() for v in z], {key: v.copy() for key, v in R.items()}
                for i, kind in enumerate(self.kinds):
                    if kind.about_prediction:  # ducm: its covariance at this row's prediction
                        zi, Ri = kind.convert(plot, noise, self._predicted(pred, i, site))
                        for a in range(len(z)):
                            z[a][i] = _fitted(zi[a], z[a][i])
                        for key, v in Ri.items():
                            R[key][i] = _fitted(v, R[key][i])
        zs = _shifted(z, site)
        pos = position_index(pred.dims)
        return [zs[a] - pred.x[..., p] for a, p in enumerate(pos)], R


def _fitted(value: ArrayLike, target: ArrayLike) -> ArrayLike:
    """``value`` shaped to go into ``target``'s place: reshaped when the sizes agree (a (1,)
    conversion into one row), else broadcast (a plot's (M, 1) point over (M, r) models)."""
    shape = np.shape(target)
    v = np.asarray(value)
    if v.size == np.prod(shape, dtype=int):
        return np.reshape(v, shape)
    while v.ndim > len(shape) and v.shape[0] == 1:  # a single track's leading axis of 1
        v = v[0]
    return np.broadcast_to(v, shape)
