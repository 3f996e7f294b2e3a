"""A track updated alone equals its row of a batch, for every update kind, 2D and 3D; and the
method registry covers what the docs say.

Every batch size runs the same step functions (``core.filters.steps_2d``, ``steps_3d``), but a
batch of 64 is applied in blocks, its arguments cut or broadcast per block
(``core.filters.state.step_2d``, ``step_3d``), and a batch of one is not: a wrong cut or a
misaligned argument shows here. The two differ by rounding at most (numpy's vector loops and
scalar code may order a sum differently), float64 ε ≈ 1e-16 amplified by the cancellation in P⁺
(the update shrinks the position variance by up to ~10⁴ here), so we assert 1e-9 relative to
the largest entry; a wrong term shows at ≥ 1e-4.
"""

from __future__ import annotations

import numpy as np
import pytest

from radarviz.core.filters.doppler import doppler_update
from radarviz.core.filters.methods import (
    ALL_METHODS,
    METHODS,
    METHODS_3D,
    POLAR_METHODS,
    Kind,
    PolarNoise,
    PolarPlot,
)
from radarviz.core.filters.polar_ekf import ekf_update
from radarviz.core.filters.polar_ukf import ukf_update
from radarviz.core.filters.position import cv_update
from radarviz.core.filters.predict import cv_predict
from radarviz.core.filters.state import BLOCK_TRACKS, CVBatch, as_batch

BATCH = 64


def _states(dims: int, seed: int) -> CVBatch:
    """Plausible predicted tracks 20–60 km from a site at (1, −2[, 0.3]) km."""
    rng = np.random.default_rng(seed)
    n = 2 * dims
    x = np.zeros((BATCH, n))
    x[:, 0::2] = rng.uniform(20e3, 60e3, (BATCH, dims)) * rng.choice([-1, 1], (BATCH, dims))
    if dims == 3:
        x[:, 4] = rng.uniform(1e3, 9e3, BATCH)
    x[:, 1::2] = rng.normal(0.0, 150.0, (BATCH, dims))
    a = rng.normal(size=(BATCH, n, n)) * np.tile([300.0, 20.0], dims)
    P = a @ a.transpose(0, 2, 1) + np.diag(np.tile([100.0, 4.0], dims))
    return as_batch(x, P)


def _site(dims: int) -> np.ndarray:
    return np.array([1000.0, -2000.0, 300.0])[:dims]


def _measurement(state: CVBatch, dims: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    d = state.x[:, 0::2] - _site(dims)
    r = np.linalg.norm(d, axis=-1) + rng.normal(0, 50.0, BATCH)
    out = [r, np.arctan2(d[:, 1], d[:, 0]) + rng.normal(0, 0.01, BATCH)]
    if dims == 3:
        out.append(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])) + rng.normal(0, 0.01, BATCH))
    return out


NOISE = {"sigma_r_m": 50.0, "sigma_beta_rad": 0.01, "sigma_elevation_rad": 0.012}


def _updates(dims: int):
    """Every update kind as f(state, rows) with the measurement of those rows."""

    def noise() -> dict:
        return NOISE if dims == 3 else {k: v for k, v in NOISE.items() if "elev" not in k}

    def ekf(st, meas, rows):
        return ekf_update(st, [m[rows] for m in meas], site=_site(dims), **noise())

    def ukf(st, meas, rows):
        return ukf_update(st, [m[rows] for m in meas], site=_site(dims), **noise())

    def position(st, meas, rows):
        z = st.x[:, 0::2] + 30.0
        R = np.tile(np.eye(dims) * 900.0 + 100.0, (st.runs, 1, 1))
        return cv_update(st, z, R)

    def doppler(st, meas, rows):
        el = meas[2][rows] if dims == 3 else 0.0
        return doppler_update(
            st,
            np.full(st.runs, 42.0),
            meas[1][rows],
            el,
            sigma_vr_mps=1.5,
            sigma_beta_rad=0.01,
            sigma_elevation_rad=0.012 if dims == 3 else 0.0,
        )

    def predict(st, meas, rows):
        return cv_predict(st, 3.3, 1.7)

    return {"predict": predict, "position": position, "ekf": ekf, "ukf": ukf, "doppler": doppler}


@pytest.mark.parametrize("dims", [2, 3])
@pytest.mark.parametrize("kind", ["predict", "position", "ekf", "ukf", "doppler"])
def test_a_track_alone_equals_its_row_of_a_batch(
    dims: int, kind: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    import radarviz.core.filters.state as state_module

    assert BLOCK_TRACKS >= BATCH
    monkeypatch.setattr(state_module, "BLOCK_TRACKS", 10)  # 64 tracks: 7 blocks, one partial
    state = _states(dims, seed=dims)
    meas = _measurement(state, dims, seed=10 + dims)
    update = _updates(dims)[kind]
    big = update(state, meas, slice(None))
    for i in (0, 17, BATCH - 1):
        one = update(CVBatch(state.x[i : i + 1], state.P[i : i + 1]), meas, slice(i, i + 1))
        scale_x = np.abs(big.x[i]).max()
        scale_p = np.abs(big.P[i]).max()
        np.testing.assert_allclose(one.x[0], big.x[i], rtol=0, atol=1e-9 * scale_x)
        np.testing.assert_allclose(one.P[0], big.P[i], rtol=0, atol=1e-9 * scale_p)
        assert not np.array_equal(one.P[0], state.P[i])  # the update did something


def test_comparison_catches_a_wrong_term() -> None:
    """Negative control: a Doppler variance missing its σβ term is outside the tolerance
    (by 90× here: a missing term of a small variance is the hardest case to see)."""
    state = _states(3, seed=3)
    meas = _measurement(state, 3, seed=13)
    big = _updates(3)["doppler"](state, meas, slice(None))
    one = doppler_update(
        CVBatch(state.x[:1], state.P[:1]),
        np.full(1, 42.0),
        meas[1][:1],
        meas[2][:1],
        sigma_vr_mps=1.5,
        sigma_beta_rad=0.0,
        sigma_elevation_rad=0.012,
    )
    assert np.abs(one.x[0] - big.x[0]).max() > 10 * 1e-9 * np.abs(big.x[0]).max()


def test_registry_lists_every_method_once() -> None:
    assert ALL_METHODS == ("naive", "seed", "cmkf_d", "ucm", "ducm", "ekf", "ukf")
    assert POLAR_METHODS == ("ekf", "ukf")
    assert METHODS_3D == ALL_METHODS  # every method exists in 2D and 3D
    assert {m.kind for m in METHODS.values()} == set(Kind)


@pytest.mark.parametrize("name", ALL_METHODS)
def test_every_method_starts_and_updates_a_batch_of_any_shape(name: str) -> None:
    """Each method on a (2, 3) batch gives its six tracks of a flat batch, bit for bit."""
    rng = np.random.default_rng(5)
    r = 80e3 + rng.normal(0, 100.0, (2, 3))
    b = 0.4 + rng.normal(0, 0.01, (2, 3))
    noise = PolarNoise(100.0, 0.01)
    kind = METHODS[name]
    grid = kind.start(PolarPlot(r, b), noise, sigma_v0_mps=300.0)
    flat = kind.start(PolarPlot(r.ravel(), b.ravel()), noise, sigma_v0_mps=300.0)
    grid = kind.update(cv_predict(grid, 5.0), PolarPlot(r + 900.0, b), noise)
    flat = kind.update(cv_predict(flat, 5.0), PolarPlot(r.ravel() + 900.0, b.ravel()), noise)
    np.testing.assert_array_equal(grid.x.reshape(6, 4), flat.x)
    np.testing.assert_array_equal(grid.P.reshape(6, 4, 4), flat.P)
