"""The embedded default (make demo): write a small synthetic bag, replay it through fcop_node,
print the summary (focal estimate against the truth) and where the report is."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .cli import HelpFormatter
from .make_bag import MAX_FRAMES, MAX_SEED, TOPICS, check_limits, make_bag
from .replay_offline import replay
from ..synthetic import PRESETS, SequenceSpec


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="fcop_demo", description=__doc__,
                                 formatter_class=HelpFormatter,
                                 epilog="exit codes:\n  0   done\n  1   nothing was estimated\n"
                                        "  2   unusable arguments (nothing is written), or the "
                                        "bag or the outputs could not be written\n"
                                        "  130 interrupted (Ctrl-C)")
    ap.add_argument("--out", default="out/demo",
                    help="directory for the bag and the replay outputs")
    ap.add_argument("--frames", type=int, default=60,
                    help=f"number of frames, 640x480 at 30 Hz (1..{MAX_FRAMES})")
    ap.add_argument("--preset", default="moderate", choices=sorted(PRESETS), help="noise preset")
    ap.add_argument("--focal", type=float, default=600.0,
                    help="true focal length before the zoom, pixels")
    ap.add_argument("--zoom-focal", type=float, default=750.0,
                    help="true focal length after the zoom at 2/3 of the frames, pixels")
    ap.add_argument("--seed", type=int, default=0,
                    help=f"seed of the scene and of the node's triplet sampling (0..{MAX_SEED})")
    return ap


def main(argv=None) -> int:
    from .bagio import BagError, not_a_bag_of, remove_bag
    from .replay_base import ReplayError, check_out_dir

    args = build_parser().parse_args(argv)
    out = Path(args.out)
    bag = out / "input_bag"
    zoom_frame = (2 * args.frames) // 3
    try:
        check_out_dir(args.out)
        check_limits(args.seed, 640, 480, args.frames, SequenceSpec.objects)
        spec = SequenceSpec(args.frames, 640, 480, args.focal, zoom_frame, args.zoom_focal,
                            args.preset)
        if out.exists() and not out.is_dir():
            raise ValueError(f"--out {out} exists and is not a directory")
        why = not_a_bag_of(bag, "/camera/")
        if why:
            raise ValueError(f"{bag} exists and is not a bag fcop_demo wrote ({why}): move it "
                             "away or choose another --out")
        remove_bag(bag)
        out.mkdir(parents=True, exist_ok=True)
    except (ValueError, OSError, ReplayError) as exc:
        print(f"fcop_demo: {exc}", file=sys.stderr)
        return 2
    print(f"1/2 writing a synthetic bag: {args.frames} frames 640x480 at 30 Hz, 5 objects, "
          f"noise preset '{args.preset}', true focal {args.focal:.0f} px, zoom to "
          f"{args.zoom_focal:.0f} px at frame {zoom_frame}")
    t0 = time.perf_counter()
    bar = None
    if sys.stderr.isatty():
        from tqdm import tqdm
        bar = tqdm(total=args.frames, unit="frame", desc="    writing", file=sys.stderr)
    try:
        make_bag(bag, spec, seed=args.seed, compression="zstd",
                 progress=(lambda k: bar.update(k - bar.n)) if bar is not None else None)
        if bar is not None:
            bar.close()
        size = sum(f.stat().st_size for f in bag.iterdir())
        print(f"    {bag} written in {time.perf_counter() - t0:.1f} s ({size / 1e6:.0f} MB, zstd)")
        print("2/2 replaying it through fcop_node (in-process, over DDS)")
        # A fixed triplet-sampling seed makes the printed figures repeatable run to run.
        summary = replay(bag, TOPICS["depth"], TOPICS["nocs"], TOPICS["mask"], out,
                         truth_topic=TOPICS["truth"], overrides=[f"seed:={args.seed}"])
    except (BagError, OSError, ReplayError) as exc:
        print(f"fcop_demo: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # as fcop_replay: no traceback, the shell's code for Ctrl-C
        print("fcop_demo: interrupted", file=sys.stderr)
        return 130
    print(summary.text())
    print(f"report image: {out / 'report.png'}")
    return 0 if summary.frames_estimated else 1


if __name__ == "__main__":  # python -m: as the console script, signals included
    from fcop_ros.entry_points import fcop_demo

    raise SystemExit(fcop_demo())
