"""The focal length the node publishes, kept apart from ROS: the sliding window over the frames'
estimates, the frames it re-evaluates when its settings change, the image size it holds, and the
publish gate. Plain Python (the node calls it under its lock), tested without a node."""
from __future__ import annotations

import dataclasses
from collections import deque
from dataclasses import dataclass

import numpy as np

from ..core import FocalWindow
from .gate import held_back


@dataclass(frozen=True)
class Publishable:
    """The estimate depth images get their CameraInfo from: the window's, when the gate lets it
    out, with the image size it belongs to."""

    focal: float
    std_rel: float
    width: int
    height: int
    window_estimate: object
    frame_id: str = ""


@dataclass(frozen=True)
class TrackStep:
    """What one frame did to the tracker: the window estimate after it (None if the frame was
    dropped), the publishable estimate, the size the window had before a change of image size
    (``resized_from``) or the frame_id before a change of camera frame (``reframed_from``), or
    the size and frame_id it kept when a frame of another size or frame_id came without a focal
    of its own (``kept_size``, ``kept_frame_id``: the frame was dropped)."""

    window_estimate: object | None
    ready: Publishable | None
    resized_from: tuple | None = None
    kept_size: tuple | None = None
    reframed_from: str | None = None
    kept_frame_id: str | None = None


def light(est):
    """The frame estimate without its pixel data: what the window needs to re-evaluate it."""
    names = {f.name for f in dataclasses.fields(est)}
    heavy = {"instances": [], "inlier_masks": None, "votes": np.zeros(0), "objects": []}
    return dataclasses.replace(est, **{k: v for k, v in heavy.items() if k in names})


class FocalTracker:
    """A FocalWindow with what the node adds around it.

    - The window holds frames of one image size and one frame_id (one camera): a frame of
      another size or frame_id starts a new window if it has a focal of its own, and is dropped
      otherwise (a window without a focal takes any).
    - The frames since the window's last restart are kept (light), as many as the largest
      ``max_frames`` so far, so that new window settings re-evaluate them and a window shrunk
      and grown again gets its frames back.
    - The gate (:func:`.gate.held_back`): the window's focal is publishable only within
      ``max_uncertainty`` and ``focal_range``.
    """

    def __init__(self, window_options, max_uncertainty: float, focal_range: tuple):
        self.size: tuple | None = None  # (width, height) of the frames in the window
        self.frame_id: str | None = None  # their depth images' frame_id
        self.publishable: Publishable | None = None
        self._history: deque = deque()
        self._history_cap = 0
        self._max_uncertainty = max_uncertainty
        self._focal_range = tuple(focal_range)
        self.window = FocalWindow(window_options)
        self._rebuild(keep=False)

    def __len__(self) -> int:
        return len(self.window)

    @property
    def current(self):
        """The window's WindowEstimate now, publishable or not."""
        return self.window.current

    def configure(self, window_options, max_uncertainty: float, focal_range: tuple) -> None:
        """New settings: new window options re-evaluate the kept frames in a new window; the
        gate is applied again either way (a focal may now be held back, or freed)."""
        self._max_uncertainty = max_uncertainty
        self._focal_range = tuple(focal_range)
        if window_options != self.window.options:
            self.window = FocalWindow(window_options)
            self._rebuild(keep=True)
        else:
            self._gate(self.window.current)

    def held_back(self) -> str:
        """Why the window's focal does not go out now ('' when it does)."""
        return held_back(self.window.current, self._max_uncertainty, self._focal_range)

    def add(self, est, t: float, frame_id: str = "") -> TrackStep:
        """Add one frame's FocalEstimate ``est`` (of its ``image_size``, its depth image in
        ``frame_id``) at ``t`` (seconds)."""
        size = tuple(est.image_size)
        resized = reframed = None
        if self.size != size or self.frame_id != frame_id:
            if est.focal is None and self.size is not None and self.window.rated:
                return TrackStep(None, self.publishable, kept_size=self.size,
                                 kept_frame_id=self.frame_id)
            if self.size is not None:
                resized = self.size if self.size != size else None
                reframed = self.frame_id if self.frame_id != frame_id else None
                self.window.reset()
                self._history.clear()
            self.size, self.frame_id = size, frame_id
        win = self._add(light(est), t)
        self._gate(win)
        return TrackStep(win, self.publishable, resized_from=resized, reframed_from=reframed)

    def reset(self) -> None:
        """Forget every frame (the image size stays until a frame of another size comes)."""
        self.window.reset()
        self._history.clear()
        self.publishable = None

    def _rebuild(self, keep: bool) -> None:
        frames = list(self._history) if keep else []
        self._history = deque()
        self._history_cap = max(self._history_cap, self.window.options.max_frames)
        for est, t in frames:
            self._add(est, t)
        self._gate(self.window.current)

    def _add(self, est, t: float):
        win = self.window.add(est, t)
        self._history.append((est, t))
        keep = len(self.window) if win.changed else max(len(self.window), self._history_cap)
        while len(self._history) > keep:
            self._history.popleft()
        return win

    def _gate(self, win) -> None:
        if self.size is None or held_back(win, self._max_uncertainty, self._focal_range):
            self.publishable = None
        else:
            self.publishable = Publishable(
                float(win.focal), float(win.std_rel), self.size[0], self.size[1], win,
                self.frame_id or ""
            )
