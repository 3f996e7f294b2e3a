"""The reference filters (``viz_app.bench.reference``: the textbook matrix form, compiled, one
track at a time) end where the engine ends, for every method the bench times.

The reference is written from the equations (H, S = H P Hᵀ + R, K = P Hᵀ S⁻¹, the Joseph form
as matrix products, the polar Jacobian, Van der Merwe's points from a Cholesky factor, the
papers' conversions) and shares no code with the engine, which evaluates the same filter in
another order (a change of variables for the EKF, packed loops, its own 1-ulp sine, cosine
and arc tangent, fused multiply-adds), while the reference runs with fastmath. So the two
agree to rounding, not bit for bit.

Tolerances. Measured over the scenarios below (64 tracks × 60 scans each), the largest
difference of a final state is 6.2e-11 of its σ (the UKF at σβ = 1°; every other method
≤ 4e-12) and of a final covariance 3.7e-12 of P's largest entry (the UKF; the others
≤ 4e-15). The UKF's is the largest because P⁺ = P⁻ − K S Kᵀ subtracts nearly equal matrices
when a plot is much more precise than the prediction, which turns rounding of P⁻'s size into
relative error of the smaller P⁺. ``TOL_STATE`` = 1e-9 leaves that worst case a margin of 16
(another machine's vector width, another compiler's contraction into fused multiply-adds),
``TOL_COV`` = 1e-10 a margin of 27. Both stay far below a difference of substance: a relative
change of 1e-6 in σβ, σr, σa or σVr moves the final states by 5e-7 to 3e-6 of their σ
(``test_a_perturbed_parameter_is_detected`` checks every such change fails the comparison).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from radarviz.core.conversion.planar import METHODS_2D, convert
from radarviz.core.experiments.prosov import TrackingConfig
from radarviz.core.filters.compiled import FilterSettings, filter_history
from radarviz.core.scenarios.planar import ConstantVelocityTarget2D
from radarviz.viz_app.bench import reference
from radarviz.viz_app.bench.per_method import BENCH_SIGMA_VR_MPS, bench_measurements
from radarviz.viz_app.bench.reference import REFERENCE_METHODS, run_reference

TOL_STATE = 1e-9
TOL_COV = 1e-10

#: The bench's target at σβ = 1° without process noise and at 2° with σa = 0.7 m/s², and a
#: target crossing the negative x axis (every track's bearing wraps from −π to π) with
#: σa = 2 m/s² and a 2 s period.
SCENARIOS: dict[str, TrackingConfig] = {
    "bench 1°": TrackingConfig(sigma_beta_deg=1.0, sigma_a_mps2=0.0, seed=6),
    "bench 2°, σa": TrackingConfig(sigma_beta_deg=2.0, sigma_a_mps2=0.7, seed=6),
    "bearing wraps": TrackingConfig(
        sigma_beta_deg=1.5,
        sigma_a_mps2=2.0,
        seed=9,
        target=ConstantVelocityTarget2D(
            x0_m=-60000.0, y0_m=-9000.0, vx_mps=-50.0, vy_mps=300.0, period_s=2.0, steps=60
        ),
    ),
}


@functools.cache
def _case(scenario: str, method: str):
    """The scenario's measurements and settings, and the engine's final x (m, 4), P (m, 4, 4)."""
    cfg = SCENARIOS[scenario]
    r, b, vr = bench_measurements(cfg, 64)
    s = FilterSettings(
        cfg.sigma_r_m,
        cfg.sigma_beta_rad,
        cfg.target.period_s,
        cfg.sigma_a_mps2,
        cfg.sigma_v0_mps,
        sigma_vr_mps=BENCH_SIGMA_VR_MPS,
    )
    doppler = method == "ekf+doppler"
    x, P = filter_history(
        method.removesuffix("+doppler"), r, b, s, radial_velocity_mps=vr if doppler else None
    )
    return r, b, vr, s, x[-1], P[-1]


def _reference(method: str, r, b, vr, s: FilterSettings, **change: float):
    kw = {
        "sigma_r_m": s.sigma_r_m,
        "sigma_beta_rad": s.sigma_beta_rad,
        "period_s": s.period_s,
        "sigma_a_mps2": s.sigma_a_mps2,
        "sigma_v0_mps": s.sigma_v0_mps,
        "sigma_vr_mps": s.sigma_vr_mps,
    }
    kw.update(change)
    return run_reference(method, r, b, radial_velocity_mps=vr, ukf_weights=s.ukf.weights(4), **kw)


def _differences(x_ref, P_ref, x, P) -> tuple[float, float]:
    """The largest state difference in units of the engine's σ, and the largest covariance
    difference relative to each track's largest entry of P."""
    sigma = np.sqrt(np.diagonal(P, axis1=-2, axis2=-1))
    scale = np.abs(P).max(axis=(-1, -2), keepdims=True)
    return float(np.max(np.abs(x_ref - x) / sigma)), float(np.max(np.abs(P_ref - P) / scale))


@pytest.mark.parametrize("method", REFERENCE_METHODS)
@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_reference_ends_where_the_engine_ends(scenario: str, method: str) -> None:
    r, b, vr, s, x, P = _case(scenario, method)
    x_ref, P_ref = _reference(method, r, b, vr, s)
    assert np.all(np.isfinite(x_ref)) and np.all(np.isfinite(P_ref))
    d_state, d_cov = _differences(x_ref, P_ref, x, P)
    assert d_state < TOL_STATE, d_state
    assert d_cov < TOL_COV, d_cov
    # The filter has moved far from its start: agreement is not the start's agreement.
    assert np.all(np.sqrt(P[:, 1, 1]) < 0.1 * s.sigma_v0_mps)


@pytest.mark.parametrize(
    ("method", "name"),
    [(m, n) for m in REFERENCE_METHODS for n in ("sigma_beta_rad", "sigma_r_m", "sigma_a_mps2")]
    + [("ekf+doppler", "sigma_vr_mps")],
)
def test_a_perturbed_parameter_is_detected(method: str, name: str) -> None:
    """Negative control: the reference given one σ changed by a relative 1e-6 no longer ends
    where the engine ends (measured: 5e-7 to 3e-6 of σ, ≥ 480 × ``TOL_STATE``)."""
    r, b, vr, s, x, P = _case("bench 2°, σa", method)
    value = {"sigma_vr_mps": s.sigma_vr_mps, "sigma_a_mps2": s.sigma_a_mps2}.get(name)
    value = getattr(s, name) if value is None else value
    x_ref, P_ref = _reference(method, r, b, vr, s, **{name: value * (1.0 + 1e-6)})
    d_state, d_cov = _differences(x_ref, P_ref, x, P)
    assert d_state > TOL_STATE or d_cov > TOL_COV, (d_state, d_cov)


def test_the_conversions_are_the_papers() -> None:
    """Each conversion of the reference (written from the papers' formulas) gives the point and
    covariance of ``core.conversion.planar`` (written separately) to 1e-13 of r̂ and of R's
    largest entry: the same closed forms in another order (measured at most 7.4e-16 over
    2 000 draws, a few ulp; 1e-13 leaves a margin of 100). ``ducm`` about a predicted
    position within a few σ of the plot."""
    rng = np.random.default_rng(3)
    z, R = np.empty(2), np.empty((2, 2))
    for _ in range(40):
        r = float(rng.uniform(1e3, 3e5))
        b = float(rng.uniform(-math.pi, math.pi))
        sigma_r_m, sigma_beta_rad = (
            float(rng.uniform(5.0, 300.0)),
            math.radians(rng.uniform(0.1, 3)),
        )
        var_r, s = sigma_r_m**2, sigma_beta_rad**2
        px, py = r * math.cos(b) + rng.normal(0, 300), r * math.sin(b) + rng.normal(0, 300)
        averaged = reference.averaged_constants(var_r, s)
        unbiased = reference.unbiased_constants(var_r, s)
        for method in METHODS_2D:
            code = reference.CONVERSIONS[method]
            reference.convert(code, r, b, var_r, s, averaged, unbiased, px, py, z, R)
            want = convert(
                method,
                r,
                b,
                sigma_r_m=sigma_r_m,
                sigma_beta_rad=sigma_beta_rad,
                predicted_xy=np.array([px, py]),
            )
            np.testing.assert_allclose(z, want.z, rtol=0, atol=1e-13 * r, err_msg=method)
            scale = np.abs(want.R).max()
            np.testing.assert_allclose(R, want.R, rtol=0, atol=1e-13 * scale, err_msg=method)
