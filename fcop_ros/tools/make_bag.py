"""fcop_make_bag: write a synthetic ROS 2 bag of depth, NOCS and mask images with ground truth.

Topics: /camera/depth, /camera/nocs, /camera/mask (sensor_msgs/Image), the true intrinsics on
/camera/camera_info_true (sensor_msgs/CameraInfo) and the true object poses on
/camera/object_poses_true (geometry_msgs/PoseArray, fcop_ros pose convention), all with the
same header stamp per frame. The scene is the core library's renderer with a noise preset.
Bags are zstd-compressed by default (MCAP chunks, or every message for sqlite3), as rosbag2
reads them; --compression none writes them plain.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from msg_adapters import (DEPTH_ENCODINGS, MASK_ENCODINGS, NOCS_ENCODINGS, camera_info,
                          depth_to_image, header_from_ns, mask_to_image, nocs_to_image,
                          pose_array)

from .bagio import COMPRESSIONS, STORAGES, BagError, BagWriter
from .cli import HelpFormatter
from ..core.pose import ObjectPose
from ..synthetic import PRESETS, SequenceSpec, camera_sequence

TOPICS = dict(depth="/camera/depth", nocs="/camera/nocs", mask="/camera/mask",
              truth="/camera/camera_info_true", poses="/camera/object_poses_true")
FRAME_ID = "camera_optical_frame"
START_NS = 1_700_000_000_000_000_000  # the first frame's stamp (November 2023)


def _stamp_step(rate: float, frames: int, start_ns: int) -> int:
    """Nanoseconds between frames at ``rate``, or ValueError when the stamps would not be
    distinct (above 1 GHz) or the last would not fit builtin_interfaces/Time (int32 seconds)."""
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"--rate must be a positive number of frames per second, got {rate}")
    # Capped where no second frame fits before 2038 anyway: int() takes no inf.
    step = int(round(min(1e9 / rate, 2**31 * 10**9)))
    if step < 1:
        raise ValueError(f"--rate {rate:g} Hz is above 1e9 Hz: the frames' nanosecond stamps "
                         "would repeat")
    if start_ns + (frames - 1) * step >= 2**31 * 10**9:
        raise ValueError(f"--rate {rate:g} Hz spreads {frames} frames beyond 2038, where a ROS "
                         "stamp's int32 seconds end")
    return step


MAX_SIDE = 8192  # pixels per side: beyond it a frame's float images need gigabytes
MAX_SEED = 2**31 - 1  # the node's `seed` parameter range, which fcop_demo passes it to
MAX_FRAMES = 100_000  # 55 minutes at 30 Hz, some 100 GB at 640x480: beyond, a typo
MAX_OBJECTS = 255  # one instance id each in a mono8 mask (a table in view holds far fewer)


def check_limits(seed: int, width: int, height: int, frames: int, objects: int) -> None:
    """ValueError for a seed outside 0..MAX_SEED (numpy refuses a negative one, after the bag
    was created), an image side above MAX_SIDE (a MemoryError traceback), more frames than
    MAX_FRAMES (a bag that fills the disk) or more objects than MAX_OBJECTS (--objects 10**9
    laid out for hours)."""
    if not 0 <= seed <= MAX_SEED:
        raise ValueError(f"--seed must be an integer in [0, {MAX_SEED}], got {seed}")
    for name, side in (("--width", width), ("--height", height)):
        if side > MAX_SIDE:
            raise ValueError(f"{name} {side} is too large: at most {MAX_SIDE} pixels per side")
    for name, n, most in (("--frames", frames, MAX_FRAMES), ("--objects", objects, MAX_OBJECTS)):
        if n > most:
            raise ValueError(f"{name} {n} is too many: at most {most}")


def make_bag(path, spec: SequenceSpec, *, rate: float = 30.0, seed: int = 0,
             storage: str = "mcap", depth_encoding: str = "32FC1", nocs_encoding: str = "32FC3",
             mask_encoding: str = "mono8", depth_scale: float = 0.001,
             start_ns: int = START_NS, progress=None,
             compression: str = "none") -> int:
    """Write the bag; returns the number of frames. Stamps start at ``start_ns``, 1/rate apart.
    ``progress(frames written)`` is called after every frame."""

    step = _stamp_step(rate, spec.frames, start_ns)
    n = 0
    with BagWriter(path, storage, compression) as bag:
        for k, frame in camera_sequence(spec, seed):
            stamp = start_ns + k * step
            h = header_from_ns(stamp, FRAME_ID)
            bag.write(TOPICS["depth"], depth_to_image(frame.depth, depth_encoding, h, depth_scale),
                      stamp)
            bag.write(TOPICS["nocs"], nocs_to_image(frame.nocs, nocs_encoding, h), stamp)
            bag.write(TOPICS["mask"], mask_to_image(frame.mask, mask_encoding, h), stamp)
            cx, cy = frame.principal_point
            bag.write(TOPICS["truth"],
                      camera_info(frame.focal, cx, cy, spec.width, spec.height, h), stamp)
            truth = [ObjectPose(o.instance_id, o.rotation, o.translation, o.scale, 1.0, 0.0, 0)
                     for o in frame.objects]
            bag.write(TOPICS["poses"], pose_array(truth, h), stamp)
            n += 1
            if progress:
                progress(k + 1)
    return n


EXIT_CODES_TEXT = """exit codes:
  0   done
  2   unusable arguments (the bag exists; a bad size, seed, frame or object count, focal
      length, rate or zoom)
      or the bag cannot be written; nothing is written
  130 interrupted (Ctrl-C); the partial bag is left behind"""


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="fcop_make_bag", description=__doc__,
                                 epilog=EXIT_CODES_TEXT, formatter_class=HelpFormatter)
    ap.add_argument("out", help="bag directory to create (must not exist)")
    ap.add_argument("--frames", type=int, default=60,
                    help=f"number of frames (1..{MAX_FRAMES})")
    ap.add_argument("--rate", type=float, default=30.0, help="frames per second (stamp spacing)")
    ap.add_argument("--seed", type=int, default=0,
                    help=f"seed of the scene, its motion and its noise (0..{MAX_SEED})")
    ap.add_argument("--preset", default="moderate", choices=sorted(PRESETS),
                    help="noise preset imitating learned depth and NOCS predictors")
    ap.add_argument("--focal", type=float, default=600.0, help="true focal length, pixels")
    ap.add_argument("--zoom-frame", type=int, default=None,
                    help="frame at which the focal length changes (with --zoom-focal; "
                         "default: no zoom)")
    ap.add_argument("--zoom-focal", type=float, default=None,
                    help="focal length from --zoom-frame on, pixels (default: no zoom)")
    ap.add_argument("--width", type=int, default=640,
                    help=f"image width, pixels (8..{MAX_SIDE})")
    ap.add_argument("--height", type=int, default=480,
                    help=f"image height, pixels (8..{MAX_SIDE})")
    ap.add_argument("--objects", type=int, default=5,
                    help=f"objects in the scene (1..{MAX_OBJECTS}; as many as fit are placed)")
    ap.add_argument("--storage", default="mcap", choices=sorted(STORAGES),
                    help="rosbag2 storage plugin")
    ap.add_argument("--compression", default="zstd", choices=COMPRESSIONS,
                    help="zstd: compressed MCAP chunks, or every message for sqlite3; none: plain")
    ap.add_argument("--depth-encoding", default="32FC1", choices=DEPTH_ENCODINGS,
                    help="depth image encoding")
    ap.add_argument("--nocs-encoding", default="32FC3", choices=NOCS_ENCODINGS,
                    help="NOCS image encoding")
    ap.add_argument("--mask-encoding", default="mono8", choices=MASK_ENCODINGS,
                    help="instance mask encoding")
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        check_limits(args.seed, args.width, args.height, args.frames, args.objects)
        spec = SequenceSpec(args.frames, args.width, args.height, args.focal, args.zoom_frame,
                            args.zoom_focal, args.preset, args.objects)
        _stamp_step(args.rate, spec.frames, START_NS)
    except ValueError as exc:
        print(f"fcop_make_bag: {exc}", file=sys.stderr)
        return 2
    bar = None
    if sys.stderr.isatty():
        from tqdm import tqdm
        bar = tqdm(total=args.frames, unit="frame", desc="fcop_make_bag", file=sys.stderr)
    t0 = time.perf_counter()
    try:
        n = make_bag(args.out, spec, rate=args.rate, seed=args.seed, storage=args.storage,
                     depth_encoding=args.depth_encoding, nocs_encoding=args.nocs_encoding,
                     mask_encoding=args.mask_encoding, compression=args.compression,
                     progress=(lambda k: bar.update(k - bar.n)) if bar is not None else None)
    except (BagError, OSError) as exc:
        print(f"fcop_make_bag: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        # The bag did not exist before (BagWriter refuses one that does): if it does now, it
        # is this run's.
        kept = (f"{args.out} holds the frames written before" if Path(args.out).exists()
                else "nothing written")
        print(f"fcop_make_bag: interrupted; {kept}", file=sys.stderr)
        return 130
    finally:
        if bar is not None:
            bar.close()
    print(f"wrote {n} frames ({args.width}x{args.height}, preset {args.preset}, {args.storage}, "
          f"compression {args.compression}) to {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":  # python -m: as the console script, signals included
    from fcop_ros.entry_points import fcop_make_bag

    raise SystemExit(fcop_make_bag())
