"""Stamp synchroniser for N input streams (message_filters is not on PyPI): plain Python, no rclpy.

Policy. Each input keeps a queue sorted by stamp (bounded: the oldest is dropped past
``queue_size``). Whenever every queue holds a message, look at the oldest of each: if they lie
within ``slop`` of each other (exact matching: slop 0, equal stamps), they form a set, which is
emitted; otherwise the oldest of them can never be matched (every other input already holds
only newer messages past the slop) and is dropped. So each message is used at most once, sets
come out in increasing stamp order, and nothing waits longer than the slowest input.

A message older than the last emitted set is dropped as late, unless it is older by more than
``reset_after`` (a time jump back, e.g. a looped bag): then all queues are cleared and the
synchroniser starts again. A second message with the same stamp on one input is dropped as a
duplicate.
"""
from __future__ import annotations

import bisect
from collections import Counter
from dataclasses import dataclass, field


@dataclass
class SyncStats:
    """Counts since start: sets emitted, messages dropped by reason, resets."""

    matched: int = 0
    dropped: Counter = field(default_factory=Counter)
    resets: int = 0

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())


class StampSynchronizer:
    """Match messages of ``n_inputs`` streams by stamp (integer nanoseconds).

    Args:
        n_inputs: number of streams (e.g. 3: depth, NOCS, mask).
        queue_size: messages kept per stream while waiting for the others.
        slop: largest stamp difference within a set, in seconds (0 = exact).
        reset_after: a stamp this many seconds older than the last set resets the synchroniser.
    """

    def __init__(self, n_inputs: int, queue_size: int = 10, slop: float = 0.0, reset_after: float = 1.0):
        if n_inputs < 1 or queue_size < 1 or slop < 0 or reset_after <= 0:
            raise ValueError("StampSynchronizer: need n_inputs >= 1, queue_size >= 1, slop >= 0, reset_after > 0")
        self.n = int(n_inputs)
        self.queue_size = int(queue_size)
        self.slop_ns = int(round(slop * 1e9))
        self.reset_ns = int(round(reset_after * 1e9))
        self.stats = SyncStats()
        self._queues: list[list] = [[] for _ in range(self.n)]
        self._last: int | None = None

    def reset(self) -> None:
        """Forget all queued messages and the last emitted stamp."""
        self._queues = [[] for _ in range(self.n)]
        self._last = None

    def pending(self) -> int:
        return sum(len(q) for q in self._queues)

    def add(self, index: int, stamp_ns: int, msg) -> list[tuple[int, list]]:
        """Offer one message of stream ``index``; return the sets completed by it, oldest first,
        each as (stamp of its first stream, [message per stream])."""
        stamp_ns = int(stamp_ns)
        if self._last is not None and stamp_ns <= self._last:
            if stamp_ns < self._last - self.reset_ns:
                self.stats.dropped["time_jump_reset"] += self.pending()
                self.stats.resets += 1
                self.reset()
            else:
                self.stats.dropped["late"] += 1
                return []
        q = self._queues[index]
        keys = [s for s, _ in q]
        pos = bisect.bisect_left(keys, stamp_ns)
        if pos < len(q) and q[pos][0] == stamp_ns:
            self.stats.dropped["duplicate"] += 1
            return []
        q.insert(pos, (stamp_ns, msg))
        if len(q) > self.queue_size:
            q.pop(0)
            self.stats.dropped["queue_full"] += 1
        return self._match()

    def _match(self) -> list[tuple[int, list]]:
        out = []
        while all(self._queues):
            heads = [q[0][0] for q in self._queues]
            lo, hi = min(heads), max(heads)
            if hi - lo <= self.slop_ns:
                msgs = [q.pop(0)[1] for q in self._queues]
                self._last = hi
                self.stats.matched += 1
                out.append((heads[0], msgs))
            else:
                self._queues[heads.index(lo)].pop(0)
                self.stats.dropped["unmatched"] += 1
        return out
