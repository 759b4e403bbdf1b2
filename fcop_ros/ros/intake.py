"""What one input message does at the synchroniser, in the node's words: plain Python, no rclpy.

The node's image callback hands each message to :func:`sync_step`, which adds it to the
:class:`~fcop_ros.ros.sync.StampSynchronizer` and reports the frames it completed, the messages
that passed the stamp check, whether time jumped back, the drops to count (under the names the
node's ``rejected`` counter and /diagnostics use) and the log lines that explain them. The node
only applies that: it resets on a jump, hands the frames on, counts and logs (throttled).
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

from .sync import StampSynchronizer


@dataclass(frozen=True)
class SyncStep:
    """One message's outcome: ``sets`` (stamp, [message per input]) matched, oldest first;
    ``accepted`` (input index, stamp, message) that passed the stamp check (held ones released
    with it included); ``jumped``: time jumped back and the synchroniser started again (the focal
    window must too, before the sets reach it); ``dropped``: reason -> messages dropped;
    ``warnings``: (throttle key, log line) explaining those drops."""

    sets: list
    accepted: list
    jumped: bool
    dropped: Counter
    warnings: tuple


def _sec(stamp) -> str:
    return "none" if stamp is None else f"{stamp / 1e9:.3f} s"


def sync_step(sync: StampSynchronizer, index: int, stamp: int, msg, inputs) -> SyncStep:
    """Add ``msg`` (input ``index`` of the names ``inputs``, stamped ``stamp`` ns) to ``sync``."""
    stats = sync.stats
    before, before_inputs, resets = Counter(stats.dropped), Counter(stats.per_input), stats.resets
    sets = sync.add(index, stamp, msg)
    new_drops = stats.dropped - before
    new_inputs = stats.per_input - before_inputs
    jumped = stats.resets != resets
    dropped, warnings = Counter(), []
    for i, stamps, ref in sync.outliers_dropped:
        dropped[f"outlier_stamp_{inputs[i]}"] += len(stamps)
        warnings.append((
            f"outlier_{i}",
            f"fcop_node: dropped {len(stamps)} {inputs[i]} message(s) with an outlier stamp "
            f"({', '.join(_sec(s) for s in stamps)}; the {inputs[i]} stamps before were at "
            f"{_sec(ref)})",
        ))
    if jumped:
        warnings.append(("time_jump", "fcop_node: time jumped back (looped bag?): synchroniser "
                                      "and window reset"))
    waiting = sync.waiting_for()
    for reason, n in new_drops.items():
        if reason == "outlier_stamp":  # counted per input above
            continue
        dropped["sync_" + reason] += n
        if reason == "time_jump_reset":  # said by the time_jump line
            continue
        which = ", ".join(
            f"{inputs[i]} {k}" for (r, i), k in sorted(new_inputs.items()) if r == reason)
        silent = ""
        if reason == "queue_full" and waiting:
            silent = (f"; nothing from {' and '.join(inputs[i] for i in waiting)} to match them "
                      "(silent, or stamped far from the others?)")
        warnings.append((
            "sync_" + reason,
            f"fcop_node: dropped {n} message(s) in the synchroniser: "
            f"{reason.replace('_', ' ')} ({which}){silent}",
        ))
    return SyncStep(sets, list(sync.accepted), jumped, dropped, tuple(warnings))
