"""Stamp synchroniser for N input streams (message_filters is not on PyPI): plain Python, no rclpy.

Policy. Each input keeps a queue sorted by stamp (bounded: the oldest is dropped past
``queue_size``). Whenever every queue holds a message, the newest of the queues' oldest
messages is the pivot: every later set holds a message at or after it, so a message more than
``slop`` before it can never be matched and is dropped. Otherwise each input offers its message
nearest the pivot, and the set goes out once no nearer one can still arrive: the input has a
message at or after the pivot, or its next one, at least its shortest recent interval after its
last, would be farther (like message_filters' ApproximateTime, which also waits; its Python
version pairs with the nearest message already queued, right or not). Exact matching (slop 0)
needs equal stamps. So each message is used at most once, sets come out in increasing stamp
order, a set holds each input's stamp nearest the pivot, and nothing waits longer than the
slowest input. Each input is taken to arrive in stamp order. Stamps that are the same frame's
but lie apart by more than half the interval between frames (independent jitter of more than a
quarter of it, a constant offset of more than half) pair with the neighbouring frame, which is
nearer, as with any rule that goes by nearness; the rule before 25 Nov 2026 (the oldest message
of each input within the slop) paired those right while no message was lost, and wrongly a NOCS
network that answers only some depth images, which this rule pairs right.

Outlier stamps. Before a message reaches its queue, its stamp is compared with the input's
previous accepted stamp: a stamp more than ``reset_after`` seconds back, or further ahead than
``max(reset_after, 10 x the input's usual interval)``, is a jump. A jump is held, not used: if
the input's next messages return to its old clock, the held ones were isolated outliers (a
frame stamped 0 or far in the future) and are dropped and counted per input
(``stats.outliers``); if ``confirm`` messages in a row continue the jump (increasing stamps), or
another input has already arrived there, the jump is real (a looped bag, a camera that paused)
and the held messages are used. A real jump back (older than the last emitted set by more than
``reset_after``) clears all queues and starts again (``stats.resets``), as does
:meth:`reset`; the other inputs' messages still on the old clock (more than ``reset_after``
after the stamp that jumped: a NOCS network's answers to the previous lap of a looped bag)
are then dropped as ``time_jump_reset`` until each input jumps too (queued, they would sort
after every new stamp and hold the new sets back). A message slightly older than the last
emitted set is dropped as late; a second message with the same stamp on one input, waiting or
already used in a set, as a duplicate.
"""
from __future__ import annotations

import bisect
from collections import Counter, deque
from dataclasses import dataclass, field

#: Seconds a stamp must lie from its input's clock to be a jump (the default of ``reset_after``,
#: the node's): a looped bag restarts the synchroniser only if it lasts longer.
RESET_AFTER = 1.0


@dataclass
class SyncStats:
    """Counts since start: sets emitted, messages dropped by reason (``dropped``) and by
    (reason, input index) (``per_input``), outlier stamps per input index, resets."""

    matched: int = 0
    dropped: Counter = field(default_factory=Counter)
    per_input: Counter = field(default_factory=Counter)
    outliers: Counter = field(default_factory=Counter)
    resets: int = 0

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())

    def drop(self, reason: str, index: int | None = None, n: int = 1) -> None:
        if n <= 0:
            return
        self.dropped[reason] += n
        if index is not None:
            self.per_input[(reason, index)] += n


def _median(values) -> float:
    """``float(np.median(values))`` of a few integers, in plain Python: the node calls this on
    the executor thread for every message, and numpy's partition releases the GIL, which on a
    busy estimator thread costs up to a switch interval (5 ms) to take back. Same arithmetic:
    the middle value, or the float sum of the two middle values halved."""
    s = sorted(values)
    n = len(s)
    if n % 2:
        return float(s[n // 2])
    return (float(s[n // 2 - 1]) + float(s[n // 2])) / 2


class StampSynchronizer:
    """Match messages of ``n_inputs`` streams by stamp (integer nanoseconds).

    Args:
        n_inputs: number of streams (e.g. 3: depth, NOCS, mask).
        queue_size: messages kept per stream while waiting for the others.
        slop: largest stamp difference within a set, in seconds (0 = exact).
        reset_after: a stamp this many seconds away from its input's clock is a jump (see the
            module docstring); a confirmed jump this far back resets the synchroniser.
        confirm: messages in a row on one input that make a jump real.
    """

    def __init__(self, n_inputs: int, queue_size: int = 10, slop: float = 0.0,
                 reset_after: float = RESET_AFTER, confirm: int = 3):
        if n_inputs < 1 or queue_size < 1 or slop < 0 or reset_after <= 0 or confirm < 1:
            raise ValueError("StampSynchronizer: need n_inputs >= 1, queue_size >= 1, slop >= 0, "
                             "reset_after > 0, confirm >= 1")
        self.n = int(n_inputs)
        self.queue_size = int(queue_size)
        self.slop_ns = int(round(slop * 1e9))
        self.reset_ns = int(round(reset_after * 1e9))
        self.confirm = int(confirm)
        self.stats = SyncStats()
        self.reset(clocks=True)
        #: Filled by each :meth:`add`: messages that passed the stamp check, as (input, stamp,
        #: msg), and outliers dropped, as (input, [stamps], the input's stamp before them).
        self.accepted: list[tuple[int, int, object]] = []
        self.outliers_dropped: list[tuple[int, list[int], int | None]] = []

    def configure(self, queue_size: int | None = None, slop: float | None = None) -> None:
        """Change the queue bound and the slop, keeping what is queued (oldest dropped past the
        bound)."""
        if queue_size is not None:
            if queue_size < 1:
                raise ValueError("queue_size must be >= 1")
            self.queue_size = int(queue_size)
            for i, q in enumerate(self._queues):
                while len(q) > self.queue_size:
                    q.pop(0)
                    self.stats.drop("queue_full", i)
        if slop is not None:
            if slop < 0:
                raise ValueError("slop must be >= 0")
            self.slop_ns = int(round(slop * 1e9))

    def reset(self, clocks: bool = False) -> None:
        """Forget all queued messages and the last emitted stamp; with ``clocks`` also each
        input's stamp history and held messages (a fresh start)."""
        self._queues: list[list] = [[] for _ in range(self.n)]
        self._last: int | None = None
        self._used: list[deque] = [deque(maxlen=64) for _ in range(self.n)]  # stamps in sets
        if clocks:
            # After a jump back: stamps above these are the old clock's (see the docstring).
            self._stale_above: list[int | None] = [None] * self.n
            self._ref: list[int | None] = [None] * self.n  # last accepted stamp per input
            self._steps: list[deque] = [deque(maxlen=9) for _ in range(self.n)]  # forward steps
            self._held: list[list] = [[] for _ in range(self.n)]  # a jump awaiting confirmation

    def pending(self) -> int:
        return sum(len(q) for q in self._queues)

    def waiting_for(self) -> list[int]:
        """The inputs with nothing queued: what the queued messages of the others wait for."""
        return [i for i, q in enumerate(self._queues) if not q]

    def held(self) -> int:
        """Messages held while a stamp jump waits for confirmation."""
        return sum(len(h) for h in self._held)

    # ----- stamp checks
    def _ahead_ns(self, index: int) -> float:
        steps = self._steps[index]
        if len(steps) < 2:
            return float("inf")  # the input's rate is not known yet
        return max(self.reset_ns, 10 * _median(steps))

    def _fits(self, index: int, stamp: int) -> bool | None:
        """Whether ``stamp`` continues input ``index``'s clock (None: no clock yet)."""
        ref = self._ref[index]
        if ref is None:
            return None
        return ref - self.reset_ns <= stamp <= ref + self._ahead_ns(index)

    def _drop_held(self, index: int) -> None:
        held = self._held[index]
        if held:
            self.stats.outliers[index] += len(held)
            self.stats.drop("outlier_stamp", index, len(held))
            self.outliers_dropped.append((index, [s for s, _ in held], self._ref[index]))
            held.clear()

    def _note(self, index: int, stamp: int, jump: bool) -> None:
        ref = self._ref[index]
        if ref is not None and stamp > ref and not jump:
            self._steps[index].append(stamp - ref)
        if ref is None or stamp > ref or jump:
            self._ref[index] = stamp

    def add(self, index: int, stamp_ns: int, msg) -> list[tuple[int, list]]:
        """Offer one message of stream ``index``; return the sets completed by it, oldest first,
        each as (stamp of its first stream, [message per stream]). See also :attr:`accepted`
        and :attr:`outliers_dropped`."""
        stamp = int(stamp_ns)
        self.accepted, self.outliers_dropped = [], []
        stale = self._stale_above[index]
        if stale is not None:
            if stamp > stale:
                self.stats.drop("time_jump_reset", index)
                return []
            self._stale_above[index] = None  # this input has jumped back too
        fits = self._fits(index, stamp)
        others = [self._fits(j, stamp) for j in range(self.n)
                  if j != index and self._ref[j] is not None]
        if fits is None:
            fits = not others or any(others)
        if fits:
            self._drop_held(index)  # the input is back on its clock: what was held were outliers
            self._note(index, stamp, False)
            return self._accept(index, stamp, msg)
        held = self._held[index]
        if held and held[-1][0] < stamp <= held[-1][0] + min(self._ahead_ns(index),
                                                             self.reset_ns * 1000):
            held.append((stamp, msg))
        else:
            self._drop_held(index)
            held.append((stamp, msg))
        if len(held) < self.confirm and not any(others):
            return []
        # A real jump: use what was held, in order.
        out = []
        release, self._held[index] = list(held), []
        for k, (s, m) in enumerate(release):
            self._note(index, s, k == 0)
            out += self._accept(index, s, m)
        return out

    # ----- matching
    def _accept(self, index: int, stamp_ns: int, msg) -> list[tuple[int, list]]:
        if self._last is not None and stamp_ns <= self._last:
            if stamp_ns < self._last - self.reset_ns:
                pending = self.pending()
                self.stats.drop("time_jump_reset", None, pending)
                self.stats.resets += 1
                self.reset()
                self._stale_above = [
                    stamp_ns + self.reset_ns if j != index and ref is not None
                    and ref > stamp_ns + self.reset_ns else None
                    for j, ref in enumerate(self._ref)
                ]
            elif stamp_ns in self._used[index]:
                self.stats.drop("duplicate", index)
                return []
            else:
                self.stats.drop("late", index)
                # a good message, only too late to match
                self.accepted.append((index, stamp_ns, msg))
                return []
        q = self._queues[index]
        keys = [s for s, _ in q]
        pos = bisect.bisect_left(keys, stamp_ns)
        if pos < len(q) and q[pos][0] == stamp_ns:
            self.stats.drop("duplicate", index)
            return []
        self.accepted.append((index, stamp_ns, msg))
        q.insert(pos, (stamp_ns, msg))
        if len(q) > self.queue_size:
            q.pop(0)
            self.stats.drop("queue_full", index)
        return self._match()

    def _match(self) -> list[tuple[int, list]]:
        out = []
        while all(self._queues):
            heads = [q[0][0] for q in self._queues]
            hi = max(heads)
            if hi - min(heads) > self.slop_ns:
                # Every later set holds a message at or after ``hi`` (the oldest of its input):
                # a head more than the slop before it can never be matched.
                self._drop_oldest_head(heads)
                continue
            picks = [self._closest(i, hi) for i in range(self.n)]
            if any(p is None for p in picks):
                break  # a closer partner may still come
            stamps = [q[k][0] for q, k in zip(self._queues, picks)]
            if max(stamps) - min(stamps) > self.slop_ns:
                self._drop_oldest_head(heads)
                continue
            msgs = []
            for i, (q, k) in enumerate(zip(self._queues, picks)):
                if k:
                    self.stats.drop("unmatched", i, k)
                msgs.append(q[k][1])
                del q[:k + 1]
            for used, s in zip(self._used, stamps):
                used.append(s)
            self._last = max(stamps)
            self.stats.matched += 1
            out.append((stamps[0], msgs))
        return out

    def _drop_oldest_head(self, heads: list[int]) -> None:
        """Drop, as unmatched, the oldest of the queues' oldest messages (stamps ``heads``)."""
        i = heads.index(min(heads))
        self._queues[i].pop(0)
        self.stats.drop("unmatched", i)

    def _closest(self, index: int, stamp: int) -> int | None:
        """The position in input ``index``'s queue of the message nearest ``stamp``, or None
        while a nearer one can still arrive: the input has nothing at or after ``stamp`` yet,
        its next message, at least its shortest recent interval after its last, could be
        nearer, and that message would not push the one at hand out of a full queue."""
        q = self._queues[index]
        keys = [s for s, _ in q]
        pos = bisect.bisect_left(keys, stamp)
        if pos < len(q):
            if pos == 0 or q[pos][0] - stamp < stamp - q[pos - 1][0]:
                return pos
            return pos - 1
        gap = stamp - keys[-1]
        if gap == 0:
            return pos - 1
        if len(q) >= self.queue_size and pos == 1:
            return 0
        steps = self._steps[index]
        soonest = keys[-1] + (min(steps) if len(steps) >= 2 else 0)
        return pos - 1 if soonest - stamp >= gap else None
