"""The array-API path (the GPU path) against the numpy engine, run under ``array_api_strict``:
every method, with and without the Doppler update, to 1e-9 of the states' own σ (the same
tolerance as the compiled kernel's; measured ~1e-12). ``array_api_strict`` refuses anything
outside the standard, so passing here means CuPy, PyTorch or JAX can run it."""

from __future__ import annotations

import numpy as np
import pytest

from radarviz.core.experiments.prosov import TrackingConfig, block_measurements
from radarviz.core.filters.array_api import filter_history_xp
from radarviz.core.filters.compiled import COMPILED_METHODS, FilterSettings
from radarviz.core.filters.doppler import doppler_update
from radarviz.core.filters.methods import METHODS, PolarNoise, PolarPlot
from radarviz.core.filters.predict import cv_predict

xps = pytest.importorskip("array_api_strict")

TOL = 1e-9


def numpy_history(method, r_hat, beta_hat, s, vr_hat=None):
    m = METHODS[method]
    noise = PolarNoise(s.sigma_r_m, s.sigma_beta_rad)
    st = m.start(PolarPlot(r_hat[:, 0], beta_hat[:, 0]), noise, sigma_v0_mps=s.sigma_v0_mps)
    xs, Ps = [st.x.copy()], [st.P.copy()]
    for n in range(1, r_hat.shape[1]):
        st = m.update(
            cv_predict(st, s.period_s, s.sigma_a_mps2),
            PolarPlot(r_hat[:, n], beta_hat[:, n]),
            noise,
        )
        if vr_hat is not None:
            st = doppler_update(
                st,
                vr_hat[:, n],
                beta_hat[:, n],
                sigma_vr_mps=s.sigma_vr_mps,
                sigma_beta_rad=s.sigma_beta_rad,
            )
        xs.append(st.x.copy())
        Ps.append(st.P.copy())
    return np.array(xs), np.array(Ps)


@pytest.mark.parametrize("doppler", [False, True])
@pytest.mark.parametrize("method", COMPILED_METHODS)
def test_array_api_path_matches_numpy_engine(method: str, doppler: bool) -> None:
    cfg = TrackingConfig(sigma_beta_deg=2.0, seed=6)
    truth = cfg.target.truth()
    r_hat, beta_hat = block_measurements(cfg, 0, 40, truth)
    rng = np.random.default_rng(1)
    vr_hat = 200.0 + 2.0 * rng.standard_normal(r_hat.shape) if doppler else None
    s = FilterSettings(cfg.sigma_r_m, cfg.sigma_beta_rad, 10.0, 0.3, 500.0, sigma_vr_mps=2.0)
    x, P = filter_history_xp(
        method,
        xps.asarray(r_hat),
        xps.asarray(beta_hat),
        s,
        radial_velocity_mps=None if vr_hat is None else xps.asarray(vr_hat),
    )
    assert isinstance(x, type(xps.asarray(0.0)))  # stayed in the strict namespace
    x, P = np.asarray(x), np.asarray(P)
    x_ref, P_ref = numpy_history(method, r_hat, beta_hat, s, vr_hat)
    sigma = np.sqrt(np.diagonal(P_ref, axis1=-2, axis2=-1))
    assert np.max(np.abs(x - x_ref) / sigma) < TOL
    assert np.max(np.abs(P - P_ref) / np.abs(P_ref).max(axis=(-1, -2), keepdims=True)) < TOL


def test_bench_gpu_without_a_gpu_says_so_in_one_line(capsys) -> None:
    from radarviz.viz_app.cli.main import main

    try:
        import cupy  # noqa: F401

        pytest.skip("CuPy is installed here: the message for a missing GPU is not reachable")
    except ImportError:
        pass
    assert main(["bench", "--device", "gpu"]) == 1
    out, err = capsys.readouterr()
    assert out == ""
    assert err.strip().splitlines() == [
        "radarviz: error: bench --device gpu: no GPU: CuPy is not installed "
        "(pip install -e '.[gpu]' on a machine with an NVIDIA GPU and CUDA 12)"
    ]
