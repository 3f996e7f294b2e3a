"""``radarviz tune``'s servers: the Viser panel, a ``rerun --serve-web`` child, the worker.

All three bind to 127.0.0.1 unless ``--host`` says otherwise. The panel answers only the
address it prints, with its secret token, and only to its own Host names and Origin
(``tune.guard``). Ports asked for are checked free before anything starts, so a taken one
is one line naming it, not an address served by some other program. Every change of a control only
records the newest parameters (``worker.Coalescer``); the worker runs the newest, logs it as a
new recording to the gRPC server (``session.TuneSession``), and the panel shows the result.
The printed panel address opens one page with the controls and the viewer side by side
(``tune.page``); the viewer's own address is printed too.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import statistics
import subprocess
import sys
import time
from dataclasses import replace

from radarviz.core.params import check_int
from radarviz.viz_app.rerun.viewer import (
    ServiceError,
    bind_address,
    check_port_free,
    connect_address,
    free_port,
    is_loopback,
    popen_server,
    rerun_executable,
    viewer_url,
    wait_viewer,
)
from radarviz.viz_app.tune.guard import PanelGuard, guarded_viser_server
from radarviz.viz_app.tune.page import embedded_viewer_url, panel_page, serve_page
from radarviz.viz_app.tune.panel import TunePanel
from radarviz.viz_app.tune.params import TuneParams
from radarviz.viz_app.tune.session import TuneSession, prepare_blueprints
from radarviz.viz_app.tune.worker import Coalescer

LOOPBACK = "127.0.0.1"


def grpc_uri(host: str, port: int) -> str:
    connect = LOOPBACK if host in ("0.0.0.0", "::", "") else host
    return f"rerun+http://{connect}:{port}/proxy"


def wait_port(
    host: str, port: int, timeout: float = 30.0, proc: subprocess.Popen | None = None
) -> None:
    """Wait until ``port`` accepts connections; stop waiting at once if ``proc`` exits."""
    connect = connect_address(host)
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc is not None and proc.poll() is not None:
            raise ServiceError(
                f"the rerun server exited (code {proc.returncode}) before listening on "
                f"{connect}:{port}"
            )
        with contextlib.suppress(OSError), socket.create_connection((connect, port), timeout=1):
            return
        time.sleep(0.05)
    raise TimeoutError(f"nothing listens on {connect}:{port} after {timeout:g} s")


#: The gRPC server's buffer (``--server-memory-limit``). The server keeps what it relays for
#: viewers that connect later and drops the oldest messages, hence the oldest runs, beyond
#: this; a run that is dropped is only gone for such late viewers (a connected viewer has it
#: already, and switches to each new run as it arrives). Its resident memory is several
#: times the limit (the limit counts the buffered messages, not the server's own copies and
#: indexes): with 512 MiB it grew by ≈ 1.1 MB per Prosov run (≈ one run's recording, 1.0 MB
#: at 60 scans) to 373 MB after 300 runs (128 MiB: 404 MB after 600); with 4 MiB, which
#: still holds the newest three Prosov runs, it stayed near 90 MB (94 MB after 600 runs).
SERVER_MEMORY_LIMIT = "4MiB"


def start_rerun(host: str, grpc_port: int, web_port: int | None) -> subprocess.Popen:
    """``rerun --serve-web`` (or ``--serve-grpc`` when ``web_port`` is None) in its own
    process group, bound to ``host``."""
    cmd = [rerun_executable()]
    cmd += (
        ["--serve-grpc"]
        if web_port is None
        else ["--serve-web", "--web-viewer-port", str(web_port)]
    )
    cmd += ["--bind", host, "--port", str(grpc_port)]
    cmd += ["--server-memory-limit", SERVER_MEMORY_LIMIT]
    env = {**os.environ, "RERUN_ANALYTICS": "0"}
    return popen_server(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)


def stop_process_group(proc: subprocess.Popen | None) -> None:
    if proc is None or proc.poll() is not None:
        return
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=5)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=5)


def measure_tune_latency(
    scene: str = "prosov", changes: int = 10, runs: int = 200, steps: int = 60
) -> float:
    """Median ms from a parameter change to the recording flushed to a local gRPC server.

    Starts ``rerun --serve-grpc`` on 127.0.0.1, then submits ``changes`` changes of the
    scene's own parameter (σβ for Prosov and velocity, C0 for Gorshkov) one after another
    through the same worker path as the panel (one warm-up run first).
    """
    port = free_port(LOOPBACK)
    proc = start_rerun(LOOPBACK, port, None)
    times: list[float] = []
    worker = None
    try:
        wait_port(LOOPBACK, port)
        session = TuneSession(grpc_uri(LOOPBACK, port))
        worker = Coalescer(
            session.run,
            lambda raw, rep, ms: times.append(ms),
            lambda raw, exc: times.append(float("nan")),
        )
        base = TuneParams(scene=scene, runs=runs, steps=steps)
        worker.submit(base)
        worker.wait_idle(120)
        times.clear()
        for i in range(changes):
            if scene == "gorshkov":
                changed = replace(base, c0=0.5 + 0.5 * (i % 10))
            else:
                changed = replace(base, sigma_beta_deg=1.0 + 0.1 * (i % 10))
            worker.submit(changed)
            worker.wait_idle(120)
    finally:
        if worker is not None:
            worker.stop()
        stop_process_group(proc)
    return float(statistics.median(times)) if times else float("nan")


def cmd_tune(
    host: str = LOOPBACK, port: int = 0, viewer_port: int = 0, no_browser: bool = False
) -> int:
    """Run the panel, the gRPC server and the web viewer until SIGTERM / Ctrl-C."""
    from radarviz.viz_app.runtime import tune_allocator

    check_int("--port", port, low=0, high=65535)
    check_int("--viewer-port", viewer_port, low=0, high=65535)
    if not is_loopback(host):
        print(
            f"radarviz: warning: binding {host}: the tuning panel and viewer are reachable "
            "from other machines (the panel still needs its printed address and token)",
            file=sys.stderr,
            flush=True,
        )
    bind = bind_address("--host", host)
    tune_allocator()

    def _stop(signum: int, frame: object) -> None:
        raise SystemExit(0)  # unwinds into the finally below

    signal.signal(signal.SIGTERM, _stop)
    connect = connect_address(bind)
    proc = None
    server = None
    worker = None
    try:
        # Viser moves to the next port when its own is taken, and rerun exits: neither must
        # end with an address served by another program, so a port asked for is checked here.
        check_port_free("--port", bind, port)
        check_port_free("--viewer-port", bind, viewer_port)
        grpc_port = free_port(connect)
        web_port = viewer_port or free_port(connect)
        proc = start_rerun(bind, grpc_port, web_port)
        view_url = viewer_url(connect, web_port, grpc_port)
        page = panel_page(embedded_viewer_url(connect, web_port, grpc_port))
        guard = PanelGuard(host=host, bind=bind)
        panels: list[TunePanel] = []  # the page's reports go to the panel, once it is built

        def finished(value: float) -> None:
            for p in panels:
                name = p.finished(value)
                if name is not None:
                    print(f"finished {name}={value:g}", flush=True)

        server = guarded_viser_server(
            guard, port, wrap=lambda inner: serve_page(inner, page, finished), verbose=False
        )
        session = TuneSession(grpc_uri(bind, grpc_port), echo=True)
        worker = Coalescer(
            session.commit,
            session.done,
            session.error,
            prepare=session.prepare,
            discard=session.discard,
        )
        panel = TunePanel(server, session, worker)
        panels.append(panel)
        prepare_blueprints()  # no run (a first switch of scene included) builds one
        wait_port(bind, grpc_port, proc=proc)
        wait_viewer(proc, "--viewer-port", bind, web_port)
        panel_url = guard.url(connect, server.get_port())
        print(f"panel {panel_url}", flush=True)
        print(f"viewer {view_url}", flush=True)
        print("stop with Ctrl-C", flush=True)
        worker.submit(panel.raw())
        if not no_browser:
            import webbrowser

            webbrowser.open(panel_url)  # the page holds the viewer too
        while True:
            time.sleep(0.5)
            if proc.poll() is not None:
                print("radarviz: error: the rerun viewer stopped", file=sys.stderr, flush=True)
                return 1
    except ServiceError as exc:
        print(f"radarviz: error: {exc}", file=sys.stderr, flush=True)
        return 1
    except (KeyboardInterrupt, SystemExit):
        return 0
    finally:
        if worker is not None:
            worker.stop()
        if server is not None:
            with contextlib.suppress(Exception):
                server.stop()
        stop_process_group(proc)
