"""Outputs that appear whole and verified, or not at all: the one home of every file write.

Every output of the command line (track and measurement CSVs, radars TOML, Parquet tables,
sweep chunks, figures, Rerun recordings) goes through :class:`Stage`:

1. The target is checked: an existing target that is not a regular file (a directory, FIFO,
   device, socket or symbolic link) is never replaced, and neither is any existing file
   unless the caller overwrites.
2. Stale temporary files of earlier, killed runs beside the target are removed (see
   :func:`remove_stale_temps`).
3. The data go to a new temporary file beside the target, created exclusively, named
   ``.NAME.PID-TOKEN.tmp`` (the creating process is in the name), with the mode the target
   will have: a replaced file keeps its permissions, a new one gets 0o666 less the umask.
4. The temporary file is flushed and fsynced, then **verified**: its size on disk must equal
   the bytes written, and the caller's check must pass (a recording is read back whole).
5. Only then is it renamed onto the target, and the directory fsynced. Without overwrite the
   rename is ``os.link`` (which fails if the target appeared meanwhile), so of two runs
   creating one new file exactly one wins.

Any failure removes the temporary file, leaves the target as it was, and raises
:class:`WriteError`, whose one-line message names the target (never the temporary name).

A command with several outputs (``simulate``'s measurements and radars, ``track --out
--rrd``, ``sweep``'s table, figures and recording) writes them inside :func:`commit_together`:
every stage is written and verified first, and only then are they renamed one after the
other, each replaced target's previous file kept as a hard link (a backup) until the last
rename has succeeded. If a rename fails, the targets already renamed get their previous
files back (``os.replace`` of the backup; a target that did not exist is removed), so the
outputs change together or not at all, as far as POSIX allows: a crash between two renames
can still leave the first replaced, and its backup is then a stale temporary file.
The command line reports it with exit status 1. :func:`check_outputs` is the check before
any work: outputs that equal an input or each other, or that are not regular files, are
refused as bad input (a ``ParameterError`` naming the option, exit status 2).
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import fcntl
import io
import os
import re
import secrets
import shutil
import stat
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import IO, Any

from radarviz.core.params import ParameterError

#: A temporary file whose creator is alive is left alone unless it is at least this old and no
#: longer held open by that process (the pid was reused).
STALE_AGE_S = 600.0
#: Suffixes of this module's temporary files (``.part``: recordings of earlier versions).
TEMP_SUFFIXES = (".tmp", ".part")
#: The target name is cut to this length in temporary names (names stay under NAME_MAX).
_NAME_IN_TEMP = 160
_TEMP_RE = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)-[0-9a-f]{8}\.(?:tmp|part)$")
#: mkstemp names of earlier versions (``.o.csv.8_ielezd.tmp``), matched for the target only.
_LEGACY_TOKEN = r"[a-z0-9_]{8}"
#: When this process started: a temporary file last written before it belongs to another run.
_RUN_START = time.time()
_SWEPT: set[str] = set()
#: The stages verified inside the innermost :func:`commit_together` block, renamed at its end.
_UNIT: contextvars.ContextVar[list[Stage] | None] = contextvars.ContextVar(
    "radarviz_commit_unit", default=None
)


class WriteError(OSError):
    """Writing an output failed; the target is untouched. ``str()`` is one line naming it."""

    def __str__(self) -> str:
        return f"cannot write {self.filename}: {self.strerror}"


def _created_meanwhile(target: Path) -> WriteError:
    """Another run created ``target`` between the start and the end of this write."""
    return WriteError(
        errno.EEXIST,
        "it was created meanwhile by another run (pass --overwrite to replace it)",
        str(target),
    )


def _reason(exc: BaseException) -> str:
    """A one-line reason for ``exc`` that names no file (a temporary name must not leak)."""
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def write_error(target: Path, exc: BaseException | str, code: int = errno.EIO) -> WriteError:
    """A :class:`WriteError` for ``target`` from an exception or a reason."""
    if isinstance(exc, OSError) and exc.errno:
        code = exc.errno
    reason = exc if isinstance(exc, str) else _reason(exc)
    if code == errno.ENOSPC and "space" not in reason.lower():
        reason = f"{os.strerror(errno.ENOSPC)} ({reason})"
    return WriteError(code, reason, str(target))


def _low_space(directory: Path) -> bool:
    """Whether the file system of ``directory`` is (nearly) full: the usual cause of a write
    the SDK reports only as a broken stream."""
    try:
        st = os.statvfs(directory)
    except OSError:
        return False
    return st.f_bavail * st.f_frsize < 1 << 20


def special_kind(path: Path) -> str | None:
    """What ``path`` is if it exists and is not a regular file ("a FIFO", …), else None."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return None
    except OSError as exc:  # e.g. a component is not a directory
        return f"not reachable ({exc.strerror})"
    mode = st.st_mode
    if stat.S_ISREG(mode):
        return None
    for test, kind in (
        (stat.S_ISLNK, "a symbolic link"),
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return kind
    return "not a regular file"


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether two paths name one file: equal once resolved, or one inode (hard links)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_outputs(
    outputs: Sequence[tuple[str, str | os.PathLike | None]],
    inputs: Sequence[tuple[str, str | os.PathLike | None]] = (),
    *,
    overwrite: bool = True,
) -> None:
    """Refuse, before any work, outputs that would lose data; ``ParameterError`` naming the
    option otherwise (the command line's exit status 2).

    ``outputs`` and ``inputs`` are (option, path) pairs; a None path is skipped. An output
    is refused if its name is empty, its directory does not exist, it exists and is not a
    regular file, it exists and ``overwrite`` is false, it exists and is read-only (no write
    permission for anyone), or it is the same file as an input or as another output.
    """
    given = [(flag, p) for flag, p in outputs if p is not None]
    for i, (flag, path) in enumerate(given):
        text = os.fspath(path)
        if not text.strip():
            raise ParameterError(f"{flag} must name a file (got {text!r})")
        target = Path(text)
        kind = special_kind(target)
        if kind is not None:
            raise ParameterError(f"{flag} must name a regular file ({text} is {kind})")
        if not target.parent.is_dir():
            raise ParameterError(f"{flag}: no such directory {str(target.parent)!r}")
        if not os.access(target.parent, os.W_OK | os.X_OK):
            raise ParameterError(
                f"{flag}: the directory {str(target.parent)!r} is not writable (nothing done)"
            )
        if not overwrite and target.exists():
            raise ParameterError(f"{flag} {text} exists: refusing to overwrite (pass --overwrite)")
        if target.exists() and not target.stat().st_mode & 0o222:
            # Renaming over a file needs only the directory's permission: a file its owner
            # made read-only would be replaced without a word.
            raise ParameterError(f"{flag} {text} is read-only: refusing to replace it")
        for other, other_path in [*given[:i], *inputs]:
            if other_path is not None and same_file(text, other_path):
                raise ParameterError(f"{flag} is the same file as {other} ({text})")


# --------------------------------------------------------------------------------------------
# Stale temporary files
# --------------------------------------------------------------------------------------------


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _held_open(pid: int, path: Path) -> bool:
    """Whether process ``pid`` has ``path`` open (True when that cannot be told)."""
    fd_dir = Path(f"/proc/{pid}/fd")
    try:
        target = os.stat(path)
        for fd in fd_dir.iterdir():
            with contextlib.suppress(OSError):
                st = os.stat(fd)
                if (st.st_dev, st.st_ino) == (target.st_dev, target.st_ino):
                    return True
    except OSError:
        return True
    return False


def _locked(path: Path) -> bool:
    """Whether a live writer holds ``path``'s lock (``Stage`` holds an exclusive ``flock`` on
    its temporary file from creating it until it is renamed or removed). A lock belongs to the
    open file, not to a process id, so it is seen across PID namespaces (a writer in a
    container sharing the directory, whose pid means nothing here) and dies with its holder.
    False when the lock is free or cannot be taken on this file system (the pid rules then
    decide)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        os.close(fd)
    return False


def _is_stale(path: Path, pid: int | None, now: float) -> bool:
    try:
        mtime = os.lstat(path).st_mtime
    except OSError:
        return False
    if _locked(path):  # a live writer, whatever its pid says
        return False
    if pid is None:  # an earlier version's name: only its age tells
        return now - mtime > STALE_AGE_S
    if pid == os.getpid():
        return False
    if not _pid_alive(pid):
        return mtime < _RUN_START  # last written before this run began: not a live writer
    return now - mtime > STALE_AGE_S and not _held_open(pid, path)


def remove_stale_temps(target: Path) -> list[Path]:
    """Remove this module's temporary files beside ``target`` left by runs that died.

    A file whose lock a writer holds (``_locked``: every ``Stage`` locks its temporary file) is
    never stale. Otherwise a ``.NAME.PID-TOKEN.tmp`` (or ``.part``, or a file of a version
    that took no lock) is stale when its creator is dead and it was last written before this
    process started, or when it is older than :data:`STALE_AGE_S` and its
    creator's pid no longer holds it open (the pid was reused). An earlier version's
    ``.NAME.XXXXXXXX.tmp`` is stale, for this very target only, when older than
    :data:`STALE_AGE_S`. A directory is swept once per process (a chunk store writes thousands
    of files into one). Returns what was removed.
    """
    directory = target.parent
    key = os.path.realpath(directory)
    if key in _SWEPT:
        return []
    _SWEPT.add(key)
    legacy = re.compile(rf"^\.{re.escape(target.name)}\.{_LEGACY_TOKEN}\.(?:tmp|part)$")
    now = time.time()
    removed: list[Path] = []
    try:
        entries = list(os.scandir(directory))
    except OSError:
        return removed
    for entry in entries:
        name = entry.name
        if not name.startswith(".") or not name.endswith(TEMP_SUFFIXES):
            continue
        m = _TEMP_RE.match(name)
        if m is not None:
            pid: int | None = int(m["pid"])
        elif legacy.match(name):
            pid = None
        else:
            continue
        path = Path(entry.path)
        if entry.is_file(follow_symlinks=False) and _is_stale(path, pid, now):
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
                removed.append(path)
    return removed


# --------------------------------------------------------------------------------------------
# The stage: a verified temporary file renamed onto its target
# --------------------------------------------------------------------------------------------


class Stage:
    """A temporary file beside ``target`` that becomes ``target`` on :meth:`commit`.

    Creating the stage checks the target (an existing non-regular file, or any existing file
    without ``overwrite``, is refused with :class:`WriteError`), removes stale temporary files
    and creates the temporary file exclusively with the target's future mode; ``fd`` is open
    for writing (a writer that opens by path may close it). Use as a context manager, or call
    :meth:`commit` / :meth:`abort` yourself.
    """

    def __init__(self, path: str | os.PathLike, *, overwrite: bool = True) -> None:
        self.target = Path(path)
        self.overwrite = overwrite
        #: Bytes written through :meth:`open` (None: the size is not checked).
        self.written: int | None = None
        self.existing = self._check_target()
        remove_stale_temps(self.target)
        self.path = self.temp_name()
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
        try:
            self.fd: int | None = os.open(self.path, flags, 0o666)  # the umask applies
        except OSError as exc:
            raise write_error(self.target, exc) from None
        # A lock held until the rename or removal tells a sweeper of another run, even in
        # another PID namespace, that this file is being written (``remove_stale_temps``).
        # It is on a descriptor of its own: a writer may close ``fd``.
        self._lock_fd: int | None = None
        with contextlib.suppress(OSError):  # a file system without flock: the pid rules
            self._lock_fd = os.open(self.path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
            fcntl.flock(self._lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        try:
            if self.existing is not None:  # a replaced file keeps its mode (and owner, as root)
                os.fchmod(self.fd, stat.S_IMODE(self.existing.st_mode))
                if os.geteuid() == 0:
                    with contextlib.suppress(OSError):
                        os.fchown(self.fd, self.existing.st_uid, self.existing.st_gid)
        except OSError as exc:
            self.abort()
            raise write_error(self.target, exc) from None

    def _check_target(self) -> os.stat_result | None:
        """The target's status if it is an existing regular file; None if it is absent."""
        kind = special_kind(self.target)
        if kind is not None:
            raise WriteError(errno.EEXIST, f"it is {kind}, not a regular file", str(self.target))
        try:
            st = os.lstat(self.target)
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise write_error(self.target, exc) from None
        if not self.overwrite:
            raise WriteError(
                errno.EEXIST,
                "it exists: refusing to overwrite (pass --overwrite)",
                str(self.target),
            )
        return st

    def release_lock(self) -> None:
        """Drop the writer's lock (after the rename, or with the removed file)."""
        if self._lock_fd is not None:
            fd, self._lock_fd = self._lock_fd, None
            os.close(fd)

    def close_fd(self) -> None:
        if self.fd is not None:
            fd, self.fd = self.fd, None
            os.close(fd)

    def commit(self, written: int | None = None, verify: Callable[[Path], None] | None = None):
        """fsync, verify and rename the temporary file onto the target.

        ``written``: the bytes the writer wrote (the size on disk must match; default
        :attr:`written`). ``verify``:
        raises if the file is not what it should be (e.g. a recording does not read back).
        Any failure aborts the stage and raises :class:`WriteError`.
        """
        try:
            self._sync_and_verify(self.written if written is None else written, verify)
            unit = _UNIT.get()
            if unit is not None:  # renamed with the unit's other outputs (commit_together)
                unit.append(self)
                return
            self._rename()
        except BaseException as exc:
            self.abort()
            if isinstance(exc, WriteError) or not isinstance(exc, Exception):
                raise
            raise self.error(exc) from None
        _fsync_directory(self.target.parent)

    def _sync_and_verify(self, written: int | None, verify: Callable[[Path], None] | None):
        fd = self.fd
        if fd is None:
            fd = os.open(self.path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
        try:
            os.fsync(fd)
            size = os.fstat(fd).st_size
        finally:
            if self.fd is None:
                os.close(fd)
            else:
                self.close_fd()
        if written is not None and size != written:
            raise WriteError(
                errno.EIO, f"{size} of {written} bytes reached the disk", str(self.target)
            )
        if verify is not None:
            try:
                verify(self.path)
            except Exception as exc:
                raise self.error(exc, "it does not read back whole") from None

    def _rename(self) -> None:
        self._rename_onto_target()
        self.release_lock()

    def _rename_onto_target(self) -> None:
        target = self.target
        if self.overwrite:
            kind = special_kind(target)  # it may have changed since the stage began
            if kind is not None:
                raise WriteError(errno.EEXIST, f"it is {kind}, not a regular file", str(target))
            os.replace(self.path, target)
            return
        try:
            os.link(self.path, target)  # fails if the target exists: no race
        except FileExistsError:
            raise _created_meanwhile(target) from None
        except OSError as exc:
            if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EMLINK):
                raise
            # No hard links on this file system: claim the name exclusively, then replace it.
            try:
                os.close(os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
            except FileExistsError:
                raise _created_meanwhile(target) from None
            os.replace(self.path, target)
            return
        os.unlink(self.path)

    def temp_name(self, kind: str = "tmp") -> Path:
        """A fresh hidden name beside the target in this module's temporary pattern (so a
        stale one is removed by :func:`remove_stale_temps`)."""
        name = self.target.name[:_NAME_IN_TEMP]
        return self.target.with_name(f".{name}.{os.getpid()}-{secrets.token_hex(4)}.{kind}")

    def backup(self) -> Path | None:
        """A hard link (a copy where links are not supported) of the target's current file,
        None if there is none: what :func:`commit_together` restores if a later rename fails.
        (Without overwrite the rename refuses an existing target, so there is nothing to keep.)
        """
        if not self.overwrite:
            return None
        path = self.temp_name()
        try:
            os.link(self.target, path)
        except FileNotFoundError:
            return None  # removed meanwhile: nothing to restore
        except OSError as exc:
            if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EMLINK):
                raise
            shutil.copy2(self.target, path)
        return path

    @contextlib.contextmanager
    def open(self, mode: str = "wb", **open_kwargs: Any) -> Iterator[IO[Any]]:
        """The temporary file as a file object (once). On a clean exit it is flushed and
        :attr:`written` set to the bytes written (the writer's final position); on an error
        the stage is aborted, and an ``OSError`` of the write itself comes out as
        :class:`WriteError` naming the target."""
        fd, self.fd = self.fd, None
        if fd is None:
            raise ValueError("the stage's file is already closed")
        try:
            with os.fdopen(fd, mode, **open_kwargs) as fh:
                yield fh
                fh.flush()
                self.written = (fh.buffer if isinstance(fh, io.TextIOWrapper) else fh).tell()
        except BaseException as exc:
            failure = self.failed(exc)
            if failure is exc:
                raise
            raise failure from None

    def error(self, exc: BaseException, what: str | None = None) -> WriteError:
        """A :class:`WriteError` for the target; a full disk is named as such."""
        if isinstance(exc, WriteError):
            return exc
        if isinstance(exc, OSError) and exc.errno:
            return write_error(self.target, exc)
        if _low_space(self.target.parent):
            return WriteError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.target))
        return write_error(self.target, what or _reason(exc))

    def abort(self) -> None:
        """Remove the temporary file; the target is untouched."""
        with contextlib.suppress(OSError):
            self.close_fd()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)
        with contextlib.suppress(OSError):
            self.release_lock()

    def __enter__(self) -> Stage:
        return self

    def __exit__(self, exc_type: Any, exc: BaseException | None, tb: Any) -> None:
        if exc is None:
            self.commit()
            return
        failure = self.failed(exc)
        if failure is not exc:
            raise failure from None

    def failed(self, exc: BaseException) -> BaseException:
        """Abort after the writer raised ``exc``; what to raise instead: a
        :class:`WriteError` naming the target if the write itself failed (an ``OSError`` about
        no file or the temporary one), else ``exc`` (e.g. a bad input found while writing)."""
        self.abort()
        if isinstance(exc, OSError) and not isinstance(exc, WriteError):
            if exc.filename in (None, os.fspath(self.path)):
                return self.error(exc)
        return exc


def _fsync_directory(directory: Path) -> None:
    """Make the rename durable (best effort: not every system can fsync a directory)."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def commit_together() -> Iterator[None]:
    """Outputs that change together or not at all: every :class:`Stage` committed inside the
    block is verified there, and all are renamed when the block ends (module docstring).

    An error inside the block aborts every stage (no target changes). A rename that fails
    restores the targets renamed before it from their backups (a new target is removed) and
    raises one :class:`WriteError` naming the failing target and those left as they were.
    A block inside another joins the outer one.
    """
    if _UNIT.get() is not None:
        yield
        return
    staged: list[Stage] = []
    token = _UNIT.set(staged)
    try:
        yield
    except BaseException:
        for stage in staged:
            stage.abort()
        raise
    finally:
        _UNIT.reset(token)
    _rename_all(staged)


def _rename_all(stages: Sequence[Stage]) -> None:
    """Rename every verified stage onto its target, or restore those renamed (see above)."""
    done: list[tuple[Stage, Path | None]] = []
    for i, stage in enumerate(stages):
        backup = None
        try:
            backup = stage.backup()
            stage._rename()
        except BaseException as exc:
            if backup is not None:
                with contextlib.suppress(OSError):
                    os.unlink(backup)
            for later in stages[i:]:
                later.abort()
            problems = _restore(done)
            error = stage.error(exc) if isinstance(exc, Exception) else None
            if error is None:  # Ctrl-C between two renames: restored, then interrupted
                raise
            kept = [str(s.target) for s, _ in done if str(s.target) not in problems]
            reason = error.strerror or "rename failed"
            if kept:
                reason += f"; {', '.join(kept)} left as before"
            for target, why in problems.items():
                reason += f"; {target} could not be restored ({why})"
            raise WriteError(error.errno or errno.EIO, reason, str(stage.target)) from None
        done.append((stage, backup))
    for _stage, backup in done:
        if backup is not None:
            with contextlib.suppress(OSError):
                os.unlink(backup)
    for directory in {os.path.realpath(s.target.parent) for s in stages}:
        _fsync_directory(Path(directory))


def _restore(done: Sequence[tuple[Stage, Path | None]]) -> dict[str, str]:
    """Undo the renames of ``done`` (last first): a backup goes back onto its target, a target
    that did not exist is removed. Returns {target: reason} for those that could not be."""
    problems: dict[str, str] = {}
    for stage, backup in reversed(done):
        try:
            if backup is not None:
                os.replace(backup, stage.target)
            else:
                os.unlink(stage.target)
        except OSError as exc:
            problems[str(stage.target)] = exc.strerror or type(exc).__name__
    return problems


@contextlib.contextmanager
def atomic_write(
    path: str | os.PathLike,
    mode: str = "wb",
    *,
    overwrite: bool = True,
    verify: Callable[[Path], None] | None = None,
    **open_kwargs: Any,
) -> Iterator[IO[Any]]:
    """Open a staged temporary file beside ``path``; it becomes ``path`` when the block ends.

    The file is flushed, fsynced and checked (size on disk = bytes written, then ``verify``
    on the temporary path if given) before the rename. On any error (the block's or the
    write's) the temporary file is deleted and ``path`` is untouched; a failure of the write
    itself comes out as :class:`WriteError` naming ``path``. ``overwrite``: replace an
    existing regular file (else refuse, also if it appears while writing). ``open_kwargs``
    go to ``open`` (e.g. ``newline=""``, ``encoding="utf-8"`` for text).
    """
    stage = Stage(path, overwrite=overwrite)
    with stage.open(mode, **open_kwargs) as fh:
        yield fh
    stage.commit(verify=verify)
