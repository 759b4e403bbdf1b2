"""A one-slot hand-off to a worker thread: the producer never waits, the worker takes the newest.

The node's subscription callbacks put each complete frame here; a newer frame replaces one the
worker has not taken yet (the caller counts that as skipped), so the estimator never works on a
backlog and publishing never waits for it. Plain Python (no rclpy), so it can be tested alone.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class WorkerState:
    """A consistent reading of the worker: ``busy_since`` (clock time the current item was taken,
    None when idle), ``last_done`` (when the last item finished, None before any), ``processed``
    (items finished, failed ones included) and whether an item waits in the slot."""

    busy_since: float | None
    last_done: float | None
    processed: int
    waiting: bool


class LatestSlotWorker:
    """Runs ``handle(item, generation)`` on a thread for the newest item put, one at a time.

    ``generation`` counts :meth:`clear` calls: the handler compares it with :attr:`generation` to
    discard work on an item taken before a reset. ``on_error(item, exc)`` is called when the
    handler raises (the worker carries on). ``now``: the clock of ``busy_since`` and ``last_done``.
    ``before``: run once on the thread before the first item is taken (e.g. a warm-up whose
    seconds no item should wait for on the producer's side); items put meanwhile wait in the slot.
    """

    def __init__(
        self,
        handle: Callable[[Any, int], Any],
        on_error: Callable[[Any, Exception], None],
        now: Callable[[], float] = time.monotonic,
        name: str = "worker",
        before: Callable[[], None] | None = None,
    ):
        self._handle, self._on_error, self._now = handle, on_error, now
        self._before = before
        self._cv = threading.Condition()
        self._slot = None
        self._has_item = False
        self._stop = False
        self._busy_since: float | None = None
        self._last_done: float | None = None
        self._processed = 0
        self._generation = 0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def put(self, item) -> bool:
        """Hand ``item`` over; True when it replaced an item the worker had not taken (skipped)."""
        with self._cv:
            replaced = self._has_item
            self._slot, self._has_item = item, True
            self._cv.notify()
        return replaced

    def clear(self) -> None:
        """Drop a waiting item and start a new generation (work taken before it is stale)."""
        with self._cv:
            self._slot, self._has_item = None, False
            self._generation += 1

    @property
    def generation(self) -> int:
        with self._cv:
            return self._generation

    def state(self) -> WorkerState:
        with self._cv:
            return WorkerState(self._busy_since, self._last_done, self._processed, self._has_item)

    @property
    def processed(self) -> int:
        with self._cv:
            return self._processed

    @property
    def busy_since(self) -> float | None:
        with self._cv:
            return self._busy_since

    @property
    def stopping(self) -> bool:
        """Whether :meth:`stop` was called (an item still running may outlive its owner)."""
        with self._cv:
            return self._stop

    def idle(self) -> bool:
        """True when no item waits and none is being handled."""
        with self._cv:
            return not self._has_item and self._busy_since is None

    def stop(self, timeout: float = 5.0) -> None:
        """Ask the thread to end after its current item and wait for it (unless called from it)."""
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=timeout)

    def _run(self) -> None:
        if self._before is not None:
            self._before()
        while True:
            with self._cv:
                while not self._has_item and not self._stop:
                    self._cv.wait(0.5)
                if self._stop:
                    return
                item, self._slot, self._has_item = self._slot, None, False
                generation = self._generation
                self._busy_since = self._now()
            try:
                self._handle(item, generation)
            except Exception as exc:  # noqa: BLE001 - the worker must outlive any bad item
                self._on_error(item, exc)
            finally:
                with self._cv:
                    self._busy_since = None
                    self._last_done = self._now()
                    self._processed += 1
