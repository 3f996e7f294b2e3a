"""The Rerun viewer as a separate process: free ports, its address, starting it.

Nothing here imports the Rerun SDK: the viewer is the ``rerun`` executable installed beside
Python, started in its own process group so it can be stopped with everything it spawned.
"""

from __future__ import annotations

import shutil
import socket
import subprocess
import sys
import urllib.parse
from pathlib import Path

from radarviz.core.params import ParameterError

LOOPBACK = "127.0.0.1"


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
    exe = Path(sys.executable).with_name("rerun")
    found = str(exe) if exe.exists() else shutil.which("rerun")
    if not found:
        raise ParameterError("the rerun viewer is not installed (pip install rerun-sdk)")
    return found


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
    return subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True
    )
