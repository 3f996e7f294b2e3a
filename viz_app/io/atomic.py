"""Files that appear whole or not at all.

Every output of the command line (track and measurement CSVs, radars TOML, Parquet tables,
sweep chunks, figures) is written under a temporary name beside its target and renamed onto it
only when complete, so a crash or a bad input never leaves half a file, and an existing file is
replaced in one step or left untouched. (Rerun recordings, which the SDK writes by path, do the
same in ``viz_app.rerun.recording.recording_file``.)
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any


@contextmanager
def atomic_write(
    path: str | os.PathLike, mode: str = "wb", fsync: bool = False, **open_kwargs: Any
) -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path``; rename it onto ``path`` when the block ends.

    On any error (the block's or the write's) the temporary file is deleted and ``path`` is
    untouched. The file gets the permissions a plain ``open`` would give (0o666 less the
    umask; ``mkstemp`` alone makes 0o600). ``fsync``: flush to disk before the rename.
    ``open_kwargs`` go to ``open`` (e.g. ``newline=""``, ``encoding="utf-8"`` for text).
    """
    target = Path(path)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    try:
        umask = os.umask(0o022)
        os.umask(umask)
        os.chmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, mode, **open_kwargs) as fh:
            yield fh
            if fsync:
                fh.flush()
                os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
