"""fcop_replay: run a recorded bag through fcop_node, or play it for a live node.

Offline mode (default) streams the bag's three image topics through the real FcopNode in this
process (same class, synchroniser, window and parameters, spun by an executor; the messages go
through DDS), one message at a time so nothing is lost, as fast as the node runs, and writes
to --out: estimates.csv, an output bag of camera_info / object_poses / object_markers, and
report.png. Play mode (--play) publishes the bag's image messages on their topics with the
recorded timing, as `ros2 bag play` would.
"""
from __future__ import annotations

import argparse
import csv
import os
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .bagio import BagError, BagSource, BagWriter
from .config import config_path
from .dds import use_large_image_profile

IMAGE_TYPE = "sensor_msgs/msg/Image"
INFO_TYPE = "sensor_msgs/msg/CameraInfo"
CSV_COLUMNS = ["stamp_ns", "focal", "std_rel", "cx", "cy", "support", "objects"]


class ReplayError(RuntimeError):
    """A replay that cannot run as asked (bad bag, topic, type or encoding)."""


@dataclass
class ReplaySummary:
    """What a replay did: counts, errors against truth (percent), speed, outputs, damage."""

    frames_read: int = 0
    frames_estimated: int = 0
    errors_pct: list = field(default_factory=list)
    seconds: float = 0.0
    out_dir: str = ""
    damaged: str = ""
    rejected: dict = field(default_factory=dict)

    @property
    def fps(self) -> float:
        return self.frames_read / self.seconds if self.seconds > 0 else 0.0

    def text(self) -> str:
        lines = [f"frames read       {self.frames_read}",
                 f"frames estimated  {self.frames_estimated}"]
        if self.errors_pct:
            e = np.asarray(self.errors_pct)
            lines.append(f"focal error       median {np.median(e):.2f}%, 90th percentile {np.percentile(e, 90):.2f}%"
                         f" (over {e.size} estimates with truth)")
        lines.append(f"throughput        {self.fps:.1f} frames/s ({self.seconds:.1f} s)")
        if self.rejected:
            lines.append("rejected inputs   " + ", ".join(f"{k}: {v}" for k, v in sorted(self.rejected.items())))
        if self.damaged:
            lines.append(f"bag damaged       {self.damaged}; outputs hold what was estimated before")
        lines.append(f"outputs           {self.out_dir}/estimates.csv, {self.out_dir}/fcop_output/, "
                     f"{self.out_dir}/report.png")
        return "\n".join(lines)


def _check_topics(source: BagSource, wanted: dict) -> None:
    """wanted: {role: (topic, expected type)}; raise ReplayError naming what the bag has instead."""
    for role, (topic, msgtype) in wanted.items():
        if topic not in source.topics:
            raise ReplayError(f"{role} topic {topic!r} is not in the bag; it has: {source.describe()}")
        if source.topics[topic] != msgtype:
            raise ReplayError(f"{role} topic {topic!r} has type {source.topics[topic]}, expected {msgtype}")


def _check_encoding(role: str, msg) -> None:
    from msg_adapters import DEPTH_ENCODINGS, MASK_ENCODINGS, NOCS_ENCODINGS
    supported = {"depth": DEPTH_ENCODINGS, "nocs": NOCS_ENCODINGS, "mask": MASK_ENCODINGS}[role]
    if msg.encoding not in supported:
        raise ReplayError(f"{role} topic: unsupported encoding {msg.encoding!r}; supported: {', '.join(supported)}")


def _node_args(params_file: str | None, overrides, inputs: dict) -> list[str]:
    args = ["--ros-args", "-r", "__ns:=/fcop"]
    for role, topic in inputs.items():
        args += ["-r", f"{role}:={topic}"]
    if params_file:
        args += ["--params-file", params_file]
    for item in overrides or ():
        args += ["-p", item]
    return args


def replay(bag, depth_topic: str, nocs_topic: str, mask_topic: str, out_dir, *, truth_topic: str | None = None,
           params_file: str | None = None, overrides=(), out_storage: str = "mcap", progress: bool | None = None,
           timeout: float = 60.0) -> ReplaySummary:
    """Offline replay (see the module docstring). Raises ReplayError/BagError for unusable input;
    a bag damaged part-way is reported in the summary and its outputs keep what came before."""
    use_large_image_profile()
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from geometry_msgs.msg import PoseArray
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import CameraInfo, Image
    from visualization_msgs.msg import MarkerArray

    from msg_adapters import stamp_ns

    from .node import FcopNode

    inputs = {"depth": depth_topic, "nocs": nocs_topic, "mask": mask_topic}
    source = BagSource(bag)
    wanted = {role: (t, IMAGE_TYPE) for role, t in inputs.items()}
    if truth_topic is not None:
        wanted["truth"] = (truth_topic, INFO_TYPE)
    try:
        _check_topics(source, wanted)
    except ReplayError:
        source.close()
        raise
    total = source.counts.get(depth_topic, 0)
    if total == 0:
        source.close()
        raise ReplayError(f"depth topic {depth_topic!r} has no messages")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    out_bag = out / "fcop_output"
    if out_bag.exists():
        import shutil
        shutil.rmtree(out_bag)
    params_file = params_file if params_file is not None else config_path()
    role_of = {v: k for k, v in inputs.items()}
    summary = ReplaySummary(out_dir=str(out))
    rows = []
    truth: dict[int, float] = {}
    checked = set()

    ctx = Context()
    rclpy.init(context=ctx, args=[])
    executor = SingleThreadedExecutor(context=ctx)
    node = FcopNode(context=ctx, cli_args=_node_args(params_file, overrides, inputs))
    feeder = Node("fcop_replay", context=ctx)
    pubs = {t: feeder.create_publisher(Image, t, qos_profile_sensor_data) for t in inputs.values()}
    outputs = {"camera_info": node.pub_info.topic_name, "object_poses": node.pub_poses.topic_name,
               "object_markers": node.pub_markers.topic_name}
    types = {"camera_info": INFO_TYPE, "object_poses": "geometry_msgs/msg/PoseArray",
             "object_markers": "visualization_msgs/msg/MarkerArray"}
    got: dict[str, list] = {k: [] for k in outputs}
    consumed = {k: 0 for k in outputs}
    classes = {"camera_info": CameraInfo, "object_poses": PoseArray, "object_markers": MarkerArray}
    subs = [feeder.create_subscription(classes[k], t, got[k].append, 100, raw=True) for k, t in outputs.items()]
    executor.add_node(node)
    executor.add_node(feeder)

    def spin_until(cond, limit=timeout):
        deadline = time.monotonic() + limit
        while not cond():
            if time.monotonic() > deadline:
                raise ReplayError("the node did not answer in time (is the machine overloaded?) "
                                  f"[received {node.received}/{sent}, matched {node.sync.stats.matched}, "
                                  f"processed {node.processed}, published {node.published}, "
                                  f"outputs {[len(v) for v in got.values()]}]")
            executor.spin_once(timeout_sec=0.01)

    bar = None
    if progress is None:
        progress = sys.stderr.isatty()
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=total, unit="frame", desc="fcop_replay", file=sys.stderr)
    t0 = time.perf_counter()
    sent = 0
    try:
        spin_until(lambda: all(p.get_subscription_count() for p in pubs.values())
                   and all(s.get_publisher_count() for s in subs), 30)
        with BagWriter(out_bag, out_storage) as writer:
            def drain():
                """Write what the node published for the frames handed over so far."""
                spin_until(lambda: node.processed >= node.sync.stats.matched and node.idle())
                wanted = [k for k, on in (("camera_info", True), ("object_poses", node.p["publish_poses"]),
                                          ("object_markers", node.p["publish_markers"])) if on]
                spin_until(lambda: all(consumed[k] + len(got[k]) >= node.published for k in wanted))
                for key in outputs:
                    consumed[key] += len(got[key])
                    for raw in got[key]:
                        if key == "camera_info":
                            info = deserialize_message(raw, CameraInfo)
                            stamp = stamp_ns(info)
                            _row(rows, info, stamp, node, summary)
                        else:
                            stamp = rows[-1]["stamp_ns"] if rows else 0
                        writer.write_raw(outputs[key], types[key], bytes(raw), stamp)
                    got[key].clear()

            try:
                for topic, _, raw in source.messages(list(inputs.values()) + [truth_topic] * bool(truth_topic)):
                    if topic == truth_topic:
                        info = deserialize_message(raw, CameraInfo)
                        truth[stamp_ns(info)] = float(info.k[0])
                        continue
                    role = role_of[topic]
                    if role not in checked:
                        _check_encoding(role, deserialize_message(raw, Image))
                        checked.add(role)
                    pubs[topic].publish(raw)
                    sent += 1
                    spin_until(lambda: node.received >= sent)
                    if role == "depth":
                        summary.frames_read += 1
                        if bar is not None:
                            bar.update(1)
                    drain()
            except (ReplayError, BagError):
                raise
            except Exception as exc:  # a damaged or truncated bag: keep what came before
                source.damaged = f"{type(exc).__name__}: {exc}"
            drain()
            summary.damaged = source.damaged
    finally:
        if bar is not None:
            bar.close()
        summary.seconds = time.perf_counter() - t0
        summary.rejected = dict(node.rejected)
        node.destroy_node()
        feeder.destroy_node()
        executor.shutdown(timeout_sec=1.0)
        ctx.try_shutdown()
        source.close()
        _attach_truth(rows, truth, summary)
        _write_csv(out / "estimates.csv", rows, truth_topic is not None)
        write_report(out / "report.png", rows, summary)
    return summary


def _row(rows, info, stamp, node, summary) -> None:
    last = node.last
    win = last[1] if last is not None and last[0] == stamp else node.window.current
    objects = last[2] if last is not None and last[0] == stamp else []
    row = {"stamp_ns": stamp, "focal": float(info.k[0]), "cx": float(info.k[2]), "cy": float(info.k[5]),
           "support": int(win.support), "objects": len(objects),
           "std_rel": win.std_rel if win.std_rel is not None else float("nan")}
    rows.append(row)
    summary.frames_estimated += 1


def _attach_truth(rows, truth: dict, summary: ReplaySummary) -> None:
    """Truth per estimate: the truth message of the same stamp, else the latest one before it
    (truth messages may come after the images of their frame in the bag)."""
    if not truth:
        return
    stamps = np.array(sorted(truth))
    values = np.array([truth[s] for s in stamps])
    for row in rows:
        i = int(np.searchsorted(stamps, row["stamp_ns"], side="right")) - 1
        if i < 0:
            continue
        row["focal_true"] = float(values[i])
        row["focal_error_pct"] = 100.0 * (row["focal"] / row["focal_true"] - 1.0)
        summary.errors_pct.append(abs(row["focal_error_pct"]))


def _write_csv(path: Path, rows, with_truth: bool) -> None:
    cols = CSV_COLUMNS + (["focal_true", "focal_error_pct"] if with_truth else [])
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for r in rows:
            w.writerow([("" if r.get(c) is None else
                         f"{r[c]:.4f}" if isinstance(r.get(c), float) else r.get(c, "")) for c in cols])


def write_report(path: Path, rows, summary: ReplaySummary) -> None:
    """report.png: the focal estimate over time with its band, the truth, and the confidence."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    if rows:
        t = (np.array([r["stamp_ns"] for r in rows]) - rows[0]["stamp_ns"]) * 1e-9
        f = np.array([r["focal"] for r in rows])
        std = np.nan_to_num(np.array([r["std_rel"] for r in rows]), nan=0.0)
        ax.fill_between(t, f * np.exp(-2 * std), f * np.exp(2 * std), color="tab:blue", alpha=0.2,
                        label="estimate ± 2 std_rel")
        ax.plot(t, f, color="tab:blue", drawstyle="steps-post", label="fcop_node focal (window)")
        if any("focal_true" in r for r in rows):
            tt = [ti for ti, r in zip(t, rows) if "focal_true" in r]
            ax.plot(tt, [r["focal_true"] for r in rows if "focal_true" in r], "k--", drawstyle="steps-post",
                    label="truth")
        ax2.plot(t, 100 * std, color="tab:green")
    else:
        ax.text(0.5, 0.5, "no estimate was published", ha="center", va="center", transform=ax.transAxes)
    ax.set_ylabel("focal length [px]")
    title = f"fcop_replay: {summary.frames_estimated} of {summary.frames_read} frames estimated"
    if summary.errors_pct:
        title += f", median error {np.median(summary.errors_pct):.2f}%"
    ax.set_title(title)
    if rows:
        ax.legend(loc="best")
    ax.grid(alpha=0.3)
    ax2.set_ylabel("std_rel [%]")
    ax2.set_xlabel("time since first estimate [s]")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def play(bag, image_topics, *, rate: float = 1.0, loop: bool = False, context=None, stop: threading.Event | None = None,
         qos_depth: int = 10) -> int:
    """Publish the bag's messages of ``image_topics`` with the recorded timing scaled by ``rate``.

    Returns the number of messages published. ``context`` is an initialised rclpy Context
    (default: the global one, initialised here); ``stop`` ends playback early."""
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    if not rate > 0:
        raise ReplayError("--rate must be > 0")
    source = BagSource(bag)
    try:
        _check_topics(source, {f"image {i + 1}": (t, IMAGE_TYPE) for i, t in enumerate(image_topics)})
    except ReplayError:
        source.close()
        raise
    own = context is None
    if own:
        use_large_image_profile()
        rclpy.init()
    node = Node("fcop_player", context=context)
    pubs = {t: node.create_publisher(Image, t, qos_depth) for t in image_topics}
    stop = stop or threading.Event()
    count = 0
    try:
        while not stop.is_set():
            start_wall, start_bag = None, None
            for topic, ts, raw in source.messages(image_topics):
                if stop.is_set():
                    break
                if start_wall is None:
                    start_wall, start_bag = time.monotonic(), ts
                due = start_wall + (ts - start_bag) * 1e-9 / rate
                if stop.wait(max(0.0, due - time.monotonic())):
                    break
                pubs[topic].publish(raw)
                count += 1
            if not loop:
                break
    finally:
        node.destroy_node()
        source.close()
        if own and rclpy.ok():
            rclpy.shutdown()
    return count


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="fcop_replay", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bag", help="ROS 2 bag directory (sqlite3 or mcap)")
    ap.add_argument("--depth-topic", required=True)
    ap.add_argument("--nocs-topic", required=True)
    ap.add_argument("--mask-topic", required=True)
    ap.add_argument("--truth-topic", default=None, help="sensor_msgs/CameraInfo topic with the true intrinsics")
    ap.add_argument("--out", default="fcop_replay_out", help="output directory (offline mode)")
    ap.add_argument("--params-file", default=None, help="node parameters (default: the package's config/fcop.yaml)")
    ap.add_argument("-p", dest="overrides", action="append", default=[], metavar="NAME:=VALUE",
                    help="override one node parameter (repeatable)")
    ap.add_argument("--out-storage", default="mcap", choices=["mcap", "sqlite3"])
    ap.add_argument("--play", action="store_true", help="publish the image topics with the recorded timing")
    ap.add_argument("--rate", type=float, default=1.0, help="play mode: speed factor")
    ap.add_argument("--loop", action="store_true", help="play mode: start over at the end")
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    for item in args.overrides:
        if ":=" not in item:
            print(f"fcop_replay: -p expects NAME:=VALUE, got {item!r}", file=sys.stderr)
            return 2
    try:
        if args.play:
            n = play(args.bag, [args.depth_topic, args.nocs_topic, args.mask_topic], rate=args.rate, loop=args.loop)
            print(f"published {n} messages")
            return 0
        summary = replay(args.bag, args.depth_topic, args.nocs_topic, args.mask_topic, args.out,
                         truth_topic=args.truth_topic, params_file=args.params_file, overrides=args.overrides,
                         out_storage=args.out_storage)
    except (ReplayError, BagError) as exc:
        print(f"fcop_replay: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    print(summary.text())
    if summary.frames_read and not summary.frames_estimated:
        print("fcop_replay: no frame was estimated: the three topics never matched or gave no evidence "
              "(see 'rejected inputs')", file=sys.stderr)
        return 1
    return 3 if summary.damaged else 0


if __name__ == "__main__":
    raise SystemExit(main())
