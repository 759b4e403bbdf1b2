"""In-process ROS 2 test harness: a private Context and executor per test, spin with a deadline."""
from __future__ import annotations

import contextlib
import time

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import Header

from msg_adapters import depth_to_image, mask_to_image, nocs_to_image, stamp_ns  # noqa: F401 (re-exported)


@contextlib.contextmanager
def ros_context(args=None):
    """A private, initialised Context and a SingleThreadedExecutor on it; both shut down after."""
    ctx = Context()
    rclpy.init(args=args, context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    try:
        yield ctx, executor
    finally:
        executor.shutdown(timeout_sec=1.0)
        ctx.try_shutdown()


def spin_until(executor, condition, timeout: float = 20.0, step: float = 0.02) -> bool:
    """Spin until ``condition()`` holds or the deadline passes; return whether it holds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        executor.spin_once(timeout_sec=step)
    return bool(condition())


def header(stamp_ns: int, frame_id: str = "camera_optical_frame") -> Header:
    h = Header()
    h.stamp.sec, h.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    h.frame_id = frame_id
    return h


def frame_messages(frame, stamp_ns: int, depth_encoding="32FC1", nocs_encoding="32FC3", mask_encoding="mono8"):
    """Depth, NOCS and mask Image messages of a rendered frame, all with the same header."""
    h = header(stamp_ns)
    return (depth_to_image(frame.depth, depth_encoding, h), nocs_to_image(frame.nocs, nocs_encoding, h),
            mask_to_image(frame.mask, mask_encoding, h))


class Recorder:
    """Collects the messages of one topic."""

    def __init__(self, node, msg_type, topic, qos=10):
        self.msgs = []
        self.sub = node.create_subscription(msg_type, topic, self.msgs.append, qos)

    def __len__(self):
        return len(self.msgs)


def as_array(values) -> np.ndarray:
    return np.asarray(values, dtype=np.float64)
