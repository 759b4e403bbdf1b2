"""A NOCS network slower than the camera, through the real fcop_node in-process over DDS: depth
at 30 Hz, NOCS and mask for every 6th depth image (5 Hz), published ``--delay`` s after their
depth with its stamp. For each ``queue_size`` it prints how many of the NOCS frames matched and
what the node's /diagnostics advice said. DDS is kept on this machine (fcop_ros.ros.dds).

    python bench/late_nocs.py --queue-sizes 5 8 10 --nocs-frames 150 --delay 0.25
"""
import argparse
import time

import numpy as np

from fcop_ros.ros.dds import keep_on_this_machine


def trial(queue_size, nocs_frames, delay):
    from fcop_ros.ros.node import FcopNode
    from fcop_ros.ros.spin import ros_context, spin_until
    from fcop_ros.synthetic import apply_noise, render_scene
    from msg_adapters import depth_to_image, header_from_ns, mask_to_image, nocs_to_image
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    fr = apply_noise(render_scene(np.random.default_rng(0), 5, 600.0), "mild",
                     np.random.default_rng(0))
    with ros_context() as (ctx, ex):
        node = FcopNode(context=ctx, cli_args=["--ros-args", "-p", f"queue_size:={queue_size}"])
        tester = Node("late_nocs_tester", context=ctx)
        pubs = [tester.create_publisher(Image, t, qos_profile_sensor_data)
                for t in ("depth", "nocs", "mask")]
        ex.add_node(node)
        ex.add_node(tester)
        assert spin_until(ex, lambda: all(p.get_subscription_count() for p in pubs), 10)
        assert spin_until(ex, lambda: not node.warming_up, 300)
        # (arrival s, input, stamp ns) in arrival order
        events = []
        for k in range(6 * nocs_frames):
            events.append((k / 30, 0, k))
            if k % 6 == 0:
                events += [(k / 30 + delay, 1, k), (k / 30 + delay, 2, k)]
        events.sort()
        to_msg = (lambda h: depth_to_image(fr.depth, "32FC1", h),
                  lambda h: nocs_to_image(fr.nocs, "32FC3", h),
                  lambda h: mask_to_image(fr.mask, "mono8", h))
        base = time.time_ns()
        t0 = time.monotonic() + 0.5
        for when, i, k in events:
            while time.monotonic() < t0 + when:
                ex.spin_once(timeout_sec=max(0.0, min(0.005, t0 + when - time.monotonic())))
            pubs[i].publish(to_msg[i](header_from_ns(base + k * 33_333_333, "camera")))
        spin_until(ex, lambda: False, 2.0)
        matched = node.sync.stats.matched
        advice = node.intake.queue_advice()
        node.destroy_node()
        tester.destroy_node()
    print(f"queue_size {queue_size}: {matched} of {nocs_frames} NOCS frames matched"
          + (f"; advice: {advice}" if advice else ""), flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--queue-sizes", type=int, nargs="+", default=[5, 8, 10])
    ap.add_argument("--nocs-frames", type=int, default=150)
    ap.add_argument("--delay", type=float, default=0.25, help="s after the depth")
    a = ap.parse_args()
    keep_on_this_machine()
    for q in a.queue_sizes:
        trial(q, a.nocs_frames, a.delay)


if __name__ == "__main__":
    main()
