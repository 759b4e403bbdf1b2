"""Which depth images got their CameraInfo. Each depth stamp is answered once: at once when an
estimate is publishable, else by the worker when that frame's own estimate makes one (if no newer
stamp was answered meanwhile). Plain Python; the node calls it under its publishing lock."""
from __future__ import annotations

from collections import OrderedDict


class DepthAnswers:
    """The last ``keep`` depth stamps answered and the last ``keep`` that came before an estimate
    (bounded: stamps are only compared with recent ones)."""

    def __init__(self, keep: int = 256):
        self.keep = keep
        self._answered: OrderedDict = OrderedDict()
        self._unanswered: OrderedDict = OrderedDict()
        self._newest = float("-inf")  # the newest stamp answered; stamps may be negative

    def answered(self, stamp: int) -> bool:
        """True if depth stamp ``stamp`` got its CameraInfo."""
        return stamp in self._answered

    def unanswered(self, stamp: int) -> None:
        """Depth stamp ``stamp`` came when no estimate could answer it."""
        self._remember(self._unanswered, stamp)

    def answer(self, stamp: int) -> None:
        """Depth stamp ``stamp`` got its CameraInfo."""
        self._remember(self._answered, stamp)
        self._unanswered.pop(stamp, None)
        self._newest = max(self._newest, stamp)

    def owed(self, stamp: int) -> bool:
        """True if depth stamp ``stamp`` came before an estimate and is still due one: nothing
        newer was answered since (CameraInfo does not go out of order)."""
        return stamp in self._unanswered and stamp > self._newest

    def forget(self) -> None:
        """After a reset, stamps seen before may come again (a looped bag, a camera clock that
        restarts): each gets its CameraInfo anew."""
        self._answered.clear()
        self._unanswered.clear()
        self._newest = float("-inf")

    def _remember(self, od: OrderedDict, stamp: int) -> None:
        od[stamp] = True
        while len(od) > self.keep:
            od.popitem(last=False)
