"""The measurement file read, tracked and written a block at a time, as columns.

``viz_app.io.plots`` defines the files; this module is their fast path for ``radarviz
track`` without a recording: the file is read in blocks of bytes (``BLOCK_BYTES``, cut at a
line end), each block parsed by pyarrow's CSV reader into columns, validated with vector
operations, handed to the tracker as a ``core.tracking.compiled.PlotBlock`` (no ``Plot`` per
row) and the tracks written back as one pyarrow table per block. Memory holds one block of
plots and its tracks, whatever the file's length.

Every check of ``viz_app.io.plots.PlotReader`` holds here, with its messages: a block that
pyarrow cannot parse, or in which any value fails a check (a number out of its range, an
unknown radar, an empty target cell, a time before its target's previous one, a missing
σε or σVr), or that the fast parser does not cover (quoted fields, blank lines, carriage
returns), is read again row by row by ``PlotReader.plots``, which raises the error naming
the file, line and column (or, for a block only the fast parser refused, yields its plots).
The row-by-row reader carries its state (the previous times) from block to block, so the
two paths check one file as one.

An ASTERIX CAT048 file takes the same path from its reader's blocks
(``viz_app.io.asterix.AsterixReader.blocks``: decoded and checked record by record, handed
over as columns); ``track_blocks`` reads either through ``BlockSource``, and names a plot
the tracker refuses by the source's own words (a CSV's line, ASTERIX's byte offset and
record).
"""

from __future__ import annotations

import contextlib
import csv
import functools
import io
import os
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from pathlib import Path
from typing import IO, NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from radarviz.core.params import ParameterError
from radarviz.core.tracking.association import AssociationOptions
from radarviz.core.tracking.compiled import PlotBlock, TrackBlock
from radarviz.core.tracking.stream import Plot, StreamOptions, plot_block, state_rows
from radarviz.core.tracking.targets import TargetTracker
from radarviz.viz_app.io.arrow_numpy import from_numpy, strings, to_numpy
from radarviz.viz_app.io.plots import (
    _COMPONENTS,
    _PAIRS,
    MAX_LINE_BYTES,
    MAX_RADIAL_VELOCITY_MPS,
    MAX_RANGE_M,
    MAX_TIME_S,
    ObserverFactory,
    PlotReader,
    Radar,
    SourceFactory,
    TrackSummary,
    _csv_locate,
    check_track_rows,
    csv_source,
    input_summary,
    is_parquet,
    long_line_error,
    parquet_writer,
    radar_table,
    track_columns,
    verify_track_parquet,
)

#: Bytes of the measurement file read and tracked at a time (≈ 5 000 plots of ~50 bytes: the
#: block, its tracks and their text are most of the command's memory above its libraries;
#: 128 KB blocks spent 40% more on reading, in the per-block calls; 512 KB added 50 MB).
BLOCK_BYTES = 1 << 18
#: Most threads that format the track file's numbers (the formatting is most of the time of
#: ``radarviz track``).
WRITE_THREADS = 4
#: Blocks formatted or being written at a time, while the next is tracked (two: one block's
#: text goes to the disk while the next is formatted).
IN_FLIGHT = 2
#: Text written between two requests to start the disk writes (``BlockWriter._start_writeback``).
WRITEBACK_BYTES = 64 << 20
_NUMERIC = ("time_s", "range_m", "azimuth_deg", "elevation_deg", "radial_velocity_mps")


class LinedBlock(NamedTuple):
    """A block of plots and the file line of each (for the tracker's errors)."""

    plots: PlotBlock
    lines: NDArray[np.int64]


class BlockSource(Protocol):
    """What ``track_blocks`` reads: a measurement file's plots in blocks of columns, with what
    its start told (``three_d``, ``targets``). ``PlotBlockReader`` (CSV) and
    ``viz_app.io.asterix.AsterixReader`` (ASTERIX CAT048) are the two; ``blocks`` yields
    (``PlotBlock``, each plot's position (B,)), the position being what ``locate`` turns into
    words with an input column (a line number; a byte offset and record)."""

    source: str

    @property
    def three_d(self) -> bool: ...

    @property
    def targets(self) -> bool: ...

    def blocks(self) -> Iterator[tuple[PlotBlock, NDArray[np.int64]]]: ...

    def locate(self, position: int, column: str) -> str: ...


class PlotBlockReader:
    """The plots of a measurement file (binary, opened by the caller) in blocks.

    The header is read on construction (``reader`` is the ``PlotReader`` that checked it:
    ``three_d``, ``doppler``, ``targets``); iterating yields ``LinedBlock`` s.
    """

    def __init__(self, fh: IO[bytes], source: str, radars: dict[str, Radar]):
        self.fh, self.source, self.radars = fh, source, radars
        head = fh.readline(MAX_LINE_BYTES + 1)
        if len(head) > MAX_LINE_BYTES:
            raise long_line_error(source, 1, head)
        if head.startswith(b"\xef\xbb\xbf"):
            head = head[3:]
        try:
            text = head.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ParameterError(
                f"{source} line 1: not UTF-8 text (byte {head[exc.start]:#04x} at "
                f"column {exc.start + 1})"
            ) from None
        self.reader = PlotReader([text] if text else [], source, radars)
        self.names = list(radars)
        self._names = strings(self.names)
        self.table = radar_table(radars)
        self._has_el = np.array([r.sigma_elevation_deg is not None for r in radars.values()])
        self._has_vr = np.array([r.sigma_vr_mps is not None for r in radars.values()])

    @property
    def three_d(self) -> bool:
        """The header has ``elevation_deg`` (``PlotReader``'s)."""
        return self.reader.three_d

    @property
    def targets(self) -> bool:
        """The header has ``target``."""
        return self.reader.targets

    def locate(self, line: int, column: str) -> str:
        """ "line L, column C" (``BlockSource``)."""
        return _csv_locate(line, column)

    def blocks(self) -> Iterator[LinedBlock]:
        """``iter(self)``: the file's ``LinedBlock`` s."""
        return iter(self)

    def __iter__(self) -> Iterator[LinedBlock]:
        line = 1  # lines before the block
        rest = b""
        # A file: whole blocks. A pipe or FIFO fed live: what is there, at most a block (its
        # plots are tracked as they come).
        read = self.fh.read if self.fh.seekable() else self.fh.read1
        while True:
            data = read(BLOCK_BYTES)
            buf = rest + data
            if not data:
                if buf:
                    yield from self._block(buf, line)
                break
            cut = buf.rfind(b"\n")
            if cut < 0:
                if len(buf) > MAX_LINE_BYTES:
                    raise ParameterError(
                        f"{self.source} line {line + 1}: longer than {MAX_LINE_BYTES} bytes "
                        "(not a plots file?)"
                    )
                rest = buf
                continue
            chunk, rest = buf[: cut + 1], buf[cut + 1 :]
            yield from self._block(chunk, line)
            line += chunk.count(b"\n")
        if self.reader.count == 0:
            raise ParameterError(f"{self.source}: no plots after the header")

    def _block(self, chunk: bytes, line: int) -> Iterator[LinedBlock]:
        fast = self._fast(chunk, line)
        if fast is not None:
            self.reader.count += fast.plots.size
            yield fast
            return
        # Row by row, with ``bounded_lines``' checks on each line: the exact errors.
        plots: list[Plot] = []
        lines: list[int] = []
        for number, plot in self.reader.plots(csv.reader(self._lines(chunk, line)), line):
            plots.append(plot)
            lines.append(number)
        if plots:
            yield LinedBlock(plot_block(plots), np.array(lines, dtype=np.int64))

    def _lines(self, chunk: bytes, line: int) -> Iterator[str]:
        for k, raw in enumerate(io.BytesIO(chunk)):
            if len(raw) > MAX_LINE_BYTES:
                raise ParameterError(
                    f"{self.source} line {line + k + 1}: longer than {MAX_LINE_BYTES} bytes "
                    "(not a plots file?)"
                )
            try:
                yield raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise ParameterError(
                    f"{self.source} line {line + k + 1}: not UTF-8 text (byte "
                    f"{raw[exc.start]:#04x} at column {exc.start + 1})"
                ) from None

    def _fast(self, chunk: bytes, line: int) -> LinedBlock | None:
        """The block parsed and checked as columns, or None (the row-by-row path decides)."""
        import pyarrow as pa
        import pyarrow.compute as pc
        import pyarrow.csv as pcsv

        if b'"' in chunk or b"\r" in chunk or b"\n\n" in chunk or chunk.startswith(b"\n"):
            return None
        ends = np.flatnonzero(np.frombuffer(chunk, dtype=np.uint8) == 10)
        if ends.size and np.diff(ends, prepend=-1).max() > MAX_LINE_BYTES:
            return None
        try:
            chunk.decode("utf-8")
        except UnicodeDecodeError:
            return None
        header = self.reader.header
        types = {h: pa.float64() for h in header if h in _NUMERIC}
        types.update({h: pa.string() for h in header if h not in _NUMERIC})
        try:
            table = pcsv.read_csv(
                io.BytesIO(chunk),
                read_options=pcsv.ReadOptions(column_names=header, use_threads=False),
                parse_options=pcsv.ParseOptions(quote_char=False),
                convert_options=pcsv.ConvertOptions(
                    column_types=types, strings_can_be_null=False, quoted_strings_can_be_null=False
                ),
            )
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
            return None
        n = table.num_rows
        if n != ends.size + (0 if chunk.endswith(b"\n") else 1):
            return None

        def col(name: str) -> NDArray[np.float64] | None:
            c = table.column(name)
            if c.null_count:
                return None
            return to_numpy(c)

        t, r, az = col("time_s"), col("range_m"), col("azimuth_deg")
        if t is None or r is None or az is None:
            return None
        ok = (np.abs(t) <= MAX_TIME_S).all() and (r > 0).all() and (r <= MAX_RANGE_M).all()
        if not (ok and (np.abs(az) <= 360).all()):
            return None  # NaN fails these too
        names = pc.utf8_trim_whitespace(table.column("radar"))
        radar = pc.index_in(names, value_set=self._names)
        if radar.null_count:
            return None
        radar_i = to_numpy(radar).astype(np.intp)
        el = None
        if self.reader.three_d:
            el = col("elevation_deg")
            if el is None or not (np.abs(el) <= 90).all() or not self._has_el[radar_i].all():
                return None
            el = np.radians(el)
        vr = None
        if self.reader.doppler:
            vr = to_numpy(table.column("radial_velocity_mps"))
            given = ~np.isnan(vr) if table.column("radial_velocity_mps").null_count else None
            v = vr if given is None else vr[given]
            if np.isnan(v).any() or not (np.abs(v) <= MAX_RADIAL_VELOCITY_MPS).all():
                return None
            if not self._has_vr[radar_i if given is None else radar_i[given]].all():
                return None
        labels: tuple[str, ...] = ("",)
        target = np.zeros(n, dtype=np.intp)
        if self.reader.targets:
            enc = pc.dictionary_encode(pc.utf8_trim_whitespace(table.column("target")))
            enc = enc.combine_chunks() if hasattr(enc, "combine_chunks") else enc
            labels = tuple(enc.dictionary.to_pylist())
            if "" in labels:
                return None
            target = to_numpy(enc.indices).astype(np.intp)
        if not self._in_order(t, target, labels):
            return None
        return LinedBlock(
            PlotBlock(t, r, np.radians(az), el, vr, radar_i, self.table, target, labels),
            line + 1 + np.arange(n, dtype=np.int64),
        )

    def _in_order(self, t: NDArray, target: NDArray[np.intp], labels: tuple[str, ...]) -> bool:
        """Times do not decrease (within each target with a target column), from the
        previous block on; the reader's state is moved past the block when they do not."""
        rd = self.reader
        if not rd.targets:
            if t[0] < rd.last_t or (np.diff(t) < 0).any():
                return False
            rd.last_t = float(t[-1])
            return True
        order = np.argsort(target, kind="stable")
        ts, gs = t[order], target[order]
        same = gs[1:] == gs[:-1]
        if (np.diff(ts)[same] < 0).any():
            return False
        first = np.flatnonzero(np.concatenate([[True], ~same]))
        last = np.concatenate([first[1:] - 1, [gs.size - 1]])
        prev = np.array([rd.last_of.get(labels[g], -np.inf) for g in gs[first]])
        if (ts[first] < prev).any():
            return False
        for g, v in zip(gs[last].tolist(), ts[last].tolist(), strict=True):
            rd.last_of[labels[g]] = v
        return True


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------

_STATE_COLS = [k for _, k in _COMPONENTS]  # index into (x, ẋ, y, ẏ, z, ż) per column


@functools.lru_cache(maxsize=65_536)
def _quoted(text: str) -> bytes:
    """A text cell as pyarrow's writer quotes it (always, inner quotes doubled)."""
    return b'"' + text.replace('"', '""').encode("utf-8") + b'"'


class BlockWriter:
    """The track file written one block of plots at a time (the columns and the number
    formatting of ``viz_app.io.plots.TrackWriter``, pyarrow's, byte for byte).

    The rows are formatted by the compiled ``viz_app.io.csv_text.format_track_rows``
    (Schubfach's shortest round-trip digits, in pyarrow's layout; about 5× pyarrow's speed), a
    block's rows split over ``WRITE_THREADS`` threads (the kernel releases the GIL) while the
    next block is read and tracked, and written in order.

    With ``parquet`` the block's columns become one pyarrow table, written as one row group
    of a Parquet file (``viz_app.io.plots.parquet_writer``: the same columns and float64
    values, no text) by one thread while the next block is tracked.

    Args:
        fh: the binary file (``atomic_write``'s).  targets: with a ``target`` column.
        methods: the tracker's methods (rows: plot order, then this order).
        where: the finite-result check's prefix ("track: FILE").
        parquet: write Parquet instead of CSV.
    """

    def __init__(
        self,
        fh: IO[bytes],
        targets: bool,
        methods: tuple[str, ...],
        where: str,
        parquet: bool = False,
    ):
        self.fh, self.targets, self.methods, self.where = fh, targets, methods, where
        self.columns = track_columns(targets)
        self.rows = 0
        self._parquet = parquet_writer(fh, targets) if parquet else None
        from concurrent.futures import ThreadPoolExecutor

        from radarviz.core.cores import available_cores

        # One single-thread pool per slice: slice i always goes to pool i; one more thread
        # writes the slices' text in order, so the tracker never waits for the disk.
        n = 1 if parquet else max(1, min(WRITE_THREADS, available_cores()))
        self._workers = [ThreadPoolExecutor(1) for _ in range(n)]
        self._output = ThreadPoolExecutor(1)
        # The written blocks' futures, oldest first: at most IN_FLIGHT blocks are formatted
        # or written at a time (the memory bound), each with its own set of buffers.
        self._pending: list[list[Future[None]]] = []
        self._methods = [_quoted(m) for m in methods]
        self._buffers = [
            [np.empty(0, dtype=np.uint8) for _ in self._workers] for _ in range(IN_FLIGHT)
        ]
        self._blocks = 0
        self._written = self._advised = 0  # bytes of text written, and when last advised
        if parquet:
            self._method_names = strings(methods)

    def add(self, block: PlotBlock, tracks: TrackBlock) -> None:
        """One block's plots and every method's posterior after each (B, M, n)."""
        b, m, n = tracks.x.shape
        rows = b * m
        x = tracks.x.reshape(rows, n)
        P = tracks.P.reshape(rows, n * n)
        self._check(block, tracks, x, P)
        state_of, cov_of = _column_index(n)
        times = np.ascontiguousarray(block.time_s, dtype=np.float64)
        if self._parquet is not None:
            self._drain(1)
            self.rows += rows
            target = block.target if self.targets else None
            job = self._workers[0].submit(
                self._write_table, times, target, block.labels, x, P, state_of, cov_of
            )
            self._pending.append([job])
            return
        # The text cells: the block's labels, then the methods, each quoted once.
        cells = ([_quoted(t) for t in block.labels] if self.targets else []) + self._methods
        text = np.frombuffer(b"".join(cells), dtype=np.uint8)
        start = np.zeros(len(cells) + 1, dtype=np.int64)
        start[1:] = np.cumsum([len(c) for c in cells])
        label_cells = len(cells) - m
        target = block.target.astype(np.int64) if self.targets else np.zeros(b, np.int64)
        widest = max(len(c) for c in cells)
        self._drain(IN_FLIGHT)
        if self.rows == 0:
            self.fh.write(b",".join(_quoted(c) for c in self.columns) + b"\n")
        self.rows += rows
        buffers = self._buffers[self._blocks % IN_FLIGHT]
        self._blocks += 1
        k = len(self._workers)
        step = -(-b // k)  # plots per slice (a plot's rows share its time)
        jobs = [
            pool.submit(
                self._format,
                buffers,
                i,
                times[i * step : (i + 1) * step],
                target[i * step : (i + 1) * step],
                label_cells,
                text,
                start,
                x[i * step * m : (i + 1) * step * m],
                P[i * step * m : (i + 1) * step * m],
                state_of,
                cov_of,
                widest,
            )
            for i, pool in enumerate(self._workers)
            if i * step < b
        ]
        self._pending.append([self._output.submit(self._write, job) for job in jobs])

    def _write(self, job: Future[memoryview]) -> None:
        """The output thread: a slice's text, once formatted, to the file (in submission
        order: one thread); every ``WRITEBACK_BYTES`` the kernel is asked to start writing
        what is written so far to the disk (``_start_writeback``)."""
        text = job.result()
        self.fh.write(text)
        self._written += len(text)
        if self._written - self._advised >= WRITEBACK_BYTES:
            self._start_writeback()

    def _start_writeback(self) -> None:
        """Start the disk writes of the file's text so far (``posix_fadvise`` DONTNEED:
        asynchronous, and the pages written leave the page cache). Without it the whole file
        (2–4 GB at 10⁶ plots) waits in memory for ``atomic_write``'s fsync, which then takes
        seconds at the end of the run with nothing else to do; a system without the call, or
        a file that refuses it, keeps that behaviour."""
        advise = getattr(os, "posix_fadvise", None)
        if advise is None:
            return
        try:
            self.fh.flush()
            advise(self.fh.fileno(), 0, 0, os.POSIX_FADV_DONTNEED)
        except (OSError, AttributeError, ValueError):  # not a real file (a pipe, a buffer)
            return
        self._advised = self._written

    def _format(
        self,
        buffers: list[NDArray[np.uint8]],
        slot: int,
        times: NDArray,
        target: NDArray,
        label_cells: int,
        text: NDArray,
        start: NDArray,
        x: NDArray,
        P: NDArray,
        state_of: NDArray,
        cov_of: NDArray,
        widest: int,
    ) -> memoryview:
        """Rows as CSV bytes by ``csv_text.format_track_rows`` (thread ``slot`` of the pool),
        into that thread's buffer of the block's set ``buffers`` (reused: a set's text is
        written before the set is taken again, ``IN_FLIGHT`` blocks later)."""
        from radarviz.viz_app.io.csv_text import format_track_rows

        n_cols = 1 + 1 + (label_cells > 0) + state_of.size + cov_of.size
        need = (n_cols * (_FLOAT_BYTES + 1) + 2 * widest + 1) * x.shape[0] + 64
        buf = buffers[slot]
        if buf.size < need:
            buf = buffers[slot] = np.empty(need + need // 4, dtype=np.uint8)
        size = format_track_rows(
            times.view(np.uint64),
            target,
            label_cells,
            text,
            start,
            x.view(np.uint64),
            P.view(np.uint64),
            state_of,
            cov_of,
            buf,
        )
        return memoryview(buf)[:size]

    def _write_table(
        self,
        times: NDArray,
        target: NDArray | None,
        labels: tuple[str, ...],
        x: NDArray,
        P: NDArray,
        state_of: NDArray,
        cov_of: NDArray,
    ) -> bytes:
        """The block's rows (B·M, plot order then method order) as one row group (the
        writer's thread: the columns are gathered and the table built off the tracker's)."""
        import pyarrow as pa

        from radarviz.viz_app.io.csv_text import track_columns_into

        b, rows = times.size, x.shape[0]
        m = rows // b
        columns = np.empty((state_of.size + cov_of.size, rows))
        track_columns_into(x, P, state_of, cov_of, columns)
        methods = pa.DictionaryArray.from_arrays(
            from_numpy(np.tile(np.arange(m, dtype=np.int32), b)), self._method_names
        )
        text = [methods.cast(pa.string())]
        if target is not None:
            cells = pa.DictionaryArray.from_arrays(
                from_numpy(np.repeat(target.astype(np.int32), m)), strings(labels)
            )
            text.insert(0, cells.cast(pa.string()))
        arrays = [from_numpy(np.repeat(times, m)), *text, *(from_numpy(c) for c in columns)]
        self._parquet.write_table(pa.Table.from_arrays(arrays, schema=self._parquet.schema))
        # the text file's writeback (``_write``) applies to the row groups as well
        self._written = self.fh.tell()
        if self._written - self._advised >= WRITEBACK_BYTES:
            self._start_writeback()
        return b""

    def _drain(self, keep: int = 0) -> None:
        """Wait until fewer than ``keep`` blocks are in flight (0: none); a failed format or
        write raises here."""
        while len(self._pending) >= max(keep, 1):
            for job in self._pending.pop(0):
                job.result()

    def _check(self, block: PlotBlock, tracks: TrackBlock, x: NDArray, P: NDArray) -> None:
        """``check_track_rows`` on the whole block at once (every entry finite, variances
        not negative; ``x`` (B·M, n), ``P`` (B·M, n·n)); its message at the first bad plot."""
        from radarviz.viz_app.io.csv_text import first_bad_row

        bad = first_bad_row(x, P)
        if bad < 0:
            return
        i = bad // len(self.methods)
        one = TrackBlock(tracks.x[i : i + 1], tracks.P[i : i + 1], tracks.target[i : i + 1])
        (rows,) = state_rows(one, self.methods)
        check_track_rows(f"{self.where} at time {float(block.time_s[i])!r} s", rows)

    def close(self) -> None:
        """Write what is being formatted and stop the threads (and finish a Parquet file)."""
        try:
            self._drain()
        finally:
            for pool in (*self._workers, self._output):
                pool.shutdown(wait=True, cancel_futures=True)
        if self._parquet is not None:
            self._parquet.close()

    def abandon(self) -> None:
        """After an error (the staged file is then removed): stop the threads and release a
        Parquet writer without reporting what fails meanwhile (the first error is the one
        that matters)."""
        for pool in (*self._workers, self._output):
            pool.shutdown(wait=True, cancel_futures=True)
        if self._parquet is not None:
            with contextlib.suppress(Exception):
                self._parquet.close()

    def verify(self, path: str | os.PathLike) -> None:
        """``atomic_write``'s check of the staged file (Parquet: ``verify_track_parquet``;
        a CSV file is checked by its size alone)."""
        if self._parquet is not None:
            verify_track_parquet(path, self.columns, self.rows)


#: Most bytes of one formatted float ("-0.0000012345678901234567"; a scientific one has 24).
_FLOAT_BYTES = 25


@functools.lru_cache(maxsize=8)
def _column_index(n: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """For a state of ``n`` components: the index into x (n,) of each state column of the
    track file and into P (n·n,) of each covariance column; −1 where the component is
    absent (the column is 0)."""
    state = np.array([k if k < n else -1 for k in _STATE_COLS], dtype=np.int64)
    cov = []
    for p, q in _PAIRS:
        i, j = _COMPONENTS[p][1], _COMPONENTS[q][1]
        cov.append(i * n + j if i < n and j < n else -1)
    return state, np.array(cov, dtype=np.int64)


def track_blocks(
    reader: BlockSource,
    methods: tuple[str, ...],
    options: StreamOptions,
    on_block: Callable[[PlotBlock, TrackBlock], None],
) -> tuple[int, tuple[str, ...]]:
    """Track every block of ``reader`` with a ``TargetTracker`` (a file without target
    labels: one target labelled ""); ``on_block(plots, tracks)`` after each. Returns (plots,
    targets). Tracker errors come back as "SOURCE " + ``reader.locate(position, column)`` +
    ": …" of the plot they are about (a CSV's "line L, column C", ASTERIX's "byte N, record
    K, item I048/xxx")."""
    from radarviz.core.tracking.stream import PlotError

    try:
        tracker = TargetTracker(methods, reader.three_d, options)
    except ParameterError as exc:  # errors about the options: the CLI names the flag
        if exc.parameter:
            raise
        raise ParameterError(f"--{exc}") from None
    plots = 0
    for block, positions in reader.blocks():
        try:
            tracks = tracker.add_arrays(block)
        except PlotError as exc:
            where = reader.locate(int(positions[exc.index]), exc.column)
            raise ParameterError(f"{reader.source} {where}: {exc}") from None
        on_block(block, tracks)
        plots += block.size
    return plots, tracker.targets if reader.targets else ()


def block_source(
    open_source: SourceFactory | None,
) -> Callable[[IO[bytes], str, dict[str, Radar]], BlockSource] | None:
    """The ``BlockSource`` of the input a ``SourceFactory`` reads plot by plot: CSV's
    ``PlotBlockReader``, ASTERIX's ``AsterixReader``; None for another (the row path)."""
    if open_source in (None, csv_source):
        return PlotBlockReader
    from radarviz.viz_app.io.asterix import (
        AsterixReader,
        asterix_source,
        capture_reader,
        capture_source,
    )

    if open_source is capture_source:
        return capture_reader
    return AsterixReader if open_source is asterix_source else None


def run_track(
    input_path: str,
    radars_path: str,
    out_path: str,
    methods: tuple[str, ...] | None = None,
    options: StreamOptions | None = None,
    observer: ObserverFactory | None = None,
    open_source: SourceFactory | None = None,
    association: AssociationOptions | None = None,
) -> TrackSummary:
    """``radarviz track``: ``input_path`` tracked into ``out_path``. A CSV or ASTERIX file
    (``open_source``: ``block_source``) without a recording (``observer``) or association,
    with the first-plot start and no finite-memory track, in blocks of columns (this module;
    the tracks of ``viz_app.io.plots.run_track`` to rounding, the same errors); otherwise by
    ``viz_app.io.plots.run_track``, a ``Plot`` at a time."""
    import time
    from contextlib import ExitStack

    from radarviz.core.experiments.prosov import ALL_METHODS
    from radarviz.core.filters.methods import METHODS_3D
    from radarviz.viz_app.io.atomic import atomic_write
    from radarviz.viz_app.io.plots import _open_input, load_radars
    from radarviz.viz_app.io.plots import run_track as run_track_rows

    options = options or StreamOptions()
    open_blocks = block_source(open_source)
    rows_only = (
        observer is not None
        or options.init != "first-plot"
        or options.finite_memory_k
        or open_blocks is None
        or association is not None
    )
    if rows_only or open_blocks is None:  # (the type checker's narrowing)
        return run_track_rows(
            input_path, radars_path, out_path, methods, options, observer, open_source, association
        )
    radars = load_radars(radars_path)
    start = time.perf_counter()
    with ExitStack() as stack:
        fh = stack.enter_context(_open_input(input_path))
        reader = open_blocks(fh, input_path, radars)
        three_d = reader.three_d
        if methods is None:
            methods = METHODS_3D if three_d else ALL_METHODS
        writer: BlockWriter | None = None

        def verify(path: Path) -> None:
            if writer is not None:
                writer.verify(path)

        out = stack.enter_context(atomic_write(out_path, "wb", verify=verify))
        writer = BlockWriter(
            out,
            reader.targets,
            tuple(methods),
            f"track: {input_path}",
            parquet=is_parquet(out_path),
        )
        try:
            plots, targets = track_blocks(reader, tuple(methods), options, writer.add)
        except BaseException:
            writer.abandon()
            raise
        writer.close()
    seconds = time.perf_counter() - start
    return TrackSummary(
        plots, writer.rows, three_d, tuple(methods), seconds, targets, input_summary(reader)
    )
