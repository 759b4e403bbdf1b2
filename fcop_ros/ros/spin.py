"""A private Context with its executor, and spinning it until a condition holds or a deadline
passes: how the tools and the tests run ROS and wait for DDS traffic without a bare sleep."""

from __future__ import annotations

import contextlib
import time


@contextlib.contextmanager
def ros_context(args=None):
    """A private, initialised Context and a SingleThreadedExecutor on it; both shut down after.
    rclpy is imported here, so the DDS environment can be set up after importing this module."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    ctx = Context()
    rclpy.init(args=args, context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    try:
        yield ctx, executor
    finally:
        executor.shutdown(timeout_sec=1.0)
        ctx.try_shutdown()


def spin_until(executor, condition, timeout: float = 20.0, step: float = 0.02) -> bool:
    """Spin ``executor`` in steps of at most ``step`` seconds until ``condition()`` holds or
    ``timeout`` seconds have passed; return whether it holds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        executor.spin_once(timeout_sec=step)
    return bool(condition())
