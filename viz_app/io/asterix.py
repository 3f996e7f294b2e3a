"""ASTERIX CAT048 monoradar target reports in (``track``) and out (``simulate``), from a file
of data blocks or a packet capture.

An ASTERIX file is a sequence of data blocks, each ``CAT (1 octet) LEN (2 octets, the block's
length with this header) records…``; a CAT048 record is an FSPEC (presence bits in the order
of the category's user application profile, UAP) followed by the items it announces. The
records are decoded by ``pyobelix`` (CAT048 edition 1.32, CAT034 1.29) and written by
``libasterix`` (``asterix.generated.Cat_048_1_32``); this module only frames the file into
data blocks (to name byte offsets and to keep memory flat) and turns the decoded items into
plots.

**Captures.** A file starting with a pcap or pcapng magic (``viz_app.io.pcap``) is a capture:
its UDP payloads are read a packet at a time, each one a run of data blocks that must tile it
(else the datagram is not ASTERIX: skipped and counted). A block's byte offset is then its
offset in the capture file, and errors name its packet too (number from 1, byte offset).

**Items read** (a record's other items are decoded and not used):

* I048/010 data source, SAC/SIC: the radar whose ``sac`` and ``sic`` keys in the radars file
  match; a pair no radar has is an error naming it.
* I048/140 time of day, 1/128 s, in [0, 86400): ``time_s`` is seconds since midnight (UTC) of
  the first record's day (a CAT048 or CAT034 record). A file may cross midnight: each
  record's time is taken on the day that puts it nearest the previous record's time (within
  12 h), so 86399.5 followed by 0.25 is 86399.5, 86400.25, and a late record from before
  midnight stays before it. (Two records more than 12 h apart are therefore ambiguous;
  recordings have no such gaps.)
* I048/040 measured position: RHO (1/256 NM, 1 NM = 1852 m) is ``range_m``; THETA (360/2¹⁶°,
  clockwise from north) becomes the azimuth β = 90° − θ, counter-clockwise from the x axis,
  in (−180°, 180°]: x is east, y north, z up (the radars file's sites are in that frame). A
  record without I048/040 is a track-only record (a track status, a coasted track: no plot):
  skipped and counted (``InputCounts.track_only_skipped``).
* I048/161 track number: the plot's ``target`` label, as the number in decimal, and its
  ``radar_track``. The number is the label across radars: records of two radars with the same
  number are one target (as ``simulate`` writes a target seen by several radars). The
  association (``track --associate``) sets the labels itself and keeps the number as
  ``radar_track`` only (``radar_tracks``).
* I048/110 height measured by a 3D radar (25 ft) or, without it, I048/090 flight level
  (1/4 FL, only when validated and not garbled; a flight level is a pressure altitude, taken
  as height above mean sea level: the standard atmosphere, no QNH correction) → elevation by
  ``elevation_from_height`` (the 4/3 effective-earth-radius model, the radar's ``z_m`` its
  antenna's height above mean sea level). Heights are used only from a radar with
  ``sigma_elevation_deg`` in the radars file (another radar's plots are 2D, refused in a 3D
  file).
* I048/120 radial Doppler speed, subfield CAL (calculated Doppler speed, 1 m/s, positive away
  from the radar): ``radial_velocity_mps``, when D = 0 (valid) and the radar has
  ``sigma_vr_mps``; a doubtful one (D = 1) is not used.

**The file's kind** is set by its first CAT048 record, as a CSV's is by its header: it is 3D
when that record has a usable height, and of many targets when it has a track number; every
later record must then have the same (one without is refused, byte offset named; so is one
with a height or a track number the first lacks: "Corruption" below). Data blocks of other
categories than CAT048 and CAT034 are skipped whole (after the checks below). Within a
target (or the whole file, without track numbers) times must not decrease, as in a CSV.

**Duplicates.** A redundant feed sends each record twice, maybe in other packets and blocks;
applied twice, a plot would halve its track's covariance. A record whose octets equal a record
read recently (``_RecentRecords``: ``DUPLICATE_WINDOW_S`` of time of day, at most
``DUPLICATE_RECORDS`` records) is dropped and counted.

**CAT034 scan timing.** I034/000 message type 1 (north marker) and 2 (sector crossing, with the
sector's azimuth I034/020), of the data source I034/010 at I034/030 time of day (on the same
running day as the CAT048 records), and the antenna rotation period I034/041 when present,
make each radar's ``ScanTiming`` (``AsterixReader.scan_timing``: filled as the file is read).

**Bad input** is one ``ParameterError`` line naming the file and the byte offset (in a capture
the packet first): a data block
whose LEN is under 3 or runs past the end of the file (truncated), a data block the decoder
cannot parse (an item running past its end: the block's offset and the decoder's reason), a
record announcing items beyond the UAP, an unknown SAC/SIC, a height impossible at the plot's
range (these by the block's offset and the record's number in it, from 1), a file or capture
without any CAT048 target report (what was passed over, counted). The file is read
``READ_BYTES`` at a time, one data block (≤ 64 KiB) decoded at a time: memory does not grow
with the file.

**Corruption.** ASTERIX has no checksum: a changed octet is found only by what it makes
implausible, and the reader refuses such a file rather than track what is left (a corrupt
FSPEC bit or repetition count makes a record take the next ones as its items, and a corrupt
category octet skips a block of plots as "another category"). Refused, each by its byte
offset (and record number): a record without I048/010 or I048/140 (every CAT048 record has
both, track-only ones too); a time of day jumping more than ``MAX_TIME_JUMP_S`` from the
previous record's (CAT048 or CAT034; it would move every later record's day); a height
outside ``MIN_HEIGHT_M`` … ``MAX_HEIGHT_M``; a record of another kind than the first (a
height when the first record, of a radar measuring heights, has none; a track number when it
has none); a record whose items run over the records after it (``_successor_inside``: from
an octet inside it, the rest of it reads as whole records of the radars file's data sources,
the first a target report of the file's kind within ``SUCCESSOR_WINDOW_S``; tested where a
record's FSPEC or length differs from the previous one's); a data block of a category number
no published ASTERIX category has (``ASTERIX_CATEGORIES``), or of another category whose
records read whole as CAT048 target reports of the file's data sources (its category octet
corrupt). Blocks of other categories that pass are skipped and counted, with the first one's
byte offset and category (``input_summary``, the ``track`` input line).

**Two consumers, one reader.** ``AsterixReader`` yields (position, ``Plot``) for the row path
(``viz_app.io.plots.run_track``: a recording, the association, a finite-memory start) and, by
``blocks``, the same plots as the columns of a ``core.tracking.compiled.PlotBlock``,
``BLOCK_PLOTS`` at a time, with each plot's position (``PlacedBlock``), for the compiled block
path of ``viz_app.io.plot_blocks.run_track`` (``track`` otherwise). Both come from one pass of
decoding and checks (``_checked``), so the two give the same plots and the same errors.

``write_asterix`` is ``simulate --format asterix``: each plot as a record with I048/010, /140,
/040, /161 (for labelled plots), /110 (3D plots: the height ``height_from_elevation`` gives,
the inverse of the reader's elevation) and /120 CAL (plots with Doppler), ``BLOCK_RECORDS``
records to a data block. Values are rounded to the items' resolution, so a read back plot
differs from the simulated one by at most half a least significant bit of each item.
"""

from __future__ import annotations

import itertools
import math
import statistics
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import IO, Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.params import ParameterError
from radarviz.core.tracking.compiled import PlotBlock, RadarTable
from radarviz.core.tracking.stream import Plot
from radarviz.viz_app.io.atomic import commit_together
from radarviz.viz_app.io.pcap import CaptureCounts, is_capture, packet_place, udp_datagrams
from radarviz.viz_app.io.plots import (
    MAX_TIME_S,
    Locate,
    PlotSource,
    Radar,
    SourceFactory,
    _radar_toml,
    atomic_text,
    check_plots_finite,
    csv_source,
    input_format_of,
    radar_table,
)

CATEGORY = 48
#: Metres per nautical mile and per foot (exact by definition).
NM_M = 1852.0
FT_M = 0.3048
#: A flight level is 100 ft.
FL_M = 100.0 * FT_M
#: The 4/3 effective earth radius of standard refraction: the mean earth radius 6371 km × 4/3.
EFFECTIVE_EARTH_RADIUS_M = 6_371_000.0 * 4.0 / 3.0
DAY_S = 86_400.0
#: Largest step of time of day between consecutive records (CAT048 and CAT034, file order),
#: s. A record more than 12 h from the previous is ambiguous (``_DayClock`` takes the nearest
#: day), so one corrupt time would move every later record by a day; a recording's records
#: are seconds apart, so a jump of over 6 h is refused as corrupt, well before the ambiguity.
MAX_TIME_JUMP_S = 6 * 3600.0
#: Largest time of day (s) between a record and the next in its data block, for telling a
#: swallowed successor (``AsterixReader._successor_inside``): a data block holds a sector's
#: or a scan's reports, seconds apart.
SUCCESSOR_WINDOW_S = 60.0
#: Least significant bits of the items written: I048/140 time (s), I048/040 RHO (NM) and
#: THETA (deg), I048/110 height (ft), I048/120 CAL (m/s).
TIME_LSB_S = 1.0 / 128.0
RHO_LSB_NM = 1.0 / 256.0
THETA_LSB_DEG = 360.0 / 65536.0
HEIGHT_LSB_FT = 25.0
CAL_LSB_MPS = 1.0
#: Largest magnitudes of the signed items: 14-bit height, 10-bit CAL.
MAX_HEIGHT_LSB = 2**13 - 1
MAX_CAL_LSB = 2**9 - 1
#: Records ``write_asterix`` puts in one data block.
BLOCK_RECORDS = 128
#: Bytes read from the file at a time.
READ_BYTES = 1 << 18
#: Plots of one ``PlacedBlock`` (``AsterixReader.blocks``: a block is tracked at a time).
BLOCK_PLOTS = 4096
#: The input columns' items (the tracker's errors name a column).
ITEM_OF_COLUMN = {
    "time_s": "I048/140",
    "radar": "I048/010",
    "range_m": "I048/040",
    "azimuth_deg": "I048/040",
    "elevation_deg": "I048/110 or I048/090",
    "radial_velocity_mps": "I048/120",
    "target": "I048/161",
}
CAT034 = 34
#: I034/000 message types: the antenna crossed north; it crossed a sector's start (I034/020).
NORTH_MARKER, SECTOR_CROSSING = 1, 2
#: Duplicate records (``_RecentRecords``): a record is dropped when one of the same bytes was
#: read among the records of the last ``DUPLICATE_WINDOW_S`` of time of day (I048/140),
#: and at most ``DUPLICATE_RECORDS`` records are kept. A redundant feed's second copy comes
#: within a second of the first (two network paths, a recorder's buffering); a later record
#: of the same bytes would be the same radar at the same position at the same 1/128 s, which
#: only the day's wrap (24 h on) can make honestly. So any window well under a day drops no
#: real plot, and the window is set by memory: 10 s of 7 radars' ~1000 reports/s is ~10⁴
#: records of ~30 octets. The count bound holds memory even where times do not advance.
DUPLICATE_WINDOW_S = 10.0
DUPLICATE_RECORDS = 1 << 16
#: Data blocks of a capture whose packet ``AsterixReader`` remembers, to name it in errors.
#: The tracker's errors are about a plot of the plots in hand (a ``BLOCK_PLOTS`` block, a
#: ``viz_app.io.plots.READ_BLOCK`` or a scan), and a feed's datagram carries tens of plots,
#: so these span ~10⁴ plots; a block older than that is named by its byte offset alone (exact
#: too), and memory stays bounded (~200 octets each).
NAMED_BLOCKS = 1024
#: Physical bounds of a measured height above mean sea level (I048/110, or I048/090 as
#: pressure altitude), m: from below the lowest dry land (the Dead Sea shore, −430 m) and the
#: lowest pressure altitude a standard atmosphere reports (FL −15) to above the highest
#: aircraft (50 km, stratospheric balloons). The items hold ±62 km (I048/110) and ±62 km
#: (I048/090): a value outside these bounds is a corrupt record, not a target.
MIN_HEIGHT_M = -1_000.0
MAX_HEIGHT_M = 50_000.0
#: The published ASTERIX categories (EUROCONTROL's list: civil and military standards and the
#: special applications 150, 205, 240, 247, 252). A data block of another category number is
#: not skipped as "another category": a corrupt header, or data blocks that are not framed
#: where the file says (a LEN changed), so the reader refuses it.
ASTERIX_CATEGORIES = frozenset(
    (1, 2, 4, 8, 9, 10, 11, 15, 16, 17, 18, 19, 20, 21, 23, 24, 25, 30, 31, 32, 34, 48, 62,
     63, 65, 150, 205, 240, 247, 252)
)  # fmt: skip
#: A plot's position packs (data block byte offset, record index in the block).
_RECORDS_PER_POSITION = 1 << 16

_PYOBELIX_MISSING = "reading ASTERIX needs the pyobelix package: pip install pyobelix"
_LIBASTERIX_MISSING = "writing ASTERIX needs the libasterix package: pip install libasterix"


# --------------------------------------------------------------------------------------------
# Geometry: height above mean sea level ↔ elevation, 4/3 earth
# --------------------------------------------------------------------------------------------


def sin_elevation_from_height(
    range_m: float, height_m: float, site_height_m: float, earth_radius_m: float
) -> float:
    """sin ε of a target at slant range r and height h seen from a site at height hs.

    The triangle earth centre – site – target on a sphere of radius R (the effective radius;
    refraction bends the ray by as much as a larger earth straightens it) has sides
    a = R + hs, b = R + h and r, and the angle at the site is 90° + ε; the law of cosines
    b² = a² + r² + 2 a r sin ε gives::

        sin ε = ((h − hs)(2R + h + hs) − r²) / (2 a r)

    (b² − a² factored, so no large squares cancel). Not clipped: |sin ε| > 1 means no such
    geometry (``elevation_from_height`` refuses it).
    """
    a = earth_radius_m + site_height_m
    return ((height_m - site_height_m) * (2.0 * earth_radius_m + height_m + site_height_m)
            - range_m * range_m) / (2.0 * a * range_m)  # fmt: skip


def elevation_from_height(
    range_m: float,
    height_m: float,
    site_height_m: float,
    earth_radius_m: float = EFFECTIVE_EARTH_RADIUS_M,
) -> float:
    """Elevation ε (rad) of a target at slant range r (m) and height h (m above mean sea
    level) seen from a site at height hs: arcsin of ``sin_elevation_from_height``, in degrees
    first and then in radians, exactly as a CSV's ``elevation_deg`` becomes a plot's angle, so
    an ASTERIX file and the CSV of its plots give the same plots. Raises ``ValueError`` when
    |sin ε| > 1 (a height the range cannot reach)."""
    s = sin_elevation_from_height(range_m, height_m, site_height_m, earth_radius_m)
    if not -1.0 <= s <= 1.0:
        raise ValueError(f"sin(elevation) = {s:.6g} is outside [-1, 1]")
    return math.radians(elevation_deg_of_sin(s))


def elevation_deg_of_sin(s: float) -> float:
    """The elevation in degrees of sin ε = ``s`` (in [−1, 1])."""
    return math.degrees(math.asin(s))


def height_from_elevation(
    range_m: float,
    elevation_rad: float,
    site_height_m: float,
    earth_radius_m: float = EFFECTIVE_EARTH_RADIUS_M,
) -> float:
    """Height (m above mean sea level) of a target at slant range r and elevation ε from a site
    at height hs: the inverse of ``sin_elevation_from_height``, b = √(a² + r² + 2 a r sin ε),
    h = b − R, written as h = hs + (r² + 2 a r sin ε) / (b + a) (no cancellation)."""
    a = earth_radius_m + site_height_m
    q = range_m * (range_m + 2.0 * a * math.sin(elevation_rad))
    return site_height_m + q / (math.sqrt(a * a + q) + a)


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------


class _Parser(NamedTuple):
    """pyobelix's record parser, its UAPs and its error class."""

    parse_record: Any
    uap48: Any
    uap34: Any
    malformed: type[Exception]


def _decoder() -> _Parser:
    """pyobelix's record parser. A data block is split into records here rather than by
    ``pyobelix.iter_records``, which does the same loop but does not tell each record's octets,
    and duplicates are found by their octets (``pyobelix.engine._parse_record``, the one call
    of its block loop; the package is pinned below 0.2)."""
    try:
        import pyobelix
        from pyobelix.engine import _parse_record
        from pyobelix.specs import CATEGORIES
    except ImportError:
        raise ParameterError(_PYOBELIX_MISSING) from None
    return _Parser(_parse_record, CATEGORIES[CATEGORY], CATEGORIES[CAT034], pyobelix.AsterixError)


def split_records(block: bytes, parser: _Parser, uap: Any) -> list[tuple[Any, bytes]]:
    """The records of one data block (header included) as (decoded items, the record's
    octets), in order. Raises the decoder's error for an item running past the block. A
    record whose FSPEC announces items beyond the UAP ends the block (its length is unknown)
    and is returned with ``_fspec_reserved`` set."""
    out, pos, end = [], 3, len(block)
    parse = parser.parse_record
    while pos < end:
        rec, consumed = parse(block, pos, uap=uap, block_end=end)
        out.append((rec, block[pos : pos + consumed]))
        pos += consumed
        if rec.get("_fspec_reserved"):
            break
    return out


def tiled_blocks(payload: bytes) -> list[tuple[int, int, bytes]] | None:
    """A UDP payload as ASTERIX data blocks (offset in the payload, category, the block),
    or None when it is not: its blocks must tile it exactly, each LEN at least 3 and the
    last ending at the payload's end (a datagram may carry several blocks)."""
    out, pos, end = [], 0, len(payload)
    while pos < end:
        if end - pos < 3:
            return None
        length = int.from_bytes(payload[pos + 1 : pos + 3], "big")
        if length < 3 or pos + length > end:
            return None
        out.append((pos, payload[pos], payload[pos : pos + length]))
        pos += length
    return out or None


def data_blocks(fh: IO[bytes], source: str, head: bytes = b"") -> Iterator[tuple[int, int, bytes]]:
    """The data blocks of a binary ASTERIX file as (byte offset, category, the block's bytes,
    header included), reading ``READ_BYTES`` at a time (``head``: the file's first octets,
    already read). A LEN under 3 or past the end of the file is a ParameterError naming the
    block's offset."""
    buf = head
    base = 0  # file offset of buf[0]
    pos = 0
    eof = False
    while True:
        if len(buf) - pos < 3 or len(buf) - pos < int.from_bytes(buf[pos + 1 : pos + 3], "big"):
            if eof:
                break
            chunk = fh.read(READ_BYTES)
            eof = not chunk
            base += pos
            buf = buf[pos:] + chunk
            pos = 0
            continue
        cat = buf[pos]
        length = int.from_bytes(buf[pos + 1 : pos + 3], "big")
        if length < 3:
            raise ParameterError(
                f"{source} byte {base + pos}: data block LEN {length} is under 3 (the header's "
                "own length): not ASTERIX, or corrupt"
            )
        yield base + pos, cat, buf[pos : pos + length]
        pos += length
    left = len(buf) - pos
    if left:
        declared = int.from_bytes(buf[pos + 1 : pos + 3], "big") if left >= 3 else None
        what = f"declares LEN {declared}" if declared is not None else "has no complete header"
        raise ParameterError(
            f"{source} byte {base + pos}: truncated data block (CAT {buf[pos]:03d} {what}, the "
            f"file ends {left} byte(s) after its start)"
        )


class _DayClock:
    """Times of day (s) onto one running day: each time is taken on the day that puts it
    nearest the previous one (within 12 h), so 86399.5 then 0.25 is 86399.5, 86400.25 (the
    module docstring). One clock serves a file's CAT048 and CAT034 records in file order."""

    __slots__ = ("day_s", "previous")

    def __init__(self) -> None:
        self.day_s = 0.0
        self.previous: float | None = None

    def __call__(self, tod: float) -> float:
        """``tod`` on the running day. Raises ``ValueError`` for a time of day that is not one
        (not under 24 h) or that jumps more than ``MAX_TIME_JUMP_S`` from the previous: a
        corrupt time would otherwise move the day of every later record."""
        if not 0.0 <= tod < DAY_S:
            raise ValueError(f"time of day {tod!r} s is not under 24 h (a corrupt record)")
        if self.previous is None:
            t = tod
        else:
            t = tod + self.day_s
            if t < self.previous - DAY_S / 2:
                self.day_s += DAY_S
                t += DAY_S
            elif t > self.previous + DAY_S / 2:
                self.day_s -= DAY_S
                t -= DAY_S
            if abs(t - self.previous) > MAX_TIME_JUMP_S:
                raise ValueError(
                    f"time of day {tod!r} s is {abs(t - self.previous) / 3600:.1f} h from the "
                    f"previous record's: over {MAX_TIME_JUMP_S / 3600:g} h, a corrupt time (a "
                    "recording with such a gap: split it)"
                )
        self.previous = t
        return t


class _RecentRecords:
    """The octets of the records read recently (``DUPLICATE_WINDOW_S``,
    ``DUPLICATE_RECORDS``), in reading order, to drop a byte-identical repeat."""

    def __init__(self, window_s: float = DUPLICATE_WINDOW_S, size: int = DUPLICATE_RECORDS):
        self.window_s = window_s
        self.size = size
        self._seen: set[bytes] = set()
        self._order: deque[tuple[float | None, bytes]] = deque()

    def repeat(self, raw: bytes, tod: float | None) -> bool:
        """Whether ``raw`` was read recently; if not, it is remembered (``tod``: its time of
        day, None without one). Older records go first: those more than the window before
        ``tod`` (the age taken modulo a day, so midnight does not age the whole window), and
        any beyond the count bound."""
        if raw in self._seen:
            return True
        order, seen = self._order, self._seen
        while order:
            t0 = order[0][0]
            age = None if tod is None or t0 is None else (tod - t0) % DAY_S
            if len(order) < self.size and (age is None or not self.window_s < age < DAY_S / 2):
                break
            seen.discard(order.popleft()[1])
        order.append((tod, raw))
        seen.add(raw)
        return False


@dataclass(frozen=True)
class ScanTiming:
    """One radar's antenna timing, from its CAT034 service messages.

    Attributes:
        radar: the radar's name in the radars file (its I034/010 SAC/SIC), or
            "SAC s SIC c" for a data source no radar has.
        rotation_period_s: the antenna's rotation period (s): the last I034/041 antenna
            rotation period (1/128 s) read, else the median interval between successive north
            markers (a missed marker doubles one interval, which the median ignores), else
            None (fewer than two north markers and no I034/041).
        period_from: "I034/041", "north markers" or None: where ``rotation_period_s`` is from.
        north_times_s: the times (I034/030, on the CAT048 records' running day) of its north
            markers (I034/000 message type 1), in file order: one per antenna turn.
        sector_crossings: its sector-crossing messages (I034/000 type 2).
        last_sector_deg: the azimuth (I034/020, 360/2⁸°, clockwise from north) of its last
            sector crossing, or None.
    """

    radar: str
    rotation_period_s: float | None
    period_from: str | None
    north_times_s: tuple[float, ...]
    sector_crossings: int = 0
    last_sector_deg: float | None = None


@dataclass
class _ScanLog:
    """What ``ScanTiming`` is made of, gathered as the messages are read."""

    period_041_s: float | None = None
    north: list[float] = field(default_factory=list)
    sectors: int = 0
    last_sector_deg: float | None = None

    def timing(self, radar: str) -> ScanTiming:
        period, source = self.period_041_s, "I034/041" if self.period_041_s else None
        if period is None and len(self.north) >= 2:
            period = statistics.median(b - a for a, b in itertools.pairwise(self.north))
            source = "north markers"
        return ScanTiming(
            radar, period, source, tuple(self.north), self.sectors, self.last_sector_deg
        )


@dataclass
class InputCounts:
    """What the reader passed over, counted as it reads: ``records`` (CAT048 records read),
    of them ``track_only_skipped`` (without I048/040: a track status, no plot) and
    ``duplicates_dropped`` (``_RecentRecords``); ``cat034_messages``, ``other_blocks`` (data
    blocks of other categories) and ``first_other`` (the first one's byte offset and
    category); for a capture ``capture`` (``viz_app.io.pcap``'s counts)
    and ``not_asterix`` (UDP datagrams that are not ASTERIX data blocks)."""

    records: int = 0
    track_only_skipped: int = 0
    duplicates_dropped: int = 0
    cat034_messages: int = 0
    other_blocks: int = 0
    capture: CaptureCounts | None = None
    not_asterix: int = 0
    first_other: tuple[int, int] | None = None


class _Source(NamedTuple):
    """A data source's radar and what its plots take from it, computed once: the radar's
    ``index`` in the radars file, σr (m), σβ and σε (rad, 0 without), the site (m), σVr
    (m/s, 0 without)."""

    radar: Radar
    index: int
    sigma_r_m: float
    sigma_beta_rad: float
    site: tuple[float, float, float]
    sigma_elevation_rad: float
    sigma_vr_mps: float


class PlacedBlock(NamedTuple):
    """A block of plots and each plot's position (data block byte offset × 2¹⁶ + record
    index, ``AsterixReader.locate``'s), for the tracker's errors."""

    plots: PlotBlock
    positions: NDArray[np.int64]


class AsterixReader:
    """Validated plots of an ASTERIX CAT048 file or capture, one data block at a time (module
    docstring).

    The input is a capture (``viz_app.io.pcap``) when its first octets are a pcap or pcapng
    magic, or ``container`` is "pcap"; otherwise a file of data blocks. The first CAT048
    target report is read on construction (``three_d``, ``targets`` tell the file's kind);
    iterating yields (position, ``Plot``), position = data block offset × 2¹⁶ + record index
    in the block, which ``locate`` names; ``blocks`` yields the same plots as columns (the
    compiled path of ``viz_app.io.plot_blocks.run_track``). Errors: ``ParameterError``
    "SOURCE byte N, record K, item I048/xxx: …", in a capture "SOURCE packet P (byte B), data
    block at byte N, record K, …".

    While and after reading: ``counts`` (``InputCounts``), ``scan_timing`` (per radar, from
    CAT034), ``input_summary()`` (both, as the summary's JSON).
    """

    def __init__(
        self, fh: IO[bytes], source: str, radars: dict[str, Radar], container: str = "auto"
    ):
        self.source = source
        self._parser = _decoder()
        self._by_id = {(r.sac, r.sic): r for r in radars.values() if r.sac is not None}
        self._radars = radars
        self.counts = InputCounts()
        self._clock = _DayClock()
        self._recent = _RecentRecords()
        self._scans: dict[str, _ScanLog] = {}
        # (block offset, packet, packet offset) of the last NAMED_BLOCKS data blocks of a
        # capture: a ring of constant size, searched only to word an error.
        self._packet_of: deque[tuple[int, int, int]] = deque(maxlen=NAMED_BLOCKS)
        self._first_foreign: tuple[int, int] | None = None
        #: The previous CAT048 record's (FSPEC, length): a record of another shape is tested
        #: for a swallowed successor (``_framed``).
        self._last_shape: tuple[bytes, int] | None = None
        self.three_d = self.targets = False  # the file's kind: set by its first record below
        head = _head(fh, 12)
        self.capture = container == "pcap" or is_capture(head)
        self.container = "asterix"
        if self.capture:
            self.container = "pcapng" if head[:1] == b"\x0a" else "pcap"
        blocks = self._capture_blocks(fh, head) if self.capture else data_blocks(fh, source, head)
        self._records = self._decoded(blocks)
        first = next(self._records, None)
        if first is None:
            raise ParameterError(f"{source}: no CAT048 target reports ({self._nothing()})")
        self._first = first
        position, rec = first
        radar = self._radar(position, rec)
        self.three_d = radar.sigma_elevation_deg is not None and _height_m(rec) is not None
        #: The first record is of a radar that measures heights but has none: a later record
        #: with a height is of another kind than the file's, refused. (A 2D radar's first
        #: plot leaves a later 3D radar's heights unused, as before: a mixed fleet.)
        self._first_heightless_3d = radar.sigma_elevation_deg is not None and not self.three_d
        self.targets = "track_number" in rec
        #: The plots carry the radar's own track numbers (I048/161), as ``Plot.radar_track``
        #: and as their ``target`` labels (``track --associate`` keeps the first only).
        self.radar_tracks = self.targets

    def _nothing(self) -> str:
        """Why a file gave no plot, in words: what its reading passed over."""
        c = self.counts
        parts = [f"{c.records} CAT048 records, {c.track_only_skipped} of them track-only"]
        if c.duplicates_dropped:
            parts.append(f"{c.duplicates_dropped} duplicates")
        if c.capture is not None:
            k = c.capture
            parts.append(
                f"{k.packets} packets: {k.udp_datagrams} UDP datagrams, {c.not_asterix} of them "
                f"not ASTERIX, {k.non_udp} not UDP, {k.fragments} IP fragments"
            )
            if self._first_foreign is not None:
                n, off = self._first_foreign
                parts.append(f"the first datagram not ASTERIX: {packet_place(n, off)}")
        else:
            parts.append("not an ASTERIX CAT048 file?")
        return "; ".join(parts)

    @property
    def scan_timing(self) -> dict[str, ScanTiming]:
        """Per radar (its name) the antenna timing its CAT034 messages read so far tell
        (``ScanTiming``); complete once the plots are read. Radars without CAT034 messages
        are absent."""
        return {name: log.timing(name) for name, log in self._scans.items()}

    def input_summary(self) -> dict[str, Any]:
        """``counts`` and ``scan_timing`` as the ``track --summary`` document's
        ``input_counts`` section (north times as their count, first and last)."""
        c = self.counts
        doc: dict[str, Any] = {
            "container": self.container,
            "records": c.records,
            "track_only_skipped": c.track_only_skipped,
            "duplicates_dropped": c.duplicates_dropped,
            "cat034_messages": c.cat034_messages,
            "other_category_blocks": c.other_blocks,
            "first_other_category_block": None
            if c.first_other is None
            else {"byte": c.first_other[0], "category": c.first_other[1]},
        }
        if c.capture is not None:
            doc |= {
                "packets": c.capture.packets,
                "udp_datagrams": c.capture.udp_datagrams,
                "packets_skipped_non_udp": c.capture.non_udp,
                "packets_skipped_fragment": c.capture.fragments,
                "datagrams_skipped_not_asterix": c.not_asterix,
            }
        doc["scan_timing"] = {
            name: {
                "rotation_period_s": s.rotation_period_s,
                "period_from": s.period_from,
                "north_crossings": len(s.north_times_s),
                "first_north_s": s.north_times_s[0] if s.north_times_s else None,
                "last_north_s": s.north_times_s[-1] if s.north_times_s else None,
                "sector_crossings": s.sector_crossings,
            }
            for name, s in self.scan_timing.items()
        }
        return doc

    def locate(self, position: int, column: str) -> str:
        """ "byte N, record K, item I048/xxx" of a plot's position and input column."""
        return f"{self._where(position)}, item {ITEM_OF_COLUMN.get(column, column)}"

    def _block_where(self, offset: int) -> str:
        """A data block's place: "byte N", in a capture with its packet first."""
        for block_offset, packet, packet_offset in reversed(self._packet_of):
            if block_offset == offset:
                return f"{packet_place(packet, packet_offset)}, data block at byte {offset}"
        return f"byte {offset}"

    def _where(self, position: int) -> str:
        offset, index = divmod(position, _RECORDS_PER_POSITION)
        return f"{self._block_where(offset)}, record {index + 1}"

    def _capture_blocks(self, fh: IO[bytes], head: bytes) -> Iterator[tuple[int, int, bytes]]:
        """The data blocks of a capture's UDP datagrams (``viz_app.io.pcap``), each with its
        byte offset in the file; a datagram not tiled by data blocks is skipped and counted."""
        counts = self.counts.capture = CaptureCounts()
        named = self._packet_of
        for dg in udp_datagrams(fh, self.source, counts, head):
            blocks = tiled_blocks(dg.payload)
            if blocks is None:
                self.counts.not_asterix += 1
                if self._first_foreign is None:
                    self._first_foreign = (dg.packet, dg.packet_offset)
                continue
            for start, cat, block in blocks:
                offset = dg.offset + start
                named.append((offset, dg.packet, dg.packet_offset))
                yield offset, cat, block

    def _split(self, offset: int, block: bytes, uap: Any, cat: int) -> list[tuple[Any, bytes]]:
        try:
            return split_records(block, self._parser, uap)
        except self._parser.malformed as exc:
            raise ParameterError(
                f"{self.source} {self._block_where(offset)}: CAT{cat:03d} data block (LEN "
                f"{len(block)}) does not decode: {exc}"
            ) from None

    def _decoded(self, blocks: Iterable[tuple[int, int, bytes]]) -> Iterator[tuple[int, Any]]:
        """The CAT048 target reports of the data blocks as (position, decoded items); track-only
        records and duplicates are counted and passed over, CAT034 blocks read for the scan
        timing, other categories' blocks skipped whole (``_foreign``). Each record is framed
        (``_framed``) before it is used."""
        counts, recent = self.counts, self._recent
        for offset, cat, block in blocks:
            if cat != CATEGORY:
                self._foreign(offset, cat, block)
                if cat == CAT034:
                    self._service(offset, block)
                else:
                    counts.other_blocks += 1  # another category: not target reports
                    if counts.first_other is None:
                        counts.first_other = (offset, cat)
                continue
            position = offset * _RECORDS_PER_POSITION
            for index, (rec, raw) in enumerate(self._framed(offset, block)):
                counts.records += 1
                if "rho" not in rec:
                    # No measured position: a track-only record (a track status, a coasted
                    # track), nothing to track; counted, not refused.
                    counts.track_only_skipped += 1
                    continue
                if recent.repeat(raw, rec["time_of_day"]):
                    counts.duplicates_dropped += 1  # a redundant feed's second copy
                    continue
                yield position + index, rec

    def _framed(self, offset: int, block: bytes) -> list[tuple[Any, bytes]]:
        """A CAT048 data block's records, each checked to be framed where its FSPEC says.

        ASTERIX has no checksum and no record length: a corrupt FSPEC bit or repetition count
        changes where the next record starts, and what follows is read from the wrong octets.
        Such a file is refused here, not tracked (by the block's offset and the record's
        number): a record announcing items beyond the UAP; a record without I048/010 (the
        UAP's one mandatory item) or I048/140 (every CAT048 record is stamped, track-only
        ones too: a record of octets torn from another has neither, or not where they
        belong); and a record whose items run
        over a record that follows it (``_successor_inside``, tested for a record whose FSPEC
        or length differs from its predecessor's, where a corruption shows)."""
        records = self._split(offset, block, self._parser.uap48, CATEGORY)
        position = offset * _RECORDS_PER_POSITION
        start = 3
        for index, (rec, raw) in enumerate(records):
            where = self._where(position + index)
            if rec.get("_fspec_reserved"):
                raise ParameterError(
                    f"{self.source} {where}: the FSPEC announces items beyond CAT048's UAP "
                    "(another edition, or a corrupt record)"
                )
            for key, item in (("sac", "I048/010"), ("time_of_day", "I048/140")):
                if key not in rec:
                    raise ParameterError(
                        f"{self.source} {where}, item {item}: missing (every CAT048 record has "
                        "one; a record without is corrupt, or not framed where its block says)"
                    )
            shape = (raw[: _fspec_length(raw)], len(raw))
            if shape != self._last_shape:
                self._successor_inside(block, start, len(raw), rec["time_of_day"], where)
            self._last_shape = shape
            start += len(raw)
        return records

    def _successor_inside(
        self, block: bytes, start: int, length: int, near_tod: float, where: str
    ) -> None:
        """Refuse a record (octets ``start`` … ``start + length`` of ``block``, its time of
        day ``near_tod``) that swallowed
        the record(s) after it: when, from an octet inside it, its remaining octets read as
        whole CAT048 records of the radars file's data sources to its last octet exactly,
        the first a target report of the file's kind (``_is_successor``) within
        ``SUCCESSOR_WINDOW_S`` of the record's own time, those are the records that followed
        it, and an FSPEC bit or a repetition count set by corruption made it take them as
        its own items (a Mode S item taking the next record, an RDS or explicit item the
        next 32). Honest item octets reading so are far less likely than the corruption: a
        known SAC/SIC, the FSPEC bits of the kind's items and a time of day within the
        window, at one offset, and whole records to the end."""
        end = start + length
        by_id = self._by_id
        for p in range(start + 1, end - 2):
            if not block[p] & 0x80:  # no I048/010 (the cheap tests first: most octets fail)
                continue
            f = p + _fspec_length(block[p : min(p + 8, end)])
            if f + 2 > end or (block[f], block[f + 1]) not in by_id:
                continue
            n = self._whole_reports(block, p, end, target_reports=False, near_tod=near_tod)
            if n:
                raise ParameterError(
                    f"{self.source} {where}: the record's items run over {n} record(s) of "
                    f"the radars file's data sources ({p - start} octets into it): a corrupt "
                    "FSPEC or item length, refused rather than losing them"
                )

    def _whole_reports(
        self,
        block: bytes,
        start: int,
        end: int,
        target_reports: bool,
        near_tod: float | None = None,
    ) -> int:
        """How many CAT048 records octets ``start`` … ``end`` of ``block`` read as, each one
        of a data source of the radars file with a time of day (and a measured position, with
        ``target_reports``), the last ending at ``end`` exactly; 0 when they do not. With
        ``near_tod`` (a swallowed successor), the first must be ``_is_successor``."""
        parse, uap, n = self._parser.parse_record, self._parser.uap48, 0
        pos = start
        while pos < end:
            if not block[pos] & 0x80:  # no I048/010: not a record's start
                return 0
            f = _fspec_length(block[pos : min(pos + 8, end)])
            if pos + f + 2 > end or (block[pos + f], block[pos + f + 1]) not in self._by_id:
                return 0
            try:
                rec, consumed = parse(block, pos, uap=uap, block_end=end)
            except self._parser.malformed:
                return 0
            if rec.get("_fspec_reserved") or "time_of_day" not in rec:
                return 0
            if target_reports and "rho" not in rec:
                return 0
            if n == 0 and near_tod is not None and not self._is_successor(rec, near_tod):
                return 0
            pos += consumed
            n += 1
        return n

    def _is_successor(self, rec: Any, near_tod: float) -> bool:
        """A decoded record could be the one after a record of time of day ``near_tod``: a
        target report within ``SUCCESSOR_WINDOW_S`` of it (modulo a day), with a track number
        and a height when the file's kind (its first record) has them."""
        if "rho" not in rec:
            return False
        age = abs(rec["time_of_day"] - near_tod) % DAY_S
        if min(age, DAY_S - age) > SUCCESSOR_WINDOW_S:
            return False
        if self.targets and "track_number" not in rec:
            return False
        return not (self.three_d and _height_m(rec) is None)

    def _foreign(self, offset: int, cat: int, block: bytes) -> None:
        """Refuse a data block of another category that is not one: a category number that
        is no published ASTERIX category (``ASTERIX_CATEGORIES``: a corrupt header, or the
        block does not start where the previous block's LEN says), or a block whose octets
        read whole as CAT048 target reports of the radars file's data sources (its category
        octet corrupt: skipped, its plots would be lost without a word)."""
        if cat not in ASTERIX_CATEGORIES:
            raise ParameterError(
                f"{self.source} {self._block_where(offset)}: data block of category {cat}, "
                "which is no ASTERIX category: a corrupt block header, or the previous block's "
                "LEN is wrong"
            )
        n = self._whole_reports(block, 3, len(block), target_reports=True)
        if n:
            raise ParameterError(
                f"{self.source} {self._block_where(offset)}: a CAT{cat:03d} data block whose "
                f"{n} records read as CAT048 target reports of the radars file's data sources: "
                "a corrupt category octet, refused rather than skipping its plots"
            )

    def _service(self, offset: int, block: bytes) -> None:
        """A CAT034 data block's north markers and sector crossings into ``scan_timing``."""
        for index, (rec, _) in enumerate(self._split(offset, block, self._parser.uap34, CAT034)):
            self.counts.cat034_messages += 1
            kind = rec.get("message_type")
            if kind not in (NORTH_MARKER, SECTOR_CROSSING) or "sac" not in rec:
                continue
            radar = self._by_id.get((rec["sac"], rec["sic"]))
            name = radar.name if radar is not None else f"SAC {rec['sac']} SIC {rec['sic']}"
            log = self._scans.get(name)
            if log is None:
                log = self._scans[name] = _ScanLog()
            period = rec.get("antenna_rotation_period_s")
            if period:
                log.period_041_s = period
            tod = rec.get("time_of_day")
            if kind == NORTH_MARKER:
                if tod is not None:
                    log.north.append(self._service_time(offset, index, tod))
            else:
                log.sectors += 1
                log.last_sector_deg = rec.get("sector_number_deg")

    def _service_time(self, offset: int, index: int, tod: float) -> float:
        """A CAT034 message's I034/030 on the running day (``_DayClock``), its error by the
        block's offset and the message's number."""
        try:
            return self._clock(tod)
        except ValueError as exc:
            where = self._where(offset * _RECORDS_PER_POSITION + index)
            raise ParameterError(f"{self.source} {where}, item I034/030: {exc}") from None

    def _radar(self, position: int, rec: Any) -> Radar:
        if "sac" not in rec:
            raise ParameterError(
                f"{self.source} {self._where(position)}, item I048/010: missing (the data "
                "source names the radar)"
            )
        radar = self._by_id.get((rec["sac"], rec["sic"]))
        if radar is None:
            known = ", ".join(f"{r.name} {r.sac}/{r.sic}" for r in self._by_id.values())
            raise ParameterError(
                f"{self.source} {self._where(position)}, item I048/010: unknown data source "
                f"SAC {rec['sac']} SIC {rec['sic']} (radars with sac/sic: {known or 'none'})"
            )
        return radar

    def _checked(
        self,
    ) -> Iterator[
        tuple[int, float, float, float, float | None, float | None, _Source, str, int | None]
    ]:
        """Every target report decoded and checked (the one home of the checks of the module
        docstring): (position, time_s, range_m, azimuth_rad, elevation_rad or None,
        radial_velocity_mps or None, the data source's ``_Source``, target label, I048/161
        track number or None). ``__iter__`` makes plots of them, ``blocks`` columns."""
        three_d, labelled = self.three_d, self.targets
        last_t = -math.inf
        last_of: dict[str, float] = {}
        clock = self._clock
        target = ""
        track: int | None = None
        sources: dict[tuple[int, int], _Source] = {}  # per data source, computed once
        index = {name: i for i, name in enumerate(self._radars)}

        radians = math.radians
        for position, rec in itertools.chain((self._first,), self._records):
            c = sources.get((rec.get("sac"), rec.get("sic")))  # type: ignore[arg-type]
            if c is None:
                radar = self._radar(position, rec)
                c = sources[rec["sac"], rec["sic"]] = _Source(
                    radar,
                    index[radar.name],
                    radar.sigma_r_m,
                    math.radians(radar.sigma_beta_deg),
                    (radar.x_m, radar.y_m, radar.z_m),
                    math.radians(radar.sigma_elevation_deg or 0.0),
                    radar.sigma_vr_mps or 0.0,
                )
            radar = c.radar
            if "time_of_day" not in rec:
                raise self._bad(position, "I048/140", "missing (every plot needs a time)")
            try:
                t = clock(rec["time_of_day"])  # midnight: the day nearest the previous time
            except ValueError as exc:
                raise self._bad(position, "I048/140", str(exc)) from None
            if abs(t) > MAX_TIME_S:
                raise self._bad(position, "I048/140", f"time {t!r} s is beyond {MAX_TIME_S:g} s")
            if labelled:
                if "track_number" not in rec:
                    raise self._bad(
                        position, "I048/161", "missing: the file's first record has a track "
                        "number, so every record needs one (the target's label)"
                    )  # fmt: skip
                track = rec["track_number"]
                target = str(track)
                last_t = last_of.get(target, -math.inf)
            elif "track_number" in rec:
                raise self._bad(
                    position, "I048/161", "a track number, but the file's first record has "
                    "none, so its plots are one target's (a record of another kind: corrupt?)"
                )  # fmt: skip
            if t < last_t:
                of = f" of target {target}" if labelled else ""
                raise self._bad(
                    position, "I048/140", f"time {t!r} s is before the previous time{of} "
                    f"{last_t!r} s"
                )  # fmt: skip
            last_t = t
            if labelled:
                last_of[target] = t
            r = rec["rho"] * NM_M
            if not r > 0:
                raise self._bad(position, "I048/040", "RHO is 0: a plot needs a range > 0")
            beta_deg = 90.0 - rec["theta"]
            if beta_deg <= -180.0:
                beta_deg += 360.0
            el = None
            h = _height_m(rec) if radar.sigma_elevation_deg is not None else None
            if h is not None and not MIN_HEIGHT_M <= h <= MAX_HEIGHT_M:
                raise self._bad(
                    position, "I048/110 or I048/090", f"height {h:.0f} m is outside the "
                    f"physical range [{MIN_HEIGHT_M:g}, {MAX_HEIGHT_M:g}] m (a corrupt record)"
                )  # fmt: skip
            if h is not None and not three_d and self._first_heightless_3d:
                raise self._bad(
                    position, "I048/110 or I048/090", "a height, but the file's first record "
                    "(of a radar with sigma_elevation_deg) has none, so the file is 2D (a "
                    "record of another kind: corrupt?)"
                )  # fmt: skip
            if three_d:
                if h is None:
                    raise self._bad(
                        position, "I048/110 or I048/090", "missing: the file's first record "
                        f"has a height, so every record needs one (radar {radar.name!r})"
                    )  # fmt: skip
                if radar.sigma_elevation_deg is None:
                    raise self._bad(
                        position, "I048/010", f"radar {radar.name!r} has no sigma_elevation_deg "
                        "in the radars file, and the file is 3D (its first plot has a height)"
                    )  # fmt: skip
                s = sin_elevation_from_height(r, h, radar.z_m, EFFECTIVE_EARTH_RADIUS_M)
                if not -1.0 <= s <= 1.0:
                    raise self._bad(
                        position, "I048/110 or I048/090", f"height {h:.1f} m cannot be at slant "
                        f"range {r:.1f} m from radar {radar.name!r} at {radar.z_m:g} m "
                        f"(sin elevation {s:.4g})"
                    )  # fmt: skip
                el = radians(elevation_deg_of_sin(s))
            vr = None
            if c.sigma_vr_mps > 0 and rec.get("cal_valid"):
                vr = rec["cal_doppler_m_per_s"]
            yield position, t, r, radians(beta_deg), el, vr, c, target, track

    def __iter__(self) -> Iterator[tuple[int, Plot]]:
        three_d = self.three_d
        for position, t, r, az, el, vr, c, target, track in self._checked():
            yield (
                position,
                Plot(
                    t,
                    r,
                    az,
                    c.sigma_r_m,
                    c.sigma_beta_rad,
                    c.site,
                    c.radar.name,
                    el,
                    c.sigma_elevation_rad if three_d else 0.0,
                    vr,
                    c.sigma_vr_mps if vr is not None else 0.0,
                    target,
                    track,
                ),
            )

    def blocks(self) -> Iterator[PlacedBlock]:
        """The plots as ``PlacedBlock`` s of ``BLOCK_PLOTS`` (the last fewer): the columns of
        ``core.tracking.compiled.PlotBlock`` (radars indexed into
        ``viz_app.io.plots.radar_table`` of the radars file, in its order; NaN for a
        plot without Doppler, None when no plot of the block has one) and each plot's
        position, checked as ``__iter__``'s plots are (``_checked``)."""
        table = radar_table(self._radars)
        rows: list[tuple] = []
        for row in self._checked():
            rows.append(row)
            if len(rows) == BLOCK_PLOTS:
                yield self._placed(rows, table)
                rows = []
        if rows:
            yield self._placed(rows, table)

    def _placed(self, rows: list[tuple], table: RadarTable) -> PlacedBlock:
        """``_checked``'s rows as one ``PlacedBlock``."""
        position, t, r, az, el, vr, c, target, _ = zip(*rows, strict=True)
        labels: dict[str, int] = {}
        doppler = any(v is not None for v in vr)
        block = PlotBlock(
            np.array(t, dtype=np.float64),
            np.array(r, dtype=np.float64),
            np.array(az, dtype=np.float64),
            np.array(el, dtype=np.float64) if self.three_d else None,
            np.array([np.nan if v is None else v for v in vr], dtype=np.float64)
            if doppler
            else None,
            np.array([s.index for s in c], dtype=np.intp),
            table,
            np.array([labels.setdefault(g, len(labels)) for g in target], dtype=np.intp),
            tuple(labels),
        )
        return PlacedBlock(block, np.array(position, dtype=np.int64))

    def _bad(self, position: int, item: str, what: str) -> ParameterError:
        return ParameterError(f"{self.source} {self._where(position)}, item {item}: {what}")


def asterix_source(
    fh: IO[bytes], source: str, radars: dict[str, Radar]
) -> tuple[PlotSource, Locate]:
    """``run_track``'s reader of an ASTERIX file or capture (a
    ``viz_app.io.plots.SourceFactory``; a capture is told by its magic)."""
    reader = AsterixReader(fh, source, radars)
    return reader, reader.locate


def capture_reader(fh: IO[bytes], source: str, radars: dict[str, Radar]) -> AsterixReader:
    """An ``AsterixReader`` of a pcap or pcapng capture (``--format pcap``: a file of
    another magic is refused, not read as data blocks)."""
    return AsterixReader(fh, source, radars, container="pcap")


def capture_source(
    fh: IO[bytes], source: str, radars: dict[str, Radar]
) -> tuple[PlotSource, Locate]:
    """``run_track``'s reader of a capture (``capture_reader``)."""
    reader = capture_reader(fh, source, radars)
    return reader, reader.locate


def source_for(path: str, file_format: str = "auto") -> SourceFactory:
    """The reader of the measurement file ``path``: ``asterix_source``, ``capture_source`` or
    ``viz_app.io.plots.csv_source``, by ``file_format`` (``input_format_of``: "auto" goes by
    the magic of a capture, else by the suffix). The one place the input format is chosen
    (``track``, ``radarviz.track_file``)."""
    fmt = input_format_of(path, file_format)
    if fmt == "pcap":
        return capture_source
    return asterix_source if fmt == "asterix" else csv_source


def input_line(source: str, doc: dict[str, Any]) -> str:
    """``AsterixReader.input_summary``'s counts as one line of words (``track``'s stderr)."""
    parts = []
    if "packets" in doc:
        parts.append(
            f"{doc['packets']} packets ({doc['packets_skipped_non_udp']} not UDP, "
            f"{doc['packets_skipped_fragment']} IP fragments and "
            f"{doc['datagrams_skipped_not_asterix']} datagrams not ASTERIX skipped)"
        )
    parts.append(
        f"{doc['records']} CAT048 records ({doc['track_only_skipped']} track-only skipped, "
        f"{doc['duplicates_dropped']} duplicates dropped)"
    )
    first = doc.get("first_other_category_block")
    if first is not None:
        parts.append(
            f"{doc['other_category_blocks']} data blocks of other categories skipped (the "
            f"first CAT{first['category']:03d} at byte {first['byte']})"
        )
    scans = [
        f"{name} {s['rotation_period_s']:.3f} s ({s['period_from']})"
        for name, s in doc["scan_timing"].items()
        if s["rotation_period_s"] is not None
    ]
    if scans:
        parts.append("antenna rotation " + ", ".join(scans))
    return f"{source}: " + ", ".join(parts)


def _head(fh: IO[bytes], n: int) -> bytes:
    """The first ``n`` octets of ``fh`` (fewer at its end), a pipe's short reads joined."""
    head = b""
    while len(head) < n:
        chunk = fh.read(n - len(head))
        if not chunk:
            break
        head += chunk
    return head


def _fspec_length(raw: bytes) -> int:
    """Octets of the FSPEC at the start of ``raw``: up to and with the first octet whose FX
    bit (the last) is 0 (all of ``raw`` when none is)."""
    for i, octet in enumerate(raw):
        if not octet & 1:
            return i + 1
    return len(raw)


def _height_m(rec: Any) -> float | None:
    """A decoded record's height above mean sea level (m): I048/110, else a validated,
    ungarbled I048/090 flight level; None without either."""
    h = rec.get("height")
    if h is not None:
        return h * FT_M
    fl = rec.get("flight_level")
    if fl is not None and rec.get("fl_valid") and not rec.get("fl_garbled"):
        return fl * FL_M
    return None


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------


def _encoder() -> Any:
    try:
        import asterix.generated as gen
    except ImportError:
        raise ParameterError(_LIBASTERIX_MISSING) from None
    return gen.Cat_048_1_32


def with_source_ids(radars: list[Radar]) -> list[Radar]:
    """``radars`` with a data source each: those without sac/sic get SAC 0 and the lowest SIC
    from 1 up that no radar has."""
    from dataclasses import replace

    taken = {(r.sac, r.sic) for r in radars if r.sac is not None}
    out, sic = [], 1
    for r in radars:
        if r.sac is None:
            while (0, sic) in taken:
                sic += 1
            taken.add((0, sic))
            r = replace(r, sac=0, sic=sic)
        out.append(r)
    return out


def track_numbers(plots: Iterable[Plot]) -> dict[str, int]:
    """Each target label's I048/161 track number (12 bits): a label that is a decimal number in
    [0, 4095] keeps it, the others get the lowest free numbers from 1 in order of first plot."""
    labels = list(dict.fromkeys(p.target for p in plots))
    numbers = {lb: int(lb) for lb in labels if _is_number(lb)}
    used = set(numbers.values())
    free = (n for n in range(1, 4096) if n not in used)
    for lb in labels:
        if lb not in numbers:
            n = next(free, None)
            if n is None:
                raise ParameterError("simulate: more than 4096 targets do not fit I048/161")
            numbers[lb] = n
    return numbers


def _is_number(label: str) -> bool:
    """The label is a track number as the reader writes it: decimal, no leading 0, < 4096."""
    return label.isdigit() and label == str(int(label)) and int(label) < 4096


def record_items(plot: Plot, radar: Radar, track_number: int | None) -> dict[str, Any]:
    """One plot's CAT048 items as ``libasterix`` record arguments, every value the raw integer
    of its item (the rounding done here, once): I048/010, /140, /040, /161, /110, /120."""
    where = f"simulate: plot at time {plot.time_s!r} s of radar {radar.name!r}"
    t = round(plot.time_s / TIME_LSB_S) % round(DAY_S / TIME_LSB_S)
    rho = round(plot.range_m / NM_M / RHO_LSB_NM)
    if not 0 < rho < 65536:
        raise ParameterError(f"{where}: range {plot.range_m!r} m is outside I048/040's (0, 256) NM")
    theta = round((90.0 - math.degrees(plot.azimuth_rad)) / THETA_LSB_DEG) % 65536
    items: dict[str, Any] = {
        "010": (("SAC", radar.sac), ("SIC", radar.sic)),
        "140": t,
        "040": (("RHO", rho), ("THETA", theta)),
    }
    if track_number is not None:
        items["161"] = (0, ("TRN", track_number))
    if plot.elevation_rad is not None:
        h_m = height_from_elevation(plot.range_m, plot.elevation_rad, radar.z_m)
        h = round(h_m / FT_M / HEIGHT_LSB_FT)
        if abs(h) > MAX_HEIGHT_LSB:
            raise ParameterError(f"{where}: height {h_m:.0f} m is beyond I048/110's ±62 km")
        items["110"] = (0, h & 0x3FFF)  # 14-bit two's complement
    if plot.radial_velocity_mps is not None:
        v = round(plot.radial_velocity_mps / CAL_LSB_MPS)
        if abs(v) > MAX_CAL_LSB:
            raise ParameterError(
                f"{where}: radial velocity {plot.radial_velocity_mps!r} m/s is beyond "
                f"I048/120 CAL's ±{MAX_CAL_LSB} m/s"
            )
        items["120"] = {"CAL": (0, 0, v & 0x3FF)}  # D = 0 (valid), 10-bit two's complement
    return items


def encode_plots(
    plots: list[Plot], radars: list[Radar], block_records: int = BLOCK_RECORDS
) -> Iterator[bytes]:
    """The CAT048 data blocks of ``plots`` (radars with sac/sic), ``block_records`` records
    each. Labelled plots carry I048/161 (``track_numbers``)."""
    cat = _encoder()
    by_name = {r.name: r for r in radars}
    numbers = track_numbers(plots) if any(p.target for p in plots) else None
    for start in range(0, len(plots), block_records):
        records = [
            cat.cv_record.create(
                record_items(p, by_name[p.radar], None if numbers is None else numbers[p.target])
            )
            for p in plots[start : start + block_records]
        ]
        yield cat.create(records).unparse().to_bytes()


def write_asterix(
    meas_path: str,
    radars_path: str,
    plots: list[Plot],
    radars: list[Radar],
    block_records: int = BLOCK_RECORDS,
) -> int:
    """Plots as an ASTERIX CAT048 file of data blocks of ``block_records`` records and their
    radars (given SAC/SIC by ``with_source_ids``) as TOML, committed together (both or
    neither; nothing on an error); returns plots. The plots pass the finite-result check
    first, as ``write_measurements``'s do."""
    from radarviz.viz_app.io.atomic import atomic_write

    check_plots_finite(plots)  # a NaN is an error, not a record
    radars = with_source_ids(radars)
    blocks = encode_plots(plots, radars, block_records)
    with commit_together(), atomic_write(meas_path, "wb") as fh, atomic_text(radars_path) as rh:
        for block in blocks:
            fh.write(block)
        rh.write(_radar_toml(radars))
    return len(plots)
