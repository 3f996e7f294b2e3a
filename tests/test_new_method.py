"""A method added through the registry alone (docs/architecture.md, "Adding a method").

The test does the checklist's steps at run time: a scale κ(s) = 1 − s/4 of its own (step 1),
its ``Conversion`` with the averaged covariance (step 2) and its ``Method`` (step 3; step 4,
the colour, only changes a picture). Nothing else is touched: the numpy functions, the numpy
engine, the Monte Carlo kernel, the tracker kernels (2D and 3D) and the array-API path then
run it, and agree with one another to the tolerances their own tests hold them to. The
kernels take the method as data (``method_plan``, ``conversion_table``, ``scale_table``), so
the Monte Carlo kernel runs it on the machine code it already has (no new specialisation).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest
from test_compiled import assert_close, numpy_history
from test_targets import close

from radarviz.core.conversion import planar, spatial
from radarviz.core.conversion.elementwise import Covariance
from radarviz.core.conversion.registry import CONVERSIONS, Conversion
from radarviz.core.experiments.prosov import TrackingConfig, block_measurements
from radarviz.core.filters.compiled import FilterSettings, filter_history
from radarviz.core.filters.methods import METHODS, Kind, Method, method_names
from radarviz.core.tracking.stream import StreamOptions
from radarviz.core.tracking.targets import TargetTracker
from radarviz.viz_app.io.plots import fusion_plots, prosov_plots

NEW = "quarter"


def quarter_scale(s):
    """κ = 1 − s/4: half of the seed's correction (a method no paper has; only a test's)."""
    return 1.0 - s / 4.0


@pytest.fixture
def registered(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The new method in the two registries for one test."""
    conversion = Conversion(NEW, quarter_scale, Covariance.AVERAGED)
    monkeypatch.setitem(CONVERSIONS, NEW, conversion)
    monkeypatch.setitem(METHODS, NEW, Method(NEW, Kind.CONVERTED, (2, 3), NEW, NEW, "a test's"))
    yield


def test_its_point_is_its_scale_and_its_covariance_its_form(registered: None) -> None:
    r, b, el = np.array([2e3, 40e3, 150e3]), np.array([0.3, -2.0, 3.1]), np.array([0.1, 0.4, 0.0])
    sr, sb, se = 25.0, np.deg2rad(2.0), np.deg2rad(1.0)
    new = planar.convert_parts(NEW, r, b, sigma_r_m=sr, sigma_beta_rad=sb)
    seed = planar.convert_parts("seed", r, b, sigma_r_m=sr, sigma_beta_rad=sb)
    kappa = 1.0 - sb * sb / 4.0
    np.testing.assert_allclose(new.x, kappa * r * np.cos(b), rtol=1e-15)
    np.testing.assert_allclose(new.y, kappa * r * np.sin(b), rtol=1e-15)
    for a, c in ((new.r00, seed.r00), (new.r01, seed.r01), (new.r11, seed.r11)):
        np.testing.assert_array_equal(a, c)  # the same covariance form
    noise = {"sigma_r_m": sr, "sigma_beta_rad": sb, "sigma_elevation_rad": se}
    new3 = spatial.convert_parts_3d(NEW, r, b, el, **noise)
    seed3 = spatial.convert_parts_3d("seed", r, b, el, **noise)
    k_xy, k_z = 1.0 - (sb * sb + se * se) / 4.0, 1.0 - se * se / 4.0
    u = np.stack([np.cos(el) * np.cos(b), np.cos(el) * np.sin(b), np.sin(el)])
    np.testing.assert_allclose(new3[:3], r * u * np.array([[k_xy], [k_xy], [k_z]]), rtol=1e-15)
    for a, c in zip(new3[3:], seed3[3:], strict=True):
        np.testing.assert_array_equal(a, c)
    assert NEW in method_names(2) and NEW in method_names(3)


def test_the_monte_carlo_kernel_and_the_array_api_path_run_it(registered: None) -> None:
    from radarviz.core.filters.kernels_2d import filter_scans_2d

    cfg = TrackingConfig(sigma_beta_deg=2.0, sigma_a_mps2=0.7, seed=5)
    r_hat, beta_hat = block_measurements(cfg, 0, 64, cfg.target.truth())
    s = FilterSettings(cfg.sigma_r_m, cfg.sigma_beta_rad, cfg.target.period_s, 0.7, 500.0)
    x_seed, _ = filter_history("seed", r_hat, beta_hat, s)
    compiled_before = len(filter_scans_2d.signatures)
    x, P = filter_history(NEW, r_hat, beta_hat, s)
    assert len(filter_scans_2d.signatures) == compiled_before  # the same machine code
    x_ref, P_ref = numpy_history(NEW, r_hat, beta_hat, s)
    assert_close(x, P, x_ref, P_ref)
    # Its κ is not seed's: the tracks differ by far more than the engines' rounding.
    sigma = np.sqrt(np.diagonal(P_ref, axis1=-2, axis2=-1))
    assert np.max(np.abs(x - x_seed) / sigma) > 1e-3

    xps = pytest.importorskip("array_api_strict")
    from radarviz.core.filters.array_api import filter_history_xp

    xa, Pa = filter_history_xp(NEW, xps.asarray(r_hat), xps.asarray(beta_hat), s)
    assert_close(np.asarray(xa), np.asarray(Pa), x_ref, P_ref)


@pytest.mark.parametrize("three_d", [False, True], ids=["2d", "3d"])
@pytest.mark.parametrize("imm", [False, True], ids=["cv", "imm"])
def test_the_tracker_kernels_run_it(registered: None, three_d: bool, imm: bool) -> None:
    """The compiled tracker (cv and IMM) against the numpy engine, on two interleaved
    targets seen by radars of different noise."""
    plots = []
    for k in range(2):
        own, _ = fusion_plots(seed=k + 1, steps=10) if three_d else prosov_plots(seed=k + 1)
        for j, p in enumerate(own):
            g = (j + k) % 2
            plots.append(
                replace(
                    p,
                    time_s=p.time_s + 0.37 * k,
                    target=f"T{k}",
                    sigma_r_m=p.sigma_r_m * (1.0 + 0.5 * g),
                    sigma_beta_rad=p.sigma_beta_rad * (1.0 + 0.25 * g),
                )
            )
    plots.sort(key=lambda p: p.time_s)
    methods = (NEW, "seed")
    model = {"model": "imm"} if imm else {}
    rows = {}
    for engine in ("numpy", "compiled"):
        options = StreamOptions(sigma_a_mps2=1.0, engine=engine, **model)
        tracker = TargetTracker(methods, three_d, options)
        assert tracker.engine == engine
        rows[engine] = tracker.add_block(plots)
    for a, b in zip(rows["numpy"], rows["compiled"], strict=True):
        assert [m for m, _, _ in a] == list(methods)
        for (m, xa, Pa), (_, xb, Pb) in zip(a, b, strict=True):
            assert close(xa, xb), m
            assert close(Pa, Pb), m
