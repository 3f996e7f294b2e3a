"""Packet captures of ASTERIX (``viz_app.io.pcap``, ``viz_app.io.asterix``).

* A tiny writer here (``Frames``, ``pcap``, ``pcapng``) lays out captures by the formats'
  field tables: Ethernet (with 802.1Q tags), Linux cooked SLL and SLL2, raw IP, IPv4 (with
  options) and IPv6 (with an extension header), UDP.
* A simulated scene written as ASTERIX, its data blocks wrapped into pcap and pcapng captures
  (several blocks to a datagram, every framing, a non-UDP packet, a fragment, a datagram that
  is not ASTERIX, track-only records, duplicated records in later packets, CAT034 north
  markers and sector crossings), is tracked into the same track file, byte for byte, as the
  CSV of the scene's plots at the items' resolution; the counts and the scan timing are
  those laid in.
* ``--associate gnn`` takes a file with I048/161 and keeps the numbers in their own column.
* Bad captures: no ASTERIX, a truncated packet, an unknown link type, a snap length that cut
  a datagram: exit 2, one line naming the packet, nothing written.
"""

from __future__ import annotations

import csv
import io
import json
import struct
from dataclasses import replace
from pathlib import Path

import asterix.generated as gen
import pyarrow.parquet
import pytest
from test_asterix import RADARS, block, rec, rounded_csv

from radarviz.core.params import ParameterError
from radarviz.viz_app.cli.main import main
from radarviz.viz_app.io import asterix as ax
from radarviz.viz_app.io import pcap
from radarviz.viz_app.io.plots import (
    PlotReader,
    input_format_of,
    load_radars,
    parse_radars,
    simulated_plots,
)

CAT034 = gen.Cat_034_1_29


# --------------------------------------------------------------------------------------------
# The test's capture writer
# --------------------------------------------------------------------------------------------


def udp(payload: bytes) -> bytes:
    """UDP header: source port 50000, destination port 8600, length, checksum 0 (none)."""
    return struct.pack(">HHHH", 50000, 8600, 8 + len(payload), 0) + payload


def ipv4(body: bytes, proto: int = 17, options: bytes = b"", frag: int = 0) -> bytes:
    """IPv4 header: version 4, IHL, total length, flags/fragment offset ``frag``, TTL 64,
    protocol, checksum 0, 10.0.0.1 → 239.1.1.1, ``options`` (a multiple of 4 octets)."""
    ihl = 5 + len(options) // 4
    head = struct.pack(
        ">BBHHHBBH4s4s", 0x40 | ihl, 0, 4 * ihl + len(body), 1, frag, 64, proto, 0,
        bytes([10, 0, 0, 1]), bytes([239, 1, 1, 1]),
    )  # fmt: skip
    return head + options + body


def ipv6(body: bytes, hop_by_hop: bool = False, nxt: int = 17) -> bytes:
    """IPv6 header (payload length, next header ``nxt``, hop limit, ::1 → ff02::1),
    optionally with an 8-octet hop-by-hop options header first."""
    if hop_by_hop:
        body = bytes([nxt, 0]) + bytes(6) + body
        nxt = 0
    src, dst = bytes(15) + b"\x01", b"\xff\x02" + bytes(13) + b"\x01"
    return struct.pack(">IHBB", 6 << 28, len(body), nxt, 64) + src + dst + body


def ethernet(ip: bytes, ethertype: int = 0x0800, vlans: int = 0) -> bytes:
    """Ethernet II: destination, source, ``vlans`` 802.1Q tags (TPID 0x8100, TCI), EtherType;
    padded to the 60-octet minimum (the IP length bounds the datagram)."""
    head = bytes.fromhex("01005e010101") + bytes.fromhex("020000000001")
    for k in range(vlans):
        head += struct.pack(">HH", 0x8100, 100 + k)
    frame = head + struct.pack(">H", ethertype) + ip
    return frame + bytes(max(0, 60 - len(frame)))


def sll(ip: bytes, ethertype: int) -> bytes:
    """Linux cooked v1: packet type, ARPHRD_ETHER, address length 6, address (8), protocol."""
    return struct.pack(">HHH8sH", 0, 1, 6, bytes(8), ethertype) + ip


def sll2(ip: bytes, ethertype: int) -> bytes:
    """Linux cooked v2: protocol, reserved, interface index, ARPHRD_ETHER, packet type,
    address length, address (8)."""
    return struct.pack(">HHIHBB8s", ethertype, 0, 2, 1, 0, 6, bytes(8)) + ip


def pcap_file(frames: list[bytes], link: int = 1, order: str = "<", ns: bool = False) -> bytes:
    """A classic pcap file: the header (magic, 2.4, zone 0, sigfigs 0, snaplen 65535, link
    type) and a record (seconds, fraction, incl_len, orig_len) per frame."""
    magic = pcap.PCAP_MAGIC_NS if ns else pcap.PCAP_MAGIC_US
    out = struct.pack(order + "IHHiIII", magic, 2, 4, 0, 0, 65535, link)
    for k, f in enumerate(frames):
        out += struct.pack(order + "IIII", 1_700_000_000 + k, 0, len(f), len(f)) + f
    return out


def ng_block(kind: int, body: bytes, order: str) -> bytes:
    """A pcapng block: type, total length, the body padded to 4, total length again."""
    body += bytes(-len(body) % 4)
    n = 12 + len(body)
    return struct.pack(order + "II", kind, n) + body + struct.pack(order + "I", n)


def pcapng_file(
    frames: list[tuple[int, bytes]], links: list[int], order: str = "<", simple: int = 0
) -> bytes:
    """A pcapng file: a section header (byte-order magic, 1.0, section length −1), an
    interface description (link type, snaplen 0 = none) per ``links``, a name-resolution
    block (skipped), and an enhanced packet block (interface, timestamp, captured and
    original length, data) per (interface, frame); the first ``simple`` frames as simple
    packet blocks (interface 0)."""
    out = ng_block(pcap.PCAPNG_SHB, struct.pack(order + "IHHq", 0x1A2B3C4D, 1, 0, -1), order)
    for link in links:
        out += ng_block(pcap.PCAPNG_IDB, struct.pack(order + "HHI", link, 0, 0), order)
    out += ng_block(4, struct.pack(order + "HH", 0, 0), order)  # NRB, end of records
    for k, (iface, f) in enumerate(frames):
        if k < simple:
            out += ng_block(pcap.PCAPNG_SPB, struct.pack(order + "I", len(f)) + f, order)
        else:
            head = struct.pack(order + "IIIII", iface, 0, k, len(f), len(f))
            out += ng_block(pcap.PCAPNG_EPB, head + f, order)
    return out


# --------------------------------------------------------------------------------------------
# A scene in a capture
# --------------------------------------------------------------------------------------------


def north(sac: int, sic: int, t: float, period: float | None = None) -> bytes:
    items = {"000": 1, "010": (("SAC", sac), ("SIC", sic)), "030": (t, "s")}
    if period is not None:
        items["041"] = (period, "s")
    return CAT034.create([CAT034.cv_record.create(items)]).unparse().to_bytes()


def sector(sac: int, sic: int, t: float, raw_azimuth: int) -> bytes:
    items = {"000": 2, "010": (("SAC", sac), ("SIC", sic)), "030": (t, "s"), "020": raw_azimuth}
    return CAT034.create([CAT034.cv_record.create(items)]).unparse().to_bytes()


def records_of(data_block: bytes) -> list[bytes]:
    """A CAT048 data block's records' octets (``split_records``)."""
    return [raw for _, raw in ax.split_records(data_block, ax._decoder(), ax._decoder().uap48)]


def as_block(records: list[bytes]) -> bytes:
    body = b"".join(records)
    return bytes([48]) + (3 + len(body)).to_bytes(2, "big") + body


class Scene:
    """A simulated two-radar scene written by ``simulate --format asterix``, its blocks to be
    carried by a capture with what a real feed adds (``payloads``)."""

    def __init__(self, tmp_path: Path):
        self.ast, self.toml = tmp_path / "m.ast", tmp_path / "r.toml"
        argv = ["simulate", "--preset", "fusion", "--out", str(self.ast)]
        assert main([*argv, "--radars-out", str(self.toml), "--scans", "12", "--seed", "3"]) == 0
        self.plots, self.radars = simulated_plots("fusion", 3, 1.0, 12)
        rounded_csv(tmp_path / "m.csv", self.plots, self.radars, None)
        self.csv = tmp_path / "m.csv"
        with open(self.ast, "rb") as fh:
            self.blocks = [b for _, _, b in ax.data_blocks(fh, "m.ast")]
        ids = [(r.sac, r.sic) for r in load_radars(str(self.toml)).values()]
        self.ids = ids

    def payloads(self) -> list[bytes]:
        """UDP payloads: CAT034 first (a north marker with I034/041 4 s for radar 1, plain
        north markers 2.5 s apart and a sector crossing for radar 2), then the CAT048 blocks
        cut to two records each, two blocks to a datagram, with a block of three track-only
        records, and each 5th block's last record sent again after the next block (in a
        block of its own: another packet, some 7 s of plots later, within the duplicates'
        window) and every 7th block whole again."""
        (s1, c1), (s2, c2) = self.ids[:2]
        out = [north(s1, c1, 0.0, 4.0) + north(s2, c2, 0.0), sector(s2, c2, 0.5, 64)]
        out += [north(s2, c2, 2.5), north(s2, c2, 5.0)]
        small = []
        for b in self.blocks:
            rs = records_of(b)
            small += [as_block(rs[k : k + 2]) for k in range(0, len(rs), 2)]
        track_only = CAT048_TRACK_ONLY
        pending: list[bytes] = []
        self.duplicates = 0
        for k, b in enumerate(small):
            out.append(b)
            if k == 1:
                out.append(track_only)
            if pending:
                out.append(pending.pop())
            if k % 5 == 0:
                pending.append(as_block(records_of(b)[-1:]))
                self.duplicates += 1
            if k % 7 == 3:
                out.append(b + north(s2, c2, 7.5) if k == 3 else b)
                self.duplicates += len(records_of(b))
        out += pending
        self.records = sum(len(records_of(b)) for b in small) + self.duplicates + 3
        # two blocks to a datagram: join neighbours (a datagram may carry several blocks)
        joined = [out[i] + out[i + 1] for i in range(0, len(out) - 1, 2)]
        return joined + ([out[-1]] if len(out) % 2 else [])


#: Three track-only CAT048 records (I048/010, /140, /161: no measured position) of SAC 9.
CAT048_TRACK_ONLY = block(
    *({"010": (("SAC", 9), ("SIC", 9)), "140": 128 * k, "161": (0, ("TRN", k))} for k in (1, 2, 3))
)


def framings(payloads: list[bytes]) -> list[tuple[int, bytes]]:
    """Each payload in a frame of its own kind, in turn: Ethernet/IPv4, 802.1Q Ethernet/IPv4
    with IP options, Ethernet/IPv6 with a hop-by-hop header, two VLAN tags; then the frames
    that carry no plots: an ARP frame, an ICMP packet, an IPv4 fragment, a UDP datagram that
    is not ASTERIX. Interface 0 is Ethernet; the SLL and SLL2 frames (interfaces 1, 2) carry
    two payloads."""
    frames: list[tuple[int, bytes]] = []
    for k, p in enumerate(payloads):
        kind = k % 6
        if kind == 0:
            frames.append((0, ethernet(ipv4(udp(p)))))
        elif kind == 1:
            frames.append((0, ethernet(ipv4(udp(p), options=bytes([1, 1, 1, 0])), vlans=1)))
        elif kind == 2:
            frames.append((0, ethernet(ipv6(udp(p), hop_by_hop=True), 0x86DD)))
        elif kind == 3:
            frames.append((0, ethernet(ipv4(udp(p)), vlans=2)))
        elif kind == 4:
            frames.append((1, sll(ipv4(udp(p)), 0x0800)))
        else:
            frames.append((2, sll2(ipv6(udp(p)), 0x86DD)))
    frames.insert(3, (0, ethernet(bytes(28), 0x0806)))  # ARP
    frames.insert(5, (0, ethernet(ipv4(bytes(8), proto=1))))  # ICMP
    frames.insert(7, (0, ethernet(ipv4(udp(b"x" * 20), frag=0x2000))))  # MF: a fragment
    frames.insert(9, (0, ethernet(ipv4(udp(b"\x12\x34\x56 not ASTERIX")))))
    return frames


SKIPPED = {"non_udp": 2, "fragments": 1, "not_asterix": 1}


def as_ethernet_only(frames: list[tuple[int, bytes]]) -> list[bytes]:
    """The frames for a one-link-type pcap: the cooked ones re-framed as Ethernet."""
    out = []
    for iface, f in frames:
        if iface == 1:
            f = ethernet(f[16:], 0x0800)
        elif iface == 2:
            f = ethernet(f[20:], 0x86DD)
        out.append(f)
    return out


def track(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    capsys.readouterr()
    status = main(argv)
    out, err = capsys.readouterr()
    return status, out, err


@pytest.mark.parametrize(
    "container", ["pcap-le-us", "pcap-be-ns", "pcapng-le", "pcapng-be", "pcapng-as-bin"]
)
def test_a_capture_tracks_as_the_csv_does(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], container: str
) -> None:
    scene = Scene(tmp_path)
    frames = framings(scene.payloads())
    if container.startswith("pcapng"):
        order = ">" if "be" in container else "<"
        data = pcapng_file(frames, [1, 113, 276], order, simple=1)
    else:
        data = pcap_file(as_ethernet_only(frames), 1, ">" if "be" in container else "<",
                         ns="ns" in container)  # fmt: skip
    # The name says nothing in the last case: the magic tells the capture.
    cap = tmp_path / ("m.data" if "bin" in container else f"m.{container.split('-')[0]}")
    cap.write_bytes(data)
    assert input_format_of(str(cap)) == "pcap"
    out_c, out_p, summary = tmp_path / "c.csv", tmp_path / "p.csv", tmp_path / "s.json"
    base = ["track", "--radars", str(scene.toml), "--method", "ucm", "ekf", "--model", "cv"]
    assert main([*base, "--input", str(scene.csv), "--out", str(out_c)]) == 0
    status, _, err = track([*base, "--input", str(cap), "--out", str(out_p),
                            "--summary", str(summary)], capsys)  # fmt: skip
    assert status == 0, err
    assert out_p.read_bytes() == out_c.read_bytes()

    counts = json.loads(summary.read_text())["input_counts"]
    skipped = {
        "packets": len(frames),
        "packets_skipped_non_udp": SKIPPED["non_udp"],
        "packets_skipped_fragment": SKIPPED["fragments"],
        "datagrams_skipped_not_asterix": SKIPPED["not_asterix"],
        "records": scene.records,
        "track_only_skipped": 3,
        "duplicates_dropped": scene.duplicates,
    }
    assert {k: counts[k] for k in skipped} == skipped
    assert counts["container"] == ("pcapng" if "pcapng" in container else "pcap")
    names = list(load_radars(str(scene.toml)))
    timing = counts["scan_timing"]
    assert timing[names[0]]["rotation_period_s"] == 4.0
    assert timing[names[0]]["period_from"] == "I034/041"
    assert timing[names[1]] == {
        "rotation_period_s": 2.5,
        "period_from": "north markers",
        "north_crossings": 4,
        "first_north_s": 0.0,
        "last_north_s": 7.5,
        "sector_crossings": 1,
    }
    line = [x for x in err.splitlines() if x.startswith("radarviz: input: ")]
    assert len(line) == 1 and f"{len(frames)} packets" in line[0], err
    assert f"{scene.duplicates} duplicates dropped" in line[0] and "3 track-only" in line[0]


def test_the_reader_tells_the_scan_timing_while_reading(tmp_path: Path) -> None:
    """``reader.scan_timing``: what the CAT034 messages read so far say, a ``ScanTiming``
    per radar (name, period, its source, north times, sector crossings)."""
    rad = parse_radars(RADARS, "r.toml")
    data = (
        north(25, 201, 86399.0)
        + block(rec(128))
        + north(25, 201, 3.0)  # past midnight: 86403
        + sector(25, 201, 4.0, 128)
        + block(rec(256))
        + north(25, 7, 1.0, 6.0)
    )
    reader = ax.AsterixReader(io.BytesIO(pcap_file([ethernet(ipv4(udp(data)))])), "c", rad)
    plots = list(reader)
    assert len(plots) == 2
    assert reader.scan_timing == {
        "north": ax.ScanTiming("north", 4.0, "north markers", (86399.0, 86403.0), 1, 180.0),
        "flat": ax.ScanTiming("flat", 6.0, "I034/041", (86401.0,), 0, None),
    }


# --------------------------------------------------------------------------------------------
# Pieces
# --------------------------------------------------------------------------------------------


def test_duplicates_are_byte_identical_records_within_the_window() -> None:
    recent = ax._RecentRecords(window_s=10.0, size=4)
    assert not recent.repeat(b"a", 100.0) and recent.repeat(b"a", 105.0)
    assert not recent.repeat(b"b", 111.0)  # "a" (100 s) is now out of the window
    assert not recent.repeat(b"a", 111.0)
    assert not recent.repeat(b"c", 105.0)  # a late record ages none
    for k in range(5):  # the count bound
        recent.repeat(bytes([k]), 112.0)
    assert not recent.repeat(b"b", 112.0)
    # Midnight: 86398 then 2.0 are 4 s apart, then 20.0 is 22 s on.
    recent = ax._RecentRecords(window_s=10.0)
    assert not recent.repeat(b"z", 86398.0) and not recent.repeat(b"y", 2.0)
    assert recent.repeat(b"z", 2.0)
    assert not recent.repeat(b"w", 20.0) and not recent.repeat(b"z", 20.0)


def test_a_datagram_of_several_blocks_and_one_that_is_not_asterix() -> None:
    one, two = block(rec(128)), north(25, 201, 1.0)
    assert ax.tiled_blocks(one + two) == [(0, 48, one), (len(one), 34, two)]
    assert ax.tiled_blocks(one + b"\x30") is None and ax.tiled_blocks(b"") is None
    assert ax.tiled_blocks(one[:-1]) is None


def test_the_obsolete_packet_block_and_a_second_section() -> None:
    """pcapng's Packet Block (type 2: interface id (2), drops (2), timestamp (8), captured
    and original length, data), and a second section in the other byte order with its own
    interfaces."""
    payload = block(rec(128))
    frame = ethernet(ipv4(udp(payload)))
    pb = ng_block(2, struct.pack("<HHIIII", 0, 0, 0, 0, len(frame), len(frame)) + frame, "<")
    first = pcapng_file([], [pcap.LINK_ETHERNET], "<") + pb
    cooked = sll(ipv4(udp(payload)), 0x0800)
    second = pcapng_file([(0, cooked)], [pcap.LINK_SLL], ">")
    counts = pcap.CaptureCounts()
    got = list(pcap.udp_datagrams(io.BytesIO(first + second), "c", counts))
    assert [(d.packet, d.payload) for d in got] == [(1, payload), (2, payload)]
    epb = ng_block(pcap.PCAPNG_EPB, bytes(20) + cooked, ">")  # the last block
    assert got[1].packet_offset == len(first) + len(second) - len(epb)


def test_link_types_and_skips() -> None:
    payload = block(rec(128))
    cases = [
        (pcap.LINK_RAW, ipv4(udp(payload))),
        (pcap.LINK_RAW, ipv6(udp(payload))),
        (pcap.LINK_IPV4, ipv4(udp(payload), options=bytes(8))),
        (pcap.LINK_IPV6, ipv6(udp(payload), hop_by_hop=True)),
        (pcap.LINK_SLL, sll(ipv4(udp(payload)), 0x0800)),
        (pcap.LINK_SLL2, sll2(ipv4(udp(payload)), 0x0800)),
    ]
    for link, frame in cases:
        counts = pcap.CaptureCounts()
        got = list(pcap.udp_datagrams(io.BytesIO(pcap_file([frame], link)), "c", counts))
        assert [d.payload for d in got] == [payload], link
        assert got[0].offset == 24 + 16 + len(frame) - len(payload)
    frames = [
        ethernet(ipv4(udp(payload), proto=6)),  # TCP
        ethernet(ipv6(bytes(8), nxt=58), 0x86DD),  # ICMPv6
        ethernet(ipv4(udp(payload), frag=5)),  # a later fragment
    ]
    counts = pcap.CaptureCounts()
    assert list(pcap.udp_datagrams(io.BytesIO(pcap_file(frames)), "c", counts)) == []
    assert counts == pcap.CaptureCounts(packets=3, udp_datagrams=0, non_udp=2, fragments=1)


# --------------------------------------------------------------------------------------------
# The association takes the radars' track numbers
# --------------------------------------------------------------------------------------------


def test_associate_takes_track_numbers_into_their_own_column(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The crossing scene associated from its CSV; its plots then labelled with the track
    ids found, as I048/161 numbers, in an ASTERIX file and a capture: associated again, each
    gives the CSV's track file with the numbers in a column of their own (the association
    does not use them), and without ``--associate`` the numbers are the targets."""
    m, toml = tmp_path / "m.csv", tmp_path / "r.toml"
    argv = ["simulate", "--preset", "crossing", "--out", str(m), "--radars-out", str(toml)]
    assert main([*argv, "--scans", "20"]) == 0
    rad = load_radars(str(toml))
    plots = [p for _, p in PlotReader(m.read_text().splitlines(), str(m), rad)]
    radar_list = ax.with_source_ids(list(rad.values()))
    rounded_csv(tmp_path / "q.csv", plots, radar_list, None)
    gnn = ["--method", "ucm", "--model", "cv", "--associate", "gnn"]
    base = ["track", "--radars", str(toml), *gnn]
    out_c = tmp_path / "c.csv"
    assert main([*base, "--input", str(tmp_path / "q.csv"), "--out", str(out_c)]) == 0
    with open(out_c, newline="") as fh:
        expected = list(csv.DictReader(fh))
    assert len(expected) == len(plots) and len({r["target"] for r in expected}) >= 2
    labelled = [replace(p, target=r["target"]) for p, r in zip(plots, expected, strict=True)]
    ast = tmp_path / "m.ast"
    ax.write_asterix(str(ast), str(toml), labelled, radar_list)
    cap = tmp_path / "m.pcapng"
    frames = [(0, ethernet(ipv4(udp(b)))) for b in ax.encode_plots(labelled, radar_list)]
    cap.write_bytes(pcapng_file(frames, [1]))
    for source in (ast, cap):
        out = tmp_path / "t.csv"
        status, _, err = track([*base, "--input", str(source), "--out", str(out)], capsys)
        assert status == 0, err
        with open(out, newline="") as fh:
            rows = list(csv.DictReader(fh))
        assert list(rows[0])[:4] == ["time_s", "target", "status", "radar_track_number"]
        assert [r.pop("radar_track_number") for r in rows] == [r["target"] for r in expected]
        assert rows == expected
        # Parquet: the numbers as int64.
        pq_out = tmp_path / "t.parquet"
        status, _, err = track([*base, "--input", str(source), "--out", str(pq_out)], capsys)
        assert status == 0, err
        table = pyarrow.parquet.read_table(pq_out)
        assert str(table.schema.field("radar_track_number").type) == "int64"
        assert table.column("radar_track_number").to_pylist() == [
            int(r["target"]) for r in expected
        ]
        # Without --associate the numbers are the labels, as before.
        status, _, err = track([*base[:-2], "--input", str(source), "--out", str(out)], capsys)
        assert status == 0, err
        with open(out, newline="") as fh:
            assert next(csv.reader(fh))[:3] == ["time_s", "target", "method"]


# --------------------------------------------------------------------------------------------
# Bad captures
# --------------------------------------------------------------------------------------------

GOOD_FRAME = ethernet(ipv4(udp(block(rec(128), rec(256)))))
#: The second packet's byte offset in a pcap file, and its UDP payload's.
P2 = 24 + 16 + len(GOOD_FRAME)
P2_DATA = P2 + 16 + 14 + 20 + 8


#: A record of a data source no radar has.
STRANGER = rec(512) | {"010": (("SAC", 9), ("SIC", 9))}


def cut_snap() -> bytes:
    f = ethernet(ipv4(udp(block(*(rec(128 * k) for k in range(1, 30))))))
    return pcap_file([GOOD_FRAME, f[:100]])


BAD = {
    "no ASTERIX": (
        lambda: pcap_file([ethernet(ipv4(udp(b"\x12\x34\x56"))), ethernet(bytes(28), 0x0806)]),
        "no CAT048 target reports (0 CAT048 records, 0 of them track-only; 2 packets: 1 UDP "
        "datagrams, 1 of them not ASTERIX, 1 not UDP, 0 IP fragments; the first datagram not "
        "ASTERIX: packet 1 (byte 24))",
    ),
    "truncated packet": (
        lambda: pcap_file([GOOD_FRAME, GOOD_FRAME])[:-10],
        f"packet 2 (byte {P2}): truncated (it needs "
        f"{16 + len(GOOD_FRAME)} octets, the file ends {6 + len(GOOD_FRAME)} after its start)",
    ),
    "truncated pcapng block": (
        lambda: pcapng_file([(0, GOOD_FRAME)] * 2, [1])[:-3],
        "packet 2 (byte ",
    ),
    "unknown link type": (
        lambda: pcap_file([GOOD_FRAME], link=147),
        "packet 1 (byte 24): link type 147 is not read (link types read: 1 Ethernet",
    ),
    "unknown link type of an interface": (
        lambda: pcapng_file([(0, GOOD_FRAME), (1, GOOD_FRAME)], [1, 147]),
        "packet 2 (byte ",
    ),
    "snap length": (cut_snap, f"packet 2 (byte {P2}): truncated: IPv4 total length"),
    "bad data block in a packet": (
        lambda: pcap_file([GOOD_FRAME, ethernet(ipv4(udp(bytes([48, 0, 4, 0b1000_0000]))))]),
        f"packet 2 (byte {P2}), data block at byte {P2_DATA}: CAT048 data block (LEN 4) does "
        "not decode",
    ),
    "unknown source in a one-record block": (
        lambda: pcap_file([GOOD_FRAME, ethernet(ipv4(udp(block(STRANGER))))]),
        f"packet 2 (byte {P2}), data block at byte {P2_DATA}, record 1, item I048/010: unknown "
        "data source SAC 9 SIC 9",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_captures_exit_2_one_line_naming_the_packet(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str
) -> None:
    make, expected = BAD[case]
    (tmp_path / "m.pcap").write_bytes(make())
    (tmp_path / "r.toml").write_text(RADARS)
    argv = ["track", "--input", str(tmp_path / "m.pcap"), "--radars", str(tmp_path / "r.toml")]
    for extra in ([], ["--associate", "gnn"], ["--summary", str(tmp_path / "s.json")]):
        status, out, err = track([*argv, "--out", str(tmp_path / "t.csv"), *extra], capsys)
        assert status == 2 and out == "", err
        assert err.count("\n") == 1 and err.startswith("radarviz: error: "), err
        assert f"m.pcap {expected}" in err or expected in err, err
        assert sorted(p.name for p in tmp_path.iterdir()) == ["m.pcap", "r.toml"]


def test_format_pcap_refuses_a_file_that_is_not_a_capture(tmp_path: Path) -> None:
    """``--format pcap`` reads captures only; ``--format asterix`` still knows one by its
    magic (a capture is never read as data blocks)."""
    rad = parse_radars(RADARS, "r.toml")
    with pytest.raises(ParameterError, match=r"f byte 0: not a pcap or pcapng capture"):
        ax.capture_reader(io.BytesIO(block(rec(128))), "f", rad)
    (tmp_path / "m.bin").write_bytes(pcap_file([GOOD_FRAME]))
    (tmp_path / "r.toml").write_text(RADARS)
    argv = ["track", "--input", str(tmp_path / "m.bin"), "--radars", str(tmp_path / "r.toml")]
    for fmt in ("asterix", "pcap", "auto"):
        out = tmp_path / f"{fmt}.csv"
        assert main([*argv, "--format", fmt, "--out", str(out), "--method", "ucm"]) == 0
        assert len(out.read_text().splitlines()) == 3


def test_reading_a_capture_holds_memory_flat(tmp_path: Path) -> None:
    """The peak of Python's allocations while reading a capture (no plot kept) is the same for
    one four times longer: a packet at a time, the duplicates' window and the packets named
    for errors bounded."""
    import tracemalloc

    frames = [
        ethernet(ipv4(udp(block(rec(128 * (2 * j + 1), 2560), rec(128 * (2 * j + 2), 2561)))))
        for j in range(4 * ax.NAMED_BLOCKS + 2000)
    ]
    short, long = tmp_path / "short.pcap", tmp_path / "long.pcap"
    short.write_bytes(pcap_file(frames[: ax.NAMED_BLOCKS + 500]))
    long.write_bytes(pcap_file(frames))
    peaks = []
    for path in (short, short, long):  # the first pass warms up (one-time allocations)
        with open(path, "rb") as fh:
            tracemalloc.start()
            reader = ax.AsterixReader(fh, "c.pcap", parse_radars(RADARS, "r.toml"))
            n = sum(1 for _ in reader)
            peaks.append(tracemalloc.get_traced_memory()[1])
            tracemalloc.stop()
        assert n == 2 * (len(path.read_bytes()) - 24) // (16 + len(frames[0]))
    assert peaks[2] < peaks[1] + 4096, peaks
    assert peaks[2] < long.stat().st_size / 4, (peaks, long.stat().st_size)


def test_association_takes_the_antenna_period_from_cat034(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """With ``--associate`` the CAT034 period of a radar (I034/041, or its north markers)
    replaces the one the association would estimate from its plots: the summary's
    ``association`` section lists no estimated period for the two radars CAT034 times, while
    the third radar's is left to its plots (12 scans: too few revisits to tell, null)."""
    scene = Scene(tmp_path)
    cap = tmp_path / "m.pcapng"
    cap.write_bytes(pcapng_file(framings(scene.payloads()), [1, 113, 276], "<", simple=1))
    summary = tmp_path / "s.json"
    argv = ["track", "--radars", str(scene.toml), "--method", "ucm", "--associate", "gnn"]
    status, _, err = track(
        [*argv, "--input", str(cap), "--out", str(tmp_path / "t.csv"), "--summary", str(summary)],
        capsys,
    )
    assert status == 0, err
    est = json.loads(summary.read_text())["association"]["radars"]
    names = list(load_radars(str(scene.toml)))
    for name in names[:2]:
        assert "rotation_period_s" not in est[name]["estimated"], name
    assert "rotation_period_s" in est[names[2]]["estimated"]
