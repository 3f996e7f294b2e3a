"""Every column of a result table, and every number of a result document, is named with its
unit: the quantity's name, then ``_m``, ``_mps``, ``_rad``, ``_deg``, ``_s`` … (``UNITS``).
Dimensionless statistics are the exception the documentation names once: a NEES or NIS
(``nees_…``, ``nis_…``), and the counts, labels and ratios of ``DIMENSIONLESS``.

The names are checked where the tables are built (the sweep's Parquet columns, the track
file's header, ``radarviz.to_columns`` of each result) and in the JSON documents of
``reproduce prosov``, ``gorshkov``, ``velocity``, ``association`` and ``doppler``, whose keys
the command line prints."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import replace
from typing import Any

import pytest

import radarviz
from radarviz.core.experiments.association import AssociationConfig, run_association
from radarviz.core.experiments.doppler_start import compare_doppler_updates
from radarviz.viz_app.io.plots import TRACK_COLUMNS, track_columns
from radarviz.viz_app.reports.association import association_document
from radarviz.viz_app.reports.doppler import doppler_document
from radarviz.viz_app.reports.gorshkov import gorshkov_document
from radarviz.viz_app.reports.prosov import prosov_document
from radarviz.viz_app.reports.velocity import velocity_document
from radarviz.viz_app.sweep.output import table_columns

#: Unit suffixes: metres, m/s, m/s², m², m²/s, m²/s², radians, degrees, °/s, seconds,
#: kilometres, per cent, and m^p (the GOSPA parts, p its order).
UNITS = (
    "_m",
    "_mps",
    "_mps2",
    "_m2",
    "_m2ps",
    "_m2ps2",
    "_rad",
    "_deg",
    "_degps",
    "_s",
    "_km",
    "_percent",
    "_m_p",
)
#: Statistics that have no unit: NEES and NIS (quadratic forms in σ units), correlations and
#: ratios of like quantities.
DIMENSIONLESS_PREFIXES = ("nees_", "nis_", "corr_", "ratio_")
#: Labels, indices, counts and dimensionless numbers.
DIMENSIONLESS = frozenset(
    {
        "method",
        "variant",
        "radar",
        "target",
        "status",
        "radar_track_number",
        "plot",
        "point",
        "scan",
        "k",
        "n",
        "runs",
        "seed",
        "trials",
        "dims",
        "condition_number",
        "geometry_metric",
        "c0",
        "level",
        "groups",
        "scans",
        "peak_scan",
        "k_within_band",
        "start_scans",
        "m",  # the velocity paper's geometry metric
        "m_warn",
        "sweep_direction",  # a unit vector
        "sweep_trials",
        "targets",
        "tracks",
        "false_tracks",
        "swaps",
        "clutter_per_scan",
        "detection_prob",
        "gate_probability",
        "gate",  # a χ² threshold
        "confirm_n",
        "delete_misses",
        "order",  # of the GOSPA distance
    }
)
#: Keys of a band or a summary, whose unit is that of the key holding them.
BAND_KEYS = frozenset({"lo", "hi", "mean", "delta", "value", "ci95"})


def without_unit(names: Iterable[str]) -> list[str]:
    """The names that carry no unit suffix and are not dimensionless."""
    return [
        n
        for n in names
        if not n.endswith(UNITS)
        and not n.startswith(DIMENSIONLESS_PREFIXES)
        and n not in DIMENSIONLESS
    ]


def _is_number(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _numeric(v: object) -> bool:
    """A number, a list of numbers (or nulls), or a list of such lists."""
    if _is_number(v):
        return True
    return isinstance(v, list) and bool(v) and all(x is None or _numeric(x) for x in v)


def number_keys(doc: Any, parent: str = "") -> Iterator[str]:
    """The key naming each number of a JSON document: the key itself, or the key above it for
    the entries of a band (``lo``, ``hi``, ``ci95`` …) and for the labelled entries of a key
    that has its unit already (``delta_x_percent: {"rmse": …}``, ``gain_percent: {"r_m": …}``)."""
    if isinstance(doc, dict):
        for key, value in doc.items():
            labelled = bool(parent) and not without_unit([parent])
            named = parent if key in BAND_KEYS or labelled else key
            if _numeric(value):
                yield named
            else:
                yield from number_keys(value, named)
    elif isinstance(doc, list):
        for item in doc:
            yield from number_keys(item, parent)


def test_the_check_finds_a_name_without_unit() -> None:
    assert without_unit(["rmse_x", "bias_range", "sigma_mc"]) == [
        "rmse_x",
        "bias_range",
        "sigma_mc",
    ]
    assert without_unit(["rmse_x_m", "nees_pos", "scan", "p_xvy_m2ps", "gain_mc_r_percent"]) == []
    doc = {"methods": {"ucm": {"rmse_x": [1.0, None], "ci95": {"rmse_x": {"lo": [0.5]}}}}}
    assert sorted(set(number_keys(doc))) == ["rmse_x"]
    assert list(number_keys({"gain_percent": {"r": [1.0]}, "sigma": {"r": [2.0]}})) == [
        "gain_percent",
        "r",
    ]


@pytest.mark.parametrize("dims", [2, 3])
def test_sweep_columns(dims: int) -> None:
    assert without_unit(table_columns(dims)) == []


def test_track_file_columns() -> None:
    assert without_unit(TRACK_COLUMNS) == []
    assert without_unit(track_columns(True, status=True, radar_tracks=True)) == []


@pytest.fixture(scope="module")
def prosov() -> list[Any]:
    return radarviz.run_prosov([1.0], runs=64, seed=1, steps=5, methods=("naive", "seed", "ucm"))


@pytest.fixture(scope="module")
def gorshkov() -> radarviz.GorshkovRun:
    return radarviz.run_gorshkov(["RLS3"], trials=64, seed=1, k_max=4, tracking_runs=64)


def test_api_tables(prosov: list[Any], gorshkov: radarviz.GorshkovRun) -> None:
    plots, _ = radarviz.simulate("fusion", steps=4)
    velocity = radarviz.estimate_velocity(
        [(0.0, 0.0, 0.0), (80e3, 0.0, 0.0), (40e3, 70e3, 0.0)],
        [100.0, -50.0, 20.0],
        [0.6, 2.4, -1.7],
        [0.2, 0.2, 0.2],
        sigma_vr_mps=1.0,
        sigma_beta_rad=0.01,
        sigma_elevation_rad=0.01,
    )
    for result in (prosov, gorshkov, radarviz.track(plots), velocity):
        assert without_unit(radarviz.to_columns(result)) == [], type(result).__name__


def test_reproduce_documents(prosov: list[Any], gorshkov: radarviz.GorshkovRun) -> None:
    config = AssociationConfig(runs=2, methods=("ucm",))
    association = replace(config, scene=replace(config.scene, scans=8))
    for doc in (
        prosov_document(prosov),
        gorshkov_document(gorshkov.fits, gorshkov.tracking),
        velocity_document(radarviz.run_velocity(trials=64)),
        association_document(run_association(association)),
        doppler_document(compare_doppler_updates(("RLS3",), sigma_beta_deg=1.0, runs=64, seed=1)),
    ):
        assert sorted(set(without_unit(number_keys(doc)))) == [], doc["experiment"]
