"""fcop_node throughput, latency and memory, in-process, 640x480 inputs with 5 objects.

    python bench/bench_node.py [--frames 600] [--rate 30] [--cores 1] [--slow-ms 0]   (make bench)

Paced run: a timer publishes depth, NOCS and mask at --rate; CameraInfo latency is the time from
the depth message's publication to the CameraInfo with its stamp (published on arrival with the
current estimate), estimate latency the time to the poses of that frame (for the frames the
estimator took; it skips to the newest frame when it is slower than the input). Reference in
the same run: the latency of the depth image itself to a plain subscriber (DDS transport alone).
--slow-ms adds that much to every frame estimate (a deliberately slow estimator). Closed loop:
the next frame is published when the previous frame's poses arrive: the estimator's maximum rate.
Memory: resident set size sampled over the paced run (flat means no growth per frame).
--cores 1 pins the process to one core (both the executor and the estimator thread).
"""
from __future__ import annotations

import argparse
import contextlib
import os
import time

import numpy as np


def rss_mb() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


@contextlib.contextmanager
def ros_context():
    """A private, initialised Context and a SingleThreadedExecutor on it; both shut down after."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    ctx = Context()
    rclpy.init(context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    try:
        yield ctx, executor
    finally:
        executor.shutdown(timeout_sec=1.0)
        ctx.try_shutdown()


def spin_until(executor, condition, timeout: float, step: float = 0.02) -> bool:
    """Spin until ``condition()`` holds or the deadline passes (the test harness's loop; the
    benchmark keeps its own copy rather than reaching into test/)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not condition():
        executor.spin_once(timeout_sec=step)
    return bool(condition())


def frame_messages(frame):
    """Depth (32FC1), NOCS (32FC3) and mask (mono8) Image messages of a rendered frame."""
    from std_msgs.msg import Header

    from msg_adapters import depth_to_image, mask_to_image, nocs_to_image
    h = Header(frame_id="camera_optical_frame")
    return (depth_to_image(frame.depth, "32FC1", h), nocs_to_image(frame.nocs, "32FC3", h),
            mask_to_image(frame.mask, "mono8", h))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=600)
    ap.add_argument("--rate", type=float, default=30.0)
    ap.add_argument("--cores", type=int, default=1)
    ap.add_argument("--closed-loop-frames", type=int, default=200)
    ap.add_argument("--slow-ms", type=float, default=0.0,
                    help="extra time per frame estimate (ms)")
    args = ap.parse_args()
    if args.cores:
        os.sched_setaffinity(0, set(sorted(os.sched_getaffinity(0))[: args.cores]))
    from fcop_ros.ros.dds import keep_on_this_machine
    keep_on_this_machine()
    from geometry_msgs.msg import PoseArray
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image

    import fcop_ros.ros.node as node_module
    from fcop_ros.ros.node import FcopNode
    if args.slow_ms > 0:
        real = node_module.estimate_focal

        def slow(*a, **k):
            time.sleep(args.slow_ms / 1000)
            return real(*a, **k)
        node_module.estimate_focal = slow
    from msg_adapters import stamp_ns
    from fcop_ros.synthetic import apply_noise, render_scene

    frames = [apply_noise(render_scene(np.random.default_rng(k), 5, 600.0), "moderate",
                          np.random.default_rng(k))
              for k in range(20)]
    msgs = [frame_messages(fr) for fr in frames]
    print(
        f"machine: {os.cpu_count()} cores, pinned to {len(os.sched_getaffinity(0))}; "
        f"{args.frames} frames 640x480, 5 objects, preset moderate, estimator slowed by "
        f"{args.slow_ms:g} ms"
    )
    with ros_context() as (ctx, ex):
        node = FcopNode(context=ctx)
        tester = Node("bench", context=ctx)
        pubs = [
            tester.create_publisher(Image, t, qos_profile_sensor_data)
            for t in ("depth", "nocs", "mask")
        ]
        sent, got, depth_got, posed = {}, {}, {}, {}
        tester.create_subscription(CameraInfo, "camera_info",
                                   lambda m: got.setdefault(stamp_ns(m), time.perf_counter()), 100)
        tester.create_subscription(PoseArray, "object_poses",
                                   lambda m: posed.setdefault(stamp_ns(m), time.perf_counter()),
                                   100)
        tester.create_subscription(
            Image,
            "depth",
            lambda m: depth_got.setdefault(stamp_ns(m), time.perf_counter()),
            qos_profile_sensor_data,
        )
        ex.add_node(node)
        ex.add_node(tester)
        spin_until(ex, lambda: all(p.get_subscription_count() >= 1 for p in pubs), 10)

        def publish(k: int) -> None:
            stamp = 10**18 + k * 10**7
            trio = msgs[k % len(msgs)]
            for m in trio:
                m.header.stamp.sec, m.header.stamp.nanosec = divmod(stamp, 10**9)
            sent[stamp] = time.perf_counter()
            for p, m in zip(pubs, trio):
                p.publish(m)

        # Paced run.
        state = {"k": 0}
        mem = []

        def tick():
            if state["k"] < args.frames:
                publish(state["k"])
                state["k"] += 1
                if state["k"] % 50 == 0:
                    mem.append(rss_mb())

        timer = tester.create_timer(1.0 / args.rate, tick)
        t0 = time.perf_counter()
        spin_until(
            ex,
            lambda: (
                state["k"] >= args.frames
                and node.idle()
                and len(posed) >= node.published
                and len(got) >= node.camera_info_published
            ),
            timeout=args.frames / args.rate * 4 + 30,
        )
        wall = time.perf_counter() - t0
        tester.destroy_timer(timer)
        lat = np.array([got[s] - sent[s] for s in sent if s in got]) * 1000
        dds = np.array([depth_got[s] - sent[s] for s in sent if s in depth_got]) * 1000
        est = np.array([posed[s] - sent[s] for s in sent if s in posed]) * 1000
        done = len(lat)
        print(
            f"paced at {args.rate:.0f} Hz: {done}/{args.frames} depth images got their CameraInfo "
            f"({done / wall:.1f} CameraInfo/s over {wall:.1f} s); the estimator took "
            f"{node.processed} frames "
            f"({node.processed / wall:.1f}/s), skipped {node.handoff_dropped} for newer ones; "
            f"sync drops {node.sync.stats.dropped_total}"
        )
        print(
            f"  latency depth -> CameraInfo: median {np.median(lat):.2f} ms, p95 "
            f"{np.percentile(lat, 95):.2f} ms"
        )
        print(
            "  latency depth -> poses of the frame (estimated frames): median "
            f"{np.median(est):.1f} ms, "
            f"p95 {np.percentile(est, 95):.1f} ms"
        )
        print(f"  reference, depth image to a plain subscriber: median {np.median(dds):.2f} ms, "
              f"p95 {np.percentile(dds, 95):.2f} ms")
        proc = np.array(node._proc_times) * 1000
        print(
            "  node processing per frame (convert + estimate + window + publish): median "
            f"{np.median(proc):.1f} ms"
        )
        if mem:
            print(
                f"  resident memory: {mem[0]:.0f} MB after 50 frames, {mem[-1]:.0f} MB after "
                f"{50 * len(mem)} frames"
            )

        # Closed loop: maximum rate.
        posed.clear()
        sent.clear()
        base = args.frames + 10
        t0 = time.perf_counter()
        for i in range(args.closed_loop_frames):
            publish(base + i)
            spin_until(ex, lambda: len(posed) >= i + 1, 10)
        wall = time.perf_counter() - t0
        print(f"closed loop (next frame when the previous one's poses arrive): "
              f"{args.closed_loop_frames / wall:.1f} frames/s")
        node.destroy_node()
        tester.destroy_node()


if __name__ == "__main__":
    main()
