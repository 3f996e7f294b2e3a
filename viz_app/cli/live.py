"""``radarviz replay`` and ``radarviz live``: a radar feed sent again, and tracked as it comes.

``replay`` (``viz_app.live.replay``) sends a recording's ASTERIX datagrams to a UDP address at
the recording's pace. ``live`` (``viz_app.live.session``) receives such a feed, or follows a
growing ``.ast`` file, associates its plots as they come and logs them to a live Rerun viewer.
Both stay on this machine unless told otherwise.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from radarviz.viz_app.cli.args import integer, number
from radarviz.viz_app.cli.commands import Registrar
from radarviz.viz_app.cli.params import add_parameter, map_flag

#: Default longest time order horizon of ``live`` (s): a merged feed is out of order by a
#: packet or two. The horizon starts short and grows to twice the largest lateness seen, up
#: to this (``viz_app.live.session.Horizon``); every plot waits that long (of the feed's
#: time) before it is tracked.
REORDER_S = 1.0
#: Default time budget of ``live`` (ms): held batches are associated at least this often.
BUDGET_MS = 100.0


def add_commands(sub: Registrar) -> None:
    """Register ``replay`` and ``live`` on the ``radarviz`` parser."""
    _add_live(sub)
    rp = sub.add_parser("replay")
    rp.add_argument("capture", metavar="CAPTURE", help="pcap, pcapng or .ast file of data blocks")
    rp.add_argument(
        "--to",
        default="127.0.0.1:8600",
        metavar="HOST:PORT",
        help="UDP address (default 127.0.0.1:8600; a multicast group is allowed)",
    )
    rp.add_argument(
        "--speed",
        type=number,
        default=1.0,
        metavar="N",
        help="N times the recording's pace (default 1)",
    )


def cmd_replay(args: argparse.Namespace) -> int:
    from radarviz.core.params import check_real
    from radarviz.viz_app.live.replay import MAX_SPEED, parse_address, replay

    check_real("--speed", args.speed, low=0.0, high=MAX_SPEED)
    to = parse_address("--to", args.to)
    if not to.loopback:
        print(f"radarviz: replay: sending to {to}: the feed leaves this machine", file=sys.stderr)

    def refused() -> None:
        print(
            f"radarviz: replay: {to} refuses datagrams (nothing listens there); sending on",
            file=sys.stderr,
        )

    try:
        counts = replay(args.capture, to, args.speed, on_refused=refused)
    except OSError as exc:
        if exc.filename:  # the recording itself: bad input
            raise
        print(f"radarviz: error: replay to {to}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    if counts.refused:
        print(
            f"radarviz: error: replay to {to}: {counts.refused} of {counts.datagrams} "
            "datagrams refused (nothing listened there for part of the replay or all of it)",
            file=sys.stderr,
        )
        return 1
    print(
        f"replayed {counts.datagrams} datagrams ({counts.octets} octets, {counts.span_s:.3f} s "
        f"of the recording) to {to}",
        file=sys.stderr,
    )
    return 0


def _add_live(sub: argparse._SubParsersAction) -> None:
    from radarviz.core.experiments.prosov import ALL_METHODS
    from radarviz.core.params import parameter
    from radarviz.viz_app.cli.track import LIVE_ASSOCIATION_FLAGS

    lv = sub.add_parser("live")
    src = lv.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--udp",
        metavar="HOST:PORT",
        help="UDP address to listen on (a multicast group is joined); beyond loopback needs --host",
    )
    src.add_argument("--follow", metavar="FILE", help="a growing .ast file, read as it grows")
    lv.add_argument("--radars", required=True, metavar="RADARS.toml", help="radar sites, σ")
    lv.add_argument(
        "--method",
        nargs="+",
        default=None,
        metavar="METHOD",
        help=f"methods whose tracks are logged (default all: {' '.join(ALL_METHODS)})",
    )
    map_flag(lv, "method", "--method")
    for name, flag in LIVE_ASSOCIATION_FLAGS:
        shown = parameter(name).default
        add_parameter(lv, name, flag, default=None, shown_default=shown)
    lv.add_argument(
        "--reorder-s",
        type=number,
        default=REORDER_S,
        help="how late a plot may come and be put back in time order, s: the horizon starts "
        "at 0.05 s and grows to twice the largest lateness seen, up to this (default "
        f"{REORDER_S:g})",
    )
    lv.add_argument(
        "--budget-ms",
        type=number,
        default=BUDGET_MS,
        help="associate held plots once the tracker has caught up with the feed, and at the "
        f"latest this long after the first was held, ms (default {BUDGET_MS:g})",
    )
    lv.add_argument("--duration-s", type=number, default=None, help="stop after this long")
    lv.add_argument("--max-plots", type=integer, default=None, help="stop after this many plots")
    lv.add_argument("--rrd", default=None, metavar="OUT.rrd", help="also save the session")
    lv.add_argument(
        "--summary", default=None, metavar="SUMMARY.json", help="the final account as JSON"
    )
    lv.add_argument("--no-viewer", action="store_true", help="no live viewer")
    lv.add_argument(
        "--host",
        default="127.0.0.1",
        help="address the viewer binds and a non-loopback --udp needs (default 127.0.0.1; "
        "anything else is exposed)",
    )
    lv.add_argument(
        "--viewer-port", type=integer, default=0, help="web viewer port (default: a free one)"
    )
    lv.add_argument(
        "--panel",
        action="store_true",
        help="also serve the panel that changes the tracker while it runs (motion model, σa, "
        "gate, confirmation, deletion, methods shown; on --host, guarded as tune's)",
    )
    lv.add_argument(
        "--panel-port", type=integer, default=0, help="panel port (default: a free one)"
    )


def cmd_live(args: argparse.Namespace) -> int:
    from radarviz.viz_app.live.run import run_live

    return run_live(args)


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "replay": cmd_replay,
    "live": cmd_live,
}
