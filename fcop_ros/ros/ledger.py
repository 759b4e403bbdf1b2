"""The node's bookkeeping, apart from ROS: what it dropped and why, what deserved a warning, the
frames whose estimate went out, how long frames took, and why the newest frame gave no focal.
Plain Python; the node changes and reads it under its lock, /diagnostics and fcop_replay read it
through the node's counts."""
from __future__ import annotations

from collections import Counter, deque


def clipped(reason: str) -> str:
    """A reason for diagnostics: at most 300 characters."""
    return reason if len(reason) <= 300 else reason[:297] + "..."


class NodeLedger:
    """Counters of one node run. ``dropped``: input messages and frames not used, by reason (the
    diagnostics' ``dropped_<reason>``); ``warnings``: accepted input that deserved a word;
    ``frames_published``: processed frames whose window estimate was publishable (their poses and
    markers went out, if asked for); ``skipped``: matched frames a newer one replaced in the
    hand-off (their drop count, ``estimator_busy``); ``no_focal_frames``: frames the estimator
    took that gave no focal, refused input included; ``since_empty``: frames it finished since
    the window was last emptied; ``newest_refusal``: why the newest of them gave no focal (''
    if it gave one); ``processing_seconds``: the last ``keep`` estimated frames' times."""

    def __init__(self, keep: int = 200):
        self.dropped: Counter = Counter()
        self.warnings: Counter = Counter()
        self.frames_published = 0
        self.no_focal_frames = 0
        self.since_empty = 0
        self.newest_refusal = ""
        self.processing_seconds: deque = deque(maxlen=keep)

    @property
    def skipped(self) -> int:
        return self.dropped["estimator_busy"]

    def no_focal(self, reason: str, why: str) -> None:
        """A frame the estimator took but could not use (refused input, a failure): counted as
        dropped under ``reason``; ``why`` is kept as the newest frame's reason."""
        self.dropped[reason] += 1
        self.no_focal_frames += 1
        self.since_empty += 1
        self.newest_refusal = clipped(why)

    def estimated(self, est, outcome, seconds: float) -> None:
        """Frame estimate ``est`` reached the tracker with :class:`.frame_outcome.FrameOutcome`
        ``outcome`` after ``seconds``."""
        self.newest_refusal = "" if est.focal is not None else clipped(est.reason)
        self.no_focal_frames += est.focal is None
        self.since_empty += 1
        self.processing_seconds.append(seconds)
        self.dropped.update(outcome.dropped)
        self.warnings.update(outcome.warnings)

    def window_emptied(self) -> None:
        """A reset or a jump back in time emptied the window."""
        self.newest_refusal = ""
        self.since_empty = 0
