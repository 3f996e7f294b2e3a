"""The stale-temporary sweeper keeps a live writer's file whatever its pid says
(``viz_app.io.atomic``: ``Stage`` holds a lock on its temporary file, ``remove_stale_temps``
asks the lock before the pid).

A writer in another PID namespace (a container sharing the directory) names its temporary
file with a pid that here is another process or none: by pid alone its file looked like a dead
run's, and the sweeper deleted the file it was writing.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import radarviz.viz_app.io.atomic as atomic
from radarviz.viz_app.io.atomic import Stage, remove_stale_temps

#: A writer elsewhere: opens the file, takes an exclusive flock, says so, waits on stdin.
HOLDER = """
import fcntl, os, sys
fd = os.open(sys.argv[1], os.O_RDWR)
fcntl.flock(fd, fcntl.LOCK_EX)
print("locked", flush=True)
sys.stdin.read()
"""


def test_a_locked_temporary_of_a_pid_unknown_here_is_kept(tmp_path: Path, monkeypatch) -> None:
    out = tmp_path / "o.csv"
    past = time.time() - 3600
    # Pid 999999999 is above any pid_max: dead here, as a container's pid is.
    foreign = tmp_path / ".o.csv.999999999-0badc0de.tmp"
    dead = tmp_path / ".o.csv.999999998-0badc0de.tmp"
    for path in (foreign, dead):
        path.write_text("partial")
        os.utime(path, (past, past))
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(foreign)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        monkeypatch.setattr(atomic, "_SWEPT", set())
        assert remove_stale_temps(out) == [dead]
        assert foreign.read_text() == "partial"
    finally:
        holder.communicate("")
    # The writer gone, its file is a dead run's and goes.
    monkeypatch.setattr(atomic, "_SWEPT", set())
    assert remove_stale_temps(out) == [foreign]


def test_a_stage_holds_its_lock_until_renamed(tmp_path: Path, monkeypatch) -> None:
    """Another process cannot take the lock of a stage's file while it is written, even after
    the writer closed its descriptor, and the sweeper of another run keeps the file."""
    target = tmp_path / "t.csv"
    stage = Stage(target)
    stage.close_fd()  # a writer that opens by path closes the stage's descriptor
    probe = "import fcntl,os,sys; fd=os.open(sys.argv[1], os.O_RDONLY)\n"
    probe += "try:\n fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB); print('free')\n"
    probe += "except BlockingIOError: print('held')"
    check = [sys.executable, "-c", probe, str(stage.path)]
    assert subprocess.run(check, capture_output=True, text=True).stdout.strip() == "held"
    monkeypatch.setattr(atomic, "_RUN_START", time.time() + 60)  # a sweeper started later
    monkeypatch.setattr(atomic, "_SWEPT", set())
    monkeypatch.setattr(os, "getpid", lambda: 999999999)  # ... in another namespace
    assert remove_stale_temps(target) == []
    monkeypatch.undo()
    stage.commit(written=0)
    assert target.exists() and stage._lock_fd is None
