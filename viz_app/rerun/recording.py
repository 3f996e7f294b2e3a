"""Core results → Rerun entities. One entity-path scheme, logged column-wise.

Entity paths (``{m}`` a method such as ``naive`` or ``ducm``, ``{r}`` a radar name):

    world/radars/{r}                 radar site: a labelled point (label carries σr, σβ, …)
    world/truth/position             true target position per scan
    world/truth/path                 the whole true trajectory (static line strip)
    world/measurements/{r}           each radar's measurement, converted naively, per scan
    world/converted/{m}              the converted point of each method, per scan
    world/tracks/{m}/position        track position per scan
    world/tracks/{m}/path            track path (static line strip)
    world/tracks/{m}/covariance      1σ position ellipsoid per scan
    world/tracks/{m}/velocity        velocity arrow per scan (length = 1 scan period of motion)
    world/fused_velocity/vector      multi-radar velocity arrow; …/covariance its ellipsoid
    world/monte_carlo/{m}/cloud      Monte Carlo cloud of converted points around the target
    world/monte_carlo/{m}/mean       that cloud's mean; world/monte_carlo/truth the true point
    plots/{metric}/{m}               time series per method (bias_range, rmse_x, sigma_x_filter,
                                     nees_pos, …); plots/nees_pos/band95_lo|hi the χ² band
    plots/delta_x/{reading}          Prosov's Δx(n), readings filter / rmse / std
    plots/finite_memory/...          Gorshkov σ and gains per radar and variant, against k
    log                              text log: warnings (e.g. a bad velocity geometry)

Timelines: ``scan`` (sequence n = 1 …) and ``time`` (duration, s). Everything per scan goes
through ``send_columns`` (one call per entity, not one ``log`` per scan).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import uuid
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from numpy.typing import NDArray

from radarviz.viz_app.palette import rgb

APPLICATION_ID = "radarviz"


def colour(name: str) -> tuple[int, int, int]:
    """A method's (or other named thing's) colour from the one palette (``viz_app.palette``)."""
    return rgb(name)


def new_recording(recording_id: str | None = None) -> rr.RecordingStream:
    """A fresh stream (never the global one); a new recording id unless one is given."""
    return rr.RecordingStream(APPLICATION_ID, recording_id=recording_id or str(uuid.uuid4()))


@contextlib.contextmanager
def recording_file(
    path: str | os.PathLike, overwrite: bool = False
) -> Iterator[rr.RecordingStream]:
    """Log into a new recording saved at ``path``, atomically.

    The stream writes to a temporary file beside ``path``; on success it is flushed,
    disconnected (which writes the footer) and renamed onto ``path``. On any error the
    temporary file is removed and ``path`` is untouched. Refuses to replace an existing file
    unless ``overwrite``.
    """
    target = Path(path)
    if target.exists() and not overwrite:
        raise FileExistsError(17, "refusing to overwrite (pass --overwrite)", str(target))
    if not target.parent.is_dir():
        raise FileNotFoundError(2, "no such directory", str(target.parent))
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; a shared recording wants the default
    rec = new_recording()
    try:
        rec.save(tmp)
        yield rec
        rec.flush()
        rec.disconnect()
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(Exception):
            rec.disconnect()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def _indexes(scans: NDArray, times: NDArray) -> list[rr.TimeColumn]:
    return [
        rr.TimeColumn("scan", sequence=np.asarray(scans, dtype=np.int64)),
        rr.TimeColumn("time", duration=np.asarray(times, dtype=np.float64)),
    ]


def _xyz(points: NDArray) -> NDArray[np.float64]:
    """(N, 2) or (N, 3) → (N, 3), z = 0 for planar results."""
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-1] == 3:
        return p
    return np.concatenate([p, np.zeros((*p.shape[:-1], 1))], axis=-1)


def log_radar_site(rec: rr.RecordingStream, name: str, position: Sequence[float], label: str):
    """A radar site as a static labelled point; ``label`` carries its accuracy."""
    rec.log(
        f"world/radars/{name}",
        rr.Points3D(
            [_xyz(np.asarray(position, dtype=float)[None])[0]],
            labels=[label],
            radii=[400.0],
            colors=[(0, 0, 0)],
        ),
        static=True,
    )


def log_truth(
    rec: rr.RecordingStream,
    scans: NDArray,
    times: NDArray,
    positions: NDArray,
    root: str = "world/truth",
):
    """True positions per scan and the whole path (static)."""
    p = _xyz(positions)
    rec.send_columns(
        f"{root}/position",
        indexes=_indexes(scans, times),
        columns=rr.Points3D.columns(positions=p, radii=[300.0] * len(p)),
    )
    rec.log(f"{root}/path", rr.LineStrips3D([p], colors=[colour("truth")]), static=True)


def log_points(
    rec: rr.RecordingStream,
    entity: str,
    scans: NDArray,
    times: NDArray,
    positions: NDArray,
    rgb: tuple[int, int, int],
    radius: float = 200.0,
) -> None:
    """One point per scan at ``entity``."""
    p = _xyz(positions)
    rec.send_columns(
        entity,
        indexes=_indexes(scans, times),
        columns=rr.Points3D.columns(positions=p, colors=[rgb] * len(p), radii=[radius] * len(p)),
    )


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


def position_cov_3d(P: NDArray[np.float64]) -> NDArray[np.float64]:
    """The (N, 3, 3) position covariance of CV states (x, ẋ, y, ẏ[, z, ż]); planar → σz = 0."""
    if P.shape[-1] == 6:
        return P[..., [0, 2, 4], :][..., :, [0, 2, 4]]
    out = np.zeros((*P.shape[:-2], 3, 3))
    out[..., :2, :2] = P[..., [0, 2], :][..., :, [0, 2]]
    return out


def log_track(
    rec: rr.RecordingStream,
    method: str,
    scans: NDArray,
    times: NDArray,
    x: NDArray[np.float64],
    P: NDArray[np.float64],
    period: float,
) -> None:
    """Track position, path, 1σ covariance ellipsoid and velocity arrow per scan.

    ``x`` (N, 4) or (N, 6) CV states (x, ẋ, y, ẏ[, z, ż]); ``P`` their covariances.
    """
    rgb = colour(method)
    if x.shape[-1] == 6:
        pos, vel = x[:, [0, 2, 4]], x[:, [1, 3, 5]]
    else:
        pos, vel = _xyz(x[:, [0, 2]]), _xyz(x[:, [1, 3]])
    base = f"world/tracks/{method}"
    idx = _indexes(scans, times)
    n = len(pos)
    rec.send_columns(
        f"{base}/position",
        indexes=idx,
        columns=rr.Points3D.columns(positions=pos, colors=[rgb] * n, radii=[250.0] * n),
    )
    rec.log(f"{base}/path", rr.LineStrips3D([pos], colors=[rgb]), static=True)
    half, quat = ellipsoid_axes(position_cov_3d(P))
    half = np.maximum(half, 1.0)  # planar tracks: give the zero axis a visible thickness
    rec.send_columns(
        f"{base}/covariance",
        indexes=idx,
        columns=rr.Ellipsoids3D.columns(
            centers=pos, half_sizes=half, quaternions=quat, colors=[rgb] * n
        ),
    )
    rec.send_columns(
        f"{base}/velocity",
        indexes=idx,
        columns=rr.Arrows3D.columns(origins=pos, vectors=vel * period, colors=[rgb] * n),
    )


def log_velocity(
    rec: rr.RecordingStream,
    scans: NDArray,
    times: NDArray,
    position: NDArray,
    position_cov: NDArray,
    velocity: NDArray,
    velocity_cov: NDArray,
    period: float,
) -> None:
    """Fused position (point + 1σ ellipsoid) and the multi-radar velocity vector per scan.

    The arrow is drawn from the fused position, as the motion over one scan period; its error
    ellipsoid (1σ of the velocity, times the period) sits at the arrow's tip. Scans whose
    velocity is NaN (geometry flagged) get no arrow and no ellipsoid.
    """
    idx = _indexes(scans, times)
    n = len(position)
    rgb = (230, 80, 20)
    rec.send_columns(
        "world/fusion/position",
        indexes=idx,
        columns=rr.Points3D.columns(
            positions=position, colors=[(0, 120, 200)] * n, radii=[250.0] * n
        ),
    )
    half, quat = ellipsoid_axes(position_cov)
    rec.send_columns(
        "world/fusion/position_covariance",
        indexes=idx,
        columns=rr.Ellipsoids3D.columns(
            centers=position, half_sizes=half, quaternions=quat, colors=[(0, 120, 200)] * n
        ),
    )
    ok = np.all(np.isfinite(velocity), axis=-1)
    if not ok.any():
        return
    idx_ok = _indexes(np.asarray(scans)[ok], np.asarray(times)[ok])
    k = int(ok.sum())
    vec = velocity[ok] * period
    rec.send_columns(
        "world/fused_velocity/vector",
        indexes=idx_ok,
        columns=rr.Arrows3D.columns(origins=position[ok], vectors=vec, colors=[rgb] * k),
    )
    half_v, quat_v = ellipsoid_axes(velocity_cov[ok] * period**2)
    rec.send_columns(
        "world/fused_velocity/covariance",
        indexes=idx_ok,
        columns=rr.Ellipsoids3D.columns(
            centers=position[ok] + vec,
            half_sizes=np.maximum(half_v, 1.0),
            quaternions=quat_v,
            colors=[rgb] * k,
        ),
    )


def log_series(
    rec: rr.RecordingStream,
    entity: str,
    scans: NDArray,
    times: NDArray,
    values: NDArray,
    rgb: tuple[int, int, int] | None = None,
    name: str | None = None,
):
    """A scalar time series; non-finite values (undefined scans) are left out."""
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
    rec.send_columns(
        entity,
        indexes=_indexes(np.asarray(scans)[ok], np.asarray(times)[ok]),
        columns=rr.Scalars.columns(scalars=v[ok]),
    )


def log_cloud(rec: rr.RecordingStream, method: str, points: NDArray, truth: NDArray) -> None:
    """A static Monte Carlo cloud of one method's converted points, its mean and the truth."""
    rgb = colour(method)
    p = _xyz(points)
    rec.log(
        f"world/monte_carlo/{method}/cloud", rr.Points3D(p, colors=[rgb], radii=[30.0]), static=True
    )
    rec.log(
        f"world/monte_carlo/{method}/mean",
        rr.Points3D([p.mean(axis=0)], colors=[rgb], radii=[120.0], labels=[f"{method} mean"]),
        static=True,
    )
    rec.log(
        "world/monte_carlo/truth",
        rr.Points3D(
            [_xyz(np.asarray(truth, dtype=float)[None])[0]],
            colors=[colour("truth")],
            radii=[120.0],
            labels=["truth"],
        ),
        static=True,
    )


def log_text(rec: rr.RecordingStream, text: str, level: str = "INFO", scan: int = 1) -> None:
    """A line in the text log at ``scan`` (the text-log view lists timed entries)."""
    rec.send_columns(
        "log",
        indexes=[rr.TimeColumn("scan", sequence=[scan])],
        columns=rr.TextLog.columns(text=[text], level=[level]),
    )


def default_blueprint(
    series: Sequence[str] = ("bias_range", "rmse_x", "nees_pos"),
    centre: Sequence[float] = (0.0, 0.0, 0.0),
    extent_m: float = 300e3,
) -> rrb.Blueprint:
    """3D view, top-down view of the same scene, time-series panels, text log.

    The top-down view is a 3D view whose eye looks straight down on ``centre`` from
    ``extent_m`` above, y up (a 2D view cannot show 3D entities).
    """
    plots = [rrb.TimeSeriesView(origin=f"plots/{name}", name=name) for name in series]
    cx, cy, cz = (float(v) for v in centre)
    top_down = rrb.Spatial3DView(
        origin="world",
        name="top-down",
        eye_controls=rrb.EyeControls3D(
            position=(cx, cy, cz + extent_m), look_target=(cx, cy, cz), eye_up=(0.0, 1.0, 0.0)
        ),
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Horizontal(rrb.Spatial3DView(origin="world", name="3D"), top_down),
                rrb.TextLogView(origin="log", name="log"),
                row_shares=[3, 1],
            ),
            rrb.Vertical(*plots, name="time series"),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )
