"""``radarviz replay``: a recorded ASTERIX feed sent again as UDP datagrams, at its own pace.

A radar feed is a stream of UDP datagrams; a recording of it is a packet capture (pcap or
pcapng, ``viz_app.io.pcap``) or a file of data blocks (``.ast``, ``viz_app.io.asterix``).
Replaying one turns the recording back into a feed, so ``radarviz live`` (or any receiver)
can be exercised on a known input:

* a capture: one datagram per captured UDP packet, its payload as captured, sent at the
  packet's capture time (the pcap record's or pcapng block's timestamp);
* a data-block file: one datagram per data block, sent at the time of day (I048/140 or
  I034/030) of the block's first record, taken on one running day as the reader does
  (``asterix._DayClock``: a feed crossing midnight keeps its pace). A block without a time
  (another category) goes with the previous one.

The pace is the recording's, ``speed`` times faster: datagram k leaves at
``start + (t_k − t_0) / speed`` on the monotonic clock, so a late wake-up is caught up on
the next datagram instead of accumulating. A time going backwards (a capture merged from two
interfaces) sends at once. Nothing here decodes more than a block's first record.
"""

from __future__ import annotations

import ipaddress
import socket
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import IO, NamedTuple

from radarviz.core.params import ParameterError, check_real
from radarviz.viz_app.io.asterix import (
    CAT034,
    CATEGORY,
    _DayClock,
    _decoder,
    _head,
    data_blocks,
)
from radarviz.viz_app.io.pcap import CaptureCounts, is_capture, udp_datagrams

#: Fastest replay asked for (×): beyond it the pace is the socket's, not the recording's.
MAX_SPEED = 10_000.0
#: Multicast hops of a replayed datagram: the local network only.
MULTICAST_TTL = 1


class Address(NamedTuple):
    """A UDP address: ``host`` (an IPv4 address), ``port``."""

    host: str
    port: int

    def __str__(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def loopback(self) -> bool:
        """Whether the address stays on this machine."""
        return ipaddress.ip_address(self.host).is_loopback

    @property
    def multicast(self) -> bool:
        """Whether the address is a multicast group (224.0.0.0/4)."""
        return ipaddress.ip_address(self.host).is_multicast


def parse_address(flag: str, text: str) -> Address:
    """``HOST:PORT`` → ``Address``: the host an IPv4 address or a name of this network (resolved
    here, once), the port in [1, 65535]; anything else a ``ParameterError`` naming ``flag``."""
    host, sep, port_text = text.rpartition(":")
    if not sep or not host:
        raise ParameterError(f"{flag} must be HOST:PORT (got {text!r})")
    try:
        port = int(port_text)
    except ValueError:
        port = -1
    if not 1 <= port <= 65535:
        raise ParameterError(f"{flag} port must be in [1, 65535] (got {port_text!r})")
    try:
        resolved = socket.gethostbyname(host)
    except OSError:
        raise ParameterError(f"{flag} host {host!r} is not an IPv4 address or known name") from None
    return Address(resolved, port)


class Record(NamedTuple):
    """One datagram to send: its time on the recording's clock (s; None: with the previous
    one) and its octets."""

    time_s: float | None
    payload: bytes


def capture_records(fh: IO[bytes], source: str, head: bytes) -> Iterator[Record]:
    """A capture's UDP payloads, each at its packet's capture time."""
    for dg in udp_datagrams(fh, source, CaptureCounts(), head):
        yield Record(dg.time_s, dg.payload)


def block_records(fh: IO[bytes], source: str, head: bytes) -> Iterator[Record]:
    """A data-block file's blocks, each at its first record's time of day on one running day
    (the module docstring)."""
    parser = _decoder()
    uaps = {CATEGORY: parser.uap48, CAT034: parser.uap34}
    clock = _DayClock()
    for offset, cat, block in data_blocks(fh, source, head):
        t = None
        uap = uaps.get(cat)
        if uap is not None and len(block) > 3:
            try:
                rec, _ = parser.parse_record(block, 3, uap=uap, block_end=len(block))
            except parser.malformed as exc:
                raise ParameterError(
                    f"{source} byte {offset}: CAT{cat:03d} data block does not decode: {exc}"
                ) from None
            tod = rec.get("time_of_day")
            if tod is not None:
                try:
                    t = clock(tod)
                except ValueError as exc:
                    raise ParameterError(f"{source} byte {offset}: {exc}") from None
        yield Record(t, block)


def recorded_feed(fh: IO[bytes], source: str) -> Iterator[Record]:
    """The datagrams of a recording: a capture by its magic, else a file of data blocks."""
    head = _head(fh, 12)
    if is_capture(head):
        return capture_records(fh, source, head)
    return block_records(fh, source, head)


@dataclass
class ReplayCounts:
    """What a replay sent: ``datagrams``, ``octets``, the recording's time span (s), and
    ``refused``: sends the address answered with "port unreachable" (nothing listens there)."""

    datagrams: int = 0
    octets: int = 0
    span_s: float = 0.0
    refused: int = 0


def paced(
    records: Iterator[Record],
    speed: float,
    send: Callable[[bytes], bool],
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
    on_refused: Callable[[], None] = lambda: None,
) -> ReplayCounts:
    """Hand each record's payload to ``send`` at ``start + (t − t₀) / speed`` (module
    docstring); returns the counts. ``send`` returns False when the address refused it:
    counted, ``on_refused`` called on the first, and the replay goes on (a receiver may
    start late)."""
    check_real("--speed", speed, low=0.0, high=MAX_SPEED)
    counts = ReplayCounts()
    start = clock()
    first: float | None = None
    last: float | None = None
    for record in records:
        t = record.time_s if record.time_s is not None else last
        if t is not None:
            if first is None:
                first = t
            due = start + (t - first) / speed
            wait = due - clock()
            if wait > 0:
                sleep(wait)
            last = t
            counts.span_s = max(counts.span_s, t - first)
        if not send(record.payload):
            counts.refused += 1
            if counts.refused == 1:
                on_refused()
        counts.datagrams += 1
        counts.octets += len(record.payload)
    return counts


def udp_sender(to: Address) -> tuple[socket.socket, Callable[[bytes], bool]]:
    """A UDP socket and its ``send`` of one datagram to ``to``, False when refused
    (multicast: ``MULTICAST_TTL`` hops, and looped back so a receiver on this machine hears
    it). A unicast socket is connected, so the "port unreachable" a host answers to a
    datagram for a closed port comes back as a refusal of a later send instead of being
    dropped unseen, as it is for an unconnected socket."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    target = (to.host, to.port)
    if to.multicast:
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, MULTICAST_TTL)
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)

        def send(payload: bytes) -> bool:
            sock.sendto(payload, target)
            return True

        return sock, send
    sock.connect(target)

    def send_connected(payload: bytes) -> bool:
        try:
            sock.send(payload)
        except ConnectionRefusedError:
            return False
        return True

    return sock, send_connected


def replay(
    path: str, to: Address, speed: float = 1.0, on_refused: Callable[[], None] = lambda: None
) -> ReplayCounts:
    """Send the recording ``path`` to ``to`` at ``speed`` × its pace (module docstring)."""
    check_real("--speed", speed, low=0.0, high=MAX_SPEED)
    with open(path, "rb") as fh:
        sock, send = udp_sender(to)
        with sock:
            return paced(recorded_feed(fh, path), speed, send, on_refused=on_refused)
