"""ASTERIX CAT048 in and out (``viz_app.io.asterix``).

* A record laid out by hand from the CAT048 layout (FSPEC bits in UAP order, then the items in
  FRN order) equals what the encoder (libasterix) writes byte for byte, and the reader (its
  items decoded by pyobelix) gives the values it was built from.
* The 4/3-earth elevation ↔ height formulas against a second route: the target placed by
  vectors in the plane of the earth centre, the site and the target.
* Round trip: ``simulate --format asterix`` then ``track`` writes the same track file, byte for
  byte, as ``track`` of a CSV holding the simulated plots rounded to the items' resolution by
  this file's own rounding; the decoded plots are within half an LSB of the simulated ones.
* Midnight, 3D from a height or a flight level, Doppler (valid, doubtful, radar without σVr).
* Track-only records (no I048/040) skipped and byte-identical repeats dropped, both counted;
  an error in a one-record block names record 1. (Captures: ``tests/test_pcap.py``.)
* Bad input: exit 2, one line naming the byte offset (or the data source, or the radars
  file's key), nothing written.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import replace
from pathlib import Path

import asterix.generated as gen
import numpy as np
import pytest

from radarviz.core.params import ParameterError
from radarviz.core.tracking.stream import Plot
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io import asterix as ax
from radarviz.viz_app.io.plots import Radar, load_radars, parse_radars, simulated_plots

CAT048 = gen.Cat_048_1_32

RADARS = """\
[radars.north]
x_m = 0.0
y_m = 0.0
z_m = 120.0
sigma_r_m = 50.0
sigma_beta_deg = 0.1
sigma_elevation_deg = 0.2
sigma_vr_mps = 1.0
sac = 25
sic = 201

[radars.flat]
x_m = 30000.0
y_m = 5000.0
z_m = 0.0
sigma_r_m = 100.0
sigma_beta_deg = 0.3
sac = 25
sic = 7
"""

#: One record, by hand: I048/010 SAC 25 SIC 201, /140 45296.5 s, /040 RHO 100 NM THETA 90°,
#: /161 track 1234, /110 10 000 ft, /120 CAL −12 m/s (D = 0).
#: FSPEC: FRN 1 (010), 2 (140), 4 (040), FX | FRN 11 (161), FX | FRN 19 (110), 20 (120).
HAND_FSPEC = bytes([0b1101_0001, 0b0001_0001, 0b0000_1100])
HAND_ITEMS = bytes.fromhex(
    "19c9"  # 010: SAC 0x19 = 25, SIC 0xc9 = 201
    "587840"  # 140: 45296.5 × 128 = 5 797 952 = 0x587840
    "6400" "4000"  # 040: RHO 100 × 256 = 0x6400, THETA 90 / (360 / 2¹⁶) = 0x4000
    "04d2"  # 161: 1234
    "0190"  # 110: 10 000 / 25 = 400
    "80" "03f4"  # 120: subfield FSPEC (CAL only), D = 0, −12 in 10 bits = 0x3f4
)  # fmt: skip
HAND_RECORD = HAND_FSPEC + HAND_ITEMS
HAND_BLOCK = bytes([48]) + (3 + len(HAND_RECORD)).to_bytes(2, "big") + HAND_RECORD


def radars() -> dict[str, Radar]:
    return parse_radars(RADARS, "r.toml")


def read(data: bytes, rad: dict[str, Radar] | None = None) -> tuple[ax.AsterixReader, list]:
    """The reader's plots; its blocks (the compiled path's columns) checked to be the same
    plots at the same positions on the way."""
    rad = rad or radars()
    reader = ax.AsterixReader(io.BytesIO(data), "f.ast", rad)
    placed = list(reader)
    assert block_rows(ax.AsterixReader(io.BytesIO(data), "f.ast", rad), rad) == [
        (pos, p.time_s, p.range_m, p.azimuth_rad, p.elevation_rad, p.radial_velocity_mps,
         p.radar, p.target)
        for pos, p in placed
    ]  # fmt: skip
    return reader, [p for _, p in placed]


def block_rows(reader: ax.AsterixReader, rad: dict[str, Radar]) -> list[tuple]:
    """``reader.blocks()`` as one row per plot: (position, t, r, β, ε or None, Vr or None,
    radar name, target label), the radar's noise checked against the radars file."""
    from radarviz.viz_app.io.plots import radar_table

    names, table, rows = list(rad), radar_table(rad), []
    for blk, positions in reader.blocks():
        assert all(np.array_equal(a, b) for a, b in zip(blk.radars, table, strict=True))
        assert positions.shape == (blk.size,) and len(set(blk.labels)) == len(blk.labels)
        for i in range(blk.size):
            el = None if blk.elevation_rad is None else float(blk.elevation_rad[i])
            vr = blk.radial_velocity_mps
            v = None if vr is None or np.isnan(vr[i]) else float(vr[i])
            rows.append(
                (int(positions[i]), float(blk.time_s[i]), float(blk.range_m[i]),
                 float(blk.azimuth_rad[i]), el, v, names[blk.radar[i]],
                 blk.labels[blk.target[i]])
            )  # fmt: skip
    return rows


def block(*records: dict) -> bytes:
    return CAT048.create([CAT048.cv_record.create(r) for r in records]).unparse().to_bytes()


def rec(t_raw: int = 128, rho_raw: int = 2560, theta_raw: int = 0, more: dict | None = None):
    """A record of radar "north" with raw item values (and ``more`` items by number)."""
    r = {
        "010": (("SAC", 25), ("SIC", 201)),
        "140": t_raw,
        "040": (("RHO", rho_raw), ("THETA", theta_raw)),
    }
    return r | (more or {})


# --------------------------------------------------------------------------------------------
# The hand-checked record
# --------------------------------------------------------------------------------------------


def test_a_hand_laid_record_is_what_the_encoder_writes_and_the_reader_reads() -> None:
    assert len(HAND_BLOCK) == 22 and HAND_BLOCK[:3] == bytes.fromhex("300016")
    encoded = block(
        {
            "010": (("SAC", 25), ("SIC", 201)),
            "140": (45296.5, "s"),
            "040": (("RHO", (100.0, "NM")), ("THETA", (90.0, "°"))),
            "161": (0, ("TRN", 1234)),
            "110": (0, (10_000.0, "ft")),
            "120": {"CAL": (0, 0, (-12.0, "m/s"))},
        }
    )
    assert encoded == HAND_BLOCK
    reader, plots = read(HAND_BLOCK)
    assert reader.three_d and reader.targets
    (p,) = plots
    assert p.time_s == 45296.5
    assert p.range_m == 100 * 1852.0
    assert p.azimuth_rad == 0.0  # θ = 90° from north is the x (east) axis
    assert p.target == "1234" and p.radar == "north" and p.site == (0.0, 0.0, 120.0)
    assert p.radial_velocity_mps == -12.0 and p.sigma_vr_mps == 1.0
    assert p.sigma_elevation_rad == math.radians(0.2)
    # 10 000 ft = 3048 m seen from 120 m at 185.2 km: the vector route below, to 1e-12 rad.
    assert p.elevation_rad == pytest.approx(vector_elevation(185_200.0, 3048.0, 120.0), abs=1e-12)


# --------------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------------


def vector_elevation(r: float, h: float, hs: float, R: float = ax.EFFECTIVE_EARTH_RADIUS_M):
    """ε by search along the ray: the site at (0, R + hs), the target at site + r (cos ε,
    sin ε); bisection on |target| − R = h (monotone in ε)."""
    lo, hi = -math.pi / 2, math.pi / 2
    for _ in range(200):
        mid = (lo + hi) / 2
        if math.hypot(r * math.cos(mid), R + hs + r * math.sin(mid)) - R < h:
            lo = mid
        else:
            hi = mid
    return (lo + hi) / 2


def test_elevation_and_height_against_the_vector_route() -> None:
    rng = np.random.default_rng(4)
    for r, el, hs in zip(
        rng.uniform(1e3, 4.5e5, 200),
        rng.uniform(-0.2, 1.4, 200),
        rng.uniform(0, 3000, 200),
        strict=True,
    ):
        R = ax.EFFECTIVE_EARTH_RADIUS_M
        # The height by vectors: |site + r (cos ε, sin ε)| − R.
        h_vec = math.hypot(r * math.cos(el), R + hs + r * math.sin(el)) - R
        h = ax.height_from_elevation(r, el, hs)
        assert h == pytest.approx(h_vec, abs=1e-6 * max(1.0, r / 1e4))
        assert ax.elevation_from_height(r, h, hs) == pytest.approx(el, abs=1e-12)
    # A bigger earth is flatter: with R → ∞, sin ε → (h − hs) / r.
    s = ax.sin_elevation_from_height(50_000.0, 5_120.0, 120.0, 1e15)
    assert s == pytest.approx(5000.0 / 50_000.0, abs=1e-9)
    # 4/3 earth at 200 km: a target at the site's height is below its horizon by r / (2 a).
    s = ax.sin_elevation_from_height(200_000.0, 0.0, 0.0, ax.EFFECTIVE_EARTH_RADIUS_M)
    assert s == pytest.approx(-200_000.0 / (2 * ax.EFFECTIVE_EARTH_RADIUS_M), rel=1e-12)
    with pytest.raises(ValueError, match="outside"):
        ax.elevation_from_height(1000.0, 5000.0, 0.0)


# --------------------------------------------------------------------------------------------
# Round trip
# --------------------------------------------------------------------------------------------


def rounded_csv(path: Path, plots: list[Plot], radar_list: list[Radar], labels: dict | None):
    """The plots at the items' resolution as a measurement CSV, rounded here (not by the
    writer), angles in degrees as the reader forms them."""
    by_name = {r.name: r for r in radar_list}
    header = ["time_s", "radar", "range_m", "azimuth_deg"]
    three_d = plots[0].elevation_rad is not None
    doppler = any(p.radial_velocity_mps is not None for p in plots)
    header += ["elevation_deg"] * three_d + ["radial_velocity_mps"] * doppler
    header += ["target"] * (labels is not None)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for p in plots:
            k_rho = round(p.range_m / 1852.0 * 256)
            r = k_rho / 256 * 1852.0
            theta = (round((90 - math.degrees(p.azimuth_rad)) * 65536 / 360) % 65536) * (
                360 / 65536
            )
            beta = 90 - theta
            beta += 360 if beta <= -180 else 0
            row = [round(p.time_s * 128) / 128, p.radar, r, beta]
            if three_d:
                z = by_name[p.radar].z_m
                h_ft = round(ax.height_from_elevation(p.range_m, p.elevation_rad, z) / 0.3048 / 25)
                s = ax.sin_elevation_from_height(
                    r, h_ft * 25 * 0.3048, z, ax.EFFECTIVE_EARTH_RADIUS_M
                )
                row.append(math.degrees(math.asin(s)))
            if doppler:
                row.append(
                    "" if p.radial_velocity_mps is None else float(round(p.radial_velocity_mps))
                )
            if labels is not None:
                row.append(labels[p.target])
            w.writerow([repr(v) if isinstance(v, float) else v for v in row])


def track_both(tmp_path: Path, ast: Path, csv_path: Path, toml: Path, methods: list[str]):
    out_a, out_c = tmp_path / "from_ast.csv", tmp_path / "from_csv.csv"
    base = ["track", "--radars", str(toml), "--method", *methods, "--model", "cv"]
    assert main([*base, "--input", str(ast), "--out", str(out_a)]) == 0
    assert main([*base, "--input", str(csv_path), "--out", str(out_c)]) == 0
    return out_a.read_bytes(), out_c.read_bytes()


@pytest.mark.parametrize(
    ("preset", "methods"), [("fusion", ["ucm", "ekf"]), ("prosov", ["naive", "ucm", "ukf"])]
)
def test_simulate_asterix_then_track_equals_the_rounded_csv(
    tmp_path: Path, preset: str, methods: list[str]
) -> None:
    ast, toml = tmp_path / "m.ast", tmp_path / "r.toml"
    argv = ["simulate", "--preset", preset, "--out", str(ast), "--radars-out", str(toml)]
    scans = [] if preset == "prosov" else ["--scans", "30"]  # prosov's run has its 60 scans
    assert main([*argv, *scans, "--seed", "3"]) == 0
    plots, radar_list = simulated_plots(preset, 3, 1.0, 30)
    rounded_csv(tmp_path / "m.csv", plots, radar_list, None)
    a, c = track_both(tmp_path, ast, tmp_path / "m.csv", toml, methods)
    assert a == c and len(a.splitlines()) == 1 + len(plots) * len(methods)

    # The decoded plots are the simulated ones to within half an LSB of each item.
    rad = load_radars(str(toml))
    with open(ast, "rb") as fh:
        decoded = [p for _, p in ax.AsterixReader(fh, str(ast), rad)]
    assert len(decoded) == len(plots)
    for q, p in zip(decoded, plots, strict=True):
        assert (q.radar, q.site, q.sigma_r_m, q.sigma_beta_rad) == (
            p.radar, p.site, p.sigma_r_m, p.sigma_beta_rad
        )  # fmt: skip
        assert abs(q.time_s - p.time_s) <= ax.TIME_LSB_S / 2
        assert abs(q.range_m - p.range_m) <= ax.RHO_LSB_NM * ax.NM_M / 2 * (1 + 1e-12)
        d_az = math.remainder(q.azimuth_rad - p.azimuth_rad, 2 * math.pi)
        assert abs(d_az) <= math.radians(ax.THETA_LSB_DEG) / 2 * (1 + 1e-9)
        if p.elevation_rad is not None:
            # ε moves by ∂ε/∂h δh + ∂ε/∂r δr: δh ≤ 12.5 ft, δr ≤ half the RHO LSB.
            dh, dr = ax.HEIGHT_LSB_FT * ax.FT_M / 2, ax.RHO_LSB_NM * ax.NM_M / 2
            bound = (dh + dr * abs(math.sin(p.elevation_rad))) / (
                p.range_m * math.cos(p.elevation_rad)
            )
            assert abs(q.elevation_rad - p.elevation_rad) <= 1.01 * bound + 1e-12
            assert abs(q.radial_velocity_mps - p.radial_velocity_mps) <= 0.5


def test_labelled_plots_round_trip_with_their_track_numbers(tmp_path: Path) -> None:
    """Two targets, labels "7" (kept as track number 7) and "a" (given number 1)."""
    one, radar_list = simulated_plots("prosov", 1, 1.0, 60)
    two, _ = simulated_plots("prosov", 2, 1.0, 60)
    plots = [
        replace(p, target=label, time_s=p.time_s + 0.5 * k)
        for a, b in zip(one, two, strict=True)
        for k, (p, label) in enumerate(((a, "7"), (b, "a")))
    ]
    ast, toml = tmp_path / "m.ast", tmp_path / "r.toml"
    assert ax.write_asterix(str(ast), str(toml), plots, radar_list) == len(plots)
    rounded_csv(tmp_path / "m.csv", plots, radar_list, {"7": "7", "a": "1"})
    a, c = track_both(tmp_path, ast, tmp_path / "m.csv", toml, ["ucm"])
    assert a == c
    assert {row["target"] for row in csv.DictReader(io.StringIO(a.decode()))} == {"7", "1"}


def many_targets(preset: str, n: int, steps: int) -> tuple[list[Plot], list[Radar]]:
    """``n`` runs of a preset (seeds 1…n) as ``n`` labelled targets, in time order (run k
    shifted by k/n of a second); with Doppler, every 7th plot without it."""
    plots, radar_list = [], []
    for k in range(n):
        run, radar_list = simulated_plots(preset, k + 1, 1.0, steps)
        plots += [replace(p, target=f"{k + 1}", time_s=p.time_s + k / n) for p in run]
    plots.sort(key=lambda p: p.time_s)
    return [
        replace(p, radial_velocity_mps=None) if p.radial_velocity_mps is not None and i % 7 == 3
        else p
        for i, p in enumerate(plots)
    ], radar_list  # fmt: skip


SCENES = {
    "one target, 2D": lambda: simulated_plots("prosov", 2, 1.0, 60),
    "one target, 3D with Doppler": lambda: simulated_plots("fusion", 2, 1.0, 30),
    "five targets, 2D": lambda: many_targets("prosov", 5, 60),
    "four targets, 3D with Doppler": lambda: many_targets("fusion", 4, 25),
}


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_the_block_route_writes_the_row_routes_track_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, scene: str
) -> None:
    """``track`` of an ASTERIX file through the compiled block path (``plot_blocks.run_track``)
    gives the track file of the row path (``plots.run_track``, a ``Plot`` at a time on the
    numpy engine), byte for byte; blocks of 37 plots, so blocks cut the data blocks and the
    targets' runs."""
    from radarviz.viz_app.io import plot_blocks
    from radarviz.viz_app.io import plots as plots_io

    plots, radar_list = SCENES[scene]()
    ast, toml = tmp_path / "m.ast", tmp_path / "r.toml"
    ax.write_asterix(str(ast), str(toml), plots, radar_list)
    three_d = plots[0].elevation_rad is not None
    methods = ("ucm", "ekf") if three_d else ("naive", "ucm", "ukf")
    rows, blocks = tmp_path / "rows.csv", tmp_path / "blocks.csv"
    row = plots_io.run_track(str(ast), str(toml), str(rows), methods, open_source=ax.asterix_source)

    def not_here(*args: object, **kwargs: object) -> None:
        raise AssertionError("the row path")

    monkeypatch.setattr(ax, "BLOCK_PLOTS", 37)
    monkeypatch.setattr(plots_io, "run_track", not_here)
    monkeypatch.setattr(ax.AsterixReader, "__iter__", not_here)
    blk = plot_blocks.run_track(
        str(ast), str(toml), str(blocks), methods, open_source=ax.asterix_source
    )
    assert blocks.read_bytes() == rows.read_bytes()
    assert len(rows.read_bytes().splitlines()) == 1 + len(plots) * len(methods)
    assert (blk.plots, blk.rows, blk.three_d, blk.methods) == (
        row.plots, row.rows, row.three_d, row.methods
    )  # fmt: skip
    assert blk.targets == row.targets and len(blk.targets) == (
        0 if "one" in scene else len(set(p.target for p in plots))
    )


def test_the_trackers_error_names_the_plots_byte_and_record(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A plot the compiled tracker refuses (here a time made to go back on the way in, past
    the reader's check) is named by its data block's byte offset and its record."""
    from radarviz.core.tracking.compiled import PlotBlock, TrackBlock
    from radarviz.core.tracking.targets import TargetTracker

    data = b"".join(block(*(rec(128 * (8 * j + k + 1)) for k in range(8))) for j in range(3))
    (tmp_path / "m.ast").write_bytes(data)
    (tmp_path / "r.toml").write_text(RADARS)
    add_arrays, calls = TargetTracker.add_arrays, []

    def back_in_time(self: TargetTracker, blk: PlotBlock) -> TrackBlock:
        calls.append(blk.size)
        if len(calls) == 2:  # plot 10 of the file: the second data block's record 2
            t = blk.time_s.copy()
            t[4] = t[3] - 1.0
            blk = blk._replace(time_s=t)
        return add_arrays(self, blk)

    monkeypatch.setattr(ax, "BLOCK_PLOTS", 5)
    monkeypatch.setattr(TargetTracker, "add_arrays", back_in_time)
    argv = ["track", "--input", str(tmp_path / "m.ast"), "--radars", str(tmp_path / "r.toml")]
    capsys.readouterr()
    assert main([*argv, "--out", str(tmp_path / "t.csv"), "--method", "ucm"]) == 2
    out, err = capsys.readouterr()
    where = f"m.ast byte {len(data) // 3}, record 2, item I048/140: "
    assert out == "" and err.count("\n") == 1 and where in err, err
    assert "times must not decrease within a target (got 8.0 after 9.0)" in err, err
    assert calls == [5, 5] and sorted(p.name for p in tmp_path.iterdir()) == ["m.ast", "r.toml"]


# --------------------------------------------------------------------------------------------
# Midnight, heights, Doppler
# --------------------------------------------------------------------------------------------


def test_times_cross_midnight_onto_the_next_day() -> None:
    day = 86400 * 128
    times = [day - 256, day - 128, 64, day - 64, 192]  # 86398, 86399, 0.5, 86399.5 (late), 1.5
    data = block(*(rec(t, 2560 + 8 * k, 0, {"161": (0, ("TRN", k))}) for k, t in enumerate(times)))
    _, plots = read(data)
    assert [p.time_s for p in plots] == [86398.0, 86399.0, 86400.5, 86399.5, 86401.5]


def test_height_or_flight_level_make_a_3d_file() -> None:
    north = radars()["north"]
    r = 2560 / 256 * 1852.0
    # I048/110 wins over I048/090; a flight level counts only validated (V = 0), not garbled.
    data = block(
        rec(128, more={"110": (0, 200), "090": (0, 0, 400)}),
        rec(256, more={"090": (0, 0, 200)}),
        rec(384, more={"110": (0, 100)}),
    )
    reader, plots = read(data)
    assert reader.three_d and not reader.targets
    expected = [200 * 25 * 0.3048, 200 / 4 * 100 * 0.3048, 100 * 25 * 0.3048]
    for p, h in zip(plots, expected, strict=True):
        assert p.elevation_rad == pytest.approx(vector_elevation(r, h, north.z_m), abs=1e-12)
    for flags in ((1, 0), (0, 1)):  # not validated, garbled: no height, so a 2D file
        reader, plots = read(block(rec(128, more={"090": (*flags, 400)})))
        assert not reader.three_d and plots[0].elevation_rad is None
    # A radar without sigma_elevation_deg: its heights are not used.
    flat = rec(128, more={"110": (0, 200)})
    flat["010"] = (("SAC", 25), ("SIC", 7))
    reader, plots = read(block(flat))
    assert not reader.three_d and plots[0].elevation_rad is None


def test_doppler_valid_doubtful_and_without_sigma() -> None:
    cal = lambda d, v: {"CAL": (d, 0, v & 0x3FF)}  # noqa: E731
    _, plots = read(
        block(rec(128, more={"120": cal(0, -300)}), rec(256, more={"120": cal(1, 40)}), rec(384))
    )
    assert [p.radial_velocity_mps for p in plots] == [-300.0, None, None]
    assert [p.sigma_vr_mps for p in plots] == [1.0, 0.0, 0.0]
    flat = rec(128, more={"120": cal(0, 12)})
    flat["010"] = (("SAC", 25), ("SIC", 7))
    _, plots = read(block(flat))
    assert plots[0].radial_velocity_mps is None


def test_other_categories_are_skipped_and_blocks_span_reads(monkeypatch) -> None:
    cat034 = gen.Cat_034_1_29
    north_marker = (
        cat034.create([cat034.cv_record.create({"000": 1, "010": (("SAC", 25), ("SIC", 201))})])
        .unparse()
        .to_bytes()
    )
    data = north_marker + block(*(rec(128 * k, 2560 + k) for k in range(1, 40))) + north_marker
    _, whole = read(data)
    monkeypatch.setattr(ax, "READ_BYTES", 7)  # blocks cut across many reads
    monkeypatch.setattr(ax, "BLOCK_PLOTS", 5)  # and the compiled path's blocks in pieces
    _, pieces = read(data)
    assert pieces == whole and len(whole) == 39


# --------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------


GOOD = block(rec(128), rec(256), rec(384))


def without_040() -> bytes:
    return GOOD + block({"010": (("SAC", 25), ("SIC", 201)), "140": 512})


def unknown_source() -> bytes:
    r = rec(512)
    r["010"] = (("SAC", 9), ("SIC", 99))
    return GOOD + block(r)


def overrun() -> bytes:
    # A record whose FSPEC announces I048/040 (4 octets) with 2 left in the block.
    body = bytes([0b1101_0000]) + bytes.fromhex("19c90002000a00")
    return GOOD + bytes([48]) + (3 + len(body)).to_bytes(2, "big") + body


def beyond_uap() -> bytes:
    # FSPEC of five octets: FRN 29, past CAT048's 28 items (another edition's record).
    body = bytes([0x01, 0x01, 0x01, 0x01, 0x80, 0x00])
    return GOOD + bytes([48]) + (3 + len(body)).to_bytes(2, "big") + body


def height_then_none() -> bytes:
    return block(rec(128, more={"110": (0, 200)}), rec(256))


def track_then_none() -> bytes:
    return block(rec(128, more={"161": (0, ("TRN", 5))}), rec(256))


BAD_FILES = {
    "beyond UAP": (beyond_uap, f"byte {len(GOOD)}, record 1: the FSPEC announces items beyond"),
    "3D, then no height": (height_then_none, "record 2, item I048/110 or I048/090: missing"),
    "labelled, then none": (track_then_none, "record 2, item I048/161: missing"),
    "truncated": (
        lambda: GOOD[:-5],
        f"byte 0: truncated data block (CAT 048 declares LEN {len(GOOD)}",
    ),
    "short header": (lambda: GOOD + b"\x30\x00", f"byte {len(GOOD)}: truncated"),
    "LEN under 3": (lambda: GOOD + b"\x30\x00\x01", f"byte {len(GOOD)}: data block LEN 1"),
    "overrun": (overrun, f"byte {len(GOOD)}: CAT048 data block (LEN 11) does not decode"),
    "unknown SAC/SIC": (unknown_source, "unknown data source SAC 9 SIC 99"),
    "empty": (lambda: b"", "no CAT048 target reports (0 CAT048 records"),
    "only track-only": (
        lambda: without_040()[len(GOOD) :],
        "no CAT048 target reports (1 CAT048 records, 1 of them track-only",
    ),
    "time back": (lambda: GOOD + block(rec(200)), "item I048/140: time 1.5625 s is before"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_files_exit_2_one_line_nothing_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str
) -> None:
    make, expected = BAD_FILES[case]
    (tmp_path / "m.ast").write_bytes(make())
    (tmp_path / "r.toml").write_text(RADARS)
    capsys.readouterr()
    out_path = tmp_path / "t.csv"
    argv = ["track", "--input", str(tmp_path / "m.ast"), "--radars", str(tmp_path / "r.toml")]
    status = main([*argv, "--out", str(out_path), "--method", "ucm"])
    out, err = capsys.readouterr()
    assert status == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("radarviz: error: "), err
    assert expected in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.ast", "r.toml"]
    # The row path (a recording's, the association's) says the same.
    from radarviz.viz_app.io.plots import run_track

    with pytest.raises(ParameterError) as info:
        args = (str(tmp_path / "m.ast"), str(tmp_path / "r.toml"), str(out_path), ("ucm",))
        run_track(*args, open_source=ax.asterix_source)
    assert err == f"radarviz: error: {info.value}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.ast", "r.toml"]


def test_the_format_flag_overrides_the_suffix(tmp_path: Path, capsys) -> None:
    (tmp_path / "m.bin").write_bytes(GOOD)
    (tmp_path / "r.toml").write_text(RADARS)
    argv = ["track", "--input", str(tmp_path / "m.bin"), "--radars", str(tmp_path / "r.toml")]
    out = ["--out", str(tmp_path / "t.csv"), "--method", "ucm"]
    assert main([*argv, *out]) == 2  # read as CSV: not UTF-8 text
    assert main([*argv, *out, "--format", "asterix"]) == 0
    assert len((tmp_path / "t.csv").read_text().splitlines()) == 4
    capsys.readouterr()


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        ("sac = 1\n", "key sic: missing (sac and sic go together)"),
        ("sac = 256\nsic = 1\n", "key sac: must be an integer in [0, 255] (got 256)"),
        ("sac = 1\nsic = 2.0\n", "key sic: must be an integer in [0, 255] (got 2.0)"),
        ("sac = 25\nsic = 201\n", "data source SAC 25 SIC 201 is radar 'north''s too"),
    ],
)
def test_bad_source_keys(extra: str, expected: str) -> None:
    text = RADARS.replace("sac = 25\nsic = 7\n", extra)
    with pytest.raises(ParameterError) as info:
        parse_radars(text, "r.toml")
    assert "r.toml, radar 'flat'" in str(info.value) and expected in str(info.value)


def test_simulate_refuses_values_the_items_cannot_hold() -> None:
    radar = Radar("r", 0.0, 0.0, 0.0, 1.0, 1.0, sac=0, sic=1)
    far = Plot(0.0, 500_000.0, 0.0, 1.0, 0.01, radar="r")
    with pytest.raises(ParameterError, match=r"outside I048/040's \(0, 256\) NM"):
        ax.record_items(far, radar, None)
    fast = Plot(0.0, 1e5, 0.0, 1.0, 0.01, radar="r", radial_velocity_mps=600.0)
    with pytest.raises(ParameterError, match="beyond I048/120 CAL's ±511 m/s"):
        ax.record_items(fast, radar, None)


def test_reading_memory_does_not_grow_with_the_file(tmp_path: Path, monkeypatch) -> None:
    """The peak of Python's allocations while reading a file (no plot kept) is the same for a
    file four times longer, and a small part of it: one read and one data block are held,
    not the file."""
    import tracemalloc

    monkeypatch.setattr(ax, "READ_BYTES", 4096)
    blocks = [block(*(rec(128 * (8 * j + k + 1), 2560 + k) for k in range(8))) for j in range(1200)]
    short, long = tmp_path / "short.ast", tmp_path / "long.ast"
    short.write_bytes(b"".join(blocks[:300]))
    long.write_bytes(b"".join(blocks))
    peaks = []
    for path in (short, short, long):  # the first pass warms up (one-time allocations)
        with open(path, "rb") as fh:
            tracemalloc.start()
            n = sum(1 for _ in ax.AsterixReader(fh, "f.ast", radars()))
            peaks.append(tracemalloc.get_traced_memory()[1])
            tracemalloc.stop()
        assert n == path.stat().st_size // len(blocks[0]) * 8
    assert peaks[2] < peaks[1] + 4096, peaks
    assert peaks[2] < long.stat().st_size / 4, (peaks, long.stat().st_size)


def test_the_api_reads_asterix_files_too(tmp_path: Path) -> None:
    import radarviz

    plots, radar_list = simulated_plots("prosov", 5, 1.0, 60)
    ast, toml = tmp_path / "m.ast", tmp_path / "r.toml"
    ax.write_asterix(str(ast), str(toml), plots, radar_list)
    rounded_csv(tmp_path / "m.csv", plots, radar_list, None)
    a = radarviz.track_file(str(ast), str(toml), ["ucm"])
    c = radarviz.track_file(str(tmp_path / "m.csv"), str(toml), ["ucm"])
    assert a.plots == c.plots and len(a.steps) == len(plots)
    for sa, sc in zip(a.steps, c.steps, strict=True):
        assert np.array_equal(sa.x, sc.x) and np.array_equal(sa.P, sc.P)


def test_bench_section_figures_are_consistent(capsys) -> None:
    """``bench --only asterix``: the plots asked for, the ratio its own two rates' (speed is
    measured by running the benchmark, never asserted here)."""
    import json

    argv = ["bench", "--only", "asterix", "--asterix-plots", "300", "--asterix-targets", "7"]
    assert main([*argv, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)["asterix"]
    assert doc["plots"] == 300 and doc["repeats"] == 3
    assert doc["asterix_over_csv"] == pytest.approx(
        doc["asterix_plots_per_s"] / doc["csv_plots_per_s"], rel=1e-12
    )
    assert doc["bytes_per_plot"]["asterix"] * 300 == pytest.approx(doc["file_kib"] * 1024)
    assert 0 < doc["read_peak_kib"]
    track = doc["track"]
    # The air-traffic file: whole scans of two radars seeing all 7 targets (≥ 300 plots).
    assert track["targets"] == 7 and track["plots"] == 7 * 2 * -(-300 // 14)
    rate = {k: track[k]["plots_per_s"] for k in ("block", "row", "decoder", "csv")}
    assert track["block_over_csv"] == pytest.approx(rate["block"] / rate["csv"], rel=1e-12)
    assert track["block_over_row"] == pytest.approx(rate["block"] / rate["row"], rel=1e-12)
    assert track["block_over_decoder"] == pytest.approx(rate["block"] / rate["decoder"], rel=1e-12)
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert out.startswith("ASTERIX CAT048 reading, 300 fusion plots"), out
    assert "ASTERIX track end to end, 308 plots of 7 targets" in out, out


def test_simulate_writes_nothing_for_a_nan(tmp_path: Path) -> None:
    from radarviz.core.finite import ResultError

    plots, radar_list = simulated_plots("prosov", 1, 1.0, 60)
    plots[5] = replace(plots[5], range_m=math.nan)
    with pytest.raises(ResultError, match="range_m"):
        ax.write_asterix(str(tmp_path / "m.ast"), str(tmp_path / "r.toml"), plots, radar_list)
    assert list(tmp_path.iterdir()) == []


def test_items_not_used_are_read_past() -> None:
    """A record as a secondary radar sends it (Mode 3/A, aircraft address and identification,
    track status, track velocity, Mode S capability, all read past) gives the plot of the bare
    record."""
    extra = {
        "020": ((1, 0, 0, 0, 0, None),),  # target report descriptor (one octet; None: FX)
        "070": (0, 0, 0, 0, ("MODE3A", "7421")),
        "220": 0x3C6DA9,
        "240": "DLH4AB",
        "170": ((1, 2, 0, 0, 0, None), (0, 0, 0, 0, 0, None)),  # track status, extended
        "200": (("GSP", 1000), ("HDG", 16384)),
        "230": (1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0),
        "161": (0, ("TRN", 77)),
    }
    bare = rec(128, more={"161": (0, ("TRN", 77))})
    data = block(rec(128, more=extra))
    assert len(data) == len(block(bare)) + 1 + 2 + 3 + 6 + 2 + 4 + 2 + 1  # items + FSPEC octet
    _, full = read(data)
    _, plain = read(block(bare))
    assert full == plain and full[0].target == "77"


def test_track_only_records_and_duplicates_are_counted_not_tracked() -> None:
    """A record without I048/040 (a track status) is skipped, a byte-identical repeat of a
    recent record dropped (a redundant feed), each counted; the plots are the others."""
    twice = block(rec(512), rec(640))
    reader, plots = read(without_040() + twice + GOOD[:3] + GOOD[3:] + twice)
    assert [p.time_s for p in plots] == [1.0, 2.0, 3.0, 4.0, 5.0]
    c = reader.counts
    assert (c.records, c.track_only_skipped, c.duplicates_dropped) == (11, 1, 5)
    doc = reader.input_summary()
    assert doc["container"] == "asterix" and "packets" not in doc
    assert (doc["records"], doc["track_only_skipped"], doc["duplicates_dropped"]) == (11, 1, 5)


def test_an_error_in_a_one_record_block_names_record_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Each record of a file of one-record blocks is "record 1" of its block, in the reader's
    errors and with ``--associate``."""
    r = rec(384)
    r["010"] = (("SAC", 9), ("SIC", 99))
    (tmp_path / "m.ast").write_bytes(block(rec(128, more={"161": (0, ("TRN", 4))})) + block(r))
    (tmp_path / "r.toml").write_text(RADARS)
    argv = ["track", "--input", str(tmp_path / "m.ast"), "--radars", str(tmp_path / "r.toml")]
    for extra in ([], ["--associate", "gnn"]):
        capsys.readouterr()
        assert main([*argv, "--out", str(tmp_path / "t.csv"), "--method", "ucm", *extra]) == 2
        err = capsys.readouterr().err
        assert "m.ast byte 16, record 1, item I048/010: unknown data source SAC 9" in err, err
    # A one-record file associates (its track number is the radar's, not a label).
    (tmp_path / "m.ast").write_bytes(block(rec(128, more={"161": (0, ("TRN", 4))})))
    assert main([*argv, "--out", str(tmp_path / "t.csv"), "--associate", "gnn"]) == 0
    assert "radar_track_number" in (tmp_path / "t.csv").read_text().splitlines()[0]
