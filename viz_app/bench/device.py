"""``radarviz bench --device gpu``: the array-API path (``core.filters.array_api``) on a GPU.

CuPy is the GPU namespace (the optional ``gpu`` extra). When it is missing or sees no CUDA
device, ``gpu_namespace`` says which, and the command says so in one line instead of
printing figures of something else.
"""

from __future__ import annotations

import time
from typing import Any

from radarviz.core.experiments.prosov import TrackingConfig, block_measurements
from radarviz.core.filters.compiled import COMPILED_METHODS, FilterSettings
from radarviz.core.params import MIN_MONTE_CARLO_RUNS


class NoGPUError(RuntimeError):
    """No usable GPU: the message says why."""


def gpu_namespace() -> tuple[Any, str]:
    """(cupy, device name), or ``NoGPUError`` saying what is missing."""
    try:
        import cupy
    except ImportError:
        raise NoGPUError(
            "no GPU: CuPy is not installed (pip install -e '.[gpu]' on a machine with an "
            "NVIDIA GPU and CUDA 12)"
        ) from None
    try:
        count = cupy.cuda.runtime.getDeviceCount()
    except Exception as exc:  # CUDA driver missing or broken: CuPy raises its own errors
        raise NoGPUError(f"no GPU: CuPy found no CUDA driver ({exc})") from None
    if count == 0:
        raise NoGPUError("no GPU: CuPy sees no CUDA device")
    props = cupy.cuda.runtime.getDeviceProperties(0)
    name = props["name"]
    return cupy, name.decode() if isinstance(name, bytes) else str(name)


def bench_gpu(runs: int = 100_000, repeats: int = 3) -> dict[str, Any]:
    """ns per track-step of every method by the array-API path on the GPU (after a warm-up
    run; the device is synchronised before each clock reading)."""
    from radarviz.core.filters.array_api import filter_history_xp

    cp, device = gpu_namespace()
    config = TrackingConfig(runs=MIN_MONTE_CARLO_RUNS)
    truth = config.target.truth()
    r_hat, b_hat = block_measurements(config, 0, runs, truth)
    r_dev, b_dev = cp.asarray(r_hat), cp.asarray(b_hat)
    s = FilterSettings(config.sigma_r_m, config.sigma_beta_rad, config.target.period_s, 0.0, 1000.0)
    ns = {}
    for method in COMPILED_METHODS:
        filter_history_xp(method, r_dev[:64], b_dev[:64], s, xp=cp)
        cp.cuda.Device().synchronize()
        best = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            filter_history_xp(method, r_dev, b_dev, s, xp=cp)
            cp.cuda.Device().synchronize()
            best = min(best, time.perf_counter() - t0)
        ns[method] = best / (runs * truth.shape[0]) * 1e9
    return {"device": device, "gpu_runs": runs, "gpu_ns_per_step": ns}


def format_gpu(doc: dict[str, Any]) -> str:
    lines = [f"array-API path on {doc['device']}, {doc['gpu_runs']} runs, ns per track-step:"]
    lines += [f"  {m:>7}: {v:8.2f}" for m, v in doc["gpu_ns_per_step"].items()]
    return "\n".join(lines)
