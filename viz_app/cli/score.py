"""``radarviz score TRACKS --truth TRUTH``: score a track file against the truth.

The files are read by ``viz_app.io.score_files``, scored per method by
``core.tracking.scoring`` and reported by ``viz_app.reports.score``: a text table by default,
the JSON document with ``--json``, and with ``--out FILE.json`` the document written
atomically (``viz_app.io.atomic``) as well.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable

from radarviz.core.finite import check_finite_document
from radarviz.core.params import check_choice
from radarviz.viz_app.cli.args import print_report
from radarviz.viz_app.cli.commands import Registrar
from radarviz.viz_app.cli.params import add_parameter, map_flag


def add_commands(sub: Registrar) -> None:
    """Register ``score`` on the ``radarviz`` parser."""
    sc = sub.add_parser("score")
    sc.add_argument(
        "tracks",
        metavar="TRACKS",
        help="track file (radarviz track's CSV or Parquet, or any with time_s, method, x_m, y_m)",
    )
    sc.add_argument(
        "--truth",
        required=True,
        metavar="TRUTH",
        help="truth file, CSV or Parquet: time_s, target, x_m, y_m [, z_m] "
        "[, vx_mps, vy_mps [, vz_mps]] (simulate --preset crossing --truth-out writes one)",
    )
    add_parameter(sc, "gospa_cutoff_m", "--gospa-cutoff-m")
    add_parameter(sc, "gospa_order", "--gospa-order")
    add_parameter(sc, "score_max_gap_s", "--max-gap-s")
    sc.add_argument(
        "--method",
        nargs="+",
        default=None,
        metavar="METHOD",
        help="methods to score (default: every method in the file)",
    )
    map_flag(sc, "method", "--method")
    sc.add_argument(
        "--all-tracks",
        action="store_true",
        help="score tentative tracks too (default: only confirmed ones where the file has a "
        "status column)",
    )
    sc.add_argument(
        "--json", action="store_true", help="print only the JSON document on standard output"
    )
    sc.add_argument(
        "--out", default=None, metavar="FILE.json", help="also write the JSON document (replaced)"
    )


def cmd_score(args: argparse.Namespace) -> int:
    from radarviz.core.tracking.scoring import ScoreOptions, score_tracks
    from radarviz.viz_app.io.atomic import atomic_write, check_outputs
    from radarviz.viz_app.io.score_files import TrackFile, read_truth
    from radarviz.viz_app.reports.score import format_score_table, score_document

    options = ScoreOptions(
        gospa_cutoff_m=args.gospa_cutoff_m,
        gospa_order=args.gospa_order,
        score_max_gap_s=args.score_max_gap_s,
        confirmed_only=not args.all_tracks,
    )
    check_outputs([("--out", args.out)], [("TRACKS", args.tracks), ("--truth", args.truth)])
    truth = read_truth(args.truth)
    tracks = TrackFile(args.tracks)
    methods = tracks.methods if args.method is None else list(dict.fromkeys(args.method))
    for m in methods:
        check_choice("method", m, tracks.methods)
    scores = {m: score_tracks(truth, tracks.rows[m], options) for m in methods}
    columns = {
        "rows": tracks.n_rows,
        "status": tracks.has_status,
        "velocity": tracks.has_velocity,
        "covariance": tracks.has_covariance,
    }
    doc = score_document(args.tracks, args.truth, options, len(truth.times_s), columns, scores)
    check_finite_document("score", doc, nonnegative=True)
    if args.out:
        with atomic_write(args.out, "w", encoding="utf-8") as fh:
            json.dump(doc, fh, allow_nan=False, indent=1)
            fh.write("\n")
    print_report(doc, args.json, format_score_table, allow_nan=False)
    if args.out and not args.json:
        print(f"\nscores written to {args.out}")
    return 0


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {"score": cmd_score}
