"""fcop_replay: run a recorded bag through fcop_node, or play it for a live node.

Offline mode (default) streams the bag's three image topics through the real FcopNode in this
process (same class, synchroniser, window and parameters, spun by an executor; the messages go
through DDS), one message at a time so nothing is lost, as fast as the node runs, and writes
to --out: estimates.csv (row by row, flushed as it goes), an output bag of camera_info /
object_poses / object_markers, and report.png. Play mode (--play) publishes the bag's image
messages on their topics with the recorded timing, as `ros2 bag play --clock` would, and the
recorded time on /clock for nodes with use_sim_time.

Parameters: --params-file sections keyed '/**', '/**/fcop_node', 'fcop_node' or
'<namespace>/fcop_node' all apply, in file order as rcl applies them (a later value wins),
then every -p NAME:=VALUE; unknown names and invalid values are refused before anything runs.
"""

from __future__ import annotations

import argparse
import re
import sys

from .bagio import BagError
from .cli import HelpFormatter
from .replay_base import OutputError, ReplayError, ReplaySummary
from .replay_offline import replay
from .replay_play import play

EXIT_OK, EXIT_NOTHING, EXIT_INPUT, EXIT_DAMAGED, EXIT_OUTPUT, EXIT_INTERRUPTED = 0, 1, 2, 3, 4, 130
EXIT_CODES = {
    EXIT_OK: "done",
    EXIT_NOTHING: (
        "no CameraInfo was published from an undamaged bag: the topics never matched or gave "
        "no evidence, or every estimate was held back by max_uncertainty or "
        "focal_min..focal_max"
    ),
    EXIT_INPUT: (
        "unusable input or arguments: missing bag or one that cannot be opened at all, unknown "
        "topic or one without messages, wrong type, unsupported encoding, unknown parameter "
        "name, invalid parameter value or --params-file"
    ),
    EXIT_DAMAGED: (
        "the bag is damaged: read (replayed or played) up to the damage; outputs keep what came "
        "before (also when nothing was published from it)"
    ),
    EXIT_OUTPUT: (
        "the outputs cannot be written (--out not a directory, read-only, disk full) or are not "
        "a previous replay's (a user's estimates.csv, report.png or fcop_output); the message "
        "says what was lost"
    ),
    EXIT_INTERRUPTED: "interrupted (Ctrl-C)",
}


def exit_codes_text() -> str:
    return "exit codes:\n" + "\n".join(f"  {code:<4}{text}" for code, text in EXIT_CODES.items())


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="fcop_replay",
        description=__doc__,
        epilog=exit_codes_text(),
        formatter_class=HelpFormatter,
    )
    ap.add_argument("bag", help="ROS 2 bag directory (sqlite3 or mcap), or an .mcap file")
    ap.add_argument(
        "--depth-topic",
        required=True,
        help="sensor_msgs/Image topic of the metric depth (required)",
    )
    ap.add_argument(
        "--nocs-topic", required=True, help="sensor_msgs/Image topic of the NOCS map (required)"
    )
    ap.add_argument(
        "--mask-topic",
        required=True,
        help="sensor_msgs/Image topic of the instance mask (required)",
    )
    ap.add_argument(
        "--truth-topic",
        default=None,
        help="sensor_msgs/CameraInfo topic with the true intrinsics: adds focal_true and "
        "focal_error_pct to the CSV and the error panel to the report (default: none)",
    )
    ap.add_argument("--out", default="fcop_replay_out", help="output directory (offline mode)")
    ap.add_argument(
        "--params-file",
        default=None,
        help="ROS 2 parameter file for the node; sections '/**', '/**/fcop_node', 'fcop_node' "
        "and '<ns>/fcop_node' apply (default: the package's config/fcop.yaml)",
    )
    ap.add_argument(
        "-p",
        dest="overrides",
        action="append",
        default=[],
        metavar="NAME:=VALUE",
        help="set one node parameter, after the params file (repeatable)",
    )
    ap.add_argument(
        "--out-storage",
        default="mcap",
        choices=["mcap", "sqlite3"],
        help="storage of the output bag",
    )
    ap.add_argument(
        "--play",
        action="store_true",
        help="publish the image topics with the recorded timing (and /clock) instead of replaying",
    )
    ap.add_argument("--rate", type=float, default=1.0, help="play mode: speed factor")
    ap.add_argument("--loop", action="store_true", help="play mode: start over at the end")
    ap.add_argument(
        "--no-clock",
        dest="clock",
        action="store_false",
        help="play mode: do not publish the recorded time on /clock",
    )
    ap.add_argument(
        "--clock-hz",
        type=float,
        default=40.0,
        help="play mode: /clock messages per second of wall time between the bag's messages "
        "(one also goes out with every message; 0 = only those)",
    )
    ap.add_argument(
        "--wait-subscribers",
        type=float,
        default=5.0,
        metavar="SECONDS",
        help="play mode: before the first message, wait up to this long until each image topic "
        "has a subscriber (a live node still being discovered would lose the first frames); "
        "0 = do not wait",
    )
    return ap


# The options of one mode, by their argparse names, as typed.
PLAY_ONLY = {"rate": "--rate", "loop": "--loop", "clock": "--no-clock", "clock_hz": "--clock-hz",
             "wait_subscribers": "--wait-subscribers"}
OFFLINE_ONLY = {"truth_topic": "--truth-topic", "out": "--out", "params_file": "--params-file",
                "overrides": "-p", "out_storage": "--out-storage"}


def _ignored(ap: argparse.ArgumentParser, args) -> list[str]:
    """The options given that the chosen mode does not use."""
    names = OFFLINE_ONLY if args.play else PLAY_ONLY
    return [flag for name, flag in names.items() if getattr(args, name) != ap.get_default(name)]


def main(argv=None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    ignored = _ignored(ap, args)
    if ignored:
        print(f"fcop_replay: {', '.join(ignored)} "
              f"{'apply' if len(ignored) > 1 else 'applies'} only "
              f"{'without' if args.play else 'with'} --play: ignored", file=sys.stderr)
    summary = ReplaySummary()  # filled as the offline run goes: what Ctrl-C leaves
    try:
        if args.play:
            res = play(
                args.bag,
                [args.depth_topic, args.nocs_topic, args.mask_topic],
                rate=args.rate,
                loop=args.loop,
                clock=args.clock,
                clock_hz=args.clock_hz,
                wait_subscribers=args.wait_subscribers,
                say=lambda line: print(f"fcop_replay: {line}", file=sys.stderr, flush=True),
            )
            print(
                f"published {res.published} messages"
                + (f" and {res.clock} on /clock" if args.clock else "")
            )
            if res.damaged:
                print(
                    f"fcop_replay: bag damaged ({res.damaged}); played the {res.published} "
                    "messages before "
                    "the damage",
                    file=sys.stderr,
                )
                return EXIT_DAMAGED
            return EXIT_OK
        replay(
            args.bag,
            args.depth_topic,
            args.nocs_topic,
            args.mask_topic,
            args.out,
            truth_topic=args.truth_topic,
            params_file=args.params_file,
            overrides=args.overrides,
            out_storage=args.out_storage,
            summary=summary,
        )
    except OutputError as exc:
        print(f"fcop_replay: {exc}", file=sys.stderr)
        return EXIT_OUTPUT
    except (ReplayError, BagError) as exc:
        print(f"fcop_replay: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        print(f"fcop_replay: {_interrupted(args, summary)}", file=sys.stderr)
        return EXIT_INTERRUPTED
    print(summary.text())
    if summary.metadata_problem:
        print(f"fcop_replay: {summary.metadata_problem}", file=sys.stderr)
    nothing = summary.frames_read and not summary.frames_estimated
    if summary.damaged:
        after = f"; {_nothing_published(summary)}" if nothing else ""
        print(f"fcop_replay: bag damaged: {summary.damaged}; the outputs hold the "
              f"{summary.frames_estimated} estimates of the {summary.frames_read} frames read "
              f"before{after}", file=sys.stderr)
        return EXIT_DAMAGED
    if nothing:
        print(f"fcop_replay: {_nothing_published(summary)}", file=sys.stderr)
        return EXIT_NOTHING
    return EXIT_OK


def _interrupted(args, summary: ReplaySummary) -> str:
    """The Ctrl-C line: what was written, only if something was."""
    if args.play:
        return "interrupted"
    if not summary.out_dir:
        return "interrupted before --out was written: nothing written"
    return (f"interrupted after {summary.frames_read} frames; {summary.out_dir} holds what "
            f"was estimated before ({summary.csv_rows} rows in estimates.csv)")


def _nothing_published(summary: ReplaySummary) -> str:
    """Why no CameraInfo came out: estimates held back by the publish gate (with the option
    that lets them through), else topics that never matched or gave no evidence."""
    if not summary.held_back:
        return ("no frame gave a focal length: the three topics never matched, or their frames "
                "gave no evidence (see 'dropped input')")
    std = re.search(r"std_rel ([0-9.eE+-]+) above", summary.held_reason)
    if "focal_range" in summary.held_reason:
        hint = "-p focal_min:=... / -p focal_max:=... if the camera's focal lies outside"
    elif std:
        # Just above the last estimate's std_rel, in two significant digits (the default 0.05).
        held = float(std.group(1))
        above = float(f"{held * 1.2:.1g}") if held > 0 else 0.05
        while above <= held:
            above *= 1.5
        hint = (f"-p max_uncertainty:={float(f'{above:.2g}'):g} (or higher) to publish "
                "estimates that uncertain")
    else:
        hint = "-p max_uncertainty:=... (default 0.05) higher to publish less certain estimates"
    return (f"no CameraInfo published: {summary.held_back} of {summary.frames_read} frames "
            "were estimated but held back by max_uncertainty / focal_range (the last: "
            f"{summary.held_reason}); try {hint}")


if __name__ == "__main__":  # python -m: as the console script, signals included
    from fcop_ros.entry_points import fcop_replay

    raise SystemExit(fcop_replay())
