"""``radarviz demo``, ``record`` and ``view``: write and serve Rerun recordings."""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from radarviz.core.params import ParameterError, check_choice, check_int
from radarviz.viz_app.cli.commands import Registrar
from radarviz.viz_app.io.atomic import check_outputs
from radarviz.viz_app.rerun.preset_names import PRESETS
from radarviz.viz_app.rerun.viewer import (
    LOOPBACK,
    ServiceError,
    bind_address,
    check_port_free,
    connect_address,
    free_port,
    is_loopback,
    rerun_executable,
    serve_recording,
    viewer_url,
    wait_viewer,
)

DEFAULT_DEMO_PATH = "recordings/demo.rrd"


def add_commands(sub: Registrar) -> None:
    """Register the three subcommands on the ``radarviz`` parser."""
    demo = sub.add_parser("demo")
    demo.add_argument(
        "--out",
        default=DEFAULT_DEMO_PATH,
        help=f"where to write the recording (default {DEFAULT_DEMO_PATH})",
    )
    demo.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing file that is not a recording (one is always replaced)",
    )
    demo.add_argument("--seed", type=int, default=1, help="random seed (default 1)")

    rec = sub.add_parser("record")
    rec.add_argument("--preset", required=True, help=f"one of {', '.join(PRESETS)}")
    rec.add_argument("--out", required=True, help="path of the .rrd to write")
    rec.add_argument("--overwrite", action="store_true", help="replace an existing file")
    rec.add_argument("--seed", type=int, default=1, help="random seed (default 1)")

    view = sub.add_parser("view")
    view.add_argument(
        "path",
        nargs="?",
        default=DEFAULT_DEMO_PATH,
        help=f"recording to open (default {DEFAULT_DEMO_PATH})",
    )
    view.add_argument(
        "--host",
        default=LOOPBACK,
        help="address to bind (default 127.0.0.1; anything else is exposed)",
    )
    view.add_argument("--port", type=int, default=0, help="gRPC port (default: a free one)")
    view.add_argument(
        "--web-port", type=int, default=0, help="web viewer port (default: a free one)"
    )
    view.add_argument(
        "--native", action="store_true", help="open the native viewer instead (needs a display)"
    )


def _write(preset: str, out: str, overwrite: bool, seed: int) -> float:
    import radarviz

    t0 = time.perf_counter()
    radarviz.record(preset, out, overwrite=overwrite, seed=seed)
    return time.perf_counter() - t0


def cmd_demo(args: argparse.Namespace) -> int:
    from radarviz.viz_app.rerun.recording import is_recording

    check_int("--seed", args.seed, low=0)
    if args.out.strip():
        parent = Path(args.out).parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:  # a component that is a file, a read-only parent
            blocker = next((str(q) for q in [parent, *parent.parents] if q.is_file()), None)
            why = f"{blocker} is a file" if blocker else (exc.strerror or str(exc))
            raise ParameterError(
                f"--out: cannot make the directory {str(parent)!r} ({why})", "--out"
            ) from None
    check_outputs([("--out", args.out)])
    if Path(args.out).exists() and not args.overwrite and not is_recording(args.out):
        raise ParameterError(
            f"--out {args.out} exists and is not a recording: refusing to replace it "
            "(pass --overwrite)"
        )
    seconds = _write("demo", args.out, overwrite=True, seed=args.seed)
    size = os.path.getsize(args.out) / 1e6
    print(f"wrote {args.out} ({size:.1f} MB) in {seconds:.2f} s")
    print(f"open it with:  radarviz view {args.out}    (web viewer on 127.0.0.1)")
    print(f"          or:  rerun {args.out}            (native viewer, needs a display)")
    return 0


def cmd_record(args: argparse.Namespace) -> int:
    check_choice("--preset", args.preset, PRESETS)
    check_int("--seed", args.seed, low=0)
    check_outputs([("--out", args.out)], overwrite=args.overwrite)
    seconds = _write(args.preset, args.out, overwrite=args.overwrite, seed=args.seed)
    print(f"wrote {args.out} ({os.path.getsize(args.out) / 1e6:.1f} MB) in {seconds:.2f} s")
    return 0


def check_recording(path: str) -> None:
    """``path`` must be a whole recording (``verify_recording``: every chunk decodes and the
    footer a cleanly ended stream writes is there), else a ParameterError naming it, before any
    viewer is started. A file cut short on a message boundary reads chunk by chunk like a whole
    one, but the viewer then waits for the rest of it, one core busy, for ever."""
    from radarviz.viz_app.rerun.recording import verify_recording

    try:
        verify_recording(path)
    except Exception as exc:  # the reader raises plain exceptions (and warnings) for bad bytes
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if "no footer" in reason:
            reason = "it has no footer (cut short, or still being written)"
        raise ParameterError(f"{path} is not a whole Rerun recording: {reason}") from None


def cmd_view(args: argparse.Namespace) -> int:
    if not Path(args.path).is_file():
        raise ParameterError(f"path must be an existing .rrd file (got {args.path!r})")
    check_recording(args.path)
    if args.native:
        if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
            raise ParameterError(
                "--native needs a display (DISPLAY is not set); "
                "drop --native to serve the web viewer"
            )
        return subprocess.call([rerun_executable(), args.path])
    if not is_loopback(args.host):
        print(
            f"radarviz: warning: binding {args.host}: the viewer is reachable from other machines",
            file=sys.stderr,
        )
    for name, port in (("--port", args.port), ("--web-port", args.web_port)):
        check_int(name, port, low=0, high=65535)
    host = bind_address("--host", args.host)
    proc = None
    try:
        # A port taken by another program must not be printed as the viewer's address.
        check_port_free("--port", host, args.port)
        check_port_free("--web-port", host, args.web_port)
        grpc_port = args.port or free_port(host)
        web_port = args.web_port or free_port(host)
        proc = serve_recording(args.path, host, grpc_port, web_port)
        wait_viewer(proc, "--web-port", host, web_port)
    except ServiceError as exc:
        print(f"radarviz: error: {exc}", file=sys.stderr)
        _stop_viewer(proc)
        return 1

    def _stop(signum: int, frame: object) -> None:
        raise SystemExit(0)  # unwinds into the finally below, which stops the viewer

    signal.signal(signal.SIGTERM, _stop)
    print(f"serving {args.path}")
    print(f"open {viewer_url(connect_address(host), web_port, grpc_port)}", flush=True)
    print("stop with Ctrl-C", flush=True)
    try:
        return proc.wait()
    except (KeyboardInterrupt, SystemExit):
        return 0
    finally:
        _stop_viewer(proc)


def _stop_viewer(proc: subprocess.Popen | None) -> None:
    if proc is not None and proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)


COMMANDS = {"demo": cmd_demo, "record": cmd_record, "view": cmd_view}
