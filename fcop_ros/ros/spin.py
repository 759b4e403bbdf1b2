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
        shut_down(ctx)


def shut_down(context=None) -> None:
    """``rclpy.try_shutdown`` of ``context`` (None: the default one, which rclpy then replaces,
    so that ``rclpy.init`` works again), also when a Ctrl-C shuts it down at the same moment.
    On Jazzy rclpy's signal handler shuts contexts down from its own thread without the
    context's lock: between ``try_shutdown``'s check and its shutdown, rcl raised
    "rcl_shutdown already called" after a clean stop (one CI run in many). Kilted's handle says
    "Context already shutdown" (a RuntimeError, as rcl's RCLError is)."""
    import rclpy
    from rclpy.utilities import get_default_context

    try:
        rclpy.try_shutdown(context=context)
    except RuntimeError:
        if (get_default_context() if context is None else context).ok():
            raise
        if context is None:
            rclpy.try_shutdown()  # it is down now: rclpy replaces the default context


def spin_until(executor, condition, timeout: float = 20.0, step: float = 0.02) -> bool:
    """Spin ``executor`` in steps of at most ``step`` seconds until ``condition()`` holds or
    ``timeout`` seconds have passed; return whether it holds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        executor.spin_once(timeout_sec=step)
    return bool(condition())
