"""ASTERIX CAT048 monoradar target reports in (``track``) and out (``simulate``).

An ASTERIX file is a sequence of data blocks, each ``CAT (1 octet) LEN (2 octets, the block's
length with this header) records…``; a CAT048 record is an FSPEC (presence bits in the order
of the category's user application profile, UAP) followed by the items it announces. The
records are decoded by ``pyobelix`` (CAT048 edition 1.32) and written by ``libasterix``
(``asterix.generated.Cat_048_1_32``); this module only frames the file into data blocks (to
name byte offsets and to keep memory flat) and turns the decoded items into plots.

**Items read** (a record's other items are decoded and not used):

* I048/010 data source, SAC/SIC: the radar whose ``sac`` and ``sic`` keys in the radars file
  match; a pair no radar has is an error naming it.
* I048/140 time of day, 1/128 s, in [0, 86400): ``time_s`` is seconds since midnight (UTC) of
  the first record's day. A file may cross midnight: each record's time is taken on the day
  that puts it nearest the previous record's time (within 12 h), so 86399.5 followed by 0.25
  is 86399.5, 86400.25, and a late record from before midnight stays before it. (Two records
  more than 12 h apart are therefore ambiguous; recordings have no such gaps.)
* I048/040 measured position: RHO (1/256 NM, 1 NM = 1852 m) is ``range_m``; THETA (360/2¹⁶°,
  clockwise from north) becomes the azimuth β = 90° − θ, counter-clockwise from the x axis,
  in (−180°, 180°]: x is east, y north, z up (the radars file's sites are in that frame). A
  record without I048/040 is refused (its byte offset named): a CAT048 target report without
  a measured position cannot be tracked, and dropping it silently would hide it.
* I048/161 track number: the plot's ``target`` label, as the number in decimal. The number is
  the label across radars: records of two radars with the same number are one target (as
  ``simulate`` writes a target seen by several radars).
* I048/110 height measured by a 3D radar (25 ft) or, without it, I048/090 flight level
  (1/4 FL, only when validated and not garbled; a flight level is a pressure altitude, taken
  as height above mean sea level: the standard atmosphere, no QNH correction) → elevation by
  ``elevation_from_height`` (the 4/3 effective-earth-radius model, the radar's ``z_m`` its
  antenna's height above mean sea level). Heights are used only from a radar with
  ``sigma_elevation_deg`` in the radars file (another radar's plots are 2D, refused in a 3D
  file).
* I048/120 radial Doppler speed, subfield CAL (calculated Doppler speed, 1 m/s, positive away
  from the radar): ``radial_velocity_mps``, when D = 0 (valid) and the radar has
  ``sigma_radial_velocity_mps``; a doubtful one (D = 1) is not used.

**The file's kind** is set by its first CAT048 record, as a CSV's is by its header: it is 3D
when that record has a usable height, and of many targets when it has a track number; every
later record must then have the same (one without is refused, byte offset named). Data blocks
of other categories (e.g. CAT034 service messages) are skipped whole. Within a target (or the
whole file, without track numbers) times must not decrease, as in a CSV.

**Bad input** is one ``ParameterError`` line naming the file and the byte offset: a data block
whose LEN is under 3 or runs past the end of the file (truncated), a data block the decoder
cannot parse (an item running past its end: the block's offset and the decoder's reason), a
record announcing items beyond the UAP, an unknown SAC/SIC, a height impossible at the plot's
range (these by the block's offset and the record's index in it). The file is read
``READ_BYTES`` at a time, one data block (≤ 64 KiB) decoded at a time: memory does not grow
with the file.

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
from collections.abc import Iterable, Iterator
from typing import IO, Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from radarviz.core.params import ParameterError
from radarviz.core.tracking.compiled import PlotBlock, RadarTable
from radarviz.core.tracking.stream import Plot
from radarviz.viz_app.io.atomic import commit_together
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


def _decoder() -> Any:
    try:
        import pyobelix
    except ImportError:
        raise ParameterError(_PYOBELIX_MISSING) from None
    return pyobelix


def data_blocks(fh: IO[bytes], source: str) -> Iterator[tuple[int, int, bytes]]:
    """The data blocks of a binary ASTERIX file as (byte offset, category, the block's bytes,
    header included), reading ``READ_BYTES`` at a time. A LEN under 3 or past the end of the
    file is a ParameterError naming the block's offset."""
    buf = b""
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


class _Source(NamedTuple):
    """A data source's radar and what its plots take from it, computed once: the radar's
    ``index`` in the radars file, σr (m), σβ and σε (rad, 0 without), the site (m), σVr
    (m/s, 0 without)."""

    radar: Radar
    index: int
    sigma_r: float
    sigma_az: float
    site: tuple[float, float, float]
    sigma_el: float
    sigma_vr: float


class PlacedBlock(NamedTuple):
    """A block of plots and each plot's position (data block byte offset × 2¹⁶ + record
    index, ``AsterixReader.locate``'s), for the tracker's errors."""

    plots: PlotBlock
    positions: NDArray[np.int64]


class AsterixReader:
    """Validated plots of an ASTERIX CAT048 file, one data block at a time (module docstring).

    The first CAT048 record is read on construction (``three_d``, ``targets`` tell the file's
    kind); iterating yields (position, ``Plot``), position = data block offset × 2¹⁶ + record
    index, which ``locate`` names; ``blocks`` yields the same plots as columns (the compiled
    path of ``viz_app.io.plot_blocks.run_track``). Errors: ``ParameterError`` "SOURCE byte N,
    record K, item I048/xxx: …".
    """

    def __init__(self, fh: IO[bytes], source: str, radars: dict[str, Radar]):
        self.source = source
        self._decode = _decoder().iter_records
        self._malformed = _decoder().AsterixError
        self._by_id = {(r.sac, r.sic): r for r in radars.values() if r.sac is not None}
        self._radars = radars
        self._records = self._decoded(fh)
        first = next(self._records, None)
        if first is None:
            raise ParameterError(f"{source}: no CAT048 records (not an ASTERIX CAT048 file?)")
        self._first = first
        position, rec = first
        radar = self._radar(position, rec)
        self.three_d = radar.sigma_elevation_deg is not None and _height_m(rec) is not None
        self.targets = "track_number" in rec

    def locate(self, position: int, column: str) -> str:
        """ "byte N, record K, item I048/xxx" of a plot's position and input column."""
        return f"{self._where(position)}, item {ITEM_OF_COLUMN.get(column, column)}"

    def _where(self, position: int) -> str:
        offset, index = divmod(position, _RECORDS_PER_POSITION)
        return f"byte {offset}, record {index + 1}"

    def _decoded(self, fh: IO[bytes]) -> Iterator[tuple[int, Any]]:
        decode, malformed = self._decode, self._malformed
        for offset, cat, block in data_blocks(fh, self.source):
            if cat != CATEGORY:
                continue  # another category's block (service messages): not target reports
            try:
                records = list(decode(block, strict=True))
            except malformed as exc:
                raise ParameterError(
                    f"{self.source} byte {offset}: CAT048 data block (LEN {len(block)}) does "
                    f"not decode: {exc}"
                ) from None
            position = offset * _RECORDS_PER_POSITION
            for index, rec in enumerate(records):
                if rec.get("_fspec_reserved"):
                    raise ParameterError(
                        f"{self.source} {self._where(position + index)}: the FSPEC announces "
                        "items beyond CAT048's UAP (another edition?)"
                    )
                yield position + index, rec

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
    ) -> Iterator[tuple[int, float, float, float, float | None, float | None, _Source, str]]:
        """Every record decoded and checked (the one home of the checks of the module
        docstring): (position, time_s, range_m, azimuth_rad, elevation_rad or None,
        radial_velocity_mps or None, the data source's ``_Source``, target label). ``__iter__``
        makes plots of them, ``blocks`` columns."""
        three_d, labelled = self.three_d, self.targets
        last_t = -math.inf
        last_of: dict[str, float] = {}
        day_s = 0.0
        previous: float | None = None
        target = ""
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
                    radar.sigma_range_m,
                    math.radians(radar.sigma_azimuth_deg),
                    (radar.x_m, radar.y_m, radar.z_m),
                    math.radians(radar.sigma_elevation_deg or 0.0),
                    radar.sigma_radial_velocity_mps or 0.0,
                )
            radar = c.radar
            if "time_of_day" not in rec:
                raise self._bad(position, "I048/140", "missing (every plot needs a time)")
            if "rho" not in rec:
                raise self._bad(
                    position, "I048/040", "missing: a record without a measured position is "
                    "refused (not a target report that can be tracked)"
                )  # fmt: skip
            tod = rec["time_of_day"]
            if previous is None:
                t = tod
            else:
                t = tod + day_s
                # Midnight: take the day that puts t nearest the previous record's time.
                if t < previous - DAY_S / 2:
                    day_s += DAY_S
                    t += DAY_S
                elif t > previous + DAY_S / 2:
                    day_s -= DAY_S
                    t -= DAY_S
            previous = t
            if abs(t) > MAX_TIME_S:
                raise self._bad(position, "I048/140", f"time {t!r} s is beyond {MAX_TIME_S:g} s")
            if labelled:
                if "track_number" not in rec:
                    raise self._bad(
                        position, "I048/161", "missing: the file's first record has a track "
                        "number, so every record needs one (the target's label)"
                    )  # fmt: skip
                target = str(rec["track_number"])
                last_t = last_of.get(target, -math.inf)
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
            if three_d:
                h = _height_m(rec)
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
            if c.sigma_vr > 0 and rec.get("cal_valid"):
                vr = rec["cal_doppler_m_per_s"]
            yield position, t, r, radians(beta_deg), el, vr, c, target

    def __iter__(self) -> Iterator[tuple[int, Plot]]:
        three_d = self.three_d
        for position, t, r, az, el, vr, c, target in self._checked():
            yield (
                position,
                Plot(
                    t,
                    r,
                    az,
                    c.sigma_r,
                    c.sigma_az,
                    c.site,
                    c.radar.name,
                    el,
                    c.sigma_el if three_d else 0.0,
                    vr,
                    c.sigma_vr if vr is not None else 0.0,
                    target,
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
        position, t, r, az, el, vr, c, target = zip(*rows, strict=True)
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
    """``run_track``'s reader of an ASTERIX file (a ``viz_app.io.plots.SourceFactory``)."""
    reader = AsterixReader(fh, source, radars)
    return reader, reader.locate


def source_for(path: str, file_format: str = "auto") -> SourceFactory:
    """The reader of the measurement file ``path``: ``asterix_source`` or
    ``viz_app.io.plots.csv_source``, by ``file_format`` (``input_format_of``: "auto" goes by
    the suffix). The one place the input format is chosen (``track``, ``radarviz.track_file``)."""
    return asterix_source if input_format_of(path, file_format) == "asterix" else csv_source


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


def encode_plots(plots: list[Plot], radars: list[Radar]) -> Iterator[bytes]:
    """The CAT048 data blocks of ``plots`` (radars with sac/sic), ``BLOCK_RECORDS`` records
    each. Labelled plots carry I048/161 (``track_numbers``)."""
    cat = _encoder()
    by_name = {r.name: r for r in radars}
    numbers = track_numbers(plots) if any(p.target for p in plots) else None
    for start in range(0, len(plots), BLOCK_RECORDS):
        records = [
            cat.cv_record.create(
                record_items(p, by_name[p.radar], None if numbers is None else numbers[p.target])
            )
            for p in plots[start : start + BLOCK_RECORDS]
        ]
        yield cat.create(records).unparse().to_bytes()


def write_asterix(meas_path: str, radars_path: str, plots: list[Plot], radars: list[Radar]) -> int:
    """Plots as an ASTERIX CAT048 file and their radars (given SAC/SIC by ``with_source_ids``)
    as TOML, committed together (both or neither; nothing on an error); returns plots. The
    plots pass the finite-result check first, as ``write_measurements``'s do."""
    from radarviz.viz_app.io.atomic import atomic_write

    check_plots_finite(plots)  # a NaN is an error, not a record
    radars = with_source_ids(radars)
    blocks = encode_plots(plots, radars)
    with commit_together(), atomic_write(meas_path, "wb") as fh, atomic_text(radars_path) as rh:
        for block in blocks:
            fh.write(block)
        rh.write(_radar_toml(radars))
    return len(plots)
