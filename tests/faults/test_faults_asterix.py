"""Corrupted ASTERIX is refused, not tracked (``viz_app.io.asterix``: ``AsterixReader._framed``,
``_foreign``, ``_successor_inside``, the day clock's jump bound, the height's physical range).

ASTERIX has no checksum, so the reader's defence is plausibility. The fuzz test holds it to the
rule the user needs: a corrupted file either decodes to exactly the plots of the intact file
except the plot of the record the corruption is in, or is refused with one line naming a byte
offset. The hand-made cases are the corruptions that were once accepted: a category octet
changed (a block of plots skipped as "another category"), an FSPEC bit that makes a record
swallow the records after it, a height no aircraft flies at, a record of another kind.
"""

from __future__ import annotations

import io
import random
from dataclasses import replace
from pathlib import Path

import asterix.generated as gen
import pytest

from radarviz.core.params import ParameterError
from radarviz.core.tracking.stream import Plot
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io import asterix as ax
from radarviz.viz_app.io.plots import Radar, parse_radars, simulated_plots

CAT048 = gen.Cat_048_1_32
CAT034 = gen.Cat_034_1_29
#: Data sources as radars have them (SAC of a country, SIC of a site).
SOURCES = ((25, 201), (25, 7), (25, 90))
MUTANTS = 2000
RECORDS_PER_BLOCK = 50


def fuzz_file(monkeypatch: pytest.MonkeyPatch) -> tuple[bytes, dict[str, Radar]]:
    """The fuzz test's own file: three labelled 3D targets with Doppler (every 7th plot
    without) seen by three radars, CAT048 blocks of ``RECORDS_PER_BLOCK`` records with CAT034
    north markers before and between them."""
    plots: list[Plot] = []
    radar_list: list[Radar] = []
    for k in range(3):
        run, radar_list = simulated_plots("fusion", k + 1, 1.0, 14)
        plots += [replace(p, target=f"{k + 1}", time_s=p.time_s + k / 3) for p in run]
    plots.sort(key=lambda p: p.time_s)
    plots = [replace(p, radial_velocity_mps=None) if i % 7 == 3 else p for i, p in enumerate(plots)]
    radar_list = [replace(r, sac=a, sic=b) for r, (a, b) in zip(radar_list, SOURCES, strict=True)]
    monkeypatch.setattr(ax, "BLOCK_RECORDS", RECORDS_PER_BLOCK)
    blocks = list(ax.encode_plots(plots, radar_list))
    north = CAT034.create(
        [CAT034.cv_record.create({"000": 1, "010": (("SAC", 25), ("SIC", 201)), "030": 128})]
    )
    marker = north.unparse().to_bytes()
    data = marker + b"".join(b + marker for b in blocks)
    return data, {r.name: r for r in radar_list}


def decode(data: bytes, rad: dict[str, Radar]) -> list[tuple[int, Plot]]:
    return list(ax.AsterixReader(io.BytesIO(data), "f.ast", rad))


def record_extents(data: bytes) -> list[tuple[int, int, int]]:
    """(first byte, length, position) of every CAT048 record of an intact file."""
    parser, out, offset = ax._decoder(), [], 0
    while offset < len(data):
        length = int.from_bytes(data[offset + 1 : offset + 3], "big")
        if data[offset] == ax.CATEGORY:
            start = offset + 3
            for index, (_, raw) in enumerate(
                ax.split_records(data[offset : offset + length], parser, parser.uap48)
            ):
                out.append((start, len(raw), offset * 65536 + index))
                start += len(raw)
        offset += length
    return out


def test_every_mutant_decodes_to_the_original_plots_or_is_refused_by_byte(monkeypatch) -> None:
    data, rad = fuzz_file(monkeypatch)
    original = decode(data, rad)
    assert len(original) == 126 and len(data) > 2000
    extents = record_extents(data)
    rng = random.Random(20240531)
    accepted = refused = 0
    for _ in range(MUTANTS):
        at = rng.randrange(len(data))
        value = rng.randrange(256) if rng.random() < 0.5 else data[at] ^ (1 << rng.randrange(8))
        if value == data[at]:
            value ^= 0x01
        mutant = bytearray(data)
        mutant[at] = value
        try:
            plots = decode(bytes(mutant), rad)
        except ParameterError as exc:
            message = str(exc)
            assert "\n" not in message and " byte " in message, (at, value, message)
            refused += 1
            continue
        # Accepted: every plot but the mutated record's is the original, at its position.
        inside = next((pos for s, n, pos in extents if s <= at < s + n), None)
        assert [pp for pp in plots if pp[0] != inside] == [
            pp for pp in original if pp[0] != inside
        ], (at, data[at], value)
        accepted += 1
    # Both outcomes occur: value octets change a plot, framing octets are refused.
    assert accepted > MUTANTS // 4 and refused > MUTANTS // 4, (accepted, refused)


# --------------------------------------------------------------------------------------------
# The corruptions once accepted
# --------------------------------------------------------------------------------------------

RADARS = """\
[radars.north]
x_m = 0.0
y_m = 0.0
z_m = 120.0
sigma_r_m = 50.0
sigma_beta_deg = 0.1
sigma_elevation_deg = 0.2
sac = 25
sic = 201
"""


def rec(k: int, track: int = 1, height: int | None = None) -> dict:
    """Record ``k`` of radar "north": k s, RHO 10 NM + k/256, track ``track``."""
    r = {
        "010": (("SAC", 25), ("SIC", 201)),
        "140": 128 * k,
        "040": (("RHO", 2560 + k), ("THETA", 100 * k)),
        "161": (0, ("TRN", track)),
    }
    return r | ({} if height is None else {"110": (0, height & 0x3FFF)})


def block(records: list[dict]) -> bytes:
    return CAT048.create([CAT048.cv_record.create(r) for r in records]).unparse().to_bytes()


def refused(tmp_path: Path, capsys, data: bytes, *needles: str) -> str:
    """``track`` of ``data``: exit 2, one line naming a byte offset and ``needles``, no output."""
    meas, toml, out = tmp_path / "m.ast", tmp_path / "r.toml", tmp_path / "t.csv"
    meas.write_bytes(data)
    toml.write_text(RADARS)
    capsys.readouterr()
    argv = ["track", "--input", str(meas), "--radars", str(toml), "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and " byte " in err, err
    for needle in needles:
        assert needle in err, err
    assert not out.exists()
    return err


def rad() -> dict[str, Radar]:
    return parse_radars(RADARS, "r.toml")


def test_a_category_octet_changed_is_refused_not_skipped(tmp_path: Path, capsys) -> None:
    first, second = block([rec(k) for k in range(1, 9)]), block([rec(k) for k in range(9, 20)])
    assert len(decode(first + second, rad())) == 19
    for cat in (34, 21):  # the service messages' category, ADS-B's
        data = first + bytes([cat]) + second[1:]
        err = refused(tmp_path, capsys, data, f"byte {len(first)}", f"CAT{cat:03d}", "11 records")
        assert "corrupt category octet" in err
    # A category number no published ASTERIX category has: a corrupt header.
    for cat in (52, 209):
        data = first + bytes([cat]) + second[1:]
        refused(tmp_path, capsys, data, f"byte {len(first)}", f"category {cat},")


def test_blocks_of_other_categories_are_still_skipped_and_counted(tmp_path: Path) -> None:
    """An honest CAT021 block (records that are not CAT048 reports) is skipped, and counted
    with the first one's byte offset in the input summary."""
    first, second = block([rec(k) for k in range(1, 9)]), block([rec(k) for k in range(9, 20)])
    other = bytes([21, 0, 8]) + bytes([0x01, 0x02, 0x03, 0x04, 0x05])
    reader = ax.AsterixReader(io.BytesIO(first + other + second), "f.ast", rad())
    assert len(list(reader)) == 19
    doc = reader.input_summary()
    assert doc["other_category_blocks"] == 1
    assert doc["first_other_category_block"] == {"byte": len(first), "category": 21}
    assert f"1 data blocks of other categories skipped (the first CAT021 at byte {len(first)})" in (
        ax.input_line("f.ast", doc)
    )


def test_an_fspec_bit_that_swallows_the_next_records_is_refused(tmp_path: Path, capsys) -> None:
    """Record 2's FSPEC gains I048/250 (Mode S MB data, FRN 10): its repetition count is then
    the track number's high octet (8), so it takes 1 + 8 × 8 = 65 octets, the five 13-octet
    records after it, and ends at the block's end. Accepted, 5 of 7 plots were lost."""
    data = bytearray(block([rec(k, track=0x800 + k) for k in range(1, 8)]))
    assert len(decode(bytes(data), rad())) == 7
    at = 3 + 13 + 1  # the second record's second FSPEC octet
    assert data[at] == 0x10  # FRN 11 (I048/161)
    data[at] |= 0x20  # FRN 10 (I048/250)
    refused(tmp_path, capsys, bytes(data), "byte 0, record 2", "run over 5 record(s)")


def test_a_height_outside_the_physical_range_is_refused(tmp_path: Path, capsys) -> None:
    """I048/110 holds ±204 775 ft; −134 275 ft (a record read from the wrong octets) is no
    aircraft's height."""
    good = [rec(k, height=400) for k in range(1, 4)]
    data = block([*good, rec(4, height=round(-134_275 / 25))])
    refused(tmp_path, capsys, data, "record 4", "I048/110", "physical range")


def test_a_record_of_another_kind_is_refused(tmp_path: Path, capsys) -> None:
    """The first record has no height (the file is 2D) though its radar measures heights: a
    later record with one is of another kind (the first's FSPEC corrupt), refused; so is a
    track number in a file whose first record has none."""
    data = block([rec(1), rec(2, height=400)])
    refused(tmp_path, capsys, data, "record 2", "the file is 2D")
    plain = {k: v for k, v in rec(1).items() if k != "161"}
    refused(tmp_path, capsys, block([plain, rec(2)]), "record 2", "I048/161")


def test_a_record_without_a_time_is_refused_even_without_a_position(tmp_path: Path, capsys) -> None:
    """A three-octet record (FSPEC with I048/010 alone), what a record cut short leaves of its
    tail, was once skipped as track-only."""
    ghost = {"010": (("SAC", 25), ("SIC", 201))}
    refused(tmp_path, capsys, block([rec(1), ghost, rec(2)]), "record 2", "I048/140")


def test_a_time_jump_that_would_move_the_day_is_refused(tmp_path: Path, capsys) -> None:
    """A north marker's time corrupted to 13 h made every later plot a day later."""
    marker = CAT034.create(
        [
            CAT034.cv_record.create(
                {"000": 1, "010": (("SAC", 25), ("SIC", 201)), "030": 128 * 46800}
            )
        ]
    )
    data = marker.unparse().to_bytes() + block([rec(k) for k in range(1, 4)])
    refused(tmp_path, capsys, data, "record 1", "I048/140", "from the previous record")
