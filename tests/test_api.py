"""The public API (``import radarviz``): the functions give the engine's numbers, the tables
hold them row for row, bad input is one line naming the parameter, and the command line is
the same computation."""

from __future__ import annotations

import contextlib
import csv
import inspect
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import radarviz
from radarviz.core.conversion.planar import convert as core_convert
from radarviz.core.experiments.prosov import (
    ALL_METHODS,
    TrackingConfig,
    prosov_target,
    run_tracking,
)
from radarviz.core.finite import ResultError
from radarviz.core.finite_memory.fit import finite_memory_fit, preset
from radarviz.core.params import ParameterError
from radarviz.core.tracking.stream import StreamOptions
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io.plots import (
    PLOT_FIELDS,
    PlotField,
    check_plots_finite,
    run_track,
    simulated_plots,
    state_from_row,
    write_measurements,
)


def test_all_names_resolve_and_core_and_viz_app_still_import() -> None:
    import radarviz.core
    import radarviz.viz_app

    for name in radarviz.__all__:
        assert getattr(radarviz, name) is not None, name
    assert sorted(radarviz.__all__) == sorted(set(radarviz.__all__))


def test_run_prosov_is_the_engine_bit_for_bit() -> None:
    [res] = radarviz.run_prosov(2.0, runs=64, seed=3, steps=12, methods=("naive", "seed"))
    ref = run_tracking(
        TrackingConfig(
            sigma_beta_deg=2.0,
            runs=64,
            seed=3,
            target=prosov_target(10.0, 12),
            methods=("naive", "seed"),
        )
    )
    for m in ("naive", "seed"):
        for field in ("bias_range_m", "rmse_x_m", "nees_pos"):
            np.testing.assert_array_equal(
                getattr(res.metrics[m], field), getattr(ref.metrics[m], field)
            )
    table = radarviz.to_table([res])
    assert len(table) == 2 * 12
    rows = table[table.method == "seed"].sort_values("scan")
    np.testing.assert_array_equal(rows.bias_range_m.to_numpy(), ref.metrics["seed"].bias_range_m)
    assert radarviz.to_arrow(res).num_rows == 24


def test_convert_and_finite_memory_are_the_core_functions() -> None:
    r = np.array([150e3, 90e3])
    b = np.array([0.1, -0.3])
    for method in ("naive", "seed", "cmkf_d", "ucm"):
        a = radarviz.convert(method, r, b, sigma_r_m=250.0, sigma_beta_rad=0.03)
        c = core_convert(method, r, b, sigma_r_m=250.0, sigma_beta_rad=0.03)
        np.testing.assert_array_equal(a.z, c.z)
        np.testing.assert_array_equal(a.R, c.R)
    p = preset("RLS3")
    fit = radarviz.finite_memory(
        5, sigma_r_m=p.sigma_r_m, sigma_vr_mps=p.sigma_vr_mps, period_s=10.0
    )
    ref = finite_memory_fit(5, sigma_r_m=p.sigma_r_m, sigma_vr_mps=p.sigma_vr_mps, period_s=10.0)
    np.testing.assert_array_equal(fit.R, ref.R)
    assert fit.sigma.shape == (3,)


def test_estimate_velocity_recovers_the_true_velocity_without_noise() -> None:
    from radarviz.core.geometry import direction_cosines

    sites = np.array([(0.0, 0.0, 0.0), (80e3, 0.0, 0.0), (40e3, 70e3, 0.0)])
    target, v = np.array([40e3, 30e3, 10e3]), np.array([216.5, 125.0, 0.0])
    d = target - sites
    az, el = np.arctan2(d[:, 1], d[:, 0]), np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1]))
    est = radarviz.estimate_velocity(
        sites,
        direction_cosines(az, el) @ v,
        az,
        el,
        sigma_vr_mps=[1.0, 3.0, 5.0],
        sigma_beta_rad=np.deg2rad([0.1, 0.3, 0.5]),
        sigma_elevation_rad=np.deg2rad([0.2, 0.5, 1.0]),
    )
    np.testing.assert_allclose(est.velocity, v, atol=1e-9)
    # The first-order σ of the baseline (docs/velocity.md): 2.157, 3.385, 10.665 m/s.
    np.testing.assert_allclose(np.sqrt(np.diag(est.covariance)), [2.157, 3.385, 10.665], atol=5e-4)
    table = radarviz.to_table(est)
    assert table.shape[0] == 1 and table.geometry_metric.iloc[0] == pytest.approx(0.053, abs=5e-4)


def _convert(method: str = "ucm", **values: object) -> object:
    """``radarviz.convert`` of a plot at 10 km, with ``values`` replacing its own."""
    args = {"range_m": 1e4, "azimuth_rad": 0.3, "sigma_r_m": 50.0, "sigma_beta_rad": 0.01}
    args |= values
    return radarviz.convert(
        method,
        args["range_m"],
        args["azimuth_rad"],
        sigma_r_m=args["sigma_r_m"],
        sigma_beta_rad=args["sigma_beta_rad"],
    )


def _plots(target: str = "") -> list[radarviz.Plot]:
    """A few plots of one target, labelled ``target``."""
    plots, _ = simulated_plots("prosov", 1, 1.0, 5)
    return [replace(p, target=target) for p in plots]


def _sites() -> list[radarviz.Radar]:
    return simulated_plots("prosov", 1, 1.0, 5)[1]


@pytest.mark.parametrize("field", PLOT_FIELDS, ids=lambda f: f.name)
def test_a_bad_plot_field_is_refused_alike_as_input_and_as_a_simulated_result(
    tmp_path: Path, field: PlotField
) -> None:
    # One field table: the API's write_measurements refuses a user's value (ParameterError),
    # the simulator's check a computed one (ResultError), each naming the same field.
    bad = replace(_plots()[0], **{field.name: float("nan")})
    meas, sites = tmp_path / "m.csv", tmp_path / "r.toml"
    with pytest.raises(ParameterError, match=rf"^plots\[0\]\.{field.name} must be a finite"):
        radarviz.write_measurements(meas, sites, [bad], _sites())
    with pytest.raises(ResultError, match=rf"^simulate: {field.name} at plot 1 is NaN"):
        check_plots_finite([bad])
    assert not meas.exists() and not sites.exists()
    if field.optional:  # None: the plot has no such value, which both accept
        check_plots_finite([replace(bad, **{field.name: None})])
    if field.positive:
        negative = replace(bad, **{field.name: -1.0})
        with pytest.raises(ParameterError, match=r"must be a finite number > 0 \(got -1.0\)"):
            radarviz.write_measurements(meas, sites, [negative], _sites())
        with pytest.raises(ResultError, match=rf"^simulate: {field.name} at plot 1 is -1"):
            check_plots_finite([negative])


@pytest.mark.parametrize(
    ("call", "start"),
    [
        (lambda: radarviz.run_prosov(1.0, runs=1), "runs must be"),
        (lambda: radarviz.run_prosov(1.0, methods=("nope",)), "methods must be among"),
        (lambda: radarviz.run_prosov(-1.0), "sigma_beta_deg must be"),
        (lambda: radarviz.run_gorshkov(k_max=0), "k_max must be an integer in [1, 20]"),
        (lambda: radarviz.run_gorshkov(["RLS9"]), "radars must be among"),
        (lambda: radarviz.run_gorshkov(tracking_runs=1), "tracking_runs must be 0"),
        (lambda: radarviz.finite_memory(0, sigma_r_m=1, sigma_vr_mps=1, period_s=1), "k must"),
        (lambda: radarviz.track([], init="later"), "init must be one of"),
        (lambda: _convert("bogus"), "method must be one of"),
        (lambda: _convert(sigma_r_m=-1.0), "sigma_r_m must be finite numbers in [2,"),
        (lambda: _convert(range_m=[1e4, np.nan]), "range_m must be finite numbers in (0,"),
        (lambda: _convert(range_m=[1e4, -5.0]), "range_m must be finite numbers in (0,"),
        (lambda: _convert(sigma_beta_rad=-0.01), "sigma_beta_rad must be finite number"),
        (lambda: _convert(azimuth_rad=np.inf), "azimuth_rad must be finite numbers"),
        (lambda: _convert("ducm"), "predicted_xy_m is needed by ducm"),
        (lambda: radarviz.track([], model="imm", sigma_a_mps2=1.0), "sigma_a_mps2 is the cv"),
        (lambda: radarviz.track([], imm_sigma_a_mps2=(1, 5), transition_prob=(1,)), "transit"),
        (lambda: radarviz.track([], model="cv", imm_turn_rate_degps=(0, 2)), "imm_turn_rate"),
        (lambda: radarviz.track([], model="bogus"), "model must be one of"),
        (lambda: radarviz.to_table(42), "result must be"),
        (lambda: radarviz.record("nope", "x.rrd"), "preset must be one of"),
        (
            lambda: radarviz.track(_plots("a"), association=radarviz.AssociationOptions()),
            "association is for plots without target labels (plots[0].target is 'a'",
        ),
        (
            lambda: radarviz.track(
                _plots(), association=radarviz.AssociationOptions(), init="finite-memory"
            ),
            "init must be first-plot",
        ),
        (
            lambda: radarviz.write_measurements(
                "m.csv", "r.toml", [replace(_plots()[0], range_m=np.nan)], _sites()
            ),
            "plots[0].range_m must be a finite number > 0 (got nan)",
        ),
        (
            lambda: radarviz.write_measurements(
                "m.csv", "r.toml", [replace(_plots()[0], sigma_r_m=0.0)], _sites()
            ),
            "plots[0].sigma_r_m must be a finite number > 0 (got 0.0)",
        ),
        (
            lambda: radarviz.track(_plots()[::-1], association=radarviz.AssociationOptions()),
            "plots[1].time_s: must not be before the previous time",
        ),
    ],
)
def test_bad_input_is_one_line_naming_the_parameter(call, start: str) -> None:
    with pytest.raises(ParameterError) as exc:
        call()
    assert str(exc.value).startswith(start), str(exc.value)
    assert "\n" not in str(exc.value)


#: One bad value for every public function that takes an argument: the parameter the error
#: must name, and the call.
BAD_VALUE: dict[str, tuple[str, object]] = {
    "convert": ("sigma_r_m", lambda: _convert(sigma_r_m=-1.0)),
    "finite_memory": (
        "period_s",
        lambda: radarviz.finite_memory(3, sigma_r_m=1.0, sigma_vr_mps=1.0, period_s=np.nan),
    ),
    "radar_preset": ("preset", lambda: radarviz.radar_preset("RLS9")),
    "estimate_velocity": (
        "radial_velocity_mps",
        lambda: radarviz.estimate_velocity(
            np.eye(3) * 1e4,
            [1.0, np.nan, 3.0],
            [0.0, 1.0, 2.0],
            [0.1, 0.2, 0.3],
            sigma_vr_mps=1.0,
            sigma_beta_rad=0.01,
            sigma_elevation_rad=0.01,
        ),
    ),
    "direction_cosines": ("elevation_rad", lambda: radarviz.direction_cosines(0.0, [0.1, np.inf])),
    "run_prosov": ("runs", lambda: radarviz.run_prosov(1.0, runs=1)),
    "run_gorshkov": ("k_max", lambda: radarviz.run_gorshkov(k_max=0)),
    "run_velocity": ("trials", lambda: radarviz.run_velocity(trials=1)),
    "track": ("init", lambda: radarviz.track([], init="later")),
    "track_file": ("init", lambda: radarviz.track_file("m.csv", "r.toml", init="later")),
    "simulate": ("steps", lambda: radarviz.simulate("fusion", steps=0)),
    "write_measurements": ("plots", lambda: radarviz.write_measurements("m.csv", "r.toml", [], [])),
    "record": ("seed", lambda: radarviz.record("prosov", "x.rrd", seed=-1)),
    "show": ("width", lambda: radarviz.show("prosov", width=5)),
    "colour": ("name", lambda: radarviz.colour("mauve")),
    "to_table": ("result", lambda: radarviz.to_table(42)),
    "to_arrow": ("result", lambda: radarviz.to_arrow(42)),
    "to_columns": ("result", lambda: radarviz.to_columns(42)),
}


def test_every_public_function_has_a_bad_value_case() -> None:
    """A new public function that takes arguments gets its line in ``BAD_VALUE``."""
    taking_arguments = {
        name
        for name in radarviz.__all__
        if inspect.isfunction(obj := getattr(radarviz, name)) and inspect.signature(obj).parameters
    }
    assert set(BAD_VALUE) == taking_arguments


@pytest.mark.parametrize("name", sorted(BAD_VALUE))
def test_each_public_function_refuses_a_bad_value_naming_it(name: str, tmp_path: Path) -> None:
    parameter, call = BAD_VALUE[name]
    with contextlib.chdir(tmp_path), pytest.raises(ParameterError) as exc:
        call()  # type: ignore[operator]
    assert exc.value.parameter == parameter, str(exc.value)
    assert str(exc.value).startswith(parameter + " "), str(exc.value)
    assert "\n" not in str(exc.value)
    assert not list(tmp_path.iterdir()), "a refused call left a file behind"


def test_track_equals_the_file_tracker(tmp_path: Path) -> None:
    """``radarviz track`` with its defaults, ``radarviz.track_file`` and ``radarviz.track``
    with theirs: the same tracker (the IMM), the same numbers."""
    plots, radars = simulated_plots("fusion", 2, 1.0, 20)
    meas, sites = tmp_path / "m.csv", tmp_path / "r.toml"
    write_measurements(str(meas), str(sites), plots, radars)
    out = tmp_path / "tracks.csv"
    assert main(["track", "--input", str(meas), "--radars", str(sites), "--out", str(out)]) == 0
    with out.open() as fh:
        cli_rows = list(csv.DictReader(fh))
    from_file = radarviz.track_file(str(meas), str(sites))
    from_plots = radarviz.track(plots, radars=radars)
    assert len(from_file.steps) == len(from_plots.steps) == len(cli_rows) > 0
    for a, b, row in zip(from_file.steps, from_plots.steps, cli_rows, strict=True):
        x, P = state_from_row(row)
        assert a.method == b.method == row["method"]
        np.testing.assert_allclose(a.x, b.x, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(a.x, x, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(a.P, P, rtol=1e-12, atol=1e-9)
    table = radarviz.to_table(from_file)
    assert len(table) == len(cli_rows)
    first = from_file.steps[0]
    np.testing.assert_array_equal(table[["x_m", "y_m", "z_m"]].iloc[0], first.x[[0, 2, 4]])
    np.testing.assert_array_equal(table.sigma_vy_mps.iloc[0], np.sqrt(first.P[3, 3]))
    assert set(table.method) == set(from_file.methods)
    pos = from_file.positions_m("ekf")
    assert pos.shape == (len(plots), 3)
    # The papers' filter is one argument away, and differs (Q = 0 is over-confident).
    papers = radarviz.track_file(str(meas), str(sites), model="cv", sigma_a_mps2=0.0)
    assert papers.steps[-1].P[1, 1] < 0.5 * from_file.steps[-1].P[1, 1]


def test_track_of_many_targets_equals_each_target_alone() -> None:
    from dataclasses import replace

    plots, radars = simulated_plots("prosov", 1, 1.0, 30)
    other = [replace(p, azimuth_rad=p.azimuth_rad + 0.3, time_s=p.time_s + 0.5) for p in plots]
    a = [replace(p, target="a") for p in plots]
    b = [replace(p, target="b") for p in other]
    mixed = sorted(a + b, key=lambda p: p.time_s)
    both = radarviz.track(mixed, ["ucm", "ekf"], radars=radars)
    table = radarviz.to_table(both)
    assert set(table.target) == {"a", "b"}
    for label, alone in (("a", plots), ("b", other)):
        single = radarviz.track(alone, ["ucm", "ekf"])
        mine = [s for s in both.steps if s.target == label]
        assert len(mine) == len(single.steps) > 0
        for s, t in zip(mine, single.steps, strict=True):
            assert s.method == t.method
            np.testing.assert_allclose(s.x, t.x, rtol=1e-12, atol=1e-9)
            np.testing.assert_allclose(s.P, t.P, rtol=1e-12, atol=1e-9)


def test_track_file_associates_as_the_cli_does(tmp_path: Path) -> None:
    m, r = tmp_path / "m.csv", tmp_path / "r.toml"
    argv = ["simulate", "--preset", "crossing", "--out", str(m), "--radars-out", str(r)]
    assert main([*argv, "--scans", "12", "--clutter-per-scan", "2"]) == 0
    out = tmp_path / "tracks.csv"
    flags = ["--associate", "gnn", "--method", "ucm", "ekf", "--confirm-m", "2", "--model", "cv"]
    flags += ["--sigma-a", "0"]
    assert main(["track", "--input", str(m), "--radars", str(r), "--out", str(out), *flags]) == 0
    with out.open() as fh:
        cli_rows = list(csv.DictReader(fh))
    options = radarviz.AssociationOptions(confirm_m=2)
    tracks = radarviz.track_file(
        str(m), str(r), ["ucm", "ekf"], association=options, model="cv", sigma_a_mps2=0.0
    )
    assert len(tracks.steps) == len(cli_rows) > 0
    for s, row in zip(tracks.steps, cli_rows, strict=True):
        assert (s.method, s.target, s.status) == (row["method"], row["target"], row["status"])
        np.testing.assert_allclose(s.x, state_from_row(row)[0], rtol=1e-12, atol=1e-9)
    assert {"target", "status"} <= set(radarviz.to_table(tracks).columns)

    # What a recording is made of: the replay hands an observer the calls ``run_track`` hands
    # the command's recorder, in the same order (each scan's deleted tracks after its plots).
    streamed, replayed = CallLog(), CallLog()
    run_track(
        str(m),
        str(r),
        str(tmp_path / "again.csv"),
        ("ucm", "ekf"),
        StreamOptions(model="cv"),
        lambda _radars: contextlib.nullcontext(streamed),
        association=options,
    )
    tracks.replay(replayed)
    assert replayed.calls == streamed.calls
    assert sum(c[0] == "end_scan" for c in streamed.calls) == len(tracks.scans) > 0
    assert any(c[0] == "end_scan" and c[1] for c in streamed.calls)  # some tracks deleted


def test_track_associates_plots_in_memory_as_track_file(tmp_path: Path) -> None:
    """``track(plots, association=...)`` of a file's plots read into memory is
    ``track_file(file, association=...)``: the same route, so the same numbers to the bit,
    the same track ids, statuses and scans, and so the same recording."""
    from radarviz.viz_app.io.plots import csv_source, load_radars
    from radarviz.viz_app.rerun.recording import verify_recording

    m, r = tmp_path / "m.csv", tmp_path / "r.toml"
    argv = ["simulate", "--preset", "crossing", "--out", str(m), "--radars-out", str(r)]
    assert main([*argv, "--scans", "12", "--clutter-per-scan", "2"]) == 0
    sites = load_radars(str(r))
    with m.open("rb") as fh:
        reader, _ = csv_source(fh, str(m), sites)
        plots = [plot for _, plot in reader]
    assert plots and not any(p.target for p in plots)
    options = radarviz.AssociationOptions(confirm_m=2)
    from_file = radarviz.track_file(str(m), str(r), ["ucm", "ekf"], association=options)
    tracks = radarviz.track(plots, ["ucm", "ekf"], association=options, radars=sites.values())

    assert len(tracks.steps) == len(from_file.steps) == 2 * len(plots)
    for s, t in zip(tracks.steps, from_file.steps, strict=True):
        assert (s.plot, s.time_s, s.method, s.target, s.status) == (
            t.plot,
            t.time_s,
            t.method,
            t.target,
            t.status,
        )
        np.testing.assert_array_equal(s.x, t.x)
        np.testing.assert_array_equal(s.P, t.P)
    assert tracks.scans == from_file.scans and tracks.plots == from_file.plots
    assert (tracks.methods, tracks.three_d, tracks.radars) == (
        from_file.methods,
        from_file.three_d,
        from_file.radars,
    )
    # Not a vacuous equality: the clutter starts tentative tracks that are deleted, the
    # targets' tracks are confirmed, and a plot is labelled with its track id.
    assert {"tentative", "confirmed"} <= {s.status for s in tracks.steps}
    assert any(end.deleted for end in tracks.scans)
    assert all(p.target for p in tracks.plots)

    in_memory, of_file = CallLog(), CallLog()
    tracks.replay(in_memory)
    from_file.replay(of_file)
    assert in_memory.calls == of_file.calls
    verify_recording(radarviz.record(tracks, tmp_path / "t.rrd"))


class CallLog:
    """A ``RowObserver`` that notes its calls: (add, plot, methods, status), (end_scan, ids)."""

    def __init__(self) -> None:
        self.calls: list[tuple] = []

    def add(self, plot: radarviz.Plot, rows: list, status: str = "") -> None:
        self.calls.append(("add", plot, [m for m, _, _ in rows], status))

    def end_scan(self, deleted: list[str]) -> None:
        self.calls.append(("end_scan", list(deleted)))

    def report(self, account: object) -> None:
        self.calls.append(("report", account))


def test_record_tracks_and_refuse_to_overwrite(tmp_path: Path) -> None:
    from radarviz.viz_app.rerun.recording import verify_recording

    plots, radars = simulated_plots("prosov", 1, 1.0, 60)
    tracks = radarviz.track(plots, ("naive", "ekf"), radars=radars)
    # Without the association: no scans, so the recorder gets each plot with no status.
    calls = CallLog()
    tracks.replay(calls)
    assert tracks.scans == () and len(calls.calls) == len(plots)
    assert all(c[0] == "add" and c[3] == "" for c in calls.calls)
    path = radarviz.record(tracks, tmp_path / "t.rrd")
    verify_recording(path)
    before = path.read_bytes()
    with pytest.raises(ParameterError, match="exists"):
        radarviz.record(tracks, path)
    assert path.read_bytes() == before
    with pytest.raises(ParameterError, match="radars"):
        radarviz.record(radarviz.track(plots, ("naive",)), tmp_path / "u.rrd")
    assert not (tmp_path / "u.rrd").exists()


def test_cli_reproduce_is_the_api(capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(
            [
                "reproduce",
                "prosov",
                "--runs",
                "40",
                "--steps",
                "8",
                "--sigma-beta-deg",
                "2",
                "--json",
            ]
        )
        == 0
    )
    doc = json.loads(capsys.readouterr().out)
    [res] = radarviz.run_prosov(2.0, runs=40, steps=8)
    case = doc["cases"][0]
    for m in ALL_METHODS:
        np.testing.assert_allclose(
            case["methods"][m]["bias_range_m"], res.metrics[m].bias_range_m, rtol=1e-15
        )
    assert main(["reproduce", "gorshkov", "--k-max", "0"]) == 2
    assert "--k-max must be an integer in [1, 20]" in capsys.readouterr().err
