"""Large images across processes: how many 640x480 32FC3 images (3.7 MB each) a subscriber in
this process receives of those a publisher in a child process sends, best effort (the node's
input QoS) or reliable, with Fast DDS's default transports or with
config/fastdds_large_images.xml. DDS is kept on this machine (fcop_ros.ros.dds), in the domain
of $ROS_DOMAIN_ID if set.

    python bench/dds_large_images.py                     # default transports, then the profile
    python bench/dds_large_images.py --images 300 --rate 30 --transports profile
"""
import argparse
import os
import subprocess
import sys
import time

from fcop_ros.ros.dds import keep_on_this_machine, large_image_profile, profile_env_vars

TOPIC = "dds_large_images_bench"


def _qos(reliable):
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE if reliable
                      else ReliabilityPolicy.BEST_EFFORT)


def publish(images, rate, reliable):
    """The child: wait for the subscriber, send ``images`` images at ``rate`` Hz."""
    import numpy as np
    import rclpy
    from sensor_msgs.msg import Image

    rclpy.init()
    node = rclpy.create_node("dds_large_images_pub")
    pub = node.create_publisher(Image, TOPIC, _qos(reliable))
    end = time.monotonic() + 30
    while pub.get_subscription_count() == 0 and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
    time.sleep(1.0)  # let discovery settle on both sides
    msg = Image(height=480, width=640, encoding="32FC3", step=640 * 12)
    msg.data = np.zeros(480 * 640 * 12, np.uint8).tobytes()
    t0 = time.monotonic()
    for k in range(images):
        now = time.time_ns()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
        msg.header.frame_id = str(k)
        pub.publish(msg)
        time.sleep(max(0.0, t0 + (k + 1) / rate - time.monotonic()))
    time.sleep(2.0)
    node.destroy_node()
    rclpy.shutdown()


def receive(images, rate, reliable, transports):
    env = keep_on_this_machine(dict(os.environ))
    for var in profile_env_vars():
        env.pop(var, None)
        if transports == "profile":
            env[var] = large_image_profile()
    # This process's Fast DDS reads the same file (once, when rclpy initialises it).
    os.environ.update(env)
    for var in set(profile_env_vars()) - set(env):
        os.environ.pop(var, None)
    import rclpy
    from sensor_msgs.msg import Image

    rclpy.init()
    node = rclpy.create_node("dds_large_images_sub")
    got = {}

    def on_image(msg):
        sent = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        got[msg.header.frame_id] = (time.time_ns() - sent) / 1e6

    node.create_subscription(Image, TOPIC, on_image, _qos(reliable))
    child = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--publish",
                              "--images", str(images), "--rate", str(rate)]
                             + (["--reliable"] if reliable else []), env=env)
    while child.poll() is None:
        rclpy.spin_once(node, timeout_sec=0.05)
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    node.destroy_node()
    rclpy.shutdown()
    lat = sorted(got.values())
    spread = f", latency {lat[len(lat) // 10]:.0f}-{lat[(9 * len(lat)) // 10]:.0f} ms " \
             "(10th-90th percentile)" if lat else ""
    print(f"{transports} transports, {'reliable' if reliable else 'best effort'}: "
          f"{len(got)} of {images} images received{spread}", flush=True)
    return child.returncode


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--images", type=int, default=300)
    ap.add_argument("--rate", type=float, default=30.0, help="Hz")
    ap.add_argument("--reliable", action="store_true", help="reliable QoS (default best effort)")
    ap.add_argument("--transports", choices=("default", "profile", "both"), default="both")
    ap.add_argument("--publish", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.publish:
        return publish(a.images, a.rate, a.reliable)
    runs = ("default", "profile") if a.transports == "both" else (a.transports,)
    if len(runs) > 1:  # Fast DDS reads the profile once per process: one process per run
        for t in runs:
            subprocess.run([sys.executable, os.path.abspath(__file__), "--images",
                            str(a.images), "--rate", str(a.rate), "--transports", t]
                           + (["--reliable"] if a.reliable else []), check=True)
        return 0
    return receive(a.images, a.rate, a.reliable, runs[0])


if __name__ == "__main__":
    sys.exit(main())
