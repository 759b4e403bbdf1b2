"""The node's CameraInfo side, apart from ROS: each depth image answered once with the publishable
focal, the last publication (:class:`LatestEstimate`) and the objects of the newest frame. Both
threads publish (the executor for depth images that come after an estimate, the worker for one
that came before), so everything here is under one lock. Plain Python: the node hands it the
function that publishes, and the tests a list."""
from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass

from .answers import DepthAnswers
from .intrinsics import IntrinsicsRefused


@dataclass(frozen=True)
class LatestEstimate:
    """What the node published last: the CameraInfo of depth stamp ``stamp_ns`` (focal, principal
    point, image size) and the window estimate behind it (``std_rel``, ``support`` votes,
    ``frames`` in the window); ``objects``: the ObjectPoses of the newest processed frame, of this
    stamp once that frame is processed."""

    stamp_ns: int
    focal: float
    cx: float
    cy: float
    width: int
    height: int
    std_rel: float | None
    support: int
    frames: int
    objects: tuple = ()


class CameraInfoOutput:
    """``publish(info)`` sends one CameraInfo (the node: camera_info and ~/latest_camera_info);
    ``camera_info(focal, width, height, header)`` builds it or raises IntrinsicsRefused."""

    def __init__(self, publish, camera_info):
        self.lock = threading.RLock()  # the node's reset swaps its publisher under it
        self._publish = publish
        self._camera_info = camera_info
        self._answers = DepthAnswers()
        self._latest: LatestEstimate | None = None
        self._objects: tuple = ()
        self.published = 0  # CameraInfo messages

    @property
    def latest(self) -> LatestEstimate | None:
        with self.lock:
            return self._latest

    def answer_depth(self, stamp: int, msg, publishable) -> None:
        """Publish the CameraInfo of depth image ``msg`` (stamp ``stamp``) with the estimate
        ``publishable()`` gives (a :class:`.tracker.Publishable` or None). It is read under the
        lock, so that a frame the worker finishes meanwhile finds the stamp owed
        (:meth:`answer_owed`)."""
        with self.lock:
            if self._answers.answered(stamp):
                return
            ready = publishable()
            if ready is None or (msg.width, msg.height, msg.header.frame_id) != (
                    ready.width, ready.height, ready.frame_id):
                self._answers.unanswered(stamp)
                return
            try:
                info = self._camera_info(ready.focal, ready.width, ready.height, msg.header)
            except IntrinsicsRefused:
                self._answers.unanswered(stamp)
                return
            self._send(stamp, info, ready.window_estimate, self._objects)

    def answer_owed(self, stamp: int, header, ready) -> None:
        """The worker's frame ``stamp`` made estimate ``ready`` publishable: its depth image,
        which came before any estimate, gets its CameraInfo now (unless a newer one went out)."""
        with self.lock:
            if not self._answers.owed(stamp):
                return
            try:
                info = self._camera_info(ready.focal, ready.width, ready.height, header)
            except IntrinsicsRefused:
                return
            self._send(stamp, info, ready.window_estimate, ())

    def objects(self, stamp: int, objects) -> None:
        """The poses of frame ``stamp``: the next publications carry them, and so does the latest
        if it is of this stamp."""
        with self.lock:
            self._objects = tuple(objects)
            if self._latest is not None and self._latest.stamp_ns == stamp:
                self._latest = dataclasses.replace(self._latest, objects=self._objects)

    def forget(self) -> None:
        """After a jump back in time: stamps seen before may come again, each answered anew."""
        with self.lock:
            self._answers.forget()

    def withdraw(self) -> None:
        """The gate closed on the latest publication (the node swapped its latched publisher):
        no latest estimate until the next one goes out."""
        with self.lock:
            self._latest = None

    def clear(self) -> None:
        """After a reset: no latest estimate, no objects, every stamp answered anew."""
        with self.lock:
            self._answers.forget()
            self._latest, self._objects = None, ()

    def _send(self, stamp: int, info, window_estimate, objects: tuple) -> None:
        self._publish(info)
        self.published += 1
        self._answers.answer(stamp)
        self._latest = LatestEstimate(
            stamp, float(info.k[0]), float(info.k[2]), float(info.k[5]), int(info.width),
            int(info.height), getattr(window_estimate, "std_rel", None),
            int(window_estimate.support), int(window_estimate.frames), objects)
