"""The Rerun viewer as a separate process: free ports, its address, starting it.

Nothing here imports the Rerun SDK: the viewer is the ``rerun`` executable installed beside
Python, started in its own process group so it can be stopped with everything it spawned, and
(on Linux) told to stop when the command that started it dies, even by SIGKILL.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import http.client
import ipaddress
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.parse
from collections.abc import Callable
from pathlib import Path

from radarviz.core.params import ParameterError

LOOPBACK = "127.0.0.1"
WILDCARDS = ("0.0.0.0", "::", "")

#: What the Rerun web viewer's page says of itself (its ``<title>``): how a port is known to be
#: served by the viewer this command started and not by some other program.
VIEWER_MARK = b"<title>Rerun Viewer</title>"


class ServiceError(RuntimeError):
    """A server of ours cannot start or stopped (a port taken, a child gone): one line."""


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (127.0.0.0/8, ::1): not reachable from
    other machines, so binding them needs no warning."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def bind_address(flag: str, host: str) -> str:
    """The IPv4 address to bind for ``host``: ``localhost`` and other names resolved here.

    ``rerun --bind`` takes an address, not a name (``--bind localhost`` makes it exit); one
    resolution for every server keeps them on the same address. An unknown name is a
    ParameterError naming ``flag``.
    """
    if host in WILDCARDS:
        return "0.0.0.0"
    if host.lower() == "localhost":
        return LOOPBACK
    try:
        ipaddress.ip_address(host)
    except ValueError:
        try:
            return socket.gethostbyname(host)
        except OSError as exc:
            raise ParameterError(f"{flag} {host!r} is not an address of this machine") from exc
    return host


def connect_address(host: str) -> str:
    """Where a client on this machine connects for a server bound to ``host``."""
    return LOOPBACK if host in WILDCARDS else host


def check_port_free(flag: str, host: str, port: int) -> None:
    """Raise ServiceError naming ``flag`` and ``port`` if ``port`` cannot be bound on ``host``.

    A bind test, not a connect: it also sees a program bound to the port that is not
    answering yet. ``SO_REUSEADDR`` as the servers set it, so a port that only lingers in
    TIME_WAIT counts as free. Port 0 (any free one) is always free.
    """
    if port == 0:
        return
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as exc:
            raise ServiceError(
                f"{flag} {port}: the port is in use on {host} ({exc.strerror or exc}); "
                "choose another or 0 for a free one"
            ) from exc


def wait_viewer(
    proc: subprocess.Popen, flag: str, host: str, web_port: int, timeout: float = 30.0
) -> None:
    """Wait until the web viewer ``proc`` serves ``web_port`` as a Rerun viewer.

    Raises ServiceError (one line naming ``flag`` and the port) when the child exits first
    (most often: the port was taken between the check and its bind) or when the port answers
    with a page that is not the Rerun viewer (another program got it), or after ``timeout``.
    """
    end = time.monotonic() + timeout
    connect = connect_address(host)
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise ServiceError(
                f"{flag} {web_port}: the rerun viewer exited (code {proc.returncode}) before "
                "serving it; is the port taken?"
            )
        page = b""
        with contextlib.suppress(OSError, http.client.HTTPException):
            conn = http.client.HTTPConnection(connect, web_port, timeout=2)
            try:
                conn.request("GET", "/")
                page = conn.getresponse().read(65536)
            finally:
                conn.close()
        if page:
            if VIEWER_MARK in page:
                return
            raise ServiceError(
                f"{flag} {web_port}: another program answers on that port, not the rerun viewer"
            )
        time.sleep(0.05)
    raise ServiceError(f"{flag} {web_port}: the rerun viewer did not answer after {timeout:g} s")


def free_port(host: str = LOOPBACK) -> int:
    """A currently free TCP port on ``host`` (bind to port 0, read it, close)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def viewer_url(host: str, web_port: int, grpc_port: int) -> str:
    """The web viewer's address with the gRPC source it should connect to."""
    source = f"rerun+http://{host}:{grpc_port}/proxy"
    return f"http://{host}:{web_port}/?url={urllib.parse.quote(source, safe='')}"


def rerun_executable() -> str:
    """The viewer's binary: the one the ``rerun-sdk`` wheel bundles when it is there (its
    ``rerun`` script runs that binary as a child of its own, which a signal to the script
    would not reach), else the ``rerun`` beside Python or on the path."""
    with contextlib.suppress(ImportError):
        import rerun_cli

        bundled = Path(rerun_cli.__file__).with_name("rerun")
        if bundled.is_file() and os.access(bundled, os.X_OK):
            return str(bundled)
    exe = Path(sys.executable).with_name("rerun")
    found = str(exe) if exe.exists() else shutil.which("rerun")
    if not found:
        raise ParameterError("the rerun viewer is not installed (pip install rerun-sdk)")
    return found


#: PR_SET_PDEATHSIG of prctl(2): the signal a process gets when its parent dies.
_PR_SET_PDEATHSIG = 1


@functools.cache
def _libc_prctl() -> Callable[..., int] | None:
    """libc's ``prctl`` on Linux, else None (looked up once, by the first server started)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


def popen_server(cmd: list[str], **kwargs) -> subprocess.Popen:
    """``subprocess.Popen`` of a server of ours: its own session (stopped as a group) that
    ends when the command that started it dies.

    The child gets SIGTERM when the thread that started it ends (Linux ``PR_SET_PDEATHSIG``;
    the servers are started from the command's main thread, so: when the command dies), so a
    command killed by SIGKILL leaves no viewer listening on its port. Elsewhere a plain
    ``Popen``."""
    prctl = _libc_prctl()  # looked up in the parent: the child only makes the call

    def parent_death_signal() -> None:
        if prctl is not None:
            prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)

    return subprocess.Popen(cmd, start_new_session=True, preexec_fn=parent_death_signal, **kwargs)


def serve_recording(path: str, host: str, grpc_port: int, web_port: int) -> subprocess.Popen:
    """Start ``rerun --serve-web`` for ``path`` in its own process group."""
    cmd = [
        rerun_executable(),
        "--serve-web",
        path,
        "--bind",
        host,
        "--port",
        str(grpc_port),
        "--web-viewer-port",
        str(web_port),
    ]
    return popen_server(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
