"""What each input message does at the synchroniser, in the node's words: plain Python, no rclpy.

The node's image callback hands each message to :meth:`Intake.add`, which adds it to the
:class:`~fcop_ros.ros.sync.StampSynchronizer` and reports the frames it completed, the messages
that passed the stamp check, whether time jumped back, the drops to count (under the names the
node's ``dropped`` counter and /diagnostics use) and the log lines that explain them. The node
only applies that: it resets on a jump, hands the frames on, counts and logs (throttled).

Drops of a faster input while frames keep matching are how inputs of different rates meet
(30 Hz depth with a 5 Hz NOCS network leaves five of six depth images unmatched): said once, at
INFO. Drops of the slowest input (each of its messages should make a frame), or with no frame
matched for :data:`FLOWING_SECONDS`, are a WARN that names what is missing.
"""
from __future__ import annotations

from collections import Counter, deque
from itertools import islice
from dataclasses import dataclass

from .sync import StampSynchronizer

#: A set matched this recently (seconds) means frames are flowing.
FLOWING_SECONDS = 5.0
#: An input that has sent nothing for this long (seconds) has stopped, not fallen behind.
SILENT_SECONDS = 5.0
#: An input that sent this many times the messages of the slowest one is a faster input.
FASTER = 1.5
#: Messages per input whose arrival is kept: for rates and ages, and for delays.
_KEPT = 128


@dataclass(frozen=True)
class SyncStep:
    """One message's outcome: ``sets`` (stamp, [message per input]) matched, oldest first;
    ``accepted`` (input index, stamp, message) that passed the stamp check (held ones released
    with it included); ``jumped``: time jumped back and the synchroniser started again (the focal
    window must too, before the sets reach it); ``dropped``: reason -> messages dropped;
    ``log``: (level 'warn' or 'info', throttle key, line) explaining those drops."""

    sets: list
    accepted: list
    jumped: bool
    dropped: Counter
    log: tuple


def _sec(stamp) -> str:
    return "none" if stamp is None else f"{stamp / 1e9:.3f} s"


class Intake:
    """A StampSynchronizer (``sync``) for the inputs named ``inputs``, and what its drops mean."""

    def __init__(self, sync: StampSynchronizer, inputs):
        self.sync = sync
        self.inputs = tuple(inputs)
        self._last_match: float | None = None  # clock time of the last matched set
        self._said_flowing: set = set()  # drop reasons said at INFO since their last WARN
        self.received = [0] * len(self.inputs)  # messages per input
        # (stamp, clock time) of each input's recent messages: rates and ages.
        self._arrivals = [deque(maxlen=_KEPT) for _ in self.inputs]
        # For queue_size advice, stamp -> clock time of the messages that passed the stamp check
        # since time last jumped back (a looped bag's stamps come again, seconds later: no
        # delay), and how late each input's newest came after the first of its stamp (s; None
        # until known).
        self._when: list = [{} for _ in self.inputs]
        self._lag: list = [None] * len(self.inputs)  # (delay s, the input it is after)
        self._first: float | None = None  # clock time of the first message of any input

    def _note_arrival(self, index: int, stamp: int, now: float) -> None:
        """Note a message that passed the stamp check: its delay after the first message of its
        stamp (or, matching approximately, of a stamp within the slop) on the other inputs."""
        when = self._when[index]
        if len(when) >= _KEPT:
            del when[next(iter(when))]
        when.setdefault(stamp, now)
        slop = self.sync.slop_ns
        first = []
        for j, other in enumerate(self._when):
            if j == index:
                continue
            if stamp in other:
                first.append((other[stamp], j))
            elif slop > 0:  # approximate matching: the nearest recent stamps
                first += [(t, j) for s, t in islice(reversed(other.items()), 16)
                          if abs(s - stamp) <= slop]
        # First of its stamp: on time now, whatever it was before.
        t, j = min(first) if first else (now, index)
        self._lag[index] = (now - t, j)

    def reset(self) -> None:
        """A fresh start of the synchroniser (its clocks too): no frame has matched since. The
        inputs' arrivals and delays stay: they describe the inputs, not the frames."""
        self.sync.reset(clocks=True)
        self._last_match = None
        self._said_flowing.clear()

    def configure(self, queue_size: int, slop: float) -> Counter:
        """Change the synchroniser's queue bound and slop; the messages a smaller queue drops,
        under the names :meth:`add` counts them by."""
        before = self.sync.stats.dropped["queue_full"]
        self.sync.configure(queue_size, slop)
        lost = self.sync.stats.dropped["queue_full"] - before
        return Counter({"sync_queue_full": lost} if lost else {})

    def since_first(self, now: float) -> float | None:
        """Seconds since the first message of any input at clock time ``now`` (None before it):
        how long an input that never sent has been silent."""
        return None if self._first is None else now - self._first

    def ages(self, now: float) -> tuple:
        """(input name, seconds since its last message at clock time ``now``, None before the
        first) for each input."""
        return tuple((name, now - seen[-1][1] if seen else None)
                     for name, seen in zip(self.inputs, self._arrivals))

    def _rate(self, index: int) -> float:
        seen = self._arrivals[index]
        span = seen[-1][1] - seen[0][1] if len(seen) > 1 else 0.0
        return (len(seen) - 1) / span if span > 0 else 0.0

    def queue_advice(self) -> str:
        """What queue_size the inputs' delays need, when the latest input comes later than the
        queue covers (e.g. 'nocs comes 250 ms after the depth of its stamp, at 30 Hz:
        queue_size must be above 7.5'), else ''."""
        late = [(lag[0], i, lag[1]) for i, lag in enumerate(self._lag)
                if lag is not None and lag[0] > 0]
        if not late:
            return ""
        lag, i, after = max(late, key=lambda item: (round(item[0], 3), -item[1]))
        # The others queue that long at their fastest rate.
        rate = max(self._rate(j) for j in range(len(self.inputs)) if j != i)
        need = lag * rate
        if need < self.sync.queue_size:
            return ""
        return (f"{self.inputs[i]} comes {lag * 1000:.0f} ms after the {self.inputs[after]} of "
                f"its stamp, at {rate:.0f} Hz: queue_size must be above {need:.1f}")

    def _waiting_hint(self, waiting, now: float) -> str:
        """Why the queued messages find nothing to match: inputs that never sent or stopped
        (SILENT_SECONDS), else inputs later than the queue covers."""
        every = self.ages(now)
        ages = [every[i] for i in waiting]
        names = [name for name, _ in ages]
        never = [name for name, age in ages if age is None]
        stopped = [(name, age) for name, age in ages if age is not None and age >= SILENT_SECONDS]
        if len(never) + len(stopped) < len(waiting):
            advice = self.queue_advice() or ("raise queue_size to cover that delay times "
                                             "their rate")
            return (f"; nothing from {' and '.join(names)} to match them: silent, or later than "
                    f"queue_size ({self.sync.queue_size}) messages of the others ({advice})")
        said = []
        if never:
            they = ("are they", "topics", "theirs") if len(never) > 1 else ("is it", "topic", "it")
            said.append(f"nothing received from {' and '.join(never)} yet ({they[0]} published, "
                        f"and the node's {they[1]} remapped to {they[2]}?)")
        if stopped:
            said.append(f"nothing from {' and '.join(n for n, _ in stopped)} for "
                        f"{min(a for _, a in stopped):.0f} s (stopped?)")
        return "; " + "; ".join(said)

    def add(self, index: int, stamp: int, msg, now: float) -> SyncStep:
        """Add ``msg`` (input ``index``, stamped ``stamp`` ns) at clock time ``now`` (s)."""
        sync, inputs, stats = self.sync, self.inputs, self.sync.stats
        self.received[index] += 1
        if self._first is None:
            self._first = now
        self._arrivals[index].append((stamp, now))
        before, before_inputs = Counter(stats.dropped), Counter(stats.per_input)
        resets = stats.resets
        sets = sync.add(index, stamp, msg)
        if sets:
            self._last_match = now
        new_drops = stats.dropped - before
        new_inputs = stats.per_input - before_inputs
        jumped = stats.resets != resets
        if jumped:
            self._when = [{} for _ in self.inputs]
            self._lag = [None] * len(self.inputs)
        for i, s, _ in sync.accepted:
            self._note_arrival(i, s, now)
        dropped, log = Counter(), []
        for i, stamps, ref in sync.outliers_dropped:
            dropped[f"outlier_stamp_{inputs[i]}"] += len(stamps)
            log.append(("warn", f"outlier_{i}",
                        f"dropped {len(stamps)} {inputs[i]} message(s) with an outlier "
                        f"stamp ({', '.join(_sec(s) for s in stamps)}; the {inputs[i]} stamps "
                        f"before were at {_sec(ref)})"))
        if jumped:
            log.append(("warn", "time_jump", "time jumped back (looped bag?): "
                                             "synchroniser and window reset"))
        flowing = self._last_match is not None and now - self._last_match <= FLOWING_SECONDS
        slowest = min(self.received)
        waiting = sync.waiting_for()
        for reason, n in new_drops.items():
            if reason == "outlier_stamp":  # counted per input above
                continue
            dropped["sync_" + reason] += n
            if reason == "time_jump_reset":  # said by the time_jump line
                continue
            mine = sorted((i, k) for (r, i), k in new_inputs.items() if r == reason)
            which = ", ".join(f"{inputs[i]} {k}" for i, k in mine)
            faster = all(self.received[i] >= FASTER * slowest for i, _ in mine)
            if flowing and faster and reason in ("unmatched", "queue_full"):
                if reason not in self._said_flowing:
                    self._said_flowing.add(reason)
                    log.append(("info", "sync_flowing_" + reason, (
                        f"{reason.replace('_', ' ')} messages ({which}) dropped in "
                        "the synchroniser while frames keep matching: expected where an input "
                        "comes at a lower rate than the others (e.g. a NOCS network slower than "
                        "the camera); counted in /diagnostics, said again only if no frame "
                        f"matches for {FLOWING_SECONDS:.0f} s")))
                continue
            self._said_flowing.discard(reason)
            hint = ""
            if reason == "queue_full" and waiting:
                hint = self._waiting_hint(waiting, now)
            log.append(("warn", "sync_" + reason,
                        f"dropped {n} message(s) in the synchroniser: "
                        f"{reason.replace('_', ' ')} ({which}){hint}"))
        return SyncStep(sets, list(sync.accepted), jumped, dropped, tuple(log))
