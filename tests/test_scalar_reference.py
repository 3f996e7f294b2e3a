"""The bench's compiled scalar reference (``viz_app.bench.scalar_reference``) computes what the
engine computes, so ``radarviz bench``'s engine / reference ratio compares like with like.

The reference is written independently (the textbook Joseph form (I − KH) P (I − KH)ᵀ + KRKᵀ,
the EKF with the polar Jacobian, the UKF with P − K S Kᵀ, fastmath) and the engine evaluates
the same equations in another order, so the two agree to rounding: measured ~5e-12 of the
states' σ and ~1e-14 of P's largest entry after 60 scans. The bound 1e-9 leaves that
rounding three orders of magnitude and is still far below any error of substance: a wrong
coefficient or sign moves the states by whole standard deviations within a few scans.
"""

from __future__ import annotations

import numpy as np
import pytest

from radarviz.core.experiments.prosov import TrackingConfig
from radarviz.core.filters.compiled import FilterSettings, filter_history
from radarviz.viz_app.bench.per_method import BENCH_SIGMA_VR_MPS, bench_measurements
from radarviz.viz_app.bench.scalar_reference import REFERENCE_METHODS, run_reference

TOL = 1e-9


@pytest.mark.parametrize("method", REFERENCE_METHODS)
@pytest.mark.parametrize(("sigma_beta_deg", "sigma_a_mps2"), [(1.0, 0.0), (2.0, 0.7)])
def test_reference_ends_where_the_engine_ends(
    method: str, sigma_beta_deg: float, sigma_a_mps2: float
) -> None:
    cfg = TrackingConfig(sigma_beta_deg=sigma_beta_deg, sigma_a_mps2=sigma_a_mps2, seed=6)
    r, b, vr = bench_measurements(cfg, 64)
    s = FilterSettings(
        cfg.sigma_r_m,
        cfg.sigma_beta_rad,
        cfg.target.period_s,
        sigma_a_mps2,
        cfg.sigma_v0_mps,
        sigma_vr_mps=BENCH_SIGMA_VR_MPS,
    )
    doppler = method.endswith("+doppler")
    x, P = filter_history(
        method.removesuffix("+doppler"), r, b, s, radial_velocity_mps=vr if doppler else None
    )
    x_ref, P_ref = run_reference(
        method,
        r,
        b,
        sigma_r_m=s.sigma_r_m,
        sigma_beta_rad=s.sigma_beta_rad,
        period_s=s.period_s,
        sigma_a_mps2=sigma_a_mps2,
        sigma_v0_mps=s.sigma_v0_mps,
        radial_velocity_mps=vr,
        sigma_vr_mps=s.sigma_vr_mps,
        ukf_weights=s.ukf.weights(4),
    )
    sigma = np.sqrt(np.diagonal(P[-1], axis1=-2, axis2=-1))
    assert np.all(np.isfinite(x_ref))
    assert np.max(np.abs(x_ref - x[-1]) / sigma) < TOL
    scale = np.abs(P[-1]).max(axis=(-1, -2), keepdims=True)
    assert np.max(np.abs(P_ref - P[-1]) / scale) < TOL
    # The filter has moved far from its start: agreement is not the start's agreement.
    assert np.all(np.sqrt(P[-1][:, 1, 1]) < 0.1 * cfg.sigma_v0_mps)
