"""Attacks from the same machine, each tried and each refused.

Loopback keeps other machines out, not other programs or other web pages in the user's
browser. Each test plays the attacker against the real service: the ``radarviz tune`` panel
and the ``radarviz live --panel`` one (foreign WebSocket Origin, DNS-rebinding Host, no
token), the sweep's local Dask scheduler (a client without the run's TLS certificate), and
``radarviz view`` / ``tune`` on a port that another program holds. Each also checks that the
legitimate request still works, so a service that refused everything would fail too.
"""

from __future__ import annotations

import http.client
import os
import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.parse
from collections.abc import Iterator
from pathlib import Path

import pytest
import viser
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

EXE = Path(sys.executable).with_name("radarviz")


def _lines(proc: subprocess.Popen) -> queue.Queue[str]:
    out: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            out.put(line.rstrip("\n"))

    threading.Thread(target=pump, daemon=True).start()
    return out


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.fixture(scope="module", params=["tune", "live"])
def panel(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[urllib.parse.SplitResult]:
    """A running ``radarviz tune``, or ``radarviz live --panel`` (a feed with its viewer),
    and the panel address it printed."""
    command = request.param
    if command == "tune":
        argv, stop = [str(EXE), "tune", "--no-browser"], signal.SIGTERM
    else:
        tmp = tmp_path_factory.mktemp("live")
        radars = tmp / "r.toml"
        sim = [str(EXE), "simulate", "--preset", "crossing", "--out", str(tmp / "m.ast")]
        subprocess.run([*sim, "--radars-out", str(radars)], check=True, capture_output=True)
        argv = [str(EXE), "live", "--udp", f"127.0.0.1:{_free_udp_port()}", "--radars"]
        argv, stop = [*argv, str(radars), "--panel"], signal.SIGINT  # Ctrl-C ends a session
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        lines = _lines(proc)
        end = time.monotonic() + 60
        url = None
        while url is None and time.monotonic() < end:
            try:
                m = re.match(r"^panel (\S+)", lines.get(timeout=1))
            except queue.Empty:
                assert proc.poll() is None, f"radarviz {command} exited"
                continue
            url = m.group(1) if m else None
        assert url, f"radarviz {command} printed no panel address"
        yield urllib.parse.urlsplit(url)
    finally:
        proc.send_signal(stop)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _get(url: urllib.parse.SplitResult, path: str, host: str | None = None) -> tuple[int, bytes]:
    conn = http.client.HTTPConnection(url.hostname, url.port, timeout=10)
    try:
        headers = {"Host": host} if host else {}
        conn.request("GET", path, headers=headers)
        response = conn.getresponse()
        return response.status, response.read()
    finally:
        conn.close()


def _ws(url: urllib.parse.SplitResult, path: str, origin: str) -> None:
    """Open the panel's WebSocket as the panel page does (its subprotocol, an Origin)."""
    with connect(
        f"ws://{url.netloc}{path}",
        origin=origin,
        subprotocols=[f"viser-v{viser.__version__}"],
        open_timeout=10,
    ):
        pass


def test_panel_needs_its_token(panel: urllib.parse.SplitResult) -> None:
    token = panel.path.strip("/")
    assert len(token) >= 40, f"the printed address carries no token: {panel.geturl()}"
    status, page = _get(panel, panel.path)  # the page: the controls' and the viewer's frames
    assert status == 200 and b"<title>radarviz " in page and b"./?controls" in page
    status, page = _get(panel, panel.path + "?controls")
    assert status == 200 and b"<title>Viser</title>" in page
    for path in (
        "/",
        "/?controls",
        "/index.html",
        "/?token=" + token,
        "/" + token[:-1] + "/",
        "/x" + token,
    ):
        assert _get(panel, path)[0] == 403, path


def test_panel_refuses_a_rebound_host_name(panel: urllib.parse.SplitResult) -> None:
    """DNS rebinding: the browser sends the attacker's name as Host, with the right path."""
    assert _get(panel, panel.path, host=f"evil.example:{panel.port}")[0] == 403
    assert _get(panel, panel.path, host=f"localhost:{panel.port}")[0] == 200


def test_panel_websocket_refuses_a_foreign_origin(panel: urllib.parse.SplitResult) -> None:
    """Cross-site WebSocket: a page elsewhere opens the panel's socket from the user's browser."""
    ws_path = panel.path.rstrip("/")  # what the panel page connects to
    for origin in ("https://evil.example", f"http://evil.example:{panel.port}", "null"):
        with pytest.raises(InvalidStatus) as info:
            _ws(panel, ws_path, origin)
        assert info.value.response.status_code == 403, origin
    with pytest.raises(InvalidStatus) as info:  # the panel's own origin, no token
        _ws(panel, "/", f"http://{panel.netloc}")
    assert info.value.response.status_code == 403
    _ws(panel, ws_path, f"http://{panel.netloc}")  # the panel page itself gets through


def test_local_dask_scheduler_refuses_clients_without_the_certificate() -> None:
    """A second process on the machine tries to run code on the sweep's workers."""
    from distributed import Client
    from distributed.security import Security

    from radarviz.viz_app.sweep.run import dask_client

    with dask_client("local", 1) as client:
        address = client.scheduler.address
        assert address.startswith("tls://127.0.0.1:"), address
        workers = client.scheduler_info(n_workers=-1)["workers"]
        assert workers and all(w.startswith("tls://") for w in workers)
        assert client.submit(sum, [40, 2]).result(timeout=30) == 42
        # A plain client, and a TLS client with a certificate of its own making.
        with pytest.raises(OSError):
            Client(address.replace("tls://", "tcp://"), timeout="2s")
        with pytest.raises(OSError):
            Client(address, security=Security.temporary(), timeout="2s")
        assert client.submit(sum, [1, 2]).result(timeout=30) == 3  # still serving its own


def _taken_port() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.bind(("127.0.0.1", 0))
    s.listen()
    return s


def test_view_on_a_taken_web_port_is_one_line(tmp_path: Path) -> None:
    rrd = tmp_path / "x.rrd"
    # A real recording: view reads the file whole before it touches a port.
    made = subprocess.run(
        [str(EXE), "record", "--preset", "velocity", "--out", str(rrd)], capture_output=True
    )
    assert made.returncode == 0, made.stderr
    with _taken_port() as other:
        port = other.getsockname()[1]
        done = subprocess.run(
            [str(EXE), "view", str(rrd), "--web-port", str(port)],
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert done.returncode == 1
    assert done.stdout == "", "an address was printed for a port another program holds"
    assert done.stderr.count("\n") == 1 and f"--web-port {port}" in done.stderr, done.stderr


def test_tune_on_a_taken_viewer_port_fails_at_once() -> None:
    with _taken_port() as other:
        port = other.getsockname()[1]
        start = time.monotonic()
        done = subprocess.run(
            [str(EXE), "tune", "--no-browser", "--viewer-port", str(port)],
            capture_output=True,
            text=True,
            timeout=60,
            env={**os.environ, "RERUN_ANALYTICS": "0"},
        )
    assert done.returncode == 1 and time.monotonic() - start < 15
    assert done.stdout == ""
    assert done.stderr.count("\n") == 1 and f"--viewer-port {port}" in done.stderr, done.stderr


def _listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(1.0)
        return s.connect_ex(("127.0.0.1", port)) == 0


def test_view_killed_by_sigkill_leaves_no_viewer_listening(tmp_path: Path) -> None:
    """SIGKILL gives ``radarviz view`` no chance to stop its viewer: the viewer itself is
    told to stop when its parent dies, so neither of its ports stays served."""
    from radarviz.viz_app.rerun.viewer import free_port, wait_viewer

    rrd = tmp_path / "x.rrd"
    made = subprocess.run(
        [str(EXE), "record", "--preset", "velocity", "--out", str(rrd)], capture_output=True
    )
    assert made.returncode == 0, made.stderr
    grpc, web = free_port(), free_port()
    proc = subprocess.Popen(
        [str(EXE), "view", str(rrd), "--port", str(grpc), "--web-port", str(web)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        wait_viewer(proc, "--web-port", "127.0.0.1", web, timeout=120.0)
        assert _listening(grpc) and _listening(web)
        proc.kill()
        proc.wait(timeout=10)
        end = time.monotonic() + 15.0
        while time.monotonic() < end and (_listening(grpc) or _listening(web)):
            time.sleep(0.2)
        assert not _listening(grpc) and not _listening(web), "the viewer outlived its command"
    finally:
        if proc.poll() is None:
            proc.kill()
