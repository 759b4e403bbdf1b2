"""Log throttling by reason: a flood of one problem becomes one line every few seconds with a
count, while a different problem still gets its own line at once. No rclpy (any logger)."""

from __future__ import annotations

import math
import threading
import time
from collections import Counter


class LogThrottle:
    """At most one log line per reason every ``period`` seconds, with the count since the last."""

    def __init__(self, logger, period: float = 5.0):
        self.logger, self.period = logger, period
        self._last: dict[str, float] = {}
        self._since: Counter = Counter()
        self._lock = threading.Lock()

    def _due(self, reason: str):
        with self._lock:
            self._since[reason] += 1
            now = time.monotonic()
            if now - self._last.get(reason, -math.inf) >= self.period:
                self._last[reason] = now
                return self._since.pop(reason)
        return 0

    def warn(self, reason: str, text: str) -> None:
        n = self._due(reason)
        if n:
            self.logger.warning(
                f"{text}" + (f" ({n} such since the last report)" if n > 1 else "")
            )

    def info(self, reason: str, text: str) -> None:
        n = self._due(reason)
        if n:
            self.logger.info(f"{text}" + (f" ({n} such since the last report)" if n > 1 else ""))
