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

from radarviz.viz_app.cli.args import number


def add_commands(sub: argparse._SubParsersAction) -> None:
    """Register ``replay`` on the ``radarviz`` parser."""
    rp = sub.add_parser(
        "replay",
        help="send a capture's or .ast file's ASTERIX datagrams to a UDP address at its pace",
    )
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
    try:
        counts = replay(args.capture, to, args.speed)
    except OSError as exc:
        if exc.filename:  # the recording itself: bad input
            raise
        print(f"radarviz: error: replay to {to}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    print(
        f"replayed {counts.datagrams} datagrams ({counts.octets} octets, {counts.span_s:.3f} s "
        f"of the recording) to {to}",
        file=sys.stderr,
    )
    return 0


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {"replay": cmd_replay}
