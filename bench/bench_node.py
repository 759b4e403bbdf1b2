"""fcop_node at camera rate: latency, CPU and memory, in-process, 640x480 inputs with 5 objects.

    python bench/bench_node.py [--frames 600] [--rate 30] [--cores 1] [--slow-ms 0]   (make bench)
    python bench/bench_node.py --frames 10000 --closed-loop-frames 0   (memory, 10,000 frames)

Paced run: a timer publishes depth, NOCS and mask at --rate. CameraInfo latency, twice: from the
depth message's publication, and from its arrival in the node's depth callback, to the CameraInfo
with its stamp arriving at a subscriber (published on the depth image's arrival with the current
estimate). Reference in the same run: the depth image's own latency to a plain subscriber (DDS
transport alone). Estimate latency: to the poses of that frame (for the frames the estimator
took; it skips to the newest frame when it is slower than the input). CPU: thread CPU time of
the estimator thread per estimated frame (all of the node's work on a frame: conversion,
estimate_focal, window, poses, publishing; and estimate_focal alone), and the whole process's
CPU time per input frame. --slow-ms adds that much (sleeping) to every frame estimate (a
deliberately slow estimator). Closed loop: the next frame is published when the previous frame's
poses arrive: the estimator's maximum rate.
Memory: resident set size (VmRSS) every --mem-every frames of the paced run (glibc's allocator
limited to two arenas, as fcop_node's main() does; --glibc-arenas leaves glibc's default), with the
slope of a least-squares line through the samples of the second half (flat: no growth). The
benchmark's own records are arrays allocated before the run, so they add nothing while it runs.
--cores 1 pins the process to one core (the executor thread and the estimator thread).
--listener process (default) also records, in a second process pinned to the same core, when
the CameraInfo and the depth image arrive there: what a consumer of camera_info sees, without
the benchmark's own executor (which publishes the images and serves the in-process subscribers)
in the way. Both processes then use the shipped Fast DDS profile (shared memory).
--profile prints where the executor thread (the input side and the CameraInfo path) spends
its time; --switch-interval changes how soon a thread waiting for the GIL gets it from the busy
estimator thread (a diagnostic: the node leaves the interpreter's setting alone).
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from fcop_ros.ros.spin import ros_context, spin_until


def rss_mb() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


class FrameTimes:
    """Values recorded once per frame (thread CPU seconds) into an array allocated up front: a
    list that grew by a float per frame was the benchmark's own memory growth (65 bytes per
    estimated frame, two of them), read as the node's. Past ``size`` values are counted, not
    kept."""

    def __init__(self, size: int):
        self._values = np.full(size, np.nan)
        self.n = 0  # values offered

    def add(self, value: float) -> None:
        if self.n < len(self._values):
            self._values[self.n] = value
        self.n += 1

    def array(self) -> np.ndarray:
        return self._values[: min(self.n, len(self._values))]


def thread_timed(fn, record: FrameTimes, before=None):
    """``fn`` recording each call's thread CPU time in ``record`` (``before()`` first, timed)."""
    def timed(*a, **k):
        c0 = time.thread_time()
        if before is not None:
            before()
        try:
            return fn(*a, **k)
        finally:
            record.add(time.thread_time() - c0)
    return timed


def frame_messages(frame):
    """Depth (32FC1), NOCS (32FC3) and mask (mono8) Image messages of a rendered frame."""
    from std_msgs.msg import Header

    from msg_adapters import depth_to_image, mask_to_image, nocs_to_image
    h = Header(frame_id="camera_optical_frame")
    return (depth_to_image(frame.depth, "32FC1", h), nocs_to_image(frame.nocs, "32FC3", h),
            mask_to_image(frame.mask, "mono8", h))


def ms_stats(values_s: np.ndarray) -> str:
    v = values_s[np.isfinite(values_s)] * 1000
    if not len(v):
        return "no samples"
    return f"median {np.median(v):.2f} ms, p95 {np.percentile(v, 95):.2f} ms (n={len(v)})"


def theil_sen(xy: np.ndarray) -> float:
    """The median of the slopes between every pair of samples (x, y)."""
    i, j = np.triu_indices(len(xy), 1)
    dx = xy[j, 0] - xy[i, 0]
    return float(np.median((xy[j, 1] - xy[i, 1])[dx > 0] / dx[dx > 0])) if len(i) else np.nan


def listen(out: str, total: int) -> None:
    """The other process of --listener process: record when each CameraInfo and each depth image
    arrives (perf_counter, the system-wide monotonic clock) until stdin closes; save to
    ``out``."""
    import threading

    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image

    from msg_adapters import stamp_ns
    info, depth = np.full(total, np.nan), np.full(total, np.nan)

    def record(arr):
        def cb(msg) -> None:
            k = (stamp_ns(msg) - 10**18) // 10**7
            if 0 <= k < total and np.isnan(arr[k]):
                arr[k] = time.perf_counter()
        return cb

    done = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    with ros_context() as (ctx, ex):
        node = Node("bench_listener", context=ctx)
        node.create_subscription(CameraInfo, "camera_info", record(info), 100)
        node.create_subscription(Image, "depth", record(depth), qos_profile_sensor_data)
        ex.add_node(node)
        while not done.is_set():
            ex.spin_once(timeout_sec=0.05)
        np.savez(out, info=info, depth=depth)
        node.destroy_node()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=600)
    ap.add_argument("--rate", type=float, default=30.0)
    ap.add_argument("--cores", type=int, default=1)
    ap.add_argument("--closed-loop-frames", type=int, default=200)
    ap.add_argument("--mem-every", type=int, default=500,
                    help="frames between resident-memory samples")
    ap.add_argument("--slow-ms", type=float, default=0.0,
                    help="extra time per frame estimate (ms)")
    ap.add_argument("--glibc-arenas", action="store_true",
                    help="glibc's default arenas (up to 8 per core); fcop_node sets 2")
    ap.add_argument("--profile", action="store_true",
                    help="profile the executor thread over the paced run (cProfile)")
    ap.add_argument("--switch-interval", type=float, default=0.0,
                    help="sys.setswitchinterval for the run, seconds (0: Python's 0.005)")
    ap.add_argument("--listener", choices=("process", "none"), default="process",
                    help="also receive CameraInfo and depth in a second process (pinned to the "
                         "same core)")
    ap.add_argument("--listen", metavar="OUT", help=argparse.SUPPRESS)  # the second process
    args = ap.parse_args()
    if not args.glibc_arenas:
        from fcop_ros.ros.allocator import limit_allocator_arenas
        limit_allocator_arenas()  # as fcop_node's main() does, before the node's threads
    if args.switch_interval > 0:
        sys.setswitchinterval(args.switch_interval)
    if args.cores:
        os.sched_setaffinity(0, set(sorted(os.sched_getaffinity(0))[: args.cores]))
    from fcop_ros.ros.dds import keep_on_this_machine
    keep_on_this_machine()
    if args.listener == "process" or args.listen:
        from fcop_ros.ros.dds import use_large_image_profile
        use_large_image_profile()  # 640x480 images across processes: shared memory
    total = args.frames + 10 + args.closed_loop_frames
    if args.listen:
        listen(args.listen, total)
        return
    listener = None
    if args.listener == "process":
        import subprocess
        import tempfile
        listen_out = os.path.join(tempfile.mkdtemp(prefix="bench_node_"), "listener.npz")
        listener = subprocess.Popen(
            [sys.executable, os.path.abspath(__file__), *sys.argv[1:], "--listen", listen_out],
            stdin=subprocess.PIPE)
    from geometry_msgs.msg import PoseArray
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image

    import fcop_ros.ros.frame_estimate as frame_estimate_module
    from fcop_ros.ros.node import FcopNode
    from fcop_ros.synthetic import apply_noise, render_scene
    from msg_adapters import stamp_ns

    # The CPU time of estimate_focal alone, measured in the thread that runs it.
    est_cpu = FrameTimes(total)
    frame_estimate_module.estimate_focal = thread_timed(
        frame_estimate_module.estimate_focal, est_cpu,
        (lambda: time.sleep(args.slow_ms / 1000)) if args.slow_ms > 0 else None)

    frames = [apply_noise(render_scene(np.random.default_rng(k), 5, 600.0), "moderate",
                          np.random.default_rng(k))
              for k in range(20)]
    msgs = [frame_messages(fr) for fr in frames]
    print(
        f"machine: {os.cpu_count()} cores, pinned to {len(os.sched_getaffinity(0))}; "
        f"{args.frames} frames 640x480 at {args.rate:g} Hz, 5 objects, preset moderate, "
        f"estimator slowed by {args.slow_ms:g} ms; GIL switch interval "
        f"{sys.getswitchinterval() * 1000:g} ms; load average "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}"
    )
    # Per frame index k (stamp 1e18 + k * 1e7 ns): times in perf_counter seconds, NaN until set.
    sent, node_got, info_pubd, info_got, depth_got, posed = (
        np.full(total, np.nan) for _ in range(6))

    def first(arr: np.ndarray):
        def record(msg) -> None:
            k = (stamp_ns(msg) - 10**18) // 10**7
            if 0 <= k < total and np.isnan(arr[k]):
                arr[k] = time.perf_counter()
        return record

    with ros_context() as (ctx, ex):
        node = FcopNode(context=ctx)
        # The node's depth callback, timed on arrival (the subscription calls self._on_image).
        on_image, record_node = node._on_image, first(node_got)

        def on_image_timed(index, msg):
            if index == 0:
                record_node(msg)
            on_image(index, msg)
        node._on_image = on_image_timed
        # When the node hands each CameraInfo to DDS.
        info_pub = first(info_pubd)
        publish_info = node.pub_info.publish

        def publish_info_timed(msg):
            publish_info(msg)
            info_pub(msg)
        node.pub_info.publish = publish_info_timed
        # Thread CPU time of each frame the estimator thread handles.
        proc_cpu = FrameTimes(total)
        node.process = thread_timed(node.process, proc_cpu)

        tester = Node("bench", context=ctx)
        pubs = [
            tester.create_publisher(Image, t, qos_profile_sensor_data)
            for t in ("depth", "nocs", "mask")
        ]
        tester.create_subscription(CameraInfo, "camera_info", first(info_got), 100)
        tester.create_subscription(PoseArray, "object_poses", first(posed), 100)
        tester.create_subscription(Image, "depth", first(depth_got), qos_profile_sensor_data)
        ex.add_node(node)
        ex.add_node(tester)
        others = 1 if listener is not None else 0
        spin_until(
            ex,
            lambda: all(p.get_subscription_count() >= 1 for p in pubs)
            and pubs[0].get_subscription_count() >= 2 + others
            and node.pub_info.get_subscription_count() >= 1 + others,
            30,
        )
        # A first run on a machine compiles the estimator's kernels: not part of the figures.
        t_warm = time.monotonic()
        if not spin_until(ex, lambda: not node.warming_up, 900):
            raise SystemExit("bench_node: the node's kernels were not ready within 900 s")
        if time.monotonic() - t_warm > 1.0:
            print(f"(the node prepared its estimator's kernels for "
                  f"{time.monotonic() - t_warm:.1f} s before the run)")

        def publish(k: int) -> None:
            stamp = 10**18 + k * 10**7
            trio = msgs[k % len(msgs)]
            for m in trio:
                m.header.stamp.sec, m.header.stamp.nanosec = divmod(stamp, 10**9)
            sent[k] = time.perf_counter()
            for p, m in zip(pubs, trio):
                p.publish(m)

        # Paced run.
        state = {"k": 0}
        n_mem = args.frames // args.mem_every
        mem = np.full((n_mem, 2), np.nan)  # (frames published, RSS MB)

        def tick():
            k = state["k"]
            if k < args.frames:
                publish(k)
                state["k"] = k + 1
                if (k + 1) % args.mem_every == 0 and (k + 1) // args.mem_every <= n_mem:
                    mem[(k + 1) // args.mem_every - 1] = (k + 1, rss_mb())

        rss0 = rss_mb()
        if args.profile:
            import cProfile
            prof = cProfile.Profile()
            prof.enable()
        timer = tester.create_timer(1.0 / args.rate, tick)
        t0, cpu0, main0 = time.perf_counter(), time.process_time(), time.thread_time()
        spin_until(
            ex,
            lambda: (
                state["k"] >= args.frames
                and node.idle()
                and np.count_nonzero(~np.isnan(posed)) >= node.counts.frames_published
                and np.count_nonzero(~np.isnan(info_got)) >= node.counts.camera_info_published
            ),
            timeout=args.frames / args.rate * 4 + 30,
        )
        wall = time.perf_counter() - t0
        if args.profile:
            prof.disable()
            import pstats
            print("executor thread, paced run, by own time (wall clock: a call that lets go of "
                  "the GIL is charged the wait to take it back):")
            pstats.Stats(prof).sort_stats("tottime").print_stats(15)
        cpu, main_cpu = time.process_time() - cpu0, time.thread_time() - main0
        tester.destroy_timer(timer)
        if listener is not None:
            # Let the last messages reach the other process, then collect its records.
            spin_until(ex, lambda: False, 1.0)
            listener.stdin.close()
            listener.wait(timeout=60)
            rec = np.load(listen_out)
            far_info, far_depth = rec["info"], rec["depth"]
        n = args.frames
        answered = int(np.count_nonzero(~np.isnan(info_got[:n])))
        print(
            f"paced at {args.rate:.0f} Hz: {answered}/{n} depth images got their CameraInfo "
            f"({answered / wall:.1f} CameraInfo/s over {wall:.1f} s); the estimator took "
            f"{node.processed} frames ({node.processed / wall:.1f}/s), skipped "
            f"{node.counts.skipped} for newer ones; sync drops {node.sync.stats.dropped_total}"
        )
        print(f"  latency depth published -> CameraInfo received: "
              f"{ms_stats(info_got[:n] - sent[:n])}")
        print(f"  latency depth in the node's callback -> CameraInfo received: "
              f"{ms_stats(info_got[:n] - node_got[:n])}")
        print(f"  inside the node, depth callback -> CameraInfo handed to DDS: "
              f"{ms_stats(info_pubd[:n] - node_got[:n])}")
        print(f"  CameraInfo handed to DDS -> received: {ms_stats(info_got[:n] - info_pubd[:n])}")
        print(f"  reference (DDS alone), depth published -> a plain subscriber: "
              f"{ms_stats(depth_got[:n] - sent[:n])}")
        print(f"  reference (DDS alone), depth published -> the node's callback: "
              f"{ms_stats(node_got[:n] - sent[:n])}")
        if listener is not None:
            print("  another process on the same core (as a consumer of camera_info would be):")
            print(f"    latency depth in the node's callback -> CameraInfo received there: "
                  f"{ms_stats(far_info[:n] - node_got[:n])}")
            print(f"    latency depth published -> CameraInfo received there: "
                  f"{ms_stats(far_info[:n] - sent[:n])}")
            print(f"    reference (DDS alone), depth published -> depth received there: "
                  f"{ms_stats(far_depth[:n] - sent[:n])}")
        print(f"  latency depth published -> poses of the frame (estimated frames): "
              f"{ms_stats(posed[:n] - sent[:n])}")
        pc, ec = proc_cpu.array() * 1000, est_cpu.array() * 1000
        if not (pc.size and ec.size):
            raise SystemExit("bench_node: the estimator finished no frame during the run")
        print(
            f"  estimator thread CPU per estimated frame (convert + estimate + window + poses + "
            f"publish): median {np.median(pc):.1f} ms, p95 {np.percentile(pc, 95):.1f} ms, "
            f"mean {pc.mean():.1f} ms; estimate_focal alone: median {np.median(ec):.1f} ms"
        )
        wall_proc = np.array(node.processing_seconds) * 1000
        print(f"  node processing wall time per frame (convert + estimate + window; last "
              f"{len(wall_proc)}): median {np.median(wall_proc):.1f} ms")
        print(
            f"  process CPU {cpu:.1f} s over {wall:.1f} s ({cpu / wall:.0%} of one core): "
            f"{cpu / n * 1000:.1f} ms per input frame, of it the executor thread "
            f"{main_cpu / n * 1000:.1f} ms (publishing, DDS, callbacks) and the estimator thread "
            f"{pc.sum() / n:.1f} ms"
        )
        if n_mem:
            print(f"  resident memory (MB) before the run {rss0:.1f}; after N frames:")
            for k, r in mem:
                print(f"    {int(k):6d} {r:8.1f}")
            half = mem[n_mem // 2:]
            if len(half) >= 2:
                slope = np.polyfit(half[:, 0], half[:, 1], 1)[0] * 1000
                print(f"  slope over the second half ({int(half[0, 0])}-{int(half[-1, 0])} "
                      f"frames): {slope:+.3f} MB per 1000 frames "
                      f"({slope * 1024 / 1000:+.2f} kB per frame)")
            full = np.polyfit(mem[:, 0], mem[:, 1], 1)[0] * 1000 if n_mem >= 2 else np.nan
            print(f"  slope over all samples: {full:+.3f} MB per 1000 frames; Theil-Sen (the "
                  f"median of the pairwise slopes, unmoved by a transient dip): "
                  f"{theil_sen(mem) * 1000:+.3f} MB per 1000 frames")

        # Closed loop: maximum rate.
        if args.closed_loop_frames:
            base = args.frames + 10
            t0 = time.perf_counter()
            for i in range(args.closed_loop_frames):
                publish(base + i)
                spin_until(ex, lambda: not np.isnan(posed[base + i]), 10)
            wall = time.perf_counter() - t0
            print(f"closed loop (next frame when the previous one's poses arrive): "
                  f"{args.closed_loop_frames / wall:.1f} frames/s")
        node.destroy_node()
        tester.destroy_node()


if __name__ == "__main__":
    main()
