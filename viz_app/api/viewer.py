"""Rerun recordings of presets and tracks: written to a file, or shown in a notebook.

The embedded viewer is ``rerun-notebook``'s widget. Its JavaScript and WebAssembly ship in
that package; by default the widget fetches them from the Rerun website, which fails without
internet. Unless ``RERUN_NOTEBOOK_ASSET`` is already set, ``show`` sets it to ``serve-local``
before the widget is first imported: the kernel then serves the package's own files on
localhost and the viewer works offline.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from radarviz.core.params import ParameterError, check_choice, check_int
from radarviz.tracking import Tracks
from radarviz.viz_app.rerun.preset_names import PRESETS

if TYPE_CHECKING:
    import rerun as rr

#: ``RERUN_NOTEBOOK_ASSET`` value that serves the widget's files from the installed package.
OFFLINE_ASSETS = "serve-local"

Recordable = str | Tracks


#: Viewer widths (pixels) below which ``show`` stacks the views (``narrow_layout``).
NARROW_BELOW_PX = 1200


def _log(rec: rr.RecordingStream, what: Recordable, seed: int, narrow: bool = False) -> None:
    """Fill ``rec`` with a preset's scenes or a ``Tracks`` result, and send its blueprint:
    the wide one, or with ``narrow`` the stacked one of ``scenes.narrow_layout``."""
    from radarviz.viz_app.rerun.scenes import blueprint_of, narrow_layout

    if isinstance(what, Tracks):
        from radarviz.viz_app.rerun.track_recording import TrackRecorder

        if not what.radars:
            raise ParameterError(
                "tracks must carry their radars to be recorded (pass radars= to track, or use "
                "track_file)",
                "tracks",
            )
        recorder = TrackRecorder(rec, what.radars)
        what.replay(recorder)
        recorder.close()  # sends the wide blueprint; a later one sent replaces it
        if narrow:
            rec.send_blueprint(blueprint_of(narrow_layout(recorder.layout)))
        return
    if not isinstance(what, str):
        raise ParameterError(
            f"what must be a preset name ({', '.join(PRESETS)}) or Tracks "
            f"(got {type(what).__name__})",
            "what",
        )
    from radarviz.viz_app.rerun.scenes import log_preset

    check_choice("preset", what, PRESETS)
    # glibc's default allocator, not viz_app.runtime.tune_allocator's: the presets' Monte
    # Carlos are a few hundred runs, whose speed the kept memory does not change (the demo's
    # CPU time the same within 0.1 s), while keeping what the Prosov scene's conversion
    # cloud freed held the demo's peak about 25 MB higher (docs/performance.md, section 10).
    layout = log_preset(rec, what, seed=seed)
    rec.send_blueprint(blueprint_of(narrow_layout(layout) if narrow else layout))


def record(
    what: Recordable, path: str | os.PathLike, *, overwrite: bool = False, seed: int = 1
) -> Path:
    """Write a Rerun recording (``.rrd``) of a preset or of ``track`` results.

    The file is written whole or not at all (``radarviz.viz_app.io.atomic``); open it with
    ``radarviz view PATH`` or ``show``.

    A ``Tracks`` result is recorded as ``radarviz track --rrd`` records the same plots: its
    plots and rows go to the command's recorder in the command's order (``Tracks.replay``).
    Tracks of the association (``track_file(..., association=...)``) carry each plot's
    status and each scan's deleted tracks, so the recording is the one of ``track
    --associate gnn --rrd``: tentative tracks and their plots faint, a deleted track cleared
    at the scan that deleted it, paths and time series for confirmed tracks only. (The
    command's log also lists the NIS band exits of its consistency monitor; ``record`` has
    no monitor.)

    Args:
        what: a preset name (``demo``, ``prosov``, ``prosov3d``, ``gorshkov``, ``velocity``,
            ``manoeuvre``: the scenes of ``radarviz record``) or a ``Tracks`` result with its
            radars.
        path: the ``.rrd`` file to write.
        overwrite: replace an existing file.
        seed: root seed of a preset's Monte Carlo.

    Returns:
        The path written.
    """
    from radarviz.viz_app.io.atomic import check_outputs
    from radarviz.viz_app.rerun.recording import recording_file

    check_int("seed", seed, low=0)
    check_outputs([("path", str(path))], overwrite=overwrite)
    if isinstance(what, str):
        check_choice("preset", what, PRESETS)
    with recording_file(path, overwrite=overwrite) as rec:
        _log(rec, what, seed)
    return Path(path)


def use_offline_assets() -> str:
    """Make the notebook viewer load its files from the installed package (see the module
    docstring); returns the ``RERUN_NOTEBOOK_ASSET`` value in force.

    Has no effect once ``rerun_notebook`` is imported: its asset location is fixed then.
    """
    if "rerun_notebook" not in sys.modules:
        os.environ.setdefault("RERUN_NOTEBOOK_ASSET", OFFLINE_ASSETS)
    return os.environ.get("RERUN_NOTEBOOK_ASSET", "")


def show(what: Recordable, *, seed: int = 1, width: int | str = "auto", height: int = 720) -> Any:
    """The embedded Rerun viewer of a preset or of ``track`` results, for a notebook cell.

    Return it as a cell's last value (or call ``.display()`` on it) to show it.

    A notebook cell is about 900 px wide, where the recordings' wide tabs (made for a
    1600 px window) squeeze their charts until the labels cover each other: below
    ``NARROW_BELOW_PX``, and for ``"auto"`` (the cell's width), the views are stacked on
    more tabs instead (``viz_app.rerun.scenes.narrow_layout``: at most three charts or four
    small multiples a tab, the legend above the small multiples).

    Args:
        what: as for ``record``.
        seed: root seed of a preset's Monte Carlo.
        width: viewer width, pixels in [100, 10 000], or ``"auto"`` (the cell's width).
        height: viewer height, pixels in [100, 10 000].

    Returns:
        A ``rerun.notebook.Viewer`` widget holding the recording.
    """
    # Every value is checked before the widget's module is imported: that import starts the
    # asset server, which a call refused for a bad value should not leave behind.
    check_int("seed", seed, low=0)
    if width != "auto":
        check_int("width", width, low=100, high=10_000)
    check_int("height", height, low=100, high=10_000)
    if isinstance(what, str):
        check_choice("preset", what, PRESETS)
    use_offline_assets()
    from rerun.notebook import Viewer

    from radarviz.viz_app.rerun.recording import new_recording

    rec = new_recording()
    _log(rec, what, seed, narrow=width == "auto" or int(width) < NARROW_BELOW_PX)
    return Viewer(width=width, height=height, recording=rec)  # type: ignore[arg-type]
