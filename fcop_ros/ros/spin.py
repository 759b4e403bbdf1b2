"""Spin an rclpy executor until a condition holds or a deadline passes: how the tools and the
tests wait for DDS traffic without a bare sleep."""

from __future__ import annotations

import time


def spin_until(executor, condition, timeout: float = 20.0, step: float = 0.02) -> bool:
    """Spin ``executor`` in steps of at most ``step`` seconds until ``condition()`` holds or
    ``timeout`` seconds have passed; return whether it holds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        executor.spin_once(timeout_sec=step)
    return bool(condition())
