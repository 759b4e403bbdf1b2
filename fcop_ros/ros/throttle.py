"""Log throttling by cause: a flood of one problem becomes one line every few seconds with a
count, while a different problem, or another cause of the same drop reason, still gets its own
line at once. No rclpy (any logger)."""

from __future__ import annotations

import math
import re
import threading
import time
from collections import Counter

_NUMBER = re.compile(r"\d+(?:\.\d+)?")


class LogThrottle:
    """At most one log line per cause every ``period`` seconds, with the count since the last.

    A cause is the drop reason with the text's shape: its words, not its numbers. So one bad
    stream repeats as one line however its sizes or stamps vary, while a depth image in rgb8
    and a NOCS image in mono8 (both ``bad_encoding``) are each reported."""

    def __init__(self, logger, period: float = 5.0, clock=time.monotonic):
        self.logger, self.period, self._clock = logger, period, clock
        self._last: dict[tuple, float] = {}
        self._since: Counter = Counter()
        self._lock = threading.Lock()

    def _due(self, reason: str, text: str):
        key = (reason, _NUMBER.sub("#", text))
        with self._lock:
            self._since[key] += 1
            now = self._clock()
            if now - self._last.get(key, -math.inf) >= self.period:
                self._last[key] = now
                return self._since.pop(key)
        return 0

    def warn(self, reason: str, text: str) -> None:
        n = self._due(reason, text)
        if n:
            self.logger.warning(
                f"{text}" + (f" ({n} such since the last report)" if n > 1 else "")
            )

    def info(self, reason: str, text: str) -> None:
        n = self._due(reason, text)
        if n:
            self.logger.info(f"{text}" + (f" ({n} such since the last report)" if n > 1 else ""))
