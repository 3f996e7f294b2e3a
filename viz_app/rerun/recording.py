"""Rerun streams and the logging helpers every scene shares.

Each scene has its own entity root and documents its paths: ``prosov/…``
(``prosov_scene``), ``velocity/…`` (``velocity_scene``), ``gorshkov/…``
(``gorshkov_scene``), ``world/…`` for a measurement file's tracks
(``track_recording``), ``sweep/…`` for sweeps (``viz_app.sweep.output``). Time series go to
``plots/<scene>/<quantity_unit>/<series>`` (values, on the timelines) and are drawn as charts
with their own axes at ``charts/<scene>/<quantity_unit>`` (``plot2d``); ``log`` is the text
log.

Timelines: ``scan`` (sequence n = 1 …) and ``time`` (duration, s). Everything per scan goes
through ``send_columns`` (one call per entity, not one ``log`` per scan).
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import uuid
import warnings
from collections.abc import Callable, Iterator

import numpy as np
import rerun as rr
from numpy.typing import NDArray

from radarviz.viz_app.io.atomic import Stage
from radarviz.viz_app.palette import rgb

APPLICATION_ID = "radarviz"


def colour(name: str) -> tuple[int, int, int]:
    """A method's (or other named thing's) colour from the one palette (``viz_app.palette``)."""
    return rgb(name)


def new_recording(recording_id: str | None = None) -> rr.RecordingStream:
    """A fresh stream (never the global one); a new recording id unless one is given."""
    return rr.RecordingStream(APPLICATION_ID, recording_id=recording_id or str(uuid.uuid4()))


#: The open ``recording_file(..., to_disk=True)`` streams: id of the recording → pushes what
#: it has logged so far to its temporary file (``drain``).
_DRAINS: dict[int, Callable[[], None]] = {}


@contextlib.contextmanager
def recording_file(
    path: str | os.PathLike, overwrite: bool = False, *, to_disk: bool = False
) -> Iterator[rr.RecordingStream]:
    """Log into a new recording saved at ``path``: written, verified, then renamed onto it.

    The stream logs into memory (``binary_stream``; the SDK's own file writer can stall and
    hang the process on a full disk, and logs our temporary name). When the block ends the
    stream is flushed and disconnected (which ends it with the footer) and its bytes go
    through ``viz_app.io.atomic``: a staged temporary file beside ``path``, fsynced, read back
    whole (:func:`verify_recording`), renamed. On any error — a full disk included — the
    temporary file is removed, ``path`` is untouched and a ``WriteError`` names ``path``.
    Refuses to replace an existing file unless ``overwrite`` (also when another run creates
    it meanwhile). The encoded recording is held in memory until it is written.

    ``to_disk``: for a recording that grows with its input (``track --rrd``), whose bytes
    held in memory were the whole peak (10⁵ plots of 7 methods: 2.2 GB). The SDK's file sink
    writes the staged file as the stream encodes, and the logger calls :func:`drain` after each
    chunk it logs: the stream is flushed into the file and, before the next chunk, the disk
    must have room for twice the last one, so a disk filling up is a ``WriteError`` of ours,
    not a stalled writer. (The bytes of several ``binary_stream`` reads cannot be one file:
    each read is a whole stream with its own manifest, which the readers refuse.)
    """
    if to_disk:
        with _recording_to_disk(path, overwrite) as rec:
            yield rec
        return
    stage = Stage(path, overwrite=overwrite)  # the target is checked before any work
    try:
        rec = new_recording()
        stream = rec.binary_stream()
    except BaseException:
        stage.abort()
        raise
    try:
        yield rec
        rec.flush()
        rec.disconnect()
        data = stream.read(flush=False) or b""
    except BaseException as exc:
        with contextlib.suppress(Exception):
            rec.disconnect()
            stream.read(flush=False)  # drained: the SDK warns about unread data otherwise
        failure = stage.failed(exc)
        if failure is exc:
            raise
        raise failure from None
    with stage.open("wb") as fh:
        fh.write(data)
    del data
    stage.commit(verify=verify_recording)


@contextlib.contextmanager
def _recording_to_disk(path: str | os.PathLike, overwrite: bool) -> Iterator[rr.RecordingStream]:
    """``recording_file(path, overwrite, to_disk=True)``: the SDK's file sink on the staged
    temporary file, flushed by :func:`drain`."""
    stage = Stage(path, overwrite=overwrite)
    try:
        stage.close_fd()  # the sink opens the temporary file by its name
        rec = new_recording()
        rec.save(stage.path)
    except BaseException:
        stage.abort()
        raise
    written = [0]

    def flush_to_file() -> None:
        rec.flush()
        size = os.stat(stage.path).st_size
        step, written[0] = size - written[0], size
        if shutil.disk_usage(stage.path.parent).free < 2 * step + (1 << 20):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    _DRAINS[id(rec)] = flush_to_file
    try:
        try:
            yield rec
        finally:
            del _DRAINS[id(rec)]
        rec.flush()
        rec.disconnect()
    except BaseException as exc:
        with contextlib.suppress(Exception):
            rec.disconnect()
        failure = stage.failed(exc)
        if failure is exc and isinstance(exc, RuntimeError):  # the SDK's writer failed
            raise stage.error(exc, "the recording's writer failed") from None
        if failure is exc:
            raise
        raise failure from None
    stage.commit(verify=verify_recording)


def drain(rec: rr.RecordingStream) -> None:
    """Flush what ``rec`` has logged into its file, freeing that memory, and check there is
    room for as much again: a ``recording_file(..., to_disk=True)`` stream only (elsewhere,
    e.g. a viewer's stream, nothing is done)."""
    flush = _DRAINS.get(id(rec))
    if flush is not None:
        flush()


#: The first bytes of every Rerun recording file.
RRD_MAGIC = b"RRF2"


def is_recording(path: str | os.PathLike) -> bool:
    """Whether ``path`` starts like a Rerun recording (whole or not: replacing one loses no
    other kind of data)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(len(RRD_MAGIC)) == RRD_MAGIC
    except OSError:
        return False


def verify_recording(path: str | os.PathLike) -> None:
    """Raise unless ``path`` is a whole recording: the equivalent of ``rerun rrd verify``.

    The reader opens the file from its footer's manifest, which only a cleanly ended stream
    has (a file cut short anywhere, even by one byte, has none), and every chunk of every
    store (recordings and blueprints) decodes (a flipped byte of a compressed chunk fails its
    codec; chunks carry no checksum, so one of an uncompressed payload goes unseen). The
    stores are not built: that held a second copy of the recording in memory (the largest
    part of a ``track --rrd`` run's peak after the tracking) and finds nothing more.
    """
    from rerun.chunk import RrdReader

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "no footer/manifest" is a warning of the reader
        reader = RrdReader(path)
        stores = [*reader.recordings(), *reader.blueprints()]
        if not stores:
            raise ValueError("no stores in the file")
        for store in stores:
            for _chunk in reader.stream(store=store):
                pass


def indexes(scans: NDArray, times: NDArray) -> list[rr.TimeColumn]:
    return [
        rr.TimeColumn("scan", sequence=np.asarray(scans, dtype=np.int64)),
        rr.TimeColumn("time", duration=np.asarray(times, dtype=np.float64)),
    ]


def ellipsoid_axes(cov: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """Half sizes (..., 3) (1σ) and rotation quaternions (..., 4) xyzw of covariances (..., 3, 3).

    cov = V diag(λ) Vᵀ (``eigh``): the ellipsoid's half axes are √λ along the columns of V.
    V is orthogonal but its determinant may be −1 (a reflection, which no quaternion
    represents); negating its last column keeps cov = V diag(λ) Vᵀ and makes det V = +1, a
    proper rotation. scipy's ``as_quat`` is scalar last, (x, y, z, w), Rerun's order.
    """
    from scipy.spatial.transform import Rotation  # ~0.5 s to import: only when drawing

    w, v = np.linalg.eigh(cov)
    half = np.sqrt(np.clip(w, 0.0, None))
    v[..., :, 2] *= np.sign(np.linalg.det(v))[..., None]
    quat = Rotation.from_matrix(v.reshape(-1, 3, 3)).as_quat()
    return half, quat.reshape(*v.shape[:-2], 4)


#: An ellipsoid's smallest drawn half axis (m): a collapsed axis stays visible.
MIN_HALF_SIZE_M = 1.0


def ellipsoid_columns(
    centers: NDArray[np.float64], cov: NDArray[np.float64], colors: list
) -> rr.ComponentColumnList:
    """The 1σ ellipsoids of covariances ``cov`` (k, 3, 3) about ``centers`` (k, 3) as
    ``Ellipsoids3D`` columns, one per row (``.partition`` them for rows of several)."""
    half, quat = ellipsoid_axes(cov)
    return rr.Ellipsoids3D.columns(
        centers=centers,
        half_sizes=np.maximum(half, MIN_HALF_SIZE_M),
        quaternions=quat,
        colors=colors,
    )


def log_series(
    rec: rr.RecordingStream,
    entity: str,
    scans: NDArray,
    times: NDArray | None,
    values: NDArray,
    rgb: tuple[int, int, int] | None = None,
    name: str | None = None,
    timeline: str = "scan",
):
    """A scalar series over ``scans`` on the sequence ``timeline`` (and over ``times`` on the
    ``time`` timeline unless None); non-finite values (undefined scans) are left out."""
    v = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(v)
    if not ok.any():
        return
    if rgb is not None or name is not None:
        rec.log(
            entity,
            rr.SeriesLines(colors=[rgb] if rgb else None, names=[name] if name else None),
            static=True,
        )
    at = [rr.TimeColumn(timeline, sequence=np.asarray(scans, dtype=np.int64)[ok])]
    if times is not None:
        at.append(rr.TimeColumn("time", duration=np.asarray(times, dtype=np.float64)[ok]))
    rec.send_columns(entity, indexes=at, columns=rr.Scalars.columns(scalars=v[ok]))


def log_texts(rec: rr.RecordingStream, entries: list[tuple[int, float, str, str]]) -> None:
    """Lines ``(scan, time_s, text, level)`` in the text log on the ``scan`` and ``time``
    timelines, in one chunk (one ``log_text`` per line would be one chunk each for the
    viewer to take in)."""
    if not entries:
        return
    rec.send_columns(
        "log",
        indexes=indexes([e[0] for e in entries], [e[1] for e in entries]),
        columns=rr.TextLog.columns(text=[e[2] for e in entries], level=[e[3] for e in entries]),
    )


def log_text(
    rec: rr.RecordingStream,
    text: str,
    level: str = "INFO",
    scan: int = 1,
    time_s: float = 0.0,
    at: list[rr.TimeColumn] | None = None,
) -> None:
    """A line in the text log at ``scan`` and ``time_s`` (the ``scan`` and ``time``
    timelines), or at ``at`` (one time on each timeline of another recording). The text-log
    view lists only the entries timed on the active timeline: a line on one timeline alone
    leaves the log view empty on the other one."""
    rec.send_columns(
        "log",
        indexes=at if at is not None else indexes([scan], [time_s]),
        columns=rr.TextLog.columns(text=[text], level=[level]),
    )
