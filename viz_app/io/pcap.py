"""UDP payloads of a packet capture: classic pcap and pcapng, read a packet at a time.

A radar's ASTERIX feed travels as UDP datagrams, and a recording of it is usually a packet
capture. This module turns a capture into its UDP payloads, with ``struct`` alone (no pcap
library: the formats needed are small, and a packet at a time keeps memory flat).

**Classic pcap** (``FILE_MAGICS``): a 24-octet file header ``magic (4) version_major (2)
version_minor (2) thiszone (4) sigfigs (4) snaplen (4) linktype (4)``, then per packet a
16-octet record header ``ts_sec (4) ts_frac (4) incl_len (4) orig_len (4)`` and ``incl_len``
captured octets. The magic, read little-endian, tells the byte order of every later field:
``0xA1B2C3D4`` (microsecond times) or ``0xA1B23C4D`` (nanosecond), and byte-swapped when the
writer was big-endian. The link type is the low 16 bits of its field (the upper bits may hold
a frame check sequence length; the trailing FCS octets lie past the IP packet, so they are
ignored by construction).

**pcapng**: a sequence of blocks ``type (4) total_length (4) body… total_length (4)``, the
length a multiple of 4 including the 12 framing octets. A Section Header Block (type
``0x0A0D0D0A``) starts each section; its body begins with the byte-order magic
``0x1A2B3C4D`` written in the section's byte order, which every later field of the section
follows. Interface Description Blocks (type 1: ``linktype (2) reserved (2) snaplen (4)
options``) are numbered from 0 in each section, and each packet names its interface, so each
packet has its interface's link type. Packets are the Enhanced Packet Block (type 6:
``interface_id (4) ts_high (4) ts_low (4) captured_len (4) original_len (4) data, padded to
4``), the Simple Packet Block (type 3: ``original_len (4) data``, interface 0, captured
length the smaller of ``original_len`` and the block's room) and the obsolete Packet Block
(type 2: ``interface_id (2) drops (2) ts (8) captured_len (4) original_len (4) data``). Other
blocks (name resolution, statistics, custom…) are skipped.

**Times.** Each datagram carries its packet's capture time (``Datagram.time_s``, s since the
epoch): a pcap record's ``ts_sec + ts_frac`` (µs or ns by the magic), a pcapng packet's 64-bit
timestamp in its interface's unit (the IDB option ``if_tsresol``, µs by default); a Simple
Packet Block has none (None). ``radarviz replay`` paces a capture by them.

**Link layers** (``LINK_TYPES``): Ethernet (1), with any number of 802.1Q / 802.1ad VLAN tags
(``0x8100``, ``0x88A8``, ``0x9100``: 4 octets each, TCI then the next EtherType); Linux cooked
capture SLL (113: 16 octets, the protocol at octet 14) and SLL2 (276: 20 octets, the protocol
at octet 0); raw IP (101, by the version nibble), raw IPv4 (228), raw IPv6 (229).

**Network and transport**: IPv4 (header length IHL × 4 octets, so options are passed over;
the packet bounded by its total length, so Ethernet padding is not read as payload) and IPv6
(40 octets, then the hop-by-hop, routing, destination-options and authentication extension
headers passed over). UDP (protocol 17): an 8-octet header ``src_port dst_port length
checksum``, the payload ``length − 8`` octets. A fragment (IPv4 MF set or a fragment offset;
an IPv6 fragment header) is skipped and counted: only the first fragment has the UDP header
and reassembly would hold packets in memory (ASTERIX datagrams fit one Ethernet frame). A
packet that is not IP, or IP but not UDP, is skipped and counted.

**Bad input** is a ``ParameterError`` line naming the packet, its number from 1 (as
Wireshark's frame numbers) and the byte offset of its record or block in the file: a packet
or block the file ends inside (truncated), a captured length beyond ``MAX_PACKET_BYTES``
(corrupt), an IP or UDP length beyond the captured octets (the capture's snap length cut the
datagram), a link type of none of the above.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import IO, NamedTuple

from radarviz.core.params import ParameterError

#: Classic pcap magics as read little-endian: byte order, and whether times are in ns.
PCAP_MAGIC_US = 0xA1B2C3D4
PCAP_MAGIC_NS = 0xA1B23C4D
#: The first four octets of a classic pcap file (both byte orders, µs and ns).
FILE_MAGICS = (
    PCAP_MAGIC_US.to_bytes(4, "little"),
    PCAP_MAGIC_US.to_bytes(4, "big"),
    PCAP_MAGIC_NS.to_bytes(4, "little"),
    PCAP_MAGIC_NS.to_bytes(4, "big"),
)
#: pcapng: the Section Header Block's type (a palindrome: the same in both byte orders) and
#: the byte-order magic that follows its length.
PCAPNG_SHB = 0x0A0D0D0A
PCAPNG_BYTE_ORDER = 0x1A2B3C4D
PCAPNG_IDB, PCAPNG_PB, PCAPNG_SPB, PCAPNG_EPB = 1, 2, 3, 6
#: The link types read (``linktype`` values of the pcap and pcapng headers).
LINK_ETHERNET, LINK_RAW, LINK_SLL, LINK_IPV4, LINK_IPV6, LINK_SLL2 = 1, 101, 113, 228, 229, 276
LINK_TYPES = {
    LINK_ETHERNET: "Ethernet",
    LINK_RAW: "raw IP",
    LINK_SLL: "Linux cooked (SLL)",
    LINK_IPV4: "raw IPv4",
    LINK_IPV6: "raw IPv6",
    LINK_SLL2: "Linux cooked v2 (SLL2)",
}
ETHERTYPE_IPV4, ETHERTYPE_IPV6 = 0x0800, 0x86DD
#: EtherTypes of a VLAN tag (802.1Q, 802.1ad, the older QinQ value).
VLAN_TAGS = (0x8100, 0x88A8, 0x9100)
IPPROTO_UDP = 17
#: IPv6 extension headers passed over (hop-by-hop, routing, destination options) and the
#: fragment and authentication headers.
IPV6_EXTENSIONS = (0, 43, 60)
IPV6_FRAGMENT, IPV6_AUTH = 44, 51
#: A captured length beyond this is corrupt (the largest IP packet is 64 KiB; pcapng allows
#: more on paper, and a bad length must not make the reader allocate gigabytes).
MAX_PACKET_BYTES = 1 << 18
#: The largest pcapng block read (a packet block holds one packet and its options).
MAX_BLOCK_BYTES = MAX_PACKET_BYTES + (1 << 16)


def is_capture(head: bytes) -> bool:
    """Whether a file starting with ``head`` (at least its first 12 octets) is a pcap or
    pcapng capture, by its magic: a classic pcap magic, or a Section Header Block type
    followed by the byte-order magic in either byte order."""
    if head[:4] in FILE_MAGICS:
        return True
    return head[:4] == PCAPNG_SHB.to_bytes(4, "big") and head[8:12] in (
        PCAPNG_BYTE_ORDER.to_bytes(4, "big"),
        PCAPNG_BYTE_ORDER.to_bytes(4, "little"),
    )


@dataclass
class CaptureCounts:
    """What a capture held, counted as it is read: ``packets`` in all; of them
    ``udp_datagrams`` (whole UDP payloads handed on), ``non_udp`` (not IP, or IP but not UDP)
    and ``fragments`` (IP fragments), all skipped but the first."""

    packets: int = 0
    udp_datagrams: int = 0
    non_udp: int = 0
    fragments: int = 0


class Datagram(NamedTuple):
    """A UDP payload: the packet's number (from 1), the byte offset of the packet's record or
    block in the file, the byte offset of the payload in the file, the payload, and the
    packet's capture time (s since the epoch; None for a pcapng Simple Packet Block, which
    has none)."""

    packet: int
    packet_offset: int
    offset: int
    payload: bytes
    time_s: float | None = None


def packet_place(packet: int, offset: int) -> str:
    """How an error names a packet: "packet N (byte B)"."""
    return f"packet {packet} (byte {offset})"


def packet_name(source: str, packet: int, offset: int) -> str:
    """A packet of the capture ``source``: "SOURCE packet N (byte B)"."""
    return f"{source} {packet_place(packet, offset)}"


def udp_datagrams(
    fh: IO[bytes], source: str, counts: CaptureCounts, head: bytes = b""
) -> Iterator[Datagram]:
    """The UDP payloads of the capture ``fh`` (``head``: octets already read from its start),
    in file order, a packet at a time; ``counts`` is updated as packets are read."""
    reader = _Reader(fh, head)
    start = reader.peek(12)
    if start[:4] in FILE_MAGICS:
        packets = _pcap_packets(reader, source)
    elif is_capture(start):
        packets = _pcapng_packets(reader, source)
    else:
        raise ParameterError(
            f"{source} byte 0: not a pcap or pcapng capture (its first octets are "
            f"{start[:4].hex() or 'none'}; a capture starts with a pcap magic or a pcapng "
            "section header)"
        )
    for number, offset, link, data_offset, data, time_s in packets:
        counts.packets = number
        got = _udp_payload(link, data)
        if isinstance(got, str):
            if got == "fragment":
                counts.fragments += 1
            elif got == "non-udp":
                counts.non_udp += 1
            else:
                raise ParameterError(f"{packet_name(source, number, offset)}: {got}")
            continue
        start_in_data, payload = got
        counts.udp_datagrams += 1
        yield Datagram(number, offset, data_offset + start_in_data, payload, time_s)


class _Reader:
    """Exact reads from a binary file that may be a pipe (no seek), with the file offset."""

    def __init__(self, fh: IO[bytes], head: bytes):
        self.fh = fh
        self.buf = head
        self.offset = 0  # of buf[0] in the file

    def peek(self, n: int) -> bytes:
        while len(self.buf) < n:
            chunk = self.fh.read(n - len(self.buf))
            if not chunk:
                break
            self.buf += chunk
        return self.buf[:n]

    def take(self, n: int) -> bytes:
        got = self.peek(n)
        self.buf = self.buf[len(got) :]
        self.offset += len(got)
        return got


def _truncated(source: str, what: str, offset: int, need: int, got: int) -> ParameterError:
    return ParameterError(
        f"{source} {what}: truncated (it needs {need} octets, the file ends {got} after its start)"
    )


#: number, offset, link type, data offset, data, capture time (s) or None
_Packet = tuple[int, int, int, int, bytes, float | None]


def _pcap_packets(reader: _Reader, source: str) -> Iterator[_Packet]:
    """The packets of a classic pcap file (module docstring)."""
    header = reader.take(24)
    if len(header) < 24:
        raise _truncated(source, "byte 0, the pcap file header", 0, 24, len(header))
    order = "<" if header[:4] in (FILE_MAGICS[0], FILE_MAGICS[2]) else ">"
    link = struct.unpack(order + "I", header[20:24])[0] & 0xFFFF
    # The nanosecond magic's second field counts nanoseconds, the other's microseconds.
    frac_s = 1e-9 if header[:4] in (FILE_MAGICS[1], FILE_MAGICS[3]) else 1e-6
    record = struct.Struct(order + "IIII")
    number = 0
    while True:
        offset = reader.offset
        raw = reader.take(16)
        if not raw:
            return
        number += 1
        where = packet_name(source, number, offset)
        if len(raw) < 16:
            raise _truncated(source, f"packet {number} (byte {offset}), its record header",
                             offset, 16, len(raw))  # fmt: skip
        ts_sec, ts_frac, incl_len, _ = record.unpack(raw)
        if incl_len > MAX_PACKET_BYTES:
            raise ParameterError(
                f"{where}: captured length {incl_len} is beyond {MAX_PACKET_BYTES} octets "
                "(corrupt, or not a pcap file)"
            )
        data = reader.take(incl_len)
        if len(data) < incl_len:
            raise _truncated(source, f"packet {number} (byte {offset})", offset,
                             16 + incl_len, 16 + len(data))  # fmt: skip
        yield number, offset, link, offset + 16, data, ts_sec + ts_frac * frac_s


def _pcapng_packets(reader: _Reader, source: str) -> Iterator[_Packet]:
    """The packets of a pcapng file (module docstring), each with its interface's link type."""
    order = "<"
    links: list[int] = []
    units: list[float] = []  # each interface's timestamp unit (s)
    number = 0
    while True:
        offset = reader.offset
        head = reader.peek(12)
        if not head:
            return
        if len(head) < 8:
            raise _truncated(source, f"byte {offset}, a pcapng block header", offset, 8,
                             len(head))  # fmt: skip
        if head[:4] == PCAPNG_SHB.to_bytes(4, "big"):
            magic = head[8:12]
            if magic == PCAPNG_BYTE_ORDER.to_bytes(4, "big"):
                order = ">"
            elif magic == PCAPNG_BYTE_ORDER.to_bytes(4, "little"):
                order = "<"
            else:
                raise ParameterError(
                    f"{source} byte {offset}: pcapng section header without the byte-order "
                    f"magic (got {magic.hex()})"
                )
            links = []  # interfaces are numbered per section
            units = []
        kind, length = struct.unpack(order + "II", head[:8])
        is_packet = kind in (PCAPNG_EPB, PCAPNG_SPB, PCAPNG_PB)
        what = f"packet {number + 1} (byte {offset})" if is_packet else f"byte {offset}"
        if length < 12 or length % 4 or length > MAX_BLOCK_BYTES:
            raise ParameterError(
                f"{source} {what}: pcapng block of type {kind:#x} has total length {length} "
                f"(a multiple of 4 in [12, {MAX_BLOCK_BYTES}]; corrupt)"
            )
        block = reader.take(length)
        if len(block) < length:
            raise _truncated(source, what, offset, length, len(block))
        body = block[8:-4]
        if kind == PCAPNG_IDB:
            if len(body) < 8:
                raise ParameterError(f"{source} {what}: interface description block too short")
            links.append(struct.unpack(order + "H", body[:2])[0])
            units.append(_tsresol(body[8:], order))
            continue
        if not is_packet:
            continue  # name resolution, statistics, custom blocks: nothing to read
        number += 1
        stamp: int | None = None
        if kind == PCAPNG_EPB:
            fields, iface, high, low, cap_len = 20, *struct.unpack(order + "IIII", body[:16])
            stamp = high << 32 | low
        elif kind == PCAPNG_PB:
            fields, iface, high, low, cap_len = 20, *struct.unpack(order + "H2xIII", body[:16])
            stamp = high << 32 | low
        else:  # SPB: interface 0, the captured length bounded by the block, no timestamp
            fields, iface = 4, 0
            cap_len = min(struct.unpack(order + "I", body[:4])[0], len(body) - 4)
        if iface >= len(links):
            raise ParameterError(
                f"{source} {what}: names interface {iface}, and the section describes "
                f"{len(links)} (an interface description block must come first)"
            )
        if fields + cap_len > len(body):
            raise ParameterError(
                f"{source} {what}: captured length {cap_len} runs past its block "
                f"({len(body) - fields} octets of data; corrupt)"
            )
        time_s = None if stamp is None else stamp * units[iface]
        yield (
            number,
            offset,
            links[iface],
            offset + 8 + fields,
            body[fields : fields + cap_len],
            time_s,
        )


#: pcapng's Interface Description Block option ``if_tsresol`` (its timestamps' unit).
IF_TSRESOL = 9


def _tsresol(options: bytes, order: str) -> float:
    """An interface's timestamp unit (s) from its IDB options: ``if_tsresol`` (one octet: 10⁻ⁿ,
    or 2⁻ⁿ with the top bit set), else the format's default, microseconds."""
    pos = 0
    while pos + 4 <= len(options):
        code, length = struct.unpack(order + "HH", options[pos : pos + 4])
        if code == 0:  # opt_endofopt
            break
        if code == IF_TSRESOL and length >= 1 and pos + 5 <= len(options):
            v = options[pos + 4]
            return 2.0 ** -(v & 0x7F) if v & 0x80 else 10.0**-v
        pos += 4 + (length + 3) // 4 * 4
    return 1e-6


def _udp_payload(link: int, data: bytes) -> tuple[int, bytes] | str:
    """(the payload's offset in ``data``, the UDP payload) of one packet, or why there is
    none: "fragment", "non-udp", or an error's words (a truncated datagram, an unknown link
    type)."""
    if link == LINK_ETHERNET:
        pos, ethertype = 14, _u16(data, 12)
        while ethertype in VLAN_TAGS:
            ethertype, pos = _u16(data, pos + 2), pos + 4
    elif link == LINK_SLL:
        pos, ethertype = 16, _u16(data, 14)
    elif link == LINK_SLL2:
        pos, ethertype = 20, _u16(data, 0)
    elif link in (LINK_RAW, LINK_IPV4, LINK_IPV6):
        pos = 0
        version = data[0] >> 4 if data else 0
        ethertype = {4: ETHERTYPE_IPV4, 6: ETHERTYPE_IPV6}.get(version, -1)
    else:
        known = ", ".join(f"{k} {v}" for k, v in LINK_TYPES.items())
        return f"link type {link} is not read (link types read: {known})"
    if ethertype is None or pos > len(data):
        return f"truncated: {len(data)} octets captured, under the link-layer header"
    if ethertype == ETHERTYPE_IPV4:
        return _ipv4(data, pos)
    if ethertype == ETHERTYPE_IPV6:
        return _ipv6(data, pos)
    return "non-udp"


def _u16(data: bytes, pos: int) -> int | None:
    return int.from_bytes(data[pos : pos + 2], "big") if pos + 2 <= len(data) else None


def _ipv4(data: bytes, pos: int) -> tuple[int, bytes] | str:
    if len(data) < pos + 20:
        return f"truncated: the IPv4 header needs 20 octets, {len(data) - pos} captured"
    ihl = (data[pos] & 0x0F) * 4
    total = int.from_bytes(data[pos + 2 : pos + 4], "big")
    if data[pos] >> 4 != 4 or ihl < 20 or total < ihl:
        return f"IPv4 header with version {data[pos] >> 4}, IHL {ihl}, total length {total}"
    if pos + total > len(data):
        return (
            f"truncated: IPv4 total length {total}, {len(data) - pos} octets captured (the "
            "capture's snap length cut the packet?)"
        )
    flags_offset = int.from_bytes(data[pos + 6 : pos + 8], "big")
    if flags_offset & 0x3FFF:  # MF, or a fragment offset
        return "fragment"
    if data[pos + 9] != IPPROTO_UDP:
        return "non-udp"
    return _udp(data, pos + ihl, pos + total)


def _ipv6(data: bytes, pos: int) -> tuple[int, bytes] | str:
    if len(data) < pos + 40:
        return f"truncated: the IPv6 header needs 40 octets, {len(data) - pos} captured"
    end = pos + 40 + int.from_bytes(data[pos + 4 : pos + 6], "big")
    if end > len(data):
        return (
            f"truncated: IPv6 payload length {end - pos - 40}, {len(data) - pos - 40} octets "
            "captured (the capture's snap length cut the packet?)"
        )
    nxt, pos = data[pos + 6], pos + 40
    while nxt in IPV6_EXTENSIONS or nxt == IPV6_AUTH:
        if pos + 2 > end:
            return "truncated: an IPv6 extension header runs past the packet"
        size = (data[pos + 1] + 2) * 4 if nxt == IPV6_AUTH else (data[pos + 1] + 1) * 8
        nxt, pos = data[pos], pos + size
    if nxt == IPV6_FRAGMENT:
        return "fragment"
    if nxt != IPPROTO_UDP:
        return "non-udp"
    return _udp(data, pos, end)


def _udp(data: bytes, pos: int, end: int) -> tuple[int, bytes] | str:
    if pos + 8 > end:
        return f"truncated: the UDP header needs 8 octets, {max(end - pos, 0)} in the packet"
    length = int.from_bytes(data[pos + 4 : pos + 6], "big")
    if length < 8 or pos + length > end:
        return f"UDP length {length} is outside [8, {end - pos}] (the octets the IP packet has)"
    return pos + 8, data[pos + 8 : pos + length]
