"""Manoeuvring targets: the scenario, the IMM and finite-memory tracks in the streaming
tracker, the consistency monitor on them, ``track``'s options and ``reproduce manoeuvre``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from radarviz.core.experiments.manoeuvre import raw_converted_errors
from radarviz.core.filters.measurement import DopplerMeasurement
from radarviz.core.filters.methods import ALL_METHODS, METHODS_3D, PolarNoise, PolarPlot
from radarviz.core.filters.models import DEFAULT_IMM
from radarviz.core.finite_memory.fit import finite_memory_fit
from radarviz.core.scenarios.manoeuvre import (
    FLIGHTS,
    MANOEUVRE_RADARS,
    STEP_S,
    Flight,
    Leg,
    fly,
    manoeuvre_plots,
)
from radarviz.core.scenarios.multi_radar import Segment, Trajectory3D
from radarviz.core.tracking.consistency import ConsistencyMonitor
from radarviz.core.tracking.stream import (
    FINITE_MEMORY_TRACK,
    Plot,
    StreamOptions,
    StreamTracker,
    TrackGroup,
)
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.cli.presets import manoeuvre_file_plots

# --------------------------------------------------------------------------------------------
# Scenario
# --------------------------------------------------------------------------------------------


def test_flight_integration_matches_the_closed_form_turn() -> None:
    """Constant-speed turns and straight legs against ``Trajectory3D``'s exact arcs: the
    mid-step rule's error is O(v (ω dt)² / 24) per step, < 1 mm here, so 1200 s of it stays
    below 1 m."""
    w = math.radians(3.0)
    legs = (
        Leg(100.0, climb_mps=5.0),
        Leg(60.0, w, climb_mps=5.0),
        Leg(200.0, climb_mps=5.0),
        Leg(60.0, -w, climb_mps=5.0),
    )
    flight = Flight("t", (1e4, 2e4, 3000.0), 0.3, 220.0, 5.0, legs)
    v0 = (220.0 * math.cos(0.3), 220.0 * math.sin(0.3), 5.0)
    exact = Trajectory3D(
        flight.position_m, v0, tuple(Segment(leg.duration_s, leg.turn_rate_radps) for leg in legs)
    )
    tr = fly(flight)
    pos, vel = exact.state(tr.time_s)
    assert np.abs(tr.position_m - pos).max() < 1.0
    assert np.abs(tr.velocity_mps - vel).max() < 1e-6


def test_speed_and_climb_changes_are_integrated_exactly() -> None:
    """Along-track acceleration a: s = v₀t + at²/2 exactly (the mid-step speed is exact for a
    linear speed); the climb reaches its command at 1 m/s² and holds it."""
    flight = Flight("a", (0.0, 0.0, 1000.0), 0.0, 150.0, 0.0, (Leg(100.0, 0.0, 0.5, 8.0),))
    tr = fly(flight)
    t = tr.time_s
    np.testing.assert_allclose(tr.position_m[:, 0], 150.0 * t + 0.25 * t * t, atol=1e-6)
    np.testing.assert_allclose(tr.velocity_mps[:, 0], 150.0 + 0.5 * t, atol=1e-9)
    assert tr.velocity_mps[-1, 2] == pytest.approx(8.0)
    # Vertical: a 1 m/s² ramp for 8 s, then 8 m/s: z = 1000 + 32 + 8 (t − 8).
    assert tr.position_m[-1, 2] == pytest.approx(1000.0 + 32.0 + 8.0 * 92.0, abs=1e-6)


def test_flight_plans_are_realistic() -> None:
    for f in FLIGHTS:
        tr = fly(f)
        speed = np.hypot(tr.velocity_mps[:, 0], tr.velocity_mps[:, 1])
        assert 120.0 <= speed.min() and speed.max() <= 300.0, f.name
        assert 1000.0 <= tr.position_m[:, 2].min() and tr.position_m[:, 2].max() <= 12000.0
        assert np.abs(tr.velocity_mps[:, 2]).max() <= 15.0 + 1e-9
        heading = np.unwrap(np.arctan2(tr.velocity_mps[:, 1], tr.velocity_mps[:, 0]))
        rate = np.abs(np.diff(heading)) / STEP_S
        assert rate.max() <= math.radians(3.0) + 1e-9
        assert rate.max() >= math.radians(1.5) - 1e-9  # every flight turns
        for r in MANOEUVRE_RADARS:  # no flight passes over a radar (its blind cone)
            d = tr.position_m[:, :2] - np.array(r.position[:2])
            assert np.hypot(d[:, 0], d[:, 1]).min() > 20e3


def test_raw_converted_rmse_matches_the_measurement_accuracy() -> None:
    """The raw (ucm) error's mean square against σr² + (r cos ε σβ)² + (r σε)² at each plot
    (first order; the conversion is unbiased), within 4.5 SE over the runs."""
    mp = manoeuvre_plots(runs=40, seed=2, steps=40)
    e2 = (raw_converted_errors(mp) ** 2).sum(-1)  # (N, B)
    n, f, m = mp.range_m.shape
    sig = np.array(
        [[r.sigma_r_m, r.sigma_beta_rad, r.sigma_elevation_rad] for r in MANOEUVRE_RADARS]
    )[mp.schedule.radar]
    tp = mp.true_position_m
    sites = np.array([r.position for r in MANOEUVRE_RADARS])[mp.schedule.radar]
    d = tp - sites[:, None, :]
    rng = np.linalg.norm(d, axis=-1)
    cos_el = np.hypot(d[..., 0], d[..., 1]) / rng
    expected = (
        sig[:, 0, None] ** 2 + (rng * cos_el * sig[:, 1, None]) ** 2 + (rng * sig[:, 2, None]) ** 2
    )  # (N, F)
    per_run = e2.reshape(n, f, m).mean(axis=(0, 1))
    se = per_run.std(ddof=1) / math.sqrt(m)
    assert abs(per_run.mean() - expected.mean()) < 4.5 * se


# --------------------------------------------------------------------------------------------
# The IMM in the tracker: batched equals streamed, every method, 2D and 3D, with Doppler
# --------------------------------------------------------------------------------------------


def _plots_of(mp, b: int, three_d: bool) -> list[Plot]:
    """Run b's plots (flight-major batch index) as the tracker's Plot objects."""
    f, m = divmod(b, mp.range_m.shape[2])
    out = []
    for n, t in enumerate(mp.schedule.time_s):
        r = mp.schedule.radars[int(mp.schedule.radar[n])]
        el = float(mp.elevation_rad[n, f, m])
        rng = float(mp.range_m[n, f, m])
        vr = float(mp.radial_velocity_mps[n, f, m])
        out.append(
            Plot(
                float(t),
                rng if three_d else rng * math.cos(el),
                float(mp.azimuth_rad[n, f, m]),
                r.sigma_r_m,
                r.sigma_beta_rad,
                r.position,
                r.name,
                el if three_d else None,
                r.sigma_elevation_rad,
                None if math.isnan(vr) else vr,
                r.sigma_vr_mps,
            )
        )
    return out


@pytest.mark.parametrize("three_d", [False, True], ids=["2D", "3D"])
def test_batched_imm_equals_each_streamed_track(three_d: bool) -> None:
    """The Monte Carlo path (one batch of B runs per method group, ``TrackGroup.add_arrays``)
    gives each run's streamed track (``StreamTracker``, a batch of one) to 1e-9: the IMM's
    model axis broadcasts with any leading batch, for every conversion method and Doppler."""
    mp = manoeuvre_plots(runs=2, seed=4, flights=FLIGHTS[:2], steps=25)
    dims = 3 if three_d else 2
    methods = METHODS_3D if three_d else ALL_METHODS
    n_plots, f, m = mp.range_m.shape
    b = f * m
    streamed = []
    for run in range(b):
        tr = StreamTracker(methods, three_d, StreamOptions(model="imm"))
        streamed.append(tr.add_block(_plots_of(mp, run, three_d)))
    from radarviz.core.filters.methods import method_groups

    for names in method_groups(methods):
        g = TrackGroup(names, dims, DEFAULT_IMM)
        for n in range(n_plots):
            radar = mp.schedule.radars[int(mp.schedule.radar[n])]
            el = mp.elevation_rad[n].reshape(b)
            rng = mp.range_m[n].reshape(b)
            plot = (
                PolarPlot(rng, mp.azimuth_rad[n].reshape(b), el)
                if three_d
                else PolarPlot(rng * np.cos(el), mp.azimuth_rad[n].reshape(b))
            )
            noise = PolarNoise(radar.sigma_r_m, radar.sigma_beta_rad, radar.sigma_elevation_rad)
            pre = g.group.start_parts(plot, noise) if g.group.converted else None
            dop = None
            if mp.doppler[n]:
                dop = DopplerMeasurement(
                    mp.radial_velocity_mps[n].reshape(b),
                    plot.azimuth_rad,
                    el if three_d else 0.0,
                    radar.sigma_vr_mps,
                    radar.sigma_beta_rad,
                    radar.sigma_elevation_rad,
                )
            site = np.asarray(radar.position[:dims], dtype=np.float64)
            state, _ = g.add_arrays(float(mp.schedule.time_s[n]), plot, noise, site, pre, dop)
            x = state.x.reshape(len(names), b, 2 * dims)
            for i, name in enumerate(names):
                k = methods.index(name)
                for run in range(b):
                    row = streamed[run][n][k]
                    assert row[0] == name
                    np.testing.assert_allclose(x[i, run], row[1][: 2 * dims], rtol=1e-9, atol=1e-6)


def test_monitor_flags_q0_on_a_manoeuvring_flight_and_not_the_imm() -> None:
    plots, _ = manoeuvre_file_plots("holding", seed=6, steps=120)
    verdicts = {}
    for model in ("cv", "imm"):
        mon = ConsistencyMonitor(10)
        StreamTracker(METHODS_3D, True, StreamOptions(model=model, monitor=mon)).add_block(plots)
        verdicts[model] = {m: mon.result(m) for m in METHODS_3D}
    for m in METHODS_3D:
        assert verdicts["cv"][m].inconsistent and verdicts["cv"][m].fraction_out > 0.5
        assert not verdicts["imm"][m].inconsistent
        assert verdicts["cv"][m].first_exit_s is not None


# --------------------------------------------------------------------------------------------
# The finite-memory track
# --------------------------------------------------------------------------------------------


def test_finite_memory_track_is_the_window_fit() -> None:
    """Noise-free plots of a radially moving target: the window's least-squares range and
    radial velocity are exact, so the track sits on the truth; its range variance is the
    fit's (Gorshkov's eq. for k plots), its rows only at the first radar's plots."""
    k, period, v = 5, 4.0, 180.0
    plots = []
    for j in range(12):
        t = j * period
        r = 80e3 + v * t
        plots.append(
            Plot(
                t,
                r,
                0.4,
                50.0,
                1e-3,
                radar="a",
                radial_velocity_mps=v,
                sigma_vr_mps=1.0,
            )
        )
        plots.append(Plot(t + 1.0, r + v, 0.4, 50.0, 1e-3, radar="b"))
    tr = StreamTracker(("naive",), False, StreamOptions(model="cv", finite_memory_k=k))
    rows = tr.add_block(plots)
    fm = [(p, r[-1]) for p, r in zip(plots, rows, strict=True) if r[-1][0] == FINITE_MEMORY_TRACK]
    assert [p.radar for p, _ in fm] == ["a"] * (12 - k + 1)
    fit = finite_memory_fit(k, sigma_r_m=50.0, sigma_vr_mps=1.0, period_s=period, with_doppler=True)
    u = np.array([math.cos(0.4), math.sin(0.4)])
    for p, (_, x, P) in fm:
        np.testing.assert_allclose(x[[0, 2]], p.range_m * u, rtol=1e-9)
        np.testing.assert_allclose(x[[1, 3]], v * u, rtol=1e-9)
        assert u @ P[np.ix_([0, 2], [0, 2])] @ u == pytest.approx(fit.R[0, 0], rel=1e-9)


# --------------------------------------------------------------------------------------------
# The command line
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def manoeuvre_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("manoeuvre")
    meas, radars = d / "m.csv", d / "r.toml"
    argv = ["simulate", "--preset", "manoeuvre", "--flight", "s-turns", "--scans", "80"]
    assert main([*argv, "--out", str(meas), "--radars-out", str(radars)]) == 0
    return meas, radars


def test_track_defaults_to_a_consistent_imm_and_writes_its_summary(
    manoeuvre_files, tmp_path: Path, capsys
) -> None:
    meas, radars = manoeuvre_files
    out, summary = tmp_path / "t.csv", tmp_path / "s.json"
    base = ["track", "--input", str(meas), "--radars", str(radars)]
    assert main([*base, "--out", str(out), "--summary", str(summary)]) == 0
    cap = capsys.readouterr()
    assert "model imm" in cap.out and "every track within its NIS band" in cap.out
    doc = json.loads(summary.read_text())
    assert doc["model"]["kind"] == "imm" and doc["inconsistent_tracks"] == []
    assert set(doc["tracks"]) == set(METHODS_3D)
    assert all(t["fraction_out_of_band"] < 0.2 for t in doc["tracks"].values())
    # The papers' Q = 0 on the same file: flagged on stderr and in the JSON.
    assert main([*base, "--out", str(tmp_path / "q.csv"), "--model", "cv", "--json"]) == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    assert doc["model"] == {"kind": "cv", "sigma_a_mps2": 0.0}
    assert sorted(doc["inconsistent_tracks"]) == sorted(METHODS_3D)
    assert "has left its NIS band" in cap.err and "outside its NIS band" in cap.err


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--sigma-a", "-1"], "--sigma-a must be a finite number in [0, 1000] (got -1.0)"),
        (["--imm-sigma-a", "-0.5", "10"], "--imm-sigma-a must be a finite number in [0, 1000]"),
        (["--imm-sigma-a", "1"], "--imm-sigma-a must give at least 2 models (got 1)"),
        (
            ["--imm-sigma-a", "1", "10", "--imm-transition", "0.9", "0.2", "0.1", "0.9"],
            "--imm-transition row 1 must sum to 1",
        ),
        (
            ["--imm-sigma-a", "1", "10", "--imm-transition", "1", "0", "0.1", "0.9"],
            "--imm-transition must be a finite number in (0, 1)",
        ),
        (
            ["--imm-sigma-a", "1", "10", "--imm-transition", "0.9", "0.1", "0.1"],
            "--imm-transition must give 4 probabilities",
        ),
        (["--imm-transition", "0.9", "0.1"], "--imm-transition must give 16 probabilities"),
        (
            ["--imm-turn-rate", "0", "30", "-2", "0"],
            "--imm-turn-rate must be a finite number in [-20, 20] (got 30.0)",
        ),
        (["--imm-turn-rate", "0", "2"], "--imm-turn-rate must have one entry per model, 4 (got 2)"),
        (["--model", "cv", "--imm-turn-rate", "0", "2"], "--imm-turn-rate is the imm model's"),
        (["--model", "ct"], "--model must be one of cv, imm (got 'ct')"),
        (["--nis-window", "0"], "--nis-window must be an integer in [1, 10000] (got 0)"),
        (["--finite-memory", "1"], "--finite-memory must be an integer in [2, 1000] (got 1)"),
        (["--model", "imm", "--sigma-a", "1"], "--sigma-a is the cv model's"),
        (["--sigma-a", "1", "--imm-sigma-a", "1", "5"], "--imm-sigma-a is the imm model's"),
    ],
)
def test_bad_model_parameters_are_one_line_exit_2_nothing_written(
    manoeuvre_files, tmp_path: Path, capsys, args: list[str], needle: str
) -> None:
    meas, radars = manoeuvre_files
    out = tmp_path / "t.csv"
    argv = ["track", "--input", str(meas), "--radars", str(radars), "--out", str(out)]
    assert main([*argv, "--summary", str(tmp_path / "s.json"), *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err
    assert list(tmp_path.iterdir()) == []


def test_reproduce_manoeuvre_meets_its_targets(capsys) -> None:
    """The reproduction's claims with its own bands (few runs: the margins are wide)."""
    assert main(["reproduce", "manoeuvre", "--runs", "4", "--straight-runs", "64", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    raw = doc["raw_rmse_m"]["value"]
    assert 300.0 < raw < 900.0
    for name, r in doc["models"]["imm"]["methods"].items():
        assert r["rmse_over_raw"]["ci95"][1] <= 0.6, name
        lo, hi = r["nees_pos"]["ci95"]
        assert 2.1 <= lo and hi <= 4.5, name
        assert r["runs_flagged"] == 0.0
    assert all(doc["targets"]["imm_meets"].values())
    assert doc["flags_q0"]
    for r in doc["models"]["cv-q0"]["methods"].values():
        assert r["rmse_over_raw"]["value"] > 5.0
    for v in doc["straight_line"]["imm_over_cv"].values():
        assert 1.0 < v["value"] < 1.5
    # The finite-memory tracks (k = 5): consistent, and no better than their radar's plots
    # across the line of sight (docs/manoeuvre.md, section 3).
    fm = {f["radar"]: f for f in doc["finite_memory"]}
    assert fm["north"]["with_doppler"] is False and fm["east"]["with_doppler"] is True
    for f in fm.values():
        lo, hi = f["nees_pos"]["ci95"]
        assert 2.1 <= lo and hi <= 4.5
        assert 0.95 < f["rmse_over_raw"]["value"] < 1.05


# --------------------------------------------------------------------------------------------
# Recordings
# --------------------------------------------------------------------------------------------


def test_manoeuvre_scene_logs_core_values_and_the_monitor_events(
    tmp_path: Path, rrd_contents
) -> None:
    from radarviz.core.experiments.manoeuvre import track_flight
    from radarviz.viz_app.rerun.manoeuvre_scene import FLIGHT, log_manoeuvre
    from radarviz.viz_app.rerun.recording import recording_file

    path = tmp_path / "m.rrd"
    with recording_file(path) as rec:
        logged = log_manoeuvre(rec, seed=2)
    rows, cols = rrd_contents(path)
    ft = track_flight(FLIGHT, 2)
    n = ft.time_s.size
    for entity in ("manoeuvre/map/truth/position", "manoeuvre/map/plots"):
        assert rows[f"/{entity}"] == n
    for label in ("cv-q0", "imm"):
        got = [v[0] for v in cols[f"/plots/manoeuvre/error_m/{label}"]["Scalars:scalars"]]
        np.testing.assert_array_equal(got, ft.errors_m[label])
        nis = [v[0] for v in cols[f"/plots/manoeuvre/nis/{label}"]["Scalars:scalars"]]
        np.testing.assert_array_equal(nis, ft.windows[label][:, 1])
        assert rows[f"/manoeuvre/map/tracks/{label}/position"] == n
    # Q = 0 leaves its band and the log says so; the IMM stays (on this flight and seed).
    assert logged.events["cv-q0"] and logged.events["cv-q0"][0].kind == "leaves"
    assert not [e for e in logged.events["imm"] if e.kind == "leaves"]
    texts = [t[0] for t in cols["/log"]["TextLog:text"]]
    assert any(t.startswith("cv-q0: track ucm has left its NIS band") for t in texts)


def test_track_recording_logs_the_band_exits(manoeuvre_files, tmp_path: Path, rrd_contents):
    meas, radars = manoeuvre_files
    rrd = tmp_path / "t.rrd"
    argv = ["track", "--input", str(meas), "--radars", str(radars), "--model", "cv"]
    assert main([*argv, "--out", str(tmp_path / "t.csv"), "--rrd", str(rrd)]) == 0
    _, cols = rrd_contents(rrd)
    texts = [t[0] for t in cols["/log"]["TextLog:text"]]
    levels = [lv[0] for lv in cols["/log"]["TextLog:level"]]
    exits = [(t, lv) for t, lv in zip(texts, levels, strict=True) if "has left its NIS band" in t]
    assert {t.split()[1] for t, _ in exits} == set(METHODS_3D)
    assert all(lv == "WARN" for _, lv in exits)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--flight", "loop"], "--flight must be one of approach, departure"),
        (["--scans", "1"], "--scans must be an integer in [2, 1000000] (got 1)"),
        # The default flight lasts 240 of the fastest radar's periods: 241 scans, not more.
        (["--scans", "5000"], "--scans must be an integer in [2, 241] (got 5000)"),
    ],
)
def test_bad_manoeuvre_preset_input_writes_nothing(tmp_path: Path, capsys, args, needle) -> None:
    argv = ["simulate", "--preset", "manoeuvre", "--out", str(tmp_path / "m.csv")]
    assert main([*argv, "--radars-out", str(tmp_path / "r.toml"), *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------------
# Consistency in turns (core.experiments.turns)
# --------------------------------------------------------------------------------------------

#: Standard errors a Monte Carlo figure may lie beyond its bound before a test fails: 3 is a
#: one-sided false alarm of 0.13% per figure for a figure that meets it exactly.
SE_MARGIN = 3.0
#: Straight-leg RMSE the default IMM may add to the former default before it is "materially
#: worse" (5%).
MATERIAL = 0.05


def test_airliner_scene_turns_are_inside_turn_legs_and_away_from_the_radar() -> None:
    from radarviz.core.scenarios.airliner import AIRLINER_FLIGHTS, AIRLINER_RADAR, turn_mask

    mp = manoeuvre_plots(2, 1, AIRLINER_FLIGHTS, (AIRLINER_RADAR,))
    mask = turn_mask(mp.schedule, AIRLINER_FLIGHTS)
    for f, flight in enumerate(AIRLINER_FLIGHTS):
        turning = sum(leg.duration_s for leg in flight.legs if leg.turn_rate_radps)
        # one plot every 4.5 s inside the turn legs
        assert abs(mask[:, f].sum() - turning / AIRLINER_RADAR.period_s) <= len(flight.legs)
        rates = [abs(math.degrees(leg.turn_rate_radps)) for leg in flight.legs]
        assert all(w == 0.0 or 1.5 - 1e-9 <= w <= 3.0 + 1e-9 for w in rates)
        speed = np.linalg.norm(mp.true_velocity_mps[:, f, :2], axis=-1)
        assert 140.0 <= speed.min() and speed.max() <= 260.0
        ground = np.linalg.norm(mp.true_position_m[:, f, :2], axis=-1)
        assert ground.min() > 20e3  # outside the radar's blind cone


@pytest.mark.parametrize(
    ("scene", "dims"),
    [("airliner", 2), ("airliner", 3), ("manoeuvre", 3)],
    ids=["airliner-2d", "airliner-3d", "manoeuvre-3d"],
)
def test_the_default_imm_is_consistent_in_turns_and_no_worse_on_straight_legs(
    scene: str, dims: int
) -> None:
    """The default IMM's mean position NEES in the turn segments lies in [d/2, 2d] (d the
    position dof) within ``SE_MARGIN`` Monte Carlo standard errors; its straight-leg RMSE is
    at most ``MATERIAL`` above the former two-CV default's on the same runs (paired standard
    error), and its turn RMSE lower. Figures: ``docs/manoeuvre.md``, "Turn models"."""
    from radarviz.core.experiments.turns import rmse_ratio, turn_figures
    from radarviz.core.filters.models import CV_IMM

    runs = 32 if scene == "airliner" else 16
    new = turn_figures(DEFAULT_IMM, scene, dims, runs=runs)
    old = turn_figures(CV_IMM, scene, dims, runs=runs)
    d = dims
    nees = new.nees_turn
    assert d / 2.0 - SE_MARGIN * nees.se <= nees.value <= 2.0 * d + SE_MARGIN * nees.se, nees
    ratio = rmse_ratio(new, old)
    assert ratio.value <= 1.0 + MATERIAL + SE_MARGIN * ratio.se, ratio
    a, b = new.rmse_turn_m, old.rmse_turn_m
    assert a.value + SE_MARGIN * a.se < b.value - SE_MARGIN * b.se, (a, b)
